"""The pair form of the peridynamic bond passes (pdsim/peridynamics/pairs.py, kernels/peridynamics/pairs.py): each
bond pair evaluated once on the CPU, the other particle's share scattered into fixed-range buffers.

Covered, against the directed form (every bond gathered by its particle, kernels/peridynamics/step.py) as the
independent reference: dilatation, force density and strain energy to float32 round-off (1e-5 of the largest value)
on a deformed elastic block 1 km from the origin, also with bond weights made asymmetric (so the reverse bond's
weight is the one scattered); the bond cache bit for bit; a fracturing block breaks the same bonds in the same steps
over 20 steps; with the rigid hand-off (one half rigid) the same forces and no bond force on the rigid half; the
pair form bit-identical on 1, 2 and 3 threads; which form a scene gets, and the errors of the setting. With
plasticity (the return mapping in pair passes): the same broken bonds step by step and the plastic state to 1e-5 of
the largest value, breaking by stretch and by ductile failure, with asymmetric weights and beside an elastic body;
bit-identical on 1, 2 and 3 threads and through a checkpoint restored into a fresh solver.
"""

from __future__ import annotations

import numpy as np
import pytest

import pdsim
from pdsim.errors import ParameterError
from pdsim.peridynamics import SolverPeridynamics
from pdsim.peridynamics.pairs import PAIR_RANGES, PairPasses, pair_layout

CENTER = (1000.0, -40.0, 20.0)  # 1 km from the origin
TOL = 1.0e-5  # float32 round-off of sums of ~100 terms, relative to the largest value


def _block(pairs, threads=1, critical_stretch=None, debris=0.0, n=7):
    """An n^3 block (h = 1 mm, E = 1 GPa) at CENTER, breakable where ``critical_stretch`` is given, pulled apart by
    a stretch-rate field of 1500 1/s along x (-450 along y, 300 along z)."""
    h = 1.0e-3
    mat = pdsim.Material(
        density=1000.0,
        youngs_modulus=1.0e9,
        poisson_ratio=0.25,
        critical_stretch=critical_stretch,
        debris_damping=debris,
        debris_damage=0.5,
    )
    body = pdsim.PeridynamicBody(pdsim.box((n * h,) * 3, center=CENTER), mat, h)
    solver = SolverPeridynamics([body], threads=threads, pairs=pairs)
    x = body.rest_positions - np.asarray(CENTER)
    solver.set_velocities(1500.0 * x * np.array([1.0, -0.3, 0.2]))
    return solver


def _deformation(solver):
    """A smooth non-uniform displacement field [m] (strains of order 1e-3, rotations, shear)."""
    x = (solver.positions() - np.asarray(CENTER)) / 3.5e-3
    return 3.5e-6 * np.stack(
        [x[:, 0] + 0.3 * x[:, 1] ** 2, np.sin(x[:, 0] * 1.7) - 0.4 * x[:, 1], 0.5 * x[:, 2] * x[:, 0]], axis=1
    )


def _close(a, b, tol=TOL):
    scale = np.abs(a).max()
    assert scale > 0.0
    return np.abs(a - b).max() <= tol * scale


def _skew_weights(solver, rng):
    """Multiplies every directed bond's weights by its own factor in [0.5, 1.5] (bond k -> j and j -> k differ) and
    rebuilds the pair layout from them."""
    m = solver.model
    for name in ("bond_wv_dil", "bond_wv_dev"):
        w = getattr(m, name)
        w.assign(w.numpy() * rng.uniform(0.5, 1.5, w.shape[0]).astype(np.float32))
    if solver._pairs is not None:
        solver._pairs = PairPasses(m, m.fracture, False, solver.device)
        solver._pairs.set_threads(1)


@pytest.mark.parametrize("skew", [False, True])
def test_pairs_give_the_directed_dilatation_forces_and_energy(skew):
    """Same displacements, both forms: dilatation, force density and strain energy density agree to 1e-5 of the
    largest value; the directed bond cache (n, e) is the same bit for bit (eta_jk = -eta_kj exactly)."""
    directed, paired = _block(False), _block(None)
    assert directed.bond_passes == "directed" and paired.bond_passes == "pairs"
    if skew:
        for s in (directed, paired):
            _skew_weights(s, np.random.default_rng(4))
    u = _deformation(directed)
    for s in (directed, paired):
        s.set_displacements(u)
    assert _close(directed.dilatation(), paired.dilatation())
    assert _close(directed.force_density(), paired.force_density())
    assert _close(directed.strain_energy_density(), paired.strain_energy_density())
    assert np.array_equal(directed.bond_cache().numpy(), paired.bond_cache().numpy())
    assert np.abs(directed.dilatation()).max() > 1e-4  # a real deformation


