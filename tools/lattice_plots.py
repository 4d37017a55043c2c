"""Figures of lattice runs in the style of dell'Erba 2018 (docs/lattice.md): configurations at chosen steps over a
contour plot of a per-particle field (PE1, PE2, ...), and trajectories of chosen particles. Everything is read back
from the USD cache a scene wrote (``/World/<body>`` points with the lattice primvars), so a plot shows exactly what
the cache holds. matplotlib is imported on first use.

    python tools/lattice_plots.py lattice_case_a.usdc --frames 1 10 20 401 --pe2-frames 2 10 --track 66 --out plots/
    python tools/lattice_plots.py lattice_case_d.usdc --frames 1 5 6 7 100 --field pe1_intact

Particle indices are 0-based (the paper's point j is index j - 1). Frames are steps when steps_per_frame = 1.
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass

import numpy as np
import warp as wp
from pxr import Usd, UsdGeom

from pdsim.errors import ParameterError, PdsimError
from pdsim.output.usd_files import world_points

__all__ = [
    "LatticeCacheBody",
    "plot_configurations",
    "plot_trajectories",
    "read_lattice_cache",
    "run_lattice_scene",
    "write_case_plots",
]

KIND_COLOURS = {0: "#1f4fd1", 1: "#d62728", 2: "#f2c200"}  # followers blue, leaders red, frame yellow (Figure 3)
KIND_LABELS = {0: "follower", 1: "leader", 2: "frame"}


@dataclass
class LatticeCacheBody:
    """One lattice body read from a cache: frames [F] (time codes), positions [F, n, 3] [m] and primvars
    {name: [F, n], or [F, n, 3] for vector primvars such as ``displacement`` [m]} (frames where a primvar has no
    sample repeat its last value)."""

    name: str
    frames: np.ndarray
    positions: np.ndarray
    primvars: dict

    def field(self, name: str) -> np.ndarray:
        """Per-particle scalar values of primvar ``name``, [F, n]: the primvar itself, or the norm of a vector
        primvar (``displacement``: |u| [m])."""
        if name not in self.primvars:
            raise ParameterError("field", name, f"a primvar of '{self.name}': {sorted(self.primvars)}")
        values = self.primvars[name]
        return np.linalg.norm(values, axis=-1) if values.ndim == 3 else values

    def frame_index(self, frame: int) -> int:
        """Row of ``frame`` in the arrays."""
        hit = np.nonzero(self.frames == frame)[0]
        if len(hit) == 0:
            raise ParameterError("frame", frame, f"a frame of the cache in [{self.frames[0]}, {self.frames[-1]}]")
        return int(hit[0])


def read_lattice_cache(path: str | os.PathLike) -> list[LatticeCacheBody]:
    """Every ``UsdGeom.Points`` prim under /World that carries a ``pe1`` primvar (a lattice body), all frames."""
    stage = Usd.Stage.Open(os.fspath(path))
    start, end = int(stage.GetStartTimeCode()), int(stage.GetEndTimeCode())
    frames = np.arange(start, end + 1)
    bodies = []
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Points):
            continue
        api = UsdGeom.PrimvarsAPI(prim)
        if not api.HasPrimvar("pe1"):
            continue
        pos = np.stack([world_points(prim, float(f)) for f in frames])  # through the prim's double translate
        pv = {}
        for p in api.GetPrimvars():
            vals = [p.Get(float(f)) for f in frames]
            if any(v is None for v in vals):
                continue
            pv[p.GetPrimvarName()] = np.stack([np.asarray(v) for v in vals])
        bodies.append(LatticeCacheBody(prim.GetName(), frames, pos, pv))
    return bodies


def _triangles(rest: np.ndarray) -> tuple[np.ndarray, float]:
    """Delaunay triangles of the rest configuration (x, y) without slivers (an edge over 2.5 spacings), and the
    spacing (the shortest edge) [m]."""
    import matplotlib.tri as mtri

    t = mtri.Triangulation(rest[:, 0], rest[:, 1]).triangles
    edges = np.stack([t, np.roll(t, -1, axis=1)], axis=2)
    length = np.linalg.norm(rest[edges[..., 0], :2] - rest[edges[..., 1], :2], axis=2)
    spacing = float(length.min())
    return t[length.max(axis=1) < 2.5 * spacing], spacing


def plot_configurations(
    body: LatticeCacheBody,
    frames,
    path: str | os.PathLike,
    *,
    field: str = "pe1",
    title: str | None = None,
    stretch_mask: float = 3.0,
) -> str:
    """A row of panels, one per frame: the particles (leaders red, followers blue, frame yellow) at their positions
    over a filled contour of ``field`` (a vector primvar as its norm) on the leaders and followers (one colour scale
    for all panels), interpolated over the rest configuration's Delaunay triangles. Triangles that join two fragments
    (bodies with fracture: the ``fragment`` primvar) or have an edge stretched over ``stretch_mask`` times its rest
    length are left blank, so cracks and torn cells show. 2D lattices only (x, y); writes a PNG and returns its
    path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.tri as mtri

    values = body.field(field)  # [F, n] (the norm of a vector primvar such as displacement)
    rows = [body.frame_index(f) for f in frames]
    kind0 = body.primvars["kind"][0]
    solid = kind0 != 2
    rest = body.positions[0][solid]
    tris, spacing = _triangles(rest)
    rest_edges = np.linalg.norm(rest[tris][:, :, :2] - rest[np.roll(tris, -1, axis=1)][:, :, :2], axis=2)
    vmax = max(float(values[r][solid].max()) for r in rows)
    levels = np.linspace(0.0, vmax if vmax > 0 else 1.0, 21)
    fig, axes = plt.subplots(1, len(rows), figsize=(3.2 * len(rows) + 1.2, 3.6), squeeze=False, layout="constrained")
    lo = body.positions[rows].reshape(-1, 3).min(axis=0) - spacing
    hi = body.positions[rows].reshape(-1, 3).max(axis=0) + spacing
    cs = None
    for ax, r, f in zip(axes[0], rows, frames, strict=True):
        x = body.positions[r]
        kind = body.primvars["kind"][r]
        xs = x[solid]
        tri = mtri.Triangulation(xs[:, 0], xs[:, 1], tris)
        edges = np.stack([tris, np.roll(tris, -1, axis=1)], axis=2)
        now = np.linalg.norm(xs[edges[..., 0], :2] - xs[edges[..., 1], :2], axis=2)
        mask = np.any(now > stretch_mask * rest_edges, axis=1)
        if "fragment" in body.primvars:
            frag = body.primvars["fragment"][r][solid][tris]
            mask |= np.any(frag != frag[:, :1], axis=1)
        tri.set_mask(mask)
        cs = ax.tricontourf(tri, values[r][solid], levels=levels, cmap="jet", extend="max")
        for k, colour in KIND_COLOURS.items():
            m = kind == k
            if m.any():
                ax.scatter(x[m, 0], x[m, 1], s=9, c=colour, edgecolors="k", linewidths=0.3, label=KIND_LABELS[k])
        ax.set_title(f"step {int(f)}")
        ax.set_aspect("equal")
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.tick_params(labelsize=7)
    fig.colorbar(cs, ax=axes[0].tolist(), shrink=0.9, label=f"{field} [units^2]" if field == "pe1" else field)
    axes[0][0].legend(loc="upper left", fontsize=6, framealpha=0.8)
    fig.suptitle(title or f"{body.name}: {field}")
    out = os.fspath(path)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def plot_trajectories(
    body: LatticeCacheBody, particles, path: str | os.PathLike, *, title: str | None = None, field: str = "pe1"
) -> str:
    """x, y and ``field`` of the given particles (indices) against the frame (= step for steps_per_frame 1), as the
    paper's Figures 8, 9, 11, 13, 16, 19 and 21. Writes a PNG and returns its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    idx = np.atleast_1d(np.asarray(particles, dtype=np.int64))
    if idx.size == 0 or idx.min() < 0 or idx.max() >= body.positions.shape[1]:
        raise ParameterError("particles", particles, f"indices in [0, {body.positions.shape[1]})")
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.4))
    for j in idx:
        label = f"j = {j + 1}"
        axes[0].plot(body.frames, body.positions[:, j, 0], label=label)
        axes[1].plot(body.frames, body.positions[:, j, 1], label=label)
        axes[2].plot(body.frames, body.field(field)[:, j], label=label)
    for ax, name in zip(axes, ("x [units]", "y [units]", field), strict=True):
        ax.set_xlabel("step")
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(title or f"{body.name}: tracked particles (paper numbering j = index + 1)")
    fig.tight_layout()
    out = os.fspath(path)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def write_case_plots(cache_path, out_dir, *, frames, tracked: dict | None = None, pe2_frames=None) -> list[str]:
    """For every lattice body in the cache: ``<name>_pe1.png`` at ``frames``, ``<name>_pe2.png`` at ``pe2_frames``
    (default: the first two of ``frames``) and ``<name>_track.png`` for ``tracked[name]`` (indices). 2D bodies."""
    os.makedirs(out_dir, exist_ok=True)
    written = []
    for body in read_lattice_cache(cache_path):
        fs = [f for f in frames if body.frames[0] <= f <= body.frames[-1]]
        if np.ptp(body.positions[0][:, 2]) > 0:
            continue  # 3D body: contour plots are for plane lattices
        written.append(plot_configurations(body, fs, os.path.join(out_dir, f"{body.name}_pe1.png"), field="pe1"))
        f2 = [f for f in (pe2_frames or fs[:2]) if body.frames[0] <= f <= body.frames[-1]]
        if f2:
            written.append(plot_configurations(body, f2, os.path.join(out_dir, f"{body.name}_pe2.png"), field="pe2"))
        if tracked and len(tracked.get(body.name, [])):
            written.append(plot_trajectories(body, tracked[body.name], os.path.join(out_dir, f"{body.name}_track.png")))
    return written


def run_lattice_scene(build_scene, *, frames, pe2_frames=None, argv=None) -> int:
    """Entry point of the lattice scene scripts: runs the scene into ``--out`` (default ``<scene name>.usdc``) and
    writes the plots of :func:`write_case_plots` into ``--plots`` (default ``<scene name>_plots``); tracked particles
    are those of each body's ``track``. Returns the exit status."""
    parser = argparse.ArgumentParser(description="run this lattice scene and plot it")
    parser.add_argument("--out", help="output cache (.usdc/.usda/.usd)")
    parser.add_argument("--plots", help="folder for the PNG figures")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    wp.config.quiet = True
    try:
        scene = build_scene()
        out = args.out or f"{scene.name}.usdc"
        report = scene.run(out, progress=not args.quiet)
        tracked = {b.name: np.asarray(getattr(b, "tracked", [])) for b in scene.bodies}
        plots = write_case_plots(
            out, args.plots or f"{scene.name}_plots", frames=frames, tracked=tracked, pe2_frames=pe2_frames
        )
    except PdsimError as exc:
        print(f"pdsim: error: {exc}", file=sys.stderr)
        return 1
    print(f"pdsim: wrote {report.path} ({report.frames_written} frames, {report.particle_count} points)")
    for p in plots:
        print(f"pdsim: wrote {p}")
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("cache", help="a USD cache written by a lattice scene")
    p.add_argument("--frames", type=int, nargs="+", required=True, help="frames of the configuration panels")
    p.add_argument("--pe2-frames", type=int, nargs="*", default=None, help="frames of the PE2 panels")
    p.add_argument(
        "--field", default=None, help="another primvar to contour (pe1_intact, displacement (its norm), ...)"
    )
    p.add_argument("--track", type=int, nargs="*", default=[], help="particle indices to plot against the step")
    p.add_argument("--out", default=None, help="output folder (default: <cache>_plots)")
    args = p.parse_args(argv)

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
