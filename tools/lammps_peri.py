"""Reference timings from LAMMPS's PERI package on a simple cubic block of particles.

Builds an ``n^3`` block (``lattice sc``), runs ``pair_style peri/lps``, ``peri/pmb`` or ``peri/eps`` with
``fix nve`` on one process and one thread, and reads the loop time and the peridynamic family size from the log.

Bond count convention: LAMMPS's ``fix PERI_NEIGH`` prints ``total # of bonds``, the sum over particles of the
family size (a pair ``i``-``j`` counts once for ``i`` and once for ``j``), built once at setup with
``r^2 <= horizon^2``. That is the number a CSR family list holds, and it is what ``bonds`` returns. The
``Total # of neighbors`` line is *not* used: it is the occasional full neighbour list at horizon + skin, so it
counts pairs out to the skin as well.

Script use::

    python tools/lammps_peri.py --n 25 --steps 200 --style lps
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import subprocess
import tempfile

LAMMPS_EXECUTABLE = os.environ.get("PDSIM_LAMMPS", "lmp")
"""LAMMPS binary to run (override with the ``PDSIM_LAMMPS`` environment variable)."""

PERI_STYLES = ("lps", "pmb", "eps")

SKIN_FACTOR = 0.3
"""Neighbour skin as a multiple of the lattice spacing (affects only the short-range contact loop)."""

VELOCITY_AMPLITUDE = 0.1
"""Half-width of the uniform random initial velocity per component [m/s]."""

TIMESTEP_FACTOR = 0.05
"""Time step as a fraction of spacing / sqrt(E / rho) (the stable limit is several times that)."""


def lammps_available() -> bool:
    """Return True when the LAMMPS binary runs and lists the PERI pair styles."""
    exe = shutil.which(LAMMPS_EXECUTABLE)
    if exe is None:
        return False
    try:
        proc = subprocess.run([exe, "-h"], check=False, capture_output=True, text=True, timeout=30, env=_lammps_env())
    except (OSError, subprocess.SubprocessError):
        return False
    return proc.returncode == 0 and "peri/lps" in proc.stdout


def _lammps_env() -> dict[str, str]:
    env = dict(os.environ)
    env["OMP_NUM_THREADS"] = "1"
    return env


def _input_script(
    n: int,
    steps: int,
    style: str,
    horizon: float,
    spacing: float,
    youngs_modulus: float,
    poisson_ratio: float,
    density: float,
    yield_stress: float | None,
) -> tuple[str, float]:
    bulk = youngs_modulus / (3.0 * (1.0 - 2.0 * poisson_ratio))
    shear = youngs_modulus / (2.0 * (1.0 + poisson_ratio))
    critical_stretch = 1.0  # large enough that no bond breaks
    alpha = 0.25  # s0 = s00 - alpha * s_min; irrelevant when nothing breaks
    if style == "pmb":
        # Bond micromodulus from the bulk modulus: c = 18 K / (pi delta^4).
        micromodulus = 18.0 * bulk / (math.pi * horizon**4)
        coeff = f"{micromodulus:.10g} {horizon:.10g} {critical_stretch} {alpha}"
    elif style == "lps":
        coeff = f"{bulk:.10g} {shear:.10g} {horizon:.10g} {critical_stretch} {alpha}"
    else:  # eps
        coeff = f"{bulk:.10g} {shear:.10g} {horizon:.10g} {critical_stretch} {alpha} {yield_stress:.10g}"
    timestep = TIMESTEP_FACTOR * spacing / math.sqrt(youngs_modulus / density)
    hi = n - 0.5  # lattice points 0 .. n-1 in each direction, none on the region surface
    thermo = max(steps, 1)
    script = f"""# pdsim reference run: {n}^3 sc block, pair_style peri/{style}
