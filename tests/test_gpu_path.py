"""The GPU path (docs/architecture.md, GPU path): a frame's steps read nothing from the device, take their time from
the kinematics' device clock and their projectile poses from a table written before the frame, so that a frame can be
captured once and replayed (pdsim/capture.py); fragments are labelled on the device (pdsim/fragment_labels.py).

Warp records and replays graphs on the CPU too, so the capture path runs here: a replayed frame must give the same
state, bit for bit, as the frame launched step by step. The CPU/CUDA agreement tests and the CUDA capture test run
where CUDA is present (``tools/gpu_suite.sh`` runs them on a borrowed GPU).
"""

import numpy as np
import pytest
import warp as wp

import pdsim
from pdsim.capture import FrameGraphs
from pdsim.colliders import SphereProjectile
from pdsim.fragment_labels import (
    DeviceLabeller,
    FragmentTracker,
    connected_components,
    fragment_labels,
    labels_from_roots,
)
from pdsim.lattice import Lattice, LatticeBody, LatticeFracture, LatticeKind
from pdsim.run import advance_frame, method_contact

HAS_CUDA = wp.get_cuda_device_count() > 0
needs_cuda = pytest.mark.skipif(not HAS_CUDA, reason="needs a CUDA device")

MAT = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.25)
H = 0.01


@pytest.fixture(autouse=True)
def _one_thread(monkeypatch):
    """Peridynamics on one CPU thread: a capture records the launches of its own thread only (with more threads the
    solver's graph_capture_blocker turns capture off, see test_threaded_peridynamics_is_not_captured)."""
    monkeypatch.setenv("PDSIM_THREADS", "1")


def _random_csr(rng, n, max_degree=6, live=0.5):
    degree = rng.integers(0, max_degree + 1, size=n)
    offsets = np.concatenate([[0], np.cumsum(degree)]).astype(np.int32)
    neighbors = rng.integers(0, n, size=int(offsets[-1])).astype(np.int32)
    alive = (rng.random(int(offsets[-1])) < live).astype(np.uint8)
    return degree, offsets, neighbors, alive


# -- (b) fragment labelling on the device --------------------------------------------------------------------------
def test_device_labels_equal_scipy_components_on_random_graphs(device):
    """Random CSR graphs (1-400 nodes, 0-6 edges a node, half of them live, then a third of those broken): the device
    labeller's roots give exactly scipy's components (connected_components, numbered by smallest node) and the
    fragment labels of both numberings."""
    rng = np.random.default_rng(7)
    for n in (1, 2, 17, 150, 400):
        degree, offsets, neighbors, alive = _random_csr(rng, n)
        labeller = DeviceLabeller(offsets, neighbors, wp.array(alive, dtype=wp.uint8, device=device))
        for _ in range(2):
            roots = labeller.roots().numpy()
            src = np.repeat(np.arange(n), degree)
            live = alive != 0
            expected = connected_components(n, src[live], neighbors[live])
            assert np.array_equal(labels_from_roots(roots, [0, n]), expected)
            assert np.array_equal(
                labels_from_roots(roots, [0, n], compact=False),
                fragment_labels(offsets, neighbors, alive, compact=False),
            )
            alive = alive & (rng.random(alive.shape[0]) < 0.67).astype(np.uint8)
            labeller.alive.assign(alive)


def test_fragment_tracker_on_device_equals_host_tracker(device):
    """Two bodies of random bonds (edges kept inside each body): a FragmentTracker updated with a Warp array (device
    labelling, one count and one label read) gives the host tracker's labels, version and change flags."""
    rng = np.random.default_rng(3)
    sizes = (60, 90)
    offsets, neighbors, base = [0], [], 0
    for size in sizes:
        for _ in range(size):
            k = int(rng.integers(0, 5))
            neighbors += list(base + rng.integers(0, size, size=k))
            offsets.append(offsets[-1] + k)
        base += size
    offsets = np.asarray(offsets, dtype=np.int32)
    neighbors = np.asarray(neighbors, dtype=np.int32)
    body_offsets = np.array([0, sizes[0], sum(sizes)])
    alive = np.ones(neighbors.shape[0], dtype=np.uint8)
    host = FragmentTracker(offsets, neighbors, body_offsets, compact=False)
    dev = FragmentTracker(
        wp.array(offsets, dtype=wp.int32, device=device),
        wp.array(neighbors, dtype=wp.int32, device=device),
        body_offsets,
        compact=False,
    )
    alive_wp = wp.array(alive, dtype=wp.uint8, device=device)
    for _ in range(4):
        assert dev.update(alive_wp) == host.update(alive)
        assert np.array_equal(dev.labels, host.labels)
        assert dev.version == host.version
        alive = alive & (rng.random(alive.shape[0]) < 0.6).astype(np.uint8)
        alive_wp.assign(alive)


