"""The solver contract, checked the same way for the three methods (peridynamics, FEM, particle lattice): momentum,
the watchdog, independence of world position, the shared output attributes and the feature gate.

Tests run on the CPU always and on CUDA where present (the ``device`` fixture of tests/conftest.py). Every scene is
built through pdsim.Scene, as a user builds it, with the defaults on (automatic step; contact where the
method has it), and runs through the scene's own frame stepping (pdsim.run.advance_frame), so the origin of the local
frame and the time-step policy are those of a real run.
"""

import numpy as np
import pytest

import pdsim
from pdsim.lattice import Lattice, LatticeBody, LatticeFracture
from pdsim.output.views import ATTRIBUTES, MeshView, PointsView
from pdsim.run import advance_frame

METHODS = ["peridynamics", "fem", "lattice"]
SHIFT = np.array([1000.0, -500.0, 250.0])
STEPS = 120  # steps of the translation-invariance run


def _pd_plate(offset, *, gravity=(0.0, 0.0, 0.0)):
    """A notched plate (24 x 10 x 2 particles, h = 2.5 mm, E = 1 MPa, s_c = 5e-3) pulled apart by its end columns
    (velocity ramped over 0.2 ms to 0.5 m/s): the crack grows from the notch."""
    scene = pdsim.Scene(fps=24.0, frames=1, gravity=gravity, name="plate")
    h = 2.5e-3
    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.25, critical_stretch=5.0e-3)
    o = np.asarray(offset, dtype=np.float64)
    body = scene.add_peridynamic_body(pdsim.box((24 * h, 10 * h, 2 * h), center=o), mat, h, name="plate")
    body.add_notch(pdsim.BoxRegion(lo=o + np.array([-1.0e-4, -1.0, -1.0]), hi=o + np.array([1.0e-4, 0.0, 1.0])))
    ramp = pdsim.TimeCurve.ramp(2.0e-4)
    x = body.rest_positions[:, 0] - o[0]
    left = pdsim.BoxRegion(lo=o + np.array([-1.0, -1.0, -1.0]), hi=o + np.array([x.min() + 0.5 * h, 1.0, 1.0]))
    right = pdsim.BoxRegion(lo=o + np.array([x.max() - 0.5 * h, -1.0, -1.0]), hi=o + np.array([1.0, 1.0, 1.0]))
    body.set_velocity(left, (-0.5, 0.0, 0.0), axes="x", curve=ramp, name="left")
    body.set_velocity(right, (0.5, 0.0, 0.0), axes="x", curve=ramp, name="right")
    return scene


def _fem_bar(offset, *, gravity=(0.0, 0.0, 0.0)):
    """A bar of 8 x 2 x 2 cubes (6 tetrahedra each), E = 1 MPa, pulled apart at 0.5 m/s by its end vertices until
    elements pass their tensile strength and split."""
    scene = pdsim.Scene(fps=24.0, frames=1, gravity=gravity, name="bar")
    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)
    o = np.asarray(offset, dtype=np.float64)
    mesh = pdsim.box_tet_mesh((0.08, 0.02, 0.02), (8, 2, 2), center=o)
    body = scene.add_body(pdsim.FemBody(mesh, mat, tensile_strength=2.0e3, name="bar"))
    body.set_velocity(
        pdsim.BoxRegion(lo=o + np.array([-1.0, -1.0, -1.0]), hi=o + np.array([-0.0399, 1.0, 1.0])), (-0.5, 0.0, 0.0)
    )
    body.set_velocity(
        pdsim.BoxRegion(lo=o + np.array([0.0399, -1.0, -1.0]), hi=o + np.array([1.0, 1.0, 1.0])), (0.5, 0.0, 0.0)
    )
    return scene


def _lattice_block(offset, **_):
    """A 12 x 5 x 3 simple-cubic lattice (spacing 1 cm, a 3D lattice so that the shift moves it in z too) with
    fracture, left layer clamped, right layer pulled at 3.5 mm a step for 10 steps."""
    scene = pdsim.Scene(fps=24.0, frames=1, name="lattice")
    h = 0.01
    body = LatticeBody.block(
        Lattice.simple_cubic(h),
        (12, 5, 3),
        origin=np.asarray(offset),
        name="block",
        fracture=LatticeFracture((1.6 * h,)),
    )
    x = body.rest_positions[: body.body_count, 0]
    body.clamp(x < x.min() + 0.5 * h)
    body.add_leaders(x > x.max() - 0.5 * h, velocity=(0.35 * h, 0.0, 0.0), stop_step=10)
    scene.add_body(body)
    return scene


