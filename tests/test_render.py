"""Overlay renderer: registration against cv2.projectPoints, display modes, compositing, GL platform errors.

References are independent of the renderer: silhouettes are every triangle of the mesh projected with
cv2.projectPoints (distortion included) and filled by OpenCV at 4x4 supersampling.
"""

import os
import subprocess
import sys
import textwrap

import cv2
import numpy as np
import pytest
import trimesh

from arapp.render import LineSet, RendererError
from arapp.render import projection
from tracking.poses import make_pose

W, H = 640, 480
K_OFFSET = np.array([[610.0, 0.0, 347.3], [0.0, 560.0, 221.8], [0.0, 0.0, 1.0]])  # fx != fy, pp off-centre
K_WIDE = np.array([[420.0, 0.0, 301.6], [0.0, 455.0, 259.4], [0.0, 0.0, 1.0]])
DIST = np.array([-0.28, 0.09, 0.0012, -0.0008, -0.012])  # a wide-ish webcam lens


def rot(axis, deg):
    return cv2.Rodrigues(np.asarray(axis, float) / np.linalg.norm(axis) * np.radians(deg))[0]


def pose(R, t):
    return make_pose(R, np.asarray(t, float))


def reference_coverage(mesh, T, K, dist, w=W, h=H, s=4):
    """Per-pixel coverage (h, w) in 0..1 of the mesh's triangles projected by cv2.projectPoints."""
    pc = mesh.vertices @ T[:3, :3].T + T[:3, 3]
    px, _ = cv2.projectPoints(pc.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, dist)
    px = px.reshape(-1, 2)
    sub = ((px + 0.5) * s - 0.5) * 16  # supersampled pixel centres, 4 fractional bits
    tri = np.round(sub[mesh.faces]).astype(np.int32)
    big = np.zeros((h * s, w * s), np.uint8)
    for t in tri:
        cv2.fillConvexPoly(big, t, 255, lineType=cv2.LINE_8, shift=4)
    return cv2.resize(big.astype(np.float32) / 255.0, (w, h), interpolation=cv2.INTER_AREA)


def iou_and_centroid_error(alpha, coverage):
    a = alpha.astype(float) / 255.0
    m1, m2 = a >= 0.5, coverage >= 0.5
    iou = (m1 & m2).sum() / max((m1 | m2).sum(), 1)
    ys, xs = np.mgrid[0:alpha.shape[0], 0:alpha.shape[1]]
    c1 = np.array([(a * xs).sum(), (a * ys).sum()]) / a.sum()
    c2 = np.array([(coverage * xs).sum(), (coverage * ys).sum()]) / coverage.sum()
    return iou, float(np.linalg.norm(c1 - c2))


def fine_box(extents):
    m = trimesh.creation.box(extents)
    for _ in range(4):  # fine enough that distorted straight edges are smooth curves
        m = m.subdivide()
    return m


SPHERE = trimesh.creation.icosphere(subdivisions=4, radius=0.05)
BOX = fine_box((0.08, 0.05, 0.03))
TORUS = trimesh.creation.torus(0.05, 0.018, major_sections=48, minor_sections=24)

CASES = [
    ("sphere", SPHERE, pose(np.eye(3), [0.03, -0.02, 0.45])),
    ("box", BOX, pose(rot([1, 0.4, 0.2], 35), [-0.05, 0.03, 0.40])),
    ("torus", TORUS, pose(rot([1, 0, 0], 60), [0.08, 0.05, 0.5])),
]


@pytest.fixture(scope="module")
def renderers():
    from arapp.render import OverlayRenderer

    rs = {
        "offset": OverlayRenderer(K_OFFSET, None, W, H),
        "wide_dist": OverlayRenderer(K_WIDE, DIST, W, H),
        "offset_dist": OverlayRenderer(K_OFFSET, DIST * 0.5, W, H),
    }
    yield rs
    for r in rs.values():
        r.close()


# -- pure projection maths (no GL) --------------------------------------------------------------

