"""The pair pass against the directed form on the benchmark block of tools/bench_pd_throughput.py, in one process:
two solvers (pairs=False, pairs=True) from the same state, timed in interleaved rounds of 20 steps (process CPU time
and wall clock per round), and a check that both end bit for bit the same.

    python tools/bench_pd_pairs.py N STATE THREADS [ROUNDS] [plastic]     e.g. 20 ramp 1 6, 20 fracture 1 6 plastic
"""
import sys, time, numpy as np
sys.path.insert(0, "tools")
import warp as wp
wp.config.quiet = True
import bench_pd_throughput as b
import lammps_peri as lp
import pdsim
n = int(sys.argv[1]); state = sys.argv[2]; threads = int(sys.argv[3]); plastic = "plastic" in sys.argv
steps, rounds = 20, int(sys.argv[4]) if len(sys.argv) > 4 and sys.argv[4].isdigit() else 5
sc = b.critical_stretch_for(state, False)
orig = pdsim.SolverPeridynamics
sol = {}
for pairs in (False, True):
    pdsim.SolverPeridynamics = lambda *a, **k: orig(*a, pairs=pairs, **k)
    s = b.build_solver(n, horizon_factor=3.015, device="cpu", plastic=plastic, critical_stretch=sc, threads=threads)
    dt = b.TIME_STEP_SAFETY * s.stable_time_step()
    rest = s.positions()
    s.set_velocities(lp.initial_velocities(state, rest, steps * rounds, dt, seed=0))
    s.step(dt)
    sol[pairs] = (s, dt)
t = {False: [], True: []}
for r in range(rounds):
    for pairs in ((False, True) if r % 2 == 0 else (True, False)):
        s, dt = sol[pairs]
        w0, c0 = time.perf_counter(), time.process_time()
        for _ in range(steps):
            s.step(dt)
        t[pairs].append((time.perf_counter() - w0, time.process_time() - c0))
bonds = sol[False][0].bond_count
for pairs in (False, True):
    cpu = np.array([c for _, c in t[pairs]]); wall = np.array([w for w, _ in t[pairs]])
    print(f"pairs={pairs}: M bond visits per CPU s median {bonds*steps/np.median(cpu)/1e6:.1f} (min-max {bonds*steps/cpu.max()/1e6:.1f}-{bonds*steps/cpu.min()/1e6:.1f}); wall median {bonds*steps/np.median(wall)/1e6:.1f}")
ratio = np.array([c for _, c in t[False]]) / np.array([c for _, c in t[True]])
print("CPU-time ratio directed/pairs per round:", np.round(ratio, 3), "median", round(float(np.median(ratio)), 3))
print("same result:", np.array_equal(sol[False][0].displacements(), sol[True][0].displacements()))
