"""The cache's material hooks, debris and crack events (docs/cache_format.md, "Material hooks", "Debris", "Crack
events"), read back with usd-core: no Blender needed (tests/test_cache_blender.py imports and renders them in
Blender).

- every fracturing surface carries a per-face ``material_index`` (0 outer, 1 crack) equal to its ``crack`` attribute
  at every frame, beside the GeomSubsets ``outer`` and ``crack`` that partition its faces, bound to the materials
  ``pdsim_outer`` and ``pdsim_crack`` of distinct colours; the particles under a surface are guides unless
  ``render_points=True``;
- ``debris_particles``: small fragments leave the surface and become point-instancer instances at their centroid,
  velocity, rotation and size;
- ``crack_events``: per frame, one point per broken bond; count, energies (against float64 numpy from the
  displacements of every step) and normals of a bar pulled apart.
"""

from __future__ import annotations

import colorsys

import numpy as np
import pytest
from test_cache_schema import _fem_scene, _pd_scene

import pdsim
from pdsim.errors import FeatureNotAvailableError, ParameterError
from pdsim.output.usd import UsdCache
from pdsim.output.usd_files import usd_problems
from pdsim.output.views import MeshView, PointsView
from pdsim.output.writer import ViewWriter

FRAMES = 4


@pytest.fixture(scope="module")
def pd_cache(tmp_path_factory):
    """The peridynamic block of tests/test_cache_schema.py pulled apart over 4 frames (it fractures at frame 1)."""
    path = tmp_path_factory.mktemp("materials") / "pd.usdc"
    scene = _pd_scene()
    scene.frames = FRAMES
    scene.run(path, device="cpu", progress=False)
    return path


def _stage(path):
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    assert stage is not None
    return stage


def test_crack_material_index_partition_and_materials(pd_cache):
    """On every frame of a fracturing block: the uniform int primvar material_index equals the crack attribute
    (0 outer, 1 crack) and changes with the topology (its samples are the topology's, and it holds crack faces at the
    end, none at frame 0); the subsets outer and crack are a partition of the faces (every face in exactly one); they
    are bound to /World/Looks/pdsim_outer and /World/Looks/pdsim_crack, whose UsdPreviewSurface diffuse colours differ
    in hue by more than 0.1 of the hue circle; the particle Points prim is a guide."""
    from pxr import UsdGeom, UsdShade

    assert usd_problems(pd_cache) == []
    stage = _stage(pd_cache)
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/block_surface"))
    index = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("material_index")
    assert index.GetInterpolation() == UsdGeom.Tokens.uniform and str(index.GetTypeName()) == "int[]"
    assert index.GetAttr().GetTimeSamples() == mesh.GetFaceVertexIndicesAttr().GetTimeSamples()
    crack = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("crack")
    subsets = {s.GetPrim().GetName(): s for s in UsdGeom.Subset.GetAllGeomSubsets(mesh)}
    assert list(subsets) == ["outer", "crack"]  # Blender's material slots follow this order: index 0 outer, 1 crack
    for frame in range(FRAMES + 1):
        faces = len(mesh.GetFaceVertexCountsAttr().Get(frame))
        values = np.asarray(index.Get(frame))
        assert values.shape == (faces,)
        np.testing.assert_array_equal(values, np.asarray(crack.Get(frame)))
        outer = np.asarray(subsets["outer"].GetIndicesAttr().Get(frame))
        cracked = np.asarray(subsets["crack"].GetIndicesAttr().Get(frame))
        np.testing.assert_array_equal(np.sort(np.r_[outer, cracked]), np.arange(faces))  # each face exactly once
        np.testing.assert_array_equal(cracked, np.flatnonzero(values == 1))
    assert np.asarray(index.Get(0)).sum() == 0 and np.asarray(index.Get(FRAMES)).sum() > 0
    hues = {}
    for name in ("outer", "crack"):
        material = UsdShade.MaterialBindingAPI(subsets[name].GetPrim()).ComputeBoundMaterial()[0]
        assert material.GetPath() == f"/World/Looks/pdsim_{name}"
        shader = UsdShade.Shader(stage.GetPrimAtPath(f"/World/Looks/pdsim_{name}/PreviewSurface"))
        assert shader.GetIdAttr().Get() == "UsdPreviewSurface"
        hues[name] = colorsys.rgb_to_hsv(*shader.GetInput("diffuseColor").Get())
    assert hues["crack"][1] > 0.5 and hues["outer"][1] < 0.2  # a saturated crack colour, a grey outer one
    points = UsdGeom.Imageable(stage.GetPrimAtPath("/World/block"))
    assert points.ComputePurpose() == UsdGeom.Tokens.guide


