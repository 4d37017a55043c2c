"""Preview of a pdsim USD cache: a thin wrapper of ``pdsim preview`` (pdsim/preview/, docs/preview.md).

    python tools/preview_cache.py CACHE.usdc --out preview.png [--frames A:B] [--color ATTR] [--camera AZ,EL]

takes the options of ``pdsim preview``: a PNG still (default the last frame) or a GIF / MP4 animation.
"""

from __future__ import annotations

import sys

from pdsim.cli import main as pdsim_main


def main(argv: list[str] | None = None) -> int:
    return pdsim_main(["preview", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
