"""Run time against error: sweeps the accuracy knobs of every validation problem (pdsim/reference_problems.py) on Dask
and writes docs/accuracy_map.json, the "Run time against error" section of docs/accuracy.md (tables, convergence rates,
the cheapest knobs per tolerance, the recommended defaults) and the Pareto plots docs/accuracy_*.png.

    python tools/accuracy_map.py                          # the committed map (a LocalCluster, one worker per core)
    python tools/accuracy_map.py --quick                  # the two cheapest levels of each series (a smoke run)
    python tools/accuracy_map.py --scheduler tcp://host:8786  # on a farm (pdsim installed on every worker)
    python tools/accuracy_map.py --from-json              # rewrite the doc section and plots from the JSON only

Peers in the same sweep, when installed: LAMMPS's peri/lps (the ``lmp`` binary with the PERI package, run through
tools/lammps_peri.py's set-up) on the PD wave-speed bar, and Newton's tetrahedral solver (SolverSemiImplicit, the
set-up of tools/bench_fem.py) on the cantilever. A peer that is not installed is named in the doc.
"""

from __future__ import annotations

import argparse
import datetime
import importlib.util
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from importlib.metadata import version

import numpy as np
import warp as wp

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import pdsim  # noqa: E402
import pdsim.reference_problems as problems  # noqa: E402
from pdsim.fem import FemBody, SolverFem  # noqa: E402
from pdsim.fem.mesh import box_tet_mesh  # noqa: E402
from pdsim.sweep import run_sweeps  # noqa: E402

from bench_fem import newton_soft_mesh  # noqa: E402

BEGIN, END = "<!-- accuracy_map:begin -->", "<!-- accuracy_map:end -->"
LAMMPS_PERI = os.path.join(HERE, "lammps_peri.py")

# (problem, series label, fixed knobs, refinement levels cheapest first)
PLAN = [
    ("pd_wave_speed", "PD directional, m=3", {"surface_correction": "directional"}, (4, 5, 7, 10)),
    ("pd_wave_speed", "PD none, m=3", {"surface_correction": "none"}, (4, 5, 7, 10)),
    ("pd_wave_speed", "PD directional, m=4", {"horizon_factor": 4.015}, (4, 5, 7)),
    ("pd_wave_speed", "PD directional, dt 0.35", {"dt_factor": 0.35}, (4, 5, 7)),
    ("pd_bar_stiffness", "PD directional, m=3", {"surface_correction": "directional"}, (4, 5, 7, 10)),
    ("pd_bar_stiffness", "PD none, m=3", {"surface_correction": "none"}, (4, 5, 7, 10)),
    ("pd_bar_stiffness", "PD directional, m=4", {"horizon_factor": 4.015}, (4, 5, 7)),
    ("pd_energy_density", "PD directional", {"surface_correction": "directional"}, (3.015, 4.02, 5.025)),
    ("pd_energy_density", "PD none", {"surface_correction": "none"}, (3.015, 4.02, 5.025)),
    ("pd_crack_speed", "PD directional, m=3", {}, (20, 30, 40)),
    ("cantilever", "FEM linear float64 static", {"method": "fem", "measure": "linear"}, (2, 3, 4, 6, 8, 12)),
    (
        "cantilever",
        "FEM corotated float32 static",
        {"method": "fem", "measure": "corotated", "precision": "float32"},
        (2, 3, 4, 6, 8),
    ),
    (
        "cantilever",
        "FEM corotated float32 implicit",
        {"method": "fem", "measure": "corotated", "precision": "float32", "integrator": "implicit"},
        (2, 3, 4),
    ),
    (
        "cantilever",
        "FEM corotated float32 explicit",
        {"method": "fem", "measure": "corotated", "precision": "float32", "integrator": "explicit"},
        (2, 3),
    ),
    ("cantilever", "PD directional, m=3", {"method": "pd"}, (2, 3, 4, 5, 6)),
    ("fem_patch_test", "FEM linear float64", {"measure": "linear"}, (3, 5, 8)),
    ("fem_patch_test", "FEM corotated float32", {"measure": "corotated", "precision": "float32"}, (3, 5, 8)),
    ("lattice_laplace", "lattice square, gradient 1", {}, (9, 17, 33, 65)),
    ("lattice_laplace", "lattice square, gradient 2", {"gradient": 2}, (9, 17, 33, 65)),
    ("lattice_laplace", "lattice hexagonal, gradient 1", {"lattice": "hexagonal"}, (9, 17, 33)),
]
PEER_PLAN = [
    ("pd_wave_speed", "LAMMPS peri/lps, m=3", "lammps", (4, 5, 7, 10)),
]
# Newton's cantilever runs only with --newton: its set-up does not yet give a usable static answer (docs/accuracy.md)
NEWTON_PLAN = ("cantilever", "Newton SemiImplicit (neo-Hookean)", "newton", (2, 3))