# -- (a) time curves, kicks, prescribed velocities and projectiles on the device clock -----------------------------
def _free_block(scene, **kwargs):
    return scene.add_peridynamic_body(pdsim.box((4 * H, 3 * H, 3 * H)), MAT, H, name="block", **kwargs)


def test_load_curve_and_kick_follow_the_device_clock():
    """A free block (no gravity) under a body force scaled by a table curve, kicked at t_kick, over 4 frames stepped
    by the scene (frame 1 launched step by step as the first of its configuration, frame 2 too as it holds the
    kick, frame 3 captured, frame 4 replayed: the device clock must advance in the replay). Internal forces sum to
    zero, so the momentum is the velocity-Verlet sum of the load,
    P_N = M dt sum_k (g(t_k) + g(t_{k+1})) / 2 (a trapezoid sum of the curve at the step ends), plus M dv from the
    kick's step on; checked within 1e-5 relative at each frame end."""
    scene = pdsim.Scene(fps=24.0, frames=4, gravity=(0.0, 0.0, 0.0), graph_capture=True, frame_time=3.0e-4)
    body = _free_block(scene)
    curve = pdsim.TimeCurve.table([0.0, 2.0e-4, 5.0e-4, 8.0e-4], [0.0, 1.0, -0.5, 0.25])
    accel = np.array([2.0, -1.0, 0.5])
    body.add_body_force(accel, curve=curve)
    t_kick, dv = 4.3e-4, np.array([0.0, 0.3, 0.0])
    body.add_velocity_kick(dv, time=t_kick)
    (solver,) = scene.build_solvers(device="cpu")
    graphs = FrameGraphs("cpu", True)
    substeps = 12
    dt = scene.frame_time / substeps
    assert dt < solver.stable_time_step()
    mass = solver.masses().sum()
    times = [0.0]
    modes = []
    for _ in range(4):
        graphs_state = (graphs.captures, graphs.replays)
        advance_frame([solver], dt, substeps, graphs=graphs)
        modes.append((graphs.captures - graphs_state[0], graphs.replays - graphs_state[1]))
        for _ in range(substeps):
            times.append(times[-1] + dt)
        g = np.array([np.interp(t, curve.times, curve.values) for t in times])
        impulse = mass * dt * np.sum(0.5 * (g[:-1] + g[1:])) * accel
        kicked = any(t <= t_kick < t + dt for t in times[:-1])
        expected = impulse + (mass * dv if kicked else 0.0)
        assert solver.linear_momentum() == pytest.approx(expected, rel=1.0e-5, abs=1.0e-9 * mass)
        assert solver.time == times[-1]
    assert modes == [(0, 0), (0, 0), (1, 0), (0, 1)]


