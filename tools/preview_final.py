"""Brittle presets at the preview spacing and at half of it: a 30 cm sphere of each brittle preset dropped onto the
ground at 6 m/s, and the same sphere hit by a ball, measured when the break has played out (docs/fracture.md,
"Presets at preview and final spacing").

The preview spacing is what an artist previews a 30 cm object with: 15 particles across it, h = 2 cm
(:data:`PREVIEW_SPACING`); the final spacing is half of it. Figures of one run, at its last frame (fragments are the
connected pieces of live bonds, pdsim/fragment_labels.py; masses from the particles):

- ``broken_out``: the share of the body's mass outside its largest fragment;
- ``dust``: the share of the broken-out mass in fragments of fewer than 8 particles (must-show: at most 20 %);
- ``big``: the number of fragments (the largest included) each holding more than 5 % of the body's mass
  (must-show: at least 3);
- ``n80``: the fewest broken-out fragments, largest first, that hold 80 % of the broken-out mass.

Preview against final: ``n80`` at h and h/2 within a factor of 1.5 of each other, ``broken_out`` within +-30 %
(relative). The dust limit is counted in particles of the run's own spacing, so at h/2 a "dust" fragment is 8 times
smaller in volume.

    python tools/preview_final.py                                   # every preset and case at h, figures only
    python tools/preview_final.py --spacings 0.02 0.01 --json runs/preview_final.json
    python tools/preview_final.py --from-json runs/preview_final.json --doc docs/fracture.md
    python tools/preview_final.py --presets glass --cases drop --spacings 0.02 --usd runs/   # a cache for stills
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time

import numpy as np
import warp as wp

import pdsim

DIAMETER = 0.3  # the sphere [m]
PREVIEW_SPACING = DIAMETER / 15.0  # 15 particles across: 2 cm
SPEED = 6.0  # the drop's and the ball's speed [m/s]
BALL_RADIUS = 0.1  # [m]
DURATION = 0.04  # simulated time of a run [s]: the break and the pieces' first separation
FRAMES = 2
DUST_PARTICLES = 8  # a fragment of fewer particles does not read as a shard on screen
BIG_SHARE = 0.05  # a "big" fragment holds more than this share of the body's mass
HELD_SHARE = 0.8  # n80: the fragments that hold this share of the broken-out mass
BRITTLE = ("glass", "ceramic", "stone", "plaster")
FRICTION = 0.5  # Coulomb friction of the ground and the ball
BALL_DIRECTION = (0.0, 0.0, -1.0)  # the ball's flight
CASES = ("drop", "hit")
CENTRE = np.array([0.0, 0.0, DIAMETER / 2.0 + 0.002])  # the sphere's centre [m], 2 mm above the ground


def build_case(case: str, material: pdsim.Material, spacing: float, *, frames=FRAMES, duration=DURATION):
    """The scene of one case: "drop" (the sphere falls onto the ground plane at SPEED, under gravity) or "hit" (the
    sphere resting on the ground, a kinematic ball of BALL_RADIUS coming down onto it at SPEED along BALL_DIRECTION);
    ground and ball with Coulomb friction FRICTION; ``frames`` frames over ``duration`` [s]."""
    if case not in CASES:
        raise ValueError(f"case {case!r}: one of {CASES}")
    scene = pdsim.Scene(fps=24, frames=frames, frame_time=duration / frames, name=f"sphere_{case}")
    shape = pdsim.sphere(DIAMETER / 2.0, center=tuple(CENTRE), name="sphere")
    body = scene.add_peridynamic_body(shape, material, spacing)
    scene.add_ground_plane(height=0.0, friction=FRICTION)
    if case == "drop":
        body.set_initial_velocity((0.0, 0.0, -SPEED))
    else:
        d = np.asarray(BALL_DIRECTION, dtype=np.float64) / np.linalg.norm(BALL_DIRECTION)
        start = CENTRE - d * (DIAMETER / 2.0 + BALL_RADIUS + 0.002)
        scene.add_collider(
            pdsim.SphereProjectile(
                BALL_RADIUS, center=tuple(start), velocity=tuple(SPEED * d), friction=FRICTION, name="ball"
            )
        )
    return scene


def run_scene(scene, *, device="cpu"):
    """Runs every frame of ``scene`` (one peridynamic solver) at the scene's time step; returns (solver, wall [s])."""
    solver = scene.build_solvers(device=device)[0]
    dt = scene.time_step_safety * solver.stable_time_step()
    substeps = max(1, math.ceil(scene.frame_time / dt - 1.0e-9))
    t0 = time.perf_counter()
    for _ in range(scene.frames):
        solver.simulate(scene.frame_time / substeps, substeps)
        solver.check_state(1.0e3)
    return solver, time.perf_counter() - t0