# -- peers -------------------------------------------------------------------------------------------------------------
def _load_lammps_peri():
    if "lammps_peri" in sys.modules:
        return sys.modules["lammps_peri"]
    spec = importlib.util.spec_from_file_location("lammps_peri", LAMMPS_PERI)
    module = importlib.util.module_from_spec(spec)
    sys.modules["lammps_peri"] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def _lammps_command():
    """(argv prefix, environment, description) of the newest LAMMPS with PERI that tools/lammps_peri.py finds."""
    lp = _load_lammps_peri()
    if hasattr(lp, "find_installation"):
        inst = lp.find_installation("newest")
        if inst is None:
            raise RuntimeError("no LAMMPS with the PERI package found (tools/lammps_peri.py)")
        return inst.command(1), inst.environment(), inst.describe()
    return [lp.LAMMPS_EXECUTABLE], lp._lammps_env(), "LAMMPS"


def lammps_available() -> bool:
    return os.path.isfile(LAMMPS_PERI) and _load_lammps_peri().lammps_available()


def newton_available() -> bool:
    return importlib.util.find_spec("newton") is not None


def _newton_version() -> str:
    return "newton " + version("newton")


def lammps_wave_speed(n: int = 5, *, horizon_factor: float = 3.015, dt_factor: float = 0.7) -> dict:
    """pd_wave_speed's bar and pulse run by LAMMPS's peri/lps (the same lattice, horizon, material, pulse and step:
    dt_factor x pdsim's stable estimate for this bar). LAMMPS has no surface correction: its "none" is the
    supplement's constants with its own partial volumes. The family is built by a first ``run 0`` at rest, then the
    pulse is imposed with ``displace_atoms`` and ``velocity``; seconds are LAMMPS's whole process (set-up included)."""
    argv, env, describe = _lammps_command()
    width, length, pulse, x0, amp = 0.1, 3.0, 0.48, 0.8, 1.0e-4
    h = width / n
    mat = pdsim.Material(density=problems.RHO, youngs_modulus=problems.E_SOFT, poisson_ratio=0.0)
    c = mat.bar_wave_speed
    knobs = {"n": n, "horizon_factor": horizon_factor, "dt_factor": dt_factor, "spacing": h}
    with problems._Meter() as meter:
        probe = pdsim.PeridynamicBody(
            pdsim.box((length, width, width)), mat, h, horizon_factor=horizon_factor, surface_correction="none"
        )
        dt = dt_factor * pdsim.SolverPeridynamics([probe], device="cpu").stable_time_step()
        steps = round(1.2 / c / dt)
        nx = len(np.unique(np.round(probe.rest_positions[:, 0], 9)))
        script = f"""units si
boundary s s s
atom_style peri
atom_modify map array
lattice sc {h:.10g}
region bar block -0.5 {nx - 0.5} -0.5 {n - 0.5} -0.5 {n - 0.5} units lattice
create_box 1 bar
create_atoms 1 region bar
pair_style peri/lps
pair_coeff * * {mat.bulk_modulus:.10g} {mat.shear_modulus:.10g} {horizon_factor * h:.10g} 1.0 0.25
set group all density {mat.density:.10g}
set group all volume {h**3:.10g}
neighbor {0.3 * h:.10g} bin
fix integrate all nve
timestep {dt:.10g}
thermo {max(steps, 1)}
run 0
variable g atom {amp:.10g}*exp(-(((x-{x0})/{pulse})^2))
variable vx atom 2.0*{c:.10g}*(x-{x0})/{pulse**2:.10g}*v_g
velocity all set v_vx 0.0 0.0 units box
displace_atoms all move v_g 0.0 0.0 units box
write_dump all custom start.txt id x modify sort id format float %.15g
run {steps}
write_dump all custom end.txt id x modify sort id format float %.15g
"""
        with tempfile.TemporaryDirectory(prefix="lammps_wave_") as work:
            with open(os.path.join(work, "in.wave"), "w") as f:
                f.write(script)
            t0 = time.perf_counter()
            proc = subprocess.run(
                [*argv, "-in", "in.wave", "-log", "log.wave", "-screen", "none", "-nocite"],
                cwd=work,
                capture_output=True,
                text=True,
                env=env,
                check=False,
            )
            seconds = time.perf_counter() - t0
            if proc.returncode != 0:
                with open(os.path.join(work, "log.wave")) as f:
                    tail = "\n".join(f.read().splitlines()[-20:])
                raise RuntimeError(f"LAMMPS failed ({proc.returncode}):\n{tail}")
            xs = [np.loadtxt(os.path.join(work, name), skiprows=9)[:, 1] for name in ("start.txt", "end.txt")]
        rest = np.round(xs[0] / h) * h  # lattice sites (the pulse moves them by 1e-4 m << h)
        slices, idx = np.unique(np.round(rest, 9), return_inverse=True)
        counts = np.bincount(idx)

        def peak(x):
            prof = np.bincount(idx, x - rest) / counts
            i = int(np.argmax(prof))
            a, b, cc = prof[i - 1], prof[i], prof[i + 1]
            return slices[i] + 0.5 * h * (a - cc) / (a - 2 * b + cc)

        speed = (peak(xs[1]) - peak(xs[0])) / (steps * dt)
    rec = problems._record(
        "pd_wave_speed", "lammps", knobs, meter, speed, c, abs(speed / c - 1.0), len(rest), steps=steps
    )
    rec["seconds"] = seconds  # the LAMMPS process alone (pdsim's probe for dt is not the peer's time)
    rec["peer_version"] = describe
    return rec


