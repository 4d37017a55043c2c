"""The preview renderer (pdsim/preview/, ``pdsim preview``): images of caches of every method, silhouettes
where the geometry projects through the camera, animations with one image per frame, colouring by an attribute, and
one-line errors with exit status 1.

The caches are made with pdsim itself (a few frames of a small scene per method) and read back only through
``pxr.Usd.Stage.Open``, as the renderer reads them.
"""

import subprocess
import sys

import numpy as np
import pytest

import pdsim
from pdsim.output.usd_files import world_points

BACKGROUND = np.array([round(255 * c) for c in (0.95, 0.96, 0.97)])


def _pd_plate(path):
    """A notched PD plate (24 x 10 x 2 particles, h = 2.5 mm) pulled apart at its ends: cracks and damage by frame 3;
    one prim per fragment, and a ground plane 1 cm below (written as the quad /World/ground, which the preview
    replaces by its own ground)."""
    scene = pdsim.Scene(fps=24.0, frames=3, gravity=(0.0, 0.0, 0.0), name="plate")
    h = 2.5e-3
    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.25, critical_stretch=5.0e-3)
    body = scene.add_peridynamic_body(pdsim.box((24 * h, 10 * h, 2 * h)), mat, h, name="plate")
    body.add_notch(pdsim.BoxRegion(lo=(-1.0e-4, -1.0, -1.0), hi=(1.0e-4, 0.0, 1.0)))
    x = body.rest_positions[:, 0]
    ramp = pdsim.TimeCurve.ramp(2.0e-4)
    body.set_velocity(
        pdsim.BoxRegion(lo=(-1, -1, -1), hi=(x.min() + 0.5 * h, 1, 1)), (-0.2, 0, 0), axes="x", curve=ramp
    )
    body.set_velocity(pdsim.BoxRegion(lo=(x.max() - 0.5 * h, -1, -1), hi=(1, 1, 1)), (0.2, 0, 0), axes="x", curve=ramp)
    scene.add_ground_plane(height=-0.01)
    scene.run(path, progress=False, device="cpu", fragments_as_prims=True)


def _fem_bar(path):
    """An FEM bar of 8 x 2 x 2 cubes (6 tetrahedra each), its ends pulled apart at 0.2 m/s."""
    scene = pdsim.Scene(fps=24.0, frames=3, gravity=(0.0, 0.0, 0.0), name="bar")
    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)
    body = scene.add_body(pdsim.FemBody(pdsim.box_tet_mesh((0.08, 0.02, 0.02), (8, 2, 2)), mat, name="bar"))
    body.set_velocity(pdsim.BoxRegion(lo=(-1.0, -1.0, -1.0), hi=(-0.0399, 1.0, 1.0)), (-0.2, 0.0, 0.0))
    body.set_velocity(pdsim.BoxRegion(lo=(0.0399, -1.0, -1.0), hi=(1.0, 1.0, 1.0)), (0.2, 0.0, 0.0))
    scene.run(path, progress=False, device="cpu")


def _lattice_block(path):
    """A 12 x 5 x 3 simple-cubic lattice (spacing 1 cm), left layer clamped, right layer pulled: points only."""
    from pdsim.lattice import Lattice, LatticeBody, LatticeFracture

    scene = pdsim.Scene(fps=24.0, frames=3, name="lattice")
    h = 0.01
    body = LatticeBody.block(Lattice.simple_cubic(h), (12, 5, 3), name="block", fracture=LatticeFracture((1.6 * h,)))
    x = body.rest_positions[: body.body_count, 0]
    body.clamp(x < x.min() + 0.5 * h)
    body.add_leaders(x > x.max() - 0.5 * h, velocity=(0.35 * h, 0.0, 0.0), stop_step=10)
    scene.add_body(body)
    scene.run(path, progress=False, device="cpu")


BUILDERS = {"peridynamics": _pd_plate, "fem": _fem_bar, "lattice": _lattice_block}


@pytest.fixture(scope="module")
def caches(tmp_path_factory):
    """{method: path of a 4-frame cache (frames 0..3)}, built on first use."""
    folder = tmp_path_factory.mktemp("preview")
    built = {}

    def get(method):
        if method not in built:
            path = str(folder / f"{method}.usdc")
            BUILDERS[method](path)
            built[method] = path
        return built[method]

    return get