@pytest.mark.parametrize("crop", [(0, 0, W, H), (123, 57, 200, 150), (-40, -30, 720, 560)])
def test_gl_projection_matches_project_points(crop):
    rng = np.random.default_rng(1)
    T = pose(rot([0.3, 1, 0.2], 25), [0.01, 0.02, 0.6])
    pts = rng.uniform(-0.1, 0.1, (50, 3))
    near, far = projection.near_far(T, np.zeros(3), 0.2, 1e-3)
    clip = (projection.gl_projection(K_OFFSET, crop, near, far) @ projection.gl_view(T)
            @ np.c_[pts, np.ones(len(pts))].T).T
    ndc = clip[:, :3] / clip[:, 3:]
    x0, y0, w, h = crop
    u = x0 - 0.5 + (ndc[:, 0] + 1) / 2 * w
    v = y0 - 0.5 + (ndc[:, 1] + 1) / 2 * h  # NDC y runs down the image (rows come back in image order)
    ref, _ = cv2.projectPoints(pts, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], K_OFFSET, None)
    np.testing.assert_allclose(np.c_[u, v], ref.reshape(-1, 2), atol=1e-7)
    assert np.all((ndc[:, 2] > -1) & (ndc[:, 2] < 1))  # near/far enclose the points


@pytest.mark.parametrize("dist", [DIST, DIST * 0.5, np.array([0.05, -0.01, 0.001, 0.002, 0.0])])
def test_fast_distortion_map_matches_dense_solve(dist):
    from tracking.camera import Camera

    cam = Camera(K_WIDE, dist, W, H).scaled(W // 2, H // 2)  # smaller: the dense reference is slow
    ref_x, ref_y = cam.distort_maps()
    mx, my = projection.distort_maps_fast(cam)
    assert max(np.abs(mx - ref_x).max(), np.abs(my - ref_y).max()) < 0.01


# -- registration ------------------------------------------------------------------------------

@pytest.mark.parametrize("cam", ["offset", "wide_dist", "offset_dist"])
@pytest.mark.parametrize("name,mesh,T", CASES, ids=[c[0] for c in CASES])
def test_silhouette_registration(renderers, cam, name, mesh, T):
    r = renderers[cam]
    rgba = r.render(mesh, T)
    cov = reference_coverage(mesh, T, r.K, r.camera.dist)
    assert cov.sum() > 500, "test pose must show the model"
    iou, err = iou_and_centroid_error(rgba[..., 3], cov)
    assert iou >= 0.97, f"{name}/{cam}: IoU {iou:.4f}"
    assert err <= 0.3, f"{name}/{cam}: centroid error {err:.3f} px"


def test_partly_outside_image_and_behind_camera(renderers):
    r = renderers["offset"]
    # a long bar from behind the camera to the front, crossing the image border
    bar = fine_box((0.02, 0.02, 1.0))
    T = pose(np.eye(3), [0.0, 0.0, 0.3])  # spans z in [-0.2, 0.8]
    rgba = r.render(bar, T)
    assert rgba[..., 3].max() == 255
    far_only = r.render(SPHERE, pose(np.eye(3), [0, 0, -1.0]))  # entirely behind
    assert not far_only.any()
    off = r.render(SPHERE, pose(np.eye(3), [5.0, 0, 1.0]))  # far off to the side
    assert not off.any()


# -- modes and line sets ----------------------------------------------------------------------

def patch_and_lines():
    """A bumpy patch z = 0.02 sin(.) over [-0.06, 0.06]^2 and its isolines, model frame metres."""
    n = 40
    u = np.linspace(-0.06, 0.06, n)
    X, Y = np.meshgrid(u, u, indexing="ij")
    Z = 0.01 * np.sin(X * 40) * np.cos(Y * 30)
    verts = np.c_[X.ravel(), Y.ravel(), Z.ravel()]
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.r_[np.c_[a, b, c], np.c_[a, c, d]]
    mesh = trimesh.Trimesh(verts, faces, process=False)
    lines = [np.c_[X[i], Y[i], Z[i]] for i in range(0, n, 13)] + [np.c_[X[:, j], Y[:, j], Z[:, j]] for j in range(0, n, 13)]
    return mesh, lines


PATCH, ISOLINES = patch_and_lines()
T_PATCH = pose(rot([1, 0, 0], 200), [0.0, 0.0, 0.35])  # looking at the patch's +z side, tilted


def projected_samples(lines, T, K, dist, step=7):
    pts = np.concatenate([pl[1:-1:step] for pl in lines])
    px, _ = cv2.projectPoints(pts @ T[:3, :3].T + T[:3, 3], np.zeros(3), np.zeros(3), K, dist)
    return np.round(px.reshape(-1, 2)).astype(int)


@pytest.mark.parametrize("cam", ["offset", "wide_dist"])
def test_isolines_drawn_where_they_project(renderers, cam):
    r = renderers[cam]
    rgba = r.render(PATCH, T_PATCH, mode="isolines", lines=ISOLINES)
    px = projected_samples(ISOLINES, T_PATCH, r.K, r.camera.dist)
    on = rgba[px[:, 1], px[:, 0]]
    orange = (on[:, 0] > 200) & (on[:, 2] < 90) & (on[:, 3] > 200)
    assert orange.mean() > 0.95, f"only {orange.mean():.2f} of isoline samples are drawn"
    # the surface itself is faint: a point between lines has low alpha
    shaded = r.render(PATCH, T_PATCH, mode="shaded")
    faint = (rgba[..., 3] > 0) & (rgba[..., 3] < 140) & (shaded[..., 3] == 255)
    assert faint.sum() > 0.5 * (shaded[..., 3] == 255).sum()


def test_line_sets_colours_and_caching(renderers):
    r = renderers["offset"]
    perim = LineSet([ISOLINES[0], ISOLINES[1]], (255, 0, 0), width_px=3.0)
    infill = LineSet([ISOLINES[4], ISOLINES[5]], (0.0, 0.0, 1.0, 1.0), width_px=1.5)
    rgba = r.render(None, T_PATCH, line_sets=[perim, infill, ([ISOLINES[2]], (0, 255, 0), 2.0)])
    for lines, ch in (([ISOLINES[0], ISOLINES[1]], 0), ([ISOLINES[4], ISOLINES[5]], 2), ([ISOLINES[2]], 1)):
        px = projected_samples(lines, T_PATCH, r.K, None)
        hit = rgba[px[:, 1], px[:, 0]]
        others = [c for c in range(3) if c != ch]
        ok = (hit[:, ch] > 200) & (hit[:, others].max(axis=1) < 60) & (hit[:, 3] > 150)
        assert ok.mean() > 0.9, f"channel {ch}: {ok.mean():.2f}"
    frame = np.zeros((H, W, 3), np.uint8)
    drawn = r.draw_lines(frame, [perim], T_PATCH)
    px = projected_samples([ISOLINES[0], ISOLINES[1]], T_PATCH, r.K, None)
    assert (drawn[px[:, 1], px[:, 0], 2] > 200).mean() > 0.9  # red in BGR
    before = set(r._linesets)
    r.render(None, T_PATCH, line_sets=[perim, infill])
    assert set(r._linesets) == before and id(perim) in before  # uploaded once, reused


def test_wireframe_and_translucent(renderers):
    r = renderers["offset"]
    shaded = r.render(SPHERE, CASES[0][2], mode="shaded")
    inside = shaded[..., 3] == 255
    wire = r.render(SPHERE, CASES[0][2], mode="wireframe")
    green = (wire[..., 1] > 150) & (wire[..., 0] < 120) & (wire[..., 3] > 100)
    assert green[inside].mean() > 0.2  # the edge network covers the silhouette's inside
    assert (wire[..., 3][inside] < 100).mean() > 0.05  # and leaves faint gaps between edges
    trans = r.render(SPHERE, CASES[0][2], mode="translucent")
    a = trans[..., 3][inside].astype(float)
    assert abs(np.median(a) - 0.45 * 255) < 3  # one layer only (no double blending of the back faces)
    # headlight: the sphere's centre (facing the camera) is brighter than near its rim
    c = np.round(cv2.projectPoints(np.zeros((1, 3)), np.zeros(3), CASES[0][2][:3, 3], r.K, None)[0].ravel()).astype(int)
    ys, xs = np.nonzero(inside)
    rim = np.argmax(xs)
    assert int(shaded[c[1], c[0], :3].sum()) > int(shaded[ys[rim], xs[rim] - 2, :3].sum()) + 60


def test_contact_shadow_on_anchor_plane(renderers):
    r = renderers["offset"]
    cube = trimesh.creation.box((0.04, 0.04, 0.04))
    cube.apply_translation([0, 0, 0.02])  # resting on z = 0
    T = pose(rot([1, 0, 0], 210), [0.0, 0.02, 0.4])
    plain = r.render(cube, T)
    shadowed = r.render(cube, T, shadow=True)
    extra = (shadowed[..., 3] > 10) & (plain[..., 3] == 0)
    assert extra.sum() > 200
    assert shadowed[..., :3][extra].max() <= 1  # black, partly transparent
    assert shadowed[..., 3][extra].max() < 200


# -- compositing -------------------------------------------------------------------------------

@pytest.mark.parametrize("cam", ["offset", "wide_dist"])
def test_draw_composites_only_inside_overlay(renderers, cam):
    r = renderers[cam]
    rng = np.random.default_rng(7)
    frame = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    name, mesh, T = CASES[1]
    original = frame.copy()
    rgba = r.render(mesh, T, mode="translucent")
    out = r.draw(frame, mesh, T, mode="translucent")
    assert out is not frame and np.array_equal(frame, original)  # the input frame is not modified
    a = rgba[..., 3]
    assert np.array_equal(out[a == 0], frame[a == 0])
    sel = a > 0
    fg = rgba[..., 2::-1][sel].astype(float)
    alpha = a[sel].astype(float)[:, None] / 255
    expected = fg * alpha + frame[sel] * (1 - alpha)
    assert np.abs(out[sel] - expected).max() <= 2.0
    inplace = frame.copy()
    r.draw(inplace, mesh, T, mode="translucent", inplace=True)
    assert np.array_equal(inplace, out)


def test_mesh_cache_follows_edits(renderers):
    r = renderers["offset"]
    m = SPHERE.copy()
    T = CASES[0][2]
    a1 = r.render(m, T)[..., 3]
    n = len(r._meshes)
    r.render(m, T)
    assert len(r._meshes) == n  # same mesh, same GPU copy
    m.vertices = m.vertices + [0.02, 0, 0]  # edit in place: the GPU copy must follow
    a2 = r.render(m, T)[..., 3]
    cov = reference_coverage(m, T, r.K, None)
    assert iou_and_centroid_error(a2, cov)[0] >= 0.97
    assert not np.array_equal(a1, a2)


def test_bad_arguments(renderers):
    r = renderers["offset"]
    with pytest.raises(ValueError, match="display mode"):
        r.render(SPHERE, np.eye(4), mode="glossy")
    with pytest.raises(ValueError, match="4x4"):
        r.render(SPHERE, np.eye(3))
    with pytest.raises(RendererError, match="frame must be"):
        r.draw(np.zeros((10, 10, 3), np.uint8), SPHERE, np.eye(4))
    with pytest.raises(ValueError, match=r"\(k, 3\)"):
        LineSet([np.zeros((4, 2))]).segments()


# -- GL platform -------------------------------------------------------------------------------

def _run_isolated(code: str, env_extra: dict, drop_platform: bool = False):
    env = dict(os.environ, **env_extra)
    if drop_platform:
        env.pop("PYOPENGL_PLATFORM", None)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=env, capture_output=True,
                          text=True, timeout=60, cwd=root)


