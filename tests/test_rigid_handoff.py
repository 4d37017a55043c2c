"""The rigid hand-off (pdsim/peridynamics/handoff.py): a quiet fragment of a breakable peridynamic body becomes a
rigid body whose particles are collision proxies and whose bonds are no longer visited.

Covered: linear and angular momentum through the hand-off and in free flight afterwards, the energy it drops (the
fragment's internal kinetic and elastic energy, computed here independently), near the origin and 1 km away; the bond
passes skip the fragments' particles (no bond force on them under a stretch that would give a large one); a scene in
which the pieces of a notched block go rigid, fall and rest on the ground as rigid shapes; the setting on but nothing
handed off is bit-identical to the setting off; a run with the hand-off stopped and resumed writes the same cache bit
for bit.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_resume_cache import _assert_resume_is_bit_identical

import pdsim
from pdsim.peridynamics import SolverPeridynamics
from pdsim.peridynamics.handoff import rigid_properties

MATERIAL = pdsim.Material(density=2500.0, youngs_modulus=5.0e9, poisson_ratio=0.25, critical_stretch=2.0e-3)
SPACING = 0.01


def _notched_block(origin, handoff):
    """A 8 x 4 x 4 particle block cut in two halves by a notch at x = 0 (both halves free)."""
    o = np.asarray(origin, dtype=np.float64)
    body = pdsim.PeridynamicBody(
        pdsim.box((0.08, 0.04, 0.04), center=tuple(o)), MATERIAL, SPACING, name="block", rigid_handoff=handoff
    )
    body.add_notch(pdsim.BoxRegion(lo=tuple(o + np.array([-0.001, -1, -1])), hi=tuple(o + np.array([0.001, 1, 1]))))
    return body


def _angular_momentum_about_centre(s):
    x, v, m = s.positions(), s.velocities(), s.masses()
    c = (m[:, None] * x).sum(0) / m.sum()
    return (m[:, None] * np.cross(x - c, v)).sum(0)


@pytest.mark.parametrize("origin", [(0.0, 0.0, 0.0), (1000.0, -700.0, 300.0)], ids=["origin", "1km"])
def test_handoff_keeps_momentum_and_drops_only_the_internal_energy(origin, device):
    """Two deformed, vibrating, spinning halves handed off: linear momentum within 1e-6 and angular momentum within
    1e-5 (relative, float32 state), the kinetic energy lost equals the internal kinetic energy computed here from the
    particles (1e-6 relative), plus the elastic energy; then 200 free steps keep P, L and K (1e-5) and every
    particle distance (1e-6 m)."""
    s = SolverPeridynamics([_notched_block(origin, pdsim.RigidHandoff(strain=1.0, frames=1))], device=device, threads=1)
    x = s.positions()
    c = x.mean(axis=0)
    rng = np.random.default_rng(4)
    s.set_displacements(1.0e-5 * rng.standard_normal(x.shape))  # an elastic energy
    x = s.positions()
    v = np.array([1.0, 0.5, -0.3]) + np.cross([3.0, -2.0, 20.0], x - c) + 0.05 * rng.standard_normal(x.shape)
    s.set_velocities(v)
    v = s.velocities()
    m = s.masses()
    p0, l0, k0, e0 = s.linear_momentum(), s.angular_momentum(c), s.kinetic_energy(), s.strain_energy()
    labels = s.fragment_ids()
    group = np.unique(labels, return_inverse=True)[1]
    ref = rigid_properties(x - c, v, m, group, 2)
    # independent: the kinetic energy of the rigid motion with the same momentum and angular momentum per half
    rigid_k = sum(
        0.5 * m[group == g].sum() * ref["velocity"][g] @ ref["velocity"][g]
        + 0.5 * ref["angular_momentum"][g] @ np.linalg.solve(ref["inertia"][g], ref["angular_momentum"][g])
        for g in range(2)
    )
    assert s.handoff.update() == 2 and s.handoff.rigid_particles().all()
    p1, l1, k1 = s.linear_momentum(), s.angular_momentum(c), s.kinetic_energy()
    np.testing.assert_allclose(p1, p0, rtol=0, atol=1e-6 * np.linalg.norm(p0))
    np.testing.assert_allclose(l1, l0, rtol=0, atol=1e-5 * np.linalg.norm(l0))
    assert abs((k0 - k1) - (k0 - rigid_k)) < 1e-6 * k0
    assert abs(s.handoff.released["internal_kinetic"] - (k0 - rigid_k)) < 1e-6 * k0
    assert abs(s.handoff.released["elastic"] - e0) < 1e-6 * e0 and e0 > 0.0
    assert 0.0 < k0 - k1 < 0.05 * k0  # the vibration given: about 1 % of the kinetic energy
    d0 = np.linalg.norm(s.positions()[:, None] - s.positions()[None, labels == labels[0]], axis=2)[labels == labels[0]]
    l_c = _angular_momentum_about_centre(s)
    s.simulate(0.5 * s.stable_time_step(), 200)
    np.testing.assert_allclose(s.linear_momentum(), p1, rtol=0, atol=1e-5 * np.linalg.norm(p1))
    np.testing.assert_allclose(_angular_momentum_about_centre(s), l_c, rtol=0, atol=1e-5 * np.linalg.norm(l_c))
    assert abs(s.kinetic_energy() - k1) < 1e-5 * k1
    x2 = s.positions()
    d2 = np.linalg.norm(x2[:, None] - x2[None, labels == labels[0]], axis=2)[labels == labels[0]]
    assert np.abs(d2 - d0).max() < 1e-6
    assert np.linalg.norm(x2.mean(0) - x.mean(0)) > 2.0e-4  # it flew (and turned: 200 steps of 1.3 us)


def test_rigid_fragments_skip_their_bonds():
    """After the hand-off the dilatation and force passes visit no bond of the fragments: a 1 % stretch of their
    particles gives no force density and leaves their dilatation as it was, where the same stretch without the
    hand-off gives a force density above 1e8 N/m^3; the bond rows visited drop to zero."""
    stretched = {}
    for on in (False, True):
        s = SolverPeridynamics([_notched_block((0.0, 0.0, 0.0), pdsim.RigidHandoff(strain=1.0, frames=1))], threads=1)
        if on:
            assert s.handoff.live_bond_rows() == s.bond_count
            assert s.handoff.update() == 2
            assert s.handoff.live_bond_rows() == 0
        theta = s.dilatation()
        s.set_displacements(0.01 * (s.positions() - s.positions().mean(0)))
        stretched[on] = (np.abs(s.force_density()).max(), np.abs(s.dilatation() - theta).max())
    assert stretched[False][0] > 1e8 and stretched[False][1] > 1e-3
    assert stretched[True] == (0.0, 0.0)


def _halves_over_ground(name, frames, height, shift, *, in_flight, retardation_time=0.0):
    """A scene ``name`` of ``frames`` frames of 5 ms: the notched block (softened: E 50 MPa, c_p 155 m/s; its
    ``retardation_time`` [s]) with its centre ``height`` [m] above a ground plane, all moved by ``shift``, the
    hand-off at strain 1e-4 over 2 frames (``in_flight``: the settling test off). Returns (scene, block, its centre)."""
    o = np.asarray(shift, dtype=np.float64)
    scene = pdsim.Scene(fps=24, frames=frames, frame_time=5.0e-3, name=name)
    soft = pdsim.Material(
        density=2500.0, youngs_modulus=5.0e7, poisson_ratio=0.25, critical_stretch=2.0e-3,
        retardation_time=retardation_time,
    )  # fmt: skip
    centre = o + np.array([0.0, 0.0, height])
    body = pdsim.PeridynamicBody(
        pdsim.box((0.08, 0.04, 0.04), center=tuple(centre)), soft, SPACING, name="block",
        rigid_handoff=pdsim.RigidHandoff(strain=1.0e-4, frames=2, in_flight=in_flight),
    )  # fmt: skip
    cut = np.array([0.001, 1.0, 1.0])
    body.add_notch(pdsim.BoxRegion(lo=tuple(centre - cut), hi=tuple(centre + cut)))
    scene.add_body(body)
    scene.add_ground_plane(height=float(o[2]))
    return scene, body, centre


def _pieces(frames=16, shift=(0.0, 0.0, 0.0)):
    """The notched block thrown spinning at the ground from 8 cm (_halves_over_ground): its halves go rigid in
    flight, then land and come to rest."""
    scene, body, centre = _halves_over_ground("pieces", frames, 0.1, shift, in_flight=True)
    body.set_initial_velocity(np.array([0.5, 0.0, -1.5]) + np.cross([0.0, 4.0, 0.0], body.rest_positions - centre))
    return scene


def test_pieces_go_rigid_and_rest_on_the_ground(tmp_path, device):
    """Both halves are rigid by the last frame (100 % of the particles); their particles still meet the ground
    (none below -h/4) and each half keeps its shape (distances within 1e-6 m of the hand-off's)."""
    seen = {}

    def on_frame(frame, solvers):
        s = solvers[0]
        seen[frame] = (s.handoff.rigid_particles().copy(), s.positions().copy(), s.fragment_ids().copy())

    _pieces().run(tmp_path / "p.usdc", device=device, progress=False, on_frame=on_frame)
    rigid, x, labels = seen[max(seen)]
    assert rigid.all()
    first = min(f for f, r in seen.items() if r[0].all())
    assert first < max(seen)
    assert x[:, 2].min() > -0.25 * SPACING
    x0 = seen[first][1]
    for lab in np.unique(labels):
        sel = labels == lab
        d0 = np.linalg.norm(x0[sel][:, None] - x0[sel][None], axis=2)
        d1 = np.linalg.norm(x[sel][:, None] - x[sel][None], axis=2)
        assert np.abs(d1 - d0).max() < 1e-6


def _falling_halves(in_flight, shift):
    """The notched block (_halves_over_ground, retardation time 5e-5 s so that it settles) let fall from 2.5 cm onto
    the ground (inelastic projection), 56 frames; returns the scene and the block's P-wave speed [m/s]."""
    scene, body, _ = _halves_over_ground("fall", 56, 0.045, shift, in_flight=in_flight, retardation_time=5.0e-5)
    return scene, body.material.p_wave_speed


@pytest.mark.parametrize(("in_flight", "shift"), [(False, (1000.0, -700.0, 300.0)), (True, (0.0, 0.0, 0.0))])
def test_a_falling_piece_is_handed_off_once_it_has_settled(tmp_path, in_flight, shift):
    """The settling test (pdsim/peridynamics/handoff.py): two quiet halves falling onto the ground are not handed off
    while they fall, land or bounce (no rigid particle at a frame end where a particle moves faster than 0.1 m/s,
    6.5 times the settling speed strain c_p = 1.55 cm/s), only once they rest: both rigid by the last frame (measured:
    from frame 42; they bounce faster than 0.1 m/s until frame 32), the frame end before the hand-off below twice the
    settling speed, and resting on the ground (none below -h/4); 1 km away.
    With ``in_flight=True`` they go rigid while still falling (measured: at frame 2, 2.5 cm up at 9.8 cm/s; they land
    rigid at frame 15)."""
    scene, c_p = _falling_halves(in_flight, shift)
    settle = 1.0e-4 * c_p
    seen = {}

    def on_frame(frame, solvers):
        s = solvers[0]
        z = s.positions()[:, 2] - shift[2]
        seen[frame] = (s.handoff.rigid_particles().mean(), np.linalg.norm(s.velocities(), axis=1).max(), z.min())

    scene.run(tmp_path / "fall.usdc", progress=False, on_frame=on_frame)
    frames = sorted(seen)
    first = min(f for f in frames if seen[f][0] == 1.0)
    fast = [f for f in frames if seen[f][1] > 0.1]
    print(f"first rigid at frame {first};", "rigid share, fastest particle [m/s], lowest z [m] by frame:",
          [tuple(round(float(v), 4) for v in seen[f]) for f in frames])  # fmt: skip
    assert seen[frames[-1]][0] == 1.0 and seen[frames[-1]][2] > -0.25 * SPACING
    if in_flight:
        assert seen[first][1] > 0.05 and seen[first][2] > 0.02  # still falling, 2 cm up
    else:
        assert all(seen[f][0] == 0.0 for f in fast) and max(fast) > 20  # it bounces
        assert seen[first - 1][1] < 2.0 * settle


@pytest.mark.parametrize("yielding", [False, True], ids=["alone", "beside_a_yielding_body"])
def test_handoff_on_with_nothing_handed_off_is_bit_identical_to_off(yielding):
    """The setting on changes nothing until a fragment is handed off (the skip test is the only change), also with
    a yielding body in the same solver (it keeps the pair passes: a fall-back to the directed passes, which sum in
    another order, made the runs part by round-off)."""
    out = []
    ductile = pdsim.Material(density=2500.0, youngs_modulus=5.0e9, poisson_ratio=0.25, yield_stress=1.0e6)
    for handoff in (False, pdsim.RigidHandoff()):
        bodies = [_notched_block((0.0, 0.0, 0.0), handoff)]
        if yielding:
            bodies.append(
                pdsim.PeridynamicBody(pdsim.box((0.04, 0.04, 0.04), center=(0.2, 0.0, 0.0)), ductile, SPACING)
            )
        s = SolverPeridynamics(bodies, threads=1)
        assert s.bond_passes == "pairs"
        x = s.positions()
        s.set_velocities(np.cross([0.0, 0.0, 30.0], x - x.mean(0)) + np.array([0.0, 0.0, 1.0]))
        s.simulate(0.5 * s.stable_time_step(), 50)
        out.append((s.kin.u.numpy().copy(), s.kin.v.numpy().copy()))
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])