def test_pairs_break_the_same_bonds_in_the_same_steps():
    """A block pulled apart (s_c = 1e-3) over 20 steps: after every step both forms hold the same live bonds, and
    their displacements agree to 1e-5 of the largest; between 20 % and 80 % of the bonds are broken at the end."""
    directed, paired = _block(False, critical_stretch=1.0e-3), _block(None, critical_stretch=1.0e-3)
    dt = 0.5 * directed.stable_time_step()
    for _ in range(20):
        directed.step(dt)
        paired.step(dt)
        assert np.array_equal(directed.bond_alive(), paired.bond_alive())
        assert _close(directed.displacements(), paired.displacements())
    broken = 1.0 - paired.bond_alive().mean()
    assert 0.2 < broken < 0.8, broken
    assert _close(directed.damage(), paired.damage())


def test_pairs_with_a_rigid_half():
    """A notched block with one half handed off (rigid), shaken for 30 steps: both forms give the same force
    density and dilatation (1e-5 of the largest) and the same live bonds, and no bond force on the rigid half."""
    out = []
    for pairs in (False, None):
        mat = pdsim.Material(density=2500.0, youngs_modulus=5.0e9, poisson_ratio=0.25, critical_stretch=2.0e-3)
        o = np.array([1000.0, 0.0, 0.0])
        handoff = pdsim.RigidHandoff(5.0e-4, 1, in_flight=True)  # the spinning half
        body = pdsim.PeridynamicBody(pdsim.box((0.08, 0.04, 0.04), center=tuple(o)), mat, 0.01, rigid_handoff=handoff)
        d = np.array([0.001, 1.0, 1.0])
        body.add_notch(pdsim.BoxRegion(lo=tuple(o - d), hi=tuple(o + d)))
        s = SolverPeridynamics([body], threads=1, pairs=pairs)
        x = s.positions()
        shake = np.where(x[:, :1] > o[0], 1.0, 0.0) * np.random.default_rng(2).standard_normal(x.shape)
        s.set_velocities(np.cross([0.0, 5.0, 30.0], x - x.mean(0)) + shake)
        assert s.handoff.update() == 1
        s.simulate(0.5 * s.stable_time_step(), 30)
        out.append((s.force_density(), s.dilatation(), s.bond_alive(), s.handoff.rigid_particles()))
    (fa, ta, aa, ra), (fb, tb, ab, rb) = out
    assert np.array_equal(ra, rb) and ra.sum() == len(ra) // 2
    assert np.array_equal(aa, ab)
    assert _close(fa, fb) and _close(ta, tb)
    assert np.abs(fb[ra]).max() == 0.0 and np.abs(fb[~ra]).max() > 1e5


def test_pairs_are_bit_identical_on_one_two_and_three_threads():
    """The pair form on 1, 2 and 3 threads (the same fixed pair ranges): after 40 steps of a block that breaks and
    damps its debris, displacements, live bonds, dilatation, force and energy densities are bit-identical."""
    results = []
    for threads in (1, 2, 3):
        s = _block(None, threads=threads, critical_stretch=1.0e-3, debris=1.0e5)
        assert s.threads == threads and s._pairs.range_count == PAIR_RANGES
        s.simulate(0.5 * s.stable_time_step(), 40)
        results.append(
            [s.displacements(), s.bond_alive(), s.dilatation(), s.force_density(), s.strain_energy_density()]
        )
    assert 0.05 < 1.0 - results[0][1].mean() < 0.95
    for other in results[1:]:
        for a, b in zip(results[0], other, strict=True):
            assert np.array_equal(a, b)


def test_which_form_a_scene_gets():
    """CPU: pairs by default, also for a yielding material (and beside a brittle body with the rigid hand-off:
    test_plastic_pairs_beside_a_brittle_body_with_a_rigid_half); a breakable yielding body with the rigid hand-off
    runs the directed form and refuses pairs=True; a setting other than None, True or False is refused, naming the
    field."""
    assert _block(None)._pairs is not None and _block(True)._pairs is not None
    yielding = pdsim.Material(density=1000.0, youngs_modulus=1.0e9, poisson_ratio=0.25, yield_stress=1.0e6)
    body = pdsim.PeridynamicBody(pdsim.box((4e-3,) * 3), yielding, 1.0e-3)
    assert SolverPeridynamics([body], threads=1).bond_passes == "pairs"
    tearing = pdsim.Material(
        density=1000.0, youngs_modulus=1.0e9, poisson_ratio=0.25, yield_stress=1.0e6, critical_stretch=1e-2
    )
    body = pdsim.PeridynamicBody(pdsim.box((4e-3,) * 3), tearing, 1.0e-3, rigid_handoff=True)
    assert SolverPeridynamics([body], threads=1).bond_passes == "directed"
    with pytest.raises(ParameterError, match=r"pairs.*rigid_handoff"):
        SolverPeridynamics([body], threads=1, pairs=True)
    with pytest.raises(ParameterError, match="pairs"):
        _block("yes")


