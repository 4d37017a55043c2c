"""The sliver clean-up of the render surfaces, this code against a git revision, paired on the same shell complexes.

    python tools/bench_cleanup.py MESH.obj [--rev 96fcd0c] [--pairs 1] [--frames 2] [--save CALLS.pkl]
    python tools/bench_cleanup.py --calls CALLS.pkl [--rev 96fcd0c] [--pairs 1]
    python tools/bench_cleanup.py --scene fem_slab_crack [--frames N] [--rev 96fcd0c]   # a gallery scene's preview

Runs a figurine shot (MESH fitted to 30 cm, Y up, ceramic preset at 1 cm spacing, a 2.5 cm steel ball at 12 m/s) or,
with ``--scene``, a gallery scene at its PREVIEW settings, surfaces built in the main thread, and keeps the input of
every `clean_complex` call of its topology rebuilds (``--save`` writes them, ``--calls`` reads them instead of running
the shot). Then, pair by pair, times `clean_complex` of pdsim/fragment_surfaces/cleanup.py at ``--rev`` (read with
``git show``) and of this checkout on each complex, in turn, and checks that both give the same triangles, shells,
patches and points bit for bit. Prints one row per call and pair: triangles in, triangles out and crack triangles with
an angle under the sliver angle of the revision and of this code, their seconds and ratio, identical.
"""

from __future__ import annotations

import argparse
import pickle
import subprocess
import sys
import tempfile
import time
import types
from pathlib import Path

import numpy as np

import pdsim
import pdsim.fragment_surfaces.booleans as booleans
from pdsim import presets
from pdsim.fragment_surfaces import cleanup

ROOT = Path(__file__).resolve().parents[1]


def figurine_scene(mesh_path: str, frames: int) -> pdsim.Scene:
    """The figurine shot: ``mesh_path`` fitted to 30 cm, Y up, the ceramic preset at 1 cm, a 2.5 cm steel ball."""
    mesh = pdsim.load_mesh(mesh_path, up_axis="Y", fit_size=0.3, position=(0.0, 0.0, 0.0), name="figurine")
    scene = pdsim.Scene(fps=24, frames=frames, name="figurine")
    scene.add_ground_plane(height=0.0, friction=0.5)
    scene.add_peridynamic_body(mesh, presets.ceramic(), spacing=0.01)
    scene.add_rigid_body(
        pdsim.SphereShape(0.025), density=7850.0, position=(-0.13, 0.0, 0.2), velocity=(12.0, 0.0, 0.0), name="ball"
    )
    return scene


def gallery_scene(name: str, frames: int | None) -> pdsim.Scene:
    """Gallery scene ``name`` (scenes/<name>.py) at its PREVIEW settings, ``frames`` frames (None: its own)."""
    sys.path.insert(0, str(ROOT / "tools"))
    from make_gallery import load_scene_module

    module = load_scene_module(name)
    kwargs = dict(getattr(module, "PREVIEW", {}))
    if frames is not None:
        kwargs["frames"] = frames
    return module.build_scene(**kwargs)


def capture(scene: pdsim.Scene) -> list:
    """The arguments of every clean_complex call of ``scene``'s topology rebuilds (surfaces in the main thread)."""
    calls = []
    inner = booleans.clean_complex

    def keep(points, tri, shell, patch, spacing, **kw):
        calls.append((points.copy(), tri.copy(), shell.copy(), patch.copy(), spacing, kw))
        return inner(points, tri, shell, patch, spacing, **kw)

    booleans.clean_complex = keep
    try:
        with tempfile.TemporaryDirectory() as tmp:
            scene.run(str(Path(tmp) / "capture.usdc"), progress=False, surface_thread=False)
    finally:
        booleans.clean_complex = inner
    return calls


def _crack_slivers(points, result, kw) -> int:
    """Crack triangles of a clean-up's ``result`` (tri, shell, patch, ...) with an angle under SLIVER_ANGLE."""
    tri, patch = result[0], result[2]
    crack = kw.get("crack_patch")
    mask = np.ones(len(tri), dtype=bool) if crack is None else np.asarray(crack, dtype=bool)[patch]
    if not mask.any():
        return 0
    return int((cleanup.triangle_angles(points, tri[mask]).min(axis=1) < cleanup.SLIVER_ANGLE).sum())


def revision_module(rev: str) -> types.ModuleType:
    """pdsim/fragment_surfaces/cleanup.py as it was at ``rev``, loaded as a module of its own."""
    text = subprocess.run(
        ["git", "show", f"{rev}:pdsim/fragment_surfaces/cleanup.py"],
        cwd=ROOT,
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    module = types.ModuleType(f"cleanup_{rev}")
    exec(compile(text, f"cleanup@{rev}", "exec"), module.__dict__)
    return module


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("mesh", nargs="?", help="the figurine's mesh (OBJ); not needed with --calls")
    parser.add_argument("--rev", default="96fcd0c", help="git revision to compare against (default 96fcd0c)")
    parser.add_argument("--pairs", type=int, default=1, help="timed pairs per call (default 1)")
    parser.add_argument("--frames", type=int, help="frames of the shot (default 2; with --scene: the scene's)")
    parser.add_argument("--scene", help="a gallery scene (scenes/<name>.py, PREVIEW settings) instead of the figurine")
    parser.add_argument("--save", help="write the captured calls to this pickle")
    parser.add_argument("--calls", help="read the calls from this pickle instead of running the shot")
    args = parser.parse_args(argv)
    if args.calls:
        with open(args.calls, "rb") as f:
            calls = pickle.load(f)
    else:
        if args.scene:
            scene = gallery_scene(args.scene, args.frames)
        elif args.mesh:
            scene = figurine_scene(args.mesh, 2 if args.frames is None else args.frames)
        else:
            parser.error("mesh: give an OBJ file, --scene or --calls")
        calls = capture(scene)
        if args.save:
            with open(args.save, "wb") as f:
                pickle.dump(calls, f)
    old = revision_module(args.rev)
    print(f"call  tri in  tri out ({args.rev} / this)  slivers  {args.rev} [s]  this [s]  this/{args.rev}  identical")
    same = True
    for i, (points, tri, shell, patch, spacing, kw) in enumerate(calls):
        for _ in range(args.pairs):
            out = {}
            for name, module in ((args.rev, old), ("this", cleanup)):
                p = points.copy()
                start = time.perf_counter()
                result = module.clean_complex(p, tri, shell, patch, spacing, **kw)
                out[name] = (time.perf_counter() - start, p, result)
            (t_old, p_old, r_old), (t_new, p_new, r_new) = out[args.rev], out["this"]
            ident = np.array_equal(p_old, p_new) and all(np.array_equal(a, b) for a, b in zip(r_old, r_new))
            same &= ident
            slivers = [_crack_slivers(pp, r, kw) for pp, r in ((p_old, r_old), (p_new, r_new))]
            print(
                f"{i:4d}  {len(tri):6d}  {len(r_old[0]):7d} / {len(r_new[0]):<7d}  {slivers[0]:4d} / {slivers[1]:<4d}"
                f"  {t_old:10.2f}  {t_new:8.2f}  {t_new / t_old:9.2f}  {ident}"
            )
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