def test_resume_with_rigid_fragments_is_bit_identical(tmp_path):
    """Stopped inside a frame after the halves went rigid, then resumed: the cache equals the uninterrupted run's."""
    _assert_resume_is_bit_identical(_pieces, tmp_path, 9, 16)


def test_one_rigid_half_is_bit_identical_on_one_and_three_threads():
    """One half handed off (the other vibrates above the threshold): 100 steps on 1 and on 3 CPU threads (ranges
    rebalanced on the bonds still visited) give the same state bit for bit."""
    out = []
    for threads in (1, 3):
        handoff = pdsim.RigidHandoff(strain=5.0e-4, frames=1, in_flight=True)  # the spinning half
        s = SolverPeridynamics([_notched_block((0.0, 0.0, 0.0), handoff)])
        s.threads = threads
        x = s.positions()
        rng = np.random.default_rng(2)
        shake = np.where(x[:, :1] > 0.0, 1.0, 0.0) * rng.standard_normal(x.shape)
        s.set_velocities(np.cross([0.0, 5.0, 30.0], x - x.mean(0)) + shake)
        assert s.handoff.update() == 1
        assert s.handoff.rigid_particles().sum() == len(x) // 2
        assert s.threads == threads
        s.simulate(0.5 * s.stable_time_step(), 100)
        out.append((s.kin.u.numpy().copy(), s.kin.v.numpy().copy()))
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])


