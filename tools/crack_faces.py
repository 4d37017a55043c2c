"""Crack faces and contact: the Kalthoff-Winkler-like steel plate of tools/contact_stability.py with contact on and
off, and the angle of the cracks that grow from its notch tips; prints the table of docs/fracture.md (section "Crack
faces and contact").

    python tools/crack_faces.py [--spacing 2e-3] [--end 100e-6] [--notch-width 1.5e-3]
                                [--projectile-height 0.046 0.048 0.05] [--seeds 1 2] [--history 10]
                                [--former-rule] [--safety 0.7] [--distance-factor 1.35] [--out docs]

Contact within a body acts only where crack faces close across dead bonds (kernels/contact.py,
crack_pair_geometry): the notch faces, which the punched block slides along, must not push the plate apart, so the
crack angle must not depend on whether contact is on.

The notches (contact_stability.kalthoff_winkler): slots ``--notch-width`` wide (default 1.5 mm, the notch width
peridynamic models of the experiment commonly use), the particle layer nearest y = +-25 mm removed; 0 cuts them as
planes of zero width between two particle layers instead, whose faces start in contact range.

The angle (crack_angles, tip_crack_angle), each tip on its own: the damaged particles (damage > 0.5, every particle
layer through the thickness) 5 to 25 mm from the tip (PATH_FROM, PATH_TO), ahead of it (x > x_tip) and outside the
notch (|y| >= |y_notch| + h), are scanned for the line through the tip with the most damage near it (directions in
steps of SCAN_STEP = 0.25 degrees; each particle's damage weighted by a triangle kernel across the line, zero at
BAND = 1.5 h), and REFINE = 3 passes of the damage- and kernel-weighted principal direction of the particles around
that line refine it. Its angle from the notch direction (+x, the impact direction) towards the outside is the tip's
crack angle [deg]. A crack branching off the line (or a second crack from the punched block) adds little to it, and
the spall of the plate's back face lies beyond 25 mm.

The notch's closing: the largest shortening, over the run's end state, of the gap across the notch along a bond the
notch cut (its rest offset's component across the notch, y), as a fraction of h: a zero-width cut's faces start h
apart and touch (contact distance 0.9 of the rest distance) after closing 0.1 h; a slot's start 2 h apart and touch
at 1.35 h (the contact distance between separate surfaces, kernels/contact.py), after closing 0.65 h.
``--projectile-height`` gives the punching box's widths across the notches (default 50 mm: its edges lie on the
notches' centre lines); ``--seeds`` adds runs with the particles jittered (that sampling seed) to the lattice run;
``--former-rule`` adds a run with contact on that ignores the bonds (run's ``former_rule``); ``--safety`` sets the
step over the stable estimate, ``--distance-factor`` the contact distance of separate surfaces over h.
``--history N`` also prints, at N times through each run with contact on, the notch's closing and the number of
notch-face particles (those with a bond the notch cut) in contact (ParticleContact.diagnostics), and where the
particles in contact at those times lie (contact_regions).
"""

from __future__ import annotations

import argparse
import datetime
import math
import platform
import time
from pathlib import Path

import contact_stability as cs
import numpy as np
import warp as wp

from pdsim.run import advance_frame

NOTCH_TIP_X = 0.0  # the notches run from the plate's edge x = -0.05 m to x = 0 (tools/contact_stability.py)
NOTCH_WIDTH = 1.5e-3  # [m], the slots' default width
DAMAGED = 0.5
PATH_FROM = 5.0e-3  # [m], the fitted stretch of crack path: its distance from the tip
PATH_TO = 25.0e-3
BAND = 1.5  # [h], the half-width of the band around a candidate crack line
SCAN_STEP = 0.25  # [deg], the candidate lines' angles
REFINE = 3  # principal-direction passes over the damage within the band


def tip_offsets(rest_positions: np.ndarray, notch_y: float) -> np.ndarray:
    """Offsets [n, 2] [m] of the particles from the notch tip (NOTCH_TIP_X, ``notch_y``), the outside of the notch
    towards +y (y mirrored for the lower notch)."""
    offset = np.asarray(rest_positions, dtype=np.float64)[:, :2] - np.array([NOTCH_TIP_X, notch_y])
    offset[:, 1] *= math.copysign(1.0, notch_y)
    return offset


