"""The drawn surface's sliver pass (pdsim/fragment_surfaces/drawn.py: ``_unsliver``), this code against a git
revision, paired on the same drawn surfaces.

    python tools/bench_drawn.py [--scene four_walls] [--frames 40] [--rev c0addff] [--save CALLS.pkl]
                                [--save-cleanups CLEAN.pkl]
    python tools/bench_drawn.py --calls CALLS.pkl [--rev c0addff]

Runs a scene of scenes/ at its PREVIEW settings (surfaces built in the main thread) and keeps the input of every
``_unsliver`` call of its drawn surfaces (``--save`` writes them, ``--calls`` reads them instead of running the
scene). Then times ``_unsliver`` of pdsim/fragment_surfaces/drawn.py at ``--rev`` (read with ``git show``, with this
checkout's cleanup.py) and of this checkout on each surface, in turn, and checks that both give the same triangles,
parents and points bit for bit. Prints the calls over 0.3 s and the totals; exits 1 if any call differs.
``--save-cleanups`` also keeps the scene's ``clean_complex`` calls (its topology rebuilds' sliver clean-ups) for
``python tools/bench_cleanup.py --calls CLEAN.pkl``.
"""

from __future__ import annotations

import argparse
import os
import pickle
import subprocess
import sys
import tempfile
import time
import types
from pathlib import Path

import numpy as np

import pdsim.fragment_surfaces.booleans as booleans
import pdsim.fragment_surfaces.drawn as drawn

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

from make_gallery import load_scene_module  # noqa: E402


def capture(scene_name: str, frames: int) -> tuple[list, list]:
    """The arguments of every ``_unsliver`` call of the scene's drawn surfaces, and of every ``clean_complex`` call
    of its rebuilds (as tools/bench_cleanup.py keeps them)."""
    calls, cleanups = [], []
    inner, inner_clean = drawn._unsliver, booleans.clean_complex

    def keep(x, faces, parent, shell_of, patch_of, crack_of, first_added, spacing):
        calls.append((x.copy(), faces.copy(), parent.copy(), shell_of, patch_of, crack_of, first_added, spacing))
        return inner(x, faces, parent, shell_of, patch_of, crack_of, first_added, spacing)

    def keep_clean(points, tri, shell, patch, spacing, **kw):
        cleanups.append((points.copy(), tri.copy(), shell.copy(), patch.copy(), spacing, kw))
        return inner_clean(points, tri, shell, patch, spacing, **kw)

    drawn._unsliver, booleans.clean_complex = keep, keep_clean
    try:
        module = load_scene_module(scene_name)
        scene = module.build_scene(**getattr(module, "PREVIEW", {}))
        with tempfile.TemporaryDirectory() as tmp:
            scene.run(os.path.join(tmp, "out.usdc"), frames=frames, progress=False, surface_thread=False)
    finally:
        drawn._unsliver, booleans.clean_complex = inner, inner_clean
    return calls, cleanups


def revision_module(rev: str) -> types.ModuleType:
    """pdsim/fragment_surfaces/drawn.py as it was at ``rev``, loaded as a module of its own (in the package, so
    that it imports this checkout's cleanup.py)."""
    text = subprocess.run(
        ["git", "show", f"{rev}:pdsim/fragment_surfaces/drawn.py"], cwd=ROOT, check=True, capture_output=True, text=True
    ).stdout
    name = f"pdsim.fragment_surfaces.drawn_{rev}"
    module = types.ModuleType(name)
    module.__package__ = "pdsim.fragment_surfaces"
    sys.modules[name] = module
    exec(compile(text, f"drawn@{rev}", "exec"), module.__dict__)
    return module


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", default="four_walls", help="a scene of scenes/ (default four_walls)")
    parser.add_argument("--frames", type=int, default=40, help="frames to run (default 40)")
    parser.add_argument("--rev", default="c0addff", help="git revision to compare against (default c0addff)")
    parser.add_argument("--save", help="write the captured calls to this pickle")
    parser.add_argument("--save-cleanups", help="write the captured clean_complex calls to this pickle")
    parser.add_argument("--calls", help="read the calls from this pickle instead of running the scene")
    args = parser.parse_args(argv)
    if args.calls:
        with open(args.calls, "rb") as f:
            calls = pickle.load(f)
    else:
        calls, cleanups = capture(args.scene, args.frames)
        for path, what in ((args.save, calls), (args.save_cleanups, cleanups)):
            if path:
                with open(path, "wb") as f:
                    pickle.dump(what, f)
    old = revision_module(args.rev)
    print(f"call  triangles  {args.rev} [s]  this [s]  identical")
    t_old = t_new = 0.0
    same = True
    for i, (x, faces, parent, shell_of, patch_of, crack_of, first_added, spacing) in enumerate(calls):
        out = []
        for module in (old, drawn):
            p = x.copy()
            start = time.perf_counter()
            result = module._unsliver(p, faces, parent, shell_of, patch_of, crack_of, first_added, spacing)
            out.append((time.perf_counter() - start, p, result))
        (a, p_old, r_old), (b, p_new, r_new) = out
        t_old, t_new = t_old + a, t_new + b
        ident = np.array_equal(p_old, p_new) and all(np.array_equal(u, v) for u, v in zip(r_old, r_new))
        same &= ident
        if a > 0.3 or not ident:
            print(f"{i:4d}  {len(faces):9d}  {a:10.2f}  {b:8.2f}  {ident}")
    print(f"{len(calls)} calls: {args.rev} {t_old:.2f} s, this {t_new:.2f} s, this/{args.rev} {t_new / t_old:.3f}, "
          f"identical: {same}")  # fmt: skip
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
