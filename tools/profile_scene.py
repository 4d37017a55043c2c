"""Where a scene's run spends its time: ``Scene.run`` under cProfile, the functions of the frame loop, the render
surfaces and the writer by cumulative time (the main thread only: with the surface thread on, its work does not
show; pass ``--main-thread`` to profile the surfaces in the main thread).

    python tools/profile_scene.py drop_shatter --main-thread  # a scene of scenes/ at its PREVIEW settings
    python tools/profile_scene.py default                     # the shipped default scene
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tools"))

from make_gallery import load_scene_module  # noqa: E402

SHOWN = "run.py|solver.py|fragment_surfaces|writer.py|usd"  # the functions listed


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("scene", help="a scene of scenes/ (run at its PREVIEW settings), or 'default'")
    parser.add_argument("--main-thread", action="store_true", help="build the render surfaces in the main thread")
    parser.add_argument("--lines", type=int, default=40, help="functions listed (default 40)")
    parser.add_argument("--frames", type=int, default=None, help="frames to run (default: the scene's)")
    args = parser.parse_args(argv)
    if args.scene == "default":
        from pdsim.default_scene import build_scene

        scene = build_scene()
    else:
        module = load_scene_module(args.scene)
        scene = module.build_scene(**getattr(module, "PREVIEW", {}))
    profile = cProfile.Profile()
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        profile.enable()
        scene.run(
            os.path.join(tmp, "out.usdc"), frames=args.frames, progress=False, surface_thread=not args.main_thread
        )
        profile.disable()
        wall = time.perf_counter() - t0
    print(f"{args.scene}: wall {wall:.1f} s under cProfile, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    pstats.Stats(profile).sort_stats("cumulative").print_stats(SHOWN, args.lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