CREATE = """
    import numpy as np
    from arapp.render import OverlayRenderer, RendererError
    try:
        OverlayRenderer(np.array([[500, 0, 320], [0, 500, 240], [0, 0, 1.0]]), None, 640, 480)
    except RendererError as e:
        print("RendererError:", e)
    else:
        print("created")
"""


def test_invalid_platform_names_the_packages():
    res = _run_isolated(CREATE, {"PYOPENGL_PLATFORM": "nosuchgl"})
    assert "RendererError:" in res.stdout, res.stdout + res.stderr
    assert "nosuchgl" in res.stdout and "libegl1" in res.stdout and "libosmesa6" in res.stdout


def test_no_gl_library_names_the_packages():
    # simulate a machine without libEGL and libOSMesa: the library lookup finds nothing
    code = "import ctypes.util\nctypes.util.find_library = lambda name: None\n" + textwrap.dedent(CREATE)
    res = _run_isolated(code, {}, drop_platform=True)
    assert "RendererError: no offscreen OpenGL platform works" in res.stdout, res.stdout + res.stderr
    assert "libegl1" in res.stdout and "libgl1-mesa-dri" in res.stdout


def test_platform_chosen_automatically():
    res = _run_isolated(CREATE.replace('print("created")', 'import os; print("created", os.environ["PYOPENGL_PLATFORM"])'),
                        {}, drop_platform=True)
    assert "created egl" in res.stdout or "created osmesa" in res.stdout, res.stdout + res.stderr