def tip_crack_angle(rest_positions: np.ndarray, damage: np.ndarray, spacing: float, notch_y: float) -> float:
    """The crack angle [deg] of the notch tip (NOTCH_TIP_X, ``notch_y``) [m] (module docstring); nan when no damaged
    particle lies in the window. ``rest_positions`` [n, 3] in the plate's frame [m], ``damage`` [n]."""
    offset = tip_offsets(rest_positions, notch_y)
    r = np.hypot(offset[:, 0], offset[:, 1])
    pick = (damage > DAMAGED) & (offset[:, 0] > 0.0) & (offset[:, 1] >= spacing) & (r >= PATH_FROM) & (r < PATH_TO)
    if not pick.any():
        return math.nan
    p, w = offset[pick], damage[pick]
    band = BAND * spacing

    def score(angle):  # damage near the ray from the tip at ``angle`` [rad], a triangle kernel across it
        across = np.abs(p @ np.array([-math.sin(angle), math.cos(angle)]))
        return w @ np.maximum(0.0, 1.0 - across / band)

    grid = np.radians(np.arange(0.0, 180.0, SCAN_STEP))
    angle = float(grid[int(np.argmax([score(a) for a in grid]))])
    for _ in range(REFINE):  # the principal direction of the damage around the ray, weighted by the kernel
        across = np.abs(p @ np.array([-math.sin(angle), math.cos(angle)]))
        weight = w * np.maximum(0.0, 1.0 - across / band)
        _, _, vt = np.linalg.svd((p * weight[:, None]).T @ p)
        direction = vt[0] if vt[0] @ (weight @ p) > 0.0 else -vt[0]
        angle = math.atan2(direction[1], direction[0])
    return math.degrees(angle)


def crack_angles(
    rest_positions: np.ndarray, damage: np.ndarray, spacing: float, notch_y: tuple = (0.025, -0.025)
) -> tuple[float, float]:
    """The crack angles [deg] of the upper and lower notch tips (module docstring), the notches at ``notch_y`` [m]."""
    return tuple(tip_crack_angle(rest_positions, damage, spacing, y) for y in notch_y)


def crack_angle(
    rest_positions: np.ndarray, damage: np.ndarray, spacing: float, notch_y: tuple = (0.025, -0.025)
) -> float:
    """Mean of the two tips' crack angles [deg] (crack_angles); nan when a tip has no traced path."""
    return float(np.mean(crack_angles(rest_positions, damage, spacing, notch_y)))


def notch_closing(solver, rest: np.ndarray) -> float:
    """The largest closing [m] of the gap across the notch along a bond the notch cut (module docstring): over the
    cut bonds (k, j), the most negative (u_j - u_k)_y sign((X_j - X_k)_y), as a positive number (0 when none closes)."""
    m = solver.model
    offsets = m.family_offsets.numpy()
    owner = np.repeat(np.arange(len(rest)), np.diff(offsets))
    cut = m.bond_alive_initial.numpy() == 0
    k, j = owner[cut], m.family_neighbors.numpy()[cut]
    u = solver.positions() - rest
    change = (u[j, 1] - u[k, 1]) * np.sign(rest[j, 1] - rest[k, 1])
    return float(max(0.0, -change.min())) if len(change) else 0.0


def run(
    spacing: float,
    end_time: float,
    contact: bool,
    projectile_height: float = 0.05,
    history: int = 0,
    notch_width: float = NOTCH_WIDTH,
    sampling_seed: int | None = None,
    former_rule: bool = False,
    time_step_safety: float = 0.7,
    distance_factor: float | None = None,
) -> dict:
    """The plate at ``spacing`` [m] with notches ``notch_width`` [m] wide (0: the zero-width cut), particles on the
    lattice or jittered with ``sampling_seed``, run to ``end_time`` [s] at the automatic step: the two tips' crack
    angles [deg] (``angles``, upper then lower) and their mean (``angle``), damaged particle count, the notch's
    closing [m] (notch_closing), wall time [s]; with ``history`` > 0 and contact on, ``history`` rows (time [s],
    closing [m], notch-face particles in contact) at as many even times through the run. ``former_rule`` (with
    contact on): the contact ignores the bonds (ParticleContact.cracks off), so particles of one body repel below
    0.9 of their rest distance whatever lies between them, the rule before crack_pair_geometry. ``time_step_safety``:
    the step over the smallest stable estimate (the Scene's default 0.7). ``distance_factor``: the contact distance
    of separate surfaces over h (ParticleContact's, default 1.35)."""
    case = cs.kalthoff_winkler(
        spacing,
        contact=contact,
        projectile_height=projectile_height,
        notch_width=notch_width,
        sampling_seed=sampling_seed,
        time_step_safety=time_step_safety,
        contact_options=None if distance_factor is None else {"distance_factor": distance_factor},
    )
    solver = case.solver
    if former_rule and solver.contact is not None:
        solver.contact.cracks = False
    dt = case.scene.time_step_safety * min(s.stable_time_step() for s in case.solvers)
    rest = np.concatenate([b.rest_positions for b in solver.bodies])
    steps = math.ceil(end_time / dt)
    chunks = history if history > 0 and solver.contact is not None else 1
    rows = []
    faces = notch_faces(solver, rest)
    first = np.full(len(rest), np.nan)  # time of each particle's first contact at a history sample [s]
    start = time.perf_counter()
    done = 0
    for c in range(chunks):
        n = (steps * (c + 1)) // chunks - done
        advance_frame(case.solvers, dt, n)
        done += n
        if chunks > 1:
            touching = in_contact(solver)
            first[touching & np.isnan(first)] = done * dt
            rows.append((done * dt, notch_closing(solver, rest), int((touching & faces).sum())))
    wall = time.perf_counter() - start
    damage = solver.damage()
    angles = crack_angles(rest, damage, spacing, tuple(cs.notch_lines(spacing, notch_width)))
    return {
        "contact": contact,
        "angles": angles,
        "angle": float(np.mean(angles)),
        "damaged": int((damage > DAMAGED).sum()),
        "closing": notch_closing(solver, rest),
        "particles": solver.particle_count,
        "wall": wall,
        "history": rows,
        "regions": contact_regions(rest, first, cs.notch_lines(spacing, notch_width)) if rows else [],
    }