NEWTON_NU = 0.05  # Newton's stable neo-Hookean needs lambda > 0 (see newton_cantilever)
NEWTON_DT_FACTOR = 0.3  # of pdsim's explicit step for the mesh; SolverSemiImplicit drifts away at 0.7


def _scale_kernel():
    @wp.kernel
    def load_and_damp(
        qd: wp.array(dtype=wp.vec3),
        force: wp.array(dtype=wp.vec3),
        inv_mass: wp.array(dtype=float),
        dt: float,
        factor: float,
    ):
        i = wp.tid()
        qd[i] = (qd[i] + force[i] * (inv_mass[i] * dt)) * factor

    return load_and_damp


def newton_cantilever(n: int = 2) -> dict:
    """reference_problems.cantilever's beam, mesh, clamp and tip load run by Newton's SolverSemiImplicit (stable
    neo-Hookean tetrahedra) with nu = 0.05 instead of 0: its volume term's alpha = 1 + mu / lambda needs lambda > 0, and
    a
    small lambda puts alpha so far from J = 1 that float32 loses the strain (the reference uses the same E and this
    G), damped to rest at 2 omega_1 for 1.5 periods of the first bending mode
    (the tip load and the damping applied after each step as v <- (v + dt f / m) / (1 + c dt): symplectic Euler
    with an external force), at 0.7 x pdsim's explicit step for the mesh."""
    import newton

    t, L, F = problems.CANTILEVER_T, problems.CANTILEVER_L, problems.CANTILEVER_F
    mat = pdsim.Material(density=problems.RHO, youngs_modulus=problems.E_SOFT, poisson_ratio=0.0)
    peer = pdsim.Material(density=problems.RHO, youngs_modulus=problems.E_SOFT, poisson_ratio=NEWTON_NU)
    omega1 = 1.875**2 * math.sqrt(problems.E_SOFT * t**2 / 12.0 / problems.RHO) / L**2
    knobs = {"n": n, "spacing": t / n, "poisson_ratio": NEWTON_NU}
    with problems._Meter() as meter:
        mesh = box_tet_mesh((L, t, t), (8 * n, n, n), center=(0.5 * L, 0.0, 0.0))
        dt = NEWTON_DT_FACTOR * SolverFem([FemBody(mesh, mat)], device="cpu").explicit_time_step()
        clamped = np.flatnonzero(mesh.vertices[:, 0] <= 1.0e-9)
        # the default particle radius (0.1 m) makes neighbouring vertices repel by contact
        builder = newton_soft_mesh(newton, mesh, peer, clamped, particle_radius=1.0e-6)
        model = builder.finalize(device="cpu")
        model.set_gravity((0.0, 0.0, 0.0))
        solver = newton.solvers.SolverSemiImplicit(model, enable_tri_contact=False)
        s0, s1 = model.state(), model.state()
        control = model.control()
        tip = np.isclose(mesh.vertices[:, 0], L)
        load = np.zeros((mesh.vertex_count, 3), dtype=np.float32)
        load[tip, 2] = F / tip.sum()  # uniform shear traction: near-equal shares on a structured face
        f_ext = wp.array(load, dtype=wp.vec3, device="cpu")
        scale = 1.0 / (1.0 + 2.0 * omega1 * dt)
        load_and_damp = _scale_kernel()
        steps = math.ceil(problems.RELAX_PERIODS * 2.0 * math.pi / omega1 / dt)
        for _ in range(steps):
            s0.clear_forces()
            solver.step(s0, s1, control, None, dt)
            s0, s1 = s1, s0
            wp.launch(
                load_and_damp,
                dim=mesh.vertex_count,
                inputs=[s0.particle_qd, f_ext, model.particle_inv_mass, dt, scale],
                device="cpu",
            )
        u = s0.particle_q.numpy().astype(np.float64) - mesh.vertices
        deflection = float(u[tip, 2].mean())
    ref = problems._timoshenko(L, peer.shear_modulus)
    rec = problems._record(
        "cantilever", "newton", knobs, meter, deflection, ref, abs(deflection / ref - 1.0), mesh.vertex_count
    )
    rec.update(steps=steps, peer_version=getattr(newton, "__version__", "?"))
    return rec