def test_prescribed_velocity_ramp_is_integrated_at_mid_step_times():
    """Points held by a velocity ramped from 0 to 0.2 m/s over 0.5 ms: after each frame their displacement is
    sum_k dt v(t_k + dt/2), the midpoint rule of the conditions' mid-step time, within 1e-5 relative (float32), in
    frames launched step by step, captured and replayed; the rule itself is the ramp's analytic integral but for the
    step holding the ramp's end."""
    scene = pdsim.Scene(fps=24.0, frames=4, gravity=(0.0, 0.0, 0.0), graph_capture=True, frame_time=3.0e-4)
    body = _free_block(scene)
    x = body.rest_positions[:, 0]
    ramp = pdsim.TimeCurve.ramp(5.0e-4)
    body.set_velocity(
        pdsim.BoxRegion(lo=(x.max() - 0.5 * H, -1, -1), hi=(1, 1, 1)), (0.2, 0.0, 0.0), axes="x", curve=ramp
    )
    (solver,) = scene.build_solvers(device="cpu")
    graphs = FrameGraphs("cpu", True)
    held = x > x.max() - 0.5 * H
    substeps = 10
    dt = scene.frame_time / substeps
    starts = [0.0]
    for frame in range(1, 5):
        advance_frame([solver], dt, substeps, graphs=graphs)
        for _ in range(substeps):
            starts.append(starts[-1] + dt)
        mid = np.array(starts[:-1]) + 0.5 * dt
        midpoint = float(np.sum(dt * 0.2 * np.clip(mid / 5.0e-4, 0.0, 1.0)))
        t = frame * scene.frame_time
        exact = 0.2 * (t * t / (2 * 5.0e-4) if t <= 5.0e-4 else 5.0e-4 / 2 + (t - 5.0e-4))
        u = solver.displacements()[held, 0]
        assert u == pytest.approx(np.full(u.shape, midpoint), rel=1.0e-5)
        # the midpoint rule errs only in the step holding the ramp's end: dt^2 v_max / (8 * 0.5 ms) at most
        assert midpoint == pytest.approx(exact, abs=dt * dt * 0.2 / (8 * 5.0e-4) + 1.0e-15)
    assert graphs.captures == 1 and graphs.replays == 2


def test_projectile_pose_table_gives_the_analytic_pose_each_step():
    """A ballistic sphere (velocity, spin and gravity): in a frame prepared by begin_frame, the motion each step
    copies on the device equals the analytic pose at the step's end (position to 1e-6 m in float32, quaternion to
    1e-6) and its velocity the mean velocity over the step; a step outside a frame program writes the same."""
    proj = SphereProjectile(
        0.01, (0.1, 0.0, 0.2), velocity=(3.0, 0.0, -1.0), angular_velocity=(0.0, 50.0, 0.0), gravity=(0.0, 0.0, -9.81)
    )
    proj.bind(np.array([0.05, 0.0, 0.1]))
    rest = wp.zeros(1, dtype=wp.vec3)
    zeros = wp.zeros(1, dtype=wp.vec3)
    radius = wp.zeros(1, dtype=float)
    kind = wp.zeros(1, dtype=wp.int32)
    dt, steps, t = 1.0e-3, 5, 0.0
    proj.begin_frame(0.0, dt, steps)
    for _ in range(steps):
        t_end = t + dt
        proj.apply(rest, wp.zeros_like(zeros), wp.zeros_like(zeros), radius, kind, t_end, dt)
        m = proj._motion.array.numpy()[0]
        p, q = proj.pose(t_end)
        p0, _ = proj.pose(t)
        assert np.allclose(m["pose"][:3], p - proj.origin, atol=1.0e-6)
        assert np.allclose(m["pose"][3:], q, atol=1.0e-6)
        assert np.allclose(m["linear_velocity"], (p - p0) / dt, rtol=1.0e-5)
        t = t_end
    other = SphereProjectile(0.01, (0.1, 0.0, 0.2), velocity=(3.0, 0.0, -1.0), gravity=(0.0, 0.0, -9.81))
    other.bind(np.array([0.05, 0.0, 0.1]))
    other.apply(rest, wp.zeros_like(zeros), wp.zeros_like(zeros), radius, kind, 2.0 * dt, dt)  # scratch row
    assert np.allclose(other._motion.array.numpy()[0]["pose"][:3], other.pose(2.0 * dt)[0] - other.origin, atol=1e-6)


# Computed with the code before the device clock and the pose tables (commit c109d27, the same scene and steps, CPU):
# sums over the vertices of u [m] and v [m/s], and the two conditions' reactions [N] at the end.
_REFERENCE_BEFORE = {
    "u_sum": [0.001963153937204254, 0.0004249711732882133, 0.0020964467421435984],
    "v_sum": [4.580547909252346, 1.9970425870269537, -14.340196188539267],
    "reactions": [
        [0.08624163269996643, -0.15776532143354416, -1.9881922379136086],
        [2.6471985429525375, -0.17540500592440367, -1.9678325951099396],
    ],
}


