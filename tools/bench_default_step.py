"""The default scene's step (pdsim/default_scene.py: 2,560 particles, 309,440 bonds) in whatever pdsim the running
Python imports: wall, process CPU and main-thread CPU time per step, on one thread and on two, and the launches a step
makes. The tool for A/B comparisons of two checkouts run in turn (the step's host overhead: launches, hand-offs to the
pool thread, Python), e.g. a checkout from ``git archive`` on ``PYTHONPATH`` with its ``kernels`` linked as
``pdsim/kernels``:

    for i in 1 2 3; do (cd /tmp/base && PYTHONPATH=/tmp/base .venv/bin/python tools/bench_default_step.py); \
        .venv/bin/python tools/bench_default_step.py; done

Each figure is the median over ROUNDS rounds of one frame's steps (134) at 0.7 x the stable step, after a warm-up
frame; ``--json`` prints one JSON line. ``--parts`` prints instead what a step's parts cost on the main thread's CPU
clock (the fastest of ROUNDS rounds of 100): each bond pass's range launched alone (two threads' ranges), and one
kick-drift launch over the 2,560 points through ``wp.launch``, replayed from a recording, and the compiled kernel
alone.
"""

import argparse
import ctypes
import json
import statistics
import time

import warp as wp

wp.config.quiet = True  # before pdsim is imported (importing it initialises Warp)

from pdsim.default_scene import build_scene  # noqa: E402

ROUNDS = 7
STEPS = 134


def step_times(threads: int) -> dict:
    """Median wall, process CPU and main-thread CPU time per step [ms] on ``threads`` threads."""
    solver = build_scene().build_solvers(device="cpu")[0]
    solver.threads = threads
    dt = 0.7 * solver.stable_time_step()
    for _ in range(STEPS):  # kernels loaded, launches recorded, pool thread started
        solver.step(dt)
    wall, cpu, main = [], [], []
    for _ in range(ROUNDS):
        w0, c0, m0 = time.perf_counter(), time.process_time(), time.thread_time()
        for _ in range(STEPS):
            solver.step(dt)
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
        main.append(time.thread_time() - m0)
    per_step = 1.0e3 / STEPS
    return {
        "wall_ms": statistics.median(wall) * per_step,
        "cpu_ms": statistics.median(cpu) * per_step,
        "main_thread_cpu_ms": statistics.median(main) * per_step,
    }


def launches_per_step() -> int:
    """Kernel launches of one step (every launch, replayed or not), counted over one frame's steps."""
    solver = build_scene().build_solvers(device="cpu")[0]
    dt = 0.7 * solver.stable_time_step()
    solver.step(dt)
    count = [0]
    original, original_cmd = wp.launch, wp.Launch.launch

    def counted(*args, **kwargs):
        if not kwargs.get("record_cmd"):
            count[0] += 1
        return original(*args, **kwargs)

    def counted_cmd(self, *args, **kwargs):
        count[0] += 1
        return original_cmd(self, *args, **kwargs)

    wp.launch, wp.Launch.launch = counted, counted_cmd
    try:
        for _ in range(STEPS):
            solver.step(dt)
    finally:
        wp.launch, wp.Launch.launch = original, original_cmd
    return round(count[0] / STEPS)


def _fastest(call) -> float:
    """The fastest of ROUNDS rounds of 100 calls of ``call``, main-thread CPU time per call [us]."""
    best = float("inf")
    for _ in range(ROUNDS):
        t0 = time.thread_time()
        for _ in range(100):
            call()
        best = min(best, (time.thread_time() - t0) / 100)
    return best * 1.0e6


def parts() -> dict:
    """Main-thread CPU [us] of each bond pass's range launched alone and of one kick-drift launch three ways."""
    solver = build_scene().build_solvers(device="cpu")[0]
    solver.threads = 2
    dt = 0.7 * solver.stable_time_step()
    for _ in range(STEPS):
        solver.step(dt)
    out = {}
    for key, (_, commands, _) in solver._ranges._commands.items():
        name = key.split("__")[-1]
        for i, cmd in enumerate(commands):
            out[f"{name} range {i}"] = _fastest(cmd.launch)
    kin = solver.kin
    inputs = [0, kin.u, kin.v, kin.a, kin.point_condition, kin.active_kind, kin.cond_axes, kin.active_velocity]
    inputs += [kin.k.dtype(dt), kin.point_kind]
    kernel, n = kin.k.kick_drift, kin.point_count
    out["kick_drift wp.launch"] = _fastest(lambda: wp.launch(kernel, dim=n, inputs=inputs, device="cpu"))
    cmd = wp.launch(kernel, dim=n, inputs=inputs, device="cpu", record_cmd=True)
    out["kick_drift replayed"] = _fastest(cmd.launch)
    args, _ = wp._src.context._build_cpu_args_structs(kernel, cmd.hooks, cmd.params, False)
    bounds, packed = ctypes.byref(cmd.params[0]), ctypes.byref(args)
    out["kick_drift kernel alone"] = _fastest(lambda: cmd.hooks.forward(bounds, packed))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", action="store_true", help="one JSON line")
    parser.add_argument("--parts", action="store_true", help="the step's parts instead (see the module)")
    args = parser.parse_args()
    if args.parts:
        for name, us in parts().items():
            print(f"{name}: {us:.1f} us main-thread CPU")
        return
    out = {"launches_per_step": launches_per_step(), "threads": {t: step_times(t) for t in (1, 2)}}
    if args.json:
        print(json.dumps(out))
        return
    print(f"launches per step: {out['launches_per_step']}")
    for t, r in out["threads"].items():
        print(
            f"{t} thread{'s' if t > 1 else ''}: {r['wall_ms']:.3f} ms wall, {r['cpu_ms']:.3f} ms CPU, "
            f"{r['main_thread_cpu_ms']:.3f} ms main-thread CPU per step"
        )


if __name__ == "__main__":
    main()
