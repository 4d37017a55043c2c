"""A soft cantilever clamped at one end, sagging and oscillating under gravity (the default scene of `pdsim run`).

Run:  python scenes/cantilever.py --out cantilever.usdc   or   pdsim run scenes/cantilever.py --out cantilever.usdc
"""

from pdsim.cli import run_script
from pdsim.default_scene import build_scene

PREVIEW = {}  # tools/make_gallery.py and tests/test_gallery.py: the default scene is small enough as it is

if __name__ == "__main__":
    run_script(build_scene)
