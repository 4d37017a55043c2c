"""A real consumer of the caches: Blender (the ``bpy`` module) imports a small cache of each method with
``bpy.ops.wm.usd_import``, renders a fracturing frame with Cycles and motion blur, and renders a gallery scene's
fracturing frame with the crack material on the crack faces and no particle spheres.

Needs ``pip install -e ".[blender]"`` (bpy: about 370 MB to download, 820 MB installed, and it pins numpy 1.26), so it
is not in the ``test`` extra; Blender may also live in a venv of its own, named by ``PDSIM_BLENDER_PYTHON``; without
any interpreter that has bpy every test here is skipped. Blender runs in subprocesses: bpy ships its own USD
libraries, which are kept out of the process that has usd-core's pxr loaded.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import textwrap
from pathlib import Path

import pytest
from test_cache_pack import _blender_python
from test_cache_schema import _collider_scene, _fem_scene, _lattice_scene, _pd_scene

BLENDER_PYTHON = _blender_python()  # $PDSIM_BLENDER_PYTHON or this interpreter, with bpy

pytestmark = pytest.mark.skipif(
    BLENDER_PYTHON is None,
    reason='bpy (Blender as a Python module) is not installed: pip install -e ".[blender]", or set '
    "PDSIM_BLENDER_PYTHON to an interpreter that has it",
)

FRAMES = 4
ROOT = Path(__file__).resolve().parents[1]

IMPORT = textwrap.dedent(
    """
    import json, sys
    import bpy

    result = {}
    for path in sys.argv[1:]:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        assert bpy.ops.wm.usd_import(filepath=path, import_guide=True) == {"FINISHED"}  # the particles are guides
        scene = bpy.context.scene
        info = {"range": [scene.frame_start, scene.frame_end], "fps": scene.render.fps / scene.render.fps_base}
        objects = {}
        for frame in range(scene.frame_start, scene.frame_end + 1):
            scene.frame_set(frame)
            depsgraph = bpy.context.evaluated_depsgraph_get()
            for ob in scene.objects:
                if ob.type not in ("MESH", "POINTCLOUD"):
                    continue
                data = ob.evaluated_get(depsgraph).data
                entry = objects.setdefault(ob.name, {"type": ob.type, "counts": [], "attributes": [], "location": []})
                entry["counts"].append(len(data.vertices) if ob.type == "MESH" else len(data.points))
                entry["attributes"] = sorted(a.name for a in data.attributes)
                entry["location"].append(list(ob.evaluated_get(depsgraph).matrix_world.translation))
                if ob.type == "MESH":
                    entry["custom_normals"] = bool(data.has_custom_normals)
        info["objects"] = objects
        result[path] = info
    print("RESULT " + json.dumps(result))
    """
)

RENDER = textwrap.dedent(
    """
    import sys
    import bpy

    path, frame = sys.argv[1], int(sys.argv[2])
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.usd_import(filepath=path)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 1
    scene.render.resolution_x = scene.render.resolution_y = 16
    scene.render.use_motion_blur = True
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(camera)
    scene.camera = camera
    camera.location = (0.3, -0.3, 0.2)
    camera.rotation_euler = (1.2, 0.0, 0.8)
    scene.frame_set(frame)
    scene.render.filepath = sys.argv[3]
    bpy.ops.render.render(write_still=True)
    print("RENDERED", flush=True)
    """
)


def _blender(script: str, *args, timeout=300) -> str:
    proc = subprocess.run(
        [BLENDER_PYTHON, "-c", script, *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout + proc.stderr


def _usd_counts(path) -> dict:
    """{prim name: [point count per frame]} of the Points and Mesh prims of a cache, read with usd-core."""
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(path))
    out = {}
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Points) or prim.IsA(UsdGeom.Mesh):
            attr = UsdGeom.PointBased(prim).GetPointsAttr()
            out[prim.GetName()] = [len(attr.Get(f)) for f in range(int(stage.GetEndTimeCode()) + 1)]
    return out


@pytest.fixture(scope="module")
def blender_caches(tmp_path_factory):
    folder = tmp_path_factory.mktemp("blender")
    paths = {}
    for name, build in (("pd", _pd_scene), ("fem", _fem_scene), ("lattice", _lattice_scene), ("hit", _collider_scene)):
        scene = build()
        scene.frames = FRAMES if name != "lattice" else 2
        paths[name] = folder / f"{name}.usdc"
        scene.run(paths[name], device="cpu", progress=False)
    return paths


def test_blender_imports_each_method(blender_caches):
    """Blender's USD importer reads each cache: frame range 0..end and fps 24 from the stage; one object per Points
    and Mesh prim, with the point count of every frame equal to the cache's (the fracturing peridynamic surface gains
    vertices); the velocity attribute on every mesh and point cloud; meshes use the cache's normals (custom normals);
    projectiles move (their transforms follow the cache)."""
    paths = list(blender_caches.values())
    out = _blender(IMPORT, *paths)
    result = json.loads(next(ln for ln in out.splitlines() if ln.startswith("RESULT "))[len("RESULT ") :])
    for name, path in blender_caches.items():
        info = result[str(path)]
        counts = _usd_counts(path)
        end = len(next(iter(counts.values()))) - 1
        assert info["range"] == [0, end], name
        assert info["fps"] == 24.0
        objects = info["objects"]
        assert set(counts) <= set(objects), (name, set(counts) - set(objects))
        for prim, per_frame in counts.items():
            assert objects[prim]["counts"] == per_frame, (name, prim)
            assert "velocity" in objects[prim]["attributes"], (name, prim)
            if objects[prim]["type"] == "MESH":
                assert objects[prim]["custom_normals"], (name, prim)
    pd_surface = result[str(blender_caches["pd"])]["objects"]["block_surface"]["counts"]
    assert len(set(pd_surface)) > 1, "the peridynamic block did not fracture: nothing shows topology changes"
    sphere = result[str(blender_caches["hit"])]["objects"]["SphereProjectile_0"]["location"]
    assert sphere[0][2] - sphere[-1][2] == pytest.approx(FRAMES / 24.0, rel=1e-5)


def _first_topology_change(path) -> int:
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    samples = stage.GetPrimAtPath("/World/block_surface").GetAttribute("faceVertexIndices").GetTimeSamples()
    return int(samples[1])


def test_cycles_motion_blur_across_fracture(blender_caches, tmp_path, monkeypatch):
    """Cycles renders the frame where the peridynamic block first breaks (its surface changes topology between the
    motion-blur steps) with motion blur and without "Topology differs, disabling motion blur": the cached vertex
    velocities drive the blur. Control: the same scene cached without surface velocities makes Cycles print that
    line, so the log is really captured."""
    from pdsim.output import writer as output_writer

    path = blender_caches["pd"]
    frame = _first_topology_change(path)
    assert 0 < frame <= FRAMES
    log = _blender(RENDER, path, frame, tmp_path / "blur.png")
    assert "RENDERED" in log
    assert "Topology differs" not in log, log[-2000:]
    assert (tmp_path / "blur.png").stat().st_size > 0

    real = output_writer.ViewWriter._velocities
    monkeypatch.setattr(
        output_writer.ViewWriter, "_write_whole_mesh", _without_velocities(output_writer.ViewWriter._write_whole_mesh)
    )
    control = tmp_path / "control.usdc"
    scene = _pd_scene()
    scene.frames = frame
    scene.run(control, device="cpu", progress=False)
    monkeypatch.setattr(output_writer.ViewWriter, "_velocities", real)
    log = _blender(RENDER, control, frame, tmp_path / "control.png")
    assert "Topology differs, disabling motion blur" in log


def _without_velocities(write):
    def write_without(self, frame, view, *args, **kwargs):
        view.velocities = None
        return write(self, frame, view, *args, **kwargs)

    return write_without


def test_blender_gets_crack_faces_per_frame(blender_caches):
    """The crack material reaches Blender's playback with no node work: the surface's material slots are pdsim_outer
    and pdsim_crack in that order, and on every frame (frame_set, then the evaluated mesh) the faces' material
    indices are the cache's material_index: as many faces with index 1 as the cache's crack subset holds at that
    frame, none at frame 0 and some at the last (so they change during playback); the per-face ``crack`` attribute
    (domain FACE) agrees."""
    from pxr import Usd, UsdGeom

    script = textwrap.dedent(
        """
        import json, sys
        import bpy

        bpy.ops.wm.read_factory_settings(use_empty=True)
        bpy.ops.wm.usd_import(filepath=sys.argv[1])
        scene = bpy.context.scene
        ob = bpy.data.objects["block_surface"]
        frames = []
        for frame in range(scene.frame_start, scene.frame_end + 1):
            scene.frame_set(frame)
            mesh = ob.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
            index = [p.material_index for p in mesh.polygons]
            crack = [v.value for v in mesh.attributes["crack"].data]
            frames.append({"faces": len(index), "index": sum(index), "crack": sum(crack),
                           "domain": mesh.attributes["crack"].domain})
        slots = [slot.material.name if slot.material else None for slot in ob.material_slots]
        print("CRACK " + json.dumps({"frames": frames, "slots": slots}))
        """
    )
    path = blender_caches["pd"]
    out = _blender(script, path)
    info = json.loads(next(ln for ln in out.splitlines() if ln.startswith("CRACK "))[len("CRACK ") :])
    assert info["slots"] == ["pdsim_outer", "pdsim_crack"]
    stage = Usd.Stage.Open(str(path))
    subset = UsdGeom.Subset(stage.GetPrimAtPath("/World/block_surface/crack")).GetIndicesAttr()
    counts = stage.GetPrimAtPath("/World/block_surface").GetAttribute("faceVertexCounts")
    for frame, got in enumerate(info["frames"]):
        assert got["domain"] == "FACE" and got["faces"] == len(counts.Get(frame)), frame
        assert got["index"] == got["crack"] == len(subset.Get(frame)), frame
    assert info["frames"][0]["index"] == 0 < info["frames"][-1]["index"]


def _tool():
    spec = importlib.util.spec_from_file_location("blender_cracks", ROOT / "tools" / "blender_cracks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_gallery_fracture_renders_with_the_crack_material(tmp_path):
    """The gallery's tile drop (scenes/drop_shatter.py at its preview spacing, 2 cm, frames 0..5 of 24, with crack
    events) imported with bpy.ops.wm.usd_import and rendered with Cycles (CPU, 96 x 72, 4 samples, the ground hidden,
    orthographic camera on the tile's bounds at frame 5): at frame 5, where the tile has cracked, pixels of the crack
    colour (> 20) on the crack faces and the grey outer material on most of the tile (> 50 % of the opaque pixels);
    at frame 0 (no crack yet) no pixel of the crack colour, so the classification does not mistake the outer
    material for it. No point spheres: the particle prim /World/tile and the crack events are guides that Blender
    leaves out (they are there, as point clouds, when guides are imported). Imported with the guides, the crack
    events drive the Geometry Nodes dust of docs/cache_format.md: one grain per event at frames 0 and 5, the events'
    radius 0, and frame 0, without events, renders."""
    from pxr import Usd, UsdGeom

    tool = _tool()  # tools/blender_cracks.py: the same at a larger size for docs/blender_cracks.png
    path, lo, hi = tool.tile_cache(tmp_path)
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.Imageable(stage.GetPrimAtPath("/World/tile")).ComputePurpose() == UsdGeom.Tokens.guide
    info = tool.render(BLENDER_PYTHON, path, tmp_path / "render", lo, hi, size=(96, 72), samples=4)
    assert info["slots"] == ["pdsim_outer", "pdsim_crack"]
    assert not {"tile", "tile_crack_events"} & set(info["objects"])
    assert info["with_guides"].get("tile") == info["with_guides"].get("tile_crack_events") == "POINTCLOUD"
    events = UsdGeom.Points(stage.GetPrimAtPath("/World/tile_crack_events")).GetPointsAttr()
    for frame in (0, 5):
        dust = info["dust"][str(frame)]
        assert dust["grains"] == dust["events"] == len(events.Get(frame)), (frame, dust)
        assert dust["radius"] == 0.0
    assert info["dust"]["5"]["grains"] > 0
    before, after = (tool.pixel_classes(info["renders"][str(f)]) for f in (0, 5))
    assert before["crack"] == 0 and before["grey"] > 0.9 * before["opaque"], before
    assert after["crack"] > 20 and after["grey"] > 0.5 * after["opaque"], after
