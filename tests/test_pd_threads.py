"""The peridynamic bond passes on several CPU threads (pdsim/peridynamics/ranges.py, ParticleRanges): the particle
ranges cover every particle once with about equal bond counts, results are bit-identical for any thread count, and
the thread setting is checked."""

import numpy as np
import pytest

import pdsim
from pdsim.errors import ParameterError
from pdsim.peridynamics import ranges as pd_ranges
from pdsim.peridynamics.ranges import MIN_BONDS_PER_THREAD, ParticleRanges, available_cores

CENTER = (150.0, -40.0, 20.0)  # far from the origin: the local frame must not depend on the thread count either


def _block(threads):
    """A 7^3 block (h = 1 mm, E = 1 GPa) that yields (sigma_Y = 1 MPa, linear hardening), breaks (s_c = 1e-3) and
    damps its debris (1e5 1/s above a damage of 0.5), pulled apart by a stretch-rate field of 1500 1/s along x (-450
    along y, 300 along z) at (150, -40, 20) m."""
    h = 1.0e-3
    mat = pdsim.Material(
        density=1000.0,
        youngs_modulus=1.0e9,
        poisson_ratio=0.25,
        yield_stress=1.0e6,
        hardening_modulus=1.0e8,
        critical_stretch=1.0e-3,
        debris_damping=1.0e5,
        debris_damage=0.5,
    )
    body = pdsim.PeridynamicBody(pdsim.box((7 * h, 7 * h, 7 * h), center=CENTER), mat, h)
    solver = pdsim.SolverPeridynamics([body], threads=threads)
    x = body.rest_positions - np.asarray(CENTER)
    solver.set_velocities(1500.0 * x * np.array([1.0, -0.3, 0.2]))
    return solver


def test_thread_count_does_not_change_the_result(monkeypatch):
    """1, 2 and 3 threads: after 40 steps of a block that yields and breaks, the displacements, live bonds,
    equivalent plastic strains, dilatations and energy densities are bit-identical (each particle's arithmetic is the
    same whatever range it falls in), and the run did yield, break bonds and damp debris (so the comparison covers
    those branches: between 5 % and 95 % of the bonds broken, plastic strain > 1e-5, some damage above the debris
    threshold). The kick and drift run on the ranges too (at any particle count here, to cover that path)."""
    monkeypatch.setattr(pd_ranges, "MIN_POINTS_PER_THREAD", 1)
    results = []
    for threads in (1, 2, 3):
        solver = _block(threads)
        assert solver.threads == threads
        assert (solver.kin.ranges is None) == (threads == 1)
        dt = 0.5 * solver.stable_time_step()
        solver.simulate(dt, 40)
        results.append(
            (
                solver.displacements(),
                solver.bond_alive(),
                solver.plastic_strain(),
                solver.dilatation(),
                solver.strain_energy_density(),
                solver.damage(),
            )
        )
    alive = results[0][1]
    assert 0.05 < 1.0 - alive.mean() < 0.95
    assert results[0][2].max() > 1.0e-5
    assert results[0][5].max() > 0.5
    assert np.all(np.isfinite(results[0][0]))
    for other in results[1:]:
        for a, b in zip(results[0], other, strict=True):
            assert np.array_equal(a, b)


def test_ranges_cover_every_particle_once_with_equal_bond_counts():
    """Families of very different sizes: the ranges are contiguous, cover 0 .. n - 1 once, and each holds a quarter
    of the cost (bond count + 4 per particle) within the largest single particle's cost."""
    import warp as wp

    rng = np.random.default_rng(1)
    sizes = rng.integers(0, 200, 1000)
    sizes[100:200] = 0  # a stretch of particles without bonds
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    r = ParticleRanges(offsets, 4, wp.get_device("cpu"))
    assert len(r.ranges) == 4
    assert r.ranges[0][0] == 0
    assert sum(c for _, c in r.ranges) == 1000
    for (a, c), (b, _) in zip(r.ranges, r.ranges[1:]):
        assert a + c == b
    cost = sizes + 4
    share = [cost[a : a + c].sum() for a, c in r.ranges]
    assert max(abs(s - cost.sum() / 4) for s in share) <= cost.max()
    assert [c for _, c in ParticleRanges(offsets[:3], 8, wp.get_device("cpu")).ranges] == [1, 1]  # <= one per particle


def test_thread_setting(monkeypatch):
    """threads: an integer >= 1, else PDSIM_THREADS, else every core of the process's affinity with at least
    MIN_BONDS_PER_THREAD bonds per thread; the kick and drift split only with MIN_POINTS_PER_THREAD particles per
    thread; bad values raise ParameterError naming the field."""
    monkeypatch.delenv("PDSIM_THREADS", raising=False)
    solver = _block(None)
    assert solver.threads == max(1, min(available_cores(), solver.bond_count // MIN_BONDS_PER_THREAD))
    monkeypatch.setenv("PDSIM_THREADS", "2")
    assert _block(None).threads == 2
    solver.threads = 3
    assert solver.threads == 3
    assert solver.kin.ranges is None  # 343 particles: the kick and drift stay one launch (MIN_POINTS_PER_THREAD)
    monkeypatch.setattr(pd_ranges, "MIN_POINTS_PER_THREAD", solver.particle_count // 3)
    solver.threads = 3
    assert solver.kin.ranges is not None
    for bad in ("0", "two"):
        monkeypatch.setenv("PDSIM_THREADS", bad)
        with pytest.raises(ParameterError, match="PDSIM_THREADS"):
            _block(None)
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ParameterError, match="threads"):
            _block(bad)


def test_checkpoint_of_a_yielding_block_continues_exactly():
    """A checkpoint taken after 20 steps of the yielding, breaking block and restored into a fresh solver continues
    bit-identically to the uninterrupted run for 20 more steps (the mirror of the plastic extensions that the force
    pass reads is rebuilt from the restored extensions), and plastic flow happened before the checkpoint."""
    a = _block(2)
    dt = 0.5 * a.stable_time_step()
    a.simulate(dt, 20)
    assert a.plastic_strain().max() > 1.0e-5
    state = a.checkpoint()
    a.simulate(dt, 20)
    b = _block(2)
    b.restore(state)
    b.simulate(dt, 20)
    assert np.array_equal(a.displacements(), b.displacements())
    assert np.array_equal(a.bond_alive(), b.bond_alive())
    assert np.array_equal(a.plastic_strain(), b.plastic_strain())


def test_pool_threads_run_every_range_and_hand_back_what_one_raised():
    """The range launches' pool threads (ranges.py, _Workers): every task runs once per pass, the caller's first; a
    task that raises is re-raised in the caller once all have finished, and the pool keeps working after it."""
    pool = pd_ranges._executor(2)
    done = []
    pool.run(lambda: done.append("first"), [lambda: done.append("a"), lambda: done.append("b")])
    assert sorted(done) == ["a", "b", "first"]

    def fails():
        raise ValueError("range 2")

    done.clear()
    with pytest.raises(ValueError, match="range 2"):
        pool.run(lambda: done.append("first"), [fails, lambda: done.append("b")])
    assert sorted(done) == ["b", "first"]
    done.clear()
    pool.run(lambda: done.append("first"), [lambda: done.append("a")])
    assert sorted(done) == ["a", "first"]
