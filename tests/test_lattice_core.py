"""The lattice on the method-neutral core (pdsim/solver.py): features it refuses, output views, precision independent
of world position, and fragments from the one labeller (pdsim/fragment_labels.py). CPU backend. Everything here drives
SolverLattice directly, except the two scene tests at the end (they go through Scene.build_solvers)."""

from __future__ import annotations

import numpy as np
import pytest

import pdsim
from pdsim.errors import FeatureNotAvailableError
from pdsim.lattice import (
    Lattice,
    LatticeBody,
    LatticeFracture,
    LatticeKind,
    LatticeNeighbourhood,
    LatticeRuleMixedCoordinate,
    SolverLattice,
)
from pdsim.output.views import ATTRIBUTES, PointsView
from pdsim.solver import SOLVERS, SolverContext, solver_for


def _pulled_block(spacing=1.0, counts=(8, 6), *, origin=None, name="block", **kwargs) -> LatticeBody:
    """A block clamped at its lowest x layer and pulled along x at 0.35 spacings/step at its highest for 10 steps."""
    lattice = Lattice.square(spacing) if len(counts) == 2 else Lattice.simple_cubic(spacing)
    body = LatticeBody.block(lattice, counts, origin=origin, name=name, **kwargs)
    x = body.rest_positions[: body.body_count, 0]
    h = 0.5 * spacing
    body.clamp(x < x.min() + h)
    body.add_leaders(x > x.max() - h, velocity=(0.35 * spacing, 0.0, 0.0), stop_step=10)
    return body


def _centre(body) -> np.ndarray:
    return 0.5 * (body.rest_positions.min(axis=0) + body.rest_positions.max(axis=0))


# ---------------------------------------------------------------------------------------------------- contract
def test_lattice_is_registered_and_massless():
    """LatticeBody.method is "lattice" and SolverLattice is its registered solver; the lattice never limits the
    scene's time step, has no speed scale, and every simulate call advances steps_per_frame steps whatever dt is."""
    body = _pulled_block(steps_per_frame=3)
    assert LatticeBody.method == "lattice" and SOLVERS["lattice"] is SolverLattice and solver_for(body) is SolverLattice
    solver = SolverLattice([body], SolverContext(device="cpu", origin=_centre(body)))
    assert solver.stable_time_step() == np.inf and solver.speed_scale() == 0.0
    solver.simulate(1.0e-3, 7)
    assert solver.step_count == 3 and solver.time == pytest.approx(7.0e-3)
    assert solver.point_count == body.particle_count and solver.bond_count == body.link_count
    assert not hasattr(solver, "add_outputs") and not hasattr(solver, "write_outputs")


@pytest.mark.parametrize(
    ("setting", "feature"),
    [
        ({"ground": pdsim.GroundPlane()}, "ground_plane"),
        ({"colliders": [pdsim.SphereProjectile(0.5, center=(0.0, 0.0, 5.0), device="cpu")]}, "colliders"),
        ({"gravity": (0.0, 0.0, -9.81), "gravity_is_default": False}, "gravity"),
        ({"contact": True}, "contact"),
        ({"contact": {"friction": 0.3}}, "contact"),
    ],
    ids=["ground", "collider", "explicit-gravity", "contact", "contact-options"],
)
def test_features_a_lattice_cannot_honour_are_refused(setting, feature):
    """A ground plane, a collider, an explicit non-zero gravity or explicitly enabled contact raise
    FeatureNotAvailableError naming the bodies, the setting and what to do instead (leaders; the methods with mass),
    from check_features and from the constructor."""
    bodies = [_pulled_block(name="left"), _pulled_block(name="right", origin=(0.0, 20.0, 0.0))]
    context = SolverContext(device="cpu", **setting)
    assert feature in SolverLattice.requested_features(bodies, context)
    with pytest.raises(FeatureNotAvailableError) as err:
        SolverLattice.check_features(bodies, context)
    message = str(err.value)
    assert "'left'" in message and "'right'" in message and f"({feature})" in message
    assert "add_leaders" in message and "peridynamic and FEM" in message
    with pytest.raises(FeatureNotAvailableError):
        SolverLattice(bodies, context)


@pytest.mark.parametrize(
    "setting",
    [{}, {"gravity": (0.0, -9.81, 0.0)}, {"gravity": (0.0, 0.0, 0.0), "gravity_is_default": False}, {"contact": None}],
    ids=["default", "default-gravity", "explicit-zero-gravity", "automatic-contact"],
)
def test_default_context_is_accepted(setting):
    """The default context, the scene's default (non-zero) gravity, an explicit zero gravity and automatic contact
    (None) ask nothing of a lattice."""
    body = _pulled_block()
    context = SolverContext(device="cpu", **setting)
    assert SolverLattice.requested_features([body], context) == {}
    SolverLattice.check_features([body], context)
    SolverLattice([body], context).run_steps(2)


