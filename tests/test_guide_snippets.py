"""Every Python block of docs/guide.md runs.

The blocks are executed in order in one namespace (later blocks use the scenes and bodies of earlier ones), in a
temporary folder, with ``pdsim.Scene.run`` cut to one frame on the CPU. Afterwards every scene the guide builds and
does not run itself is run for one frame too, except the one it builds to show a FeatureNotAvailableError. A block
preceded by ``<!-- guide:blender -->`` is Blender's Python: it runs in a subprocess when the ``bpy`` module is
installed (``pip install -e ".[blender]"``, or an interpreter with it named by ``PDSIM_BLENDER_PYTHON``) and is
skipped otherwise. Section 8 (a downloaded OBJ to a rendered Blender frame) loads ``suzanne.obj`` from the public test
meshes beside the repository (``../shared/meshes``); its scene runs for SHOT_FRAMES frames, so that the ball has broken
the head when Blender renders the last one. The material table's numbers are checked against pdsim.presets (its
behaviour column is tests/test_guide_materials.py's).
"""

from __future__ import annotations

import importlib.util
import json
import pathlib
import re
import shutil
import subprocess
import textwrap

import numpy as np
import pytest
from PIL import Image
from test_cache_pack import _blender_python

import pdsim
from pdsim import presets

GUIDE = pathlib.Path(__file__).parents[1] / "docs" / "guide.md"
MESHES = pathlib.Path(__file__).parents[2] / "shared" / "meshes"  # the public test meshes beside the repository
FRAMES = 1  # frames each run of the guide is cut to (after the rest pose)
SHOT_FRAMES = 3  # frames of section 8's shot: the ball meets the head in frame 1
SHOT = "head"  # section 8's scene
MARKER = re.compile(r"<!--\s*guide:(\w+)\s*-->")


def _python_blocks() -> list[tuple[int, str, str]]:
    """(line number of the fence, marker name or '', code) of each ```python block of the guide."""
    lines = GUIDE.read_text(encoding="utf-8").splitlines()
    blocks, i = [], 0
    while i < len(lines):
        if lines[i].strip() == "```python":
            start = i
            marker = MARKER.fullmatch(lines[i - 1].strip()) if i > 0 else None
            i += 1
            body = []
            while lines[i].strip() != "```":
                body.append(lines[i])
                i += 1
            blocks.append((start + 1, marker.group(1) if marker else "", "\n".join(body) + "\n"))
        i += 1
    return blocks


def _run_guide(tmp_path, monkeypatch):
    """Executes the guide's blocks (Blender's excepted) in ``tmp_path``; returns (namespace, [(scene, report)])."""
    if not (MESHES / "suzanne.obj").is_file():
        pytest.skip(f"the public test meshes are not at {MESHES} (section 8 loads suzanne.obj from there)")
    shutil.copy(MESHES / "suzanne.obj", tmp_path / "suzanne.obj")
    monkeypatch.chdir(tmp_path)
    runs = []
    real_run = pdsim.Scene.run

    def short_run(self, out, **kwargs):
        kwargs["frames"] = min(kwargs.get("frames") or self.frames, SHOT_FRAMES if self.name == SHOT else FRAMES)
        kwargs["progress"] = False
        kwargs["device"] = "cpu"
        report = real_run(self, out, **kwargs)
        runs.append((self, report))
        return report

    monkeypatch.setattr(pdsim.Scene, "run", short_run)
    namespace = {"__name__": "guide"}
    for line, marker, code in _python_blocks():
        if marker == "blender":
            continue
        try:
            exec(compile(code, f"{GUIDE}:{line}", "exec"), namespace)
        except Exception as exc:
            raise AssertionError(f"docs/guide.md: the python block at line {line} failed: {exc!r}") from exc
    return namespace, runs


@pytest.fixture(scope="module")
def guide(tmp_path_factory):
    """The guide's blocks run once for this module: (folder, namespace, [(scene, report)])."""
    folder = tmp_path_factory.mktemp("guide")
    with pytest.MonkeyPatch.context() as monkeypatch:
        namespace, runs = _run_guide(folder, monkeypatch)
        yield folder, namespace, runs


