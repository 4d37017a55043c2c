"""The teaser at its PREVIEW settings (tools/shot_four_walls_preview.py) with the render surfaces' sliver clean-up
run tile by tile (``FragmentSurfaces(clean_tiles=True)``, pdsim/fragment_surfaces/tiles.py), as a scene script for
``pdsim run``, to compare with the default clean-up:

    pdsim run tools/shot_four_walls_tiles.py --profile --out /tmp/four_walls_tiles.usdc --checkpoint-interval off
"""

from __future__ import annotations

import functools
import importlib.util
from pathlib import Path

import pdsim.fragment_surfaces.surfaces as surfaces

_SPEC = importlib.util.spec_from_file_location(
    "shot_four_walls_preview", Path(__file__).resolve().parent / "shot_four_walls_preview.py"
)
_PREVIEW = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(_PREVIEW)


def build_scene():
    """The preview shot's scene, every FragmentSurfaces made from here on cleaning tile by tile."""
    init = surfaces.FragmentSurfaces.__init__
    if not getattr(init, "tiled", False):

        @functools.wraps(init)
        def tiled(self, *args, **kwargs):
            kwargs.setdefault("clean_tiles", True)
            init(self, *args, **kwargs)

        tiled.tiled = True
        surfaces.FragmentSurfaces.__init__ = tiled
    return _PREVIEW.build_scene()
