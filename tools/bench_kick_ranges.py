"""Cost of the second half kick (kernels/integration.py) as one launch and split into two particle ranges launched at
once (pdsim/peridynamics/ranges.py, ParticleRanges), per point count: the best of 7 rounds of 200 launches, wall clock
[us per launch]. It sets pdsim/peridynamics/ranges.py's MIN_POINTS_PER_THREAD (the split pays once each range's share
of the kick costs more than handing it to a pool thread).

    python tools/bench_kick_ranges.py 1000 4000 16000 64000
"""

import argparse
import time

import numpy as np
import warp as wp

from pdsim.kernels import integration as ki
from pdsim.peridynamics.ranges import ParticleRanges

ROUNDS = 7
LAUNCHES = 200


def kick_times(n: int, device: str = "cpu") -> dict[int, float]:
    """{ranges: best wall time of one kick launch over ``n`` free points [us]} for one range and two."""
    k = ki.integration_kernels(wp.float32)
    args = {
        "force": wp.zeros(n, dtype=wp.vec3, device=device),
        "inv_mass": wp.ones(n, dtype=float, device=device),
        "gravity": wp.vec3(0.0, 0.0, -9.8),
        "damping": wp.zeros(n, dtype=float, device=device),
        "point_condition": wp.full(n, -1, dtype=wp.int32, device=device),
        "point_kind": wp.zeros(n, dtype=wp.int32, device=device),
        "cond_axes": wp.zeros(1, dtype=wp.vec3, device=device),
        "velocities": wp.zeros(n, dtype=wp.vec3, device=device),
        "accelerations": wp.zeros(n, dtype=wp.vec3, device=device),
    }
    out = {}
    for threads in (1, 2):
        ranges = ParticleRanges(np.arange(n + 1, dtype=np.int64) * 100, threads, wp.get_device(device))
        for _ in range(20):  # kernel load, recorded launches, pool threads started
            ki.kick(k, n, dt=1.0e-7, device=device, ranges=ranges.launch, **args)
        best = float("inf")
        for _ in range(ROUNDS):
            start = time.perf_counter()
            for _ in range(LAUNCHES):
                ki.kick(k, n, dt=1.0e-7, device=device, ranges=ranges.launch, **args)
            best = min(best, (time.perf_counter() - start) / LAUNCHES)
        out[threads] = best * 1.0e6
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("points", type=int, nargs="+", help="point counts")
    args = parser.parse_args()
    wp.config.quiet = True
    for n in args.points:
        t = kick_times(n)
        print(f"{n} particles: kick us per launch, 1 range {t[1]:.1f}, 2 ranges {t[2]:.1f}")


if __name__ == "__main__":
    main()
