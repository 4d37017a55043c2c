"""Accuracy sweeps of the elastic peridynamic solid; writes docs/accuracy.md and docs/pd_surface_effect.png.

    python tools/accuracy_pd.py [--quick] [--out docs]

1. Supplement checks on interior particles (expansion: theta / 3 zeta and W / (9/2 kappa zeta^2); shear:
   W / (1/2 mu zeta^2)) at m = delta/h = 3.015 and 6.03 for a fixed horizon, for each surface correction.
2. Surface effect: quasi-static tension of a free-sided bar of n x n particles (grips held, interior relaxed):
   effective Young's modulus (reaction stress over mid-bar strain) over E, per surface correction.
3. Longitudinal pulse speed in a free bar with nu = 0 (bar speed = P-wave speed) over sqrt(E/rho).
4. Stable time step: the measured critical step (bisection on growth over 2000 steps) over the Silling-Askari
   estimate, for three Poisson's ratios.
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import platform
import sys

import numpy as np
import warp as wp

import pdsim
from pdsim.reference_problems import bar_tension_modulus

CORRECTIONS = ("none", "family", "directional")
CONCLUSIONS = """
## Conclusions and the default

- The supplement's constants (`none`) carry a quadrature error that depends on m = delta/h only (2-6 % at m = 3,
  about 1 % at m = 6) and leave surface particles soft: a bar 5 particles across is 21 % too soft and its pulse
  7 % too slow.
- `family` (the supplement's two matching conditions evaluated on each particle's own family) makes the interior
  exact for expansion, but it scales a truncated family isotropically, so it over-stiffens thin parts (+36 % at
  n = 5).
- `directional` (the default) is Madenci and Oterkus's per-axis correction, with the deviatoric factor calibrated
  on uniaxial stress rather than uniaxial stretch. That is the state slender parts are in under tension and
  bending, and this change about halved the thin-bar error (n = 10, nu = 0.3: +6.0 % -> +4.4 %); the dilatation
  factor keeps the stretch target, which stays well conditioned as nu -> 1/2. It is the most accurate of the three
  on every measure above except the interior energies at m = 3, where it is 1.5-2.7 % low (the supplement's
  constants are 4.6-5.9 % high there). The bar error shrinks with resolution: 9 %, 4 %, 2 % for 5, 10, 20
  particles across.
- The stable-step estimate is conservative by 1.7-2.4x, so the automatic step (0.7 x estimate) has a margin of
  2.5-3.4x. A step 3x the estimate diverges, and the divergence is caught (tests/test_pd_elastic.py).

## Plasticity and fracture (asserted in tests/test_pd_plastic_fracture.py)

- Uniaxial tension of a bar 10 particles across (E = 1 MPa, nu = 0.25, sigma_Y = 10 kPa, roller grips,
  quasi-static increments): elastic slope within 5 % of E (about +4 %, the surface effect above), yield within
  10 % of sigma_Y, a plateau flat to 5 %, elastic unloading and a permanent set. With linear hardening the
  post-yield slope is E H / (E + H) within 20 %.
- Hydrostatic expansion or compression by 5 % (50 x the yield strain) gives exactly zero plastic strain at every
  particle. The return mapping uses the family's own volumetric strain, so the deviatoric extension vanishes bond
  by bond.
- G0 -> s_c calibration: the discrete model's energy to open a unit area, with all crossing bonds at s_c, is within
  0.3 % (m = 3.015) and 0.7 % (m = 4.015) of G0 with the directional correction (6.8 % and 3.0 % without).
