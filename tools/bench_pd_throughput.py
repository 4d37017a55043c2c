"""Peridynamic step throughput of pdsim, in bond visits per second, beside LAMMPS ``peri/lps`` on the same block.

Builds an ``n^3`` simple cubic block (spacing h = 1 mm, E = 1 GPa, nu = 0.25, rho = 1000 kg/m^3, family cut at
delta = horizon_factor * h with full volumes, exactly as ``tools/lammps_peri.py`` sets up LAMMPS), gives it small random
velocities, warms up, then times ``steps`` calls of ``SolverPeridynamics.step`` (kick-drift, dilatation, force
density, kick: the full step). A bond visit is one directed bond processed in one step, so

    bond_visits_per_s = bond_count * steps / seconds

where bond_count is the number of directed bonds (the sum of the family sizes, LAMMPS's ``total # of bonds``).
When LAMMPS (``lmp``) is present it runs ``peri/lps`` on the same block in the same invocation and the ratio
pdsim / LAMMPS is reported; both run on one core (Warp runs CPU kernels on one thread; LAMMPS with one process and
``OMP_NUM_THREADS=1``).

``--plastic`` gives the material a yield stress (YIELD_STRESS; the return mapping runs every step and LAMMPS runs
``peri/eps`` with the same yield stress instead of ``peri/lps``); ``--fracture`` gives it a critical stretch of 1
(no bond breaks, but every bond is tested every step, as LAMMPS does with its s00 = 1), so the cost of each feature
shows beside the elastic step.

``--breakdown`` also times each kernel of the step on its own (every launch followed by a device synchronisation, so
the shares add up to slightly more than the plain step).

Script use::

    python tools/bench_pd_throughput.py --n 25 --steps 200
    python tools/bench_pd_throughput.py --n 25 --steps 200 --json --breakdown
"""

from __future__ import annotations

import argparse
import datetime
import importlib.util
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

SPACING = 1.0e-3
"""Lattice spacing h [m] (the LAMMPS runner's default)."""

YOUNGS_MODULUS = 1.0e9
"""[Pa], the LAMMPS runner's default."""

POISSON_RATIO = 0.25
"""[-], the LAMMPS runner's default."""

DENSITY = 1000.0
"""[kg/m^3], the LAMMPS runner's default."""

YIELD_STRESS = 1.0e6
"""[Pa] for --plastic (and LAMMPS peri/eps)."""

VELOCITY_AMPLITUDE = 0.1
"""Half-width of the uniform random initial velocity per component [m/s] (as the LAMMPS runner)."""

TIME_STEP_SAFETY = 0.5
"""dt = TIME_STEP_SAFETY * SolverPeridynamics.stable_time_step()."""


