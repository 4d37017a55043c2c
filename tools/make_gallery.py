"""Builds the gallery: runs every scene of scenes/ at preview resolution, renders a still and an animation of each with
``pdsim preview`` (pdsim.preview.write_preview), a Blender (Cycles) still of the teaser, and writes
docs/gallery.md with the images under docs/gallery/.

A gallery scene is a script in scenes/ that defines ``build_scene()``; its module-level ``PREVIEW`` dict holds the
keyword arguments of ``build_scene`` for the preview resolution (coarser spacing, fewer frames; ``{}``: the scene is
small enough as it is). scenes/lattice_paper.py is the library of the lattice cases, not a scene.

Each scene runs in its own child process (``--run-one``), whose wall time (imports, building, simulating and writing
the cache) is what docs/gallery.md reports, with the simulator's own summary line.

Usage:
    python tools/make_gallery.py                        # every scene, then docs/gallery.md
    python tools/make_gallery.py --scenes glass_pane,drop_shatter --work build/gallery   # some scenes only
    python tools/make_gallery.py --render-only          # re-render from the caches of an earlier run in --work
    python tools/make_gallery.py --blender-only         # only the teaser's Blender still, from its cache in --work

Results of each scene go to ``<work>/<scene>.json``; docs/gallery.md is written from every JSON present in --work,
so partial runs add up.
"""

from __future__ import annotations

import argparse
import datetime
import importlib.util
import json
import math
import os
import platform
import re
import subprocess
import sys
import textwrap
import time

import numpy as np
import warp as wp
from PIL import Image
from pxr import Usd, UsdGeom

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.path.join(ROOT, "scenes")
LIBRARIES = {"lattice_paper"}  # modules of scenes/ that are not scenes
TEASER = "four_walls"
GIF_SIZE = "320x240"
GIF_FRAMES = 48  # at most, evenly spaced
STILL_SIZE = "480x360"

# How each scene is best looked at (options of pdsim.preview.write_preview); "still": the frame of the still
# (default: the last). Scenes not listed get the preview's defaults.
VIEWS: dict[str, dict] = {
    "four_walls": {"fit": "first", "still": 24},
    "glass_pane": {"camera": "-35,15", "fit": "first"},
    "plank_grain": {"camera": "-70,40", "fit": "first"},
    "metal_dent_tear": {"camera": "-60,35", "fit": "first"},
    "drop_shatter": {"camera": "-60,30", "fit": "first"},
    "mixed_methods": {"camera": "-80,20", "still": 6},
    "ductile_bar": {"camera": "-75,20,0.9", "fit": "first"},
    "fem_plastic_bar": {"camera": "-90,10"},
    "lattice_3d_tear": {"camera": "-90,30"},
}
# What the preview run shows that differs from the scene's description (seen on the gallery's own stills).
NOTES: dict[str, str] = {}
# The scenes' full-resolution runs where measured (CPU only, the 2-core development machine, its other core busy with
# other work, no GPU): particles (and tetrahedra), steps per frame, wall time, and the command and date of the
# measurement.
FULL_RUNS: dict[str, str] = {
    "ductile_bar": (
        "2,136 particles, 330 steps per frame, 36 frames: 88 s wall, 449 MB peak memory, `/usr/bin/time -v pdsim run "
        "scenes/ductile_bar.py --out ductile.usdc --quiet`, 2026-12-05, load average 1.8-2.4"
    ),
    "glass_pane": (
        "16,875 particles, 214 steps per frame: 294 s wall, 992 MB peak memory, `/usr/bin/time -v pdsim run "
        "scenes/glass_pane.py --out glass.usdc --quiet`, 2026-12-05, load average 1.2-2.1 (1,111 s on 2026-12-02, "
        "when the fragments' surface rebuilds took most of it)"
    ),
    "plank_grain": (
        "6,400 particles, 96 steps per frame: 50 s wall, 627 MB peak memory, `/usr/bin/time -v pdsim run "
        "scenes/plank_grain.py --out plank.usdc --quiet`, 2026-12-05, load average 2.4-3.1"
    ),
    "metal_dent_tear": (
        "4,800 particles, 49 steps per frame: 34 s wall, 545 MB peak memory, `/usr/bin/time -v pdsim run "
        "scenes/metal_dent_tear.py --out metal.usdc --quiet`, 2026-12-05, load average 1.6-2.3"
    ),
    "drop_shatter": (
        "2,396 particles, 302 steps per frame: 80 s wall, 487 MB peak memory, `/usr/bin/time -v pdsim run "
        "scenes/drop_shatter.py --out drop.usdc --quiet`, 2026-12-05 08:57 UTC, load average 0.9 (with its cells; "
        "before them 72 s and 530 MB, load average 0.6-1.6)"
    ),
    "mixed_methods": (
        "1,045 particles and 11,520 tetrahedra, 198 steps per frame: 54 s wall, 504 MB peak memory, `/usr/bin/time -v "
        "pdsim run scenes/mixed_methods.py --out mixed.usdc --quiet`, 2026-12-05, load average 2.3-3.1"
    ),
}

