"""Digests of the first frames of every gallery scene's preview cache: points and mesh topology, bit for bit.

Runs each gallery scene (tools/make_gallery.py's list, at its PREVIEW settings) for a few frames on the CPU, reads the
cache back through ``pxr`` and records, per frame and per prim, a SHA-256 of every ``points`` array and of every
mesh's ``faceVertexCounts`` / ``faceVertexIndices``. Two commits that compute the same thing print the same digests,
so a restructuring can be checked to change nothing:

    python tools/frame_digest.py --out /tmp/before.json            # on the old commit
    python tools/frame_digest.py --out /tmp/after.json             # on the new one
    python tools/frame_digest.py --compare /tmp/before.json /tmp/after.json

Each scene runs in its own child process (``--one NAME``). ``--frames`` (default 3) counts frames after the rest
pose; ``--scenes a,b`` limits the list.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tools"))

from make_gallery import gallery_scenes, load_scene_module  # noqa: E402


def _digest(array) -> str:
    import numpy as np

    data = np.ascontiguousarray(np.asarray(array))
    return hashlib.sha256(str(data.dtype).encode() + str(data.shape).encode() + data.tobytes()).hexdigest()[:16]


def digest_cache(path: str, frames: int) -> dict:
    """{frame: {prim path: {attribute: digest}}} for the points and the topology of every prim of the cache."""
    from pxr import Usd

    stage = Usd.Stage.Open(path)
    out: dict = {}
    for frame in range(frames + 1):
        entry = {}
        for prim in stage.Traverse():
            for name in ("points", "faceVertexCounts", "faceVertexIndices"):
                attr = prim.GetAttribute(name)
                if not attr or not attr.HasValue():
                    continue
                value = attr.Get(frame)
                if value is not None:
                    entry.setdefault(str(prim.GetPath()), {})[name] = _digest(value)
        out[str(frame)] = entry
    return out


def run_one(name: str, frames: int) -> dict:
    import warp as wp

    wp.config.quiet = True
    module = load_scene_module(name)
    scene = module.build_scene(**dict(getattr(module, "PREVIEW", {})))
    with tempfile.TemporaryDirectory() as tmp:
        cache = os.path.join(tmp, f"{name}.usdc")
        scene.run(cache, device="cpu", progress=False, frames=frames)
        return digest_cache(cache, frames)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", help="JSON file for the digests")
    parser.add_argument("--frames", type=int, default=3)
    parser.add_argument("--scenes", help="comma-separated scene names (default: every gallery scene)")
    parser.add_argument("--one", help=argparse.SUPPRESS)
    parser.add_argument(
        "--compare", nargs=2, metavar=("A", "B"), help="compare two digest files; exit 1 if they differ"
    )
    args = parser.parse_args(argv)
    if args.compare:
        with open(args.compare[0]) as fa, open(args.compare[1]) as fb:
            a, b = json.load(fa), json.load(fb)
        bad = [n for n in sorted(set(a) | set(b)) if a.get(n) != b.get(n)]
        for n in sorted(set(a) | set(b)):
            print(f"{n:20s} {'differs' if n in bad else 'identical'}")
        print(f"{len(set(a) | set(b)) - len(bad)} identical, {len(bad)} differ")
        return 1 if bad else 0
    if args.one:
        print("DIGEST " + json.dumps(run_one(args.one, args.frames)))
        return 0
    names = args.scenes.split(",") if args.scenes else gallery_scenes()
    result = {}
    for name in names:
        proc = subprocess.run(
            [sys.executable, os.path.abspath(__file__), "--one", name, "--frames", str(args.frames)],
            capture_output=True,
            text=True,
            check=False,
            cwd=ROOT,
        )
        line = next((ln for ln in proc.stdout.splitlines() if ln.startswith("DIGEST ")), None)
        result[name] = json.loads(line[7:]) if line else {"error": (proc.stdout + proc.stderr)[-400:]}
        print(f"{name:20s} {'error' if line is None else 'ok'}", flush=True)
    text = json.dumps(result, indent=1, sort_keys=True)
    if args.out:
        Path(args.out).write_text(text)
    else:
        print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