"""
ZETA = 1.0e-3


def machine() -> str:
    cpu = platform.processor() or "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, Warp {wp.__version__}, CPU backend"


def supplement_checks(m: float, correction: str, delta: float = 3.015 / 8.0):
    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.25)
    h = delta / m
    reach = (2.0 if correction == "directional" else 1.0) * (delta + h)
    cells = 2 * math.ceil(reach / h) + 1
    body = pdsim.PeridynamicBody(pdsim.box((cells * h,) * 3), mat, h, horizon_factor=m, surface_correction=correction)
    s = pdsim.SolverPeridynamics([body], device="cpu")
    X = body.rest_positions
    c = np.all(np.abs(X) < 0.5 * cells * h - reach, axis=1)
    s.set_positions(X * (1.0 + ZETA))
    th = s.dilatation()[c].mean() / (3 * ZETA)
    w = s.strain_energy_density()[c].mean() / (4.5 * mat.bulk_modulus * ZETA**2)
    Y = X.copy()
    Y[:, 0] += ZETA * X[:, 1]
    s.set_positions(Y)
    ws = s.strain_energy_density()[c].mean() / (0.5 * mat.shear_modulus * ZETA**2)
    return th, w, ws


def bar_tension_modulus_ratio(n: int, correction: str, nu: float = 0.3, m: float = 3.015) -> float:
    """Quasi-static tension of a free-sided bar of n x n particles: both grips (3 layers) are held at the affine
    uniaxial-stress displacement of strain ZETA, the rest relaxes under damping to equilibrium. Returns
    E_eff / E with E_eff = (reaction force / area) / (strain measured in the middle third); the run is
    pdsim.reference_problems.bar_tension_modulus with this tool's spacing 1 cm and bar length."""
    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=nu)
    h = 0.01
    width = n * h
    modulus, _ = bar_tension_modulus(mat, h, width, max(0.3, 4.0 * width), m, correction, 0.7)
    return float(modulus / mat.youngs_modulus)


def pulse_speed_ratio(n: int, correction: str) -> float:
    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.0)
    h, length = 0.02, 3.0
    body = pdsim.PeridynamicBody(
        pdsim.box((length, n * h, n * h), center=(0.5 * length, 0.0, 0.0)), mat, h, surface_correction=correction
    )
    s = pdsim.SolverPeridynamics([body], device="cpu")
    c = mat.bar_wave_speed
    X = body.rest_positions[:, 0]
    x0, width, amp = 0.8, 8.0 * body.horizon, 1.0e-4
    g = amp * np.exp(-(((X - x0) / width) ** 2))
    u = np.zeros_like(body.rest_positions)
    u[:, 0] = g
    v = np.zeros_like(u)
    v[:, 0] = 2.0 * c * (X - x0) / width**2 * g
    s.set_positions(body.rest_positions + u)
    s.set_velocities(v)
    xs, idx = np.unique(np.round(X, 9), return_inverse=True)

    def peak():
        prof = np.bincount(idx, s.positions()[:, 0] - X) / np.bincount(idx)
        i = int(np.argmax(prof))
        a, b, cc = prof[i - 1], prof[i], prof[i + 1]
        return xs[i] + 0.5 * h * (a - cc) / (a - 2 * b + cc)

    dt = 0.7 * s.stable_time_step()
    p0, t0 = peak(), s.time
    s.simulate(dt, round(1.2 / c / dt))
    return float((peak() - p0) / (s.time - t0) / c)