# -- plasticity: the return mapping in pair passes ---------------------------------------------------------------------
def _plastic_block(pairs, threads=1, ductile=False, n=7, elastic_neighbour=False):
    """An n^3 yielding block (h = 1 mm, E = 1 GPa, sigma_Y = 1 MPa, H = 50 MPa, s_c = 1e-3; with ``ductile`` a
    failure plastic strain of 1e-3) at CENTER, pulled apart as _block; with ``elastic_neighbour`` a second, elastic
    and unbreakable block beside it in the same solver (the plastic arrays then cover a prefix of the particles)."""
    h = 1.0e-3
    mat = pdsim.Material(
        density=1000.0,
        youngs_modulus=1.0e9,
        poisson_ratio=0.25,
        yield_stress=1.0e6,
        hardening_modulus=5.0e7,
        critical_stretch=1.0e-3,
        failure_plastic_strain=1.0e-3 if ductile else None,
    )
    bodies = [pdsim.PeridynamicBody(pdsim.box((n * h,) * 3, center=CENTER), mat, h)]
    if elastic_neighbour:
        other = pdsim.Material(density=1000.0, youngs_modulus=1.0e9, poisson_ratio=0.25)
        c = (CENTER[0] + 2 * n * h, CENTER[1], CENTER[2])
        bodies.append(pdsim.PeridynamicBody(pdsim.box((n * h,) * 3, center=c), other, h))
    solver = SolverPeridynamics(bodies, threads=threads, pairs=pairs)
    x = solver.positions()
    for i in range(len(bodies)):  # each block stretched about its own centre
        sl = solver.body_slice(i)
        x[sl] -= x[sl].mean(axis=0)
    solver.set_velocities(1500.0 * x * np.array([1.0, -0.3, 0.2]))
    return solver


def _plastic_state(s):
    """What a plastic step produces: displacements, live bonds, plastic extensions, equivalent plastic strain,
    dilatation, force and energy densities."""
    s.bond_cache()
    return [
        s.displacements(),
        s.bond_alive(),
        s.state.bond_plastic.numpy()[: s.model.plastic_bond_count].copy(),
        s.plastic_strain(),
        s.dilatation(),
        s.force_density(),
        s.strain_energy_density(),
    ]


@pytest.mark.parametrize("case", ["stretch", "ductile", "skewed", "mixed"])
def test_plastic_pairs_follow_the_directed_return_mapping(case):
    """A yielding, breaking block pulled apart for 20 steps, both forms side by side: after every step the same live
    bonds; at the end displacements, plastic extensions, equivalent plastic strain, dilatation, force and energy
    densities agree to 1e-5 of the largest value (float32 round-off of sums in another order), with most particles
    yielding and some bonds broken. Cases: breaking by stretch; by ductile failure too; bond weights made
    asymmetric (the reverse bond's weights are the ones scattered); an elastic block in the same solver."""
    ductile, mixed = case == "ductile", case == "mixed"
    directed = _plastic_block(False, ductile=ductile, elastic_neighbour=mixed)
    paired = _plastic_block(None, ductile=ductile, elastic_neighbour=mixed)
    assert directed.bond_passes == "directed" and paired.bond_passes == "pairs"
    if case == "skewed":  # w V beta too (the plastic sums' weight), before _skew_weights rebuilds the pairs
        for s in (directed, paired):
            w = s.model.bond_wv
            w.assign(w.numpy() * np.random.default_rng(6).uniform(0.8, 1.25, w.shape[0]).astype(np.float32))
            _skew_weights(s, np.random.default_rng(4))
    dt = 0.5 * directed.stable_time_step()
    for _ in range(20):
        directed.step(dt)
        paired.step(dt)
        assert np.array_equal(directed.bond_alive(), paired.bond_alive())
    a, b = _plastic_state(directed), _plastic_state(paired)
    for x, y in zip(a[2:], b[2:], strict=True):
        assert _close(x, y)
    assert _close(a[0], b[0])
    yielded = (b[3][: paired.model.plastic_particle_count] > 0).mean()
    broken = 1.0 - b[1].mean()
    assert yielded > 0.5 and 0.01 < broken < 0.9, (yielded, broken)
    if mixed:
        assert paired.model.plastic_particle_count == paired.particle_count // 2