PEER_FUNCTIONS = {"lammps": lammps_wave_speed, "newton": newton_cantilever}
PEER_AVAILABLE = {"lammps": lammps_available, "newton": newton_available}


# -- running -----------------------------------------------------------------------------------------------------------
def run_map(scheduler=None, *, quick=False, peers=True, newton=False, workers=None) -> tuple[list[dict], dict]:
    """Runs the plan (and the installed peers) as one batch of Dask tasks; returns the records (each with its
    ``series``) and the peers' status {name: "ran" | "not installed"}."""
    import cloudpickle

    if __name__ != "__main__":  # loaded by path: send this module's functions by value to the workers
        cloudpickle.register_pickle_by_value(sys.modules[__name__])
    jobs, labels = [], []
    for problem, label, knobs, levels in PLAN:
        run = levels[:2] if quick else levels
        refinement = problems.PROBLEMS[problem].refinement
        jobs.append((problem, [{refinement: lv, **knobs} for lv in reversed(run)]))  # costly first
        labels.append((problem, label))
    status = {}
    if not newton:
        status["newton"] = (
            "installed (" + _newton_version() + "), left out: see the note below"
            if newton_available()
            else "not installed"
        )
    for problem, label, peer, levels in PEER_PLAN + ([NEWTON_PLAN] if newton else []):
        ok = peers and PEER_AVAILABLE[peer]()
        status[peer] = "ran" if ok else ("skipped (--no-peers)" if not peers else "not installed")
        if ok:
            run = levels[:2] if quick else levels
            jobs.append((PEER_FUNCTIONS[peer], [{"n": lv} for lv in reversed(run)]))
            labels.append((problem, label))
    t0 = time.perf_counter()
    results = run_sweeps(jobs, scheduler=scheduler, workers=workers)
    wall = time.perf_counter() - t0
    records = []
    for (problem, label), recs in zip(labels, results):
        for r in reversed(recs):  # cheapest first again
            r["series"] = label
            r["problem"] = problem
            records.append(r)
    status["_wall_seconds"] = wall
    return records, status


# -- analysis ----------------------------------------------------------------------------------------------------------
def series_of(records):
    out = {}
    for r in records:
        out.setdefault((r["problem"], r["series"]), []).append(r)
    for recs in out.values():
        recs.sort(key=lambda r: -r["knobs"]["spacing"])
    return out


def rates(recs) -> tuple[float, float]:
    """(least-squares order over the levels, order between the two finest of them) of error against spacing, over
    the levels up to the first whose error does not fall (a round-off floor); NaN where fewer than two remain."""
    ok = []
    for r in recs:
        if not (r.get("error", 0) > 0 and math.isfinite(r["error"])):
            continue
        if ok and r["error"] >= ok[-1]["error"]:
            break
        ok.append(r)
    if len(ok) < 2:
        return math.nan, math.nan
    h = np.log([r["knobs"]["spacing"] for r in ok])
    e = np.log([r["error"] for r in ok])
    fit = float(np.polyfit(h, e, 1)[0])
    last = float((e[-2] - e[-1]) / (h[-2] - h[-1]))
    return fit, last


def pareto(points):
    """Indices of the non-dominated (seconds, error) points, fastest first."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def cheapest(recs, tol):
    ok = [r for r in recs if math.isfinite(r.get("error", math.nan)) and r["error"] <= tol]
    return min(ok, key=lambda r: r["seconds"]) if ok else None


# -- the doc -----------------------------------------------------------------------------------------------------------
TITLES = {
    "pd_wave_speed": "PD wave speed in a bar (nu = 0) against sqrt(E/rho)",
    "pd_bar_stiffness": "PD bar in quasi-static tension: effective E against E (nu = 0.3)",
    "pd_energy_density": "PD interior energy densities against 9/2 kappa zeta^2 and 1/2 mu zeta^2 (fixed horizon)",
    "pd_crack_speed": "PD mode-I crack in a pre-stretched strip: peak tip speed against the Rayleigh speed (bound)",
    "cantilever": "Cantilever under a tip force against Timoshenko (t = 0.06 m, L = 8 t, nu = 0), both methods",
    "fem_patch_test": "FEM patch test on an irregular mesh (affine field reproduced)",
    "lattice_laplace": "Lattice centroid rule at rest against its continuum limit, Laplace's equation",
}
LEVEL_NAMES = {
    "pd_wave_speed": "n across",
    "pd_bar_stiffness": "n across",
    "pd_energy_density": "m = delta/h",
    "pd_crack_speed": "n across H",
    "cantilever": "n through t",
    "fem_patch_test": "cells per edge",
    "lattice_laplace": "points per row",
}

PROSE_TOP = """
## Run time against error (generated by `python tools/accuracy_map.py`)

