"""Validation problems with reference answers, each a function of the accuracy knobs.

Every problem function takes its refinement knob first (particles or cells across a fixed geometry, or the horizon
ratio m = delta / h at a fixed horizon) and the method's knobs as keywords, runs on the CPU backend, and returns a
record (a plain dict, JSON-ready):

- ``problem``, ``method`` ("pd", "fem" or "lattice") and ``knobs`` (every knob the run used, defaults included);
- ``error``: the relative error against the reference answer [-] (see each problem), ``measured`` and ``reference``;
- ``seconds``: wall time of the run [s] (model building and simulation; Warp's start-up excluded);
- ``peak_rss_mb``: the process's peak resident memory during the run [MiB] (Linux: VmHWM, reset before the run);
  ``memory_mb``: that peak less the resident memory at the start of the run [MiB], the run's own share;
- ``points``: particles, vertices or lattice points; plus problem-specific fields.

The problems (``PROBLEMS`` maps each name to its function, refinement knob and levels, cheapest first):

- ``pd_wave_speed``: a longitudinal pulse in a free peridynamic bar with nu = 0 travels at sqrt(E / rho).
- ``pd_bar_stiffness``: a peridynamic bar in quasi-static tension has Young's modulus E (grip reaction over strain).
- ``pd_energy_density``: interior energy densities under isotropic expansion, 9/2 kappa zeta^2, and simple shear,
  1/2 mu zeta^2 (the state-based supplement's calibration).
- ``pd_crack_speed``: a mode-I crack running in a pre-stretched strip stays below the Rayleigh speed (a bound, not a
  reference value: the error is the excess over the bound, zero when the bound holds).
- ``cantilever``: a cantilever under a tip force against Timoshenko's beam, by either method (``method="fem"`` or
  ``"pd"``) on the same geometry, so the two can be compared at equal error; the FEM takes its strain measure,
  precision and integrator ("static" solve, or damped "explicit" / "implicit" dynamics to rest).
- ``fem_patch_test``: an irregular tetrahedral mesh under an affine boundary displacement reproduces it inside.
- ``lattice_laplace``: the lattice's centroid rule relaxed to rest against its continuum limit, Laplace's equation
  (each displacement component harmonic), on a square with a harmonic boundary displacement.

Run one: ``pdsim.reference_problems.run_problem("cantilever", 4, method="fem")``; sweep many with :mod:`pdsim.sweep`.
"""

from __future__ import annotations

import math
import os
import platform
import resource
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import warp as wp

import pdsim

from .errors import ParameterError
from .fem import FemBody, SolverFem
from .fem.mesh import box_tet_mesh
from .lattice import Lattice, LatticeBody, LatticeKind, LatticeNeighbourhood, SolverLattice
from .materials import Material

__all__ = [
    "PROBLEMS",
    "Problem",
    "cantilever",
    "fem_patch_test",
    "lattice_laplace",
    "pd_bar_stiffness",
    "pd_crack_speed",
    "pd_energy_density",
    "pd_wave_speed",
    "rayleigh_speed",
    "run_problem",
]

E_SOFT, RHO = 1.0e6, 1000.0  # the soft solid of the PD checks (docs/accuracy.md): E [Pa], rho [kg/m^3]
ZETA = 1.0e-3  # strain of the static checks [-]


