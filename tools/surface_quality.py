"""Triangle quality of the fracture surfaces in a pdsim cache, read back the way a renderer reads it.

    python tools/surface_quality.py CACHE.usdc [--json OUT.json]

For every mesh with a ``crack`` primvar (a peridynamic body's ``<body>_surface``) and every frame: the number of
crack (interior) triangles, the smallest interior angle among them [degrees], how many have an angle under 5
degrees, and the longest triangle edge in particle spacings (the spacing is the width of the body's points). The
positions and faces are the drawn ones (``Usd.Stage.Open``, values held between topology samples), so this measures
what a renderer shows. Exits with 1 when some crack triangle has an angle under 5 degrees or some triangle is longer
than 3 spacings (``--max-edge``).
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np
from pxr import Usd, UsdGeom

from pdsim.fragment_surfaces import triangle_angles
from pdsim.fragment_surfaces.cleanup import SLIVER_ANGLE
from pdsim.fragment_surfaces.drawn import longest_edge


def measure(path: str) -> list[dict]:
    """One row per (mesh, frame): mesh, frame, crack_triangles, min_angle, slivers, longest_edge_spacings."""
    stage = Usd.Stage.Open(path)
    rows = []
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Mesh):
            continue
        mesh = UsdGeom.Mesh(prim)
        crack_var = UsdGeom.PrimvarsAPI(prim).GetPrimvar("crack")
        if not crack_var:
            continue
        body = stage.GetPrimAtPath(str(prim.GetPath()).removesuffix("_surface"))
        spacing = float(np.median(UsdGeom.Points(body).GetWidthsAttr().Get(0))) if body and body.IsValid() else 1.0
        frames = mesh.GetPointsAttr().GetTimeSamples()
        for frame in frames:
            points = np.array(mesh.GetPointsAttr().Get(frame), dtype=np.float64)
            tri = np.array(mesh.GetFaceVertexIndicesAttr().Get(frame), dtype=np.int64).reshape(-1, 3)
            crack = np.array(crack_var.Get(frame)) == 1
            longest = longest_edge(points, tri) / spacing
            amin = triangle_angles(points, tri[crack]).min(axis=1) if crack.any() else np.zeros(0)
            rows.append(
                {
                    "mesh": str(prim.GetPath()),
                    "frame": int(frame),
                    "crack_triangles": int(crack.sum()),
                    "min_angle": float(amin.min()) if amin.size else None,
                    "slivers": int((amin < SLIVER_ANGLE).sum()),
                    "longest_edge_spacings": longest,
                }
            )
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cache")
    parser.add_argument("--json", help="write the rows to this JSON file")
    parser.add_argument("--max-edge", type=float, default=3.0, help="longest edge allowed [spacings] (default 3)")
    args = parser.parse_args(argv)
    rows = measure(args.cache)
    print(f"{'mesh':32s} {'frame':>5s} {'crack tris':>10s} {'min angle':>9s} {'< 5 deg':>7s} {'longest/h':>9s}")
    for r in rows:
        angle = "-" if r["min_angle"] is None else f"{r['min_angle']:.2f}"
        print(
            f"{r['mesh']:32s} {r['frame']:5d} {r['crack_triangles']:10d} {angle:>9s} {r['slivers']:7d} "
            f"{r['longest_edge_spacings']:9.2f}"
        )
    angles = [r["min_angle"] for r in rows if r["min_angle"] is not None]
    print(
        f"over {len(rows)} mesh samples: smallest crack angle {min(angles) if angles else float('nan'):.2f} degrees, "
        f"{sum(r['slivers'] for r in rows)} crack triangles under {SLIVER_ANGLE:g} degrees, longest edge "
        f"{max((r['longest_edge_spacings'] for r in rows), default=0.0):.2f} spacings"
    )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)
    too_long = any(r["longest_edge_spacings"] > args.max_edge for r in rows)
    return 1 if any(r["slivers"] for r in rows) or too_long else 0


if __name__ == "__main__":
    sys.exit(main())