def critical_step_ratio(nu: float, steps: int = 2000) -> float:
    """Largest stable dt (growth of a 1e-6 m random perturbation by < 100x over ``steps``) over the estimate."""
    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=nu)
    body = pdsim.PeridynamicBody(pdsim.box((0.4, 0.4, 0.4)), mat, 0.04)
    est = pdsim.SolverPeridynamics([body], device="cpu").stable_time_step()
    rng = np.random.default_rng(0)
    pert = 1.0e-6 * rng.standard_normal(body.rest_positions.shape)

    def stable(f):
        s = pdsim.SolverPeridynamics([body], device="cpu")
        s.set_positions(body.rest_positions + pert)
        s.simulate(f * est, steps)
        d = np.abs(s.positions() - body.rest_positions)
        return bool(np.all(np.isfinite(d)) and d.max() < 1.0e-4)

    lo, hi = 1.0, 4.0
    if not stable(lo):
        return float("nan")
    for _ in range(7):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="docs")
    p.add_argument("--quick", action="store_true", help="smaller sweeps (for a smoke run)")
    args = p.parse_args(argv)
    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING
    os.makedirs(args.out, exist_ok=True)
    lines = [
        "# Accuracy of the elastic peridynamic solid",
        "",
        f"Generated by `python tools/accuracy_pd.py` on {datetime.date.today()} ({machine()}).",
        "Material: E = 1 MPa, rho = 1000 kg/m^3; zeta = 1e-3. Partial volumes on (linear, family cut at delta + h/2).",
        "",
        "## 1. Supplement checks on interior particles (fixed delta, h halved)",
        "",
        "| correction | m = delta/h | theta / 3 zeta | W_exp / (9/2 kappa zeta^2) | W_shear / (1/2 mu zeta^2) |",
        "|---|---|---|---|---|",
    ]
    for corr in CORRECTIONS:
        for m in (3.015, 6.03):
            th, w, ws = supplement_checks(m, corr)
            lines.append(f"| {corr} | {m} | {th:.4f} | {w:.4f} | {ws:.4f} |")
            print(lines[-1], flush=True)
    sizes = (5, 10) if args.quick else (5, 10, 20)
    lines += [
        "",
        "## 2. Surface effect: effective Young's modulus of a bar in tension (nu = 0.3, m = 3.015, h = 0.01 m)",
        "",
        "Quasi-static tension: 3-layer grips held at a 0.1 % uniaxial-stress stretch, the bar relaxed to equilibrium",
        "under damping; E_eff = (grip reaction / area) / (strain fitted over the middle third). 1.0 is the continuum;",
        "below 1 the bar is too soft (the classic surface effect), above 1 too stiff.",
        "",
        "| n | " + " | ".join(CORRECTIONS) + " |",
        "|---|" + "---|" * len(CORRECTIONS),
    ]
    table = {c: [] for c in CORRECTIONS}
    for n in sizes:
        row = [bar_tension_modulus_ratio(n, c) for c in CORRECTIONS]
        for c, r in zip(CORRECTIONS, row, strict=False):
            table[c].append(r)
        lines.append(f"| {n} | " + " | ".join(f"{r:.4f}" for r in row) + " |")
        print(lines[-1], flush=True)
    lines += [
        "",
        "## 3. Longitudinal pulse speed in a free bar, nu = 0, over sqrt(E/rho) (m = 3.015, h = 0.02 m)",
        "",
        "With nu = 0 the bar speed equals the P-wave speed and lateral inertia plays no part, so the ratio isolates",
        "the peridynamic stiffness along the bar (tests/test_pd_elastic.py asserts 5 % for n = 5).",
        "",
        "| n | " + " | ".join(CORRECTIONS) + " |",
        "|---|" + "---|" * len(CORRECTIONS),
    ]
    for n in (5, 9) if args.quick else (5, 9, 15):
        lines.append(f"| {n} | " + " | ".join(f"{pulse_speed_ratio(n, c):.4f}" for c in CORRECTIONS) + " |")
        print(lines[-1], flush=True)
    lines += [
        "",
        "## 4. Stable time step: measured critical step over the Silling-Askari estimate",
        "",
        "The estimate uses C_kj = 2 w G (b_k + b_j) plus a Gershgorin bound of the dilatational coupling; the",
        "automatic step is 0.7 x the estimate. Measured by bisection (a 1e-6 m random perturbation of a 10^3 block",
        "must not grow past 1e-4 m in 2000 steps).",
        "",
        "| nu | critical / estimate |",
        "|---|---|",
    ]
    for nu in (0.0, 0.3, 0.45):
        lines.append(f"| {nu} | {critical_step_ratio(nu):.2f} |")
        print(lines[-1], flush=True)
    with open(os.path.join(args.out, "accuracy.md"), "w") as f:
        f.write("\n".join(lines) + "\n" + CONCLUSIONS)
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not installed: no plot written", file=sys.stderr)
        return 0
    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    for c in CORRECTIONS:
        ax.plot(sizes, table[c], "o-", label=c)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("particles across the bar (n)")
    ax.set_ylabel("effective E / E")
    ax.set_title("Surface effect, bar in uniaxial stress (m = 3.015)")
    ax.legend(title="surface_correction")
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, "pd_surface_effect.png"), dpi=120)
    return 0


if __name__ == "__main__":
    sys.exit(main())