for _case in "abcdefg":  # plane lattices: seen from above, coloured by the first-gradient strain measure
    VIEWS[f"lattice_case_{_case}"] = {"camera": "-90,75", "color": "pe1", "no_ground": True}


ORDER = [  # the gallery's order (the teaser first); scenes not listed follow in alphabetical order
    "four_walls",
    "ductile_bar",
    "glass_pane",
    "plank_grain",
    "metal_dent_tear",
    "drop_shatter",
    "fem_slab_crack",
    "fem_plastic_bar",
    "mixed_methods",
    "lattice_3d_tear",
]


def gallery_scenes() -> list[str]:
    """Names of the scene scripts in scenes/ that define build_scene, in the gallery's ORDER."""
    names = []
    for f in sorted(os.listdir(SCENES)):
        name, ext = os.path.splitext(f)
        if ext != ".py" or name in LIBRARIES or name.startswith("_"):
            continue
        with open(os.path.join(SCENES, f), encoding="utf-8") as fh:
            text = fh.read()
        if "build_scene" in text:
            names.append(name)
    return sorted(names, key=lambda n: (ORDER.index(n) if n in ORDER else len(ORDER), n))


def load_scene_module(name: str):
    """Imports scenes/<name>.py (with scenes/ on sys.path, as when the script runs on its own)."""
    if SCENES not in sys.path:
        sys.path.insert(0, SCENES)
    spec = importlib.util.spec_from_file_location(f"gallery_{name}", os.path.join(SCENES, f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run_one(name: str, out: str, frames: int | None) -> dict:
    """Runs scene ``name`` at preview resolution into ``out`` (in this process); returns what the run did."""
    wp.config.quiet = True
    t0 = time.perf_counter()
    module = load_scene_module(name)
    preview = dict(getattr(module, "PREVIEW", {}))
    scene = module.build_scene(**preview)
    report = scene.run(out, device="cpu", progress=False, frames=frames)
    return {
        "scene": name,
        "preview": preview,
        "frames": report.frames_written - 1,
        "summary": report.summary,
        "dt": report.dt,
        "substeps": report.substeps_per_frame,
        "run_seconds": report.wall_seconds,
        "process_seconds": time.perf_counter() - t0,
    }


def _child(name: str, out: str) -> dict:
    """Runs a scene in a child process and returns its result plus the child's wall time."""
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, os.path.abspath(__file__), "--run-one", name, "--cache", out],
        capture_output=True,
        text=True,
        check=False,
        cwd=ROOT,
    )
    wall = time.perf_counter() - t0
    line = next((ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")), None)
    if proc.returncode != 0 or line is None:
        tail = (proc.stdout + proc.stderr).strip().splitlines()[-5:]
        return {"scene": name, "error": " | ".join(tail) or f"exit status {proc.returncode}", "wall_seconds": wall}
    result = json.loads(line[len("RESULT ") :])
    result["wall_seconds"] = wall
    return result


def render(name: str, cache: str, images: str, result: dict) -> dict:
    """Still (PNG) and animation (GIF) of a cache; returns their file names and render times."""
    from pdsim.preview import write_preview

    view = dict(VIEWS.get(name, {}))
    still_frame = view.pop("still", None)
    options = {
        "camera": view.get("camera"),
        "color": view.get("color"),
        "fit": view.get("fit", "all"),
        "ground": not view.get("no_ground", False),
    }
    frames = int(result["frames"])
    out = {}
    t0 = time.perf_counter()
    still = f"{name}.png"
    spec = str(min(still_frame, frames)) if still_frame is not None else str(frames)
    write_preview(cache, os.path.join(images, still), spec, size=STILL_SIZE, supersample=2, **options)
    out["still"] = still
    step = max(1, math.ceil((frames + 1) / GIF_FRAMES))
    anim = f"{name}.gif"
    write_preview(cache, os.path.join(images, anim), f"0:{frames + 1}:{step}", size=GIF_SIZE, **options)
    out["animation"] = anim
    out["animation_frames"] = len(range(0, frames + 1, step))
    out["render_seconds"] = time.perf_counter() - t0
    return out


BLENDER = textwrap.dedent(
    """
    import math, sys
    import bpy
    import numpy

    path, frame, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.usd_import(filepath=path)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 32
    scene.render.resolution_x, scene.render.resolution_y = 800, 450
    scene.render.film_transparent = False
    world = bpy.data.worlds.new("sky")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs[0].default_value = (0.85, 0.88, 0.92, 1.0)
    world.node_tree.nodes["Background"].inputs[1].default_value = 0.6
    scene.world = world
    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    sun.data.energy = 3.0
    sun.rotation_euler = (math.radians(40), 0.0, math.radians(-30))
    scene.collection.objects.link(sun)
    # no node work: the cache's own materials (pdsim_outer, pdsim_crack) through its per-face material_index, and its
    # particles as guides, not rendered (docs/cache_format.md)
    scene.frame_set(frame)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    cracked = 0
    for ob in scene.objects:
        crack = ob.evaluated_get(depsgraph).data.attributes.get("crack") if ob.type == "MESH" else None
        if crack is not None:
            values = numpy.zeros(len(crack.data), dtype=numpy.int32)
            crack.data.foreach_get("value", values)
            cracked += int(values.sum())
    print("CRACK FACES", cracked, flush=True)
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(camera)
    scene.camera = camera
    camera.location = (float(sys.argv[4]), float(sys.argv[5]), float(sys.argv[6]))
    target = (float(sys.argv[7]), float(sys.argv[8]), float(sys.argv[9]))
    import mathutils
    direction = mathutils.Vector(target) - camera.location
    camera.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    camera.data.lens = 35
    scene.render.filepath = out
    bpy.ops.render.render(write_still=True)
    print("RENDERED", flush=True)
    """
)


def orange_pixels(path: str) -> int:
    """Number of pixels of a PNG in the crack faces' orange (hue 10-45 degrees, saturation > 0.4, value > 0.25)."""
    hsv = np.asarray(Image.open(path).convert("RGB").convert("HSV"), dtype=np.float64) / 255.0
    hue = hsv[..., 0] * 360.0
    return int(np.count_nonzero((hue >= 10.0) & (hue <= 45.0) & (hsv[..., 1] > 0.4) & (hsv[..., 2] > 0.25)))


def blender_python() -> str:
    """The interpreter with bpy: $PDSIM_BLENDER_PYTHON (Blender's module pins its own numpy, so it often lives in a
    venv of its own), else this one."""
    return os.environ.get("PDSIM_BLENDER_PYTHON") or sys.executable


def blender_still(cache: str, frame: int, out: str) -> dict:
    """Cycles still of ``frame`` of the cache (bpy in a child process, away from usd-core's pxr); returns its render
    time, the number of crack faces on that frame and the number of orange pixels of the image. A frame with crack
    faces and no orange pixel is an error: the crack shading did not reach the render."""
    stage = Usd.Stage.Open(cache)
    box = UsdGeom.BBoxCache(0, [UsdGeom.Tokens.default_]).ComputeWorldBound(stage.GetPseudoRoot()).ComputeAlignedRange()
    lo, hi = box.GetMin(), box.GetMax()
    centre = [0.5 * (lo[i] + hi[i]) for i in range(3)]
    extent = max(hi[i] - lo[i] for i in range(3))
    eye = [centre[0] - 0.7 * extent, centre[1] - 1.4 * extent, centre[2] + 0.6 * extent]
    t0 = time.perf_counter()
    proc = subprocess.run(
        [blender_python(), "-c", BLENDER, cache, str(frame), out, *map(str, eye), *map(str, centre)],
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode != 0 or "RENDERED" not in proc.stdout:
        raise RuntimeError("Blender render failed: " + (proc.stdout + proc.stderr)[-2000:])
    seconds = time.perf_counter() - t0
    line = next(ln for ln in proc.stdout.splitlines() if ln.startswith("CRACK FACES "))
    crack_faces = int(line.split()[-1])
    orange = orange_pixels(out)
    if crack_faces and not orange:
        raise RuntimeError(f"Blender still {out}: frame {frame} has {crack_faces} crack faces but no orange pixel")
    return {"blender_seconds": seconds, "blender_crack_faces": crack_faces, "blender_orange_pixels": orange}


def _doc(module) -> tuple[str, str]:
    """(first paragraph, the rest) of a scene's docstring, the rest without its Run: paragraph."""
    doc = (module.__doc__ or "").strip()
    parts = [p.strip() for p in doc.split("\n\n") if p.strip()]
    first = " ".join(parts[0].split()) if parts else ""
    rest = [p for p in parts[1:] if not p.startswith("Run:")]
    return first, "\n\n".join(" ".join(p.split()) for p in rest)


def write_markdown(work: str, images: str, path: str) -> None:
    """docs/gallery.md from the per-scene JSON results in ``work``."""
    rel = os.path.relpath(images, os.path.dirname(path))
    lines = [
        "# Gallery",
        "",
        "Every scene of `scenes/` at preview resolution (each scene's `PREVIEW` keyword arguments of `build_scene`),",
        "generated by `python tools/make_gallery.py` (a still and an animation per scene through `pdsim preview`,",
        "plus a Blender Cycles still of the teaser). Run times are the wall time of the scene's own process (imports,",
        "building, simulating and writing the cache) on the CPU of the development machine, measured while the run was",
        "made; the full-resolution times are listed with each scene where measured.",
        "",
    ]
    machine = None
    for name in gallery_scenes():
        jpath = os.path.join(work, f"{name}.json")
        if not os.path.isfile(jpath):
            continue
        with open(jpath, encoding="utf-8") as fh:
            r = json.load(fh)
        r["machine"] = _machine_record(r.get("machine"))
        machine = machine or r["machine"]
        module = load_scene_module(name)
        first, rest = _doc(module)
        lines += [f"## {name}", "", first, ""]
        if rest:
            lines += [rest, ""]
        if name in NOTES:
            lines += [f"*Preview:* {NOTES[name]}", ""]
        preview = ", ".join(f"{k}={v!r}" for k, v in r.get("preview", {}).items())
        if "error" in r:
            lines += [f"**The preview run failed**: `{r['error']}`", ""]
            continue
        steps = "" if "lattice" in r["summary"] else f", {r['substeps']} steps per frame of {r['dt']:.3g} s"
        lines += [f"- run: `python scenes/{name}.py` (full resolution); the gallery ran `build_scene({preview})`"]
        if name in FULL_RUNS:
            lines += [f"- full-resolution run: {FULL_RUNS[name]}"]
        lines += [
            f"- preview run: {r['frames']} frames, {r['summary']}{steps}; **{r['wall_seconds']:.0f} s** wall time "
            f"({r['run_seconds']:.0f} s in `Scene.run`; {r['machine']['date']}, load average {r['machine']['load']})",
            "",
            f"![{name}, frame {min(VIEWS.get(name, {}).get('still', r['frames']), r['frames'])}]({rel}/{r['still']})",
            "",
            f"Animation: [{r['animation']}]({rel}/{r['animation']}) ({r['animation_frames']} frames, {GIF_SIZE})",
            "",
        ]
        if r.get("blender"):
            crack = ""
            if "blender_crack_faces" in r:
                crack = (
                    f"; imported with no node work: the crack faces in the cache's `pdsim_crack` through its per-face "
                    "`material_index`, the particles as guides, not rendered: "
                    f"{r['blender_crack_faces']:,} crack faces on this frame, {r['blender_orange_pixels']:,} orange "
                    "pixels"
                )
            lines += [
                f"Blender (Cycles, 32 samples, frame {r['blender_frame']}, {r['blender_seconds']:.0f} s{crack}):",
                "",
                f"![{name} in Blender]({rel}/{r['blender']})",
                "",
            ]
    if machine:
        lines.insert(8, f"Machine: {machine['cpu']}, shared with other work (the load average of each run is given).")
        lines.insert(9, "")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines))


def _machine_record(value) -> dict:
    """The machine record of a result (results of the first version of this tool hold it as one sentence)."""
    if isinstance(value, dict):
        return value
    text = str(value or "")
    load = re.search(r"load average ([0-9., ]+?) when", text)
    date = re.search(r"\((\d{4}-\d\d-\d\d \d\d:\d\d UTC)\)", text)
    return {
        "cpu": text.split(", no GPU")[0] + ", Warp on the CPU (no GPU)",
        "load": load.group(1) if load else "?",
        "date": date.group(1) if date else "?",
    }


def _machine() -> dict:
    return {
        "cpu": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Warp on the CPU (no GPU)",
        "load": ", ".join(f"{x:.1f}" for x in os.getloadavg()),
        "date": f"{datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC",
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--scenes", help="comma-separated scene names (default: every scene)")
    p.add_argument("--work", default=os.path.join(ROOT, "build", "gallery"), help="caches and per-scene results")
    p.add_argument("--images", default=os.path.join(ROOT, "docs", "gallery"), help="folder of the stills and GIFs")
    p.add_argument("--markdown", default=os.path.join(ROOT, "docs", "gallery.md"), help="the page to write")
    p.add_argument("--render-only", action="store_true", help="render the caches of an earlier run")
    p.add_argument("--no-blender", action="store_true", help="skip the Blender still of the teaser")
    p.add_argument("--blender-only", action="store_true", help="only the teaser's Blender still, from its cache")
    p.add_argument("--run-one", metavar="SCENE", help=argparse.SUPPRESS)
    p.add_argument("--cache", help=argparse.SUPPRESS)
    p.add_argument("--frames", type=int, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.run_one:
        print("RESULT " + json.dumps(run_one(args.run_one, args.cache, args.frames)), flush=True)
        return 0
    os.makedirs(args.work, exist_ok=True)
    os.makedirs(args.images, exist_ok=True)
    names = gallery_scenes()
    if args.scenes:
        wanted = [s.strip() for s in args.scenes.split(",") if s.strip()]
        unknown = sorted(set(wanted) - set(names))
        if unknown:
            p.error(f"unknown scenes {unknown}; the gallery scenes are {names}")
        names = wanted
    if args.blender_only:
        names, args.render_only, args.no_blender = [TEASER], True, False
    failed = []
    for name in names:
        cache = os.path.join(args.work, f"{name}.usdc")
        jpath = os.path.join(args.work, f"{name}.json")
        if args.render_only:
            with open(jpath, encoding="utf-8") as fh:
                result = json.load(fh)
        else:
            print(f"gallery: running {name} ...", flush=True)
            result = _child(name, cache)
            result["machine"] = _machine()
        if "error" not in result:
            if not args.blender_only:
                result.update(render(name, cache, args.images, result))
            if name == TEASER and not args.no_blender:
                frame = min(VIEWS.get(name, {}).get("still", result["frames"]), result["frames"])
                out = os.path.join(args.images, f"{name}_blender.png")
                result.update(blender_still(cache, frame, out))
                result["blender"], result["blender_frame"] = os.path.basename(out), frame
            print(
                f"gallery: {name}: {result['wall_seconds']:.1f} s run, {result['render_seconds']:.1f} s render",
                flush=True,
            )
        else:
            failed.append(name)
            print(f"gallery: {name} FAILED: {result['error']}", flush=True)
        with open(jpath, "w", encoding="utf-8") as fh:
            json.dump(result, fh, indent=1)
    write_markdown(args.work, args.images, args.markdown)
    print(f"gallery: wrote {args.markdown}" + (f"; failed: {', '.join(failed)}" if failed else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