def test_guide_python_blocks_run(guide):
    """The blocks run; each run wrote its frame (plus the rest pose) into a cache that opens with the bodies'
    prims; then every other scene with bodies runs for one frame. Exactly one scene (the FEM body given a
    peridynamic yield stress, section 2.11) refuses with FeatureNotAvailableError, naming the FEM's own setting."""
    from pxr import Usd

    tmp_path, namespace, runs = guide
    assert len(runs) >= 3, "the guide runs its first scene, the bodies scene and section 8's shot"
    for scene, report in runs:
        frames = SHOT_FRAMES if scene.name == SHOT else FRAMES
        assert report.frames_written == frames + 1
        stage = Usd.Stage.Open(report.path)
        assert stage.GetEndTimeCode() == frames
        for body in scene.bodies:
            assert stage.GetPrimAtPath(f"/World/{body.name}").IsValid(), body.name
    first = next(report for scene, report in runs if scene.name == "first")
    stage = Usd.Stage.Open(first.path)
    assert stage.GetPrimAtPath("/World/pane_surface").IsValid()
    assert stage.GetPrimAtPath("/World/colliders/SphereProjectile_0").IsValid()
    shot = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    assert shot.GetPrimAtPath("/World/pane").IsValid()  # the shot layer sees the cache through its sublayer
    assert (tmp_path / "first_flat.usdc").stat().st_size > 0

    ran = {id(scene) for scene, _ in runs}
    refused = []
    others = [v for v in namespace.values() if isinstance(v, pdsim.Scene) and v.bodies and id(v) not in ran]
    assert others, "the guide builds scenes it does not run (plank, lattice)"
    for scene in others:
        try:
            report = scene.run(tmp_path / f"{scene.name}.usdc")
        except pdsim.FeatureNotAvailableError as exc:
            refused.append((scene.name, str(exc)))
            continue
        assert report.frames_written == FRAMES + 1, scene.name
    assert len(refused) == 1 and refused[0][0] == "fem_only", refused
    assert "FemPlasticity" in refused[0][1]


# Appended to the guide's Blender block: renders the last frame (the ball is through the pane, which has crack faces)
# from above and reports the crack faces Blender reads on that frame and the surface's material slots.
BLENDER_CHECK = """
import json, math, os, mathutils, numpy
scene.frame_set(scene.frame_end)
depsgraph = bpy.context.evaluated_depsgraph_get()
pane = bpy.data.objects["pane_surface"]
attribute = pane.evaluated_get(depsgraph).data.attributes["crack"]
values = numpy.zeros(len(attribute.data), dtype=numpy.int32)
attribute.data.foreach_get("value", values)
crack = {"crack_faces": int(values.sum()), "domain": attribute.domain}  # before the render frees the evaluated mesh
world = bpy.data.worlds.new("sky")
world.node_tree.nodes["Background"].inputs[0].default_value = (0.8, 0.8, 0.8, 1.0)
world.node_tree.nodes["Background"].inputs[1].default_value = 0.3
scene.world = world
sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
sun.data.energy = 2.0
sun.rotation_euler = (math.radians(20), 0.0, 0.0)
scene.collection.objects.link(sun)
camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
scene.collection.objects.link(camera)
scene.camera = camera
camera.location = (0.0, -0.25, 0.95)
camera.rotation_euler = (mathutils.Vector((0.0, 0.0, 0.5)) - camera.location).to_track_quat("-Z", "Y").to_euler()
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = 4
scene.render.resolution_x, scene.render.resolution_y = 128, 96
scene.view_settings.view_transform = "Standard"
scene.render.filepath = os.path.abspath("crack.png")
bpy.ops.render.render(write_still=True)
slots = sorted({slot.material.name for slot in pane.material_slots})
print("CHECK " + json.dumps({**crack, "slots": slots}))
"""


