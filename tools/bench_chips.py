"""The render surfaces of a crumbling body with its chips drawn as cells or as cubes: runs a scene of scenes/ at
its PREVIEW settings for some frames (no output), then rebuilds each peridynamic body's surfaces from the state
reached, once per chip shape, and prints per body the chips, shells, crack triangles and rebuild time.

    python tools/bench_chips.py                       # the teaser (four_walls), 20 frames
    python tools/bench_chips.py --scene drop_shatter --frames 12
    python tools/bench_chips.py --stills CELLS.usdc CUBES.usdc --frame 40 --out docs/four_walls_chips.png

With ``--stills`` it only renders frame ``--frame`` of two caches side by side (``pdsim preview``'s renderer,
480 x 360 each, left the first cache).
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tools"))

from make_gallery import load_scene_module  # noqa: E402

from pdsim.fragment_surfaces import DAMAGE_THRESHOLD, FragmentSurfaces  # noqa: E402
from pdsim.run import advance_frame, method_contact  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", default="four_walls", help="a scene of scenes/ (default four_walls)")
    parser.add_argument("--frames", type=int, default=20, help="frames simulated first (default 20)")
    parser.add_argument("--stills", nargs=2, metavar="CACHE", help="two caches to render side by side instead")
    parser.add_argument("--frame", type=int, default=40, help="the frame of --stills (default 40)")
    parser.add_argument("--out", default="chips.png", help="the PNG of --stills (default chips.png)")
    args = parser.parse_args(argv)
    if args.stills:
        side_by_side(args.stills, args.frame, args.out)
        return 0
    module = load_scene_module(args.scene)
    scene = module.build_scene(**getattr(module, "PREVIEW", {}))
    solvers = scene.build_solvers(device="cpu")
    solver = solvers[0]
    dt = scene.time_step_safety * solver.stable_time_step()
    substeps = max(1, math.ceil(scene.frame_time / dt - 1.0e-9))
    coupling = method_contact(scene, solvers)
    for _ in range(args.frames):
        advance_frame(solvers, scene.frame_time / substeps, substeps, coupling)
    labels, damage = solver.fragment_ids(), solver.damage()
    machine = platform.processor() or platform.machine()
    when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    print(f"{args.scene} at its PREVIEW settings after {args.frames} frames; {machine}, {when}")
    print("body | chips | chip shape | shells | triangles | crack triangles | rebuild [s]")
    for i, body in enumerate(solver.bodies):
        sl = solver.body_slice(i)
        chips = int((damage[sl] >= DAMAGE_THRESHOLD).sum())
        if not chips:
            continue
        for shape in ("cell", "cube"):
            surfaces = FragmentSurfaces(body.shape, body.rest_positions, body.spacing, body.name, chip_shape=shape)
            t0 = time.perf_counter()
            surfaces.update_topology(labels[sl], damage[sl])
            seconds = time.perf_counter() - t0
            crack = int((surfaces.face_crack == 1).sum())
            print(
                f"{body.name} | {chips} | {shape} | {surfaces.fragment_count} | {len(surfaces.faces)} | {crack} | "
                f"{seconds:.2f}"
            )
    return 0


def side_by_side(caches, frame: int, out: str) -> None:
    """Frame ``frame`` of each cache rendered by ``pdsim preview``'s renderer, pasted left to right into ``out``."""
    import tempfile

    from PIL import Image

    from pdsim.preview import write_preview

    with tempfile.TemporaryDirectory() as tmp:
        images = []
        for i, cache in enumerate(caches):
            path = os.path.join(tmp, f"{i}.png")
            write_preview(cache, path, str(frame), size=(480, 360), supersample=2)
            images.append(Image.open(path).convert("RGB"))
        both = Image.new("RGB", (sum(a.width for a in images), max(a.height for a in images)), "white")
        x = 0
        for a in images:
            both.paste(a, (x, 0))
            x += a.width
        both.save(out)
    print(f"wrote {out}")


if __name__ == "__main__":
    raise SystemExit(main())
