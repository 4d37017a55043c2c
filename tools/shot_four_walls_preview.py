"""The teaser (scenes/four_walls.py) at its PREVIEW settings, as a scene script for ``pdsim run``, e.g. to see where
its time goes:

    pdsim run tools/shot_four_walls_preview.py --profile --out /tmp/four_walls.usdc
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

SCENES = Path(__file__).resolve().parents[1] / "scenes"


def build_scene():
    """scenes/four_walls.py's ``build_scene(**PREVIEW)``."""
    if str(SCENES) not in sys.path:
        sys.path.insert(0, str(SCENES))
    spec = importlib.util.spec_from_file_location("four_walls_scene", SCENES / "four_walls.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.build_scene(**module.PREVIEW)