def test_survives_pyrender_terminating_the_egl_display(renderers):
    # pyrender's OffscreenRenderer.delete() calls eglTerminate on the display all EGL contexts share
    import pyrender

    r = renderers["offset"]
    name, mesh, T = CASES[0]
    before = r.render(mesh, T)
    r.render(mesh, CASES[1][2])  # so the next call cannot reuse the last result
    other = pyrender.OffscreenRenderer(64, 64)
    other.delete()
    after = r.render(mesh, T)
    assert np.array_equal(before, after)


def test_unchanged_frame_is_not_rendered_again(renderers, monkeypatch):
    r = renderers["offset"]
    name, mesh, T = CASES[2]
    calls = []
    real = r._render_crop_gl
    monkeypatch.setattr(r, "_render_crop_gl", lambda *a: calls.append(1) or real(*a))
    ls = LineSet(ISOLINES[:2], (255, 0, 0))
    first = r.render(mesh, T, line_sets=[ls])
    again = r.render(mesh, T, line_sets=[ls])
    assert len(calls) == 1 and np.array_equal(first, again)
    T2 = T.copy()
    T2[0, 3] += 0.01
    moved = r.render(mesh, T2, line_sets=[ls])
    assert len(calls) == 2 and not np.array_equal(first, moved)
    r.render(mesh, T2, line_sets=[ls], mode="translucent")
    assert len(calls) == 3
    # isolines given as the same arrays each frame: cached as line sets, so also not redrawn
    iso = r.render(PATCH, T_PATCH, mode="isolines", lines=ISOLINES)
    assert np.array_equal(iso, r.render(PATCH, T_PATCH, mode="isolines", lines=list(ISOLINES)))
    assert len(calls) == 4
    shifted = [p + [0.0, 0.0, 0.01] for p in ISOLINES]  # new arrays: drawn again
    assert not np.array_equal(iso, r.render(PATCH, T_PATCH, mode="isolines", lines=shifted))
    assert len(calls) == 5