def figures(solver, body_index: int = 0) -> dict:
    """The module docstring's figures of one body at the solver's current state."""
    sl = solver.body_slice(body_index)
    _, lab = np.unique(solver.fragment_ids()[sl].astype(np.int64), return_inverse=True)
    lab = lab.ravel()
    count = np.bincount(lab)
    mass = np.bincount(lab, solver.masses()[sl])
    total = float(mass.sum())
    main = int(np.argmax(mass))
    out = np.delete(np.arange(len(mass)), main)
    out_mass = float(mass[out].sum())
    dust = float(mass[out][count[out] < DUST_PARTICLES].sum())
    held = np.cumsum(np.sort(mass[out])[::-1])
    n80 = int(np.searchsorted(held, HELD_SHARE * out_mass * (1.0 - 1.0e-12)) + 1) if out_mass > 0 else 0
    return {
        "particles": int(len(lab)),
        "fragments": int(len(mass)),
        "broken_out": out_mass / total,
        "dust": dust / out_mass if out_mass > 0 else 0.0,
        "big": int(np.sum(mass > BIG_SHARE * total)),
        "n80": n80,
        "largest": float(mass[main] / total),
    }


def measure(preset: str, case: str, spacing: float, *, frames=FRAMES, duration=DURATION, **overrides) -> dict:
    """Runs one preset (pdsim.presets, with Material ``overrides``) in one case at ``spacing`` [m]; its figures."""
    import dataclasses

    material = pdsim.presets.preset(preset)
    if overrides:
        material = dataclasses.replace(material, **overrides)
    solver, wall = run_scene(build_case(case, material, spacing, frames=frames, duration=duration))
    return {**figures(solver), "wall_s": wall, "preset": preset, "case": case, "spacing": spacing}


def agreement(coarse: dict, fine: dict) -> dict:
    """Preview against final: the ratio of n80 (larger over smaller) and the relative change of broken_out."""
    a, b = max(coarse["n80"], 1), max(fine["n80"], 1)
    return {
        "n80_ratio": max(a, b) / min(a, b),
        "broken_out_change": fine["broken_out"] / coarse["broken_out"] - 1.0 if coarse["broken_out"] > 0 else math.inf,
    }


def table(results: list[dict]) -> str:
    """The docs/fracture.md section: one row per preset, case and spacing, and the agreement of each pair."""
    lines = [
        "| preset | case | spacing | particles | broken out | dust (< 8) | fragments > 5 % | n80 | run |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        lines.append(
            f"| {r['preset']} | {r['case']} | {r['spacing'] * 1000:.0f} mm | {r['particles']:,} | "
            f"{100 * r['broken_out']:.1f} % | {100 * r['dust']:.1f} % | {r['big']} | {r['n80']} | {r['wall_s']:.0f} s |"
        )
    pairs = [
        (c, f)
        for c in results
        for f in results
        if c["preset"] == f["preset"] and c["case"] == f["case"] and math.isclose(f["spacing"], 0.5 * c["spacing"])
    ]
    if pairs:
        lines += [
            "",
            "| preset | case | n80 at h / at h/2 (ratio; must be <= 1.5) | broken out at h / at h/2 (change; within +-30 %) |",
            "|---|---|---|---|",
        ]
        for c, f in pairs:
            g = agreement(c, f)
            lines.append(
                f"| {c['preset']} | {c['case']} | {c['n80']} / {f['n80']} ({g['n80_ratio']:.2f}: "
                f"{'yes' if g['n80_ratio'] <= 1.5 else 'NO'}) | {100 * c['broken_out']:.1f} % / "
                f"{100 * f['broken_out']:.1f} % ({100 * g['broken_out_change']:+.0f} %: "
                f"{'yes' if abs(g['broken_out_change']) <= 0.3 else 'NO'}) |"
            )
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--presets", nargs="+", default=list(BRITTLE))
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    ap.add_argument("--spacings", nargs="+", type=float, default=[PREVIEW_SPACING])
    ap.add_argument("--frames", type=int, default=FRAMES)
    ap.add_argument("--duration", type=float, default=DURATION)
    ap.add_argument("--json", help="write the figures to this JSON file (appended to as runs finish)")
    ap.add_argument("--from-json", help="read the figures from this JSON file instead of running")
    ap.add_argument("--doc", help="print the table for this page (the section is edited by hand)")
    ap.add_argument("--usd", help="folder: also write each run's USD cache there (for pdsim preview stills)")
    args = ap.parse_args(argv)
    wp.config.quiet = True
    if args.from_json:
        with open(args.from_json) as f:
            results = json.load(f)["runs"]
    else:
        results = []
        for spacing in args.spacings:
            for preset in args.presets:
                for case in args.cases:
                    if args.usd:
                        material = pdsim.presets.preset(preset)
                        scene = build_case(case, material, spacing, frames=args.frames, duration=args.duration)
                        os.makedirs(args.usd, exist_ok=True)
                        out = os.path.join(args.usd, f"{preset}_{case}_{spacing * 1000:.0f}mm.usdc")
                        t0 = time.perf_counter()
                        scene.run(out)
                        print(out, f"{time.perf_counter() - t0:.0f} s", flush=True)
                        continue
                    r = measure(preset, case, spacing, frames=args.frames, duration=args.duration)
                    results.append(r)
                    print(json.dumps(r), flush=True)
                    if args.json:
                        meta = {
                            "machine": f"{platform.machine()}, {os.cpu_count()} cores, Warp {wp.config.version} CPU",
                            "date": time.strftime("%Y-%m-%d"),
                            "command": "python tools/preview_final.py " + " ".join(argv or sys.argv[1:]),
                        }
                        with open(args.json, "w") as f:
                            json.dump({**meta, "runs": results}, f, indent=1)
    if results:
        print(table(results))


if __name__ == "__main__":
    main()