def test_loads_kick_conditions_and_projectile_give_the_results_of_before():
    """An FEM bar held at one end, its other end moved by a ramped velocity, under a ramped body force, kicked at
    0.25 ms and hit by a falling sphere, 4 frames of 7 steps: the state equals the one computed before the time moved
    to the device (launch arguments then; _REFERENCE_BEFORE) to 1e-6 relative (measured: bit for bit on the CPU)."""
    scene = pdsim.Scene(fps=24.0, frames=4, gravity=(0.0, 0.0, -9.81), frame_time=2.0e-4)
    body = scene.add_body(pdsim.FemBody(pdsim.box_tet_mesh((0.06, 0.02, 0.02), (6, 2, 2)), MAT, name="bar"))
    body.fix(pdsim.BoxRegion(lo=(-1, -1, -1), hi=(-0.0299, 1, 1)))
    body.set_velocity(
        pdsim.BoxRegion(lo=(0.0299, -1, -1), hi=(1, 1, 1)), (0.2, 0.0, 0.0), curve=pdsim.TimeCurve.ramp(3.0e-4)
    )
    body.add_body_force((0.0, 30.0, 0.0), curve=pdsim.TimeCurve.ramp(4.0e-4))
    body.add_velocity_kick((0.0, 0.0, 0.3), time=2.5e-4)
    scene.add_collider(SphereProjectile(0.01, (0.0, 0.0, 0.025), velocity=(0.0, 0.0, -10.0), name="ball"))
    (solver,) = scene.build_solvers(device="cpu")
    for _ in range(4):
        advance_frame([solver], scene.frame_time / 7, 7)
    u = solver.kin.u.numpy().astype(np.float64)
    v = solver.kin.v.numpy().astype(np.float64)
    reactions = np.array(list(solver.reaction_forces().values()))
    assert u.sum(axis=0) == pytest.approx(_REFERENCE_BEFORE["u_sum"], rel=1.0e-6)
    assert v.sum(axis=0) == pytest.approx(_REFERENCE_BEFORE["v_sum"], rel=1.0e-6)
    assert reactions == pytest.approx(np.array(_REFERENCE_BEFORE["reactions"]), rel=1.0e-6)


# -- (e) capture on the CPU: replayed frames equal frames launched step by step ------------------------------------
def _pd_impact_scene(capture):
    """A block held at its left end, pulled by a ramped velocity at its right end, under a ramped traction, hit by
    a ballistic sphere, with contact on."""
    scene = pdsim.Scene(fps=24.0, frames=4, gravity=(0.0, 0.0, -9.81), graph_capture=capture, frame_time=2.0e-4)
    body = _free_block(scene)
    x = body.rest_positions[:, 0]
    body.fix(pdsim.BoxRegion(lo=(-1, -1, -1), hi=(x.min() + 0.5 * H, 1, 1)), name="left")
    body.set_velocity(
        pdsim.BoxRegion(lo=(x.max() - 0.5 * H, -1, -1), hi=(1, 1, 1)),
        (0.1, 0.0, 0.0),
        curve=pdsim.TimeCurve.ramp(3.0e-4),
        name="right",
    )
    body.add_body_force((0.0, 50.0, 0.0), curve=pdsim.TimeCurve.table([0.0, 4.0e-4], [0.0, 1.0]))
    scene.add_collider(SphereProjectile(0.008, (0.0, 0.0, 0.026), velocity=(0.0, 0.0, -20.0), name="ball"))
    scene.enable_contact(True)
    return scene


def _fem_scene(capture):
    scene = pdsim.Scene(fps=24.0, frames=4, gravity=(0.0, 0.0, -9.81), graph_capture=capture, frame_time=2.0e-4)
    mesh = pdsim.box_tet_mesh((0.06, 0.02, 0.02), (6, 2, 2))
    body = scene.add_body(pdsim.FemBody(mesh, MAT, name="bar"))
    body.fix(pdsim.BoxRegion(lo=(-1, -1, -1), hi=(-0.0299, 1, 1)))
    body.set_velocity(
        pdsim.BoxRegion(lo=(0.0299, -1, -1), hi=(1, 1, 1)), (0.2, 0.0, 0.0), curve=pdsim.TimeCurve.ramp(3.0e-4)
    )
    body.add_body_force((0.0, 30.0, 0.0), curve=pdsim.TimeCurve.ramp(4.0e-4))
    return scene


