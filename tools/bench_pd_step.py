"""Times the peridynamic step of whatever pdsim the running Python imports, per CPU second and per wall second: the
tool for A/B comparisons of two checkouts (each with its own virtual environment), run alternately.

    git worktree add /tmp/base 3a64340 && python3 -m venv /tmp/basevenv && /tmp/basevenv/bin/pip install -e /tmp/base
    for i in 1 2 3 4 5; do (cd /tmp && /tmp/basevenv/bin/python $PWD/tools/bench_pd_step.py); \
        .venv/bin/python tools/bench_pd_step.py; done

Block: 25^3 particles, h = 1 mm, E = 1 GPa, nu = 0.25, families cut at 3.015 h with full volumes, random
velocities +-0.1 m/s, 100 steps of half the stable estimate after 3 warm-up steps. Uses only API present in every
version (PeridynamicBody, SolverPeridynamics.step, set_velocities). The bond passes run on one thread (a checkout
that splits them over threads reads the environment variable PDSIM_THREADS, set here to 1 unless it is already set),
so the figures compare what one core does.
"""

import os
import time

import numpy as np

os.environ.setdefault("PDSIM_THREADS", "1")  # set before pdsim is imported, whenever a checkout reads it

import warp as wp

wp.config.quiet = True  # before pdsim is imported (importing it initialises Warp)

import pdsim  # noqa: E402


def main() -> None:

    n, h = 25, 1.0e-3
    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e9, poisson_ratio=0.25)
    body = pdsim.PeridynamicBody(pdsim.box((n * h, n * h, n * h)), mat, h, partial_volumes=False)
    solver = pdsim.SolverPeridynamics([body])
    rng = np.random.default_rng(0)
    solver.set_velocities(rng.uniform(-0.1, 0.1, (solver.model.particle_count, 3)))
    dt = 0.5 * solver.stable_time_step()
    for _ in range(3):
        solver.step(dt)
    wp.synchronize()
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(100):
        solver.step(dt)
    wp.synchronize()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    visits = solver.model.bond_count * 100
    print(f"pdsim {pdsim.__file__}: {visits / wall / 1e6:.1f} M bond visits/s wall, {visits / cpu / 1e6:.1f} per CPU s")


if __name__ == "__main__":
    main()