def test_lines_with_their_own_colours(renderers):
    r = renderers["offset"]
    rgba = r.render(PATCH, T_PATCH, mode="isolines", lines=[(ISOLINES[0], (0, 255, 255)), (ISOLINES[4], (255, 0, 255))])
    for pl, want in ((ISOLINES[0], (0, 255, 255)), (ISOLINES[4], (255, 0, 255))):
        px = projected_samples([pl], T_PATCH, r.K, None)
        hit = rgba[px[:, 1], px[:, 0], :3].astype(int)
        assert (np.abs(hit - want).max(axis=1) < 40).mean() > 0.9


def test_osmesa_fallback_when_egl_fails(renderers, tmp_path):
    # EGL made to fail its probe: the renderer must fall back to OSMesa and draw the same overlay
    out = tmp_path / "alpha.npy"
    code = f"""
        import numpy as np, trimesh
        import arapp.render.gl as gl
        gl._egl_initialises = lambda: False
        from arapp.render import OverlayRenderer
        K = np.array({K_OFFSET.tolist()})
        T = np.array({CASES[0][2].tolist()})
        with OverlayRenderer(K, None, {W}, {H}) as r:
            np.save({str(out)!r}, r.render(trimesh.creation.icosphere(subdivisions=4, radius=0.05), T)[..., 3])
            print("platform", r.platform_name)
    """
    res = _run_isolated(code, {"PYOPENGL_PLATFORM": "egl"})  # as the Makefile sets it
    assert "platform osmesa" in res.stdout, res.stdout + res.stderr
    alpha = np.load(out)
    ref = reference_coverage(SPHERE, CASES[0][2], K_OFFSET, None)
    iou, err = iou_and_centroid_error(alpha, ref)
    assert iou >= 0.97 and err <= 0.3