def _coupled_scene(capture):
    """A peridynamic cube (4 x 4 x 4 particles) falling at 6 m/s onto an FEM slab 2 mm below it, with ground: contact
    between methods inside each step from the second frame on."""
    scene = pdsim.Scene(fps=24.0, frames=4, gravity=(0.0, 0.0, -9.81), graph_capture=capture, frame_time=2.0e-4)
    cube = scene.add_peridynamic_body(pdsim.box((4 * H, 4 * H, 4 * H), center=(0.0, 0.0, 0.042)), MAT, H, name="cube")
    cube.set_initial_velocity((0.0, 0.0, -6.0))
    mesh = pdsim.box_tet_mesh((0.08, 0.08, 0.02), (4, 4, 1), center=(0.0, 0.0, 0.01))
    scene.add_body(pdsim.FemBody(mesh, MAT, name="slab"))
    scene.add_ground_plane(height=0.0, friction=0.2)
    return scene


def _states(solvers):
    return [(s.kin.u.numpy().copy(), s.kin.v.numpy().copy()) for s in solvers]


def _run_frames(scene, frames, substeps, graphs):
    solvers = scene.build_solvers(device="cpu")
    dt = scene.frame_time / substeps
    coupling = method_contact(scene, solvers)
    for _ in range(frames):
        advance_frame(solvers, dt, substeps, coupling, graphs=graphs)
    return solvers


@pytest.mark.parametrize(
    "build", [_pd_impact_scene, _fem_scene, _coupled_scene], ids=["peridynamics", "fem", "peridynamics+fem"]
)
def test_replayed_frames_equal_frames_launched_step_by_step(build):
    """4 frames of 7 steps (an odd count, so no buffer parity can hide): launched step by step, then with capture on
    (frame 1 direct, frame 2 captured, frames 3-4 replayed): u and v equal bit for bit, and the host's time and step
    count advanced the same."""
    substeps = 7
    ref = _run_frames(build(False), 4, substeps, None)
    graphs = FrameGraphs("cpu", True)
    got = _run_frames(build(True), 4, substeps, graphs)
    assert (graphs.captures, graphs.replays, graphs.direct_frames) == (1, 2, 1)
    for (u0, v0), (u1, v1) in zip(_states(ref), _states(got)):
        assert np.array_equal(u0, u1) and np.array_equal(v0, v1)
        assert np.abs(u0).max() > 0.0
    for a, b in zip(ref, got):
        assert a.time == b.time and a.step_count == b.step_count
        assert b.kin.clock.numpy()[0] == b.time
    if build is _coupled_scene:  # the slab slowed the cube's lowest layer by over 0.5 m/s: the contact acted
        (cube,) = [s for s in got if s.bodies[0].name == "cube"]
        assert cube.velocities()[:, 2].max() > -5.5


def _lattice_frames(capture, steps_per_frame):
    body = LatticeBody.block(
        Lattice.simple_cubic(H),
        (8, 4, 3),
        name="block",
        fracture=LatticeFracture((1.3 * H,)),
        steps_per_frame=steps_per_frame,
    )
    x = body.rest_positions[: body.body_count, 0]
    body.clamp(x < x.min() + 0.5 * H)
    body.add_leaders(x > x.max() - 0.5 * H, velocity=(0.3 * H, 0.0, 0.0), stop_step=4 * steps_per_frame)
    body.change_kind(x > x.max() - 1.5 * H, LatticeKind.LEADER, at_step=2 * steps_per_frame + 1)
    scene = pdsim.Scene(fps=24.0, frames=7, graph_capture=capture)
    scene.add_body(body)
    (solver,) = scene.build_solvers(device="cpu")
    graphs = FrameGraphs("cpu", capture)
    for _ in range(7):
        advance_frame([solver], scene.frame_time, 1, graphs=graphs)
    return solver, graphs


@pytest.mark.parametrize("steps_per_frame", [3, 4])
def test_replayed_lattice_frames_equal_frames_stepped(steps_per_frame):
    """A lattice block pulled by leaders (their path read from the device step counter), breaking links, with a
    category change in frame 3: 7 frames stepped, and with capture (frame 1 direct, 2 captured, 3 direct for the
    change, 4 captured again as the leaders changed, later frames replayed, or captured once more for each role of
    the two buffers when a frame has an odd number of steps): displacements, live links and step counts equal bit
    for bit."""
    ref, _ = _lattice_frames(False, steps_per_frame)
    got, graphs = _lattice_frames(True, steps_per_frame)
    assert graphs.replays >= 1 and graphs.captures >= 1
    assert got.step_count == ref.step_count == 7 * steps_per_frame
    assert np.array_equal(got.displacements(), ref.displacements())
    assert np.array_equal(got.link_alive(), ref.link_alive())
    assert np.abs(ref.displacements()).max() > 0.0


