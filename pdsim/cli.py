"""Command line: ``pdsim run [SCENE.py] --out CACHE.usdc [--frames N] [--device cpu|cuda] [--dt SECONDS | --dt-factor F]
[--resume] [--checkpoint-interval SECONDS]`` and
``pdsim preview CACHE --out FILE.png|.gif|.mp4 [--frames A:B] [--color ATTR] [--camera ...] [--size WxH]``,
``pdsim wedge SCENE.py --set NAME=V1,V2 [--set ...] --out DIR [--frames N] [--scheduler tcp://HOST:8786]`` (one cache
per variant, on Dask) and ``pdsim bench accuracy [--quick] [--scheduler ...]`` (the run-time-vs-error map).

A scene script is a Python file defining ``build_scene()`` that returns a :class:`pdsim.Scene`. With no script the
shipped default scene runs. Exit status of ``pdsim run``: 0 done; 1 a user mistake (one line), a refused input or a
write error (the path, the error and the free space; the cache keeps every finished frame); 2 an exception in the
scene script (its file, line and message, and the script's own frames of the traceback); 3 the simulation
diverged (the watchdog's one line names the frame, the body and the likely cause; the cache keeps every finished
frame); 130 Ctrl-C (SIGINT) and 143 SIGTERM: the run stops within a few steps, writes a checkpoint, prints one line
and leaves the cache of the finished frames readable; ``--resume`` continues from the checkpoint.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import warnings

import warp as wp

from . import __version__, sweep
from .checkpoint import StopRequest, signal_exit_code
from .default_scene import build_scene as build_default_scene
from .device import resolve_device
from .errors import InstabilityError, ParameterError, PdsimError
from .explain import explain_scene
from .output.usd_pack import pack_cache
from .preview import write_preview
from .profile import RunProfile
from .scene import Scene
from .scene_script import EXIT_SCRIPT_ERROR, load_scene_script, script_error_message

EXIT_DIVERGED = 3  # exit status when the watchdog stops a diverging run


def _parser(prog: str = "pdsim", *, with_scene: bool = True) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description="pdsim: fracture-animation simulator writing USD caches")
    p.add_argument("--version", action="version", version=f"pdsim {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    r = sub.add_parser("run", help="run a scene script (or the default scene) and write a USD cache")
    if with_scene:
        r.add_argument("scene", nargs="?", help="scene script defining build_scene(); default: the shipped cantilever")
    _add_run_options(r)
    _add_preview_parser(sub)
    _add_wedge_parser(sub)
    _add_pack_parser(sub)
    b = sub.add_parser(
        "bench",
        help="measurements: 'pdsim bench accuracy [options]' runs the run-time-vs-error map (tools/accuracy_map.py)",
        add_help=False,
    )
    b.add_argument("what", nargs="?", help="accuracy")
    b.add_argument("options", nargs=argparse.REMAINDER, help="options of the benchmark ('--help' lists them)")
    return p


def _add_pack_parser(sub) -> None:
    k = sub.add_parser(
        "pack",
        help="pack a clip-layout cache (a .usdc and its .frames/ folder) into one self-contained file",
        description="Packs the clip-layout cache CACHE (written with --layout clips, or left by an interrupted run) "
        "into one file that opens alone with every frame. Without OUT, CACHE is replaced and its run folder removed.",
    )
    k.add_argument("cache", help="the top-level layer of the clip-layout cache (.usdc, .usda, .usd)")
    k.add_argument("out", nargs="?", help="the packed file to write (default: replace CACHE)")


def _pack(args) -> int:
    out = pack_cache(args.cache, args.out)
    print(f"pdsim: packed {args.cache} into {out}")
    return 0


def _add_wedge_parser(sub) -> None:
    w = sub.add_parser(
        "wedge",
        help="run a scene once per combination of settings (on Dask), one USD cache per variant",
        description="Run a scene script once per combination of --set values, one Dask task per variant (a "
        "LocalCluster on this machine, or a farm's scheduler), each writing OUT/<stem>_vNN_<settings>.usdc, and "
        "OUT/wedge.json listing them. Setting names: a build_scene keyword (spacing=0.02,0.01), scene.ATTR "
        "(scene.fps=24,48), material.FIELD (material.fracture_energy=1,2,5), body.NAME.ATTR or "
        "body.NAME.material.FIELD.",
    )
    w.add_argument("scene", help="scene script defining build_scene()")
    w.add_argument(
        "--set",
        dest="settings",
        action="append",
        metavar="NAME=V1,V2,...",
        help="a setting and its values (repeat --set for more settings; every combination runs)",
    )
    w.add_argument("--out", help="folder for the caches and wedge.json (made when missing)")
    w.add_argument("--frames", help="frames per run (integer >= 1; default: the scene's own)")
    w.add_argument("--scheduler", help="Dask scheduler address of a farm, tcp://HOST:8786 (default: a LocalCluster)")
    w.add_argument("--workers", help="worker processes of the default LocalCluster (default: one per core)")
    w.add_argument("--device", choices=["cpu", "cuda"], default="cpu", help="Warp device of the runs (default cpu)")


def _add_preview_parser(sub) -> None:
    v = sub.add_parser(
        "preview",
        help="render a USD cache to a PNG still or a GIF/MP4 animation (CPU ray casting)",
        description="Render a USD cache (any method's) to a PNG still or a GIF/MP4 animation: every Mesh prim, "
        "Points prims as spheres, Lambert shading with shadows on a ground plane, an automatically framed camera.",
    )
    v.add_argument("cache", help="USD cache (.usdc, .usda, .usd)")
    v.add_argument("--out", help="output image: .png (one frame) or .gif / .mp4 (one image per frame)")
    v.add_argument(
        "--frames",
        metavar="A:B",
        help="frames to render: N, or A:B[:STEP] with A inclusive and B exclusive, like Python slices (A:B is frames "
        "A .. B-1; negative values count from the end, -1 is the last frame; write --frames=-1 for a negative "
        "start). Default: all frames for .gif/.mp4, the last frame for .png",
    )
    v.add_argument(
        "--color",
        metavar="ATTR",
        help="colour by this primvar (per face or per vertex; vectors by length): floats through a colour ramp over "
        "the rendered frames' range, integers (fragment ids) by a palette. A body's surface without it takes it from "
        "the body's points (e.g. --color damage). Default: neutral material, crack faces in orange",
    )
    v.add_argument(
        "--camera",
        help="'AZIMUTH,ELEVATION[,DISTANCE]' in degrees, degrees, metres (looking at the centre of all frames' "
        "geometry; azimuth about the stage's up axis from +x; distance fitted when left out), or "
        "'eye=X,Y,Z:target=X,Y,Z' in metres. Default: -60,25 with the distance fitted",
    )
    v.add_argument("--size", metavar="WxH", help="image size in pixels (default 640x480; even sides for .mp4)")
    v.add_argument("--fps", type=str, help="animation frame rate (default: the cache's frames per second)")
    v.add_argument(
        "--points",
        choices=["auto", "all", "none"],
        default="auto",
        help="Points prims drawn as spheres: auto (those without a surface <name>_surface or render mesh "
        "<name>_render beside them, e.g. a lattice), all, or none (default auto)",
    )
    v.add_argument(
        "--fit",
        choices=["auto", "all", "selected", "first"],
        default="auto",
        help="what the automatic camera frames: auto (default: all frames' bodies as far as half the rest pose's "
        "size past it, so far-flung debris leaves the picture instead of shrinking the object), all (every frame's "
        "bodies, however far), the selected frames', or the first frame's",
    )
    v.add_argument("--supersample", type=str, default="1", help="rays per pixel along each axis, 1..4 (default 1)")
    v.add_argument("--no-ground", action="store_true", help="no ground plane (and no shadows on it)")
    v.add_argument("--no-shadows", action="store_true", help="no shadow rays")
    v.add_argument("--device", choices=["cpu", "cuda"], default="cpu", help="Warp device (default: cpu)")


def _number(field: str, text: str | None, kind, allowed: str):
    """Parses an option given as text (so that a bad value is a one-line pdsim error, not an argparse one)."""
    if text is None:
        return None
    try:
        return kind(text)
    except ValueError:
        raise ParameterError(field, text, allowed) from None


def _preview(args) -> int:
    if args.out is None:
        raise ParameterError("out", None, "a path ending in .png (still), .gif or .mp4 (animation)")
    fps = _number("fps", args.fps, float, "a number of frames per second in (0, 1000]")
    supersample = _number("supersample", args.supersample, int, "an integer from 1 to 4")
    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING
    result = write_preview(
        args.cache,
        args.out,
        args.frames,
        fps=fps,
        color=args.color,
        camera=args.camera,
        size=args.size,
        points=args.points,
        fit=args.fit,
        supersample=supersample,
        ground=not args.no_ground,
        shadows=not args.no_shadows,
        device=resolve_device(args.device),
    )
    frames = result.frames
    span = f"frame {frames[0]}" if len(frames) == 1 else f"{len(frames)} frames ({frames[0]}..{frames[-1]})"
    colour = ""
    if result.color_range is not None:
        colour = f", {args.color} {result.color_range[0]:.4g}..{result.color_range[1]:.4g}"
    h, w = result.images[0].shape[:2]
    print(f"pdsim: wrote {args.out}: {span}, {w}x{h}{colour}, {sum(result.seconds) / len(frames):.2f} s/frame")
    empty = [f for f, covered in zip(frames, result.coverage) if not covered.any()]
    if empty:
        which = f"frame {empty[0]}" if len(empty) == 1 else f"{len(empty)} of its frames ({empty[0]}..{empty[-1]})"
        how = (
            "the camera given does not see them"
            if args.camera is not None
            else f"the automatic camera (--fit {args.fit}) frames {FIT_VIEWS[args.fit]}, and they left it; "
            "--fit all frames every frame of the cache, --fit selected the frames drawn"
        )
        verb = "shows" if len(empty) == 1 else "show"
        print(f"pdsim: {which} of {args.out} {verb} nothing of the bodies: {how}")
    return 0


# what the preview's automatic camera frames, by --fit (pdsim.preview.render_cache)
FIT_VIEWS = {
    "auto": "the bodies' rest pose and half its size around it",
    "all": "the bodies over every frame",
    "selected": "the bodies over the frames drawn",
    "first": "the bodies' rest pose",
}


def _add_run_options(r: argparse.ArgumentParser):
    r.add_argument(
        "--explain",
        action="store_true",
        help="print what the scene runs (per body: live features, the kernels a step launches, the state allocated, "
        "the time step and substeps) and exit without simulating or writing anything",
    )
    r.add_argument("--out", help="output cache (.usdc, .usda or .usd); default: <scene name>.usdc")
    r.add_argument("--frames", help="number of frames after the rest pose (integer >= 1)")
    r.add_argument(
        "--layout",
        choices=["file", "clips"],
        default="file",
        help="'file' (default): one self-contained cache file, packed at the end of the run; 'clips': the cache "
        "file plus its <stem>.frames/ folder (for caches too big to pack; docs/cache_format.md)",
    )
    r.add_argument("--device", choices=["cpu", "cuda"], help="Warp device (default: cuda when present, else cpu)")
    r.add_argument("--dt", help="time step in seconds (> 0; default: automatic stable step)")
    r.add_argument(
        "--dt-factor",
        metavar="F",
        help="run at F times the automatic time step (F > 0; default 1; above 1 the run may diverge, which the "
        "watchdog catches). Not with --dt",
    )
    r.add_argument(
        "--resume",
        action="store_true",
        help="continue from the checkpoint <stem>.checkpoint.npz beside --out (written every --checkpoint-interval "
        "and when stopped by SIGTERM or Ctrl-C), appending to the same cache: frames the stopped run wrote after the "
        "checkpoint are replaced, and --out then plays every frame as one uninterrupted run",
    )
    r.add_argument(
        "--checkpoint-interval",
        metavar="SECONDS",
        help="wall time between checkpoints (default 60; 0: every frame; 'off': none, not even when stopped)",
    )
    r.add_argument(
        "--check-interval",
        metavar="STEPS",
        help="steps between the watchdog's divergence checks (default 16; also at every frame end)",
    )
    r.add_argument(
        "--render-points",
        action="store_true",
        help="write the particles of bodies that have a surface as renderable points (default: guides, which "
        "renderers and Blender's importer leave out; pdsim preview --points all draws them either way)",
    )
    r.add_argument(
        "--debris",
        metavar="N",
        help="write fragments of fewer than N particles as instances of the point instancer /World/<body>_debris "
        "instead of as surface meshes (default 0: none; docs/cache_format.md)",
    )
    r.add_argument(
        "--crack-events",
        action="store_true",
        help="write the bonds broken in each frame as the points /World/<body>_crack_events (midpoint, energy, "
        "normal; peridynamic bodies)",
    )
    r.add_argument("--quiet", action="store_true", help="no progress bar and no cost estimate")
    r.add_argument(
        "--profile",
        action="store_true",
        help="at the end, print the wall time of each phase (build, simulate, surfaces, write, checks, other) and "
        "write them with the run's figures to <stem>.report.json beside --out",
    )


def _run_settings(args) -> dict:
    """Scene.run keyword arguments of the run options (one-line ParameterErrors for bad values)."""
    settings = {}
    # numbers here; their ranges are checked by Scene.run (the same messages as from a script)
    args.frames = _number("frames", args.frames, int, "an integer >= 1")
    args.dt = _number("dt", args.dt, float, "a time step in seconds > 0")
    if args.dt_factor is not None:
        factor = _number("dt-factor", args.dt_factor, float, "a number > 0 (times the automatic time step)")
        if not factor > 0.0 or factor != factor or factor == float("inf"):
            raise ParameterError("dt-factor", args.dt_factor, "a finite number > 0 (times the automatic time step)")
        if args.dt is not None:
            raise ParameterError("dt-factor", args.dt_factor, "left out when --dt is given (give one of the two)")
        settings["dt_factor"] = factor
    interval = args.checkpoint_interval
    if interval is not None:
        if interval.strip().lower() == "off":
            settings["checkpoint_interval_s"] = None
        else:
            value = _number("checkpoint-interval", interval, float, "seconds >= 0, or 'off'")
            if not value >= 0.0 or value == float("inf"):
                raise ParameterError("checkpoint-interval", interval, "seconds >= 0, or 'off'")
            settings["checkpoint_interval_s"] = value
    if args.check_interval is not None:
        steps = _number("check-interval", args.check_interval, int, "an integer >= 1")
        if steps < 1:
            raise ParameterError("check-interval", args.check_interval, "an integer >= 1")
        settings["check_interval"] = steps
    if args.resume:
        settings["resume"] = True
    if args.layout != "file":
        settings["layout"] = args.layout
    if args.render_points:
        settings["render_points"] = True
    if args.debris is not None:
        settings["debris_particles"] = _number("debris", args.debris, int, "an integer >= 0 (particles)")
    if args.crack_events:
        settings["crack_events"] = True
    return settings


def _frames(text: str | None) -> int | None:
    """--frames of ``pdsim wedge``: an integer >= 1 (one-line ParameterError otherwise)."""
    frames = _number("frames", text, int, "an integer >= 1")
    if frames is not None and frames < 1:
        raise ParameterError("frames", frames, "an integer >= 1")
    return frames


def _wedge(args) -> int:
    if not args.settings:
        raise ParameterError("set", None, "at least one --set NAME=V1,V2,... (the settings to vary)")
    if args.out is None:
        raise ParameterError("out", None, "a folder for the caches and wedge.json")
    if os.path.exists(args.out) and not os.path.isdir(args.out):
        raise ParameterError("out", args.out, "a folder (this path is an existing file)")
    if not args.scene.endswith(".py") or not os.path.isfile(args.scene):
        raise ParameterError("scene", args.scene, "an existing Python scene script (*.py)")
    workers = _number("workers", args.workers, int, "an integer >= 1")
    if workers is not None and workers < 1:
        raise ParameterError("workers", args.workers, "an integer >= 1")
    settings = sweep.parse_settings(args.settings)
    records = sweep.run_wedge(
        args.scene,
        settings,
        args.out,
        scheduler=args.scheduler,
        frames=_frames(args.frames),
        device=resolve_device(args.device),
        workers=workers,
    )
    failed = [r for r in records if "failed" in r]
    for r in records:
        what = ", ".join(f"{k}={v}" for k, v in r["settings"].items())
        if "failed" in r:
            print(f"pdsim: variant {what}: failed: {r['failed']}", file=sys.stderr)
        else:
            print(f"pdsim: variant {what}: wrote {r['path']} ({r['frames_written']} frames, {r['seconds']:.1f} s)")
    listing = os.path.join(args.out, "wedge.json")
    print(f"pdsim: wedge of {len(records)} variants, {len(failed)} failed; list: {listing}")
    return 1 if failed else 0


def _bench(args) -> int:
    if args.what in (None, "-h", "--help"):
        print("usage: pdsim bench accuracy [--quick] [--scheduler tcp://HOST:8786] [--workers N] [--out DIR] ...")
        return 0 if args.what else 2
    if args.what != "accuracy":
        raise ParameterError("bench", args.what, "'accuracy' (the run-time-vs-error map)")
    return sweep.bench_accuracy(list(args.options))


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    print(f"pdsim: warning: {message}", file=sys.stderr)


def _execute(build_scene, args) -> int:
    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING  # no per-module load lines; warnings and errors still show
    settings = _run_settings(args)
    profile = RunProfile() if getattr(args, "profile", False) else None
    scene = build_scene()
    if profile is not None:
        profile.lap("build")  # the scene script's build_scene
        settings["profile"] = profile
    if not isinstance(scene, Scene):
        raise ParameterError("build_scene()", type(scene).__name__, "a function returning a pdsim.Scene")
    if getattr(args, "explain", False):
        print(
            explain_scene(
                scene,
                resolve_device(args.device) or "cpu",
                dt=args.dt,
                dt_factor=settings.get("dt_factor", 1.0),
                check_interval=settings.get("check_interval", 16),
            )
        )
        return 0
    out = f"{scene.name}.usdc" if args.out is None else args.out  # --out "": refused by the run's check
    stop = StopRequest()
    in_main = _is_main_thread()
    if in_main:
        stop.install()
    previous = warnings.showwarning
    warnings.showwarning = _one_line_warning
    try:
        report = scene.run(
            out,
            frames=args.frames,
            device=resolve_device(args.device),
            dt=args.dt,
            progress=not args.quiet,
            stop=stop,
            **settings,
        )
    except InstabilityError as exc:
        print(f"pdsim: error: {exc}", file=sys.stderr)
        return EXIT_DIVERGED
    except KeyboardInterrupt as exc:
        signum = getattr(exc, "signal", None) or stop.signal or signal.SIGINT
        where = getattr(exc, "cache", None) or out
        note = getattr(exc, "note", "")
        checkpoint = getattr(exc, "checkpoint", None)
        resume = f"; checkpoint written: continue with --resume ({checkpoint})" if checkpoint else ""
        name = signal.Signals(signum).name if signum in set(signal.Signals) else str(signum)
        print(
            f"pdsim: interrupted; {where} holds the frames finished so far ({note or 'see the cache'}){resume} "
            f"[{name}]",
            file=sys.stderr,
        )
        return signal_exit_code(signum)
    finally:
        warnings.showwarning = previous
        if in_main:
            stop.uninstall()
    span = f"{report.frames_written} frames"
    if report.first_frame:
        last = report.first_frame + report.frames_written - 1
        span = f"frames {report.first_frame}..{last} (resumed from the checkpoint; the cache holds frames 0..{last})"
    print(
        f"pdsim: wrote {report.path}: {span}, {report.summary}, "
        f"dt={report.dt:.3g} s x {report.substeps_per_frame} substeps/frame, "
        f"{report.wall_seconds:.1f} s"
    )
    return 0


def _is_main_thread() -> bool:
    """Signal handlers can be installed from the main thread only."""
    return threading.current_thread() is threading.main_thread()


_VALUE_OPTIONS = ("--dt", "--dt-factor", "--frames", "--fps", "--checkpoint-interval", "--check-interval", "--workers")


def _attach_negative_values(argv: list[str]) -> list[str]:
    """``--dt -1e-5`` as ``--dt=-1e-5``: argparse takes a word like -1e-5 for an option, so a negative value would
    end in argparse's own error instead of the one-line pdsim message naming the allowed range."""
    out: list[str] = []
    i = 0
    while i < len(argv):
        word = argv[i]
        if word in _VALUE_OPTIONS and i + 1 < len(argv) and argv[i + 1].startswith("-"):
            try:
                float(argv[i + 1])
            except ValueError:
                pass
            else:
                out.append(f"{word}={argv[i + 1]}")
                i += 2
                continue
        out.append(word)
        i += 1
    return out


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``pdsim`` command."""
    parser = _parser()
    args = parser.parse_args(_attach_negative_values(sys.argv[1:] if argv is None else list(argv)))
    if args.command not in ("run", "preview", "wedge", "bench", "pack"):
        parser.print_help()
        return 2
    try:
        if args.command == "preview":
            return _preview(args)
        if args.command == "wedge":
            return _wedge(args)
        if args.command == "bench":
            return _bench(args)
        if args.command == "pack":
            return _pack(args)
        build = load_scene_script(args.scene) if args.scene else build_default_scene
        return _execute(build, args)
    except PdsimError as exc:
        print(f"pdsim: error: {exc}", file=sys.stderr)
        return 1
    except Exception as exc:
        message = script_error_message(exc)  # None: pdsim's own exception, shown with its full traceback
        if message is None:
            raise
        print(message, file=sys.stderr)
        return EXIT_SCRIPT_ERROR


def run_script(build_scene, argv: list[str] | None = None) -> int:
    """For scene scripts: ``if __name__ == "__main__": run_script(build_scene)``; takes the options of ``pdsim run``."""
    parser = argparse.ArgumentParser(prog=os.path.basename(sys.argv[0]), description="run this pdsim scene")
    _add_run_options(parser)
    args = parser.parse_args(_attach_negative_values(sys.argv[1:] if argv is None else list(argv)))
    try:
        code = _execute(build_scene, args)
    except PdsimError as exc:
        print(f"pdsim: error: {exc}", file=sys.stderr)
        code = 1
    except Exception as exc:
        message = script_error_message(exc)  # None: pdsim's own exception, shown with its full traceback
        if message is None:
            raise
        print(message, file=sys.stderr)
        code = EXIT_SCRIPT_ERROR
    sys.exit(code)


if __name__ == "__main__":
    sys.exit(main())
