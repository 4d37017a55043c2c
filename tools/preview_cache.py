"""Quick matplotlib preview of a pdsim USD cache: the surface meshes (``*_surface`` prims) at a few frames, faces
coloured by fragment. For a look without a USD viewer; renderers (usdview, Blender, Houdini) are the real target.

    python tools/preview_cache.py CACHE.usdc --frames 0 20 40 --out preview.png
"""

from __future__ import annotations

import argparse
import sys

import numpy as np


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("cache")
    p.add_argument("--frames", type=int, nargs="+", default=[0])
    p.add_argument("--out", default="preview.png")
    p.add_argument("--elev", type=float, default=15.0)
    p.add_argument("--azim", type=float, default=-60.0)
    args = p.parse_args(argv)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(args.cache)
    meshes = [UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh) and p.GetName().endswith("_surface")]
    if not meshes:
        print(f"{args.cache}: no *_surface meshes", file=sys.stderr)
        return 1
    fig = plt.figure(figsize=(4.0 * len(args.frames), 4.0))
    for j, frame in enumerate(args.frames):
        ax = fig.add_subplot(1, len(args.frames), j + 1, projection="3d")
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for mesh in meshes:
            v = np.array(mesh.GetPointsAttr().Get(frame))
            faces = np.array(mesh.GetFaceVertexIndicesAttr().Get(frame)).reshape(-1, 3)
            fragment = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("fragment").Get(frame)
            ids = np.zeros(len(faces), int) if fragment is None else np.array(fragment)
            colours = plt.cm.tab20((ids % 20) / 20.0)
            ax.add_collection3d(Poly3DCollection(v[faces], facecolors=colours, edgecolors="none"))
            if frame == args.frames[0]:
                lo, hi = np.minimum(lo, v.min(axis=0)), np.maximum(hi, v.max(axis=0))
        if frame == args.frames[0]:
            centre, half = 0.5 * (lo + hi), 0.6 * (hi - lo).max()
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_zlim(centre[2] - half, centre[2] + half)
        ax.view_init(elev=args.elev, azim=args.azim)
        ax.set_title(f"frame {frame}")
    fig.tight_layout()
    fig.savefig(args.out, dpi=90)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
