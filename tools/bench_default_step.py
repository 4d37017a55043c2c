"""The default scene's step (pdsim/default_scene.py: 2,560 particles, 309,440 bonds) in whatever pdsim the running
Python imports: wall, process CPU and main-thread CPU time per step, on one thread and on two, and the launches a step
makes. The tool for A/B comparisons of two checkouts run in turn (the step's host overhead: launches, hand-offs to the
pool thread, Python), e.g. a checkout from ``git archive`` on ``PYTHONPATH`` with its ``kernels`` linked as
``pdsim/kernels``:

    for i in 1 2 3; do (cd /tmp/base && PYTHONPATH=/tmp/base .venv/bin/python tools/bench_default_step.py); \
        .venv/bin/python tools/bench_default_step.py; done

Each figure is the median over ROUNDS rounds of one frame's steps (134) at 0.7 x the stable step, after a warm-up
frame; ``--json`` prints one JSON line.
"""

import argparse
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", action="store_true", help="one JSON line")
    args = parser.parse_args()
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
