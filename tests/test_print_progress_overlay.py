"""During a print the highlighted layer follows what the (virtual) printer has executed."""

import re
import threading

import numpy as np
import trimesh

from arapp.printing import SliceSettings, slice_mesh
from arapp.printing.gcode import parse_gcode
from arapp.printing.link.job import Program
from arapp.printing.link.serial_link import SerialPrinter
from arapp.engine.toolpath_overlay import CURRENT_COLOUR, PrintProgressOverlay

from virtual_printer import VirtualPrinterPty

FAULTS = ["100:resend", "110:missing_lineno", "115:checksum_mismatch"]


def _quick_job() -> list[str]:
    """A real sliced job, with heating waits dropped and moves sped up so the virtual printer runs it fast."""
    result = slice_mesh(trimesh.creation.box(extents=(8.0, 8.0, 1.5)),
                        SliceSettings(layer_height=0.3, first_layer_height=0.3, infill=20, skirts=0))
    lines = []
    for line in result.gcode.splitlines():
        if re.match(r"\s*M(109|190|104|140)\b", line):
            continue
        lines.append(re.sub(r"F\d+(\.\d*)?", "F600000", line))
    return lines


def test_highlight_advances_with_the_printers_execution():
    gcode = _quick_job()
    layers = parse_gcode("\n".join(gcode))
    assert len(layers) == 5
    program = Program.from_lines(gcode)
    texts = [c.text for c in program.commands]
    # layer of each program command, from the G-code's own layer comments
    layer_of = np.full(len(texts), -1)
    layer, k = -1, 0
    for line in gcode:
        m = re.match(r";LAYER:(\d+)", line.strip())
        if m:
            layer = int(m.group(1))
        elif k < len(texts) and line.split(";")[0].strip() and re.sub(r"\s+", " ", line.split(";")[0].strip()) == texts[k]:
            layer_of[k] = layer
            k += 1
    assert k == len(texts)

    overlay = PrintProgressOverlay(layers, (250, 210, 210))
    seen = []
    lock = threading.Lock()
    with VirtualPrinterPty(simulated_errors=FAULTS) as vp:
        def progress(p):
            with lock:
                executed = sum(1 for c in vp.executed if c in set(texts))
            if overlay.update(p):
                sets = overlay.line_sets()
                highlighted = [s for s in sets if tuple(s.rgba) == tuple(CURRENT_COLOUR)]
                z = {round(float(v), 3) for s in highlighted for v in np.asarray(s.polylines)[:, :, 2].ravel()}
                seen.append((overlay.current, executed, z))

        printer = SerialPrinter(vp.port, 115200, timeout=2.0, window=1, rx_buffer=63)
        printer.connect()
        state = printer.print_gcode(gcode, progress=progress)
        printer.close()
    assert state.status == "done"
    order = [s[0] for s in seen if s[0] >= 0]
    assert order == sorted(order) and order[0] == 0 and order[-1] == len(layers) - 1
    assert set(order) == set(range(len(layers)))
    for current, executed, z in seen:
        if current < 0:
            continue
        # the printer had already executed a command of the highlighted layer, and not beyond the next
        assert executed > 0 and layer_of[min(executed, len(texts)) - 1] >= current
        assert z == {round(layers[current].z, 3)}
