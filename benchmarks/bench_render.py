"""Overlay rendering benchmark: registration against cv2.projectPoints, and speed against pyrender.

Registration: the rendered silhouette (alpha >= 0.5) against every triangle of the same mesh projected
with cv2.projectPoints (distortion included) and filled by OpenCV at 4x4 supersampling.

Speed: `OverlayRenderer.draw()` against pyrender's `OffscreenRenderer.render` + a numpy alpha blend
over the same frame, same mesh, same poses, interleaved frame by frame in the same run.
"""

from __future__ import annotations

import os
import time

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import trimesh  # noqa: E402

MACHINE = "this 2-core CPU machine (Mesa llvmpipe through EGL; no GPU was available to this session)"


def _rot(axis, deg):
    a = np.asarray(axis, float)
    return cv2.Rodrigues(a / np.linalg.norm(a) * np.radians(deg))[0]


def _pose(R, t):
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def _coverage(mesh, T, K, dist, w, h, s=4):
    pc = mesh.vertices @ T[:3, :3].T + T[:3, 3]
    px, _ = cv2.projectPoints(pc.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, dist)
    sub = ((px.reshape(-1, 2) + 0.5) * s - 0.5) * 16
    tri = np.round(sub[mesh.faces]).astype(np.int32)
    big = np.zeros((h * s, w * s), np.uint8)
    for t in tri:
        cv2.fillConvexPoly(big, t, 255, lineType=cv2.LINE_8, shift=4)
    return cv2.resize(big.astype(np.float32) / 255.0, (w, h), interpolation=cv2.INTER_AREA)


def _iou_centroid(alpha, cov):
    a = alpha.astype(float) / 255.0
    m1, m2 = a >= 0.5, cov >= 0.5
    iou = (m1 & m2).sum() / max((m1 | m2).sum(), 1)
    ys, xs = np.mgrid[0:alpha.shape[0], 0:alpha.shape[1]]
    c1 = np.array([(a * xs).sum(), (a * ys).sum()]) / a.sum()
    c2 = np.array([(cov * xs).sum(), (cov * ys).sum()]) / cov.sum()
    return float(iou), float(np.linalg.norm(c1 - c2))


def _registration(quick: bool) -> list[str]:
    from arapp.render import OverlayRenderer

    w, h = 640, 480
    cams = [
        ("fx!=fy, pp off-centre", np.array([[610.0, 0, 347.3], [0, 560.0, 221.8], [0, 0, 1]]), None),
        ("wide, k1=-0.28 distortion", np.array([[420.0, 0, 301.6], [0, 455.0, 259.4], [0, 0, 1]]),
         np.array([-0.28, 0.09, 0.0012, -0.0008, -0.012])),
        ("fx!=fy, k1=-0.14 distortion", np.array([[610.0, 0, 347.3], [0, 560.0, 221.8], [0, 0, 1]]),
         np.array([-0.14, 0.045, 0.0006, -0.0004, -0.006])),
    ]
    box = trimesh.creation.box((0.08, 0.05, 0.03))
    for _ in range(4):
        box = box.subdivide()
    meshes = [
        ("sphere", trimesh.creation.icosphere(4, radius=0.05), _pose(np.eye(3), [0.03, -0.02, 0.45])),
        ("box", box, _pose(_rot([1, 0.4, 0.2], 35), [-0.05, 0.03, 0.40])),
        ("torus", trimesh.creation.torus(0.05, 0.018, major_sections=48, minor_sections=24),
         _pose(_rot([1, 0, 0], 60), [0.08, 0.05, 0.5])),
        ("torus near edge", trimesh.creation.torus(0.05, 0.018, major_sections=48, minor_sections=24),
         _pose(_rot([1, 1, 0], 50), [0.22, 0.14, 0.5])),
    ]
    if quick:
        meshes = meshes[::2]
    rows = ["| camera | model | IoU | centroid error (px) | goal met |", "|---|---|---|---|---|"]
    worst_iou, worst_err = 1.0, 0.0
    for cname, K, dist in cams:
        with OverlayRenderer(K, dist, w, h) as r:
            for mname, mesh, T in meshes:
                iou, err = _iou_centroid(r.render(mesh, T)[..., 3], _coverage(mesh, T, K, dist, w, h))
                worst_iou, worst_err = min(worst_iou, iou), max(worst_err, err)
                ok = "yes" if iou >= 0.97 and err <= 0.3 else "**no**"
                rows.append(f"| {cname} | {mname} | {iou:.4f} | {err:.3f} | {ok} |")
    head = [
        "### Registration (640x480, vs cv2.projectPoints-filled silhouettes)",
        "",
        f"Goal: IoU >= 0.97 and centroid error <= 0.3 px, distortion included. Worst case here: "
        f"IoU {worst_iou:.4f}, centroid error {worst_err:.3f} px.",
        "",
    ]
    return head + rows