def _box(offset=(0.0, 0.0, 0.0), size=1.0):
    import trimesh

    box = trimesh.creation.box(extents=(size, size, size))
    return np.asarray(box.vertices) + offset, np.asarray(box.faces)


def _views(frame, render_mesh=True):
    """Points of 3 fragments (ids 0: 8 points, 8: 4 points, 12: 1 point) and a surface with 12 faces of each."""
    rng = np.random.default_rng(1)
    rest = np.r_[rng.random((8, 3)), [[3.0, 0, 0], [3.2, 0, 0], [3.0, 0.3, 0], [3.0, 0, 0.4]], [[6.0, 0, 0]]]
    fragment = np.r_[np.zeros(8, int), np.full(4, 8), [12]]
    angle = 0.5 * frame  # fragment 8 turns about z by 0.5 rad per frame and moves by +1 m in y
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    x = rest.copy()
    centre = rest[8:12].mean(axis=0)
    x[8:12] = (rest[8:12] - centre) @ rot.T + centre + [0.0, frame, 0.0]
    velocity = np.zeros_like(x)
    velocity[8:12] = (2.0, 0.0, 0.0)
    points = PointsView("body", x, velocity, np.full(13, 0.1), {"fragment": fragment, "displacement": x - rest})
    views = [points]
    if render_mesh:
        faces, verts, frags = [], [], []
        for i, fid in enumerate((0, 8, 12)):
            v, f = _box((3.0 * i, 0, 0))
            faces.append(f + 8 * i)
            verts.append(v)
            frags.append(np.full(len(f), fid))
        frag = np.concatenate(frags)
        views.append(
            MeshView("body_surface", np.concatenate(verts), None, 0, np.concatenate(faces), {"fragment": frag,
                     "crack": (frag > 0).astype(int)})
        )  # fmt: skip
    return views, rot, x[8:12].mean(axis=0)