def _orange_pixels(path) -> int:
    """Pixels in the crack faces' orange, counted as tools/make_gallery.py counts them."""
    spec = importlib.util.spec_from_file_location("make_gallery", GUIDE.parents[1] / "tools" / "make_gallery.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.orange_pixels(str(path))


def test_guide_blender_block(tmp_path, monkeypatch):
    """The guide's Blender block imports the guide's first cache in Blender (bpy, in a subprocess: bpy ships its own
    USD libraries) and prints the frame range 0..1 and 24 fps. The crack material works on a frame with cracks with
    no node work: the pane's surface has crack faces on the last frame (the per-face ``crack`` attribute, read on that
    frame), its slots hold the cache's materials pdsim_outer and pdsim_crack, and a small Cycles render of the pane
    shows orange pixels."""
    blender = _blender_python()
    if blender is None:
        pytest.skip(
            'bpy (Blender as a Python module) is not installed: pip install -e ".[blender]", or set '
            "PDSIM_BLENDER_PYTHON to an interpreter that has it"
        )
    blocks = _python_blocks()
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "guide"}
    exec(compile(blocks[0][2], f"{GUIDE}:{blocks[0][0]}", "exec"), namespace)
    namespace["build_scene"]().run("first.usdc", frames=FRAMES, progress=False, device="cpu")
    code = next(code for _, marker, code in blocks if marker == "blender")
    proc = subprocess.run(
        [blender, "-c", code + BLENDER_CHECK],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert re.search(rf"^0 {FRAMES} 24\b", proc.stdout, re.MULTILINE), proc.stdout[-2000:]
    check = json.loads(next(ln for ln in proc.stdout.splitlines() if ln.startswith("CHECK "))[len("CHECK ") :])
    assert check["domain"] == "FACE" and check["crack_faces"] > 0, check
    assert check["slots"] == ["pdsim_crack", "pdsim_outer"], check
    assert _orange_pixels(tmp_path / "crack.png") > 0


def test_guide_obj_to_blender_frame(guide):
    """Section 8: suzanne.obj as downloaded (Y up, quads, open eye parts) loads with one line of repairs, its shot
    breaks the head (crack faces on the last frame of the cache), pdsim's preview writes a still, and the section's
    Blender block, run as it is in Blender's Python, renders the last frame with the crack material on the crack faces
    (pixels of the crack orange) and the outer material elsewhere, and no particle spheres: the particles come in as
    guides (no object renders them)."""
    from pxr import Usd, UsdGeom

    folder, namespace, runs = guide
    assert "welded" in namespace["head"].repairs or "capped" in namespace["head"].repairs
    shot = next(report for scene, report in runs if scene.name == SHOT)
    stage = Usd.Stage.Open(shot.path)
    crack = UsdGeom.Subset(stage.GetPrimAtPath(f"/World/{SHOT}_surface/crack"))
    assert len(crack.GetIndicesAttr().Get(SHOT_FRAMES)) > 0, "the ball breaks the head by the last frame"
    assert UsdGeom.Imageable(stage.GetPrimAtPath(f"/World/{SHOT}")).GetPurposeAttr().Get() == UsdGeom.Tokens.guide
    assert (folder / "head.png").stat().st_size > 0
    blender = _blender_python()
    if blender is None:
        pytest.skip(
            'bpy (Blender as a Python module) is not installed: pip install -e ".[blender]", or set '
            "PDSIM_BLENDER_PYTHON to an interpreter that has it"
        )
    blocks = [code for line, marker, code in _python_blocks() if marker == "blender" and line > _section_line(8)]
    assert len(blocks) == 1
    check = textwrap.dedent(
        """
        print("OBJECTS", sorted((ob.name, ob.type) for ob in bpy.context.scene.objects))
        for ob in scene.objects:  # the head's surface alone, on a transparent film
            ob.hide_render = ob.type != "LIGHT" and ob.name != "head_surface"
        scene.render.film_transparent = True
        scene.render.filepath = os.path.abspath("head_alone.png")
        bpy.ops.render.render(write_still=True)
        """
    )
    proc = subprocess.run(
        [blender, "-c", blocks[0] + check], cwd=folder, capture_output=True, text=True, timeout=600, check=False
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    objects = next(ln for ln in proc.stdout.splitlines() if ln.startswith("OBJECTS"))
    assert "'POINTCLOUD'" not in objects and "head_surface" in objects, objects
    assert (folder / "head_blender.png").stat().st_size > 0
    crack, outer = _head_pixels(folder / "head_alone.png")
    assert 0 < crack < outer, (crack, outer)  # a few shards broken off: most of the head keeps its outer material


def _section_line(number: int) -> int:
    """Line number (1-based) of the guide's heading ``## <number>.``."""
    lines = GUIDE.read_text(encoding="utf-8").splitlines()
    return next(i + 1 for i, ln in enumerate(lines) if ln.startswith(f"## {number}."))


def _head_pixels(path) -> tuple[int, int]:
    """(crack, outer): opaque pixels of a render on a transparent film in the crack material's orange (hue 10-45
    degrees, saturation > 0.4) and in the outer material's grey (saturation < 0.2)."""
    rgba = Image.open(path).convert("RGBA")
    opaque = np.asarray(rgba, dtype=np.float64)[..., 3] > 127
    hsv = np.asarray(rgba.convert("RGB").convert("HSV"), dtype=np.float64) / 255.0
    hue = hsv[..., 0] * 360.0
    crack = opaque & (hue >= 10.0) & (hue <= 45.0) & (hsv[..., 1] > 0.4)
    outer = opaque & (hsv[..., 1] < 0.2)
    return int(crack.sum()), int(outer.sum())


def test_guide_material_table_matches_the_presets():
    """Each row of the guide's material table (section 4.2) names a preset and quotes its density and its animation
    Young's modulus; both equal pdsim.presets' values, and every preset has a row."""
    text = GUIDE.read_text(encoding="utf-8")
    rows = re.findall(r"^\| `(\w+)\((?:grain=\.\.\.)?\)` \| [^|]+ \| (\d+) \| [^|]+ \| ([^|]+) \|", text, re.MULTILINE)
    assert {name for name, _, _ in rows} == set(presets.PRESETS)
    units = {"kPa": 1.0e3, "MPa": 1.0e6, "GPa": 1.0e9}
    for name, density, modulus in rows:
        material = presets.preset(name)
        assert float(density) == material.density, name
        value = re.match(r"([\d.]+) (kPa|MPa|GPa)", modulus.strip())
        if value is None:  # wood: the ratio of its bonds, checked against the anisotropy
            assert f"{material.anisotropy.stiffness_ratio:g}x" in modulus, name
            continue
        assert float(value.group(1)) * units[value.group(2)] == pytest.approx(material.youngs_modulus), name
