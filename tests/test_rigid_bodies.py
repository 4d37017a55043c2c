"""Dynamic rigid bodies (pdsim/rigid.py): mass properties against analytic values, free fall and free rotation,
resting contact, two-way momentum exchange with peridynamic and FEM bodies (also 1 km from the origin), an impact on
a breakable body that cannot throw its pieces faster than momentum and energy allow, and body-body contact."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pdsim
from pdsim.errors import FeatureNotAvailableError, ParameterError
from pdsim.rigid import BoxShape, RigidBodies, RigidBody, SphereShape, box_inertia, sphere_inertia
from pdsim.run import advance_frame, method_contact

import rigid_impacts  # tools/rigid_impacts.py (tests/conftest.py puts tools/ on the path)

STEEL = 7850.0  # kg/m^3


def _alone(bodies, gravity=(0.0, 0.0, 0.0), ground=None, device="cpu"):
    """RigidBodies of ``bodies`` alone (no solver), local frame at the world origin."""
    return RigidBodies(bodies, ground=ground, colliders=[], gravity=gravity, origin=np.zeros(3), device=device)


# -- mass properties ----------------------------------------------------------------------------------------------
def test_sphere_and_box_mass_properties_match_the_analytic_values_and_the_mesh_path():
    """Analytic shapes against the closed forms, and the mesh path (trimesh's mass properties) against them: a box mesh
    within 1e-9, turned by 30 degrees (its body-frame inertia is the axis-aligned one), a 5-level icosphere within 1 %
    (its volume is 0.3 % short of the sphere's)."""
    r = 0.02
    ball = RigidBody(SphereShape(r), density=STEEL)
    m = STEEL * 4.0 / 3.0 * math.pi * r**3
    assert ball.mass == pytest.approx(m, rel=1e-12)
    assert np.allclose(ball.inertia, 0.4 * m * r * r * np.eye(3), rtol=1e-12, atol=0.0)
    size = (0.3, 0.2, 0.1)
    box = RigidBody(BoxShape(size), mass=2.0)
    expected = np.diag([2.0 / 12.0 * (0.04 + 0.01), 2.0 / 12.0 * (0.09 + 0.01), 2.0 / 12.0 * (0.09 + 0.04)])
    assert np.allclose(box.inertia, expected, rtol=1e-12, atol=0.0)
    q = np.array([0.0, 0.0, math.sin(math.pi / 12.0), math.cos(math.pi / 12.0)])  # 30 degrees about z
    turned = pdsim.box(size, center=(5.0, -2.0, 1.0))
    v = turned.vertices - np.array([5.0, -2.0, 1.0])
    rot = np.array(
        [
            [math.cos(math.pi / 6), -math.sin(math.pi / 6), 0],
            [math.sin(math.pi / 6), math.cos(math.pi / 6), 0],
            [0, 0, 1],
        ]
    )
    turned = pdsim.shape_from_arrays(v @ rot.T + np.array([5.0, -2.0, 1.0]), turned.faces)
    mesh_box = RigidBody(turned, mass=2.0, orientation=q)
    assert np.allclose(mesh_box.inertia, box_inertia(2.0, size), rtol=0.0, atol=1e-9 * expected.max())
    assert np.allclose(mesh_box.position, [5.0, -2.0, 1.0], atol=1e-12)
    mesh_ball = RigidBody(pdsim.sphere(r, subdivisions=5), density=STEEL)
    assert mesh_ball.mass == pytest.approx(m, rel=0.01)
    assert np.allclose(mesh_ball.inertia, sphere_inertia(m, r), rtol=0.01, atol=1e-3 * sphere_inertia(m, r)[0, 0])
    with pytest.raises(ParameterError, match="density"):
        RigidBody(SphereShape(r), density=STEEL, mass=1.0)
    with pytest.raises(ParameterError, match="size"):
        RigidBody(BoxShape((0.1, 0.0, 0.1)), mass=1.0)


# -- integration alone -----------------------------------------------------------------------------------------------
def test_a_rigid_body_falls_by_g_t2_over_2_and_a_free_spin_keeps_its_angular_momentum():
    """Kick-drift-kick is exact for a constant acceleration: z(t) = z0 - g t^2 / 2 and v = -g t to round-off (1e-12
    relative). A box spinning about a non-principal axis keeps its angular momentum to round-off and its rotational
    energy within 1 % over 400 steps of 1 ms at 5 rad/s."""
    g = 9.81
    ball = RigidBody(SphereShape(0.05), density=STEEL, position=(1.0, 2.0, 3.0), velocity=(0.5, 0.0, 0.0))
    system = _alone([ball], gravity=(0.0, 0.0, -g))
    dt, steps = 1.0e-3, 500
    system.simulate(dt, steps)
    t = dt * steps
    s = ball.state_values()
    assert s["position"] == pytest.approx([1.0 + 0.5 * t, 2.0, 3.0 - 0.5 * g * t * t], rel=1e-12, abs=1e-12)
    assert s["velocity"] == pytest.approx([0.5, 0.0, -g * t], rel=1e-12, abs=1e-12)
    box = RigidBody(BoxShape((0.3, 0.2, 0.1)), mass=1.0, angular_velocity=(3.0, 4.0, 0.0))
    spin = _alone([box])
    L0, e0 = box.angular_momentum(), box.kinetic_energy()
    spin.simulate(dt, 400)
    assert np.allclose(box.angular_momentum(), L0, rtol=0.0, atol=1e-12 * np.linalg.norm(L0))
    assert box.kinetic_energy() == pytest.approx(e0, rel=0.01)
    assert not np.allclose(box.state_values()["angular_velocity"], [3.0, 4.0, 0.0], atol=0.1)  # it tumbles


def test_a_ball_and_a_box_resting_on_the_ground_stay_without_gaining_energy():
    """A ball and a box placed on the ground under gravity: over 2000 steps of 1 ms neither sinks, drifts or gains
    energy: height within g dt^2 of contact, horizontal drift below 1e-9 m, speed below g dt."""
    g, dt = 9.81, 1.0e-3
    ground = pdsim.GroundPlane(normal=(0.0, 0.0, 1.0), offset=0.0)
    ball = RigidBody(SphereShape(0.05), density=STEEL, position=(0.0, 0.0, 0.05))
    box = RigidBody(BoxShape((0.2, 0.1, 0.1)), density=1000.0, position=(1.0, 0.0, 0.05))
    system = _alone([ball, box], gravity=(0.0, 0.0, -g), ground=ground)
    for _ in range(4):
        system.simulate(dt, 500)
        for body, x0 in ((ball, (0.0, 0.0, 0.05)), (box, (1.0, 0.0, 0.05))):
            s = body.state_values()
            assert abs(s["position"][2] - x0[2]) <= g * dt * dt
            assert np.allclose(s["position"][:2], x0[:2], atol=1e-9)
            assert np.linalg.norm(s["velocity"]) <= g * dt
            assert np.linalg.norm(s["angular_velocity"]) <= 1e-9


def test_bodies_collide_with_each_other_conserving_momentum_and_stack_on_the_ground(device):
    """Sphere-sphere head-on in space: momentum conserved to 1e-12, the inelastic contact leaves both at v/2 (1e-9).
    A box dropped onto a box on the ground comes to rest on it: the top box's centre ends one box height above the
    lower one's within 1 mm, at rest (speed < 0.05 m/s)."""
    a = RigidBody(SphereShape(0.05), density=STEEL, position=(-0.2, 0.0, 0.0), velocity=(2.0, 0.0, 0.0), friction=0.0)
    b = RigidBody(SphereShape(0.05), density=STEEL, position=(0.0, 0.0, 0.0), friction=0.0)
    system = _alone([a, b], device=device)
    p0 = system.linear_momentum()
    system.simulate(1.0e-3, 200)
    assert np.allclose(system.linear_momentum(), p0, rtol=0.0, atol=1e-12 * np.linalg.norm(p0))
    assert a.state_values()["velocity"] == pytest.approx([1.0, 0.0, 0.0], abs=1e-9)
    assert b.state_values()["velocity"] == pytest.approx([1.0, 0.0, 0.0], abs=1e-9)
    g = 9.81
    ground = pdsim.GroundPlane(normal=(0.0, 0.0, 1.0), offset=0.0)
    low = RigidBody(BoxShape((0.2, 0.2, 0.1)), density=1000.0, position=(0.0, 0.0, 0.05))
    top = RigidBody(BoxShape((0.1, 0.1, 0.1)), density=1000.0, position=(0.01, 0.0, 0.2))
    stack = _alone([low, top], gravity=(0.0, 0.0, -g), ground=ground, device=device)
    stack.simulate(1.0e-3, 800)
    assert top.state_values()["position"][2] == pytest.approx(0.15, abs=1e-3)
    assert low.state_values()["position"][2] == pytest.approx(0.05, abs=1e-3)
    assert np.linalg.norm(top.state_values()["velocity"]) < 0.05


# -- two-way contact with deformable bodies --------------------------------------------------------------------------
def _impact(method: str, shift, device="cpu"):
    """A steel ball (r 2 cm, 10 m/s along x, 2 cm off the block's centre line) hits a free elastic 10 cm block
    (2.4 kg, E 30 MPa) in space; returns (scene, ball, solvers, a fixed point for the angular momentum)."""
    shift = np.asarray(shift, dtype=np.float64)
    scene = pdsim.Scene(gravity=(0.0, 0.0, 0.0), fps=1000)
    material = pdsim.Material(density=2400.0, youngs_modulus=3.0e7, poisson_ratio=0.2, name="elastic")
    if method == "pd":
        scene.add_peridynamic_body(pdsim.box((0.1, 0.1, 0.1), center=shift), material, 0.02, name="block")
    else:
        mesh = pdsim.box_tet_mesh((0.1, 0.1, 0.1), (3, 3, 3), center=shift)
        scene.add_fem_body(mesh, material, name="block")
    ball = scene.add_rigid_body(
        SphereShape(0.02),
        density=STEEL,
        position=shift + np.array([-0.071, 0.02, 0.0]),
        velocity=(10.0, 0.0, 0.0),
        name="ball",
    )
    solvers = scene.build_solvers(device=device)
    point = shift + np.array([0.0, -0.05, 0.03])  # a fixed point off every line of the motion
    return scene, ball, solvers, point


def _totals(ball, solvers, point):
    p = ball.linear_momentum() + sum(s.linear_momentum() for s in solvers)
    L = ball.angular_momentum(point) + sum(s.angular_momentum(point) for s in solvers)
    return p, L


def _kinetic(body, solvers) -> float:
    return body.kinetic_energy() + sum(s.kinetic_energy() for s in solvers)


@pytest.mark.parametrize("method", ["pd", "fem"])
def test_a_rigid_ball_hitting_a_free_block_conserves_momentum_anywhere(method, device):
    """Linear momentum within 0.5 % and angular momentum (about a fixed point off the line of the impact) within 1 %
    of their initial values (measured: about 1e-7 each, docs/rigid_impacts.md); the ball's loss of momentum equals
    the block's gain within 0.5 % of the initial momentum, and the ball loses at least a third of its speed (with a
    kinematic ball, pdsim.SphereProjectile, the block gains momentum from nowhere: the same check fails by 100 %).
    The kinetic energy falls (inelastic contact; a full projection of the points out of the ball, the kinematic
    colliders' law, gains energy here and fails it). Run with the scene at the origin and 1 km from it: the ball's
    final velocity agrees within 1e-4 m/s."""
    finals = []
    for shift in ((0.0, 0.0, 0.0), (1000.0, 0.0, 0.0)):
        scene, ball, solvers, point = _impact(method, shift, device)
        dt = 0.7 * min(s.stable_time_step() for s in solvers)
        steps = math.ceil(0.03 / dt)  # the ball's travel to contact, the contact and the separation
        p0, L0 = _totals(ball, solvers, point)
        ball_p0, e0 = ball.linear_momentum(), _kinetic(ball, solvers)
        advance_frame(solvers, dt, steps, method_contact(scene, solvers))
        p1, L1 = _totals(ball, solvers, point)
        assert _kinetic(ball, solvers) < e0  # the contact is inelastic
        scale_p, scale_L = np.linalg.norm(p0), np.linalg.norm(L0)
        assert np.linalg.norm(p1 - p0) <= 0.005 * scale_p
        assert np.linalg.norm(L1 - L0) <= 0.01 * scale_L
        block_gain = sum(s.linear_momentum() for s in solvers)
        assert np.linalg.norm((ball.linear_momentum() - ball_p0) + block_gain) <= 0.005 * scale_p
        v = ball.state_values()["velocity"]
        assert v[0] < 10.0 * (2.0 / 3.0)
        finals.append(v)
    assert np.allclose(finals[0], finals[1], atol=1e-4)


def test_a_ball_cannot_throw_a_heavy_breakable_body_faster_than_momentum_and_energy_allow():
    """A 0.2 kg steel ball at v0 = 15 m/s hits a resting 10 kg breakable concrete block on the ground. The block's
    centre of mass cannot take more than a perfectly elastic collision gives, 2 m_b v0 / (m_b + M) = 0.59 m/s
    (horizontally), and no fragment of mass m can carry more kinetic energy than the ball brought plus the work
    gravity can do on it over the block's height H: v <= sqrt((m_b v0^2 + 2 m g H) / m). A kinematic ball
    (pdsim.SphereProjectile, infinite mass) fails the first bound."""
    m_ball, v0, g = rigid_impacts.FIGURINE_BALL_MASS, rigid_impacts.FIGURINE_BALL_SPEED, 9.81
    material = pdsim.presets.concrete(pattern=False)  # no debris damping: it would slow the kinematic control
    solver, edge = rigid_impacts.figurine_run(kinematic=False, material=material)
    mass, v = solver.masses(), solver.velocities()
    M = float(mass.sum())
    assert pytest.approx(10.0, rel=0.05) == M
    bound = 2.0 * m_ball * v0 / (m_ball + M)
    com = mass @ v / M
    assert 0.0 < com[0] <= bound
    ids = solver.fragment_ids()
    for f in np.unique(ids):
        sel = ids == f
        m = float(mass[sel].sum())
        speed = float(np.linalg.norm(mass[sel] @ v[sel] / m))
        assert speed <= math.sqrt((m_ball * v0**2 + 2.0 * m * g * edge) / m)
    kinematic_solver, _ = rigid_impacts.figurine_run(kinematic=True, material=material)
    km = kinematic_solver.masses()
    assert (km @ kinematic_solver.velocities() / float(km.sum()))[0] > bound


# -- refusals ---------------------------------------------------------------------------------------------------------
def test_rigid_bodies_refuse_what_they_cannot_honour():
    """A kinematic projectile beside a rigid body, and a lattice body (massless, position-based: no force to
    exchange) with one, raise FeatureNotAvailableError."""
    scene = pdsim.Scene(gravity=(0.0, 0.0, 0.0))
    scene.add_peridynamic_body(pdsim.box((0.1, 0.1, 0.1)), pdsim.presets.concrete(), 0.02, name="block")
    scene.add_rigid_body(SphereShape(0.02), density=STEEL, position=(-0.2, 0.0, 0.0))
    scene.add_collider(pdsim.SphereProjectile(0.02, (0.2, 0.0, 0.0)))
    with pytest.raises(FeatureNotAvailableError, match="kinematic projectiles"):
        scene.build_solvers(device="cpu", check=False)
    lattice = pdsim.Scene(gravity=(0.0, 0.0, 0.0))
    lattice.add_body(pdsim.LatticeBody.block(pdsim.Lattice.simple_cubic(0.01), (4, 4, 4), name="block"))
    lattice.add_rigid_body(SphereShape(0.01), density=STEEL, position=(-0.1, 0.0, 0.0))
    with pytest.raises(FeatureNotAvailableError, match="rigid bodies"):
        lattice.build_solvers(device="cpu")


def test_a_rigid_impact_is_bit_identical_on_one_and_three_threads(monkeypatch):
    """The sphere's impact on the peridynamic block with the bond passes on 1 and 3 CPU threads (PDSIM_THREADS): the
    block's velocities and the ball's state are equal bit for bit (the collision kernels' atomics run in one launch)."""
    results = []
    for threads in ("1", "3"):
        monkeypatch.setenv("PDSIM_THREADS", threads)
        scene, ball, solvers, _ = _impact("pd", (0.0, 0.0, 0.0))
        assert solvers[0].threads == int(threads)
        dt = 0.7 * solvers[0].stable_time_step()
        advance_frame(solvers, dt, 60, method_contact(scene, solvers))
        results.append((solvers[0].velocities().tobytes(), ball.state.numpy().tobytes()))
    assert results[0] == results[1]


@pytest.mark.parametrize("shape", ["box", "mesh"])
def test_a_rigid_box_and_a_rigid_mesh_hitting_a_free_block_conserve_momentum(shape):
    """The box (analytic) and a closed mesh (an icosphere through the mesh query) into the free peridynamic block of
    the sphere's test, 2 cm off its centre line: linear momentum within 0.5 %, angular momentum within 1 %, kinetic
    energy falling, the body slowed by at least a quarter."""
    scene = pdsim.Scene(gravity=(0.0, 0.0, 0.0), fps=1000)
    material = pdsim.Material(density=2400.0, youngs_modulus=3.0e7, poisson_ratio=0.2, name="elastic")
    scene.add_peridynamic_body(pdsim.box((0.1, 0.1, 0.1)), material, 0.02, name="block")
    start = np.array([-0.075, 0.02, 0.0])
    if shape == "box":
        body = scene.add_rigid_body(BoxShape((0.04, 0.04, 0.04)), density=STEEL, position=start, velocity=(10, 0, 0))
    else:
        body = scene.add_rigid_body(pdsim.sphere(0.02, center=start, subdivisions=2), density=STEEL,
                                    velocity=(10.0, 0.0, 0.0))  # fmt: skip
    solvers = scene.build_solvers(device="cpu")
    point = np.array([0.0, -0.05, 0.03])
    p0, L0 = _totals(body, solvers, point)
    e0 = _kinetic(body, solvers)
    dt = 0.7 * min(s.stable_time_step() for s in solvers)
    advance_frame(solvers, dt, math.ceil(0.03 / dt), method_contact(scene, solvers))
    p1, L1 = _totals(body, solvers, point)
    assert _kinetic(body, solvers) < e0
    assert np.linalg.norm(p1 - p0) <= 0.005 * np.linalg.norm(p0)
    assert np.linalg.norm(L1 - L0) <= 0.01 * np.linalg.norm(L0)
    assert body.state_values()["velocity"][0] < 7.5


def test_a_mesh_body_rests_on_the_ground_and_a_ball_rests_on_it():
    """A closed mesh body (a 10 cm box given as triangles: its vertices are its samples) dropped onto the ground, and
    a ball dropped onto it (the ball's centre sample against the mesh's query): after 0.8 s the mesh's centre is at
    half its height and the ball's one radius above its top, within 1 mm, both at rest (< 0.05 m/s)."""
    g = 9.81
    ground = pdsim.GroundPlane(normal=(0.0, 0.0, 1.0), offset=0.0)
    crate = RigidBody(pdsim.box((0.1, 0.1, 0.1), center=(0.0, 0.0, 0.08)), density=500.0)
    ball = RigidBody(SphereShape(0.02), density=STEEL, position=(0.01, 0.0, 0.2))
    system = _alone([crate, ball], gravity=(0.0, 0.0, -g), ground=ground)
    system.simulate(1.0e-3, 800)
    assert crate.state_values()["position"][2] == pytest.approx(0.05, abs=1e-3)
    assert ball.state_values()["position"][2] == pytest.approx(0.12, abs=1e-3)
    for body in (crate, ball):
        assert np.linalg.norm(body.state_values()["velocity"]) < 0.05


def test_a_rigid_box_resting_on_a_peridynamic_slab_does_not_sink():
    """A 6 cm steel box set on an elastic slab (h 2 cm) lying on the ground: over 0.1 s its centre stays within
    0.05 mm of where it settles after the first 25 ms (a point moved only by its velocity change, without
    kernels/colliders.py's PUSH_OUT_RATE, lets it sink 0.26 mm in that time) and the kinetic energy stays below
    1e-4 J."""
    scene = pdsim.Scene(fps=100)
    material = pdsim.Material(density=2400.0, youngs_modulus=3.0e7, poisson_ratio=0.2, name="elastic")
    scene.add_ground_plane()
    scene.add_peridynamic_body(pdsim.box((0.2, 0.2, 0.04), center=(0.0, 0.0, 0.02)), material, 0.02, name="slab")
    box = scene.add_rigid_body(BoxShape((0.06, 0.06, 0.06)), density=STEEL, position=(0.0, 0.0, 0.0705))
    solvers = scene.build_solvers(device="cpu")
    dt = 0.7 * solvers[0].stable_time_step()
    coupling = method_contact(scene, solvers)
    advance_frame(solvers, dt, math.ceil(0.025 / dt), coupling)
    z0 = box.state_values()["position"][2]
    for _ in range(4):
        advance_frame(solvers, dt, math.ceil(0.025 / dt), coupling)
        assert abs(box.state_values()["position"][2] - z0) < 5.0e-5
        assert _kinetic(box, solvers) < 1.0e-4


def test_a_ball_rests_on_a_static_mesh_collider():
    """A steel ball dropped 5 cm onto a static box mesh (MeshCollider) comes to rest on its top face: centre one
    radius above it within 1 mm, speed below 0.05 m/s after 0.5 s."""
    top = pdsim.box((0.4, 0.4, 0.1), center=(0.0, 0.0, -0.05))
    table = pdsim.MeshCollider(top)
    ball = RigidBody(SphereShape(0.05), density=STEEL, position=(0.02, 0.0, 0.1))
    system = RigidBodies([ball], ground=None, colliders=[table], gravity=(0.0, 0.0, -9.81), origin=np.zeros(3),
                         device="cpu")  # fmt: skip
    system.simulate(1.0e-3, 500)
    s = ball.state_values()
    assert s["position"] == pytest.approx([0.02, 0.0, 0.05], abs=1e-3)
    assert np.linalg.norm(s["velocity"]) < 0.05
