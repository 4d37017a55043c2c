"""The crack material in Blender: the gallery's tile drop (scenes/drop_shatter.py at its preview spacing, frames
0..5 of 24, with crack events) imported with ``bpy.ops.wm.usd_import`` and rendered with Cycles on the CPU at frame 0
(no crack yet) and frame 5 (cracked), with no node work: the cache's materials pdsim_outer and pdsim_crack and its
per-face material_index. Counts the pixels of the crack colour and of the outer grey, and the Geometry Nodes dust
grains of docs/cache_format.md ("Crack events").

    PDSIM_BLENDER_PYTHON=/path/to/python-with-bpy python tools/blender_cracks.py [--size 320x240] [--samples 16]

writes docs/blender_cracks.png (frame 5) and docs/data/blender_cracks.txt (the counts, the machine and the date).
tests/test_cache_blender.py runs the same at 96 x 72 pixels and 4 samples.
"""

from __future__ import annotations

import argparse
import datetime
import importlib.util
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
FRAME = 5  # the rendered frame of the tile drop at its preview settings: cracked, pieces still together

RENDER = textwrap.dedent(
    """
    import json, sys
    import bpy
    from mathutils import Vector

    path, out = sys.argv[1], sys.argv[2]
    lo, hi = Vector(json.loads(sys.argv[3])), Vector(json.loads(sys.argv[4]))
    width, height, samples = int(sys.argv[5]), int(sys.argv[6]), int(sys.argv[7])
    info = {"renders": {}}
    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert bpy.ops.wm.usd_import(filepath=path) == {"FINISHED"}
    scene = bpy.context.scene
    info["objects"] = {ob.name: ob.type for ob in scene.objects}
    ob = bpy.data.objects["tile_surface"]
    info["slots"] = [slot.material.name if slot.material else None for slot in ob.material_slots]
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.film_transparent = True
    centre, size = (lo + hi) / 2, (hi - lo).length
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    camera.data.type = "ORTHO"
    camera.data.ortho_scale = 1.1 * size
    scene.collection.objects.link(camera)
    scene.camera = camera
    camera.location = centre + Vector((0.6, -0.8, 1.0)).normalized() * 2.0 * size
    camera.rotation_euler = (centre - camera.location).to_track_quat("-Z", "Y").to_euler()
    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    sun.data.energy = 4.0
    sun.rotation_euler = camera.rotation_euler
    scene.collection.objects.link(sun)
    bpy.data.objects["ground"].hide_render = True  # every opaque pixel is then the tile's (or a point's)
    for frame in (0, scene.frame_end):
        scene.frame_set(frame)
        scene.render.filepath = f"{out}.{frame}.png"
        bpy.ops.render.render(write_still=True)
        info["renders"][frame] = scene.render.filepath
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.usd_import(filepath=path, import_guide=True)
    scene = bpy.context.scene
    info["with_guides"] = {ob.name: ob.type for ob in scene.objects}
    # docs/cache_format.md, "Crack events": dust on the events with Geometry Nodes
    events = bpy.data.objects["tile_crack_events"]
    events.hide_render = True  # markers only (an empty point cloud must not reach Cycles)
    bpy.data.objects["tile"].hide_render = True  # the particles, imported with the guides
    dust = bpy.data.objects.new("dust", bpy.data.meshes.new("dust"))
    scene.collection.objects.link(dust)
    tree = bpy.data.node_groups.new("dust", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    source = tree.nodes.new("GeometryNodeObjectInfo")
    source.inputs["Object"].default_value = events
    source.transform_space = "RELATIVE"
    grain = tree.nodes.new("GeometryNodeMeshIcoSphere")
    grain.inputs["Radius"].default_value = 0.002
    scatter = tree.nodes.new("GeometryNodeInstanceOnPoints")
    output = tree.nodes.new("NodeGroupOutput")
    tree.links.new(source.outputs["Geometry"], scatter.inputs["Points"])
    tree.links.new(grain.outputs["Mesh"], scatter.inputs["Instance"])
    tree.links.new(scatter.outputs["Instances"], output.inputs[0])
    dust.modifiers.new("dust", "NODES").node_group = tree
    info["dust"] = {}
    for frame in (0, scene.frame_end):
        scene.frame_set(frame)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        grains = [i for i in depsgraph.object_instances if i.is_instance and i.parent and i.parent.name == "dust"]
        cloud = events.evaluated_get(depsgraph).data
        radius = [r.value for r in cloud.attributes["radius"].data] if "radius" in cloud.attributes else []
        info["dust"][frame] = {"grains": len(grains), "events": len(cloud.points), "radius": max(radius, default=0)}
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 1
    scene.render.resolution_x, scene.render.resolution_y = 16, 16
    scene.camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(scene.camera)
    scene.frame_set(0)  # no event yet: renders (an empty point cloud of events would crash Cycles 5.0.1)
    scene.render.filepath = f"{out}.dust.png"
    bpy.ops.render.render(write_still=True)
    print("RENDER " + json.dumps(info))
    """
)