def _frame_box(path, frame):
    """Bounding box [m] of what the preview draws at a frame by default, read through Usd.Stage.Open: the points of
    the visible meshes but the ground quad, and the points (grown by half their widths) of Points prims without a
    ``<name>_surface`` prim beside them."""
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(path)
    boxes = []
    prims = list(stage.Traverse())
    names = {p.GetPath() for p in prims}
    for prim in prims:
        if prim.GetName() == "ground" or not prim.IsA(UsdGeom.Imageable):
            continue
        if UsdGeom.Imageable(prim).ComputeVisibility(frame) == UsdGeom.Tokens.invisible:
            continue
        if prim.IsA(UsdGeom.Mesh):
            p = world_points(prim, frame)
            r = 0.0
        elif prim.IsA(UsdGeom.Points):
            if prim.GetPath().AppendPath("../" + prim.GetName() + "_surface") in names:
                continue
            p = world_points(prim, frame)
            r = 0.5 * float(np.max(UsdGeom.Points(prim).GetWidthsAttr().Get(frame)))
        else:
            continue
        if len(p) == 0:
            continue
        boxes.append((p.min(axis=0) - r, p.max(axis=0) + r))
    return np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)


def _points(path, frame):
    """(positions [n, 3], radius) of the lattice block's points at a frame."""
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(path)
    (points,) = [UsdGeom.Points(p) for p in stage.Traverse() if p.IsA(UsdGeom.Points)]
    return world_points(points.GetPrim(), frame), 0.5 * float(points.GetWidthsAttr().Get(frame)[0])


def _object_mask(image):
    """Pixels that differ from the plain background (renders with ground=False)."""
    return np.abs(image.astype(int) - BACKGROUND).max(axis=2) > 6


def _corners(lo, hi):
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def _hull(xy):
    """(area [px^2], centroid [2]) of the convex hull of 2D points."""
    from scipy.spatial import ConvexHull

    p = xy[ConvexHull(xy).vertices]  # counter-clockwise
    q = np.roll(p, -1, axis=0)
    cross = p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]
    area = 0.5 * cross.sum()
    return area, ((p + q) * cross[:, None]).sum(axis=0) / (6.0 * area)


@pytest.mark.parametrize("method", list(BUILDERS))
def test_silhouette_lies_where_the_geometry_projects(caches, method):
    """Frames 0 and 3 of each method's cache, no ground: the object pixels (those that differ from the background)
    are many and all lie inside the projected bounding box of that frame's geometry, grown by 2 px. At the rest pose
    of the PD plate and the FEM bar (boxes) the object pixels' centroid is within 0.5 px of the centroid of the convex
    hull of the 8 projected corners and their area within 1 % of the hull's (a box's silhouette is that hull). The
    lattice's object pixels span the rectangle of its projected spheres to 2 px."""
    from pdsim.preview import render_cache

    path = caches(method)
    result = render_cache(path, "0:4:3", ground=False, size=(320, 240))
    assert result.frames == [0, 3]
    cam = result.camera
    for frame, image in zip(result.frames, result.images):
        assert image.shape == (240, 320, 3) and image.dtype == np.uint8
        mask = _object_mask(image)
        assert mask.sum() > 200, f"{method} frame {frame}: blank image"
        lo, hi = _frame_box(path, frame)
        xy, depth = cam.project(_corners(lo, hi))
        assert (depth > 0).all()
        rows, cols = np.nonzero(mask)
        cx, cy = cols + 0.5, rows + 0.5
        assert cx.min() >= xy[:, 0].min() - 2 and cx.max() <= xy[:, 0].max() + 2, (method, frame)
        assert cy.min() >= xy[:, 1].min() - 2 and cy.max() <= xy[:, 1].max() + 2, (method, frame)
        if method == "lattice":  # spheres: the object's pixel rectangle is that of the projected discs
            centres, radius = _points(path, frame)
            c, d = cam.project(centres)
            r = radius / d / cam.tan_half[1] * (0.5 * cam.height)
            rect = np.array([(c[:, 0] - r).min(), (c[:, 1] - r).min(), (c[:, 0] + r).max(), (c[:, 1] + r).max()])
            got = np.array([cols.min(), rows.min(), cols.max() + 1, rows.max() + 1])
            np.testing.assert_allclose(got, rect, atol=2.0, err_msg=f"frame {frame}")
        elif frame == 0:  # a box: its silhouette is the convex hull of its projected corners
            area, centre = _hull(xy)
            assert np.hypot(cx.mean() - centre[0], cy.mean() - centre[1]) < 0.5, method
            assert abs(mask.sum() / area - 1.0) < 0.01, method


