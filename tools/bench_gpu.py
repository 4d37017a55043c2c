"""Timers for the GPU path (docs/architecture.md, GPU path), pdsim only; tools/gpu_suite.sh runs them on a GPU.

``pd``: the peridynamic step throughput of an elastic n^3 block (spacing 1 mm, E = 1 GPa, nu = 0.25, rho = 1000
kg/m^3, horizon 3 h, families cut at the horizon without partial volumes), given uniform random velocities of +-0.1 m/s
(numpy default_rng(0)), stepped by the run's frame loop (``pdsim.run.advance_frame``) in frames of ``--substeps``
steps of 0.7 x the stable step: first with every step launched from the host, then with each frame replayed as a
captured graph (pdsim/capture.py; the first frame of each mode is a warm-up and is not timed). Reported per mode:

    bond_visits_per_s = bond_count * steps / seconds      (seconds between device synchronisations)

``four-walls``: scenes/four_walls.py's build_scene(spacing=...) run through ``Scene.run`` for ``--frames`` frames into
a scratch folder: the scene's build (bodies, families), the wall time of each frame (steps, watchdog, the cache's
writing; the first also holds the run's set-up: solvers, preflight, frame 0), particles, bonds and substeps per frame.

``agree``: a gallery scene's preview frames on the CPU and on the device (``Scene.run`` on each), frame by frame: the
displacement difference relative to the CPU's largest displacement, the fastest point of each, and where a run
stopped.

Each prints one JSON object (``--json-out`` also writes it to a file).

Script use::

    python tools/bench_gpu.py pd --n 100 --frames 3 --substeps 20 --device cuda
    python tools/bench_gpu.py four-walls --spacing 0.0025 --frames 3 --device cuda
    python tools/bench_gpu.py pd --n 12 --frames 2 --substeps 4 --device cpu       # a smoke run
    python tools/bench_gpu.py agree fem_slab_crack --device cuda
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np
import warp as wp

import pdsim
from pdsim.capture import FrameGraphs
from pdsim.run import advance_frame

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenes"))
import four_walls

SPACING = 1.0e-3


def _init(device: str):
    wp.config.quiet = True
    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_WARNING
    wp.init()
    return wp.get_device(device)


def bench_pd(n: int, frames: int, substeps: int, device: str, json_out: str | None = None) -> dict:
    """Bond visits per second of the n^3 block, step by step and replayed as a graph (see the module docstring); the
    result so far is written to ``json_out`` after the build and after each mode."""
    dev = _init(device)
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e9, poisson_ratio=0.25)
    t0 = time.perf_counter()
    scene = pdsim.Scene(gravity=(0.0, 0.0, 0.0), frames=frames)
    body = scene.add_peridynamic_body(
        pdsim.box((n * SPACING,) * 3), material, SPACING, horizon_factor=3.0, partial_volumes=False, name="block"
    )
    rng = np.random.default_rng(0)
    body.set_initial_velocity(rng.uniform(-0.1, 0.1, size=(body.point_count, 3)))
    (solver,) = scene.build_solvers(device=device)
    build_s = time.perf_counter() - t0
    dt = 0.7 * solver.stable_time_step()
    out = {
        "particles": int(solver.point_count),
        "bonds": int(solver.bond_count),
        "dt": dt,
        "substeps": substeps,
        "timed_frames": frames,
        "build_s": build_s,
        "device": str(dev),
        "device_name": dev.name,
        "warp": wp.__version__,
    }
    _write(out, json_out)
    for mode, enabled in (("step_by_step", False), ("graph", True)):
        graphs = FrameGraphs(dev, enabled)
        warm = 2 if enabled else 1  # the graph mode's first frame is direct, its second captures
        for _ in range(warm):
            advance_frame([solver], dt, substeps, graphs=graphs)
        wp.synchronize_device(dev)
        start = time.perf_counter()
        for _ in range(frames):
            advance_frame([solver], dt, substeps, graphs=graphs)
        wp.synchronize_device(dev)
        seconds = time.perf_counter() - start
        steps = frames * substeps
        out[mode] = {
            "seconds": seconds,
            "steps": steps,
            "bond_visits_per_s": solver.bond_count * steps / seconds,
            "steps_per_s": steps / seconds,
            "replays": graphs.replays,
            "captures": graphs.captures,
            "fallback": graphs.fallback,
        }
        _write(out, json_out)
    out["max_speed"] = float(np.sqrt((solver.velocities() ** 2).sum(axis=1)).max())
    return out


def bench_four_walls(spacing: float, frames: int, device: str, json_out: str | None = None) -> dict:
    """Build and run times of scenes/four_walls.py at ``spacing`` [m] for ``frames`` frames; the wall time of each
    frame (simulation, checks and the cache's writing) is added as it finishes, and written to ``json_out`` then, so
    that a run stopped by a time limit still leaves its finished frames' times."""
    dev = _init(device)
    t0 = time.perf_counter()
    scene = four_walls.build_scene(spacing=spacing)
    out = {
        "spacing": spacing,
        "frames": frames,
        "scene_build_s": time.perf_counter() - t0,
        "frame_s": [],
        "device": str(dev),
        "device_name": dev.name,
    }
    marks = [time.perf_counter()]

    def on_frame(frame, solvers):
        now = time.perf_counter()
        out["frame_s"].append(now - marks[-1])
        marks.append(now)
        out["particles"] = sum(s.point_count for s in solvers)
        out["bonds"] = sum(s.bond_count for s in solvers)
        _write(out, json_out)

    with tempfile.TemporaryDirectory() as folder:
        report = scene.run(
            os.path.join(folder, "four_walls.usdc"),
            frames=frames,
            device=device,
            progress=False,
            checkpoint_interval_s=None,
            on_frame=on_frame,
        )
    out.update(
        run_s=report.wall_seconds,
        substeps_per_frame=report.substeps_per_frame,
        dt=report.dt,
        checks=report.checks,
    )
    return out


def agree(name: str, frames: int | None, device: str, json_out: str | None = None) -> dict:
    """scenes/<name>.py at its PREVIEW settings run through ``Scene.run`` on the CPU and on ``device``: per frame, the
    largest displacement difference of the first solver relative to the CPU's largest displacement, each run's
    fastest point [m/s] and point count; a run that stops (a divergence) records where and why."""
    import importlib

    module = importlib.import_module(name)
    runs = {}
    for dev in ("cpu", device):
        frames_out = []

        def on_frame(frame, solvers, frames_out=frames_out):
            s = solvers[0]
            u = s.displacements()
            v = s.velocities() if hasattr(s, "velocities") else np.zeros((1, 3))
            frames_out.append((frame, u.copy(), float(np.sqrt((v**2).sum(axis=1)).max())))

        scene = module.build_scene(**module.PREVIEW)
        error = None
        with tempfile.TemporaryDirectory() as folder:
            try:
                scene.run(os.path.join(folder, f"{name}.usdc"), frames=frames, device=dev, progress=False,
                          checkpoint_interval_s=None, on_frame=on_frame)  # fmt: skip
            except pdsim.PdsimError as exc:
                error = f"{type(exc).__name__}: {str(exc)[:400]}"
        runs[dev] = (frames_out, error)
    out = {"scene": name, "device": device, "errors": {d: runs[d][1] for d in runs}, "frames": []}
    for (f, u_cpu, v_cpu), (_, u_dev, v_dev) in zip(runs["cpu"][0], runs[device][0]):
        scale = float(np.abs(u_cpu).max()) or 1.0
        same_shape = u_cpu.shape == u_dev.shape
        diff = float(np.abs(u_dev - u_cpu).max()) / scale if same_shape else None
        out["frames"].append({"frame": f, "relative_difference": diff, "points": [len(u_cpu), len(u_dev)],
                              "max_speed": [v_cpu, v_dev]})  # fmt: skip
    _write(out, json_out)
    return out


def _write(result: dict, path: str | None) -> None:
    if path:
        with open(path, "w") as f:
            f.write(json.dumps(result, indent=2) + "\n")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="what", required=True)
    pd = sub.add_parser("pd", help="peridynamic bond visits per second, step by step and as a graph")
    pd.add_argument("--n", type=int, default=100, help="particles along each edge (default 100: 1e6 particles)")
    pd.add_argument("--frames", type=int, default=3, help="timed frames per mode")
    pd.add_argument("--substeps", type=int, default=20, help="steps per frame")
    walls = sub.add_parser("four-walls", help="scenes/four_walls.py build and run times")
    walls.add_argument("--spacing", type=float, default=0.0025)
    walls.add_argument("--frames", type=int, default=3)
    same = sub.add_parser("agree", help="a gallery scene's preview frames on the CPU and on the device, compared")
    same.add_argument("scene", help="a scene of scenes/ (e.g. fem_slab_crack)")
    same.add_argument("--frames", type=int, default=None, help="frames to run (default: the preview's)")
    for p in (pd, walls, same):
        p.add_argument("--device", default="cuda")
        p.add_argument("--json-out", default=None, help="also write the JSON to this file")
    args = parser.parse_args(argv)
    if args.what == "pd":
        result = bench_pd(args.n, args.frames, args.substeps, args.device, args.json_out)
    elif args.what == "agree":
        result = agree(args.scene, args.frames, args.device, args.json_out)
    else:
        result = bench_four_walls(args.spacing, args.frames, args.device, args.json_out)
    print(json.dumps(result, indent=2))
    _write(result, args.json_out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