def _naive_pyrender(osr, mesh, T, K, znear, zfar, frame):
    """What a straightforward pyrender user writes: a new scene per frame, render, float blend."""
    import pyrender

    scene = pyrender.Scene(bg_color=[0, 0, 0, 0], ambient_light=[0.3, 0.3, 0.3])
    scene.add(pyrender.Mesh.from_trimesh(mesh, smooth=True))
    cam_pose = np.linalg.inv(T) @ np.diag([1.0, -1.0, -1.0, 1.0])  # OpenCV camera -> pyrender (GL) camera
    cam = pyrender.IntrinsicsCamera(K[0, 0], K[1, 1], K[0, 2], K[1, 2], znear=znear, zfar=zfar)
    scene.add(cam, pose=cam_pose)
    scene.add(pyrender.DirectionalLight(intensity=3.0), pose=cam_pose)
    color, _ = osr.render(scene, flags=pyrender.RenderFlags.RGBA)
    a = color[..., 3:4].astype(np.float32) / 255.0
    return (frame * (1.0 - a) + color[..., 2::-1] * a).astype(np.uint8)


class _CachedPyrender:
    """pyrender used well: scene and mesh built once, only the camera/light pose set per frame."""

    def __init__(self, mesh, K, znear, zfar):
        import pyrender

        self.scene = pyrender.Scene(bg_color=[0, 0, 0, 0], ambient_light=[0.3, 0.3, 0.3])
        self.scene.add(pyrender.Mesh.from_trimesh(mesh, smooth=True))
        cam = pyrender.IntrinsicsCamera(K[0, 0], K[1, 1], K[0, 2], K[1, 2], znear=znear, zfar=zfar)
        self.cam = self.scene.add(cam)
        self.light = self.scene.add(pyrender.DirectionalLight(intensity=3.0))

    def __call__(self, osr, T, frame):
        import pyrender

        cam_pose = np.linalg.inv(T) @ np.diag([1.0, -1.0, -1.0, 1.0])
        self.scene.set_pose(self.cam, cam_pose)
        self.scene.set_pose(self.light, cam_pose)
        color, _ = osr.render(self.scene, flags=pyrender.RenderFlags.RGBA)
        a = color[..., 3:4].astype(np.float32) / 255.0
        return (frame * (1.0 - a) + color[..., 2::-1] * a).astype(np.uint8)


