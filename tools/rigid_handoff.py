"""Measures the rigid hand-off (pdsim/peridynamics/handoff.py) on the teaser's brittle walls (scenes/four_walls.py)
and the glass pane (scenes/glass_pane.py) at their preview settings: each scene runs twice, with the hand-off off
and on (``RigidHandoff(fixed=True)``, with ``--in-flight`` also ``in_flight=True``: the defaults with static
fragments, on every peridynamic body whose material
breaks and does not yield), on one CPU thread. It reports the share of broken-out particles (those outside their
body's largest fragment) that are in rigid fragments at the last frame, the process CPU time per frame over the last
third of the run (``advance_frame`` alone, then the whole frame with the hand-off's frame-end test and the output;
CPU time rather than wall time, as the machine is shared), and renders ``pdsim preview`` stills of the last frame
of both runs side by side. Writes docs/rigid_handoff.md and docs/rigid_handoff/*.png.

Run:  python tools/rigid_handoff.py [--scenes four_walls glass_pane] [--frames N] [--page NAME.md] [--in-flight]
          [--options KEY=VALUE ...]   (build_scene keywords over the preview's, e.g. frames=64 duration=0.016)
"""

from __future__ import annotations

import argparse
import datetime
import importlib.util
import os
import platform
import sys
import tempfile
import time

import numpy as np
import warp as wp
from scipy.spatial import cKDTree

import pdsim
import pdsim.run as pdrun
from pdsim.peridynamics import PeridynamicBody, RigidHandoff, SolverPeridynamics

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.path.join(ROOT, "scenes")
DOCS = os.path.join(ROOT, "docs")
VIEWS = {
    "four_walls": {"fit": "first"},
    "glass_pane": {"camera": "-35,15", "fit": "first"},
    "drop_shatter": {"camera": "-60,30", "fit": "first"},
    "shot_sphere_drop": {"camera": "-60,30"},
}


SCENE_OPTIONS = {}  # build_scene keywords over each scene's PREVIEW (--options)
HANDOFF = {"fixed": True}  # the RigidHandoff of the runs with the hand-off on (--in-flight adds in_flight=True)


def set_handoff(scene, on: bool) -> None:
    """The brittle bodies of ``scene`` with the hand-off on (RigidHandoff(**HANDOFF)) or off, whatever their
    material's default (the presets' is on)."""
    for b in scene.bodies:
        if brittle(b):
            b.rigid_handoff = RigidHandoff(**HANDOFF) if on else None


def preview_settings(module) -> dict:
    """The scene's PREVIEW keywords with SCENE_OPTIONS over them."""
    return {**dict(getattr(module, "PREVIEW", {})), **SCENE_OPTIONS}


SCRIPTS = {}  # scene scripts given by path (--scenes path/to/script.py): their name -> path


