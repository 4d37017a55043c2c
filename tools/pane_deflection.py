"""How far the glass pane of scenes/glass_pane.py bows before it cracks (docs/fracture.md, "Glass pane").

Runs the scene frame by frame and prints, per frame: the deflection of the pane around the ball (the mean
displacement along the ball's flight of the particles between 1 and 2 ball radii from the pane's centre in the pane's
plane: the plate's bending, not the dent under the ball), the share of broken bonds, the fragments and the largest
fragment besides the main piece. Events: the first broken bond (a crack starts) and the first frame in which a piece
of at least 8 particles has come free (cracks have gone through the pane around it; chips under the ball do not
count). Real glass cracks through at a deflection of a few millimetres; the pane is 12 mm thick.

    python tools/pane_deflection.py                                  # the scene as it ships (4 mm)
    python tools/pane_deflection.py --scene-args '{"spacing": 0.01, "frames": 16}'   # the preview
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np
import warp as wp

from pdsim.timestep import frame_steps, projectile_step_limit

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenes"))
import glass_pane


PIECE = 8  # particles: a freed fragment this large is a piece, not a chip


def measure(scene_args: dict, *, stop_after: int = 2) -> dict:
    """Runs the pane frame by frame (the scene's step) and returns the per-frame rows and the two events; stops
    ``stop_after`` frames after the first frame with a free piece."""
    scene = glass_pane.build_scene(**scene_args)
    solver = scene.build_solvers(device="cpu")[0]
    steps = frame_steps(
        scene.frame_time,
        solver.stable_time_step(),
        scene.time_step_safety,
        travel_limit=projectile_step_limit(scene, scene.frames),
    )
    substeps = steps.substeps
    ball = scene.colliders[0]
    rest = solver.bodies[0].rest_positions
    flight = np.asarray(ball.velocity, dtype=np.float64) / float(np.linalg.norm(ball.velocity))
    r = np.linalg.norm((rest - glass_pane.CENTER)[:, [0, 2]], axis=1)
    radius = ball.sphere_radius
    ring = (r >= radius) & (r <= 2.0 * radius)
    alive0 = solver.bond_alive().size
    rows, events = [], {}
    t0 = time.perf_counter()
    for frame in range(1, scene.frames + 1):
        solver.simulate(scene.frame_time / substeps, substeps)
        u = solver.displacements()[: len(rest)]
        deflection = float((u[ring] @ flight).mean())
        broken = float(1.0 - solver.bond_alive().sum() / alive0)
        sizes = np.sort(np.unique(solver.fragment_ids(), return_counts=True)[1])[::-1]
        piece = int(sizes[1]) if len(sizes) > 1 else 0
        row = {
            "frame": frame,
            "time_ms": 1.0e3 * frame * scene.frame_time,
            "deflection_mm": 1.0e3 * deflection,
            "broken_bonds": broken,
            "fragments": len(sizes),
            "largest_piece": piece,
        }
        rows.append(row)
        print(json.dumps(row), flush=True)
        if broken > 0.0 and "first_break" not in events:
            events["first_break"] = row
        if piece >= PIECE and "through" not in events:
            events["through"] = row
        if "through" in events and frame >= events["through"]["frame"] + stop_after:
            break
    return {
        "rows": rows,
        "events": events,
        "particles": len(rest),
        "substeps": substeps,
        "wall_s": time.perf_counter() - t0,
        "scene_args": scene_args,
        "thickness_mm": 1.0e3 * glass_pane.THICKNESS,
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene-args", default="{}", help="build_scene keywords, JSON")
    ap.add_argument("--json", help="write the result here")
    ap.add_argument("--stop-after", type=int, default=2, help="frames to run past the first free piece")
    args = ap.parse_args(argv)
    wp.config.quiet = True
    result = measure(json.loads(args.scene_args), stop_after=args.stop_after)
    print(json.dumps(result["events"]))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