# -- measuring ---------------------------------------------------------------------------------------------------------
def _status_kb(key: str) -> float | None:
    """A field of /proc/self/status in KiB (VmRSS, VmHWM), or None off Linux."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(key + ":"):
                    return float(line.split()[1])
    except OSError:
        return None
    return None


class _Meter:
    """Wall time [s] and peak resident memory [MiB] of a block. Linux: the peak (VmHWM) is reset on entry by writing
    5 to /proc/self/clear_refs, so it is the block's own peak; elsewhere the process's peak since it started. With
    several tasks in one process at once (threads) the peak is shared between them."""

    def __enter__(self):
        wp.config.quiet = True
        wp.config.log_level = wp.LOG_WARNING
        wp.init()  # Warp's start-up is not the problem's run time
        try:
            with open("/proc/self/clear_refs", "w") as f:
                f.write("5")
        except OSError:
            pass
        self.rss0 = _status_kb("VmRSS")
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.seconds = time.perf_counter() - self.t0
        peak = _status_kb("VmHWM")
        if peak is None:
            peak = float(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
        self.peak_mb = peak / 1024.0
        self.memory_mb = (peak - (self.rss0 or 0.0)) / 1024.0 if self.rss0 is not None else float("nan")
        return False


def _record(problem, method, knobs, meter, measured, reference, error, points, **extra) -> dict:
    rec = {
        "problem": problem,
        "method": method,
        "knobs": dict(knobs),
        "error": float(error),
        "measured": float(measured),
        "reference": float(reference),
        "seconds": float(meter.seconds),
        "peak_rss_mb": float(meter.peak_mb),
        "memory_mb": float(meter.memory_mb),
        "points": int(points),
    }
    rec.update(extra)
    return rec


def _check_int(name, value, lo):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo:
        raise ParameterError(name, value, f"an integer >= {lo}")
    return int(value)


def _check_choice(name, value, choices):
    if value not in choices:
        raise ParameterError(name, value, " or ".join(map(repr, choices)))
    return value


# -- peridynamics ------------------------------------------------------------------------------------------------------
def pd_wave_speed(
    n: int = 5,
    *,
    horizon_factor: float = 3.015,
    surface_correction: str = "directional",
    dt_factor: float = 0.7,
    width: float = 0.1,
    length: float = 3.0,
    pulse_width: float = 0.48,
) -> dict:
    """Speed of a longitudinal pulse in a free peridynamic bar (nu = 0) against the bar speed sqrt(E / rho).

    With nu = 0 the bar speed equals the P-wave speed and lateral inertia plays no part, so the speed isolates the
    peridynamic stiffness along the bar. A right-going Gaussian pulse of u_x (1/e half-width ``pulse_width`` [m],
    fixed so that the nonlocal dispersion falls with the horizon; 1e-4 m amplitude) starts at x = 0.8 m and travels
    1.2 m; its peak (parabola through the cross-section means) gives the speed.

    Args:
        n: particles across the square section of side ``width`` [m] (spacing h = width / n): the refinement.
        horizon_factor: m = delta / h.
        surface_correction: "directional", "family" or "none".
        dt_factor: step as a fraction of the solver's stable estimate.
        width, length: section side and bar length [m].
        pulse_width: 1/e half-width of the pulse [m].

    Returns the record (module docstring) with ``error`` = |speed / sqrt(E/rho) - 1|.
    """
    n = _check_int("n", n, 2)
    knobs = {
        "n": n,
        "horizon_factor": horizon_factor,
        "surface_correction": surface_correction,
        "dt_factor": dt_factor,
        "spacing": width / n,
    }
    with _Meter() as meter:
        mat = pdsim.Material(density=RHO, youngs_modulus=E_SOFT, poisson_ratio=0.0)
        h = width / n
        body = pdsim.PeridynamicBody(
            pdsim.box((length, width, width), center=(0.5 * length, 0.0, 0.0)),
            mat,
            h,
            horizon_factor=horizon_factor,
            surface_correction=surface_correction,
        )
        s = pdsim.SolverPeridynamics([body], device="cpu")
        c = mat.bar_wave_speed
        X = body.rest_positions[:, 0]
        x0, amp = 0.8, 1.0e-4
        g = amp * np.exp(-(((X - x0) / pulse_width) ** 2))
        u = np.zeros_like(body.rest_positions)
        u[:, 0] = g
        v = np.zeros_like(u)
        v[:, 0] = 2.0 * c * (X - x0) / pulse_width**2 * g  # u = f(x - c t): v = -c f'
        s.set_positions(body.rest_positions + u)
        s.set_velocities(v)
        xs, idx = np.unique(np.round(X, 9), return_inverse=True)
        counts = np.bincount(idx)

        def peak():
            prof = np.bincount(idx, s.positions()[:, 0] - X) / counts
            i = int(np.argmax(prof))
            a, b, cc = prof[i - 1], prof[i], prof[i + 1]
            return xs[i] + 0.5 * h * (a - cc) / (a - 2 * b + cc)

        dt = dt_factor * s.stable_time_step()
        p0, t0 = peak(), s.time
        s.simulate(dt, round(1.2 / c / dt))
        speed = (peak() - p0) / (s.time - t0)
    return _record("pd_wave_speed", "pd", knobs, meter, speed, c, abs(speed / c - 1.0), body.particle_count)


def bar_tension_modulus(mat, h, width, length, horizon_factor, surface_correction, dt_factor) -> tuple[float, int]:
    """(E_eff [Pa], particle count) of a free-sided peridynamic bar (``width`` square, ``length`` along x, spacing
    ``h`` [m]) in quasi-static tension: 3-layer grips held at the affine uniaxial-stress displacement of strain ZETA,
    the rest relaxed under damping critical for the fundamental axial mode, at ``dt_factor`` x the stable step, until
    the modulus changes by less than 1e-4 between checks. E_eff = (grip reaction / area) / (strain fitted over the
    middle third)."""
    nu = mat.poisson_ratio
    omega = math.pi * mat.bar_wave_speed / length
    body = pdsim.PeridynamicBody(
        pdsim.box((length, width, width)),
        mat,
        h,
        horizon_factor=horizon_factor,
        surface_correction=surface_correction,
        damping=omega,
    )
    X = body.rest_positions
    grip = 0.5 * length - 3.0 * h
    body.set_velocity(lambda p: np.abs(p[:, 0]) > grip, (0.0, 0.0, 0.0))  # held where they are placed
    s = pdsim.SolverPeridynamics([body], device="cpu")
    s.set_positions(X + ZETA * X * np.array([1.0, -nu, -nu]))
    dt = dt_factor * s.stable_time_step()
    right = X[:, 0] > grip
    mid = np.abs(X[:, 0]) < length / 6.0
    volumes = body.volumes

    def modulus():
        force = -(volumes[right] @ s.force_density()[right, 0])
        strain = np.polyfit(X[mid, 0], s.positions()[mid, 0] - X[mid, 0], 1)[0]
        return force / width**2 / strain

    steps = int(8.0 * length / mat.bar_wave_speed / dt)
    prev = cur = None
    for _ in range(40):
        s.simulate(dt, steps)
        cur = modulus()
        if prev is not None and abs(cur - prev) < 1.0e-4 * abs(cur):
            break
        prev = cur
    return float(cur), body.particle_count


def pd_bar_stiffness(
    n: int = 5,
    *,
    horizon_factor: float = 3.015,
    surface_correction: str = "directional",
    dt_factor: float = 0.7,
    width: float = 0.1,
    poisson_ratio: float = 0.3,
) -> dict:
    """Effective Young's modulus of a free-sided peridynamic bar in quasi-static tension against E.

    The bar (``width`` square, length 4 ``width``) has 3-layer grips held at the affine uniaxial-stress displacement of
    strain 1e-3; the rest relaxes under damping critical for the fundamental axial mode until the modulus changes by
    less than 1e-4 between checks. E_eff = (grip reaction / area) / (strain fitted over the middle third).

    Args:
        n: particles across the section (h = width / n): the refinement.
        horizon_factor, surface_correction, dt_factor: the peridynamic knobs (see :func:`pd_wave_speed`).
        width: section side [m]; poisson_ratio: nu of the material.

    Returns the record with ``error`` = |E_eff / E - 1|.
    """
    n = _check_int("n", n, 2)
    nu = poisson_ratio
    knobs = {
        "n": n,
        "horizon_factor": horizon_factor,
        "surface_correction": surface_correction,
        "dt_factor": dt_factor,
        "spacing": width / n,
    }
    with _Meter() as meter:
        mat = pdsim.Material(density=RHO, youngs_modulus=E_SOFT, poisson_ratio=nu)
        cur, count = bar_tension_modulus(
            mat, width / n, width, 4.0 * width, horizon_factor, surface_correction, dt_factor
        )
    return _record("pd_bar_stiffness", "pd", knobs, meter, cur, E_SOFT, abs(cur / E_SOFT - 1.0), count)


def pd_energy_density(
    m: float = 3.015,
    *,
    surface_correction: str = "directional",
    horizon: float = 3.015 / 8.0,
) -> dict:
    """Interior strain-energy densities against the supplement's: 9/2 kappa zeta^2 under isotropic expansion and
    1/2 mu zeta^2 under simple shear (zeta = 1e-3), averaged over particles whose families (and, for the
    directional correction, their neighbours' families) are complete.

    Args:
        m: horizon ratio delta / h at the fixed ``horizon`` delta [m] (h = delta / m): the refinement.
        surface_correction: "directional", "family" or "none".
        horizon: delta [m].

    Returns the record with ``error`` = the larger of |W_exp / ref - 1| and |W_shear / ref - 1|, and ``expansion``,
    ``shear`` and ``dilatation`` (theta / 3 zeta) ratios.
    """
    knobs = {"m": m, "surface_correction": surface_correction, "spacing": horizon / m}
    with _Meter() as meter:
        mat = pdsim.Material(density=RHO, youngs_modulus=E_SOFT, poisson_ratio=0.25)
        h = horizon / m
        reach = (2.0 if surface_correction == "directional" else 1.0) * (horizon + h)
        cells = 2 * math.ceil(reach / h) + 1
        body = pdsim.PeridynamicBody(
            pdsim.box((cells * h,) * 3), mat, h, horizon_factor=m, surface_correction=surface_correction
        )
        s = pdsim.SolverPeridynamics([body], device="cpu")
        X = body.rest_positions
        inner = np.all(np.abs(X) < 0.5 * cells * h - reach, axis=1)
        s.set_positions(X * (1.0 + ZETA))
        theta = s.dilatation()[inner].mean() / (3.0 * ZETA)
        w_exp = s.strain_energy_density()[inner].mean() / (4.5 * mat.bulk_modulus * ZETA**2)
        Y = X.copy()
        Y[:, 0] += ZETA * X[:, 1]
        s.set_positions(Y)
        w_shear = s.strain_energy_density()[inner].mean() / (0.5 * mat.shear_modulus * ZETA**2)
    error = max(abs(w_exp - 1.0), abs(w_shear - 1.0))
    return _record(
        "pd_energy_density",
        "pd",
        knobs,
        meter,
        1.0 + (w_exp - 1.0 if abs(w_exp - 1.0) >= abs(w_shear - 1.0) else w_shear - 1.0),
        1.0,
        error,
        body.particle_count,
        expansion=float(w_exp),
        shear=float(w_shear),
        dilatation=float(theta),
    )


def rayleigh_speed(youngs_modulus: float, poisson_ratio: float, density: float, *, plane_stress: bool = False):
    """Rayleigh surface-wave speed c_R [m/s]: the root in (0, c_s) of (2 - xi)^2 = 4 sqrt(1 - xi k) sqrt(1 - xi),
    xi = (c / c_s)^2, k = (c_s / c_d)^2, with c_d the P-wave speed (3D and plane strain) or the plate speed
    sqrt(E / (rho (1 - nu^2))) (plane stress: a thin plate)."""
    mu = youngs_modulus / (2.0 * (1.0 + poisson_ratio))
    cs = math.sqrt(mu / density)
    if plane_stress:
        cd = math.sqrt(youngs_modulus / (density * (1.0 - poisson_ratio**2)))
    else:
        lam = youngs_modulus * poisson_ratio / ((1.0 + poisson_ratio) * (1.0 - 2.0 * poisson_ratio))
        cd = math.sqrt((lam + 2.0 * mu) / density)
    k = (cs / cd) ** 2

    def f(xi):
        return (2.0 - xi) ** 2 - 4.0 * math.sqrt(1.0 - xi * k) * math.sqrt(1.0 - xi)

    lo, hi = 1.0e-6, 1.0  # f(lo) < 0 < f(hi) = 1 (xi = 0 is the trivial root)
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) < 0.0 else (lo, mid)
    return cs * math.sqrt(0.5 * (lo + hi))


# The peridynamic problems share their knobs (horizon_factor, surface_correction, dt_factor) as keyword arguments of
# the same names and defaults: the sweep reads each problem's knobs from its signature.
def pd_crack_speed(
    n: int = 40,
    *,
    horizon_factor: float = 3.015,
    surface_correction: str = "directional",
    dt_factor: float = 0.7,
    overdrive: float = 1.5,
    fracture_energy: float = 2.0,
) -> dict:
    """A mode-I crack running in a pre-stretched strip (thin plate, plane stress) against the Rayleigh speed.

    The strip (0.1 m along x, H = 0.05 m along y, 3 particles thick) is stretched along y by a strain eps with its
    top and bottom 3 layers held (fixed grips) and a notch from its left edge to x = -0.025 m on y = 0; it is
    released from rest. eps makes the static energy release rate of a long strip in fixed grips,
    W0 H = E eps^2 H / (2 (1 - nu^2)), ``overdrive`` times the fracture energy, so the crack runs; continuum theory
    bounds its speed by the Rayleigh speed c_R (plane stress). eps must stay below the bonds' critical stretch
    (which grows as the horizon shrinks), else the strip fails everywhere at once: at the defaults eps = 0.011 and
    s_c = 0.015 (n = 20), 0.018 (n = 30). The tip is the largest x among particles within 1.5 h of
    y = 0 with damage over 0.35 in an unbroken run of x slices from the notch (damage that nucleates ahead is not
    the tip), sampled every quarter spacing of travel at c_R; ``measured`` is the highest speed over a sliding tenth of
    the strip's length.

    Args:
        n: particles across H (h = H / n): the refinement.
        horizon_factor, surface_correction, dt_factor: the peridynamic knobs.
        overdrive: W0 H / G0 [-]; fracture_energy: G0 [J/m^2].

    Returns the record with ``measured`` = the peak tip speed [m/s], ``reference`` = c_R [m/s], ``speed_ratio``,
    ``mean_speed_ratio`` (the tip's mean speed over its run over c_R), ``crack_length`` [m], and ``error`` =
    max(0, speed_ratio - 1): zero while the bound holds (this problem checks a bound; it has no reference value).
    """
    n = _check_int("n", n, 10)
    nu = 0.25
    length, height = 0.1, 0.05
    knobs = {
        "n": n,
        "horizon_factor": horizon_factor,
        "surface_correction": surface_correction,
        "dt_factor": dt_factor,
        "spacing": height / n,
    }
    strain = math.sqrt(2.0 * (1.0 - nu**2) * overdrive * fracture_energy / (E_SOFT * height))
    with _Meter() as meter:
        h = height / n
        mat = pdsim.Material(density=RHO, youngs_modulus=E_SOFT, poisson_ratio=nu, fracture_energy=fracture_energy)
        body = pdsim.PeridynamicBody(
            pdsim.box((length, height, 3.0 * h)),
            mat,
            h,
            horizon_factor=horizon_factor,
            surface_correction=surface_correction,
        )
        X = body.rest_positions
        tip0 = -0.25 * length
        body.add_notch(pdsim.BoxRegion((-length, -0.1 * h, -1.0), (tip0, 0.1 * h, 1.0)))

        def grips(p):
            return np.abs(p[:, 1]) > 0.5 * height - 3.0 * h

        body.set_velocity(grips, (0.0, 0.0, 0.0))  # held where they are placed
        body.set_unbreakable(grips)
        s = pdsim.SolverPeridynamics([body], device="cpu")
        u = np.zeros_like(X)
        u[:, 1] = strain * X[:, 1]
        s.set_displacements(u)
        cr = rayleigh_speed(E_SOFT, nu, RHO, plane_stress=True)
        dt = dt_factor * s.stable_time_step()
        line = np.abs(X[:, 1]) < 1.5 * h
        column = np.round((X[line, 0] - X[:, 0].min()) / h).astype(np.int64)  # x slice of each line particle
        slice_x = np.bincount(column, X[line, 0]) / np.maximum(np.bincount(column), 1)
        first = int(np.searchsorted(slice_x, tip0))  # the first slice ahead of the notch

        def tip():
            broken = np.bincount(column, s.damage()[line] > 0.35, minlength=len(slice_x)) > 0
            ahead = np.flatnonzero(~broken[first:])
            last = first + (ahead[0] if len(ahead) else len(slice_x) - first) - 1
            return max(tip0, float(slice_x[last])) if last >= first else tip0

        batch = max(1, round(0.25 * h / cr / dt))  # the tip moves at most a quarter spacing per batch
        times, tips = [0.0], [tip0]
        t_end = 3.0 * length / cr
        while s.time < t_end and tips[-1] < 0.5 * length - 4.0 * h:
            s.simulate(dt, batch)
            tips.append(tip())
            times.append(s.time)
        times, tips = np.array(times), np.array(tips)
        span = 0.1 * length
        speeds = [
            (tips[j] - tips[i]) / (times[j] - times[i])
            for i in range(len(tips))
            for j in [int(np.searchsorted(tips, tips[i] + span))]
            if j < len(tips) and tips[i] > tip0
        ]
        peak = max(speeds) if speeds else 0.0
        moved = tips > tip0
        mean = (tips[-1] - tips[moved][0]) / (times[-1] - times[moved][0]) if moved.sum() > 1 else 0.0
    ratio = peak / cr
    return _record(
        "pd_crack_speed",
        "pd",
        knobs,
        meter,
        peak,
        cr,
        max(0.0, ratio - 1.0),
        body.particle_count,
        speed_ratio=float(ratio),
        mean_speed_ratio=float(mean / cr),
        crack_length=float(tips[-1] - tip0),
    )


# -- cantilever (both methods) -----------------------------------------------------------------------------------------
CANTILEVER_T = 0.06  # square section side t [m]
CANTILEVER_L = 8.0 * CANTILEVER_T  # free length [m]
CANTILEVER_F = -1.0e-3  # tip force along z [N]
RELAX_PERIODS = 1.5  # damped runs to rest: periods of the first bending mode


def _timoshenko(arm: float, shear_modulus: float) -> float:
    """Tip deflection [m] of the cantilever under CANTILEVER_F at lever ``arm`` [m]: F a^3 / (3 E I) + F a / (k G A),
    k = 5/6 (Cowper's 10 (1 + nu) / (12 + 11 nu) at nu = 0)."""
    t = CANTILEVER_T
    inertia, area = t**4 / 12.0, t * t
    return CANTILEVER_F * arm**3 / (3.0 * E_SOFT * inertia) + CANTILEVER_F * arm / (5.0 / 6.0 * shear_modulus * area)


def cantilever(
    n: int = 4,
    *,
    method: str = "fem",
    measure: str = "linear",
    integrator: str | None = None,
    precision: str = "float64",
    horizon_factor: float = 3.015,
    surface_correction: str = "directional",
    dt_factor: float = 0.7,
) -> dict:
    """Tip deflection of a cantilever under a tip force against Timoshenko's beam, by the FEM or peridynamics.

    The beam: square section t = 0.06 m, free length L = 8 t, E = 1 MPa, nu = 0 (beam theory's plane sections hold
    at a clamped face), rho = 1000 kg/m^3, tip force 1e-3 N down (z). FEM: (8 n) x n x n cells of six linear
    tetrahedra, clamped on the x = 0 face, the force as a shear traction on the x = L face, lever arm L. PD: spacing
    t / n, 3 extra layers behind the clamp face held by ``fix``, the force on the last layer, lever arm L - h/2 (to
    the loaded layer's centre). The deflection is the loaded face's (layer's) mean z displacement. Dynamic runs are
    damped at 2 omega_1 (critical for the first bending mode) for 1.5 of its periods (the first mode's residual,
    (1 + 3 pi) exp(-3 pi), is 8e-4).

    Args:
        n: elements (FEM cells) or particles (PD) through the thickness: the refinement.
        method: "fem" or "pd".
        measure: FEM strain measure "linear", "corotated" or "green".
        integrator: FEM: "static" (Newton-CG quasi-static solve; the default), "explicit" or "implicit" (damped
            dynamics to rest; the implicit step is the body's implicit_step_ratio, 10, times the explicit limit).
            PD: "explicit" (the default and only one).
        precision: FEM "float64" or "float32" (PD is float32).
        horizon_factor, surface_correction, dt_factor: the PD knobs; dt_factor also scales the FEM explicit step
            (a fraction of its stable step).

    Returns the record with ``error`` = |deflection / Timoshenko - 1| and ``steps`` (0 for a static solve).
    """
    n = _check_int("n", n, 1)
    _check_choice("method", method, ("fem", "pd"))
    t, L = CANTILEVER_T, CANTILEVER_L
    if method == "fem":
        integrator = integrator or "static"
        _check_choice("integrator", integrator, ("static", "explicit", "implicit"))
        knobs = {"n": n, "measure": measure, "integrator": integrator, "precision": precision, "spacing": t / n}
        if integrator == "explicit":
            knobs["dt_factor"] = dt_factor
    else:
        integrator = integrator or "explicit"
        _check_choice("integrator", integrator, ("explicit",))
        knobs = {
            "n": n,
            "horizon_factor": horizon_factor,
            "surface_correction": surface_correction,
            "dt_factor": dt_factor,
            "spacing": t / n,
        }
    mat = pdsim.Material(density=RHO, youngs_modulus=E_SOFT, poisson_ratio=0.0)
    omega1 = 1.875**2 * math.sqrt(E_SOFT * t**2 / 12.0 / RHO) / L**2
    steps = 0
    with _Meter() as meter:
        if method == "fem":
            mesh = box_tet_mesh((L, t, t), (8 * n, n, n), center=(0.5 * L, 0.0, 0.0))
            dynamic = integrator != "static"
            body = FemBody(
                mesh,
                mat,
                measure=measure,
                integrator="implicit" if integrator == "implicit" else "explicit",
                damping=2.0 * omega1 if dynamic else 0.0,
                name="beam",
            )
            body.fix(pdsim.BoxRegion((-1.0, -1.0, -1.0), (1.0e-9, 1.0, 1.0)), name="clamp")
            end = pdsim.BoxRegion((L - 1.0e-9, -1.0, -1.0), (L + 1.0e-9, 1.0, 1.0))
            body.add_traction(end, (0.0, 0.0, CANTILEVER_F / t**2))
            solver = SolverFem([body], device="cpu", gravity=(0.0, 0.0, 0.0), precision=precision)
            if dynamic:
                dt = solver.stable_time_step() * (1.0 if integrator == "implicit" else dt_factor)
                steps = math.ceil(RELAX_PERIODS * 2.0 * math.pi / omega1 / dt)
                solver.simulate(dt, steps)
            else:
                tol = 1.0e-10 if precision == "float64" else 1.0e-6
                solver.solve_static(tolerance=tol, cg_tolerance=tol)
            tip = np.isclose(mesh.vertices[:, 0], L)
            deflection = float(solver.displacements()[tip, 2].mean())
            arm, points = L, mesh.vertex_count
        else:
            h = t / n
            total = L + 3.0 * h
            body = pdsim.PeridynamicBody(
                pdsim.box((total, t, t), center=(0.5 * L - 1.5 * h, 0.0, 0.0)),
                mat,
                h,
                horizon_factor=horizon_factor,
                surface_correction=surface_correction,
                damping=2.0 * omega1,
                name="beam",
            )
            body.fix(pdsim.HalfSpace((0.0, 0.0, 0.0), (-1.0, 0.0, 0.0)), name="clamp")
            loaded = pdsim.HalfSpace((L - h, 0.0, 0.0), (1.0, 0.0, 0.0))
            body.add_force(loaded, (0.0, 0.0, CANTILEVER_F))
            solver = pdsim.SolverPeridynamics([body], device="cpu")
            dt = dt_factor * solver.stable_time_step()
            steps = math.ceil(RELAX_PERIODS * 2.0 * math.pi / omega1 / dt)
            solver.simulate(dt, steps)
            deflection = float(solver.displacements()[loaded.contains(body.rest_positions), 2].mean())
            arm, points = L - 0.5 * h, body.particle_count
    reference = _timoshenko(arm, mat.shear_modulus)
    return _record(
        "cantilever",
        method,
        knobs,
        meter,
        deflection,
        reference,
        abs(deflection / reference - 1.0),
        points,
        steps=int(steps),
    )


# -- FEM patch test ----------------------------------------------------------------------------------------------------
_PATCH_GRAD = np.array([[1.0e-3, 2.0e-3, -1.0e-3], [0.5e-3, -2.0e-3, 1.0e-3], [3.0e-3, 1.0e-3, 2.0e-3]])


def fem_patch_test(n: int = 3, *, measure: str = "linear", precision: str = "float64") -> dict:
    """Patch test: a unit cube of n^3 cells cut into tetrahedra, interior vertices moved randomly by up to 0.25 cell,
    has the affine displacement u = A X (a general gradient, |A| ~ 3e-3) imposed on its boundary; the static solve
    must reproduce it at every interior vertex. Linear tetrahedra pass it exactly at any resolution (the error is
    round-off: no rate; the corotated and Green measures pass it too, a uniform F giving a uniform stress).

    Args:
        n: cells per edge (>= 3 so there are interior vertices): the refinement.
        measure: "linear", "corotated" or "green"; precision: "float64" or "float32".

    Returns the record with ``error`` = max interior |u - A X| / max |A X|.
    """
    n = _check_int("n", n, 3)
    knobs = {"n": n, "measure": measure, "precision": precision, "spacing": 1.0 / n}
    with _Meter() as meter:
        mesh = box_tet_mesh((1.0, 1.0, 1.0), (n, n, n), jitter=0.25, seed=1)
        boundary = np.zeros(mesh.vertex_count, dtype=bool)
        boundary[mesh.boundary_faces().ravel()] = True
        X = mesh.vertices
        U = X @ _PATCH_GRAD.T
        mat = Material(density=RHO, youngs_modulus=E_SOFT, poisson_ratio=0.3)
        solver = SolverFem([FemBody(mesh, mat, measure=measure)], device="cpu", precision=precision)
        x0 = X.copy()
        x0[boundary] += U[boundary]
        solver.set_positions(x0)
        tol = 1.0e-14 if precision == "float64" else 1.0e-7
        solver.solve_static(constrained=boundary, tolerance=tol, cg_tolerance=tol)
        err = float(np.abs(solver.positions() - (X + U))[~boundary].max() / np.abs(U).max())
    return _record("fem_patch_test", "fem", knobs, meter, err, 0.0, err, mesh.vertex_count)


# -- lattice -----------------------------------------------------------------------------------------------------------
def lattice_laplace(n: int = 9, *, lattice: str = "square", gradient: int = 1, amplitude: float = 1.0e-3) -> dict:
    """The lattice's centroid rule against its continuum limit, Laplace's equation.

    At rest the centroid rule says u_j = mean of its neighbours' u_k: a symmetric stencil's discrete Laplacian of u
    vanishes, so as the spacing h -> 0 each displacement component tends to a harmonic function fixed by the
    leaders (lattice steps are Jacobi sweeps). A block of points (side about 1 m, h = 1 / (n - 1); the hexagonal
    lattice's rows are sqrt(3)/2 h apart) has its outer ``gradient`` rows held as leaders at
    u_x = a exp(pi (x - 1)) sin(pi y) (harmonic; u_y = u_z = 0) and the rest relaxed from zero until the moves still
    to come (the geometric tail of the last steps' moves) are below 1 % of the error at two checks running, or the
    moves reach float32 round-off.

    Args:
        n: points per row: the refinement.
        lattice: "square" or "hexagonal" (rows of the hexagonal lattice are sqrt(3)/2 h apart).
        gradient: 1 (first-gradient neighbourhood) or 2 (second gradient: two shells, two leader rows).
        amplitude: a [m].

    Returns the record with ``error`` = max |u - u_exact| / a over the followers, and ``steps``.
    """
    n = _check_int("n", n, 5)
    _check_choice("lattice", lattice, ("square", "hexagonal"))
    _check_choice("gradient", gradient, (1, 2))
    knobs = {"n": n, "lattice": lattice, "gradient": gradient, "spacing": 1.0 / (n - 1)}
    with _Meter() as meter:
        h = 1.0 / (n - 1)
        lat = Lattice.square(h) if lattice == "square" else Lattice.hexagonal(h)
        rows = n if lattice == "square" else round(1.0 / (h * math.sqrt(0.75))) + 1
        body = LatticeBody.block(
            lat, (n, rows), neighbourhood=LatticeNeighbourhood(gradient=gradient), frame_layers=0, name="plate"
        )
        nb = body.body_count
        X = body.rest_positions[:nb] - body.rest_positions[:nb].min(axis=0)
        span = X.max(axis=0)
        row_h = span[1] / (rows - 1)
        edge = gradient * (1.0 + 1.0e-6)
        ring = (
            (X[:, 0] < edge * h)
            | (X[:, 0] > span[0] - edge * h)
            | (X[:, 1] < edge * row_h)
            | (X[:, 1] > span[1] - edge * row_h)
        )
        exact = np.zeros((body.particle_count, 3))
        exact[:nb, 0] = amplitude * np.exp(math.pi * (X[:, 0] - 1.0)) * np.sin(math.pi * X[:, 1])
        body.change_kind(ring, LatticeKind.LEADER, at_step=1)
        solver = SolverLattice([body], device="cpu")
        u0 = np.zeros_like(exact)
        u0[:nb][ring] = exact[:nb][ring]
        solver.set_displacements(u0)
        inner = np.flatnonzero(~ring)
        chunk = max(10, n)
        prev_change = None
        steps = settled = 0
        while steps < 100 * n * n:
            solver.run_steps(chunk)
            steps += chunk
            change = float(solver.pe2()[inner].max())  # the last step's largest move [m]
            err = float(np.abs(solver.displacements()[inner, 0] - exact[inner, 0]).max())
            if change <= 1.0e-7 * amplitude:  # float32 round-off of the displacements
                break
            if prev_change is not None and change < prev_change:
                rho = (change / prev_change) ** (1.0 / chunk)  # Jacobi contraction per step
                remaining = change * rho / max(1.0 - rho, 1.0e-12)  # geometric tail of the moves still to come
                settled = settled + 1 if remaining < 0.01 * err else 0
                if settled == 2:
                    break
            prev_change = change
    return _record(
        "lattice_laplace",
        "lattice",
        knobs,
        meter,
        err / amplitude,
        0.0,
        err / amplitude,
        body.particle_count,
        steps=steps,
    )


# -- registry ----------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Problem:
    """A validation problem: its function, the name of its refinement knob (the function's first argument), default
    refinement levels (cheapest first; tools/accuracy_map.py has its own plan), the reference answer in words, and
    default variants (dicts of knobs besides the refinement) for a quick sweep of its knobs."""

    name: str
    function: Callable[..., dict]
    refinement: str
    levels: tuple
    reference: str
    variants: tuple = field(default_factory=tuple)  # dicts of knobs, each swept over all levels


PROBLEMS: dict[str, Problem] = {
    p.name: p
    for p in (
        Problem(
            "pd_wave_speed",
            pd_wave_speed,
            "n",
            (4, 5, 7, 10),
            "bar speed sqrt(E/rho) (nu = 0)",
            (
                {"surface_correction": "directional"},
                {"surface_correction": "none"},
                {"surface_correction": "directional", "horizon_factor": 4.015},
                {"surface_correction": "directional", "dt_factor": 0.35},
            ),
        ),
        Problem(
            "pd_bar_stiffness",
            pd_bar_stiffness,
            "n",
            (4, 5, 7, 10),
            "Young's modulus E (uniaxial stress)",
            ({"surface_correction": "directional"}, {"surface_correction": "none"}),
        ),
        Problem(
            "pd_energy_density",
            pd_energy_density,
            "m",
            (3.015, 4.02, 5.025),
            "9/2 kappa zeta^2 (expansion), 1/2 mu zeta^2 (shear)",
            ({"surface_correction": "directional"}, {"surface_correction": "none"}),
        ),
        Problem(
            "pd_crack_speed",
            pd_crack_speed,
            "n",
            (20, 30),
            "bound: Rayleigh speed (plane stress)",
            ({"surface_correction": "directional"},),
        ),
        Problem(
            "cantilever",
            cantilever,
            "n",
            (2, 3, 4, 6, 8),
            "Timoshenko beam, F a^3 / 3EI + F a / kGA",
            (
                {"method": "fem", "measure": "linear", "integrator": "static", "precision": "float64"},
                {"method": "fem", "measure": "corotated", "integrator": "static", "precision": "float32"},
                {"method": "fem", "measure": "corotated", "integrator": "implicit", "precision": "float32"},
                {"method": "pd", "surface_correction": "directional"},
            ),
        ),
        Problem(
            "fem_patch_test",
            fem_patch_test,
            "n",
            (3, 5),
            "the imposed affine field (exact)",
            ({"measure": "linear", "precision": "float64"}, {"measure": "corotated", "precision": "float64"}),
        ),
        Problem(
            "lattice_laplace",
            lattice_laplace,
            "n",
            (9, 17, 33),
            "harmonic u_x = a exp(pi (x - 1)) sin(pi y)",
            ({"lattice": "square", "gradient": 1}, {"lattice": "square", "gradient": 2}),
        ),
    )
}


def run_problem(problem: str | Callable[..., dict], *args, **knobs) -> dict:
    """Runs one problem (a name in ``PROBLEMS`` or a problem function) with the given knobs; returns its record."""
    if isinstance(problem, str):
        if problem not in PROBLEMS:
            raise ParameterError("problem", problem, "one of " + ", ".join(sorted(PROBLEMS)))
        problem = PROBLEMS[problem].function
    if not callable(problem):
        raise ParameterError("problem", problem, "a problem name or a function returning a record")
    return problem(*args, **knobs)


def machine() -> str:
    """One line naming the CPU, the core count, Python and Warp (for the headers of generated docs)."""
    cpu = platform.processor() or "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, Warp {wp.__version__}, CPU backend"
