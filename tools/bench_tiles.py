"""The sliver clean-up tile by tile (pdsim/fragment_surfaces/tiles.py) against the whole clean-up, on the same raw
complexes.

    python tools/bench_tiles.py [--scene four_walls] [--frames 40] [--save RAW.pkl] [--tile 4]
    python tools/bench_tiles.py --calls RAW.pkl [--first 30] [--tile 4]

Runs a scene of scenes/ at its PREVIEW settings (surfaces built in the main thread, the carried edits off, so every
rebuild's clean-up starts from its raw complex) and keeps the input of every ``clean_complex`` call (``--save``
writes them, ``--calls`` reads them). Then, call after call (one TiledCleanup per body, so a tile's result is
taken from that body's earlier calls when its raw triangles are unchanged), times the whole clean-up and the tiled
one in turn (CPU seconds of this process) and prints, for each: triangles out, triangles still flagged (a side under
0.3 h or an angle under 5 degrees), crack triangles under 5 degrees and the smallest crack angle [degrees]; for the
tiled one also whether every shell is closed and how many tiles had work and were cleaned (the others were taken
from an earlier call). Calls before ``--first`` are run through the tiled clean-up only (to fill its tiles) and not
timed. ``--flags`` prints instead, for each call, why its raw triangles are flagged: crack and outer triangles
with a side under 0.3 h, with an angle under 5 degrees, and the quartiles of the crack triangles' shortest side [h].
"""

from __future__ import annotations

import argparse
import hashlib
import os
import pickle
import sys
import tempfile
import time

import numpy as np

import pdsim.fragment_surfaces.booleans as booleans
import pdsim.fragment_surfaces.surfaces as surfaces
from pdsim.fragment_surfaces.cleanup import SHORT_EDGE, SLIVER_ANGLE, _needs_work, clean_complex, shells_closed
from pdsim.fragment_surfaces.cleanup import triangle_angles
from pdsim.fragment_surfaces.tiles import TILE, TiledCleanup

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tools"))

from make_gallery import load_scene_module  # noqa: E402


def capture(scene_name: str, frames: int) -> list:
    """(points, tri, shell, patch, spacing, keyword arguments) of every clean_complex call of the scene's rebuilds,
    each from the raw complex (the carried edits off)."""
    calls = []
    inner_clean, inner_shared = booleans.clean_complex, surfaces.shared_complex

    def keep(points, tri, shell, patch, spacing, **kw):
        calls.append((points.copy(), tri.copy(), shell.copy(), patch.copy(), spacing, kw))
        return inner_clean(points, tri, shell, patch, spacing, **kw)

    def shared(*args, **kw):
        kw["record"] = None
        return inner_shared(*args, **kw)

    booleans.clean_complex, surfaces.shared_complex = keep, shared
    try:
        module = load_scene_module(scene_name)
        scene = module.build_scene(**getattr(module, "PREVIEW", {}))
        with tempfile.TemporaryDirectory() as tmp:
            scene.run(os.path.join(tmp, "out.usdc"), frames=frames, progress=False, surface_thread=False)
    finally:
        booleans.clean_complex, surfaces.shared_complex = inner_clean, inner_shared
    return calls


def quality(points, tri, patch, crack_patch, spacing) -> tuple:
    """(triangles, flagged, crack triangles under 5 degrees, smallest crack angle [degrees])."""
    crack = np.asarray(crack_patch, dtype=bool)[patch]
    smallest = triangle_angles(points, tri).min(axis=1)
    flagged = int(_needs_work(points, tri, spacing, SHORT_EDGE, SLIVER_ANGLE).sum())
    low = float(smallest[crack].min()) if crack.any() else 90.0
    return len(tri), flagged, int((smallest[crack] < SLIVER_ANGLE).sum()), round(low, 2)