# ---------------------------------------------------------------------------------------------------- views
def test_views_carry_the_shared_attributes():
    """One PointsView per body, named after it: world positions (float64 [n, 3], = rest + displacement), zero
    velocities (a lattice has no time), widths = point_width, and only shared attribute names: displacement as a
    vector [n, 3], kind, pe1, pe1_intact, pe2, broken_links and, with fracture only, fragment (-1 on the frame)."""
    plain = _pulled_block(name="plain")
    broken = _pulled_block(name="broken", origin=(0.0, 20.0, 0.0), fracture=LatticeFracture((1.6,)))
    solver = SolverLattice([plain, broken], device="cpu")
    solver.run_steps(8)
    views = solver.views()
    assert [type(v) for v in views] == [PointsView, PointsView] and [v.name for v in views] == ["plain", "broken"]
    for i, (view, body) in enumerate(zip(views, (plain, broken), strict=True)):
        n = body.particle_count
        assert set(view.attributes) <= set(ATTRIBUTES)
        assert view.positions.dtype == np.float64 and view.positions.shape == (n, 3)
        np.testing.assert_array_equal(view.velocities, np.zeros((n, 3)))
        np.testing.assert_array_equal(view.widths, np.full(n, body.point_width))
        u = view.attributes["displacement"]
        assert u.shape == (n, 3) and np.abs(u).max() > 1.0
        np.testing.assert_array_equal(u, solver.displacements(i))
        np.testing.assert_array_equal(view.positions, body.rest_positions + u)
        np.testing.assert_array_equal(view.attributes["kind"], solver.kinds(i))
        np.testing.assert_array_equal(view.attributes["pe1"], solver.pe1(i))
        np.testing.assert_array_equal(view.attributes["pe2"], solver.pe2(i))
        np.testing.assert_array_equal(view.attributes["broken_links"], solver.broken_links(i))
    assert "fragment" not in views[0].attributes
    frag = views[1].attributes["fragment"]
    assert np.all(frag[broken.body_count :] == -1) and np.all(frag[: broken.body_count] >= 0)
    assert views[1].attributes["broken_links"].sum() > 0


# ---------------------------------------------------------------------------------------------------- precision
SHIFT = np.array([1000.0, -500.0, 250.0])
PRECISION_TOL = 1.0e-7  # [m]: 3 float32 ulps of the largest displacement (0.3 m); see the test's docstring


def _poisson_tear(origin, context_origin):
    """A 3D case that uses rest positions in the kernels: simple cubic 10x6x6 block of spacing 0.1 m, second gradient,
    mixed-coordinate (Poisson) rule K = 0.5 /m about the body's axis, links lost beyond 0.16 / 0.26 m, pulled 1 cm
    per step for 30 steps; 60 steps."""
    body = LatticeBody.block(
        Lattice.simple_cubic(0.1),
        (10, 6, 6),
        origin=origin,
        neighbourhood=LatticeNeighbourhood(gradient=2),
        rule=LatticeRuleMixedCoordinate(k=0.5),
        fracture=LatticeFracture((0.16, 0.26)),
    )
    x = body.rest_positions[: body.body_count, 0]
    body.clamp(x < x.min() + 0.05)
    body.add_leaders(x > x.max() - 0.05, velocity=(0.01, 0.0, 0.0), stop_step=30)
    origin_of = _centre(body) if context_origin == "centre" else np.zeros(3)
    solver = SolverLattice([body], SolverContext(device="cpu", origin=origin_of))
    solver.run_steps(60)
    return body, solver