def pixel_classes(png) -> dict:
    """Counts of the opaque pixels of a render: crack colour (saturated, red the largest and blue the smallest
    channel: the orange of pdsim_crack lit white), grey (saturation under 0.12: pdsim_outer) and all opaque ones."""
    px = np.asarray(Image.open(png).convert("RGBA"), dtype=np.float64).reshape(-1, 4) / 255.0
    opaque = px[:, 3] > 0.5
    rgb = px[:, :3]
    hi, lo = rgb.max(axis=1), rgb.min(axis=1)
    saturation = (hi - lo) / np.maximum(hi, 1e-6)
    crack = opaque & (saturation > 0.35) & (rgb[:, 0] == hi) & (rgb[:, 2] == lo)
    grey = opaque & (saturation < 0.12)
    return {"opaque": int(opaque.sum()), "crack": int(crack.sum()), "grey": int(grey.sum())}


def tile_cache(folder) -> tuple[Path, list, list]:
    """The tile drop's cache (preview settings, frames 0..FRAME, crack events) in ``folder``, and the world bounds
    [m] (lo, hi) of its surface at FRAME."""
    from pxr import Usd, UsdGeom

    spec = importlib.util.spec_from_file_location("gallery_drop_shatter", ROOT / "scenes" / "drop_shatter.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    path = Path(folder) / "drop_shatter.usdc"
    module.build_scene(**module.PREVIEW).run(path, frames=FRAME, device="cpu", progress=False, crack_events=True)
    stage = Usd.Stage.Open(str(path))
    box = UsdGeom.BBoxCache(FRAME, [UsdGeom.Tokens.default_]).ComputeWorldBound(
        stage.GetPrimAtPath("/World/tile_surface")
    )
    r = box.ComputeAlignedRange()
    return path, list(r.GetMin()), list(r.GetMax())


def render(exe: str, path, out, lo, hi, *, size=(96, 72), samples=4, timeout=600) -> dict:
    """Runs RENDER in the interpreter ``exe`` (one with bpy; a subprocess: bpy ships its own USD libraries); returns
    what it reports (objects, slots, render paths per frame, dust per frame). AssertionError with its output when it
    fails."""
    args = [exe, "-c", RENDER, str(path), str(out), json.dumps(lo), json.dumps(hi), *map(str, (*size, samples))]
    proc = subprocess.run(args, capture_output=True, text=True, timeout=timeout, check=False)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    line = next(ln for ln in proc.stdout.splitlines() if ln.startswith("RENDER "))
    return json.loads(line[len("RENDER ") :])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--size", default="320x240", help="image size WxH (default 320x240)")
    p.add_argument("--samples", type=int, default=16, help="Cycles samples (default 16)")
    p.add_argument("--out", default=str(ROOT / "docs" / "blender_cracks.png"), help="the still of frame 5")
    p.add_argument("--table", default=str(ROOT / "docs" / "data" / "blender_cracks.txt"), help="the counts")
    args = p.parse_args(argv)
    exe = os.environ.get("PDSIM_BLENDER_PYTHON") or sys.executable
    size = tuple(int(v) for v in args.size.lower().split("x"))
    with tempfile.TemporaryDirectory() as work:
        path, lo, hi = tile_cache(work)
        info = render(exe, path, Path(work) / "render", lo, hi, size=size, samples=args.samples)
        counts = {frame: pixel_classes(info["renders"][str(frame)]) for frame in (0, FRAME)}
        shutil.copy(info["renders"][str(FRAME)], args.out)
    when = f"{datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC"
    lines = [
        f"# python tools/blender_cracks.py --size {args.size} --samples {args.samples}",
        f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cores, {when}",
        f"# material slots of tile_surface: {info['slots']}; imported objects: {sorted(info['objects'])}",
        "frame  opaque_pixels  crack_colour_pixels  outer_grey_pixels  crack_events  dust_grains",
    ]
    for frame in (0, FRAME):
        c, d = counts[frame], info["dust"][str(frame)]
        lines.append(
            f"{frame:5d}  {c['opaque']:13d}  {c['crack']:19d}  {c['grey']:17d}  {d['events']:12d}  {d['grains']:11d}"
        )
    Path(args.table).write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