def _load_lammps_runner():
    """Imports tools/lammps_peri.py (a sibling script, not a package module); None if it cannot be loaded."""
    path = Path(__file__).resolve().parent / "lammps_peri.py"
    try:
        import lammps_peri  # found when run as a script: tools/ is on sys.path

        return lammps_peri
    except ImportError:
        pass
    if not path.exists():
        return None
    spec = importlib.util.spec_from_file_location("lammps_peri", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def cpu_model() -> str:
    """CPU model name from /proc/cpuinfo (falls back to platform.processor())."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def kernel_source_digest() -> str:
    """Short SHA-1 of the step's kernel sources (pd_bonds.py, integration.py): identifies the code that was timed."""
    import hashlib

    from pdsim.kernels import integration
    from pdsim.kernels.peridynamics import bonds as pd_bonds

    digest = hashlib.sha1()
    for module in (pd_bonds, integration):
        digest.update(Path(module.__file__).read_bytes())
    return digest.hexdigest()[:12]


def machine_info(device) -> dict:
    """CPU model, core count, load average, Warp version, device name, Python version and the date (UTC)."""
    import warp as wp

    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        load = None
    return {
        "cpu_model": cpu_model(),
        "cpu_cores": os.cpu_count(),
        "load_average": load,
        "warp_version": wp.config.version,
        "device": str(device),
        "device_name": device.name,
        "python_version": platform.python_version(),
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
    }


def build_solver(n: int, *, horizon_factor: float, device: str, seed: int = 0, plastic=False, fracture=False):
    """The benchmark block: n^3 particles, families cut at delta (no partial volumes), random velocities."""
    import pdsim

    material = pdsim.Material(
        density=DENSITY,
        youngs_modulus=YOUNGS_MODULUS,
        poisson_ratio=POISSON_RATIO,
        yield_stress=YIELD_STRESS if plastic else None,
        critical_stretch=1.0 if fracture else None,
    )
    shape = pdsim.box((n * SPACING,) * 3)
    body = pdsim.PeridynamicBody(shape, material, SPACING, horizon_factor=horizon_factor, partial_volumes=False)
    solver = pdsim.SolverPeridynamics([body], device=device)
    rng = np.random.default_rng(seed)
    velocities = rng.uniform(-VELOCITY_AMPLITUDE, VELOCITY_AMPLITUDE, size=(solver.model.particle_count, 3))
    solver.set_velocities(velocities)
    return solver


def time_steps(solver, dt: float, steps: int) -> float:
    """Wall time [s] of ``steps`` solver steps, synchronising the device before reading the clock at both ends."""
    import warp as wp

    wp.synchronize_device(solver.device)
    start = time.perf_counter()
    for _ in range(steps):
        solver.step(dt)
    wp.synchronize_device(solver.device)
    return time.perf_counter() - start


def time_kernels(solver, dt: float, steps: int) -> dict[str, float]:
    """Seconds spent in each kernel over ``steps`` steps: wraps ``warp.launch`` so that every launch made by the
    solver is synchronised and timed on its own (the solver's own launch arguments are used unchanged)."""
    import warp as wp

    totals: dict[str, float] = {}
    original = wp.launch

    def timed_launch(kernel, *args, **kwargs):
        device = kwargs.get("device") or solver.device
        wp.synchronize_device(device)
        start = time.perf_counter()
        result = original(kernel, *args, **kwargs)
        wp.synchronize_device(device)
        key = getattr(kernel, "key", str(kernel))
        totals[key] = totals.get(key, 0.0) + time.perf_counter() - start
        return result

    wp.launch = timed_launch
    try:
        for _ in range(steps):
            solver.step(dt)
    finally:
        wp.launch = original
    return totals


def run_benchmark(
    n: int,
    steps: int,
    *,
    device: str = "cpu",
    horizon_factor: float = 3.015,
    warmup: int = 3,
    repeat: int = 1,
    lammps: bool = True,
    breakdown: bool = False,
    seed: int = 0,
    plastic: bool = False,
    fracture: bool = False,
) -> dict:
    """Times pdsim (and LAMMPS peri/lps when present and ``lammps``) on an n^3 block; returns the figures as a dict."""
    import warp as wp

    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_WARNING  # Warp >= 1.12: no banner or module-load lines
    else:
        wp.config.quiet = True
    wp.init()
    dev = wp.get_device(device)
    start = time.perf_counter()
    solver = build_solver(
        n, horizon_factor=horizon_factor, device=device, seed=seed, plastic=plastic, fracture=fracture
    )
    wp.synchronize_device(dev)
    setup_seconds = time.perf_counter() - start  # includes module loads (compile on a cold kernel cache)
    dt = TIME_STEP_SAFETY * solver.stable_time_step()
    for _ in range(warmup):
        solver.step(dt)
    runs = [time_steps(solver, dt, steps) for _ in range(max(1, repeat))]
    seconds = min(runs)
    particles = solver.model.particle_count
    bonds = solver.model.bond_count
    x = solver.positions()
    result = {
        "particles": particles,
        "bonds": bonds,
        "bonds_per_particle": bonds / particles,
        "steps": steps,
        "seconds": seconds,
        "seconds_all_runs": runs,
        "ms_per_step": 1.0e3 * seconds / steps if steps else float("nan"),
        "bond_visits_per_s": bonds * steps / seconds if seconds > 0 else float("nan"),
        "dt": dt,
        "horizon_factor": horizon_factor,
        "setup_seconds": setup_seconds,
        "finite": bool(np.all(np.isfinite(x))),
        "surface_correction": solver.bodies[0].surface_correction,
        "features": sorted(solver.features),
        "kernel_source_sha1": kernel_source_digest(),
        **machine_info(dev),
    }
    if breakdown:
        kernel_steps = max(1, min(steps, 100))
        totals = time_kernels(solver, dt, kernel_steps)
        result["kernel_steps"] = kernel_steps
        result["kernel_ms_per_step"] = {k: 1.0e3 * v / kernel_steps for k, v in totals.items()}
        result["kernel_bond_visits_per_s"] = {k: bonds * kernel_steps / v for k, v in totals.items() if v > 0}

    runner = _load_lammps_runner() if lammps else None
    if runner is not None and runner.lammps_available():
        ref = runner.run_lammps_peri(
            n,
            steps,
            style="eps" if plastic else "lps",
            yield_stress=YIELD_STRESS if plastic else None,
            horizon_factor=horizon_factor,
            spacing=SPACING,
            youngs_modulus=YOUNGS_MODULUS,
            poisson_ratio=POISSON_RATIO,
            density=DENSITY,
        )
        result.update(
            {
                "lammps_style": ref["style"],
                "lammps_version": ref["lammps_version"],
                "lammps_particles": ref["particles"],
                "lammps_bonds": ref["bonds"],
                "lammps_seconds": ref["seconds"],
                "lammps_pair_seconds": ref["pair_seconds"],
                "lammps_ms_per_step": 1.0e3 * ref["seconds"] / steps if steps else float("nan"),
                "lammps_bond_visits_per_s": ref["bond_visits_per_s"],
                "bonds_match": ref["bonds"] == bonds and ref["particles"] == particles,
                "ratio": result["bond_visits_per_s"] / ref["bond_visits_per_s"],
            }
        )
    elif lammps:
        result["lammps_note"] = "LAMMPS (lmp with peri/lps) not found; no reference run"
    return result


def format_text(r: dict) -> str:
    """Human-readable report of ``run_benchmark``'s result."""
    n_edge = round(r["particles"] ** (1 / 3))
    lines = [
        f"machine   : {r['cpu_model']}, {r['cpu_cores']} cores, load {r['load_average']}; device {r['device']} "
        + f"({r['device_name']}); warp {r['warp_version']}; python {r['python_version']}; {r['date']}",
        f"block     : {n_edge}^3 = {r['particles']} particles, delta = {r['horizon_factor']} h, "
        + f"{r['bonds']} directed bonds ({r['bonds_per_particle']:.1f} per particle)",
        f"features  : {', '.join(r['features'])}",
        f"pdsim     : {r['steps']} steps in {r['seconds']:.3f} s = {r['ms_per_step']:.3f} ms/step, "
        + f"{r['bond_visits_per_s'] / 1e6:.1f} M bond visits/s (dt {r['dt']:.3g} s, setup {r['setup_seconds']:.2f} s)",
    ]
    if len(r["seconds_all_runs"]) > 1:
        runs = ", ".join(f"{t:.3f}" for t in r["seconds_all_runs"])
        lines.append(f"            fastest of {len(r['seconds_all_runs'])} timings: {runs} s")
    if "kernel_ms_per_step" in r:
        total = sum(r["kernel_ms_per_step"].values())
        for key, ms in sorted(r["kernel_ms_per_step"].items(), key=lambda kv: -kv[1]):
            rate = r["kernel_bond_visits_per_s"].get(key, float("nan")) / 1e6
            lines.append(
                f"  kernel  {key:<28s} {ms:8.3f} ms/step {100 * ms / total:5.1f} %  ({rate:.0f} M bonds/s alone)"
            )
    if "lammps_seconds" in r:
        lines.append(
            f"LAMMPS    : peri/{r['lammps_style']} ({r['lammps_version']}), {r['lammps_particles']} particles, "
            f"{r['lammps_bonds']} bonds, {r['lammps_seconds']:.3f} s = {r['lammps_ms_per_step']:.3f} ms/step, "
            f"{r['lammps_bond_visits_per_s'] / 1e6:.1f} M bond visits/s"
        )
        match = "match" if r["bonds_match"] else "MISMATCH"
        lines.append(f"bonds     : pdsim {r['bonds']} vs LAMMPS {r['lammps_bonds']} ({match})")
        lines.append(f"ratio     : pdsim / LAMMPS = {r['ratio']:.2f}")
    elif "lammps_note" in r:
        lines.append(f"LAMMPS    : {r['lammps_note']}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=25, help="particles per edge (the block holds n^3)")
    parser.add_argument("--steps", type=int, default=200, help="timed steps")
    parser.add_argument("--device", default="cpu", help="Warp device (cpu, cuda, cuda:0, ...)")
    parser.add_argument("--horizon-factor", type=float, default=3.015, help="delta / h")
    parser.add_argument("--warmup", type=int, default=3, help="untimed steps before timing (after kernel loads)")
    parser.add_argument("--repeat", type=int, default=1, help="time the steps this many times and keep the fastest")
    parser.add_argument("--breakdown", action="store_true", help="also time each kernel of the step on its own")
    parser.add_argument("--no-lammps", action="store_true", help="skip the LAMMPS peri/lps reference run")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random initial velocities")
    parser.add_argument("--json", action="store_true", help="print one JSON line instead of text")
    parser.add_argument("--plastic", action="store_true", help="yielding material (LAMMPS runs peri/eps)")
    parser.add_argument("--fracture", action="store_true", help="breakable bonds (critical stretch 1: none breaks)")
    args = parser.parse_args(argv)
    if args.n < 1 or args.steps < 1:
        parser.error("--n and --steps must be >= 1")
    result = run_benchmark(
        args.n,
        args.steps,
        device=args.device,
        horizon_factor=args.horizon_factor,
        warmup=args.warmup,
        repeat=args.repeat,
        lammps=not args.no_lammps,
        breakdown=args.breakdown,
        seed=args.seed,
        plastic=args.plastic,
        fracture=args.fracture,
    )
    print(json.dumps(result) if args.json else format_text(result))
    if result.get("bonds_match") is False:
        print("warning: pdsim and LAMMPS bond counts differ; the blocks are not the same", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
