"""The render surfaces' rebuilds of the figurine shot (tools/shot_figurine.py, surfaces built in the main thread),
with the last clean-up's edits carried (pdsim/fragment_surfaces/edits.py) or, with ``--no-carry``, the whole
complex cleaned at every rebuild:

    python tools/bench_carried_edits.py [--frames 3] [--no-carry]

Prints one line per rebuild: the regions and how many were clipped, the record's edit clusters applied, the
triangles entering the clean-up, how many are flagged (a side under 0.3 h or an angle under 5 degrees) and how many
of those start settled, the triangles out and still flagged, and the clean-up's wall time.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import shot_figurine

import pdsim.fragment_surfaces.booleans as booleans
import pdsim.fragment_surfaces.surfaces as surfaces
from pdsim.fragment_surfaces.cleanup import SHORT_EDGE, SLIVER_ANGLE, _needs_work


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=3, help="frames of the shot (default 3)")
    parser.add_argument("--no-carry", action="store_true", help="clean the whole complex at every rebuild")
    args = parser.parse_args(argv)
    line: dict = {}
    clip, apply, clean, shared = (
        booleans.clip_regions,
        booleans.apply_edits,
        booleans.clean_complex,
        surfaces.shared_complex,
    )

    def clip_spy(regions, *a, **kw):
        out = clip(regions, *a, **kw)
        line.update(regions=len(regions), clipped=out[1], clusters="-")
        return out

    def apply_spy(*a):
        out = apply(*a)
        line["clusters"] = f"{out[6]}/{out[7]}"
        return out

    def clean_spy(points, tri, shell, patch, spacing, **kw):
        settled = kw.get("settled")
        flag = _needs_work(points, tri, spacing, SHORT_EDGE, SLIVER_ANGLE)
        t0 = time.perf_counter()
        out = clean(points, tri, shell, patch, spacing, **kw)
        seconds = time.perf_counter() - t0
        left = int(_needs_work(points, out[0], spacing, SHORT_EDGE, SLIVER_ANGLE).sum())
        print(
            f"regions {line['regions']} (clipped {line['clipped']}), clusters applied {line['clusters']}, "
            f"clean-up: {len(tri):,} triangles in, {int(flag.sum()):,} flagged "
            f"({0 if settled is None else int((flag & settled).sum()):,} of them settled), {len(out[0]):,} out "
            f"({left:,} flagged), {seconds:.1f} s",
            flush=True,
        )
        return out

    def shared_spy(*a, **kw):
        if args.no_carry:
            kw["record"] = None
        return shared(*a, **kw)

    booleans.clip_regions, booleans.apply_edits, booleans.clean_complex = clip_spy, apply_spy, clean_spy
    surfaces.clip_regions, surfaces.shared_complex = clip_spy, shared_spy
    scene = shot_figurine.build_scene(frames=args.frames)
    with tempfile.TemporaryDirectory() as tmp:
        scene.run(str(Path(tmp) / "figurine.usdc"), progress=False, surface_thread=False, checkpoint_interval_s=None)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