def in_contact(solver) -> np.ndarray:
    """bool [n]: the particles in contact now (ParticleContact.diagnostics)."""
    local = solver.model.rest_positions.numpy() + solver.kin.u.numpy()  # the solver's local frame, as the contact's
    positions = wp.array(local.astype(np.float32), dtype=wp.vec3, device=solver.device)
    return solver.contact.diagnostics(positions).count > 0


def notch_faces(solver, rest: np.ndarray) -> np.ndarray:
    """bool [n]: the particles with a bond the notch cut."""
    m = solver.model
    owner = np.repeat(np.arange(len(rest)), np.diff(m.family_offsets.numpy()))
    face = np.zeros(len(rest), dtype=bool)
    face[owner[m.bond_alive_initial.numpy() == 0]] = True
    return face


def contact_regions(rest: np.ndarray, first: np.ndarray, notch_y: list) -> list[tuple[str, int, float]]:
    """Where the particles in contact at some sample lie (``first`` [n]: the time of their first contact [s], nan
    for none): (region, count, earliest time [s]) for the impact end (x within 10 mm of the impacted face x =
    -50 mm), the notches' faces beyond it (within 4 mm of a notch's centre line, x < 0), within 30 mm of a notch
    tip, and elsewhere; each particle counted in the first region that holds it."""
    hit = np.isfinite(first)
    near_notch = np.min([np.abs(rest[:, 1] - y) for y in notch_y], axis=0)
    tip_distance = np.min([np.hypot(rest[:, 0] - NOTCH_TIP_X, rest[:, 1] - y) for y in notch_y], axis=0)
    regions = [
        ("impact end", rest[:, 0] < -0.04),
        ("notch faces", (near_notch < 0.004) & (rest[:, 0] < 0.0)),
        ("near a tip", tip_distance < 0.03),
        ("elsewhere", np.ones(len(rest), dtype=bool)),
    ]
    out, left = [], hit.copy()
    for name, mask in regions:
        pick = left & mask
        left &= ~mask
        out.append((name, int(pick.sum()), float(first[pick].min()) if pick.any() else math.nan))
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spacing", type=float, default=2.0e-3, help="particle spacing h [m] (gallery: 2 mm)")
    parser.add_argument("--end", type=float, default=100.0e-6, help="end time [s]")
    parser.add_argument("--notch-width", type=float, default=NOTCH_WIDTH, help="slot width [m]; 0: zero-width cut")
    parser.add_argument(
        "--projectile-height", type=float, nargs="+", default=[0.05], help="the box's widths across the notches [m]"
    )
    parser.add_argument("--seeds", type=int, nargs="*", default=[], help="jittered runs' sampling seeds")
    parser.add_argument("--history", type=int, default=0, help="rows of the notch's closing and contacts (on)")
    parser.add_argument("--former-rule", action="store_true", help="also contact on without the bonds (run)")
    parser.add_argument("--safety", type=float, default=0.7, help="time step over the stable estimate")
    parser.add_argument("--distance-factor", type=float, default=None, help="contact distance over h (1.35)")
    parser.add_argument("--out", type=Path, default=None, help="print only when omitted")
    args = parser.parse_args(argv)
    wp.config.quiet = True
    configs = [(box, None) for box in args.projectile_height] + [(args.projectile_height[0], s) for s in args.seeds]
    command = (
        f"python tools/crack_faces.py --spacing {args.spacing:g} --end {args.end:g} --notch-width {args.notch_width:g}"
        f" --projectile-height {' '.join(f'{b:g}' for b in args.projectile_height)}"
        + (f" --seeds {' '.join(str(s) for s in args.seeds)}" if args.seeds else "")
        + (" --former-rule" if args.former_rule else "")
        + (f" --safety {args.safety:g}" if args.safety != 0.7 else "")
        + (f" --distance-factor {args.distance_factor:g}" if args.distance_factor is not None else "")
    )
    notch = f"slots {args.notch_width * 1e3:g} mm wide" if args.notch_width > 0.0 else "zero-width cuts"
    lines = [
        f"Kalthoff-Winkler-like steel plate, h = {args.spacing * 1e3:g} mm, 32 m/s, t = {args.end * 1e6:g} us, notches "
        f"{notch} ({platform.processor() or platform.machine()}, {datetime.date.today().isoformat()}; `{command}`):",
        "",
        "| box [mm] | particles | contact | upper tip [deg] | lower tip [deg] | mean [deg] | on - off [deg] "
        "| damage > 0.5 | notch closing [h] | wall [s] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    means = {False: [], True: []}
    jittered = {False: [], True: []}  # the seeded runs' tip angles
    histories = []
    for box, seed in configs:
        options = {
            "notch_width": args.notch_width,
            "sampling_seed": seed,
            "time_step_safety": args.safety,
            "distance_factor": args.distance_factor,
        }
        rows = [run(args.spacing, args.end, c, box, args.history, **options) for c in (False, True)]
        if args.former_rule:
            rows.append(run(args.spacing, args.end, True, box, 0, former_rule=True, **options))
        for i, r in enumerate(rows):
            if i < 2:
                means[r["contact"]].append(r["angle"])
            if seed is not None and i < 2:
                jittered[r["contact"]] += list(r["angles"])
            label = f"{box * 1e3:g}" + ("" if seed is None else f", seed {seed}")
            mode = ("off", "on", "on, former rule")[i]
            difference = f"{r['angle'] - rows[0]['angle']:+.2f}" if i else ""
            lines.append(
                f"| {label} | {r['particles']} | {mode} | {r['angles'][0]:.1f} | {r['angles'][1]:.1f} | "
                f"{r['angle']:.2f} | {difference} | {r['damaged']} | {r['closing'] / args.spacing:.3f} | "
                f"{r['wall']:.1f} |"
            )
        if rows[1]["history"]:
            histories.append((box, seed, rows[1]["history"], rows[1]["regions"]))
        print(*lines[-len(rows) :], sep="\n", flush=True)
    lines.append("")
    spread = {c: (max(v) - min(v)) if len(v) > 1 else math.nan for c, v in means.items()}
    lines.append(
        f"Largest |on - off|: {max(abs(a - b) for a, b in zip(means[True], means[False])):.2f} degrees; the mean "
        f"angle's spread over the set-ups: {spread[False]:.2f} degrees off, {spread[True]:.2f} on."
    )
    if args.seeds:
        off, on = np.asarray(jittered[False]), np.asarray(jittered[True])
        change = on - off
        se = change.std(ddof=1) / math.sqrt(len(change))
        lines.append(
            f"Jittered runs ({len(args.seeds)} seeds, {len(off)} tips): tip angle {off.mean():.1f} +- "
            f"{off.std(ddof=1):.1f} degrees off, {on.mean():.1f} +- {on.std(ddof=1):.1f} on (mean +- standard "
            f"deviation); on - off per tip {change.mean():+.2f} +- {se:.2f} (mean +- standard error), from "
            f"{change.min():+.1f} to {change.max():+.1f}."
        )
    for box, seed, history, regions in histories:
        lines += [
            "",
            f"Box {box * 1e3:g} mm{'' if seed is None else f', seed {seed}'}, contact on:",
            "",
            "| t [us] | notch closing [h] | notch-face particles in contact |",
            "|---|---|---|",
        ]
        for t, closing, count in history:
            lines.append(f"| {t * 1e6:.0f} | {closing / args.spacing:.3f} | {count} |")
        lines.append("")
        lines.append(
            "Particles in contact at some sample: "
            + "; ".join(
                f"{name} {count}" + (f" (from {t * 1e6:.1f} us)" if count else "") for name, count, t in regions
            )
            + "."
        )
    text = "\n".join(lines)
    print(text)
    if args.out is not None:
        (args.out / "crack_faces.txt").write_text(text + "\n")


if __name__ == "__main__":
    main()