BUILDERS = {"peridynamics": _pd_plate, "fem": _fem_bar, "lattice": _lattice_block}


def _run(scene, steps, device="cpu"):
    """Builds the scene's solvers on ``device`` and advances them ``steps`` steps of the scene's automatic step."""
    solvers = scene.build_solvers(device=device)
    dt = scene.time_step_safety * min(s.stable_time_step() for s in solvers)
    if not np.isfinite(dt):
        dt = 1.0 / scene.fps
    advance_frame(solvers, dt, steps)
    return solvers


def _attributes(solvers):
    """{(view name, attribute): values} of every view, plus the view positions as ('<name>', 'positions')."""
    out = {}
    for s in solvers:
        for v in s.views():
            if isinstance(v, PointsView):
                out[(v.name, "positions")] = np.asarray(v.positions)
                for k, a in v.attributes.items():
                    out[(v.name, k)] = np.asarray(a)
    return out


@pytest.mark.parametrize("method", METHODS)
def test_translation_moves_nothing_but_the_output(method, device):
    """The same scene at the origin and shifted by (1000, -500, 250) m gives the same displacements, damage and
    fragments; the world positions differ by the shift.

    Tolerance: each scene's solvers work in a local frame centred on its bodies, so both runs start from local rest
    positions equal to float64 round-off (1e-13 m) and do the same float32 arithmetic; we allow 1e-6 of the largest
    displacement (a few float32 ulps, room for a rest coordinate that rounds to a neighbouring float32) and require
    the integer fields (fragment ids, lattice kinds, broken links) to be identical. Positions are compared with
    1e-6 m after removing the shift (float64 output of float32 displacements)."""
    build = BUILDERS[method]
    a = _attributes(_run(build((0.0, 0.0, 0.0)), STEPS, device))
    b = _attributes(_run(build(SHIFT), STEPS, device))
    assert a.keys() == b.keys()
    u = a[next(k for k in a if k[1] == "displacement")]
    scale = float(np.abs(u).max())
    assert scale > 0.0
    moved = False
    for key, va in a.items():
        vb = b[key]
        if key[1] == "positions":
            np.testing.assert_allclose(vb - SHIFT, va, rtol=0.0, atol=1.0e-6, err_msg=str(key))
        elif np.issubdtype(va.dtype, np.integer):
            np.testing.assert_array_equal(vb, va, err_msg=str(key))
            moved |= key[1] in ("fragment", "broken_links") and bool(np.any(va != va.flat[0]))
        else:
            tol = 1.0e-6 * scale if key[1] == "displacement" else 1.0e-6 * max(float(np.abs(va).max()), 1e-30)
            np.testing.assert_allclose(vb, va, rtol=0.0, atol=tol, err_msg=str(key))
    assert moved, "the scene did not fracture, so fragments were not compared"


@pytest.mark.parametrize("method", ["peridynamics", "fem"])
def test_linear_momentum_is_conserved_without_external_loads(method, device):
    """With no gravity, no boundary condition and no collider, random initial velocities keep the total linear
    momentum to float32 round-off: |P(t) - P(0)| < 1e-5 of sum m |v| over 100 steps. (The lattice is massless and
    position-based: it has no momentum to conserve.)"""
    scene = BUILDERS[method]((0.3, -0.2, 0.1))
    body = scene.bodies[0]
    body.conditions.clear()
    body.point_condition[:] = -1
    rng = np.random.default_rng(3)
    body.set_initial_velocity(rng.normal(0.0, 0.1, (body.point_count, 3)))
    (solver,) = scene.build_solvers(device=device)
    p0 = solver.linear_momentum()
    scale = float(solver.masses() @ np.linalg.norm(solver.velocities(), axis=1))
    dt = 0.7 * solver.stable_time_step()
    advance_frame([solver], dt, 100)
    assert np.abs(solver.linear_momentum() - p0).max() < 1.0e-5 * scale


@pytest.mark.parametrize("method", METHODS)
def test_a_non_finite_state_is_caught(method, device):
    """A NaN in the state makes check_state raise InstabilityError (the watchdog of every method)."""
    (solver,) = BUILDERS[method]((0.0, 0.0, 0.0)).build_solvers(device=device)
    solver.check_state(1.0e6)
    if method == "lattice":  # set_displacements refuses non-finite input: write the device state directly
        u = solver.displacements(0).astype(np.float32)
        u[3] = np.nan
        solver._runtimes[0].u_cur.assign(u)
    else:
        u = solver.displacements()
        u[3] = np.nan
        solver.kin.set_displacements(u)
    with pytest.raises(pdsim.InstabilityError):
        solver.check_state(1.0e6)