def test_debris_as_point_instancer(tmp_path):
    """debris_particles=5: the fragments of 4 and 1 points leave the surface (its faces are those of fragment 0 only)
    and are the instances of /World/body_debris (a PointInstancer with one prototype, an icosahedron of unit diameter
    bound to pdsim_crack): ids 8 and 12, positions their centroids (1e-6 m), velocities their mean velocity, the
    orientation of fragment 8 its rotation about z (0.5 rad per frame, to the half-precision of quath: 2e-3), the size
    of the 1-point fragment its width (0.1 m). With render_points=True the points are not guides; a body without a
    surface keeps default points and no instancer."""
    from pxr import UsdGeom, UsdShade

    path = tmp_path / "debris.usdc"
    with UsdCache(path, fps=24.0) as cache:
        writer = ViewWriter(cache, debris_particles=5)
        for frame in range(3):
            views, _, _ = _views(frame)
            writer.write(frame, views)
            cache.end_frame(frame)
    assert usd_problems(path) == []
    stage = _stage(path)
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/body_surface"))
    assert len(mesh.GetFaceVertexCountsAttr().Get(2)) == 12
    np.testing.assert_array_equal(np.asarray(UsdGeom.PrimvarsAPI(mesh).GetPrimvar("fragment").Get(2)), 0)
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/body_debris"))
    proto = stage.GetPrimAtPath("/World/body_debris/prototypes/chunk")
    assert [str(p) for p in instancer.GetPrototypesRel().GetTargets()] == [str(proto.GetPath())]
    assert np.ptp(np.linalg.norm(np.asarray(UsdGeom.Mesh(proto).GetPointsAttr().Get()), axis=1)) < 1e-6
    bound = UsdShade.MaterialBindingAPI(proto).ComputeBoundMaterial()[0]
    assert bound.GetPath() == "/World/Looks/pdsim_crack"
    translate = np.asarray(stage.GetPrimAtPath("/World/body_debris").GetAttribute("xformOp:translate").Get())
    for frame in range(3):
        _, _, centroid = _views(frame)
        assert list(instancer.GetIdsAttr().Get(frame)) == [8, 12]
        positions = np.asarray(instancer.GetPositionsAttr().Get(frame), dtype=np.float64) + translate
        np.testing.assert_allclose(positions, [centroid, [6.0, 0, 0]], atol=1e-6)
        np.testing.assert_allclose(np.asarray(instancer.GetVelocitiesAttr().Get(frame)), [[2, 0, 0], [0, 0, 0]])
        q = np.asarray(instancer.GetOrientationsAttr().Get(frame), dtype=np.float64)  # (x, y, z, w)
        np.testing.assert_allclose(q[0], [0, 0, np.sin(0.25 * frame), np.cos(0.25 * frame)], atol=2e-3)
        np.testing.assert_allclose(q[1], [0, 0, 0, 1], atol=2e-3)
        scales = np.asarray(instancer.GetScalesAttr().Get(frame))
        np.testing.assert_allclose(scales[1], [0.1, 0.1, 0.1], rtol=1e-6)
        np.testing.assert_allclose(instancer.GetProtoIndicesAttr().Get(frame), [0, 0])

    path = tmp_path / "shown.usdc"
    with UsdCache(path, fps=24.0) as cache:
        writer = ViewWriter(cache, render_points=True, debris_particles=5)
        views, _, _ = _views(0, render_mesh=False)
        lattice = PointsView("lattice", np.zeros((2, 3)), np.zeros((2, 3)), np.full(2, 0.1))
        writer.write(0, [*views, lattice])
        cache.end_frame(0)
    stage = _stage(path)
    assert not stage.GetPrimAtPath("/World/body_debris")  # no surface: no debris taken out of it
    for name in ("body", "lattice"):
        assert UsdGeom.Imageable(stage.GetPrimAtPath(f"/World/{name}")).ComputePurpose() == UsdGeom.Tokens.default_


def _pulled_bar(shift=(0.0, 0.0, 0.0), bars=1):
    """``bars`` 12 x 4 x 4 particle bars (h = 1 cm, no compressive bonus; "bar", then "bar_1" 0.1 m further in y, a
    weaker one: critical stretch 0.004) whose end layers are pulled apart along x at 1 m/s each: each breaks across
    the middle."""
    scene = pdsim.Scene(fps=24, frames=6, frame_time=2.0e-4, gravity=(0.0, 0.0, 0.0), name="pull")
    for i in range(bars):
        material = pdsim.Material(
            density=1000.0, youngs_modulus=1.0e7, poisson_ratio=0.25, critical_stretch=0.005 - 0.001 * i
        )
        o = np.asarray(shift, dtype=np.float64) + np.array((0.0, 0.1 * i, 0.0))
        name = "bar" if i == 0 else f"bar_{i}"
        body = scene.add_peridynamic_body(pdsim.box((0.12, 0.04, 0.04), center=tuple(o)), material, 0.01, name=name)
        left = pdsim.BoxRegion(lo=o + np.array((-1, -0.05, -1)), hi=o + np.array((-0.045, 0.05, 1)))
        right = pdsim.BoxRegion(lo=o + np.array((0.045, -0.05, -1)), hi=o + np.array((1, 0.05, 1)))
        body.set_velocity(left, (-1.0, 0, 0), axes="x", name="l")
        body.set_velocity(right, (1.0, 0, 0), axes="x", name="r")
    return scene


