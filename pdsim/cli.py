"""Command line: ``pdsim run [SCENE.py] --out CACHE.usdc [--frames N] [--device cpu|cuda] [--dt SECONDS]``.

A scene script is a Python file defining ``build_scene()`` that returns a :class:`pdsim.Scene`. With no script the
shipped default scene runs. User mistakes print one line and exit with status 1; Ctrl-C exits with 130 and leaves the
cache of the finished frames.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys

from . import __version__
from .errors import ParameterError, PdsimError


def _parser(prog: str = "pdsim", *, with_scene: bool = True) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description="pdsim: fracture-animation simulator writing USD caches")
    p.add_argument("--version", action="version", version=f"pdsim {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    r = sub.add_parser("run", help="run a scene script (or the default scene) and write a USD cache")
    if with_scene:
        r.add_argument("scene", nargs="?", help="scene script defining build_scene(); default: the shipped cantilever")
    _add_run_options(r)
    return p


def _add_run_options(r: argparse.ArgumentParser):
    r.add_argument("--out", help="output cache (.usdc, .usda or .usd); default: <scene name>.usdc")
    r.add_argument("--frames", type=int, help="number of frames after the rest pose (integer >= 1)")
    r.add_argument("--device", choices=["cpu", "cuda"], help="Warp device (default: cuda when present, else cpu)")
    r.add_argument("--dt", type=float, help="time step in seconds (default: automatic stable step)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")


def load_scene_script(path: str):
    """Imports a scene script and returns its ``build_scene`` callable."""
    if not path.endswith(".py"):
        raise ParameterError("scene", path, "a Python scene script (*.py)")
    if not os.path.isfile(path):
        raise ParameterError("scene", path, "an existing file")
    folder = os.path.dirname(os.path.abspath(path))
    if folder not in sys.path:  # as when the script runs on its own: its folder's modules import
        sys.path.insert(0, folder)
    spec = importlib.util.spec_from_file_location("pdsim_user_scene", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    build = getattr(module, "build_scene", None)
    if not callable(build):
        raise ParameterError("scene", path, "a script that defines build_scene() returning a pdsim.Scene")
    return build


def _resolve_device(name: str | None) -> str | None:
    if name != "cuda":
        return name
    import warp as wp

    if wp.get_cuda_device_count() == 0:
        raise ParameterError("device", "cuda", "'cpu' on this machine (no CUDA device found)")
    return "cuda"


def _execute(build_scene, args) -> int:
    import warp as wp

    from .scene import Scene

    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING  # no per-module load lines; warnings and errors still show
    scene = build_scene()
    if not isinstance(scene, Scene):
        raise ParameterError("build_scene()", type(scene).__name__, "a function returning a pdsim.Scene")
    out = args.out or f"{scene.name}.usdc"
    try:
        report = scene.run(
            out, frames=args.frames, device=_resolve_device(args.device), dt=args.dt, progress=not args.quiet
        )
    except KeyboardInterrupt:
        print(f"pdsim: interrupted; {out} holds the frames finished so far", file=sys.stderr)
        return 130
    print(
        f"pdsim: wrote {report.path}: {report.frames_written} frames, {report.summary}, "
        f"dt={report.dt:.3g} s x {report.substeps_per_frame} substeps/frame, "
        f"{report.wall_seconds:.1f} s"
    )
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``pdsim`` command."""
    parser = _parser()
    args = parser.parse_args(argv)
    if args.command != "run":
        parser.print_help()
        return 2
    try:
        if args.scene:
            build = load_scene_script(args.scene)
        else:
            from .default_scene import build_scene as build
        return _execute(build, args)
    except PdsimError as exc:
        print(f"pdsim: error: {exc}", file=sys.stderr)
        return 1


def run_script(build_scene, argv: list[str] | None = None) -> int:
    """For scene scripts: ``if __name__ == "__main__": run_script(build_scene)``; takes the options of ``pdsim run``."""
    parser = argparse.ArgumentParser(prog=os.path.basename(sys.argv[0]), description="run this pdsim scene")
    _add_run_options(parser)
    args = parser.parse_args(argv)
    try:
        code = _execute(build_scene, args)
    except PdsimError as exc:
        print(f"pdsim: error: {exc}", file=sys.stderr)
        code = 1
    sys.exit(code)


if __name__ == "__main__":
    sys.exit(main())
