"""Crack faces and contact: the Kalthoff-Winkler-like steel plate of tools/contact_stability.py with contact on and
off, and the angle of the cracks that grow from its notch tips; writes the table of docs/fracture.md (section "Crack
faces and contact").

    python tools/crack_faces.py [--spacing 2e-3] [--end 100e-6] [--projectile-height 0.05] [--history 10]
                                [--out docs]

Contact within a body acts only where crack faces close across dead bonds (kernels/contact.py,
crack_pair_geometry): the notch faces, which the punched block slides along, must not push the plate apart, so the
crack angle must not depend on whether contact is on. The angle: the damaged particles (damage > 0.5) ahead of each
notch tip (tip + 2 h < x < tip + 35 mm: the back face's spall is left out) and outside it (|y| > |y_tip| + h), in
the plate's first particle layer, are fitted with a line through the tip (the principal direction of their offsets
from the tip); the angle is measured from the notch direction (+x, the impact direction) towards the outside, in
degrees, averaged over the two tips. The notch's closing: the largest shortening, over the run's end state, of the
gap across the notch along a bond the notch cut (its rest offset's component across the notch, y), as a fraction of
h: contact between the notch faces starts at 0.1 h (kernels/contact.py crack_pair_geometry, bonded_factor 0.9).
``--projectile-height`` narrows the punching box (default 50 mm: its edges lie on the notches' inner faces).
``--history N`` also prints, at N times through the run with contact on, the notch's closing and the number of
notch-face particles (those with a bond the notch cut) in contact (ParticleContact.diagnostics).
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
NOTCH_Y = 0.025  # [m], the notches' distance from the plate's centre line
DAMAGED = 0.5
BACK_FACE_MARGIN_X = 0.035  # [m] from the tip: the plate's back face (x = 0.05 m) spalls; its damage is left out


def crack_angle(rest_positions: np.ndarray, damage: np.ndarray, spacing: float) -> float:
    """Mean angle [deg] from +x of the cracks grown from the two notch tips (module docstring); nan when a tip has no
    damaged particle ahead of it. ``rest_positions`` [n, 3] in the plate's frame (centre at the origin) [m]."""
    x = np.asarray(rest_positions, dtype=np.float64)
    layer = x[:, 2] < x[:, 2].mean()
    angles = []
    for sign in (1.0, -1.0):
        offset = x[:, :2] - np.array([NOTCH_TIP_X, sign * NOTCH_Y])
        ahead = (offset[:, 0] > 2.0 * spacing) & (offset[:, 0] < BACK_FACE_MARGIN_X)
        pick = layer & (damage > DAMAGED) & ahead & (sign * offset[:, 1] > spacing)
        if not pick.any():
            return math.nan
        p = offset[pick] * np.array([1.0, sign])  # the outside is +y for both tips
        _, _, vt = np.linalg.svd(p.T @ p)
        direction = vt[0] if vt[0] @ p.mean(axis=0) > 0.0 else -vt[0]
        angles.append(math.degrees(math.atan2(direction[1], direction[0])))
    return float(np.mean(angles))


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


def run(spacing: float, end_time: float, contact: bool, projectile_height: float = 0.05, history: int = 0) -> dict:
    """The plate at ``spacing`` [m] run to ``end_time`` [s] at the automatic step: crack angle [deg], damaged particle
    count, the notch's closing [m] (notch_closing), wall time [s]; with ``history`` > 0 and contact on, ``history``
    rows (time [s], closing [m], notch-face particles in contact) at as many even times through the run."""
    case = cs.kalthoff_winkler(spacing, contact=contact, projectile_height=projectile_height)
    solver = case.solver
    dt = case.scene.time_step_safety * min(s.stable_time_step() for s in case.solvers)
    rest = np.concatenate([b.rest_positions for b in solver.bodies])
    steps = math.ceil(end_time / dt)
    chunks = history if history > 0 and solver.contact is not None else 1
    rows = []
    start = time.perf_counter()
    done = 0
    for c in range(chunks):
        n = (steps * (c + 1)) // chunks - done
        advance_frame(case.solvers, dt, n)
        done += n
        if chunks > 1:
            rows.append((done * dt, notch_closing(solver, rest), notch_contacts(solver, rest)))
    wall = time.perf_counter() - start
    damage = solver.damage()
    return {
        "contact": contact,
        "angle": crack_angle(rest, damage, spacing),
        "damaged": int((damage > DAMAGED).sum()),
        "closing": notch_closing(solver, rest),
        "particles": solver.particle_count,
        "wall": wall,
        "history": rows,
    }


def notch_contacts(solver, rest: np.ndarray) -> int:
    """The number of particles with a bond the notch cut that are in contact now (ParticleContact.diagnostics)."""
    m = solver.model
    owner = np.repeat(np.arange(len(rest)), np.diff(m.family_offsets.numpy()))
    face = np.zeros(len(rest), dtype=bool)
    face[owner[m.bond_alive_initial.numpy() == 0]] = True
    local = m.rest_positions.numpy() + solver.kin.u.numpy()  # the solver's local frame, as the contact's
    positions = wp.array(local.astype(np.float32), dtype=wp.vec3, device=solver.device)
    return int(((solver.contact.diagnostics(positions).count > 0) & face).sum())


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spacing", type=float, default=2.0e-3, help="particle spacing h [m] (gallery: 2 mm)")
    parser.add_argument("--end", type=float, default=100.0e-6, help="end time [s]")
    parser.add_argument("--projectile-height", type=float, default=0.05, help="the box across the notches [m]")
    parser.add_argument("--history", type=int, default=0, help="rows of the notch's closing and contacts (on)")
    parser.add_argument("--out", type=Path, default=None, help="print only when omitted")
    args = parser.parse_args(argv)
    rows = [run(args.spacing, args.end, contact, args.projectile_height, args.history) for contact in (False, True)]
    lines = [
        f"Kalthoff-Winkler-like steel plate, h = {args.spacing * 1e3:g} mm, 32 m/s, t = {args.end * 1e6:g} us, box "
        f"{args.projectile_height * 1e3:g} mm across the notches ({rows[0]['particles']} particles; "
        f"{platform.processor() or platform.machine()}, {datetime.date.today().isoformat()}; "
        f"`python tools/crack_faces.py --spacing {args.spacing:g} --end {args.end:g} "
        f"--projectile-height {args.projectile_height:g}`):",
        "",
        "| contact | crack angle from the notch [deg] | particles with damage > 0.5 | notch closing [h] | wall [s] |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {'on' if r['contact'] else 'off'} | {r['angle']:.1f} | {r['damaged']} | "
            f"{r['closing'] / args.spacing:.3f} | {r['wall']:.1f} |"
        )
    lines.append("")
    lines.append(f"Difference: {abs(rows[1]['angle'] - rows[0]['angle']):.2f} degrees.")
    if rows[1]["history"]:
        lines += ["", "| t [us] (contact on) | notch closing [h] | notch-face particles in contact |", "|---|---|---|"]
        for t, closing, count in rows[1]["history"]:
            lines.append(f"| {t * 1e6:.0f} | {closing / args.spacing:.3f} | {count} |")
    text = "\n".join(lines)
    print(text)
    if args.out is not None:
        (args.out / "crack_faces.txt").write_text(text + "\n")


if __name__ == "__main__":
    main()
