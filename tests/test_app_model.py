"""The headless app model (arapp.app) drives a whole session with PySide6 not importable.

The session runs in a child interpreter where `sys.modules["PySide6"] = None`
makes every `import PySide6...` fail: open a recording, load a model, edit a
control point's weight, place the model, slice it and print it to the
virtual printer (tests/virtual_printer.py, OctoPrint's VirtualPrinter behind a
pty). Oracles: the recording's ground-truth poses (the tracked pose), the
model file itself (the edited weight), the placement's own rule (the solid's
size and centre), and the printer's executed lines against the G-code.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
RECORDING = ROOT / "recordings" / "board_orbit"
MODEL = ROOT / "models" / "sphere.json"

DRIVER = r'''
import json, sys, threading
sys.modules["PySide6"] = None   # any import of Qt fails from here on
sys.path.insert(0, sys.argv[1])  # tests/, for virtual_printer
from pathlib import Path

import numpy as np

from arapp.engine.commands import Step
from arapp.engine.headless import EventQueue, headless_engine_factory
from arapp.app.printlink import SerialTarget
from arapp.app.session import Session
from arapp.geometry.placement import Placement
from arapp.printing import SliceSettings
from arapp.printing.bed_anchor import bed_from_anchor_measured, save_bed_anchor
from arapp.printing.link.job import Program
from virtual_printer import VirtualPrinterPty

recording, model_path, out = sys.argv[2], sys.argv[3], Path(sys.argv[4])
report = {"qt_blocked": True}
try:
    import PySide6  # noqa: F401
    report["qt_blocked"] = False
except ImportError:
    pass

events = EventQueue()
session = Session(headless_engine_factory(events))
errors = []
session.events.error.connect(lambda t, m: errors.append(f"{t}: {m}"))
session.open_source(recording)
assert events.wait_until(lambda: session.source_info is not None, 60), errors
session.pause()
session.open_model(model_path)
report["model"] = session.model.name
s0 = session.model.surfaces[0]
w0 = float(s0.weights[1, 1])
xyz = tuple(float(v) for v in s0.control_points[1, 1])
session.edit_control_point(0, 1, 1, xyz, 3.0 * w0)
report["weights"] = [w0, float(session.model.surfaces[0].weights[1, 1])]
session.set_placement(Placement(24.0, (5.0, -3.0, 0.0), (0.0, 0.0, 30.0)))
session.seek(10)
session.send(Step(1))
gen = session.model_gen
ok = events.wait_until(lambda: session.last_shown is not None and session.last_shown.result.index == 10
                       and session.last_shown.result.extra.get("model_gen") == gen
                       and session.last_shown.result.world_from_camera is not None, 60)
shown = session.last_shown
report["frame"] = {"ok": ok, "index": shown.result.index, "gen": shown.result.extra.get("model_gen"),
                   "faces": shown.result.extra.get("mesh_faces"),
                   "pose": np.asarray(shown.result.world_from_camera).tolist(),
                   "display": list(shown.display.shape)}

profile = out / "printer.json"
save_bed_anchor(profile, {"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 42, "length": 0.04},
                bed_from_anchor_measured((110.0, 110.0)))
ps = session.new_print_session(work_dir=out / "jobs")
ps.make_solid()
report["solid"] = {"extents": [float(x) for x in ps.solid.extents]}
session.set_placement(Placement(48.0, (5.0, -3.0, 0.0), (0.0, 0.0, 30.0)))
double = session.new_print_session(work_dir=out / "jobs")
double.make_solid()
report["solid"]["extents_at_48"] = [float(x) for x in double.solid.extents]
session.print_session = ps
# every feature at 1000 mm/s, the fastest setting: the virtual printer sleeps a tenth of each move's time
fast = {f"{k}_speed": 1000.0 for k in ("perimeter", "external_perimeter", "infill", "solid_infill", "first_layer", "travel")}
assert ps.slice(SliceSettings(layer_height=0.3, first_layer_height=0.3, infill=10.0, **fast), str(profile)), errors
report["layers"] = ps.result.layers
ps.set_preview(True)
assert events.wait_until(lambda: (session.toolpaths_info or {}).get("gen") == session.toolpaths_gen, 60), errors
finished = threading.Event()
ps.events.print_event.connect(lambda ev: finished.set() if ev.finished else None)
# ambient above the job's targets: the printer's M190/M109 waits return at once (else ~19 s of simulated heating)
with VirtualPrinterPty(simulated_errors=[], settings={"ambientTemperature": 260.0}) as vp:
    assert ps.start_print(SerialTarget(vp.port), str(profile)), errors
    assert finished.wait(240), "the print did not finish"
    executed = list(vp.executed)
program = [c.text for c in Program.from_lines(ps.result.gcode.splitlines()).commands]
in_program = set(program)
report["printed_in_order"] = [c for c in executed if c in in_program] == program
report["printed"] = len(program)
report["progress"] = ps.last_progress.percent if ps.last_progress else None
report["errors"] = errors
session.shutdown(wait=5.0)
report["qt_loaded"] = any(m.startswith("PySide6.") for m in sys.modules)
(out / "report.json").write_text(json.dumps(report))
'''


@pytest.mark.slow
def test_a_whole_session_runs_without_qt(tmp_path):
    env = dict(os.environ, PYOPENGL_PLATFORM=os.environ.get("PYOPENGL_PLATFORM", "egl"))
    env.pop("QT_QPA_PLATFORM", None)
    proc = subprocess.run([sys.executable, "-c", DRIVER, str(ROOT / "tests"), str(RECORDING), str(MODEL),
                           str(tmp_path)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=420)
    assert proc.returncode == 0, proc.stderr[-3000:]
    r = json.loads((tmp_path / "report.json").read_text())
    assert r["qt_blocked"] and not r["qt_loaded"]
    assert r["errors"] == []
    # the edit: the weight in force is the one set (the loaded weight, tripled)
    assert r["weights"][0] > 0 and r["weights"][1] == pytest.approx(3.0 * r["weights"][0])
    # the frame shown is frame 10 (seeked to, then stepped) of the recording with the edited model (this generation) drawn,
    # at the pose of the recording's ground truth
    f = r["frame"]
    assert f["ok"] and f["gen"] >= 1 and f["faces"] > 0 and f["index"] == 10
    truth = np.loadtxt(RECORDING / "groundtruth.tum", comments="#")
    t_est = np.asarray(f["pose"])[:3, 3]
    assert np.linalg.norm(t_est - truth[f["index"], 1:4]) < 0.02  # metres
    # the solid is the model as placed: twice the size, twice every extent (a 2 mm shell aside: 2 %)
    ext, ext2 = np.array(r["solid"]["extents"]), np.array(r["solid"]["extents_at_48"])
    assert ext2 == pytest.approx(2.0 * ext, rel=0.02)
    assert r["layers"] == pytest.approx(ext[2] / 0.3, abs=1.5)  # 0.3 mm layers over its height
    # the printer ran the whole job, once, in order
    assert r["printed_in_order"] and r["printed"] > 100
    assert r["progress"] == pytest.approx(100.0)



# -- the app model's parts, alone (no engine threads) ----------------------------------------------------


class FakeEngine:
    """Records the commands a Session sends; the engine interface Session uses."""

    def __init__(self, spec, **options):
        self.spec, self.options, self.sent = spec, options, []
        self.playing = True
        self.running = False

    def send(self, command):
        self.sent.append(command)

    def start(self):
        self.running = True

    def stop(self, wait=0.0):
        self.running = False

    def take(self):
        return None


def fake_session():
    from arapp.app.session import Session

    engines = []
    session = Session(lambda spec, **o: engines.append(FakeEngine(spec, **o)) or engines[-1])
    return session, engines


def test_events_call_their_callbacks_in_order_until_disconnected():
    from arapp.engine.events import Event

    ev, calls = Event("x"), []
    first = ev.connect(lambda a: calls.append(("first", a)))
    ev.connect(lambda a: calls.append(("second", a)))
    ev.emit(1)
    ev.disconnect(first)
    ev.emit(2)
    assert calls == [("first", 1), ("second", 1), ("second", 2)]


def test_commands_cross_a_process_boundary_without_the_model():
    import pickle

    from arapp.engine import commands as cmd
    from arapp.geometry.placement import Placement

    place = Placement(30.0, (1.0, 2.0, 0.0), (0.0, 0.0, 45.0))
    c = cmd.SetModel(3, "models/sphere.json", {(0, 1, 1): ((1.0, 2.0, 3.0), 0.5)}, place, "wireframe",
                     model=object())
    sent = pickle.loads(pickle.dumps(c.for_transfer()))
    assert sent.model is None and sent == c  # `model` takes no part in equality: the rest is the same
    assert sent.placement == place and sent.edits[(0, 1, 1)] == ((1.0, 2.0, 3.0), 0.5)
    with pytest.raises(ValueError, match="positive"):
        cmd.SetSpeed(0.0)


def test_the_session_keeps_a_typed_placement_and_tells_the_engine():
    from arapp.engine import commands as cmd
    from arapp.geometry.placement import Placement

    session, engines = fake_session()
    seen = []
    session.events.placement_changed.connect(seen.append)
    session.open_source(str(RECORDING))
    engine = engines[-1]
    assert engine.spec == str(RECORDING) and engine.running
    with pytest.raises(TypeError, match="Placement"):
        session.set_placement({"size_mm": 20.0})
    session.model = object()  # as if loaded (set_model needs a real one; placement only needs "a model")
    session.placement = Placement(50.0)
    session.scale_by(2)  # two wheel notches: 1.1 ** 2 times the size (the rule of Session.scale_by)
    assert session.placement.size_mm == pytest.approx(60.5)
    session.scale_by(200)
    assert session.placement.size_mm == 1000.0  # at most one metre
    placements = [c.placement for c in engine.sent if isinstance(c, cmd.SetPlacement)]
    assert placements == seen and [p.size_mm for p in placements] == pytest.approx([60.5, 1000.0])
    with pytest.raises(ValueError, match="display mode"):
        session.set_mode("sparkly")


def test_dropped_paths_are_models_or_sources():
    from arapp.app.session import Session

    assert Session.classify_path("models/vase.json") == ("model", "models/vase.json")
    assert Session.classify_path("part.STL") == ("model", "part.STL")
    assert Session.classify_path("recordings/board_orbit/session.json") == ("source", "recordings/board_orbit")
    assert Session.classify_path("clip.mp4") == ("source", "clip.mp4")