def test_debris_damping_still_acts_on_rigid_particles_above_the_threshold():
    """Both halves rigid, with debris damping (c = 1e4 / s, threshold 0.2): after a force pass the force density of
    every rigid particle is the debris drag rho c (v_bar - v_k) computed here from the bonds (mean velocity over the
    live bonds, else over the whole family) where its damage is above the threshold (the notch faces), within 1e-4 of
    the largest, and exactly zero elsewhere (the bond passes skip them)."""
    glass = pdsim.Material(
        density=2500.0, youngs_modulus=5.0e9, poisson_ratio=0.25, critical_stretch=2.0e-3, debris_damping=1.0e4,
        debris_damage=0.2,
    )  # fmt: skip
    body = _notched_block((0.0, 0.0, 0.0), pdsim.RigidHandoff(strain=1.0, frames=1))
    body.material = glass
    s = SolverPeridynamics([body], threads=1)
    x = s.positions()
    s.set_velocities(np.cross([0.0, 2.0, 30.0], x - x.mean(0)) + np.random.default_rng(1).standard_normal(x.shape))
    assert s.handoff.update() == 2 and s.handoff.rigid_particles().all()
    s.compute_forces()
    got = s.force_density()
    m = s.model
    offsets = m.family_offsets.numpy()[: s.particle_count + 1]
    row = np.repeat(np.arange(s.particle_count), np.diff(offsets))
    nb = m.family_neighbors.numpy()[: s.bond_count]
    wv = m.bond_wv.numpy()[: s.bond_count].astype(np.float64)
    alive = s.bond_alive()
    v = s.kin.v.numpy().astype(np.float64)

    def wsum(w, values):
        return np.stack([np.bincount(row, weights=w * values[:, i], minlength=s.particle_count) for i in range(3)], 1)

    total = np.bincount(row, weights=wv, minlength=s.particle_count)
    live = np.bincount(row, weights=wv * alive, minlength=s.particle_count)
    v_bar = np.where((live > 0)[:, None], wsum(wv * alive, v[nb]) / np.maximum(live, 1e-300)[:, None],
                     wsum(wv, v[nb]) / total[:, None])  # fmt: skip
    damped = 1.0 - live / total > 0.2
    rho = 1.0 / m.inv_density.numpy().astype(np.float64)
    expected = np.where(damped[:, None], (1.0e4 * rho)[:, None] * (v_bar - v), 0.0)
    assert 0 < damped.sum() < s.particle_count
    assert np.all(got[~damped] == 0.0)
    scale = np.abs(expected).max()
    assert scale > 0.0 and np.abs(got - expected).max() < 1e-4 * scale


