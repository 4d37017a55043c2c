"""Preview renderer: stills (PNG) and animations (GIF, MP4) of any USD cache, ray cast on the CPU with Warp.

The cache is read like a renderer reads it, through ``pxr.Usd.Stage.Open`` (so sublayers, references and value clips
resolve as USD resolves them): every visible ``UsdGeom.Mesh`` (polygons fan-triangulated, each frame's points and
that frame's topology, world transforms applied, authored normals for shading) and ``UsdGeom.Points`` prims, drawn as
spheres of their widths (instanced icospheres with exact sphere normals). By default a body's points ``<b>`` are left
out when its surface ``<b>_surface`` or render mesh ``<b>_render`` (a Mesh or an Xform of fragment meshes) is beside
them, and a visible ``<b>_render`` stands for ``<b>_surface`` (the prim names of docs/cache_format.md; other stages
draw every prim). Guide and proxy prims are skipped; a flat ground quad is replaced by the preview's ground plane.

Shading: Lambert + hemispherical ambient from a key light above and to the left of the camera and a weak fill light,
shadow rays (self-shadowing and shadows on a ground plane at the lowest point of the geometry over all frames, which
shows only the shadows and fades into the background). Colours: ``displayColor`` (linear RGB) where authored, else a
neutral material with the faces whose ``crack`` primvar is 1 (or that lie in a ``crack`` GeomSubset) in a contrasting
interior colour. ``color=ATTR`` colours every prim that carries the primvar ATTR (constant, uniform, vertex, varying
or faceVarying; a vector by its length): floats through a colour ramp over the value range of the rendered frames,
integers (fragment ids, kinds) by a categorical palette. A body's surface, fragment or render mesh without ATTR takes
it from the body's Points prim (the value of the nearest point of each vertex), so ``color="damage"`` shows a
peridynamic body's damage on its surface.

The camera is a pinhole with a 35 degree vertical field of view. By default it looks at the centre of the bounding box
of the bodies over all frames (colliders and projectiles, the prims under /World/colliders, left out), as far as half
the rest pose's largest extent past the rest pose (far-flung debris leaves the picture), from a
three-quarter view (azimuth -60 degrees about the stage's up axis, elevation 25
degrees), at the distance that fits that box into the image; see :func:`camera_from_spec` for the other choices.

Modules: ``camera`` (camera and ``--camera`` specs), ``options`` (size and frame selection), ``colors`` (ramp,
palette, base colours), ``reader`` (the stage's renderable prims and each frame's geometry), ``render`` (the BVH, the
ray-cast launch, :func:`render_cache` and :func:`write_preview`).

Library use::

    from pdsim.preview import render_cache, write_preview

    result = render_cache("cache.usdc", frames=[3], size=(640, 480))   # images as uint8 [H, W, 3]
    write_preview("cache.usdc", "cache.gif")                          # every frame, animated

Errors in the inputs raise :class:`pdsim.ParameterError` naming the field and what is allowed; nothing is written
then (the output file is written to a temporary name and renamed when complete).
"""

from .camera import Camera, camera_from_spec
from .options import SUFFIXES, parse_frames, parse_size
from .render import PreviewResult, render_cache, write_preview

__all__ = [
    "SUFFIXES",
    "Camera",
    "PreviewResult",
    "camera_from_spec",
    "parse_frames",
    "parse_size",
    "render_cache",
    "write_preview",
]