def load_scene_module(name: str):
    """Imports scenes/<name>.py (with scenes/ on sys.path), or the scene script registered as ``name`` in SCRIPTS."""
    if SCENES not in sys.path:
        sys.path.insert(0, SCENES)
    path = SCRIPTS.get(name, os.path.join(SCENES, f"{name}.py"))
    spec = importlib.util.spec_from_file_location(f"handoff_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def brittle(body) -> bool:
    return isinstance(body, PeridynamicBody) and body.material.breaks and not body.material.yields


def broken_out(solver) -> np.ndarray:
    """bool per particle of the solver: in a brittle body, outside the body's largest fragment."""
    labels = solver.fragment_ids()
    out = np.zeros(solver.particle_count, dtype=bool)
    for i, b in enumerate(solver.bodies):
        if not brittle(b):
            continue
        sl = solver.body_slice(i)
        ids, counts = np.unique(labels[sl], return_counts=True)
        out[sl] = labels[sl] != ids[np.argmax(counts)]
    return out


def pieces(solver) -> list:
    """(particles, centre of mass [m]) of each fragment of at least 5 particles of the solver's brittle bodies,
    largest first."""
    labels, x, mass = solver.fragment_ids(), solver.positions(), solver.masses()
    out = []
    for i, b in enumerate(solver.bodies):
        if not brittle(b):
            continue
        sl = solver.body_slice(i)
        _, inverse, counts = np.unique(labels[sl], return_inverse=True, return_counts=True)
        m = np.bincount(inverse, weights=mass[sl])
        centre = np.stack([np.bincount(inverse, weights=mass[sl] * x[sl][:, d]) for d in range(3)], axis=1)
        keep = counts >= 5
        out += list(zip(counts[keep].tolist(), centre[keep] / m[keep, None]))
    return sorted(out, key=lambda p: -p[0])


def piece_shift(off: list, on: list) -> str:
    """Table cells: the pieces of both runs (:func:`pieces` at the last frame) and, where their sizes are the same,
    the median and largest distance between the centres of the pieces paired by size [m]."""
    count = f"{len(off)} / {len(on)}"
    if [c for c, _ in off] != [c for c, _ in on]:
        return f"{count} (sizes differ) | - |"
    d = np.array([np.linalg.norm(a - b) for (_, a), (_, b) in zip(off, on)])
    return f"{count} | {np.median(d):.3f} / {d.max(initial=0.0):.3f} |"


def run(name: str, handoff: bool, cache: str, frames: int | None) -> dict:
    """One preview run of scene ``name``; per frame: stepping and frame CPU times [s], broken-out and rigid counts;
    the pieces at the last frame (:func:`pieces`)."""
    module = load_scene_module(name)
    scene = module.build_scene(**preview_settings(module))
    set_handoff(scene, handoff)
    steps, frame_ends, rows, last = [], [], [], []
    original = pdrun.advance_frame

    def timed(*args, **kwargs):
        t0 = time.process_time()
        original(*args, **kwargs)
        steps.append(time.process_time() - t0)

    def on_frame(frame, solvers):
        frame_ends.append(time.process_time())
        for s in solvers:
            if isinstance(s, SolverPeridynamics):
                out = broken_out(s)
                rigid = s.handoff.rigid_particles() if s.handoff is not None else np.zeros_like(out)
                rows_visited = s.handoff.live_bond_rows() if s.handoff is not None else s.bond_count
                rows.append(
                    (frame, int(out.sum()), int((out & rigid).sum()), int(rigid.sum()), rows_visited, s.particle_count)
                )
                last[:] = pieces(s)

    os.environ["PDSIM_THREADS"] = "1"
    pdrun.advance_frame = timed
    try:
        t0 = time.process_time()
        report = scene.run(cache, device="cpu", progress=False, frames=frames, on_frame=on_frame)
    finally:
        pdrun.advance_frame = original
    frame_times = np.diff([t0, *frame_ends])
    total_bonds = report.bond_count
    return {
        "report": report, "steps": np.asarray(steps), "frames": frame_times, "rows": rows, "bonds": total_bonds,
        "pieces": last,
    }  # fmt: skip


def interleaved(name: str, cache: str, frames: int | None, rounds: int = 7, steps: int = 40) -> dict:
    """The step cost at the last frame of a hand-off run, against the same state without the hand-off: the run's
    peridynamic solver (rigid fragments live) and a solver of the scene without the hand-off given its checkpoint,
    ``steps`` steps each, alternated over ``rounds`` rounds; medians of the process CPU time per step [s]."""
    held = {}

    def keep(frame, solvers):
        held["solvers"] = solvers

    module = load_scene_module(name)
    preview = preview_settings(module)
    scene = module.build_scene(**preview)
    set_handoff(scene, True)
    report = scene.run(cache, device="cpu", progress=False, frames=frames, on_frame=keep)
    on = next(s for s in held["solvers"] if isinstance(s, SolverPeridynamics))
    plain = module.build_scene(**preview)
    set_handoff(plain, False)
    plain = plain.build_solvers(device="cpu", check=False)
    off = next(s for s in plain if isinstance(s, SolverPeridynamics))
    off.threads = on.threads = 1
    off.restore(on.checkpoint())
    on.watchdog = on.kin.watchdog = None  # the run attached one; the solver built here has none
    times = {"on": [], "off": []}
    for _ in range(rounds):
        for key, solver in (("on", on), ("off", off)):
            t0 = time.process_time()
            solver.simulate(report.dt, steps)
            times[key].append((time.process_time() - t0) / steps)
    out = {k: float(np.median(v)) for k, v in times.items()}
    out["rows"] = on.handoff.live_bond_rows() / max(on.bond_count, 1)
    return out


def strains(name: str, cache: str, frames: int | None) -> list[str]:
    """A preview run of scene ``name`` with the hand-off on; per frame and brittle body, the equivalent strain eps of
    its deformable fragments (FragmentHandoff.fragment_strains): the largest (the clamped remainder) against the
    threshold, and the broken-out ones (all others): how many, their particles, single particles, those above the
    threshold and their largest eps, those holding constrained particles, and the particles already rigid. Returns
    the table's rows."""
    module = load_scene_module(name)
    scene = module.build_scene(**preview_settings(module))
    set_handoff(scene, True)
    rows = []

    def on_frame(frame, solvers):
        for s in solvers:
            if not isinstance(s, SolverPeridynamics) or s.handoff is None:
                continue
            f = s.handoff.fragment_strains()
            rigid = s.handoff.rigid_particles()
            x = s.positions()
            tree = cKDTree(x)
            for i, b in enumerate(s.bodies):
                mine = np.flatnonzero(f["body"] == i)
                if not brittle(b):
                    continue
                held = mine[f["constrained"][mine] > 0]
                top = held[np.argmax(f["size"][held])] if len(held) else -1
                out = mine[mine != top]
                loud = out[f["eps"][out] >= f["threshold"][out]]
                touching = 0  # loud fragments with a particle within one spacing of another fragment's particle
                for g in loud:  # a loop over a few fragments
                    mine_p = np.flatnonzero(f["labels"] == f["ids"][g])
                    near = tree.query_ball_point(x[mine_p], r=b.spacing)
                    others = np.concatenate([np.asarray(n, dtype=np.int64) for n in near])
                    touching += bool(np.any(f["labels"][others] != f["ids"][g]))
                if top >= 0:
                    eps, limit = f["eps"][top], f["threshold"][top]
                    share = f["kinetic"][top] / max(f["kinetic"][top] + f["elastic"][top], 1e-300)
                    remainder = f"{f['size'][top]} | {eps:.2e} | {limit:.1e} | {eps / limit:.2f} | {100 * share:.0f} %"
                elif (s.kin.point_condition_host[s.body_slice(i)] >= 0).any():  # the remainder is a static fragment
                    remainder = "asleep | - | - | - | -"
                else:  # no particle of the body is held: every fragment is free
                    remainder = "none | - | - | - | -"
                loud_energy = f["kinetic"][loud].sum() + f["elastic"][loud].sum()
                loud_kinetic = f"{100 * f['kinetic'][loud].sum() / loud_energy:.0f} %" if loud_energy > 0 else "-"
                strained = out[
                    (f["eps"][out] < f["threshold"][out]) & (f["elastic_strain"][out] >= f["threshold"][out])
                ]
                moving = out[(f["eps"][out] < f["threshold"][out]) & (f["impact_strain"][out] >= f["threshold"][out])]
                rows.append(
                    f"| {name} | {frame} | {b.name} | {remainder} | {len(out)} | {int(f['size'][out].sum())} |"
                    f" {int((f['size'][out] == 1).sum())} | {len(loud)} ({int(f['size'][loud].sum())} particles) |"
                    f" {loud_kinetic} | {touching} |"
                    f" {f['eps'][out].max(initial=0.0):.2e} | {int((f['constrained'][out] > 0).sum())} |"
                    f" {int(rigid[s.body_slice(i)].sum())} |"
                    f" {len(strained)} ({int(f['size'][strained].sum())} particles) |"
                    f" {f['elastic_strain'][strained].max(initial=0.0):.2e} |"
                    f" {len(moving)} ({int(f['size'][moving].sum())} particles) |"
                )
                print(rows[-1], flush=True)

    os.environ["PDSIM_THREADS"] = "1"
    scene.run(cache, device="cpu", progress=False, frames=frames, on_frame=on_frame)
    return rows


TILES = 4  # the scaling slab is cut into TILES x TILES tiles


def tiled_slab(handoff: bool, spacing: float = 0.01) -> pdsim.Scene:
    """The scaling case: a free glass slab (0.24 m x 0.24 m x 0.03 m, the glass pane's material and break pattern,
    particle contact on as for any breakable body) cut by notches into TILES x TILES tiles, in space (no gravity, no
    ground); with ``handoff``, ``RigidHandoff(strain=1e-5, frames=1, in_flight=True)`` (the tiles drift)."""
    size, thick = 0.24, 0.03
    scene = pdsim.Scene(fps=24, frames=1, frame_time=1.0e-4, gravity=(0.0, 0.0, 0.0), name="tiled_slab")
    glass = pdsim.Material(
        density=2500.0, youngs_modulus=72.0e9, poisson_ratio=0.22, critical_stretch=1.0e-3,
        compressive_bonus=1.0, compressive_bonus_cap=3.0, debris_damping=2.5e4, name="glass",
    )  # fmt: skip
    body = scene.add_peridynamic_body(
        pdsim.box((size, size, thick), center=(0.0, 0.0, 0.0), name="slab"), glass, spacing,
        rigid_handoff=RigidHandoff(strain=1.0e-5, frames=1, in_flight=True) if handoff else False,
    )  # fmt: skip
    for i in range(1, TILES):
        c = -0.5 * size + i * size / TILES
        body.add_notch(pdsim.BoxRegion(lo=(c - 1e-4, -1.0, -1.0), hi=(c + 1e-4, 1.0, 1.0)))
        body.add_notch(pdsim.BoxRegion(lo=(-1.0, c - 1e-4, -1.0), hi=(1.0, c + 1e-4, 1.0)))
    return scene


def scaling(rounds: int = 5, steps: int = 40) -> list[dict]:
    """The step cost against the rigid share: the tiled slab (``tiled_slab``) with its tiles drifting apart and
    spinning; for r = 0 .. TILES^2 in steps of TILES, r tiles are quiet and the others vibrate (a random velocity of
    0.2 m/s per component and particle, an equivalent strain of about 6e-5, above the threshold 1e-5), the
    hand-off's frame-end test makes the r quiet tiles rigid, then the solver and one without the hand-off from the
    same state step ``steps`` steps each in turn over ``rounds`` rounds (one thread, process CPU time, medians)."""
    rows = []
    for rigid_tiles in range(0, TILES * TILES + 1, TILES):
        on = tiled_slab(True).build_solvers(device="cpu", check=False)[0]
        off = tiled_slab(False).build_solvers(device="cpu", check=False)[0]
        x = on.positions()
        cell = np.clip(((x[:, :2] + 0.12) / (0.24 / TILES)).astype(int), 0, TILES - 1)
        tile = cell[:, 0] * TILES + cell[:, 1]
        centre = (cell + 0.5) * (0.24 / TILES) - 0.12
        rng = np.random.default_rng(5)
        order = rng.permutation(TILES * TILES)
        quiet = np.isin(tile, order[:rigid_tiles])
        v = np.zeros_like(x)
        v[:, :2] = 0.5 * centre  # drifting apart at 0.5 / s (a few cm/s)
        v += np.cross([0.0, 0.0, 20.0], np.c_[x[:, :2] - centre, np.zeros(len(x))])  # each tile spinning
        v[~quiet] += 0.2 * rng.standard_normal((int((~quiet).sum()), 3))
        on.set_velocities(v)
        handed = on.handoff.update()
        if handed != rigid_tiles:
            raise RuntimeError(f"{handed} tiles handed off, {rigid_tiles} expected")
        off.restore(on.checkpoint())
        off.threads = on.threads = 1
        dt = 0.5 * off.stable_time_step()
        times = {"on": [], "off": []}
        for _ in range(rounds):
            for key, solver in (("on", on), ("off", off)):
                t0 = time.process_time()
                solver.simulate(dt, steps)
                times[key].append((time.process_time() - t0) / steps)
        row = {k: float(np.median(t)) for k, t in times.items()}
        row["rigid"] = float(on.handoff.rigid_particles().mean())
        row["rows"] = on.handoff.live_bond_rows() / on.bond_count
        row["particles"], row["bonds"] = on.particle_count, on.bond_count
        rows.append(row)
        print(row, flush=True)
    return rows


def last_third(values: np.ndarray) -> float:
    n = len(values)
    return float(np.mean(values[n - n // 3 :])) if n >= 3 else float(np.mean(values))


def pixel_difference(path_a: str, path_b: str, level: int = 25) -> float:
    """Share of the pixels of two same-size PNGs whose largest channel difference exceeds ``level`` (of 255)."""
    from PIL import Image

    a, b = (np.asarray(Image.open(p).convert("RGB"), dtype=np.int16) for p in (path_a, path_b))
    return float((np.abs(a - b).max(axis=2) > level).mean())


def stills(name: str, stem: str, caches: dict, frame: int, folder: str) -> str:
    """Preview stills of ``frame`` of both runs of scene ``name``, side by side (left: off, right: on),
    ``stem``_off.png, ``stem``_on.png and ``stem``_off_on.png; returns the last one's name. Both take the camera of
    the first (the scene's VIEWS, fitted to the run with the hand-off off), so that the runs' own extents do not move
    the picture."""
    from PIL import Image

    from pdsim.preview import write_preview

    paths, view = [], dict(VIEWS.get(name, {}))
    for mode, cache in caches.items():
        path = os.path.join(folder, f"{stem}_{mode}.png")
        camera = write_preview(cache, path, str(frame), size=(480, 360), supersample=2, **view).camera
        view = {
            "camera": "eye={}:target={}".format(
                *(",".join(repr(float(x)) for x in v) for v in (camera.eye, camera.target))
            )
        }
        paths.append(path)
    a, b = (Image.open(p).convert("RGB") for p in paths)
    both = Image.new("RGB", (a.width + b.width, max(a.height, b.height)), "white")
    both.paste(a, (0, 0))
    both.paste(b, (a.width, 0))
    out = f"{stem}_off_on.png"
    both.save(os.path.join(folder, out))
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--scenes", nargs="+", default=["glass_pane", "four_walls"], help="gallery scenes, or scene scripts (.py)"
    )
    parser.add_argument("--frames", type=int, default=None, help="frames to run (default: the preview's)")
    parser.add_argument("--page", default=None, help="the page written in docs/ (default: the mode's)")
    parser.add_argument(
        "--difference", action="store_true", help="only compare the stills already in docs/rigid_handoff/"
    )
    parser.add_argument(
        "--interleaved",
        action="store_true",
        help="only the step cost at the last frame with and without the hand-off, alternated (printed)",
    )
    parser.add_argument(
        "--scaling",
        action="store_true",
        help="only the step cost against the rigid share on a slab cut into tiles (docs/rigid_handoff_scaling.md)",
    )
    parser.add_argument(
        "--strains",
        action="store_true",
        help="only the equivalent strain of each brittle body's fragments per frame (docs/rigid_handoff_strains.md)",
    )
    parser.add_argument(
        "--options", nargs="+", default=[], help="build_scene keywords over the preview's, as KEY=VALUE (numbers)"
    )
    parser.add_argument(
        "--in-flight", action="store_true", help="hand off pieces in flight too (RigidHandoff(in_flight=True))"
    )
    args = parser.parse_args(argv)
    shown = " ".join(args.scenes)  # as given, for the pages' commands
    for k, scene in enumerate(args.scenes):  # a script's path: its file name stands for it in the pages and stills
        if scene.endswith(".py"):
            args.scenes[k] = os.path.splitext(os.path.basename(scene))[0]
            SCRIPTS[args.scenes[k]] = os.path.abspath(scene)
    for item in args.options:
        key, _, value = item.partition("=")
        SCENE_OPTIONS[key] = int(value) if value.lstrip("-").isdigit() else float(value)
    options = f" --options {' '.join(args.options)}" if args.options else ""
    if args.in_flight:
        HANDOFF["in_flight"] = True
        options += " --in-flight"
    setting = "RigidHandoff(fixed=True" + (", in_flight=True)" if args.in_flight else ")")
    if args.strains:
        wp.config.quiet = True
        when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        lines = [
            "# Rigid hand-off: the fragments' equivalent strain by frame",
            "",
            f"`python tools/rigid_handoff.py --strains --scenes {shown}"
            + (f" --page {args.page}" if args.page else "")
            + f"{options}` on {when}"
            f" ({platform.machine()}, Warp {wp.__version__} CPU): each scene at its preview settings (with the"
            " options) and the hand-off"
            f" on (`{setting}` on its brittle bodies); at the end of each frame, for each brittle body,"
            " the equivalent strain eps = sqrt(4 K_int / (M c_p^2)) of its deformable fragments' vibration"
            " (pdsim/peridynamics/handoff.py) against the threshold (DEFAULT_STRAIN_FRACTION x s_c). Remainder: the"
            " body's deformable fragment that holds the clamped rim (its eps counts its whole kinetic energy; asleep: a"
            " static fragment; none: the body holds no particle, every fragment is free; kinetic: the kinetic energy's"
            " share of its kinetic and elastic energy, the rest elastic, which eps does not count);"
            " broken-out: its other deformable fragments; loud: those at or above the threshold (their kinetic: the"
            " kinetic share of their kinetic and elastic energy; touching: with a particle within one spacing of"
            " another fragment's); constrained: those holding particles under a"
            " boundary condition; rigid: the body's particles in rigid fragments; quiet but strained: broken-out"
            " fragments below the threshold whose elastic energy alone, as sqrt(2 E_el / (M c_p^2)), is at or above it"
            " (the test counted it before 2026-12-05 and kept them deformable), and the largest such strain;"
            " quiet but moving: broken-out fragments below the threshold whose fastest point moves at or above"
            " threshold x c_p (the settling test keeps them deformable; 0 with --in-flight).",
            "",
            "| scene | frame | body | remainder particles | remainder eps | threshold | eps / threshold | kinetic |"
            " broken-out fragments | their particles | single particles | loud | loud: kinetic | loud touching |"
            " largest eps | constrained | rigid particles | quiet but strained | their largest elastic strain |"
            " quiet but moving |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        with tempfile.TemporaryDirectory() as tmp:
            for name in args.scenes:
                lines += strains(name, os.path.join(tmp, f"{name}.usdc"), args.frames)
                with open(os.path.join(DOCS, args.page or "rigid_handoff_strains.md"), "w") as f:
                    f.write("\n".join(lines) + "\n")
        return
    if args.scaling:
        wp.config.quiet = True
        os.environ["PDSIM_THREADS"] = "1"
        rows = scaling()
        when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
        lines = [
            "# Rigid hand-off: the step cost against the rigid share",
            "",
            f"`python tools/rigid_handoff.py --scaling` on {when} ({platform.machine()}, {os.cpu_count()} cores, Warp"
            f" {wp.__version__} CPU, one bond thread, load average {load} at the end): a free glass slab of"
            f" {rows[0]['particles']} particles and {rows[0]['bonds']} bonds (0.24 m x 0.24 m x 0.03 m at 1 cm, the"
            f" glass pane's material, particle contact on) cut into {TILES * TILES} tiles, drifting apart and spinning"
            " in space; some tiles quiet and handed off, the others vibrating; then 40 steps with the hand-off and"
            " 40 without from the same state, in turn, 5 rounds; medians of the process CPU time per step"
            " (`rigid_handoff.py: scaling`). Bound: one over the share of the bond rows still visited (the bond"
            " passes' speed-up; the step also holds contact, the kick-drift and the hand-off's projection).",
            "",
            "| rigid particles | bond rows visited | without [ms/step] | with the hand-off [ms/step] | speed-up |"
            " bond-pass bound |",
            "|---|---|---|---|---|---|",
        ]
        for r in rows:
            bound = f"{1.0 / r['rows']:.2f}x" if r["rows"] > 0 else "-"
            lines.append(
                f"| {100 * r['rigid']:.0f} % | {100 * r['rows']:.0f} % | {1e3 * r['off']:.3f} | {1e3 * r['on']:.3f} |"
                f" {r['off'] / r['on']:.2f}x | {bound} |"
            )
        with open(os.path.join(DOCS, "rigid_handoff_scaling.md"), "w") as f:
            f.write("\n".join(lines) + "\n")
        print("\n".join(lines))
        return
    if args.interleaved:
        wp.config.quiet = True
        os.environ["PDSIM_THREADS"] = "1"
        when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        lines = [
            "# Rigid hand-off: the step cost at the last frame",
            "",
            f"`python tools/rigid_handoff.py --interleaved --scenes {shown}"
            + (f" --page {args.page}" if args.page else "")
            + f"{options}` on {when}"
            f" ({platform.machine()}, {os.cpu_count()} cores, Warp {wp.__version__} CPU, one bond thread): each scene"
            " at its preview settings runs with the hand-off on to its last frame; then its peridynamic solver and a"
            " solver of the same scene without the hand-off, given the first one's checkpoint, step 40 steps each in"
            " turn, 7 rounds; medians of the process CPU time per step.",
            "",
            "| scene | without [ms/step] | with the hand-off [ms/step] | speed-up | bond rows visited |",
            "|---|---|---|---|---|",
        ]
        with tempfile.TemporaryDirectory() as tmp:
            for name in args.scenes:
                t = interleaved(name, os.path.join(tmp, f"{name}.usdc"), args.frames)
                lines.append(
                    f"| {name} | {1e3 * t['off']:.3f} | {1e3 * t['on']:.3f} | {t['off'] / t['on']:.2f}x |"
                    f" {100 * t['rows']:.0f} % |"
                )
                print(lines[-1], flush=True)
        with open(os.path.join(DOCS, args.page or "rigid_handoff_steps.md"), "w") as f:
            f.write("\n".join(lines) + "\n")
        return
    if args.difference:
        for name in args.scenes:
            off, on = (os.path.join(DOCS, "rigid_handoff", f"{name}_{m}.png") for m in ("off", "on"))
            print(f"{name}: {100 * pixel_difference(off, on):.2f} % of the pixels differ by more than 25/255")
        return
    wp.config.quiet = True
    folder = os.path.join(DOCS, "rigid_handoff")
    os.makedirs(folder, exist_ok=True)
    rows, pictures = [], []

    def write() -> None:
        """docs/rigid_handoff.md with the scenes measured so far."""
        when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        machine = f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Warp {wp.__version__} CPU"
        load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
        lines = [
            "# Rigid hand-off: measured",
            "",
            f"`python tools/rigid_handoff.py --scenes {shown}"
            + (f" --page {args.page}" if args.page else "")
            + (f" --frames {args.frames}" if args.frames else "")
            + f"{options}`"
            + f" on {when} ({machine}, one bond thread, load average {load} at the end; the machine is shared, so"
            " the times are the process's CPU time, not wall time). Each scene at its preview settings (with the"
            f" options), with the hand-off off and on (`{setting}`: the defaults with static fragments"
            + (" and pieces handed off in flight" if args.in_flight else "")
            + ", on the bodies whose material breaks and does not yield). Broken-out: particles of those bodies outside"
            " their body's largest fragment. Step: CPU time of a frame's steps (`advance_frame`); frame: with the"
            " frame-end hand-off test and the output. Times are means over the last third of the frames.",
            "",
            "| scene | frames | particles | broken-out (off / on) | in rigid fragments (on) | bond rows visited (on) |"
            " step off [s] | step on [s] | step speed-up | frame off [s] | frame on [s] | frame speed-up |"
            " pixels differing | pieces (off / on) | their centres apart: median / largest [m] |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
            *rows,
            "",
            "Bond rows visited: the share of the bonds the dilatation and force passes still visit at the last frame"
            " (the rest belong to rigid or static fragments); one over it bounds the speed-up of those passes, and"
            " the step also holds particle contact, the kick-drift, colliders and the ground for every particle."
            " Where the broken-out particles are a few per cent of the scene's, no hand-off of them alone can make"
            " the step much faster (docs/rigid_handoff_scaling.md measures the step against the rigid share): the"
            " rest is the clamped remainder, which sleeps as a static fragment only once its equivalent strain has"
            " stayed below the threshold for 3 frames (docs/rigid_handoff_strains.md measures it by frame). Pixels"
            " differing: the share of the stills' pixels whose largest channel differs by more than 25/255. Pieces:"
            " the brittle bodies' fragments of at least 5 particles at the last frame, in both runs; where their sizes"
            " are the same, the distances between the centres of mass of the pieces paired by size (largest first),"
            " which the stills show only within the picture.",
            "",
            "Rigid / broken-out particles by frame (hand-off on), and in brackets all particles in rigid or static"
            " fragments:",
        ]
        for name, png, value in pictures:
            if png is None:
                lines.append(f"- {name}: {value}")
        lines += ["", "Preview stills of the last frame, hand-off off (left) and on (right):", ""]
        for name, png, frame in pictures:
            if png is not None:
                lines += [f"- {name}, frame {frame}:", "", f"  ![{name}](rigid_handoff/{png})", ""]
        with open(os.path.join(DOCS, args.page or "rigid_handoff.md"), "w") as f:
            f.write("\n".join(lines) + "\n")
        print("\n".join(lines), flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        for name in args.scenes:
            results, caches = {}, {}
            for mode in ("off", "on"):
                caches[mode] = os.path.join(tmp, f"{name}_{mode}.usdc")
                results[mode] = run(name, mode == "on", caches[mode], args.frames)
                print(name, mode, f"{results[mode]['report'].wall_seconds:.1f} s", flush=True)
            off, on = results["off"], results["on"]
            last = on["rows"][-1]
            share = last[2] / last[1] if last[1] else float("nan")
            s_off, s_on = last_third(off["steps"]), last_third(on["steps"])
            f_off, f_on = last_third(off["frames"]), last_third(on["frames"])
            frames = on["report"].frames_written - 1
            stem = name if args.page is None else f"{name}_{os.path.splitext(os.path.basename(args.page))[0]}"
            png = stills(name, stem, caches, frames, folder)
            diff = pixel_difference(*(os.path.join(folder, f"{stem}_{m}.png") for m in ("off", "on")))
            rows.append(
                f"| {name} | {frames} | {last[5]} | {off['rows'][-1][1]} / {last[1]} | {last[2]} ({100 * share:.0f} %)"
                f" | {100 * last[4] / on['bonds']:.0f} % |"
                f" {s_off:.3f} | {s_on:.3f} | {s_off / s_on:.2f}x | {f_off:.3f} | {f_on:.3f} | {f_off / f_on:.2f}x |"
                f" {100 * diff:.2f} % | {piece_shift(off['pieces'], on['pieces'])}"
            )
            pictures.append((name, png, frames))
            series = ", ".join(f"{r[0]}: {r[2]}/{r[1]} ({r[3]})" for r in on["rows"][:: max(1, len(on["rows"]) // 10)])
            pictures.append((name, None, series))
            write()


if __name__ == "__main__":
    main()