@pytest.mark.parametrize("width_px", [1.0, 3.0, 6.0])
def test_line_width_in_pixels(renderers, width_px):
    r = renderers["offset"]
    # a line across the view at constant depth, parallel to the image rows
    T = pose(np.eye(3), [0.0, 0.0, 0.5])
    line = np.array([[-0.1, 0.0, 0.0], [0.1, 0.0, 0.0]])
    a = r.render(None, T, line_sets=[LineSet([line], (255, 255, 255), width_px)])[..., 3].astype(float) / 255
    v = cv2.projectPoints(np.zeros((1, 3)), np.zeros(3), T[:3, 3], r.K, None)[0].ravel()[1]
    column = a[:, 300]
    assert abs(column.sum() - width_px) < 0.15  # coverage integrates to the width
    rows = np.arange(H)
    assert abs((column * rows).sum() / column.sum() - v) < 0.3  # centred on the projected line (2x2 SSAA: 1/4 px steps)


def test_line_from_behind_the_camera_is_clipped(renderers):
    r = renderers["offset"]
    T = pose(np.eye(3), [0.0, 0.0, 0.0])
    line = np.array([[0.05, 0.02, -0.5], [0.05, 0.02, 1.0]])  # starts behind the camera
    a = r.render(None, T, line_sets=[LineSet([line], (255, 255, 255), 2.0)])[..., 3]
    ys, xs = np.nonzero(a > 127)
    assert len(xs) > 50
    # every drawn pixel lies on the projection of the visible part (0 < z <= 1): the image ray from
    # the projection of the far end away from the vanishing point, not on the mirrored side
    ends = cv2.projectPoints(np.array([[0.05, 0.02, 1.0], [0.05, 0.02, 0.1]]), np.zeros(3), np.zeros(3), r.K, None)[0]
    p0, p1 = ends.reshape(2, 2)
    d = (p1 - p0) / np.linalg.norm(p1 - p0)
    rel = np.c_[xs, ys] - p0
    assert np.abs(rel[:, 0] * d[1] - rel[:, 1] * d[0]).max() < 2.0  # distance to the line
    assert (rel @ d).min() > -2.0  # and only beyond the far end's projection


def test_msaa_path_registers_too():
    from arapp.render import OverlayRenderer

    name, mesh, T = CASES[2]
    with OverlayRenderer(K_OFFSET, DIST * 0.5, W, H, antialias="msaa") as r:
        assert r.samples >= 2
        iou, err = iou_and_centroid_error(r.render(mesh, T)[..., 3], reference_coverage(mesh, T, K_OFFSET, DIST * 0.5))
    assert iou >= 0.97 and err <= 0.3


def test_back_face_culling_changes_no_pixel(renderers):
    # culling is only a speed-up: a closed mesh must look exactly the same with it off
    r = renderers["offset"]
    name, mesh, T = CASES[2]  # torus: self-occluding
    culled = r.render(mesh, T)
    r.cull = False
    try:
        r._memo = None
        full = r.render(mesh, T)
    finally:
        r.cull = True
    assert r._gpu_mesh(mesh).closed
    diff = np.abs(culled.astype(int) - full.astype(int)).max(axis=2)
    covered = (culled[..., 3] > 0) | (full[..., 3] > 0)
    # identical but for a few silhouette pixels where a grazing back face takes one of the 4 sub-samples
    assert (diff > 8).sum() <= 0.005 * covered.sum()
    assert np.abs(culled[..., 3].astype(int) - full[..., 3]).max() <= 65
