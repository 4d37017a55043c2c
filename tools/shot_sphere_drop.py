"""The brittle presets' sphere drop of tools/preview_final.py (a 30 cm sphere falling onto the ground at 6 m/s, 2 cm
spacing) as a scene script, run for a whole shot instead of the 40 ms the pattern figures take: ``frames`` frames at
24 fps, long enough for the pieces to land, tumble and come to rest. E.g. the rigid hand-off on a shot whose pieces
are all free (docs/fracture.md, "Rigid hand-off"):

    python tools/rigid_handoff.py --scenes tools/shot_sphere_drop.py
    pdsim run tools/shot_sphere_drop.py --out /tmp/sphere_drop.usdc
"""

from __future__ import annotations

import dataclasses
import os
import sys

import pdsim

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import preview_final  # tools/

PREVIEW = {"frames": 48}


def build_scene(
    frames: int = 48,
    preset: str = "glass",
    spacing: float = preview_final.PREVIEW_SPACING,
    retardation_time: float | None = None,
) -> pdsim.Scene:
    """The drop: the preset ``preset`` (pdsim.presets) at particle ``spacing`` [m], ``frames`` frames at 24 fps;
    ``retardation_time`` [s]: the material's internal damping over the preset's (Material.retardation_time)."""
    material = pdsim.presets.preset(preset)
    if retardation_time is not None:
        material = dataclasses.replace(material, retardation_time=retardation_time)
    return preview_final.build_case("drop", material, spacing, frames=frames, duration=frames / 24.0)