def _cli(*args, cwd=None):
    """Runs ``python -m pdsim.cli preview ARGS``: (exit status, stdout, stderr)."""
    p = subprocess.run(
        [sys.executable, "-m", "pdsim.cli", "preview", *map(str, args)],
        capture_output=True,
        text=True,
        check=False,
        cwd=cwd,
    )
    return p.returncode, p.stdout, p.stderr


def test_animations_have_one_image_per_requested_frame(caches, tmp_path):
    """`--frames 1:3` gives a 2-image GIF (B exclusive); an MP4 of all frames has 4 images (frames 0..3); the images
    have the requested size."""
    import imageio.v2 as iio2
    import imageio.v3 as iio

    path = caches("fem")
    code, out, err = _cli(path, "--out", tmp_path / "a.gif", "--frames", "1:3", "--size", "160x120")
    assert code == 0, err
    assert "2 frames (1..2)" in out
    gif = iio.imread(tmp_path / "a.gif", index=None)
    assert gif.shape[:3] == (2, 120, 160)
    code, _, err = _cli(path, "--out", tmp_path / "a.mp4", "--size", "160x120")
    assert code == 0, err
    reader = iio2.get_reader(tmp_path / "a.mp4", format="FFMPEG")
    frames = [image for image in reader]  # noqa: C416 (list(reader) fails: the reader's len() is inf)
    reader.close()
    assert len(frames) == 4 and frames[0].shape[:2] == (120, 160)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.gif", "a.mp4"]  # no temporary files left


def test_png_still_is_the_last_frame_by_default(caches, tmp_path):
    """`pdsim preview CACHE --out x.png` renders the last frame: the PNG equals the library's render of frame 3."""
    import imageio.v3 as iio

    from pdsim.preview import render_cache

    path = caches("peridynamics")
    code, out, err = _cli(path, "--out", tmp_path / "x.png", "--size", "200x150")
    assert code == 0, err
    assert "frame 3" in out
    png = iio.imread(tmp_path / "x.png")
    expected = render_cache(path, [3], size=(200, 150)).images[0]
    np.testing.assert_array_equal(png[..., :3], expected)


def test_color_by_damage_and_crack_faces(caches):
    """The PD plate at frame 3 (cracked): by default crack faces show in the orange interior colour (none at the
    rest pose); `color="damage"` (a primvar of the particles, carried onto the surface) changes the object's colours
    and spans a non-empty range."""
    from pdsim.preview import render_cache

    path = caches("peridynamics")
    plain = render_cache(path, "0:4:3", ground=False, size=(320, 240))
    orange = [((im[..., 0].astype(int) - im[..., 2]) > 80).sum() for im in plain.images]
    assert orange[0] == 0 and orange[1] > 20, orange
    damage = render_cache(path, [3], color="damage", ground=False, size=(320, 240))
    lo, hi = damage.color_range
    assert lo == 0.0 and hi > 0.1
    mask = _object_mask(plain.images[1]) & _object_mask(damage.images[0])
    diff = np.abs(plain.images[1].astype(int) - damage.images[0]).max(axis=2)[mask]
    assert mask.sum() > 200 and np.median(diff) > 30


def _authored_cube(path):
    """A Y-up stage: a unit cube of 6 quads under an Xform (translate (5, 1, -2), scale 2), a uniform primvar
    ``heat`` = face index and a GeomSubset ``crack`` holding the top face (+y)."""
    from pxr import Gf, Usd, UsdGeom, Vt

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    xf = UsdGeom.Xform.Define(stage, "/World")
    xf.AddTranslateOp().Set(Gf.Vec3d(5.0, 1.0, -2.0))
    xf.AddScaleOp().Set(Gf.Vec3f(2.0, 2.0, 2.0))
    mesh = UsdGeom.Mesh.Define(stage, "/World/cube")
    pts = [(x, y, z) for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]
    faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]  # -x +x -y +y -z +z
    mesh.GetPointsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*p) for p in pts]))
    mesh.GetFaceVertexCountsAttr().Set([4] * 6)
    mesh.GetFaceVertexIndicesAttr().Set([i for f in faces for i in f])
    pv = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("heat", Sdf_float_array(), UsdGeom.Tokens.uniform)
    pv.Set([0.0, 1.0, 2.0, 3.0, 4.0, 5.0])
    UsdGeom.Subset.CreateGeomSubset(mesh, "crack", UsdGeom.Tokens.face, Vt.IntArray([3]))
    stage.GetRootLayer().Save()
    lo, hi = np.array([4.0, 0.0, -3.0]), np.array([6.0, 2.0, -1.0])
    return lo, hi


def Sdf_float_array():
    from pxr import Sdf

    return Sdf.ValueTypeNames.FloatArray