def _speed(quick: bool) -> list[str]:
    import pyrender

    from arapp.render import OverlayRenderer

    load0 = os.getloadavg()[0]
    mesh = trimesh.creation.torus(0.06, 0.022, major_sections=128, minor_sections=80)  # 20,480 triangles
    n_frames = 6 if quick else 30
    rng = np.random.default_rng(3)
    frames_info = []
    rows = [
        "| resolution | renderer | median ms | min ms | CPU ms / frame | naive pyrender / this | "
        "cached pyrender / this | naive / this, CPU |",
        "|---|---|---|---|---|---|---|---|",
    ]
    results = {}
    for (w, h), f in (((1280, 720), 900.0), ((640, 480), 520.0)):
        K = np.array([[f, 0, w / 2 - 3.5], [0, f * 1.01, h / 2 + 2.5], [0, 0, 1.0]])
        dist = np.array([-0.12, 0.03, 0.0005, -0.0004, 0.0])
        poses = [
            _pose(_rot([1, 0.3 * np.sin(i), 0.2], 200 + 4 * i) , [0.01 * np.sin(0.3 * i), 0.005 * np.cos(0.2 * i), 0.42])
            for i in range(n_frames)
        ]
        frame = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
        ours = OverlayRenderer(K, None, w, h)
        ours_d = OverlayRenderer(K, dist, w, h)
        osr = pyrender.OffscreenRenderer(w, h)
        cached = _CachedPyrender(mesh, K, 0.3, 0.6)
        # warm-up (first uploads, shader compiles) on a pose not timed first, so nothing is reused
        warm = _pose(_rot([0, 1, 0], 170), [0.0, 0.0, 0.45])
        ours.draw(frame, mesh, warm)
        ours_d.draw(frame, mesh, warm)
        _naive_pyrender(osr, mesh, warm, K, 0.3, 0.6, frame)
        cached(osr, warm, frame)
        times = {"this": [], "this + distortion": [], "naive": [], "cached": []}
        cpu = {k: 0.0 for k in times}  # process CPU time (all threads: llvmpipe rasterises in its own)
        runs = {
            "this": lambda T: ours.draw(frame, mesh, T),
            "this + distortion": lambda T: ours_d.draw(frame, mesh, T),
            "naive": lambda T: _naive_pyrender(osr, mesh, T, K, 0.3, 0.6, frame),
            "cached": lambda T: cached(osr, T, frame),
        }
        for T in poses:  # interleaved so machine load hits all alike
            for k, fn in runs.items():
                c0, t0 = time.process_time(), time.perf_counter()
                fn(T)
                times[k].append(time.perf_counter() - t0)
                cpu[k] += time.process_time() - c0
        area = int((ours.render(mesh, poses[0])[..., 3] > 0).sum())
        frames_info.append(f"{w}x{h}: model covers {area} px ({100 * area / (w * h):.0f}% of the frame)")
        ours.close()
        ours_d.close()
        osr.delete()
        med = {k: 1000 * float(np.median(v)) for k, v in times.items()}
        mins = {k: 1000 * float(np.min(v)) for k, v in times.items()}
        cpus = {k: 1000 * v / len(poses) for k, v in cpu.items()}
        results[(w, h)] = med
        labels = {
            "this": "arapp OverlayRenderer.draw",
            "this + distortion": "arapp draw, lens distortion on",
            "naive": "pyrender, scene built per frame + numpy blend",
            "cached": "pyrender, scene cached + numpy blend",
        }
        for k in ("this", "this + distortion", "naive", "cached"):
            if k in ("this", "this + distortion"):
                ratio = f"{med['naive'] / med[k]:.1f}x"
                ratio_c = f"{med['cached'] / med[k]:.1f}x"
                ratio_cpu = f"{cpus['naive'] / cpus[k]:.1f}x"
            else:
                ratio = ratio_c = ratio_cpu = "-"
            rows.append(f"| {w}x{h} | {labels[k]} | {med[k]:.1f} | {mins[k]:.1f} | {cpus[k]:.1f} | {ratio} | {ratio_c} "
                        f"| {ratio_cpu} |")
    r720, r480 = results[(1280, 720)], results[(640, 480)]
    goal1 = r720["naive"] / r720["this"]
    head = [
        f"### Speed (20,480-triangle torus, {n_frames} frames with changing poses, interleaved)",
        "",
        f"Goals: draw() at 1280x720 at least 10x faster than naive pyrender (issue 29): **{goal1:.1f}x** "
        f"({'met' if goal1 >= 10 else 'not met'}); under 15 ms at 640x480: **{r480['this']:.1f} ms** median "
        f"({'met' if r480['this'] < 15 else 'not met'}).",
        "",
        "- arapp: `OverlayRenderer(K, dist, w, h).draw(frame, mesh, camera_from_model)` returning a new frame: "
        "mesh on the GPU once, only the model's pixel crop rendered (2x2 supersampled on llvmpipe, back faces "
        "of the closed mesh culled, no blending for the opaque surface, framebuffers sized to the crop), read "
        "back and composited over the crop with OpenCV's integer uint8 kernels (no float copies).",
        "- naive pyrender: per frame `pyrender.Scene` + `Mesh.from_trimesh(mesh, smooth=True)` (uploads the mesh), "
        "`IntrinsicsCamera`, a `DirectionalLight` at the camera, `OffscreenRenderer.render(scene, RGBA)` "
        "(one OffscreenRenderer reused; pyrender's default 4x MSAA, full frame, colour and depth read back), "
        "then a float32 numpy blend over the full frame.",
        "- cached pyrender: the same, but scene and mesh built once and only the camera/light poses set per frame.",
        "- " + "; ".join(frames_info) + ".",
        f"- CPU load average while measuring: {load0:.1f} before, {os.getloadavg()[0]:.1f} after, on 2 cores "
        "shared with other users: medians move by 2-3x with the load, ratios much less. CPU ms / frame: the "
        "process's CPU time (all threads) per frame, mean over the frames: the work done, which the load "
        "does not stretch.",
        "",
    ]
    return head + rows


def run(quick: bool = False) -> str:
    parts = [
        "## Render (AR overlay)",
        "",
        f"Measured on {MACHINE}. No GPU machine was available in this session, so 1280x720 and "
        "1920x1080 GPU figures are not reported.",
        "",
    ]
    parts += _registration(quick)
    parts.append("")
    parts += _speed(quick)
    parts.append("")
    return "\n".join(parts)


if __name__ == "__main__":
    import sys

    print(run(quick="--quick" in sys.argv))