units           si
boundary        s s s
atom_style      peri
atom_modify     map array
lattice         sc {spacing:.10g}
region          block block -0.5 {hi} -0.5 {hi} -0.5 {hi} units lattice
create_box      1 block
create_atoms    1 region block
pair_style      peri/{style}
pair_coeff      * * {coeff}
set             group all density {density:.10g}
set             group all volume {spacing**3:.10g}
variable        vx atom {VELOCITY_AMPLITUDE}*random(-1.0,1.0,12345)
variable        vy atom {VELOCITY_AMPLITUDE}*random(-1.0,1.0,23456)
variable        vz atom {VELOCITY_AMPLITUDE}*random(-1.0,1.0,34567)
velocity        all set v_vx v_vy v_vz
neighbor        {SKIN_FACTOR * spacing:.10g} bin
fix             integrate all nve
timestep        {timestep:.10g}
thermo          {thermo}
run             {steps}
"""
    return script, timestep


def _parse_log(text: str) -> dict:
    version = re.search(r"^LAMMPS \(([^)]*)\)", text, re.MULTILINE)
    loop = re.search(r"^Loop time of (\S+) on (\d+) procs for (\d+) steps with (\d+) atoms", text, re.MULTILINE)
    bonds = re.search(r"total # of bonds = (\d+)", text)
    pair = re.search(r"^Pair\s*\|\s*(\S+)", text, re.MULTILINE)
    if loop is None or bonds is None:
        raise ValueError("LAMMPS log lacks the 'Loop time' or 'total # of bonds' line")
    return {
        "seconds": float(loop.group(1)),
        "procs": int(loop.group(2)),
        "steps": int(loop.group(3)),
        "particles": int(loop.group(4)),
        "bonds": int(bonds.group(1)),
        "pair_seconds": float(pair.group(1)) if pair else None,
        "lammps_version": version.group(1) if version else "unknown",
    }


def run_lammps_peri(
    n: int,
    steps: int,
    *,
    style: str = "lps",
    horizon_factor: float = 3.015,
    spacing: float = 1.0e-3,
    youngs_modulus: float = 1.0e9,
    poisson_ratio: float = 0.25,
    density: float = 1000.0,
    yield_stress: float | None = None,
    workdir: str | None = None,
) -> dict:
    """Run LAMMPS ``peri/<style>`` on an ``n^3`` simple cubic block and return its timing.

    Args:
        n: Particles per edge; the block holds ``n**3`` particles.
        steps: Number of velocity-Verlet steps (``fix nve``).
        style: ``"lps"``, ``"pmb"`` or ``"eps"`` (elastic-plastic; needs ``yield_stress``).
        horizon_factor: Horizon as a multiple of ``spacing``.
        spacing: Lattice spacing [m].
        youngs_modulus: Young's modulus [Pa].
        poisson_ratio: Poisson's ratio (PMB is a bond model, so only its bulk modulus is used).
        density: Mass density [kg/m^3].
        yield_stress: Yield stress [Pa] for ``"eps"``.
        workdir: Folder to write ``in.peri`` and ``log.peri`` into and keep; a temporary folder if None.

    Returns:
        ``seconds`` (LAMMPS loop time [s]), ``particles``, ``bonds`` (directed bonds: sum over particles of the
        family size), ``steps``, ``bond_visits_per_s`` (``bonds * steps / seconds``), ``style``,
        ``lammps_version``, plus ``pair_seconds`` (the Pair share of the loop [s]), ``bonds_per_particle`` and
        ``timestep`` [s].

    Raises:
        ValueError: On a bad style, a missing yield stress for ``"eps"`` or a non-physical size or material.
        RuntimeError: When LAMMPS is missing, fails or writes a log without the expected lines (with its tail).
    """
    if style not in PERI_STYLES:
        raise ValueError(f"style must be one of {PERI_STYLES}, got {style!r}")
    if style == "eps" and yield_stress is None:
        raise ValueError("style 'eps' needs yield_stress")
    if n < 1 or steps < 0:
        raise ValueError("n must be >= 1 and steps >= 0")
    if not (horizon_factor > 0.0 and spacing > 0.0 and youngs_modulus > 0.0 and density > 0.0):
        # LAMMPS itself accepts a negative horizon silently (it only uses its square).
        raise ValueError("horizon_factor, spacing, youngs_modulus and density must be positive")
    if not -1.0 < poisson_ratio < 0.5:
        raise ValueError("poisson_ratio must lie in (-1, 0.5)")
    exe = shutil.which(LAMMPS_EXECUTABLE)
    if exe is None:
        raise RuntimeError(f"LAMMPS binary {LAMMPS_EXECUTABLE!r} not found")

    horizon = horizon_factor * spacing
    script, timestep = _input_script(
        n, steps, style, horizon, spacing, youngs_modulus, poisson_ratio, density, yield_stress
    )

    tmp = None
    if workdir is None:
        tmp = tempfile.TemporaryDirectory(prefix="lammps_peri_")
        workdir = tmp.name
    else:
        os.makedirs(workdir, exist_ok=True)
    try:
        in_path = os.path.join(workdir, "in.peri")
        log_path = os.path.join(workdir, "log.peri")
        with open(in_path, "w") as f:
            f.write(script)
        proc = subprocess.run(
            [exe, "-in", "in.peri", "-log", "log.peri", "-screen", "none", "-nocite"],
            check=False,
            cwd=workdir,
            capture_output=True,
            text=True,
            env=_lammps_env(),
        )
        log = ""
        if os.path.exists(log_path):
            with open(log_path) as f:
                log = f.read()
        tail = "\n".join((log + proc.stdout + proc.stderr).splitlines()[-40:])
        if proc.returncode != 0:
            raise RuntimeError(f"LAMMPS failed with exit status {proc.returncode}:\n{tail}")
        try:
            parsed = _parse_log(log)
        except ValueError as exc:
            raise RuntimeError(f"{exc}:\n{tail}") from None
    finally:
        if tmp is not None:
            tmp.cleanup()

    seconds = parsed["seconds"]
    bonds = parsed["bonds"]
    return {
        "seconds": seconds,
        "particles": parsed["particles"],
        "bonds": bonds,
        "steps": parsed["steps"],
        "bond_visits_per_s": bonds * parsed["steps"] / seconds if seconds > 0 else float("nan"),
        "style": style,
        "lammps_version": parsed["lammps_version"],
        "pair_seconds": parsed["pair_seconds"],
        "bonds_per_particle": bonds / parsed["particles"],
        "timestep": timestep,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=25, help="particles per edge")
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--style", choices=PERI_STYLES, default="lps")
    parser.add_argument("--horizon-factor", type=float, default=3.015)
    parser.add_argument("--spacing", type=float, default=1.0e-3, help="[m]")
    parser.add_argument("--youngs-modulus", type=float, default=1.0e9, help="[Pa]")
    parser.add_argument("--poisson-ratio", type=float, default=0.25)
    parser.add_argument("--density", type=float, default=1000.0, help="[kg/m^3]")
    parser.add_argument("--yield-stress", type=float, default=None, help="[Pa], needed for --style eps")
    parser.add_argument("--workdir", default=None, help="keep in.peri and log.peri here")
    args = parser.parse_args(argv)
    result = run_lammps_peri(
        args.n,
        args.steps,
        style=args.style,
        horizon_factor=args.horizon_factor,
        spacing=args.spacing,
        youngs_modulus=args.youngs_modulus,
        poisson_ratio=args.poisson_ratio,
        density=args.density,
        yield_stress=args.yield_stress,
        workdir=args.workdir,
    )
    print(json.dumps(result))


if __name__ == "__main__":
    main()