def flags(points, tri, patch, crack_patch, spacing) -> str:
    """Why the raw triangles are flagged: per kind (crack, outer), the count, those with a side under 0.3 h and
    those with an angle under 5 degrees; the quartiles of the crack triangles' shortest side [spacings]."""
    crack = np.asarray(crack_patch, dtype=bool)[patch]
    t = points[tri]
    side = np.linalg.norm(t[:, [1, 2, 0]] - t, axis=2).min(axis=1) / spacing
    sliver = triangle_angles(points, tri).min(axis=1) < SLIVER_ANGLE
    out = []
    for name, kind in (("crack", crack), ("outer", ~crack)):
        out.append(f"{name} {kind.sum()}: short {(kind & (side < SHORT_EDGE)).sum()}, sliver {(kind & sliver).sum()}")
    q = np.quantile(side[crack], [0.25, 0.5, 0.75]) if crack.any() else np.zeros(3)
    return "; ".join(out) + f"; crack shortest side quartiles {q[0]:.3f} {q[1]:.3f} {q[2]:.3f} h"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", default="four_walls")
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--save", help="write the captured calls to this pickle")
    parser.add_argument("--calls", help="read the calls from this pickle instead of running the scene")
    parser.add_argument("--first", type=int, default=0, help="first call timed (earlier ones only fill the tiles)")
    parser.add_argument("--tile", type=float, default=TILE, help=f"tile edge [spacings] (default {TILE})")
    parser.add_argument("--flags", action="store_true", help="print why the raw triangles are flagged, no timing")
    args = parser.parse_args(argv)
    if args.calls:
        with open(args.calls, "rb") as f:
            calls = pickle.load(f)
    else:
        calls = capture(args.scene, args.frames)
        if args.save:
            with open(args.save, "wb") as f:
                pickle.dump(calls, f)
    print(f"{len(calls)} calls, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load {os.getloadavg()[0]:.1f}")
    if args.flags:
        for i, (points, tri, _, patch, spacing, kw) in enumerate(calls[args.first :], start=args.first):
            print(f"{i:4d}  {len(tri):6d}  {flags(points, tri, patch, kw['crack_patch'], spacing)}")
        return 0
    print("call  body    tri in | whole: s, (out, flagged, crack < 5 deg, min angle) | tiled: s, (...), closed, tiles")
    bodies: dict[str, TiledCleanup] = {}
    whole_s = tiled_s = 0.0
    for i, (points, tri, shell, patch, spacing, kw) in enumerate(calls):
        surface, plane_of_patch = kw["surface"][:3], kw["surface"][3]
        body = hashlib.blake2b(np.ascontiguousarray(surface[0]).tobytes(), digest_size=3).hexdigest()
        tiles = bodies.setdefault(body, TiledCleanup(surface, spacing, tile=args.tile))
        if i < args.first:
            tiles.clean(points, tri, shell, patch, plane_of_patch)
            continue
        p_whole = points.copy()
        t0 = time.process_time()
        w_tri, _, w_patch = clean_complex(p_whole, tri, shell, patch, spacing, **kw)[:3]
        t1 = time.process_time()
        p_tiled, t_tri, t_shell, t_patch = tiles.clean(points, tri, shell, patch, plane_of_patch)
        t2 = time.process_time()
        whole_s += t1 - t0
        tiled_s += t2 - t1
        closed = bool(shells_closed(t_tri, t_shell, len(p_tiled)).all())
        print(
            f"{i:4d}  {body}  {len(tri):6d} | {t1 - t0:5.2f}"
            f" {quality(p_whole, w_tri, w_patch, kw['crack_patch'], spacing)}"
            f" | {t2 - t1:5.2f} {quality(p_tiled, t_tri, t_patch, kw['crack_patch'], spacing)} {closed}"
            f" {tiles.cleaned_tiles}/{tiles.tiles}",
            flush=True,
        )
    print(f"total CPU: whole {whole_s:.1f} s, tiled {tiled_s:.1f} s, tiled / whole {tiled_s / max(whole_s, 1e-9):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