def test_plastic_pairs_beside_a_brittle_body_with_a_rigid_half():
    """A yielding, breaking block (no hand-off) pulled apart beside a notched brittle block with the rigid hand-off,
    one of whose halves is handed off (rigid), in one solver: the default is the pair form (the yielding particles
    stay outside rigid fragments). Against the directed form over 20 steps: the same live bonds after every step,
    and at the end displacements, plastic state, dilatation and force density to 1e-5 of the largest value, with
    most yielding particles yielding, no bond force on the rigid half and bond forces on the other. A live list
    without the yielding particles is refused."""
    out = []
    for pairs in (False, None):
        h = 1.0e-3
        yielding = pdsim.Material(
            density=1000.0, youngs_modulus=1.0e9, poisson_ratio=0.25, yield_stress=1.0e6, hardening_modulus=5.0e7,
            critical_stretch=1.0e-3,
        )  # fmt: skip
        brittle = pdsim.Material(density=1000.0, youngs_modulus=1.0e9, poisson_ratio=0.25, critical_stretch=2.0e-3)
        o = np.asarray(CENTER) + np.array([0.02, 0.0, 0.0])
        notched = pdsim.PeridynamicBody(
            pdsim.box((8 * h, 4 * h, 4 * h), center=tuple(o)), brittle, h, rigid_handoff=pdsim.RigidHandoff(5.0e-4, 1)
        )
        d = np.array([1.0e-4, 1.0, 1.0])
        notched.add_notch(pdsim.BoxRegion(lo=tuple(o - d), hi=tuple(o + d)))
        s = SolverPeridynamics([pdsim.PeridynamicBody(pdsim.box((7 * h,) * 3, center=CENTER), yielding, h), notched],
                               threads=1, pairs=pairs)  # fmt: skip
        assert s.bond_passes == ("directed" if pairs is False else "pairs")
        x = s.positions()
        v = np.zeros_like(x)
        sl = s.body_slice(0)
        v[sl] = 1500.0 * (x[sl] - x[sl].mean(0)) * np.array([1.0, -0.3, 0.2])
        sl = s.body_slice(1)
        right = x[sl][:, 0] > o[0]
        v[sl] = np.cross([0.0, 5.0, 30.0], x[sl] - o) + right[:, None] * np.random.default_rng(2).standard_normal(
            (right.size, 3)
        )
        s.set_velocities(v)
        assert s.handoff.update() == 1  # the quiet left half
        alive = []
        dt = 0.5 * s.stable_time_step()
        for _ in range(20):
            s.step(dt)
            alive.append(s.bond_alive())
        out.append((alive, _plastic_state(s), s.handoff.rigid_particles()))
    (aa, sa, ra), (ab, sb, rb) = out
    assert all(np.array_equal(a, b) for a, b in zip(aa, ab, strict=True))
    for x, y in zip(sa[2:6], sb[2:6], strict=True):
        assert _close(x, y)
    assert _close(sa[0], sb[0])
    assert np.array_equal(ra, rb) and ra.sum() == 64
    f = sb[5]
    assert np.abs(f[ra]).max() == 0.0 and np.abs(f[~ra]).max() > 1e5
    npp = s.model.plastic_particle_count
    assert (sb[3][:npp] > 0).mean() > 0.5
    with pytest.raises(ValueError, match="yielding"):
        s._pairs.set_particles(np.arange(1, s.particle_count))


def test_plastic_pairs_are_bit_identical_on_threads_and_through_resume():
    """The plastic pair form (ductile failure on) on 1, 2 and 3 threads: after 20 steps the plastic state is
    bit-identical; a run checkpointed at step 8 and restored into a fresh solver ends on the same bits."""
    results = []
    for threads in (1, 2, 3):
        s = _plastic_block(None, threads=threads, ductile=True)
        assert s.threads == threads and s.bond_passes == "pairs"
        dt = 0.5 * s.stable_time_step()
        s.simulate(dt, 20)
        results.append(_plastic_state(s))
    first = _plastic_block(None, ductile=True)
    first.simulate(dt, 8)
    saved = first.checkpoint()
    first.simulate(dt, 5)  # the checkpoint is a copy: stepping on does not change it
    resumed = _plastic_block(None, ductile=True, threads=2)
    resumed.restore(saved)
    resumed.simulate(dt, 12)
    results.append(_plastic_state(resumed))
    assert (results[0][3] > 0).mean() > 0.5 and 0.01 < 1.0 - results[0][1].mean() < 0.9
    for other in results[1:]:
        for x, y in zip(results[0], other, strict=True):
            assert np.array_equal(x, y)


def test_pair_layout():
    """Each undirected bond once, from its lower particle, with its reverse; a bond without a reverse is refused."""
    offsets = np.array([0, 2, 4, 6])
    neighbors = np.array([1, 2, 0, 2, 0, 1])
    pair_offsets, forward, reverse = pair_layout(offsets, neighbors, np.array([2, 4, 0, 5, 1, 3]))
    assert pair_offsets.tolist() == [0, 2, 3, 3]
    assert forward.tolist() == [0, 1, 3] and reverse.tolist() == [2, 4, 5]
    with pytest.raises(ValueError, match="symmetric"):
        pair_layout(np.array([0, 1, 1]), np.array([1]), np.array([-1]))