def _stretched_half(tau=0.0, frames=2):
    """The notched block with the half x > 0 stretched by 2e-3 (0.6e-3 across) and both halves at rest; a material
    with retardation time ``tau`` [s]; the hand-off at strain 1e-4 over ``frames`` frames."""
    material = pdsim.Material(
        density=2500.0, youngs_modulus=5.0e9, poisson_ratio=0.25, critical_stretch=2.0e-3, retardation_time=tau
    )
    body = _notched_block((0.0, 0.0, 0.0), pdsim.RigidHandoff(strain=1.0e-4, frames=frames))
    body.material = material
    s = SolverPeridynamics([body], threads=1)
    x = s.positions()
    half = x[:, 0] > 0.0
    u = np.zeros_like(x)
    u[half] = 2.0e-3 * (x[half] - x[half].mean(axis=0)) * np.array([1.0, 0.3, 0.3])
    s.set_displacements(u)
    return s, half


def test_a_strained_fragment_at_rest_is_quiet_and_a_ringing_one_is_not():
    """The test reads the motion (K_int), not the strain: at rest, the stretched half (elastic energy 0.91 J, an
    equivalent strain of 2.2e-3 had the test counted it) is handed off at once with the other, keeping its shape, and
    its elastic energy goes to ``released``. Let go, it rings (first mode about 19 kHz, frame ends every 127 us): its
    eps stays above 5e-4 at every frame end for 10 frames, and it is never handed off, where the half at rest is after
    the 2 frames asked."""
    s, half = _stretched_half(frames=1)
    e0 = s.strain_energy()
    x0 = s.positions()
    assert s.handoff.update() == 2 and s.handoff.rigid_particles().all()
    assert abs(s.handoff.released["elastic"] - e0) < 1e-6 * e0 and e0 > 0.5
    np.testing.assert_array_equal(s.positions(), x0)
    s, half = _stretched_half(frames=2)
    dt = 0.5 * s.stable_time_step()
    for frame in range(1, 11):
        s.simulate(dt, 47)
        eps = s.handoff.fragment_strains()["eps"]
        handed = s.handoff.update()
        assert not s.handoff.rigid_particles()[half].any()
        assert eps.max() > 5.0e-4
        assert s.handoff.rigid_particles()[~half].all() == (frame >= 2) and handed == (frame == 2)