@pytest.mark.parametrize("method", METHODS)
def test_views_use_the_shared_attribute_names(method, device):
    """Every view is a PointsView or MeshView; every attribute name is one of the shared names with the shared kind
    (vector3f: [n, 3]); each body has its PointsView under its own name; displacement is present for every
    method."""
    scene = BUILDERS[method]((0.0, 0.0, 0.0))
    solvers = _run(scene, 5, device)
    views = [v for s in solvers for v in s.views()]
    names = {v.name for v in views if isinstance(v, PointsView)}
    assert names == {b.name for b in scene.bodies}
    for v in views:
        assert isinstance(v, PointsView | MeshView)
        attrs = v.attributes if isinstance(v, PointsView) else v.face_attributes
        n = len(v.positions) if isinstance(v, PointsView) else len(v.faces)
        for k, a in attrs.items():
            kind = ATTRIBUTES[k][0]
            assert np.asarray(a).shape == ((n, 3) if kind == "vector3f" else (n,)), (v.name, k)
        if isinstance(v, PointsView):
            assert "displacement" in attrs


def _context_with(scene, **changes):
    import dataclasses

    return dataclasses.replace(scene.context(device="cpu"), **changes)


def test_feature_gate_of_each_method():
    """A setting a method cannot honour raises FeatureNotAvailableError naming the body and the setting, before
    anything is simulated; what a method can honour passes.

    - peridynamics honours gravity, ground, colliders, contact and loads: none raises;
    - FEM: a Material yield stress or fracture energy (FEM uses FemPlasticity and tensile_strength);
    - lattice (massless, position-based): a ground plane, a collider, explicit gravity."""
    from pdsim.solver import solver_for

    ground = pdsim.GroundPlane()
    ball = pdsim.SphereProjectile(0.01, center=(0.0, 0.0, 1.0))

    pd = _pd_plate((0.0, 0.0, 0.0), gravity=(0.0, 0.0, -9.81))
    ctx = _context_with(pd, ground=ground, colliders=[ball], contact=True)
    solver_for(pd.bodies[0]).check_features(pd.bodies, ctx)

    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3, yield_stress=1.0e4)
    fem = pdsim.Scene()
    fem.add_body(pdsim.FemBody(pdsim.box_tet_mesh((0.1, 0.02, 0.02), (5, 1, 1)), mat, name="yielding"))
    with pytest.raises(pdsim.FeatureNotAvailableError) as ei:
        fem.build_solvers(device="cpu")
    assert "'yielding'" in str(ei.value) and "yield_stress" in str(ei.value)

    lat = _lattice_block((0.0, 0.0, 0.0))
    lat.add_ground_plane()
    with pytest.raises(pdsim.FeatureNotAvailableError) as ei:
        lat.build_solvers(device="cpu")
    assert "'block'" in str(ei.value) and "ground" in str(ei.value)
    lat = _lattice_block((0.0, 0.0, 0.0))
    lat.add_collider(ball)
    with pytest.raises(pdsim.FeatureNotAvailableError):
        lat.build_solvers(device="cpu")
    explicit = pdsim.Scene(gravity=(0.0, 0.0, -9.81))
    explicit.add_body(_lattice_block((0.0, 0.0, 0.0)).bodies[0])
    with pytest.raises(pdsim.FeatureNotAvailableError) as ei:
        explicit.build_solvers(device="cpu")
    assert "gravity" in str(ei.value)


def test_only_the_output_and_preview_packages_import_pxr():
    """Solvers expose views and one writer makes USD: no module of pdsim/ outside pdsim/output/ (the writer, and the
    USD input reader of tetrahedral meshes) and pdsim/preview/ (which reads caches back), and no kernel, imports pxr.
    tests/test_layout.py checks that no solver reaches them through its imports."""
    import pathlib
    import re

    root = pathlib.Path(__file__).resolve().parents[1]
    pattern = re.compile(r"^\s*(import pxr|from pxr)", re.MULTILINE)
    offenders = [
        str(p.relative_to(root))
        for folder in ("pdsim", "kernels")
        for p in (root / folder).rglob("*.py")
        if pattern.search(p.read_text()) and not {"output", "preview"} & set(p.relative_to(root).parts)
    ]
    assert offenders == []