def test_displacements_do_not_depend_on_world_position():
    """The same lattice case at the world origin and shifted by (1000, -500, 250) m, each solved with its context
    origin at its bounding-box centre, gives the same displacements, broken links and fragments, and positions that
    differ by exactly the shift.

    Tolerance: the local rest positions of the two bodies agree to float64 round-off (1e-13 m), far below the float32
    resolution of the kernels, so the two runs do the same float32 arithmetic; PRECISION_TOL = 1e-7 m (3 float32 ulps
    of the largest displacement, 0.3 m) leaves room for a one-ulp difference in a rounded local coordinate, which K u d
    (K 0.5 /m, u <= 0.3 m) turns into 1e-9 m per step at most, averaged away by the rule (measured: bit-identical).
    The same shifted body solved in world coordinates (origin 0) misses it by more than 10 times (float32 rest
    positions near 1000 m are 6e-5 m apart: measured 1.5e-6 m), so the test does see a precision loss."""
    body0, at_origin = _poisson_tear((0.0, 0.0, 0.0), "centre")
    body1, shifted = _poisson_tear(SHIFT, "centre")
    np.testing.assert_allclose(
        body1.rest_positions - body0.rest_positions, np.broadcast_to(SHIFT, (body0.particle_count, 3))
    )
    u0, u1 = at_origin.displacements(), shifted.displacements()
    assert np.abs(u0).max() > 0.25 and np.abs(u0[:, 1:]).max() > 1.0e-3  # pulled, and contracted sideways
    np.testing.assert_allclose(u1, u0, rtol=0.0, atol=PRECISION_TOL)
    assert (~at_origin.link_alive()).sum() > 0
    np.testing.assert_array_equal(shifted.link_alive(), at_origin.link_alive())
    np.testing.assert_array_equal(shifted.fragments(), at_origin.fragments())
    np.testing.assert_allclose(shifted.positions() - at_origin.positions(), np.broadcast_to(SHIFT, u0.shape), atol=1e-9)
    _, world_frame = _poisson_tear(SHIFT, "world")
    assert np.abs(world_frame.displacements() - u0).max() > 10.0 * PRECISION_TOL


# ---------------------------------------------------------------------------------------------------- fragments
def _reference_fragments(body, alive):
    """Fragments by min-label propagation over intact links between non-frame points (numpy, independent of
    pdsim.fragment_labels), renumbered 0, 1, ... by smallest particle index; -1 on the frame."""
    n = body.particle_count
    solid = body.kind != LatticeKind.FRAME
    owner = np.repeat(np.arange(n), np.diff(body.row_offsets))
    keep = alive & solid[owner] & solid[body.link_neighbor]
    a, b = owner[keep], body.link_neighbor[keep]
    label = np.arange(n)
    while True:
        new = label.copy()
        np.minimum.at(new, a, label[b])
        new = new[new]  # pointer jumping
        if np.array_equal(new, label):
            break
        label = new
    out = np.full(n, -1)
    out[solid] = np.unique(label[solid], return_inverse=True)[1]
    return out


def test_fragments_come_from_the_one_labeller_and_are_cached(monkeypatch):
    """Fragment ids equal those of min-label propagation over the intact links (the former device labelling):
    0, 1, ... by smallest particle index, -1 on the frame; every intact link between body points joins one fragment.
    They are recomputed (pdsim.fragment_labels.fragment_labels) only when links broke since the last call."""
    import pdsim.lattice.solver as lattice_solver

    calls = []
    labeller = lattice_solver.fragment_labels

    def counting(*args, **kwargs):
        calls.append(1)
        return labeller(*args, **kwargs)

    monkeypatch.setattr(lattice_solver, "fragment_labels", counting)
    body = _pulled_block(counts=(15, 13), fracture=LatticeFracture((2.0,)))
    solver = SolverLattice([body], device="cpu")
    intact = solver.fragments()
    np.testing.assert_array_equal(intact, np.where(body.kind == LatticeKind.FRAME, -1, 0))
    assert len(calls) == 1
    solver.run_steps(1)  # nothing breaks in the first step
    solver.fragments()
    assert len(calls) == 1
    solver.run_steps(40)
    frag = solver.fragments()
    assert len(calls) == 2 and len(np.unique(frag[: body.body_count])) >= 2
    np.testing.assert_array_equal(frag, _reference_fragments(body, solver.link_alive()))
    first_seen = np.unique(frag[: body.body_count], return_index=True)[1]
    assert np.all(np.diff(first_seen) > 0)  # numbered in order of their smallest particle index
    np.testing.assert_array_equal(solver.fragments(), frag)
    assert len(calls) == 2


# ---------------------------------------------------------------------------------------------------- scene
def test_scene_with_several_lattice_bodies_and_default_settings_builds():
    """Through Scene.build_solvers: several lattice bodies (automatic contact) under the scene's default gravity
    build one SolverLattice; an explicit gravity, a ground plane or explicitly enabled contact are refused."""
    scene = pdsim.Scene(frames=2)
    scene.add_body(_pulled_block(name="a"))
    scene.add_body(_pulled_block(name="b", origin=(0.0, 20.0, 0.0)))
    assert isinstance(scene.build_solver(device="cpu"), SolverLattice)
    for make in (lambda s: s.enable_contact(), lambda s: s.add_ground_plane()):
        other = pdsim.Scene(frames=2)
        other.add_body(_pulled_block())
        make(other)
        with pytest.raises(FeatureNotAvailableError):
            other.build_solver(device="cpu")
    explicit = pdsim.Scene(frames=2, gravity=(0.0, 0.0, -9.81))
    explicit.add_body(_pulled_block())
    with pytest.raises(FeatureNotAvailableError, match="gravity"):
        explicit.build_solver(device="cpu")