def test_the_brittle_presets_hand_off_by_default():
    """Material.rigid_handoff: a peridynamic body that sets no rigid_handoff takes its material's, which the brittle
    presets set (with and without their break pattern; the defaults of pdsim.RigidHandoff); False on the body turns
    it off, True on a plain material turns it on; the ductile and soft presets carry none; a value other than True or
    False is refused, naming the field."""
    box = pdsim.box((0.06, 0.06, 0.06))
    for name in ("glass", "porcelain", "ceramic", "stone", "concrete", "plaster"):
        for pattern in (True, False):
            material = pdsim.presets.preset(name, pattern=pattern)
            assert pdsim.PeridynamicBody(box, material, 0.02).rigid_handoff == pdsim.RigidHandoff()
            assert pdsim.PeridynamicBody(box, material, 0.02, rigid_handoff=False).rigid_handoff is None
    for name in ("wood", "clay", "steel", "aluminium", "rubber"):
        assert pdsim.PeridynamicBody(box, pdsim.presets.preset(name), 0.02).rigid_handoff is None
    assert pdsim.PeridynamicBody(box, MATERIAL, 0.02).rigid_handoff is None
    on = dataclasses.replace(MATERIAL, rigid_handoff=True)
    assert pdsim.PeridynamicBody(box, on, 0.02, rigid_handoff=pdsim.RigidHandoff(frames=5)).rigid_handoff.frames == 5
    assert pdsim.PeridynamicBody(box, on, 0.02).rigid_handoff == pdsim.RigidHandoff()
    with pytest.raises(pdsim.ParameterError, match="rigid_handoff"):
        dataclasses.replace(MATERIAL, rigid_handoff="yes")
