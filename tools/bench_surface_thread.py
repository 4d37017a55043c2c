"""Wall time of a breaking gallery scene with its render surfaces built on the run's surface thread against the same
run with every surface built in the main thread (``Scene.run(surface_thread=...)``), in turn, in one process (warm
kernel cache). The two caches are the same bit for bit (tests/test_surface_thread.py).

    python tools/bench_surface_thread.py                       # drop_shatter at its PREVIEW settings, 3 pairs
    python tools/bench_surface_thread.py --frames 10 --pairs 2     # the first 10 frames of 24
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tools"))

from make_gallery import load_scene_module  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", default="drop_shatter", help="a scene of scenes/ with PREVIEW settings")
    parser.add_argument("--pairs", type=int, default=3, help="pairs of runs (default 3)")
    parser.add_argument("--frames", type=int, default=None, help="frames (default: the PREVIEW settings')")
    args = parser.parse_args(argv)
    module = load_scene_module(args.scene)
    settings = dict(module.PREVIEW)
    if args.frames is not None:
        settings["frames"] = args.frames
    walls = {True: [], False: []}
    with tempfile.TemporaryDirectory() as tmp:
        module.build_scene(**settings).run(os.path.join(tmp, "warm.usdc"), progress=False)  # warm-up
        for _ in range(args.pairs):
            for threaded in (True, False):
                scene = module.build_scene(**settings)
                t0 = time.perf_counter()
                scene.run(os.path.join(tmp, f"{threaded}.usdc"), progress=False, surface_thread=threaded)
                walls[threaded].append(time.perf_counter() - t0)
    print(f"machine: {platform.node()}, {os.cpu_count()} CPUs, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    print(f"{args.scene} at {settings}, {args.pairs} pairs")
    print("| surfaces built | wall [s] (runs) | median |")
    print("|---|---|---:|")
    for threaded, name in ((True, "on the surface thread"), (False, "in the main thread")):
        runs = ", ".join(f"{w:.1f}" for w in walls[threaded])
        print(f"| {name} | {runs} | {statistics.median(walls[threaded]):.1f} |")
    ratios = [a / b for a, b in zip(walls[True], walls[False], strict=True)]
    print(f"thread / main, pair by pair: {', '.join(f'{r:.2f}' for r in ratios)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