def test_crack_events_of_a_pulled_bar():
    """A bar pulled apart, stepped one step at a time with the events collected every 40 steps: over each collection
    the event count equals the bonds (pairs) that broke, and the event energies sum to the energy those bonds held
    in the step each broke, V_k b_k (w V beta G^dev)_kj e^2 from both ends, with e recomputed in float64 numpy from
    the displacements of that step (relative 1e-4 for float32); every event lies at its bond's midpoint (1e-5 m);
    the normals' energy-weighted orientation tensor has its principal axis along the pull (within 5 degrees). Far
    from the origin (1 km) the events are the same, shifted (1e-4 m)."""
    results = []
    for shift in ((0.0, 0.0, 0.0), (1000.0, -500.0, 250.0)):
        scene = _pulled_bar(shift)
        (solver,) = scene.build_solvers(device="cpu")
        m = solver.model
        offsets, neighbors = m.family_offsets.numpy(), m.family_neighbors.numpy()
        k = np.repeat(np.arange(m.particle_count), np.diff(offsets))
        reverse = np.full(len(k), -1)
        order = np.lexsort((neighbors, k))
        key = k * m.particle_count + neighbors
        rkey = neighbors * m.particle_count + k
        reverse = order[np.searchsorted(key[order], rkey)]
        assert np.array_equal(k[reverse], neighbors)
        geom = m.bond_geom.numpy().astype(np.float64)
        xi = geom[:, :3] * geom[:, 3:]
        term = m.volumes.numpy()[k] * m.dev_b.numpy()[k] * m.bond_wv_dev.numpy()  # V_k b_k (w V beta G^dev)_q
        rest = m.rest_positions.numpy().astype(np.float64)
        events = solver.crack_events()
        dt = 0.5 * solver.stable_time_step()
        alive = solver.bond_alive()
        collected, reference = [], []
        broken, energy = [], {}
        for step in range(1, 1601):
            solver.simulate(dt, 1)
            now = solver.bond_alive()
            broke = np.flatnonzero(alive & ~now & (k < neighbors))
            if len(broke):  # e of the step the bonds broke in: from the displacements that step's passes used
                u = solver.kin.u.numpy().astype(np.float64)
                e = np.linalg.norm(xi + u[neighbors] - u[k], axis=1) - geom[:, 3]
                energy.update(
                    zip(broke.tolist(), term[broke] * e[broke] ** 2 + term[reverse[broke]] * e[reverse[broke]] ** 2)
                )
                broken.append(broke)
            alive = now
            if step % 40 == 0:
                (view,) = events.collect()
                ids = np.sort(np.concatenate(broken)) if broken else np.zeros(0, int)
                u = solver.kin.u.numpy().astype(np.float64)
                mid = 0.5 * (rest[k[ids]] + u[k[ids]] + rest[neighbors[ids]] + u[neighbors[ids]])
                collected.append(view)
                reference.append((np.array([energy[i] for i in ids.tolist()]), mid))
                broken, energy = [], {}
        total = sum(len(v.energies) for v in collected)
        assert total > 1000, total  # the bar broke
        for view, (w, mid) in zip(collected, reference, strict=True):
            assert len(view.energies) == len(w)  # one event per bond (pair) broken since the last collect
            if len(w):
                np.testing.assert_allclose(view.energies, w, rtol=1e-3)  # in bond order
                assert view.energies.sum() == pytest.approx(w.sum(), rel=1e-4)
                np.testing.assert_allclose(view.positions - solver.origin, mid, atol=1e-5)
        energies = np.concatenate([v.energies for v in collected])
        normals = np.concatenate([v.normals for v in collected]).astype(np.float64)
        tensor = (normals.T * energies) @ normals / energies.sum()
        axis = np.linalg.eigh(tensor)[1][:, -1]
        assert abs(axis[0]) > np.cos(np.radians(5.0)), axis
        results.append((np.concatenate([v.positions for v in collected]), energies))
    np.testing.assert_allclose(results[1][0] - (1000.0, -500.0, 250.0), results[0][0], atol=1e-4)
    np.testing.assert_allclose(results[1][1], results[0][1], rtol=1e-3)


