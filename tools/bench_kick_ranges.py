"""Cost of the second half kick (kernels/integration.py) as one launch and split into two particle ranges launched at
once (pdsim/peridynamics/ranges.py, ParticleRanges), per point count: the best of 7 rounds of 200 launches, wall clock
[us per launch]. It sets pdsim/peridynamics/ranges.py's MIN_POINTS_PER_THREAD (the split pays once each range's share
of the kick costs more than handing it to a pool thread).

    python tools/bench_kick_ranges.py 1000 4000 16000 64000
"""

import time, numpy as np, warp as wp
wp.config.quiet = True
from pdsim.kernels import integration as ki
from pdsim.peridynamics.ranges import ParticleRanges
k = ki.integration_kernels(wp.float32)
import sys
for n in [int(x) for x in sys.argv[1:]]:
    d = "cpu"
    z = lambda: wp.zeros(n, dtype=wp.vec3, device=d)
    u, v, a, f = z(), z(), z(), z()
    args = dict(force=f, inv_mass=wp.ones(n, dtype=float, device=d), gravity=wp.vec3(0, 0, -9.8), damping=wp.zeros(n, dtype=float, device=d),
                point_condition=wp.full(n, -1, dtype=wp.int32, device=d), point_kind=wp.zeros(n, dtype=wp.int32, device=d),
                cond_axes=wp.zeros(1, dtype=wp.vec3, device=d), velocities=v, accelerations=a)
    res = {}
    for threads in (1, 2):
        r = ParticleRanges(np.arange(n + 1, dtype=np.int64) * 100, threads, wp.get_device(d))
        for _ in range(20): ki.kick(k, n, dt=1e-7, device=d, ranges=r.launch, **args)
        best = 1e9
        for rep in range(7):
            t = time.perf_counter()
            for _ in range(200): ki.kick(k, n, dt=1e-7, device=d, ranges=r.launch, **args)
            best = min(best, (time.perf_counter() - t) / 200)
        res[threads] = best * 1e6
    print(n, "particles: kick us per launch, 1 range %.1f, 2 ranges %.1f" % (res[1], res[2]))
