"""Contact between bodies of different methods (pdsim.contact.MethodContact): a peridynamic body against an FEM body's
surface, with momentum exchanged through equal and opposite forces inside each step."""

import numpy as np
import pytest

import pdsim
from pdsim.run import advance_frame, method_contact

SOFT = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)
H = 0.01  # particle spacing [m]


def _scene(pd_on_top: bool, *, gravity=(0.0, 0.0, 0.0), ground: bool = False, speed: float = 1.0):
    """A 6 x 6 x 6 cm body falling at ``speed`` onto a 24 x 24 x 4 cm slab 5 mm below it. pd_on_top: a peridynamic
    cube onto an FEM slab (12 x 12 x 2 cubes of 6 tetrahedra); otherwise an FEM cube (3 x 3 x 3 cubes) onto a
    peridynamic slab (h = 1 cm)."""
    scene = pdsim.Scene(fps=24.0, frames=1, gravity=gravity)
    slab_c, cube_c = np.array([0.0, 0.0, 0.02]), np.array([0.0, 0.0, 0.04 + 0.005 + 0.03])
    if pd_on_top:
        cube = scene.add_peridynamic_body(pdsim.box((0.06, 0.06, 0.06), center=cube_c), SOFT, H, name="cube")
        slab = scene.add_body(
            pdsim.FemBody(pdsim.box_tet_mesh((0.24, 0.24, 0.04), (12, 12, 2), center=slab_c), SOFT, name="slab")
        )
    else:
        cube = scene.add_body(
            pdsim.FemBody(pdsim.box_tet_mesh((0.06, 0.06, 0.06), (3, 3, 3), center=cube_c), SOFT, name="cube")
        )
        slab = scene.add_peridynamic_body(pdsim.box((0.24, 0.24, 0.04), center=slab_c), SOFT, H, name="slab")
    cube.set_initial_velocity((0.0, 0.0, -speed))
    if ground:
        scene.add_ground_plane(height=0.0, friction=0.0)
    return scene, cube, slab


def _by_name(solvers, name):
    for s in solvers:
        if any(b.name == name for b in s.bodies):
            return s
    raise KeyError(name)


def _penetration(pd_solver, fem_solver) -> float:
    """Deepest a peridynamic particle's cell reaches into the FEM surface [m] (0 when none does): signed distance of
    each particle centre to the FEM boundary (trimesh), minus the particle's half spacing."""
    import trimesh

    ids, tri, _ = fem_solver.contact_mesh()
    x_fem = fem_solver.positions()[ids.numpy()]
    mesh = trimesh.Trimesh(x_fem, tri.numpy().reshape(-1, 3), process=False)
    x_pd = pd_solver.positions()
    near = np.all((x_pd > mesh.bounds[0] - 2 * H) & (x_pd < mesh.bounds[1] + 2 * H), axis=1)
    if not near.any():
        return 0.0
    inside = trimesh.proximity.signed_distance(mesh, x_pd[near])  # positive inside
    return float(max(0.0, (inside + 0.5 * H).max()))


def _run(scene, cube_name, slab_name, duration, *, check_every=20):
    solvers = scene.build_solvers(device="cpu")
    coupling = method_contact(scene, solvers)
    assert coupling is not None
    dt = scene.time_step_safety * min(s.stable_time_step() for s in solvers)
    steps = int(duration / dt)
    cube, slab = _by_name(solvers, cube_name), _by_name(solvers, slab_name)
    pd = cube if isinstance(cube, pdsim.SolverPeridynamics) else slab
    fem = slab if pd is cube else cube
    p0 = sum(s.linear_momentum() for s in solvers)
    depth = 0.0
    for k in range(0, steps, check_every):
        advance_frame(solvers, dt, min(check_every, steps - k), coupling)
        depth = max(depth, _penetration(pd, fem))
    return solvers, cube, slab, p0, depth, steps * dt


