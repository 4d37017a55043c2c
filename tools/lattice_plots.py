"""Paper-style figures of a lattice USD cache (shared/seeds/pbd_lattice.txt, Figures 5-22): for every lattice body in
the cache, the configuration at chosen frames over a contour plot of PE1 (and PE2, or any float primvar), and the
x, y and PE1 of chosen particles against the step.

    python tools/lattice_plots.py lattice_case_a.usdc --frames 1 10 20 401 --pe2-frames 2 10 --track 66 --out plots/
    python tools/lattice_plots.py lattice_case_d.usdc --frames 1 5 6 7 100 --field pe1_intact

Particle indices are 0-based (the paper's point j is index j - 1). Frames are steps when steps_per_frame = 1.
"""

from __future__ import annotations

import argparse
import os
import sys


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("cache", help="a USD cache written by a lattice scene")
    p.add_argument("--frames", type=int, nargs="+", required=True, help="frames of the configuration panels")
    p.add_argument("--pe2-frames", type=int, nargs="*", default=None, help="frames of the PE2 panels")
    p.add_argument("--field", default=None, help="another float primvar to contour (pe1_intact, displacement, ...)")
    p.add_argument("--track", type=int, nargs="*", default=[], help="particle indices to plot against the step")
    p.add_argument("--out", default=None, help="output folder (default: <cache>_plots)")
    args = p.parse_args(argv)

    from pdsim.lattice_plots import plot_configurations, read_lattice_cache, write_case_plots

    out = args.out or os.path.splitext(args.cache)[0] + "_plots"
    names = [b.name for b in read_lattice_cache(args.cache)]
    if not names:
        print(f"{args.cache}: no lattice body (a points prim with a pe1 primvar)", file=sys.stderr)
        return 1
    written = write_case_plots(
        args.cache, out, frames=args.frames, tracked=dict.fromkeys(names, args.track), pe2_frames=args.pe2_frames
    )
    if args.field:
        for body in read_lattice_cache(args.cache):
            path = os.path.join(out, f"{body.name}_{args.field}.png")
            written.append(plot_configurations(body, args.frames, path, field=args.field))
    for w in written:
        print(w)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
