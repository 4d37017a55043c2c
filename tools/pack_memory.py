"""Peak memory of packing a clip-layout cache into one file (pdsim.output.usd_pack.pack_cache), against flattening it
through a stage (pdsim.output.usd_files.flatten_cache, which holds the whole animation).

Writes two clip caches into a temporary folder: the default scene (``pdsim run --layout clips``, its 72 frames) and a
synthetic cache of ``--points`` points over ``--frames`` frames (positions, velocities and one float primvar per
point and frame, written through the ViewWriter). Each is then packed, and flattened, in a child process of its own
that prints its peak resident set size [MB] after its imports and at the end; the difference is what the packing
holds. Prints one line per cache and method.

    python tools/pack_memory.py                      # the default scene and 100k points x 150 frames
    python tools/pack_memory.py --points 200000 --frames 100 --skip-default
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

WRITE = textwrap.dedent(
    """
    import sys
    import numpy as np
    from pdsim.output.usd import UsdCache
    from pdsim.output.views import PointsView
    from pdsim.output.writer import ViewWriter

    n, frames, out = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    base = np.random.default_rng(0).random((n, 3))
    with UsdCache(out, fps=24.0) as cache:
        writer = ViewWriter(cache)
        for f in range(frames):
            x = base + 0.01 * f
            writer.write(f, [PointsView("cloud", x, np.full((n, 3), f, float), np.full(n, 0.01), {"damage": x[:, 0]})])
            cache.end_frame(f, time=f / 24.0)
    """
)

MEASURE = textwrap.dedent(
    """
    import resource, sys
    from pdsim.output.usd_files import flatten_cache
    from pdsim.output.usd_pack import pack_cache

    method, source, out = sys.argv[1:4]
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    (pack_cache if method == "pack" else flatten_cache)(source, out)
    after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{before:.1f} {after:.1f}")
    """
)


def _python(code: str, *args: str) -> str:
    proc = subprocess.run(
        [sys.executable, "-c", code, *args], check=True, capture_output=True, text=True, cwd=ROOT, env=os.environ
    )
    lines = proc.stdout.strip().splitlines()
    return lines[-1] if lines else ""


def _folder_mb(cache: Path) -> float:
    frames = cache.with_name(f"{cache.stem}.frames")
    return (cache.stat().st_size + sum(p.stat().st_size for p in frames.rglob("*") if p.is_file())) / 1e6


def _measure(label: str, cache: Path) -> None:
    size = _folder_mb(cache)
    for method in ("pack", "flatten"):
        out = cache.with_name(f"{cache.stem}.{method}.usdc")
        before, after = (float(v) for v in _python(MEASURE, method, str(cache), str(out)).split())
        print(
            f"{label}: clip cache {size:.1f} MB -> {method} {out.stat().st_size / 1e6:.1f} MB; peak RSS "
            f"{after:.1f} MB (after imports {before:.1f} MB, +{after - before:.1f} MB)",
            flush=True,
        )
        out.unlink()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=100_000, help="points of the synthetic cache")
    parser.add_argument("--frames", type=int, default=150, help="frames of the synthetic cache")
    parser.add_argument("--skip-default", action="store_true", help="measure the synthetic cache only")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if not args.skip_default:
            cache = folder / "default.usdc"
            subprocess.run(
                [sys.executable, "-m", "pdsim.cli", "run", "--layout", "clips", "--out", str(cache), "--quiet"],
                check=True,
                cwd=ROOT,
                capture_output=True,
            )
            _measure("default scene", cache)
        cache = folder / "synthetic.usdc"
        _python(WRITE, str(args.points), str(args.frames), str(cache))
        _measure(f"synthetic {args.points} points x {args.frames} frames", cache)


if __name__ == "__main__":
    main()
