"""Throughput of the position-based particle lattice: particle updates per second.

A block of N body points (2D: a square lattice sqrt(N) x sqrt(N); 3D: a simple cubic N^(1/3) per edge) with its frame,
coordination-number neighbours of the first or second gradient, centroid rule, one face clamped and the opposite one
pulled (so every kernel of a step runs: leaders, followers, frame; with --fracture also link loss). The figure of merit
is **body points x steps / seconds** (the frame points are extra work, counted in the link rate). Timed after a
warm-up (kernel compilation and 5 steps) with ``wp.synchronize`` around the loop; the best of ``--repeat`` runs.

    python tools/bench_lattice.py                          # 2D and 3D, first and second gradient, 1e4 / 1e5 / 1e6
    python tools/bench_lattice.py --sizes 10000 --steps 200 --dims 2 --gradients 1 --device cpu --fracture
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import warp as wp

from pdsim.lattice import Lattice, LatticeBody, LatticeFracture, LatticeNeighbourhood, SolverLattice


def build(dim: int, n: int, gradient: int, fracture: bool):
    side = round(n ** (1.0 / dim))
    lattice = Lattice.square(1.0) if dim == 2 else Lattice.simple_cubic(1.0)
    body = LatticeBody.block(
        lattice,
        (side,) * dim,
        neighbourhood=LatticeNeighbourhood(gradient=gradient),
        fracture=LatticeFracture((3.0, 4.0)) if fracture else None,
    )
    x = body.rest_positions[: body.body_count, 0]
    body.clamp(x < 0.5)
    body.add_leaders(x > x.max() - 0.5, velocity=(0.01, 0.0, 0.0))
    return body


def measure(dim: int, n: int, gradient: int, *, steps: int, repeat: int, device: str, fracture: bool) -> dict:
    t0 = time.perf_counter()
    body = build(dim, n, gradient, fracture)
    solver = SolverLattice([body], device=device)
    build_s = time.perf_counter() - t0
    solver.run_steps(5)
    wp.synchronize_device(device)
    best = float("inf")
    for _ in range(repeat):
        wp.synchronize_device(device)
        t = time.perf_counter()
        solver.run_steps(steps)
        wp.synchronize_device(device)
        best = min(best, time.perf_counter() - t)
    return {
        "dim": dim,
        "gradient": gradient,
        "body_points": body.body_count,
        "frame_points": body.frame_count,
        "links": body.link_count,
        "steps": steps,
        "seconds": best,
        "ms_per_step": 1e3 * best / steps,
        "updates_per_s": body.body_count * steps / best,
        "links_per_s": body.link_count * steps / best,
        "build_s": build_s,
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000], help="body points")
    p.add_argument("--dims", type=int, nargs="+", default=[2, 3], choices=[2, 3])
    p.add_argument("--gradients", type=int, nargs="+", default=[1, 2], choices=[1, 2])
    p.add_argument("--steps", type=int, default=0, help="steps per timing (default: about 2e7 body updates)")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--device", default="cpu")
    p.add_argument("--fracture", action="store_true", help="links can break (adds the link-loss kernel)")
    args = p.parse_args(argv)

    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    print(
        f"# Warp {wp.__version__}, device {args.device} ({wp.get_device(args.device).name}), "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, fracture={args.fracture}"
    )
    print("| dim | gradient | body points | frame points | links | steps | ms/step | M updates/s | M links/s |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for dim in args.dims:
        for gradient in args.gradients:
            for n in args.sizes:
                steps = args.steps or max(10, min(2000, int(2e7 / n)))
                r = measure(
                    dim, n, gradient, steps=steps, repeat=args.repeat, device=args.device, fracture=args.fracture
                )
                print(
                    f"| {dim}D | {gradient} | {r['body_points']:,} | {r['frame_points']:,} | {r['links']:,} | "
                    f"{r['steps']} | {r['ms_per_step']:.3f} | {r['updates_per_s'] / 1e6:.1f} | "
                    f"{r['links_per_s'] / 1e6:.1f} |",
                    flush=True,
                )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