def test_crack_events_in_the_cache(tmp_path):
    """Scene.run(crack_events=True) with two bars writes /World/bar_crack_events and /World/bar_1_crack_events: one
    point per bond broken in each frame (the sum over frames equals the bonds the run broke in that body), zero
    widths, unit normals and primvars:energy > 0, time-sampled at every frame (empty at frame 0); it passes the USD
    validators. Methods without crack events refuse the option
    before the run (FeatureNotAvailableError naming the body), and a negative debris_particles is a ParameterError."""
    from pxr import UsdGeom

    path = tmp_path / "events.usdc"
    kept = {}
    scene = _pulled_bar(bars=2)
    scene.run(path, device="cpu", progress=False, crack_events=True, on_frame=lambda f, s: kept.update(s=s[0]))
    assert usd_problems(path) == []
    stage = _stage(path)
    solver = kept["s"]
    m = solver.model
    k = np.repeat(np.arange(m.particle_count), np.diff(m.family_offsets.numpy()))
    broken = ~solver.bond_alive() & (k < m.family_neighbors.numpy())
    totals = []
    for i, name in enumerate(("bar", "bar_1")):
        points = UsdGeom.Points(stage.GetPrimAtPath(f"/World/{name}_crack_events"))
        assert UsdGeom.Imageable(points).ComputePurpose() == UsdGeom.Tokens.guide
        energy = UsdGeom.PrimvarsAPI(points).GetPrimvar("energy")
        assert points.GetPointsAttr().GetTimeSamples() == [float(f) for f in range(7)]
        total = 0
        for frame in range(7):
            n = len(points.GetPointsAttr().Get(frame))
            total += n
            assert len(points.GetWidthsAttr().Get(frame)) == n and not np.any(points.GetWidthsAttr().Get(frame))
            if n:
                normals = np.asarray(points.GetNormalsAttr().Get(frame))
                np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1, 1e-5)
                assert np.all(np.asarray(energy.Get(frame)) > 0)
        assert len(points.GetPointsAttr().Get(0)) == 0
        rows = solver.body_slice(i)
        totals.append(total)
        assert total == int(broken[(k >= rows.start) & (k < rows.stop)].sum()) > 0, name
    assert totals[0] != totals[1]  # the bodies' events are not swapped or mixed

    with pytest.raises(FeatureNotAvailableError, match="'bar'"):
        _fem_scene().run(tmp_path / "fem.usdc", device="cpu", progress=False, crack_events=True)
    with pytest.raises(ParameterError, match="debris_particles"):
        _pulled_bar().run(tmp_path / "bad.usdc", device="cpu", progress=False, debris_particles=-1)


def test_run_command_options(tmp_path, capsys):
    """`pdsim run --render-points --debris 8 --crack-events` reaches Scene.run: on the default scene's cache the
    particles are not guides, the crack events prim is there; `--debris -1` exits with one line naming the
    setting."""
    from pxr import UsdGeom

    from pdsim import cli

    out = tmp_path / "options.usdc"
    args = ["run", "--frames", "1", "--out", str(out), "--device", "cpu", "--quiet"]
    assert cli.main([*args, "--render-points", "--debris", "8", "--crack-events"]) == 0
    stage = _stage(out)
    points = [p for p in stage.Traverse() if p.IsA(UsdGeom.Points) and not p.GetName().endswith("_crack_events")]
    assert points and all(UsdGeom.Imageable(p).ComputePurpose() == UsdGeom.Tokens.default_ for p in points)
    assert any(p.GetName().endswith("_crack_events") for p in stage.Traverse())
    capsys.readouterr()
    assert cli.main([*args, "--debris", "-1"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "debris_particles" in err[0], err