def test_scene_run_with_capture_matches_run_without(tmp_path):
    """Scene.run of the peridynamic impact scene with graph_capture=True (the watchdog checks at frame ends) and with
    it off (checks every 16 steps): the same final state bit for bit, and both pass the watchdog."""
    finals = {}
    for capture in (False, True):
        scene = _pd_impact_scene(capture)
        seen = {}
        scene.run(
            tmp_path / f"c{int(capture)}.usdc",
            progress=False,
            dt=scene.frame_time / 20,
            checkpoint_interval_s=None,
            on_frame=lambda f, solvers, seen=seen: seen.update(s=_states(solvers)),
        )
        finals[capture] = seen["s"]
    for (u0, v0), (u1, v1) in zip(finals[False], finals[True]):
        assert np.array_equal(u0, u1) and np.array_equal(v0, v1)


def test_fem_fracture_falls_back_visibly():
    """An FEM body with fracture cannot be captured (splits rebuild the mesh on the host): the frames run step by
    step and a warning names the reason once."""
    scene = pdsim.Scene(fps=24.0, frames=2, gravity=(0.0, 0.0, 0.0), graph_capture=True, frame_time=1.0e-4)
    mesh = pdsim.box_tet_mesh((0.04, 0.02, 0.02), (4, 2, 2))
    scene.add_body(pdsim.FemBody(mesh, MAT, tensile_strength=1.0e9, name="bar"))
    graphs = FrameGraphs("cpu", True)
    with pytest.warns(UserWarning, match="FEM fracture"):
        solvers = scene.build_solvers(device="cpu")
        for _ in range(3):
            advance_frame(solvers, scene.frame_time / 4, 4, graphs=graphs)
    assert graphs.captures == 0 and graphs.direct_frames == 3 and "FEM fracture" in graphs.fallback


def test_threaded_peridynamics_is_not_captured(monkeypatch):
    """Peridynamics on 2 CPU threads launches from a pool thread, which a capture does not record: the frames run
    step by step with a warning naming the threads."""
    monkeypatch.setenv("PDSIM_THREADS", "2")
    scene = _pd_impact_scene(True)
    graphs = FrameGraphs("cpu", True)
    with pytest.warns(UserWarning, match="CPU threads"):
        _run_frames(scene, 2, 3, graphs)
    assert graphs.captures == 0 and graphs.direct_frames == 2


# -- (c) no host read inside a frame's steps ----------------------------------------------------------------------
def _lattice_scene():
    scene = pdsim.Scene(fps=24.0, frames=1, name="lattice")
    body = LatticeBody.block(Lattice.simple_cubic(H), (6, 4, 3), name="block")
    x = body.rest_positions[: body.body_count, 0]
    body.clamp(x < x.min() + 0.5 * H)
    body.add_leaders(x > x.max() - 0.5 * H, velocity=(0.2 * H, 0.0, 0.0), stop_step=6)
    scene.add_body(body)
    return scene


@pytest.mark.parametrize("method", ["peridynamics", "fem", "lattice"])
def test_a_frame_reads_nothing_from_the_device(method, monkeypatch):
    """A frame of each method with default settings (peridynamics: the impact scene with contact and a projectile;
    FEM: the loaded bar; lattice: a pulled block), after a first frame: wp.array.numpy is not called while the
    frame's steps run (the watchdog and counters read at frame ends only)."""
    scene = {"peridynamics": _pd_impact_scene, "fem": _fem_scene}.get(method, lambda _: _lattice_scene())(None)
    solvers = scene.build_solvers(device="cpu")
    dt = scene.frame_time / 5
    advance_frame(solvers, dt, 5)
    calls = []
    original = wp.array.numpy

    def counting(self):
        calls.append(self.shape)
        return original(self)

    monkeypatch.setattr(wp.array, "numpy", counting)
    advance_frame(solvers, dt, 5)
    monkeypatch.setattr(wp.array, "numpy", original)
    assert calls == []
    assert np.isfinite(solvers[0].displacements()).all()


