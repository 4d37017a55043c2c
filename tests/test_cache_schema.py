"""One cache schema for the three methods (docs/cache_format.md): prim layout, attribute names, interpolation, units
and time metadata of small peridynamic, FEM and lattice caches; velocities and normals on every mesh sample;
colliders, projectiles and the ground in the cache; simulated time per frame (slow motion, microsecond events)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pdsim
from pdsim.lattice import Lattice, LatticeBody, LatticeFracture
from pdsim.output.usd_files import usd_problems
from pdsim.output.views import ATTRIBUTES

FRAMES = 2
MAT = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.25, critical_stretch=5.0e-3)
FEM_MAT = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)


def _pd_scene(**kwargs):
    """A peridynamic box of 8 x 4 x 4 particles (h = 1 cm) pulled apart by its end layers: it breaks."""
    scene = pdsim.Scene(fps=24.0, frames=FRAMES, gravity=(0.0, 0.0, 0.0), name="pd", **kwargs)
    body = scene.add_peridynamic_body(pdsim.box((0.08, 0.04, 0.04)), MAT, 0.01, name="block")
    body.set_velocity(pdsim.BoxRegion(lo=(-1, -1, -1), hi=(-0.03, 1, 1)), (-2.0, 0.0, 0.0), axes="x", name="left")
    body.set_velocity(pdsim.BoxRegion(lo=(0.03, -1, -1), hi=(1, 1, 1)), (2.0, 0.0, 0.0), axes="x", name="right")
    return scene


def _fem_scene(**kwargs):
    """An FEM bar of 8 x 2 x 2 cubes (box_tet_mesh) pulled apart at its ends until elements split."""
    scene = pdsim.Scene(fps=24.0, frames=FRAMES, gravity=(0.0, 0.0, 0.0), name="fem", **kwargs)
    mesh = pdsim.box_tet_mesh((0.08, 0.02, 0.02), (8, 2, 2))
    body = scene.add_body(pdsim.FemBody(mesh, FEM_MAT, tensile_strength=2.0e3, name="bar"))
    body.set_velocity(pdsim.BoxRegion(lo=(-1.0, -1.0, -1.0), hi=(-0.0399, 1.0, 1.0)), (-0.5, 0.0, 0.0))
    body.set_velocity(pdsim.BoxRegion(lo=(0.0399, -1.0, -1.0), hi=(1.0, 1.0, 1.0)), (0.5, 0.0, 0.0))
    return scene


def _lattice_scene(**kwargs):
    """A 12 x 5 x 3 simple cubic lattice block with fracture, clamped on the left, pulled on the right."""
    scene = pdsim.Scene(fps=24.0, frames=FRAMES, name="lattice", **kwargs)
    h = 0.01
    body = LatticeBody.block(Lattice.simple_cubic(h), (12, 5, 3), name="block", fracture=LatticeFracture((1.6 * h,)))
    x = body.rest_positions[: body.body_count, 0]
    body.clamp(x < x.min() + 0.5 * h)
    body.add_leaders(x > x.max() - 0.5 * h, velocity=(0.35 * h, 0.0, 0.0), stop_step=10)
    scene.add_body(body)
    return scene


BUILDERS = {"peridynamics": _pd_scene, "fem": _fem_scene, "lattice": _lattice_scene}


@pytest.fixture(scope="module")
def caches(tmp_path_factory):
    """{method: path} of a 2-frame cache of each method (built once for the module)."""
    folder = tmp_path_factory.mktemp("schema")
    out = {}
    for method, build in BUILDERS.items():
        path = folder / f"{method}.usdc"
        build().run(path, device="cpu", progress=False)
        out[method] = path
    return out


def _stage(path):
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    assert stage is not None
    return stage


def _layout(stage) -> dict:
    """{prim path: type name} below /World."""
    return {str(p.GetPath()): p.GetTypeName() for p in stage.Traverse() if str(p.GetPath()) != "/World"}


POINT_ATTRIBUTES = {"points", "velocities", "widths", "extent", "primvars:displacement"}
MESH_ATTRIBUTES = {
    "points",
    "velocities",
    "normals",
    "extent",
    "faceVertexCounts",
    "faceVertexIndices",
    "subdivisionScheme",
    "primvars:fragment",
    "primvars:crack",
}


def test_one_schema_for_every_method(caches):
    """Every method's cache has the same stage metadata (fps 24 = timeCodesPerSecond = framesPerSecond, frames 0..2,
    up axis Z, metres, defaultPrim /World, /World.pdsim:time per frame) and the same layout: a UsdGeom.Points
    /World/<body> with points, velocities, widths, extent and primvars of the shared attribute names only (vertex
    interpolation, the shared kinds), and for the methods with surfaces (peridynamics, FEM) a UsdGeom.Mesh
    /World/<body>_surface with the same attribute names (faceVarying normals, velocities, uniform fragment and crack
    primvars, the uniform material_index) and the GeomSubsets outer and crack of family materialBind, bound to the
    materials /World/Looks/pdsim_outer and /World/Looks/pdsim_crack. Every cache passes UsdValidation."""
    from pxr import UsdGeom, UsdShade

    kinds = {"float": "float[]", "int": "int[]", "vector3f": "vector3f[]"}
    bodies = {"peridynamics": "block", "fem": "bar", "lattice": "block"}
    mesh_attribute_sets = []
    for method, path in caches.items():
        assert usd_problems(path) == [], method
        stage = _stage(path)
        assert stage.GetTimeCodesPerSecond() == stage.GetFramesPerSecond() == 24.0
        assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0.0, float(FRAMES))
        assert UsdGeom.GetStageUpAxis(stage) == "Z" and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
        assert stage.GetDefaultPrim().GetPath() == "/World"
        time_attr = stage.GetPrimAtPath("/World").GetAttribute("pdsim:time")
        assert [time_attr.Get(f) for f in range(FRAMES + 1)] == pytest.approx([f / 24.0 for f in range(FRAMES + 1)])

        body = bodies[method]
        layout = _layout(stage)
        expected = {f"/World/{body}": "Points"}
        if method != "lattice":
            expected.update(
                {
                    f"/World/{body}_surface": "Mesh",
                    f"/World/{body}_surface/outer": "GeomSubset",
                    f"/World/{body}_surface/crack": "GeomSubset",
                    "/World/Looks": "Scope",
                    "/World/Looks/pdsim_outer": "Material",
                    "/World/Looks/pdsim_outer/PreviewSurface": "Shader",
                    "/World/Looks/pdsim_crack": "Material",
                    "/World/Looks/pdsim_crack/PreviewSurface": "Shader",
                }
            )
        assert layout == expected, method

        points = stage.GetPrimAtPath(f"/World/{body}")
        names = {a.GetName() for a in points.GetAttributes() if a.HasAuthoredValue() or a.GetNumTimeSamples()}
        assert names >= POINT_ATTRIBUTES, (method, POINT_ATTRIBUTES - names)
        for pv in UsdGeom.PrimvarsAPI(points).GetAuthoredPrimvars():
            assert pv.GetPrimvarName() in ATTRIBUTES, (method, pv.GetPrimvarName())
            assert pv.GetInterpolation() == "vertex"
            assert str(pv.GetTypeName()) == kinds[ATTRIBUTES[pv.GetPrimvarName()][0]]
            assert pv.GetAttr().GetTimeSamples() == [float(f) for f in range(FRAMES + 1)]
        if method == "lattice":
            continue
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/World/{body}_surface"))
        mnames = {a.GetName() for a in mesh.GetPrim().GetAttributes() if a.HasAuthoredValue() or a.GetNumTimeSamples()}
        assert mnames >= MESH_ATTRIBUTES, (method, MESH_ATTRIBUTES - mnames)
        mesh_attribute_sets.append(mnames - {"subsetFamily:materialBind:familyType"})
        assert mesh.GetNormalsInterpolation() == "faceVarying"
        assert mesh.GetSubdivisionSchemeAttr().Get() == "none"
        for pv in ("fragment", "crack", "material_index"):
            assert UsdGeom.PrimvarsAPI(mesh).GetPrimvar(pv).GetInterpolation() == "uniform"
        for name in ("outer", "crack"):
            subset = UsdGeom.Subset(stage.GetPrimAtPath(f"/World/{body}_surface/{name}"))
            assert subset.GetFamilyNameAttr().Get() == "materialBind"
            assert subset.GetElementTypeAttr().Get() == "face"
            bound = UsdShade.MaterialBindingAPI(subset.GetPrim()).ComputeBoundMaterial()[0]
            assert bound.GetPath() == f"/World/Looks/pdsim_{name}"
    assert mesh_attribute_sets[0] == mesh_attribute_sets[1]


@pytest.mark.parametrize("method", ["peridynamics", "fem"])
def test_every_mesh_sample_has_velocities_and_normals(caches, method):
    """Every frame of every surface mesh of the peridynamic and FEM caches has vertex velocities [m/s] (one per
    point) and normals (one per face corner): renderers need them for motion blur and shading. The surface's
    velocities equal the points' velocities where a vertex sits on a point at rest (FEM: surface vertices are mesh
    vertices)."""
    from pxr import UsdGeom

    stage = _stage(caches[method])
    meshes = [UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    assert meshes
    for mesh in meshes:
        name = mesh.GetPath()
        for frame in range(FRAMES + 1):
            points = mesh.GetPointsAttr().Get(frame)
            velocities = mesh.GetVelocitiesAttr().Get(frame)
            assert velocities is not None and len(velocities) == len(points), (
                f"{name} has no vertex velocities at frame {frame}: the solver's MeshView.velocities is None "
                "(peridynamics: pdsim/fragment_surfaces/ must give the surface vertices their velocities)"
            )
            assert np.isfinite(np.asarray(velocities)).all()
            normals = mesh.GetNormalsAttr().Get(frame)
            assert normals is not None and len(normals) == len(mesh.GetFaceVertexIndicesAttr().Get(frame))
            assert np.allclose(np.linalg.norm(np.asarray(normals), axis=1), 1.0, atol=1e-5)


# ----------------------------------------------------------------------------------------------------- colliders


def _collider_scene(**kwargs):
    scene = pdsim.Scene(fps=24.0, frames=2, name="hit", **kwargs)
    scene.add_peridynamic_body(pdsim.box((0.06, 0.06, 0.03), center=(0.0, 0.0, 0.02)), MAT, 0.01, name="slab")
    scene.add_ground_plane(height=0.0)
    scene.add_collider(pdsim.SphereProjectile(0.02, center=(0.0, 0.0, 0.3), velocity=(0.0, 0.0, -1.0)))
    scene.add_collider(pdsim.BoxProjectile((0.02, 0.02, 0.02), center=(0.2, 0.0, 0.1), velocity=(-0.5, 0.0, 0.0),
                                           angular_velocity=(0.0, 0.0, 3.0), name="brick"))  # fmt: skip
    scene.add_collider(pdsim.MeshCollider(pdsim.box((0.05, 0.05, 0.05), center=(-0.3, 0.0, 0.025))))
    return scene


def test_colliders_projectiles_and_ground_in_the_cache(tmp_path):
    """Scene.run writes the ground plane as a static Mesh /World/ground (a quad on the plane, larger than the scene,
    normals along the up axis), each collider as a Mesh /World/colliders/<name> (default name <class>_<index>), its
    geometry written once in its body frame and, for projectiles, xformOp:translate and xformOp:orient sampled on
    every frame from pose(t) at the frame's simulated time; world vertices of the sphere lie at its radius around
    pose(t). A static mesh collider keeps a static transform."""
    from pxr import UsdGeom

    scene = _collider_scene()
    out = tmp_path / "hit.usdc"
    scene.run(out, device="cpu", progress=False)
    assert usd_problems(out) == []
    stage = _stage(out)
    ground = UsdGeom.Mesh(stage.GetPrimAtPath("/World/ground"))
    g = np.asarray(ground.GetPointsAttr().Get(), dtype=np.float64) + np.asarray(
        ground.GetPrim().GetAttribute("xformOp:translate").Get()
    )
    assert np.allclose(g[:, 2], 0.0) and np.ptp(g[:, 0]) > 1.0
    assert np.allclose(np.asarray(ground.GetNormalsAttr().Get()), [0.0, 0.0, 1.0])
    names = {p.GetName() for p in stage.GetPrimAtPath("/World/colliders").GetChildren()}
    assert names == {"SphereProjectile_0", "brick", "MeshCollider_2"}
    sphere_prim = stage.GetPrimAtPath("/World/colliders/SphereProjectile_0")
    sphere = scene.colliders[0]
    local = np.asarray(UsdGeom.Mesh(sphere_prim).GetPointsAttr().Get(), dtype=np.float64)
    for frame in range(3):
        p, _ = sphere.pose(frame * scene.frame_time)
        m = np.asarray(UsdGeom.Xformable(sphere_prim).ComputeLocalToWorldTransform(frame))
        world = local @ m[:3, :3] + m[3, :3]
        np.testing.assert_allclose(np.linalg.norm(world - p, axis=1), 0.02, rtol=1e-5)
    brick = stage.GetPrimAtPath("/World/colliders/brick")
    assert brick.GetAttribute("xformOp:orient").GetTimeSamples() == [0.0, 1.0, 2.0]
    _, q2 = scene.colliders[1].pose(2 * scene.frame_time)
    qu = brick.GetAttribute("xformOp:orient").Get(2)
    assert abs(abs(float(np.dot([*qu.GetImaginary(), qu.GetReal()], q2))) - 1.0) < 1e-6
    static = stage.GetPrimAtPath("/World/colliders/MeshCollider_2")
    assert static.GetAttribute("xformOp:translate").GetNumTimeSamples() == 0
    np.testing.assert_allclose(static.GetAttribute("xformOp:translate").Get(), (-0.3, 0.0, 0.025), atol=1e-9)


def test_collider_names_validated(tmp_path):
    """Two colliders with the same name: Scene.run raises ParameterError naming the name before simulating; a name
    that is not a non-empty string is refused by the collider."""
    scene = _collider_scene()
    scene.colliders[2].name = "brick"
    with pytest.raises(pdsim.ParameterError, match="brick"):
        scene.run(tmp_path / "x.usdc", device="cpu", progress=False)
    assert not (tmp_path / "x.usdc").exists()
    with pytest.raises(pdsim.ParameterError, match="name"):
        pdsim.SphereProjectile(0.1, name="")


# ---------------------------------------------------------------------------------------------------------- time


def test_time_parameters_validated():
    """frame_time defaults to 1/fps; time_scale = simulated seconds per played second gives frame_time =
    time_scale / fps; frame_time is simulated seconds per frame; giving both, or a value <= 0 or not finite, raises
    ParameterError naming the parameter; fps stays in (0, 1000]."""
    assert pdsim.Scene(fps=24).frame_time == pytest.approx(1 / 24)
    assert pdsim.Scene(fps=24, time_scale=0.2).frame_time == pytest.approx(0.2 / 24)
    assert pdsim.Scene(fps=24, frame_time=50e-6 / 48).frame_time == 50e-6 / 48
    with pytest.raises(pdsim.ParameterError, match=r"time_scale.*frame_time"):
        pdsim.Scene(fps=24, time_scale=0.5, frame_time=1e-3)
    for bad in (0.0, -1.0, math.inf, math.nan, "x"):
        with pytest.raises(pdsim.ParameterError, match="time_scale"):
            pdsim.Scene(time_scale=bad)
        with pytest.raises(pdsim.ParameterError, match="frame_time"):
            pdsim.Scene(frame_time=bad)
    with pytest.raises(pdsim.ParameterError, match="fps"):
        pdsim.Scene(fps=2000)


def test_microsecond_event_over_48_frames(tmp_path):
    """A 50 us impact written over 48 frames played at 24 fps (frame_time = 50e-6 / 48 s): the cache plays at 24
    time codes per second, /World.pdsim:time gives each frame's simulated time (frame x 50e-6 / 48 s), the run uses
    whole substeps per frame at most the stable step, and the projectile's transform follows pose at those times
    (it moves 1.2 mm in 50 us at 24 m/s)."""
    scene = pdsim.Scene(fps=24, frames=48, frame_time=50e-6 / 48, gravity=(0.0, 0.0, 0.0), name="impact")
    scene.add_peridynamic_body(pdsim.box((0.04, 0.04, 0.01)), MAT, 0.01, name="plate")
    ball = scene.add_collider(pdsim.SphereProjectile(0.005, center=(0.0, 0.0, 0.0115), velocity=(0.0, 0.0, -24.0)))
    out = tmp_path / "impact.usdc"
    report = scene.run(out, device="cpu", progress=False)
    assert report.frames_written == 49
    assert report.dt * report.substeps_per_frame == pytest.approx(50e-6 / 48)
    assert report.dt <= report.stable_dt
    stage = _stage(out)
    assert stage.GetTimeCodesPerSecond() == 24.0 and stage.GetEndTimeCode() == 48.0
    times = [stage.GetPrimAtPath("/World").GetAttribute("pdsim:time").Get(f) for f in (0, 1, 24, 48)]
    assert times == pytest.approx([0.0, 50e-6 / 48, 25e-6, 50e-6], rel=1e-12)
    z = [stage.GetPrimAtPath("/World/colliders/SphereProjectile_0").GetAttribute("xformOp:translate").Get(f)[2]
         for f in (0, 48)]  # fmt: skip
    assert z[0] - z[1] == pytest.approx(24.0 * 50e-6, rel=1e-9)
    assert ball.pose(50e-6)[0][2] == pytest.approx(z[1], rel=1e-12)
    info = dict(stage.GetRootLayer().customLayerData["pdsim"])
    assert info["frameTime"] == 50e-6 / 48 and info["timeScale"] == pytest.approx(24 * 50e-6 / 48)


def test_four_walls_plays_slow_motion_at_24_fps():
    """scenes/four_walls.py plays at 24 fps in 5x slow motion: 1/120 s of simulated time per frame."""
    from four_walls import build_scene

    scene = build_scene(spacing=0.03, frames=2)
    assert scene.fps == 24.0
    assert scene.frame_time == pytest.approx(1.0 / 120.0)


def test_velocities_are_per_played_second_in_slow_motion(tmp_path):
    """USD velocities are stage units per second of playback (per timeCodesPerSecond time codes). A block drifting
    at 2 m/s in 5x slow motion (time_scale 0.2, 24 fps) moves 2 x 0.2 / 24 m per frame; the cache's velocities are
    0.4 m/s on the points and the surface vertices, so that velocities / fps equal the displacement per frame (what
    motion blur extrapolates), and /World.pdsim:time advances by 0.2 / 24 s per frame."""
    from pxr import Usd

    scene = pdsim.Scene(fps=24, time_scale=0.2, frames=2, gravity=(0.0, 0.0, 0.0), name="drift")
    body = scene.add_peridynamic_body(pdsim.box((0.04, 0.02, 0.02)), MAT, 0.01, name="block")
    body.set_initial_velocity((2.0, 0.0, 0.0))
    out = tmp_path / "drift.usdc"
    scene.run(out, device="cpu", progress=False)
    stage = Usd.Stage.Open(str(out))
    points = stage.GetPrimAtPath("/World/block")
    x = [np.asarray(points.GetAttribute("points").Get(f), dtype=np.float64) for f in (1, 2)]
    np.testing.assert_allclose((x[1] - x[0])[:, 0], 2.0 * 0.2 / 24, rtol=1e-4)
    np.testing.assert_allclose(np.asarray(points.GetAttribute("velocities").Get(1))[:, 0], 0.4, rtol=1e-5)
    surface_v = np.asarray(stage.GetPrimAtPath("/World/block_surface").GetAttribute("velocities").Get(1))
    np.testing.assert_allclose(surface_v[:, 0], 0.4, rtol=1e-4)
    t = stage.GetPrimAtPath("/World").GetAttribute("pdsim:time")
    assert t.Get(2) - t.Get(1) == pytest.approx(0.2 / 24)