Every problem of `pdsim/reference_problems.py` (module docstring and each function's docstring give the set-up) swept
over its refinement and knobs, one Dask task per point (`pdsim.sweep.run_sweeps`; a `LocalCluster`, one single-threaded
worker process per core). `seconds` is one point's wall time on one worker (model build and run; Warp's start-up
and kernel compilation excluded, the kernel cache being warm), `MiB` the worker's peak resident memory during the
point over its resident memory before it (Linux VmHWM, reset per point; the workers run with
`MALLOC_MMAP_THRESHOLD_=131072` so that freed arrays leave the process), `peak RSS` the worker's whole peak (its
baseline, about 180 MiB, is Python, Warp, pdsim and Dask). Every worker first loads pdsim and its kernels with
tiny runs. On a shared machine the timings are noisy (the load is given below): read only ratios of 2x or more.
Errors are relative: |measured / reference - 1| (the patch test and the lattice: the largest
displacement error over the imposed or boundary amplitude; the crack: the excess of the peak tip speed over the
Rayleigh speed, a bound). Rates are the observed order p of error ~ h^p: "fit" over all levels, "last" between the
two finest (both up to the first level whose error does not fall: a round-off floor).
"""

PROSE_LATTICE = """
### The lattice's continuum limit

The position-based lattice has no stress, energy or time, so it has no elastic continuum limit to compare with:
its steps are not a time integrator and its rest states are not minimisers of an elastic energy. What it has is the
rest state of its rule. For the centroid rule (and any rule with position-independent weights) a follower at rest
sits at the weighted mean of its neighbours, sum_k w_k (u_k - u_j) = 0: a symmetric stencil's discrete Laplacian of
each displacement component vanishes, so as h -> 0 the rest state tends to the harmonic field (Laplace's equation,
component by component) fixed by the leaders, and a lattice step is one Jacobi sweep towards it. That is the
continuum limit checked above. It is not Navier-Cauchy elasticity: the components do not couple (no Poisson
effect; the mixed-coordinate rule adds one by hand), so it corresponds to no isotropic elastic solid with a positive
shear modulus and bulk modulus. The distance-weighted rule's weights depend on the current distances (a nonlinear
averaging) and its limit is not derived here. The square lattice's 4-neighbour stencil converges at order 2; the
hexagonal lattice's 6-neighbour stencil is isotropic to fourth order, its h^2 error term is proportional to the
bilaplacian of u, which vanishes for harmonic fields, so it converges at order 4 (1.6e-5 at 9 points per row,
6e-7 at 17). At 33 its error is larger again (3.9e-6): the float32 relaxation stalls once a step's moves fall
below one ulp of the displacement, and Jacobi sweeps leave about n^2 such moves undone. That floor belongs to the
lattice's float32 state and its step-by-step relaxation, not to the limit; the square lattices are still far
above it at 65 points per row.
"""


def _fmt(x, digits=3):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    if x == 0:
        return "0"
    return f"{x:.{digits}g}"


def write_doc(records, status, meta, out_dir):
    groups = series_of(records)
    lines = [BEGIN, PROSE_TOP.strip("\n"), ""]
    lines.append(
        f"Generated on {meta['date']} ({meta['machine']}); {meta['workers']} workers; the whole sweep took "
        f"{meta['wall_seconds']:.0f} s of wall time ({len(records)} points). Data: `docs/accuracy_map.json`."
    )
    if meta.get("note"):
        lines.append(f"Note: {meta['note']}.")
    if "load_average" in meta:
        a, b = meta["load_average"]
        lines.append(
            f"The 1-minute load average was {a:.1f} at the start and {b:.1f} at the end on {os.cpu_count()} cores "
            "(other work shared the machine): compare times within this map, not with other machines' numbers."
        )
    lines.append("")
    peers = [
        "LAMMPS (peri/lps through tools/lammps_peri.py's binary and environment) on the wave-speed bar: "
        + status.get("lammps", "not run"),
        "Newton (SolverSemiImplicit on the same tetrahedra, tools/bench_fem.py's set-up) on the cantilever: "
        + status.get("newton", "not run"),
    ]
    lines += ["Peers: " + "; ".join(peers) + ".", ""]
    if status.get("lammps") == "ran":
        lines += [LAMMPS_NOTE.strip("\n"), ""]
    if "left out" in status.get("newton", ""):
        lines += [NEWTON_NOTE.strip("\n"), ""]
    for problem in TITLES:
        keys = [k for k in groups if k[0] == problem]
        if not keys:
            continue
        lines += [f"### {TITLES[problem]}", ""]
        lines.append(f"| series | {LEVEL_NAMES[problem]} | h [m] | error | seconds | MiB | peak RSS MiB | points |")
        lines.append("|---|---|---|---|---|---|---|---|")
        for key in keys:
            for r in groups[key]:
                level = r["knobs"].get(problems.PROBLEMS[problem].refinement)
                err = "failed" if "failed" in r else _fmt(r["error"])
                lines.append(
                    f"| {key[1]} | {level} | {_fmt(r['knobs']['spacing'])} | {err} | {_fmt(r.get('seconds'))} | "
                    f"{_fmt(r.get('memory_mb'))} | {_fmt(r.get('peak_rss_mb'))} | {r.get('points', '-')} |"
                )
        if problem in ("pd_crack_speed", "fem_patch_test"):
            lines += [
                "",
                "No rate: "
                + (
                    "a bound, not a reference value."
                    if problem == "pd_crack_speed"
                    else "the error is round-off at every resolution (float64: 1e-14; float32: 5e-8)."
                ),
                "",
            ]
        else:
            lines += ["", "| series | rate (fit) | rate (last pair) |", "|---|---|---|"]
        for key in keys if problem not in ("pd_crack_speed", "fem_patch_test") else ():
            fit, last = rates(groups[key])
            lines.append(f"| {key[1]} | {_fmt(fit, 2)} | {_fmt(last, 2)} |")
        lines.append("")
        if problem == "pd_crack_speed":
            for r in groups[keys[0]]:
                lines.append(
                    f"- n = {r['knobs']['n']}: peak {_fmt(r.get('speed_ratio'))} c_R, mean "
                    f"{_fmt(r.get('mean_speed_ratio'))} c_R, crack length {_fmt(r.get('crack_length'))} m"
                )
            lines.append("")
    lines += ["### Cheapest point per tolerance", ""]
    lines.append("| problem | series | error <= 10 % | error <= 5 % | error <= 2 % |")
    lines.append("|---|---|---|---|---|")
    for key, recs in groups.items():
        if key[0] in ("pd_crack_speed", "fem_patch_test"):
            continue
        cells = []
        for tol in (0.10, 0.05, 0.02):
            r = cheapest(recs, tol)
            ref = problems.PROBLEMS[key[0]].refinement
            cells.append("-" if r is None else f"{ref} = {r['knobs'][ref]}, {_fmt(r['seconds'], 2)} s")
        lines.append(f"| {key[0]} | {key[1]} | " + " | ".join(cells) + " |")
    lines += ["", "![PD problems](accuracy_pd.png)", "", "![Cantilever, both methods](accuracy_cantilever.png)", ""]
    lines += ["![Lattice](accuracy_lattice.png)", "", RECOMMENDED.strip("\n"), "", PROSE_LATTICE.strip("\n"), ""]
    lines += [FARM.strip("\n"), END]
    section = "\n".join(lines) + "\n"
    path = os.path.join(out_dir, "accuracy.md")
    text = "# Accuracy\n"
    if os.path.isfile(path):
        with open(path) as f:
            text = f.read()
    if BEGIN in text and END in text:
        text = text[: text.index(BEGIN)] + section + text[text.index(END) + len(END) + 1 :]
    else:
        text = text.rstrip("\n") + "\n\n" + section
    with open(path, "w") as f:
        f.write(text)


LAMMPS_NOTE = """
LAMMPS runs the wave-speed bar with the same lattice, horizon, material, pulse and step (`lammps_wave_speed` here:
`peri/lps` from a first `run 0` at rest, then `displace_atoms` and `velocity` impose the pulse). It has no surface
correction, so its series is the peer of pdsim's `none`; its time is the whole LAMMPS process (set-up included),
pdsim's the build and the run.
"""

NEWTON_NOTE = """
Newton note: `newton_cantilever` (run with `--newton`) puts the same tetrahedra into Newton's `SolverSemiImplicit`
(stable neo-Hookean, nu = 0.05 since its volume term needs lambda > 0), clamps the x = 0 vertices (mass 0,
inactive) and applies the tip load and the damping to the velocities after each step. It does not yet give a usable
answer: the tip settles at +1.5 mm at n = 2 (44x Timoshenko's 34 um, and upwards) whatever the step (0.3 or 0.7 of
pdsim's explicit step) and whether the load goes in through `particle_f` or as velocity increments, while the same
set-up under gravity sags the right way. Two findings on the way: Newton's default particle radius (0.1 m) makes
neighbouring vertices of a mesh this fine repel by particle contact (a free body at rest drifts by metres in 200
steps; `particle_radius=1e-6` stops it), which tools/bench_fem.py now switches off for its Newton timings; and
lambda = 0 (nu = 0) gives NaN. So the cantilever has no Newton point in this map.
"""

RECOMMENDED = """
### Recommended defaults (chosen from the map) and why

Measured in the tables above (2026-12-01 run; the times carry the machine's load, so only ratios of 2x or more are
read as real). The shipped defaults are all on or next to the Pareto front, so none changes:

- PD `surface_correction="directional"` (default). At the same resolution it has the smaller error on every PD
  problem: wave speed 1.5 % against 9.3 % for `none` at 4 particles across, bar stiffness 9.1 % against 21 % at 5
  and 4.5 % against 7.0 % at 10, interior energies 2.7 % against 5.9 % at m = 3. It costs about 1.2x `none` per
  point (the correction's extra bond factors), so at equal run time it still wins: the bar at 7 across is 6.5 % in
  12 s, `none` needs 10 across for 7.0 % in 45 s. Only the wave speed at 10 across is a draw (0.75 % and 0.80 %).
- PD `horizon_factor=3.015` (default). m = 4.015 is mostly slower (0.7-1.6x, noisy) and less accurate at every
  resolution on the problems that see a surface (bar stiffness 16.6 % against 12.3 % at 4 across; wave speed 2.0 %
  against 1.5 %): a wider horizon reaches more of the surface. It helps only the interior energies (quadrature),
  which m = 3 with the directional correction already has within 2.7 %.
- PD time step 0.7 x the estimate (default `time_step_safety`). Half of it (0.35) gives the same wave-speed error to
  three digits (1.48 % against 1.49 % at 4 across) at twice the time: the integration error is far below the
  spatial one.
- PD resolution: the error of a bar is set by the particles across its thinnest part and falls at order 1
  (directional: 12 %, 9.1 %, 6.5 %, 4.5 % at 4, 5, 7, 10 across); a part that bends needs 5 to 6 particles through
  its thickness for 10 % (cantilever: 9.9 % at 5, 6.4 % at 6; order 2.2-2.4, too soft).
- FEM `precision="float32"` (default): its error equals float64's to three digits on the cantilever (the strain is
  1e-4, well above float32's 1e-7); the patch test holds to 5e-8 in float32 and 1e-14 in float64. The strain
  measure does not change the small-strain answer either (linear and corotated agree to three digits); `corotated`
  stays the default because animation needs rotation invariance, at the price of Newton iterations in a static
  solve (the linear measure needs one). Linear tetrahedra lock in bending and converge at order 2 (fit 1.7, last
  pair 1.9): 6 cells through the thickness for 10 % (8.7 %), 8 for 5 % (5.1 %), 12 for 2.4 %.
- FEM integrator for a state of rest: `solve_static` reaches the answer 10-100x faster than damped dynamics (n = 3:
  0.26 s static against 12 s for explicit or implicit dynamics). The implicit integrator's 10x step did not make
  the damped run faster than explicit here (its CG iterations per step cost what the explicit steps save), so
  `integrator="explicit"` stays the default for dynamics.
- Both methods at equal error (the cantilever): the FEM static solve reaches 8.7 % in 1.4 s (n = 6); PD needs 52 s
  for 9.9 % (n = 5) and 109 s for 6.4 % (n = 6), 40-80x more. Most of that gap is the solution method (a direct
  static solve against damped explicit dynamics to rest): in the same dynamic relaxation, the FEM at n = 3 took
  12.5 s for 27 % and PD 9 s for 31 %. Use the FEM for stiff, accurate elastic parts and peridynamics where things
  break.
- Lattice: the first-gradient neighbourhood (default) is both faster and more accurate than the second-gradient one
  against the Laplace limit (4.8e-5 against 1.1e-4 at 65 points per row), and the hexagonal lattice converges at
  order 4 for harmonic fields (see below).
- Crack speed: at 20, 30 and 40 particles across the strip the peak tip speed is 0.73, 0.69 and 0.67 c_R and the
  mean 0.44, 0.48 and 0.49 c_R: below the bound at every resolution, the peak settling as h falls (a bound, so no
  rate; the speeds themselves converge slowly).
- The LAMMPS peer (no surface correction) is too fast by 10 %, 6.8 %, 3.4 % and 2.6 % at 4, 5, 7 and 10 across
  (pdsim's `none` is too slow: -9.3 % to -0.8 %; its LPS stiffens surface particles where pdsim's constants soften
  them) and takes about the time of pdsim's `none` per point, so pdsim's `directional` is ahead of it at every
  resolution.
"""

FARM = """
### Running the sweep on a farm

From the command line: `pdsim bench accuracy [--quick] [--scheduler tcp://HOST:8786] [--workers N]` runs this map
(the same as `python tools/accuracy_map.py`, from a source checkout), and `pdsim wedge SCENE.py --set
NAME=V1,V2,... [--set ...] --out DIR [--frames N] [--scheduler tcp://HOST:8786]` runs a scene once per combination of
the values, one cache per variant plus `DIR/wedge.json`, e.g.
`pdsim wedge scenes/four_walls.py --set material.critical_stretch=0.008,0.01,0.015 --set spacing=0.02 --out wedge`.
Without `--scheduler` both use a `LocalCluster` on this machine. For a farm, start `dask scheduler` on one machine
and `dask worker tcp://HOST:8786 --nthreads 1` on each worker machine (pdsim installed, `pip install -e ".[sweep]"`),
then pass `--scheduler tcp://HOST:8786`, or from Python:

```python
from pdsim.sweep import run_sweep, run_wedge
records = run_sweep("cantilever", {"n": [2, 4, 8, 12], "method": ["fem"]}, scheduler="tcp://HOST:8786")
run_wedge("scenes/four_walls.py", {"material.critical_stretch": [0.008, 0.01]}, "/shared/wedge", scheduler="tcp://HOST:8786")
```

A wedge's workers must see the scene script and the output folder at the same paths. A script that uses the default
`LocalCluster` (worker processes) must call these under `if __name__ == "__main__":`, as any script that starts
processes. `tests/test_reference_problems.py` checks the two cheapest levels of each problem (the error falls, at
the rates above), `tests/test_sweep.py` a tiny sweep and a tiny wedge on an in-process cluster, from Python and
through `pdsim wedge ... --scheduler ADDRESS`.
"""


# -- plots -------------------------------------------------------------------------------------------------------------
def write_plots(records, out_dir):
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not installed: no plots written", file=sys.stderr)
        return
    groups = series_of(records)

    def panel(ax, problem, title):
        keys = [k for k in groups if k[0] == problem]
        allpts = []
        for key in keys:
            recs = [r for r in groups[key] if r.get("error", 0) > 0 and math.isfinite(r["error"])]
            if not recs:
                continue
            x = [r["seconds"] for r in recs]
            y = [r["error"] for r in recs]
            style = "s--" if key[1].startswith(("LAMMPS", "Newton")) else "o-"
            ax.plot(x, y, style, label=key[1], ms=4)
            allpts += list(zip(x, y))
        if allpts:
            front = [allpts[i] for i in pareto(allpts)]
            ax.step([p[0] for p in front], [p[1] for p in front], where="post", color="0.6", lw=3, alpha=0.4, zorder=0)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("run time per point [s]")
        ax.set_ylabel("relative error")
        ax.set_title(title, fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    panel(axes[0], "pd_wave_speed", "PD wave speed (nu = 0)")
    panel(axes[1], "pd_bar_stiffness", "PD bar stiffness (nu = 0.3)")
    panel(axes[2], "pd_energy_density", "PD energy densities (interior)")
    fig.suptitle("Run time against error; grey: Pareto front", fontsize=10)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "accuracy_pd.png"), dpi=110)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(7, 4.8))
    panel(ax, "cantilever", "Cantilever, tip force vs Timoshenko: FEM and PD (grey: Pareto front)")
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "accuracy_cantilever.png"), dpi=110)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(6, 4.2))
    panel(ax, "lattice_laplace", "Lattice vs Laplace's equation (grey: Pareto front)")
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "accuracy_lattice.png"), dpi=110)
    plt.close(fig)


# -- main --------------------------------------------------------------------------------------------------------------
def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=os.path.join(HERE, "..", "docs"), help="folder of accuracy.md and the PNGs")
    p.add_argument("--quick", action="store_true", help="the two cheapest levels of each series")
    p.add_argument("--scheduler", help="Dask scheduler address (default: a LocalCluster here)")
    p.add_argument("--workers", type=int, help="LocalCluster worker processes (default: one per core)")
    p.add_argument("--no-peers", action="store_true", help="leave the peers out")
    p.add_argument("--newton", action="store_true", help="also run Newton's cantilever (experimental, see the doc)")
    p.add_argument("--from-json", action="store_true", help="rewrite the doc section and plots from the JSON only")
    args = p.parse_args(argv)
    out = os.path.abspath(args.out)
    json_path = os.path.join(out, "accuracy_map.json")
    if args.from_json:
        with open(json_path) as f:
            data = json.load(f)
        records, status, meta = data["records"], data["peers"], data["meta"]
    else:
        load0 = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
        records, status = run_map(
            args.scheduler, quick=args.quick, peers=not args.no_peers, newton=args.newton, workers=args.workers
        )
        meta = {
            "date": str(datetime.date.today()),
            "machine": problems.machine(),
            "workers": args.workers or (os.cpu_count() if args.scheduler is None else "farm"),
            "wall_seconds": status.pop("_wall_seconds"),
            "quick": args.quick,
            "load_average": [load0, os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")],
        }
        with open(json_path, "w") as f:
            json.dump({"meta": meta, "peers": status, "records": records}, f, indent=1)
    write_doc(records, status, meta, out)
    write_plots(records, out)
    failed = [r for r in records if "failed" in r]
    for r in failed:
        print(f"failed: {r['series']} {r['knobs']}: {r['failed']}", file=sys.stderr)
    print(f"{len(records)} points, {len(failed)} failed; wrote {json_path} and the section of accuracy.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