class _OtherDevice:
    """Stands for a device other than the CPU (a collider made for it is rebuilt when a CPU solver binds it)."""

    is_cpu = False
    is_capturing = False


@pytest.mark.parametrize("kind", ["sphere", "mesh projectile", "mesh collider"])
def test_colliders_move_to_the_device_of_the_solver_that_binds_them(kind):
    """A collider made with another device than the run's (colliders default to the CPU; a run on CUDA) has its
    device arrays rebuilt on the solver's device when the solver binds it: the frames are the same, bit for bit,
    as with the collider made on that device (on a GPU, test_cpu_and_cuda_agree runs such a projectile on CUDA)."""
    out = []
    for moved in (False, True):
        scene = _pd_impact_scene(False)
        if kind != "sphere":
            scene.colliders.clear()
            box = pdsim.box((0.012, 0.012, 0.012), center=(0.0, 0.0, 0.026))
            if kind == "mesh projectile":
                scene.add_collider(pdsim.MeshProjectile(box, velocity=(0.0, 0.0, -20.0), name="ball"))
            else:
                wall = pdsim.box((0.012, 0.012, 0.012), center=(0.0, 1.5 * H + 0.006, 0.0))  # touching the side
                scene.add_collider(pdsim.MeshCollider(wall))
        collider = scene.colliders[0]
        if moved:
            collider.device = _OtherDevice()
        solvers = _run_frames(scene, 2, 6, None)
        assert collider.device == wp.get_device("cpu")
        out.append(solvers[0].displacements())
    assert np.abs(out[0]).max() > 0.0
    np.testing.assert_array_equal(out[1], out[0])


# -- (d) CPU/CUDA agreement and (e) capture on CUDA -----------------------------------------------------------------
AGREEMENT_TOLERANCE = 1.0e-4
"""|u_cuda - u_cpu| <= 1e-4 max|u_cpu| (+ 1e-9 m): float32 sums in another order (atomics) over a few dozen steps."""


def _agreement_scene(method):
    if method == "peridynamics":
        return _pd_impact_scene(False)
    if method == "fem":
        return _fem_scene(False)
    return _lattice_scene()


@needs_cuda
@pytest.mark.parametrize("method", ["peridynamics", "fem", "lattice"])
def test_cpu_and_cuda_agree(method):
    """The same tiny scene, 3 frames of 6 steps, on "cpu" and "cuda" (capture off): displacements agree within
    AGREEMENT_TOLERANCE."""
    out = {}
    for device in ("cpu", "cuda"):
        scene = _agreement_scene(method)
        solvers = scene.build_solvers(device=device)
        dt = scene.frame_time / 6
        coupling = method_contact(scene, solvers)
        for _ in range(3):
            advance_frame(solvers, dt, 6, coupling)
        out[device] = solvers[0].displacements()
    scale = np.abs(out["cpu"]).max()
    assert scale > 0.0
    assert np.abs(out["cuda"] - out["cpu"]).max() <= AGREEMENT_TOLERANCE * scale + 1.0e-9


@needs_cuda
@pytest.mark.parametrize("build", [_pd_impact_scene, _fem_scene], ids=["peridynamics", "fem"])
def test_cuda_graph_replay_agrees_with_step_by_step(build):
    """On CUDA with graph capture (frames 3-4 replayed from the graph captured in frame 2): the state agrees with the
    frames launched step by step within AGREEMENT_TOLERANCE, and the graph was replayed."""
    scenes = {}
    for capture in (False, True):
        scene = build(capture)
        solvers = scene.build_solvers(device="cuda")
        graphs = FrameGraphs("cuda", capture)
        coupling = method_contact(scene, solvers)
        for _ in range(4):
            advance_frame(solvers, scene.frame_time / 7, 7, coupling, graphs=graphs)
        scenes[capture] = (solvers[0].displacements(), graphs)
    ref, (got, graphs) = scenes[False][0], scenes[True]
    assert graphs.replays == 2
    assert np.abs(got - ref).max() <= AGREEMENT_TOLERANCE * np.abs(ref).max() + 1.0e-9