@pytest.mark.parametrize("pd_on_top", [True, False], ids=["pd-cube-on-fem-slab", "fem-cube-on-pd-slab"])
def test_cube_bounces_off_a_slab_of_the_other_method(pd_on_top):
    """In free space a cube thrown at 1 m/s onto a slab of the other method bounces: its vertical momentum reverses
    (to more than 10 % of the incoming momentum: measured 27 % PD-on-FEM and 18 % FEM-on-PD, the thin soft slab
    keeps the rest of the energy as vibration) while the slab is pushed down; no particle cell sinks more than one
    spacing into the FEM surface (measured 0.6 mm at h = 1 cm); the two bodies' total momentum stays within 2 % of
    its initial value (the contact force acts on both sides equally and oppositely: measured to float32
    round-off)."""
    scene, *_ = _scene(pd_on_top)
    solvers, cube, slab, p0, depth, _ = _run(scene, "cube", "slab", 0.02)
    p1 = sum(s.linear_momentum() for s in solvers)
    assert cube.linear_momentum()[2] > 0.1 * abs(p0[2])  # bounced: moving up
    assert slab.linear_momentum()[2] < 0.0
    assert np.linalg.norm(p1 - p0) < 0.02 * np.linalg.norm(p0)
    assert depth < H


def test_dropped_cube_momentum_balances_gravity_and_the_ground_impulse():
    """A peridynamic cube dropped onto an FEM slab that rests on the ground, under gravity: the change of the two
    bodies' total momentum equals the weight's impulse plus the ground's impulse (GroundPlane.impulse, the momentum
    the plane removed) within 2 % of the weight's impulse; the cube bounces off the slab."""
    scene, _, _ = _scene(True, gravity=(0.0, 0.0, -9.81), ground=True)
    solvers, cube, _, p0, depth, t = _run(scene, "cube", "slab", 0.02)
    p1 = sum(s.linear_momentum() for s in solvers)
    mass = sum(float(s.masses().sum()) for s in solvers)
    weight_impulse = np.array([0.0, 0.0, -9.81 * mass * t])
    ground = scene.ground.impulse
    assert ground[2] > 0.0
    np.testing.assert_allclose(p1 - p0, weight_impulse + ground, atol=0.02 * abs(weight_impulse[2]))
    assert cube.linear_momentum()[2] > 0.0
    assert depth < H


def test_implicit_fem_cannot_take_part_in_contact_between_methods():
    """The implicit FEM step solves before contact forces exist: a scene pairing it with a peridynamic body raises
    FeatureNotAvailableError naming the body and the setting before anything is simulated."""
    scene = pdsim.Scene(gravity=(0.0, 0.0, 0.0))
    scene.add_peridynamic_body(pdsim.box((0.04, 0.04, 0.04), center=(0.0, 0.0, 0.1)), SOFT, H, name="cube")
    scene.add_body(
        pdsim.FemBody(pdsim.box_tet_mesh((0.2, 0.2, 0.04), (5, 5, 1)), SOFT, integrator="implicit", name="slab")
    )
    solvers = scene.build_solvers(device="cpu")
    with pytest.raises(pdsim.FeatureNotAvailableError) as ei:
        method_contact(scene, solvers)
    assert "'slab'" in str(ei.value) and "implicit" in str(ei.value)


@pytest.mark.parametrize("pd_on_top", [True, False], ids=["pd-cube-on-fem-slab", "fem-cube-on-pd-slab"])
def test_contact_between_methods_runs_under_the_watchdog(tmp_path, pd_on_top):
    """The same impact through Scene.run, whose watchdog checks each body's energy against the work put into it:
    the energy the cube hands the slab through contact is counted as work put into the slab (the positive part of
    the contact force's work on each side, kernels/contact.py), so the run ends normally instead of stopping with
    "energy rose with nothing putting work in" (which it did before contact work was counted). The slab's work
    account holds at least the kinetic energy it ended with."""
    scene, *_ = _scene(pd_on_top)
    scene.frame_time = 0.02
    solvers = {}

    def keep(frame, run_solvers):
        solvers.update({b.name: s for s in run_solvers for b in s.bodies})

    report = scene.run(str(tmp_path / "impact.usdc"), progress=False, on_frame=keep)
    assert report.frames_written == 2
    slab = solvers["slab"]
    work = slab.watchdog.last["work"]
    v = slab.velocities()
    kinetic = 0.5 * float((slab.masses() * (v * v).sum(axis=1)).sum())
    assert kinetic > 0.0 and work >= kinetic, (work, kinetic)
