"""Static hand-off (pdsim/peridynamics/handoff.py): a quiet fragment held by fixed boundary conditions (a clamped
remainder) sleeps: its particles stay where they are at zero velocity, its bonds are no longer visited, it stays a
collision proxy.

Covered: the remainder of a clamped, notched plate is handed off as static while its cut-off piece still vibrates;
the energy dropped is its kinetic and elastic energy, computed here from the particles; its particles do not move
(bit for bit) under gravity, and its bonds are not visited (a stretch gives no force), also 1 km away; a piece
thrown at it bounces off while it stays put; a prescribed velocity, a fix on some axes, a fix with a release, a load
on the remainder or ``RigidHandoff(fixed=False)`` keep it deformable; a run with a sleeping remainder stopped and
resumed writes the same cache bit for bit; 1 and 3 CPU threads give the same state bit for bit.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_resume_cache import _assert_resume_is_bit_identical

import pdsim
from pdsim.peridynamics import SolverPeridynamics

SPACING = 0.01
NOTCH_X = 0.02  # the notch plane: the clamped remainder at x < NOTCH_X, the cut-off piece beyond
STIFF = pdsim.Material(density=2500.0, youngs_modulus=5.0e9, poisson_ratio=0.25, critical_stretch=2.0e-3)
SOFT = pdsim.Material(density=2500.0, youngs_modulus=5.0e7, poisson_ratio=0.25, critical_stretch=2.0e-3)


def _plate(handoff, *, condition="fix", material=STIFF, shift=(0.0, 0.0, 0.0)):
    """A 12 x 2 x 4 particle plate (0.12 m x 0.02 m x 0.04 m) clamped along its end x < -0.045 m, cut by a notch at
    x = NOTCH_X into the clamped remainder (64 particles) and a free piece (32). ``condition``: how the end is held
    ("fix", "moving": a prescribed velocity, "some_axes": fixed on x and z, "released": a fix released at 1 s,
    "load": fixed, with a traction on the remainder's top)."""
    o = np.asarray(shift, dtype=np.float64)
    body = pdsim.PeridynamicBody(
        pdsim.box((0.12, 0.02, 0.04), center=tuple(o)), material, SPACING, name="plate", rigid_handoff=handoff
    )

    def box(lo, hi):
        return pdsim.BoxRegion(lo=tuple(o + np.asarray(lo)), hi=tuple(o + np.asarray(hi)))

    body.add_notch(box([NOTCH_X - 1e-3, -1, -1], [NOTCH_X + 1e-3, 1, 1]))
    end = box([-1.0, -1, -1], [-0.045, 1, 1])
    if condition == "moving":
        body.set_velocity(end, (0.0, 0.0, 1.0e-3))
    elif condition == "some_axes":
        body.fix(end, axes="xz")
    elif condition == "released":
        body.fix(end, release=1.0)
    else:
        body.fix(end)
    if condition == "load":
        body.add_traction(box([-0.03, -1, 0.015], [0.01, 1, 1]), (0.0, 0.0, -1.0e3))
    return body


def _sides(s):
    """bool masks (remainder, piece, clamped end) of the plate's particles."""
    x = s.positions() - s.origin
    return x[:, 0] < NOTCH_X, x[:, 0] > NOTCH_X, x[:, 0] < -0.045


@pytest.mark.parametrize("shift", [(0.0, 0.0, 0.0), (1000.0, -700.0, 300.0)], ids=["origin", "1km"])
def test_quiet_clamped_remainder_sleeps_and_its_energy_is_released(shift, device):
    """The remainder, deformed (random displacements of 1e-7 m) and vibrating (1e-4 m/s) below the threshold 1e-4,
    is handed off as static while the piece vibrates at 1 m/s (above it): ``released`` equals the remainder's kinetic
    energy 1/2 sum m v^2 and its elastic energy sum V W (1e-9 relative), the kinetic energy of the whole drops by the
    first exactly; then 200 steps under gravity leave its displacements bit for bit and its velocities exactly zero,
    while the piece moves; a 1 % stretch gives its particles no force density and the bond rows visited are the
    piece's alone, where without the static hand-off (fixed=False) the stretch gives above 1e8 N/m^3. The same 1 km
    from the origin."""
    stretched = {}
    for fixed in (True, False):
        s = SolverPeridynamics(
            [_plate(pdsim.RigidHandoff(strain=1.0e-4, frames=1, fixed=fixed), shift=shift)],
            device=device,
            threads=1,
            gravity=(0.0, 0.0, -9.81),
        )
        rest, piece, end = _sides(s)
        rng = np.random.default_rng(3)
        u = np.where((rest & ~end)[:, None], 1.0e-7 * rng.standard_normal((len(end), 3)), 0.0)
        s.set_displacements(u)
        v = np.where((rest & ~end)[:, None], 1.0e-4 * rng.standard_normal((len(end), 3)), 0.0)
        s.set_velocities(v + np.where(piece[:, None], rng.standard_normal((len(end), 3)), 0.0))
        m, vel = s.masses(), s.velocities()
        k_rest = 0.5 * float(np.sum(m[rest] * np.einsum("ij,ij->i", vel[rest], vel[rest])))
        e_rest = float(np.sum(s.model.volumes_host[rest] * s.strain_energy_density()[rest]))
        k0 = s.kinetic_energy()
        handed = s.handoff.update()
        if not fixed:
            assert handed == 0 and not s.handoff.rigid_particles().any()
        else:
            assert handed == 1 and np.array_equal(s.handoff.rigid_particles(), rest)
            assert s.handoff.static_particle[rest].all() and not s.handoff.static_particle[piece].any()
            assert abs(s.handoff.released["internal_kinetic"] - k_rest) < 1e-9 * k_rest and k_rest > 0.0
            assert abs(s.handoff.released["elastic"] - e_rest) < 1e-9 * e_rest and e_rest > 0.0
            assert abs((k0 - s.kinetic_energy()) - k_rest) < 1e-6 * k_rest
            u_sleep = s.kin.u.numpy().copy()
            x_piece = s.positions()[piece]
            s.simulate(0.5 * s.stable_time_step(), 200)
            assert np.array_equal(s.kin.u.numpy()[rest], u_sleep[rest])
            assert np.all(s.kin.v.numpy()[rest] == 0.0)
            assert np.abs(s.positions()[piece] - x_piece).max() > 1.0e-5
            sizes = np.diff(s._offsets_host)
            assert s.handoff.live_bond_rows() == sizes[piece].sum() < s.bond_count
        theta = s.dilatation()
        s.set_displacements(s.kin.u.numpy() + 0.01 * (s.positions() - s.positions().mean(0)))
        stretched[fixed] = (np.abs(s.force_density()[rest]).max(), np.abs(s.dilatation() - theta)[rest].max())
    assert stretched[False][0] > 1e8 and stretched[False][1] > 1e-3
    assert stretched[True] == (0.0, 0.0)


@pytest.mark.parametrize("condition", ["fix", "moving", "some_axes", "released", "load", "fixed_off"])
def test_only_a_fix_on_all_axes_without_loads_lets_the_remainder_sleep(condition):
    """Everything at rest (eps 0): with the end fixed the remainder and the piece are both handed off (the remainder
    static); a prescribed velocity, a fix on two axes, a fix with a release, a traction on the remainder or
    RigidHandoff(fixed=False) leave the remainder deformable (only the free piece is handed off, as rigid)."""
    handoff = pdsim.RigidHandoff(strain=1.0e-4, frames=1, fixed=condition != "fixed_off")
    s = SolverPeridynamics([_plate(handoff, condition="fix" if condition == "fixed_off" else condition)], threads=1)
    rest, piece, _ = _sides(s)
    handed = s.handoff.update()
    assert s.handoff.rigid_particles()[piece].all() and not s.handoff.static_particle[piece].any()
    if condition == "fix":
        assert handed == 2 and s.handoff.static_particle[rest].all()
    else:
        assert handed == 1 and not s.handoff.rigid_particles()[rest].any()


def test_a_piece_thrown_at_the_sleeping_remainder_bounces_off_it():
    """Contact on: the remainder asleep, the piece thrown back at it at 1 m/s; after 400 steps the piece moves away
    (mean velocity along x above +0.2 m/s) and the remainder's particles have not moved (bit for bit)."""
    body = _plate(pdsim.RigidHandoff(strain=1.0e-4, frames=1, fixed=True), material=SOFT)
    s = SolverPeridynamics([body], threads=1, contact=True)
    rest, piece, _ = _sides(s)
    assert s.handoff.update() == 2
    u_sleep = s.kin.u.numpy().copy()
    x = s.positions()
    s.set_velocities(np.where(piece[:, None], [-1.0, 0.0, 0.0], 0.0))  # the next projection takes it up
    dt = 0.5 * s.stable_time_step()
    s.simulate(dt, 400)
    assert s.velocities()[piece, 0].mean() > 0.2
    assert np.array_equal(s.kin.u.numpy()[rest], u_sleep[rest])
    assert (s.positions()[piece, 0].min() - x[rest, 0].max()) > 0.5 * SPACING


def _clamped_scene(frames=10, shift=(0.0, 0.0, 0.0)):
    """The soft plate under gravity, its piece thrown spinning away: both go quiet and are handed off at frame 2
    (the remainder static); without the static hand-off the remainder would sag and swing under gravity."""
    o = np.asarray(shift, dtype=np.float64)
    scene = pdsim.Scene(fps=24, frames=frames, frame_time=2.0e-3, name="clamped")
    body = _plate(pdsim.RigidHandoff(strain=1.0e-3, frames=2, fixed=True), material=SOFT, shift=shift)
    x = body.rest_positions
    piece = x[:, 0] > o[0] + NOTCH_X
    centre = x[piece].mean(axis=0)
    body.set_initial_velocity(
        np.where(piece[:, None], np.array([1.0, 0.0, 0.5]) + np.cross([0, 0, 8.0], x - centre), 0.0)
    )
    scene.add_body(body)
    return scene


def test_resume_with_a_sleeping_remainder_is_bit_identical(tmp_path):
    """Stopped inside frame 6 (the remainder asleep since frame 2), then resumed: the cache equals the uninterrupted
    run's bit for bit; the remainder is static at the end and its particles at rest."""
    seen = {}

    def on_frame(frame, solvers):
        seen[frame] = (solvers[0].handoff.static_particle.copy(), solvers[0].velocities().copy())

    _clamped_scene().run(tmp_path / "watch.usdc", device="cpu", progress=False, on_frame=on_frame)
    static, v = seen[max(seen)]
    assert 0 < static.sum() < len(static) and np.all(v[static] == 0.0)
    assert min(f for f, (st, _) in seen.items() if st.any()) <= 3
    _assert_resume_is_bit_identical(_clamped_scene, tmp_path, 5, 10)


def test_sleeping_remainder_is_bit_identical_on_one_and_three_threads():
    """The remainder asleep, the piece vibrating above the threshold (deformable, contact on): 100 steps under
    gravity on 1 and on 3 CPU threads give the same state bit for bit."""
    out = []
    for threads in (1, 3):
        s = SolverPeridynamics(
            [_plate(pdsim.RigidHandoff(strain=1.0e-4, frames=1, fixed=True), material=SOFT)], contact=True,
            gravity=(0.0, 0.0, -9.81),
        )  # fmt: skip
        s.threads = threads
        rest, piece, _ = _sides(s)
        rng = np.random.default_rng(2)
        s.set_velocities(np.where(piece[:, None], rng.standard_normal((len(piece), 3)), 0.0))
        assert s.handoff.update() == 1 and s.handoff.static_particle[rest].all()
        assert s.threads == threads
        s.simulate(0.5 * s.stable_time_step(), 100)
        out.append((s.kin.u.numpy().copy(), s.kin.v.numpy().copy()))
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])