def test_quads_transforms_y_up_subsets_and_face_colours(tmp_path):
    """A hand-written Y-up stage (quads, a scaled and translated parent, a ``crack`` GeomSubset, a uniform float
    primvar): the cube's silhouette is the hull of its projected world-space corners (0.5 px, 1 %), the crack subset
    (the top face) shows orange, and `color="heat"` gives the three visible faces three different colours."""
    from pdsim.preview import render_cache

    path = tmp_path / "cube.usda"
    lo, hi = _authored_cube(path)
    plain = render_cache(path, ground=False, size=(320, 240))
    np.testing.assert_allclose(np.concatenate(plain.bounds), np.concatenate([lo, hi]), atol=1e-6)
    np.testing.assert_allclose(plain.camera.up, [0.0, 1.0, 0.0])
    image = plain.images[0]
    mask = _object_mask(image)
    rows, cols = np.nonzero(mask)
    xy, _ = plain.camera.project(_corners(lo, hi))
    area, centre = _hull(xy)
    assert np.hypot((cols + 0.5).mean() - centre[0], (rows + 0.5).mean() - centre[1]) < 0.5
    assert abs(mask.sum() / area - 1.0) < 0.01
    top = image[int(xy[:, 1].min()) + 8, int(centre[0])]  # just below the topmost corner: the top face
    assert top[0] - top[2] > 80, top
    heat = render_cache(path, ground=False, size=(320, 240), color="heat").images[0]
    colours = {tuple(int(c) // 16 for c in px) for px in heat[mask]}
    assert len(colours) >= 3
    assert heat[mask].std(axis=0).max() > 20


def test_camera_specs():
    """--camera: 'AZ,EL,DIST' puts the eye DIST from the box centre at that azimuth/elevation about the up axis;
    'AZ,EL' fits the distance so that every box corner projects inside the image; 'eye=...:target=...' is taken
    as given."""
    from pdsim.preview import camera_from_spec

    lo, hi, up = np.array([-1.0, -0.5, 0.0]), np.array([1.0, 0.5, 0.4]), np.array([0.0, 0.0, 1.0])
    cam = camera_from_spec("30,20,5", lo, hi, up, (640, 480))
    d = (cam.eye - cam.target) / 5.0
    np.testing.assert_allclose(cam.target, 0.5 * (lo + hi))
    np.testing.assert_allclose(np.linalg.norm(cam.eye - cam.target), 5.0)
    np.testing.assert_allclose(
        d,
        [
            np.cos(np.radians(20)) * np.cos(np.radians(30)),
            np.cos(np.radians(20)) * np.sin(np.radians(30)),
            np.sin(np.radians(20)),
        ],
        atol=1e-12,
    )
    for spec in (None, "-60,25", "120,-10", "0,80"):
        cam = camera_from_spec(spec, lo, hi, up, (640, 480))
        xy, depth = cam.project(_corners(lo, hi))
        assert (depth > 0).all() and (xy >= 0).all() and (xy[:, 0] <= 640).all() and (xy[:, 1] <= 480).all(), spec
        assert max(np.ptp(xy[:, 0]) / 640, np.ptp(xy[:, 1]) / 480) > 0.8, spec  # fitted, not tiny
    cam = camera_from_spec("eye=3,-4,2:target=0,0,0.2", lo, hi, up, (320, 240))
    np.testing.assert_allclose(cam.eye, [3, -4, 2])
    np.testing.assert_allclose(cam.target, [0, 0, 0.2])
    xy, _ = cam.project(np.array([[0.0, 0.0, 0.2]]))
    np.testing.assert_allclose(xy[0], [160.0, 120.0])


def test_camera_image_up_is_continuous_towards_the_pole():
    """Raising the elevation towards 90 degrees keeps the image's orientation: the horizontal part of the image's
    up vector points the same way (within 1 degree) at elevations 85 to 89.9, for any azimuth (it used to jump to an
    arbitrary horizontal direction beyond 87.4 degrees); it always points towards the stage's up as seen from the
    eye."""
    from pdsim.preview import camera_from_spec

    lo, hi, up = np.array([-1.0, -0.5, 0.0]), np.array([1.0, 0.5, 0.4]), np.array([0.0, 0.0, 1.0])
    for azimuth in (-90.0, 0.0, 37.0, 180.0):
        ups = []
        for elevation in (85.0, 88.0, 89.0, 89.9):
            f, r, u = camera_from_spec(f"{azimuth},{elevation},5", lo, hi, up, (320, 240)).basis()
            assert u @ up > 0.0 and abs(u @ f) < 1e-12 and abs(r @ up) < 1e-9
            flat = u - (u @ up) * up
            ups.append(flat / np.linalg.norm(flat))
        assert all(np.degrees(np.arccos(np.clip(ups[0] @ w, -1.0, 1.0))) < 1.0 for w in ups), azimuth


def test_frames_spec():
    """--frames: N, A:B (B exclusive), steps, open ends and negative values like Python slices; out of range or
    empty raises ParameterError naming frames."""
    from pdsim.preview import parse_frames

    frames = list(range(11))
    assert parse_frames("3", frames) == [3]
    assert parse_frames("2:5", frames) == [2, 3, 4]
    assert parse_frames("0:11:5", frames) == [0, 5, 10]
    assert parse_frames(":", frames) == frames
    assert parse_frames("-1", frames) == [10]
    assert parse_frames("-3:", frames) == [8, 9, 10]
    assert parse_frames(None, frames) == frames
    assert parse_frames(None, frames, default="last") == [10]
    for bad in ("11", "0:12", "5:5", "6:2", "a:b", "1:2:0", "1:2:3:4", "-12"):
        with pytest.raises(pdsim.ParameterError, match="frames="):
            parse_frames(bad, frames)


ERRORS = {
    "missing cache": (["{tmp}/nope.usdc", "--out", "{tmp}/x.png"], "cache="),
    "unreadable cache": (["{tmp}/garbage.usdc", "--out", "{tmp}/x.png"], "cache="),
    "unknown attribute": (["{cache}", "--out", "{tmp}/x.png", "--color", "nosuch"], "color='nosuch'"),
    "frames out of range": (["{cache}", "--out", "{tmp}/x.gif", "--frames", "2:9"], "frames='2:9'"),
    "empty frames": (["{cache}", "--out", "{tmp}/x.gif", "--frames", "3:1"], "frames='3:1'"),
    "several frames for a png": (["{cache}", "--out", "{tmp}/x.png", "--frames", "0:2"], "frames='0:2'"),
    "bad camera": (["{cache}", "--out", "{tmp}/x.png", "--camera", "up,left"], "camera='up,left'"),
    "camera elevation": (["{cache}", "--out", "{tmp}/x.png", "--camera", "10,90"], "camera='10,90'"),
    "camera eye at target": (["{cache}", "--out", "{tmp}/x.png", "--camera", "eye=1,1,1:target=1,1,1"], "camera="),
    "unknown suffix": (["{cache}", "--out", "{tmp}/x.jpg"], "out="),
    "no output": (["{cache}"], "out="),
    "bad size": (["{cache}", "--out", "{tmp}/x.png", "--size", "640by480"], "size="),
    "odd mp4 size": (["{cache}", "--out", "{tmp}/x.mp4", "--size", "161x120"], "size="),
}


@pytest.mark.parametrize("case", list(ERRORS))
def test_errors_are_one_line_with_exit_status_1(caches, tmp_path, case):
    """Each user mistake exits with status 1 and one stderr line `pdsim: error: FIELD=... is invalid: allowed ...`,
    and writes nothing."""
    (tmp_path / "garbage.usdc").write_bytes(b"not a USD file\n")
    args, field = ERRORS[case]
    args = [a.format(tmp=tmp_path, cache=caches("fem")) for a in args]
    code, out, err = _cli(*args)
    assert code == 1, (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("pdsim: error: ") and field in lines[0] and "allowed" in lines[0], lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["garbage.usdc"]


def test_fit_and_points_options_and_the_tool_wrapper(caches, tmp_path):
    """`fit="first"` frames the rest pose (the fitted box is frame 0's); `points="all"` adds the FEM body's points
    as spheres to its surface (more object pixels than the default, which leaves them out); tools/preview_cache.py
    runs `pdsim preview`."""
    import preview_cache

    from pdsim.preview import render_cache

    path = caches("fem")
    first = render_cache(path, [3], fit="first", ground=False, size=(160, 120))
    np.testing.assert_allclose(np.concatenate(first.bounds), np.concatenate(_frame_box(path, 0)), atol=1e-6)
    cam = first.camera
    auto = render_cache(path, [0], camera=cam, ground=False)
    spheres = render_cache(path, [0], camera=cam, ground=False, points="all")
    assert _object_mask(spheres.images[0]).sum() > 1.05 * _object_mask(auto.images[0]).sum()
    assert preview_cache.main([path, "--out", str(tmp_path / "t.png"), "--size", "64x48"]) == 0
    assert (tmp_path / "t.png").is_file()
