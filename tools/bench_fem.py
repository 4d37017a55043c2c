"""Throughput of the tetrahedral FEM solver: element updates per second of the explicit and the implicit step.

A box (1 m x 0.5 m x 0.25 m) of 4k x 2k x k cells, six tetrahedra per cell (about 1e4 elements for k = 6, 1e5 for
k = 13), clamped at x = 0 and sagging under gravity (E = 1 MPa, nu = 0.3, rho = 1000 kg/m^3). Timed:

- pdsim explicit (velocity Verlet) at the automatic step 0.5 h_min / c_p, corotated and linear measure;
- pdsim implicit (backward Euler, corotated stiffness, CG) at 10 x that step, with the assembled and the matrix-free
  stiffness (CG iterations per step reported);
- Newton's tetrahedral solvers on the same mesh and step when ``newton`` is installed: SolverSemiImplicit (stable
  Neo-Hookean, triangle contact off) and SolverXPBD (2 iterations). Newton's particle-particle contact is off (its
  hash grid set to None, as Newton's SolverSemiImplicit documents, and for SolverXPBD the largest particle radius
  to 0): with it on, every vertex within two particle radii
  of another repels it (at Newton's default radius of 0.1 m every vertex of this 0.042 m mesh does, and the body flies
  apart: metres of displacement in 0.2 s), which is neither the physics pdsim runs here nor a fair cost.
  ``--newton-particle-radius R`` times it with the contact on at radius R [m] instead (0.1: the earlier set-up).

Element updates per second = element count x steps / seconds (an implicit step counts once, whatever its CG
iterations). Warm-up steps (kernel loads included) are never timed. The headline pair, pdsim's explicit corotated
step and Newton's SolverSemiImplicit, runs in alternating blocks (``--repeats``, default 5) of the same steps on the
same mesh in one process; each figure is the median block, and the ratio is that of the medians (the per-block ratios'
range printed beside it). The largest displacement of each at the end shows that both ran the same motion.

    python tools/bench_fem.py                      # both sizes, human-readable
    python tools/bench_fem.py --k 6 --json         # one size, one JSON line
    python tools/bench_fem.py --cantilever         # also the cantilever convergence table (float64 static solves)
    python tools/bench_fem.py --k 6 --newton-particle-radius 0.1   # the earlier set-up: Newton's particle contact on
    python tools/bench_fem.py --k 6 --pair-only --profile          # the pair, and where each step's time goes
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import numpy as np
import warp as wp

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import pdsim
from pdsim.fem import FemBody, SolverFem
from pdsim.fem.mesh import box_tet_mesh
from pdsim.kernels.fem import elements as ke
from pdsim.kinematics import scene_origin
from pdsim.solver import SolverContext

MAT = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)
SIZE = (1.0, 0.5, 0.25)
GRAVITY = (0.0, 0.0, -9.81)


def bench_mesh(k: int):
    return box_tet_mesh(SIZE, (4 * k, 2 * k, k), center=(0.5 * SIZE[0], 0.0, 0.0))


def _clamped(mesh):
    return mesh.vertices[:, 0] <= 1.0e-9


def _pdsim_solver(mesh, *, integrator, measure, device, stiffness="assembled"):
    """(solver, dt) of the bench box: pdsim's SolverFem, clamped at x = 0, under gravity, at its automatic step (10 x
    that step for the implicit integrator)."""
    body = FemBody(mesh, MAT, measure=measure, integrator=integrator)
    body.fix(pdsim.BoxRegion(lo=(-1, -1, -1), hi=(1e-9, 1, 1)))
    context = SolverContext(device=device, gravity=GRAVITY, origin=scene_origin([body.bounds()]))
    solver = SolverFem([body], context, stiffness=stiffness)
    dt = solver.explicit_time_step() * (10.0 if integrator == "implicit" else 1.0)
    return solver, dt


def _rates(mesh, seconds, steps, dt) -> dict:
    return {
        "seconds": seconds,
        "steps": steps,
        "dt": dt,
        "ms_per_step": 1e3 * seconds / steps,
        "element_updates_per_s": mesh.element_count * steps / seconds,
    }


def _time_pdsim(mesh, *, integrator, measure, device, steps, warmup, stiffness="assembled"):
    solver, dt = _pdsim_solver(mesh, integrator=integrator, measure=measure, device=device, stiffness=stiffness)
    solver.simulate(dt, warmup)
    wp.synchronize_device(solver.device)
    iterations = 0
    t0 = time.perf_counter()
    for _ in range(steps):
        solver.step(dt)
        if integrator == "implicit":
            iterations += solver.cg_reports[-1].iterations
    wp.synchronize_device(solver.device)
    out = _rates(mesh, time.perf_counter() - t0, steps, dt)
    if integrator == "implicit":
        out["cg_iterations_per_step"] = iterations / steps
        out["ms_per_cg_iteration"] = 1e3 * out["seconds"] / max(iterations, 1)
    return out


def newton_soft_mesh(newton, mesh, material, clamped, **options):
    """A Newton ``ModelBuilder`` holding ``mesh`` as one undamped soft tetrahedral mesh at rest with the density and
    Lame constants of ``material`` [kg/m^3, Pa], the vertices ``clamped`` (indices) held (mass 0, inactive);
    ``options`` go to ``add_soft_mesh``. The peer set-up of this benchmark and of tools/accuracy_map.py."""
    builder = newton.ModelBuilder()
    builder.add_soft_mesh(
        pos=wp.vec3(0.0, 0.0, 0.0),
        rot=wp.quat_identity(),
        scale=1.0,
        vel=wp.vec3(0.0, 0.0, 0.0),
        vertices=[wp.vec3(*p) for p in mesh.vertices],
        indices=mesh.tets.ravel().tolist(),
        density=material.density,
        k_mu=material.shear_modulus,
        k_lambda=material.lame_lambda,
        k_damp=0.0,
        **options,
    )
    active = int(newton.ParticleFlags.ACTIVE)
    for i in clamped:
        builder.particle_mass[i] = 0.0
        builder.particle_flags[i] = builder.particle_flags[i] & ~active
    return builder


def _newton_stepper(mesh, *, solver_name, device, dt, particle_radius=None):
    """(step(n), displacements()) of Newton's solver ``solver_name`` on the bench box at step ``dt`` [s]; None when
    newton is not installed. Particle-particle contact is off unless ``particle_radius`` [m] is given (see the module
    docstring)."""
    try:
        import newton
    except ImportError:
        return None
    options = {} if particle_radius is None else {"particle_radius": float(particle_radius)}
    builder = newton_soft_mesh(newton, mesh, MAT, np.flatnonzero(_clamped(mesh)), **options)
    model = builder.finalize(device=device)
    model.set_gravity(GRAVITY)
    if particle_radius is None:
        # no particle-particle contact: SolverSemiImplicit skips it without a hash grid (its documented switch),
        # SolverXPBD without a particle radius
        model.particle_grid = None
        model.particle_max_radius = 0.0
    if solver_name == "SolverSemiImplicit":
        solver = newton.solvers.SolverSemiImplicit(model, enable_tri_contact=False)
    else:
        solver = newton.solvers.SolverXPBD(model, iterations=2)
    states = [model.state(), model.state()]
    control = model.control()

    def step(n):
        s0, s1 = states
        for _ in range(n):
            s0.clear_forces()
            solver.step(s0, s1, control, None, dt)
            s0, s1 = s1, s0
        states[:] = [s0, s1]
        wp.synchronize_device(device)

    def displacements():
        return states[0].particle_q.numpy().astype(np.float64) - mesh.vertices

    return step, displacements, getattr(newton, "__version__", "?")


def _time_newton(mesh, *, solver_name, device, steps, warmup, dt, particle_radius=None):
    """Newton's tetrahedral solver on the same mesh; None when newton is not installed."""
    stepper = _newton_stepper(mesh, solver_name=solver_name, device=device, dt=dt, particle_radius=particle_radius)
    if stepper is None:
        return None
    step, displacements, version = stepper
    step(warmup)
    t0 = time.perf_counter()
    step(steps)
    out = _rates(mesh, time.perf_counter() - t0, steps, dt)
    u = displacements()
    out.update(finite=bool(np.isfinite(u).all()), max_displacement=float(np.abs(u).max()), newton_version=version)
    return out


def _alternated(mesh, *, device, steps, warmup, repeats, particle_radius=None):
    """pdsim's explicit corotated step against Newton's SolverSemiImplicit, in ``repeats`` alternating blocks of
    ``steps`` steps each at the same dt (after ``warmup`` steps each, untimed): per code the median block [s] and
    every block's time, the ratio of the medians (pdsim's element updates per second over Newton's), the range of
    the per-block ratios, the same ratio in process CPU time (both codes run their CPU kernels on this thread, so it
    leaves out the time the process waits for a core on a loaded machine), the largest displacement [m] of each at
    the end. None without newton."""
    solver, dt = _pdsim_solver(mesh, integrator="explicit", measure="corotated", device=device)
    stepper = _newton_stepper(
        mesh, solver_name="SolverSemiImplicit", device=device, dt=dt, particle_radius=particle_radius
    )
    if stepper is None:
        return None
    newton_step, newton_u, version = stepper

    def pdsim_step(n):
        for _ in range(n):
            solver.step(dt)
        wp.synchronize_device(solver.device)

    pdsim_step(warmup)
    newton_step(warmup)
    blocks = {"pdsim": [], "newton": []}
    cpu = {"pdsim": [], "newton": []}
    for _ in range(repeats):
        for name, run in (("pdsim", pdsim_step), ("newton", newton_step)):
            c0, t0 = time.process_time(), time.perf_counter()
            run(steps)
            blocks[name].append(time.perf_counter() - t0)
            cpu[name].append(time.process_time() - c0)
    med = {name: float(np.median(b)) for name, b in blocks.items()}
    med_cpu = {name: float(np.median(b)) for name, b in cpu.items()}
    pair = np.asarray(blocks["newton"]) / np.asarray(blocks["pdsim"])
    u_pdsim = solver.displacements()
    return {
        "steps_per_block": steps,
        "repeats": repeats,
        "dt": dt,
        "pdsim": _rates(mesh, med["pdsim"], steps, dt)
        | {"blocks_s": blocks["pdsim"], "cpu_ms_per_step": 1e3 * med_cpu["pdsim"] / steps},
        "newton": _rates(mesh, med["newton"], steps, dt)
        | {"blocks_s": blocks["newton"], "cpu_ms_per_step": 1e3 * med_cpu["newton"] / steps},
        "ratio": med["newton"] / med["pdsim"],
        "ratio_range": [float(pair.min()), float(pair.max())],
        "ratio_cpu": med_cpu["newton"] / med_cpu["pdsim"],
        "max_displacement": {
            "pdsim": float(np.abs(u_pdsim).max()),
            "newton": float(np.abs(newton_u()).max()),
        },
        "newton_particle_radius": particle_radius,
        "newton_version": version,
    }


def _timed(table: dict, name: str, fn):
    """fn wrapped to add its wall time [s] to table[name]."""

    def wrapper(*args, **kwargs):
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        table[name] = table.get(name, 0.0) + time.perf_counter() - t0
        return out

    return wrapper


def _element_pass_rotations_given(solver, steps) -> float:
    """Seconds of ``steps`` element passes of the corotated force math with each element's rotation given, not found:
    pdsim's matrix-free corotated product (kernels/fem/elements.py: element_stiffness_product, rotated; the same
    gathers, G = Du Dm^-1, R^T G, Hooke's law, R sigma and -V P Dm^-T, with four corner vectors written per element
    instead of added onto the vertices) at the solver's displacements and last rotations. Its time bounds from
    below what any way of finding the rotation can make of the corotated pass."""
    m = solver.model
    arguments = dict(
        u=solver.kin.u,
        tets=solver._tets,
        **m.element_arrays,
        rotation=solver._rotation,
        corner_out=solver._corner,
        dtype=solver.dtype,
        rotated=True,
        device=solver.device,
    )
    ke.element_stiffness_product(**arguments)  # loads the kernel
    wp.synchronize_device(solver.device)
    t0 = time.perf_counter()
    for _ in range(steps):
        ke.element_stiffness_product(**arguments)
    wp.synchronize_device(solver.device)
    return time.perf_counter() - t0


def step_profile(mesh, *, device, steps, warmup):
    """Where one explicit step's time goes [ms per step], each part timed around the real calls of ``steps`` steps:
    pdsim's corotated step (begin_step: velocity kicks, clock, conditions, kick-drift, colliders; loads; the element
    pass; the kick; beside them the corotated pass with the rotations given, _element_pass_rotations_given), the
    element pass of the linear measure (the same pass without the rotation), and Newton's
    SolverSemiImplicit per kernel launch (its particle contact off as in the headline pair; None without newton)."""
    out = {}
    for measure in ("corotated", "linear"):
        solver, dt = _pdsim_solver(mesh, integrator="explicit", measure=measure, device=device)
        solver.simulate(dt, warmup)
        parts: dict = {}
        solver.begin_step = _timed(parts, "begin_step", solver.begin_step)
        solver.loads_into_force = _timed(parts, "loads", solver.loads_into_force)
        solver.element_forces = _timed(parts, "element_pass", solver.element_forces)
        solver.kin.end_step = _timed(parts, "kick", solver.kin.end_step)
        t0 = time.perf_counter()
        for _ in range(steps):
            solver.step(dt)
        wp.synchronize_device(solver.device)
        parts["step"] = time.perf_counter() - t0
        if measure == "corotated":
            parts["element_pass_rotations_given"] = _element_pass_rotations_given(solver, steps)
        out[f"pdsim_{measure}"] = {name: 1e3 * s / steps for name, s in parts.items()}
    stepper = _newton_stepper(mesh, solver_name="SolverSemiImplicit", device=device, dt=dt)
    if stepper is None:
        out["newton"] = None
        return out
    step, _, _ = stepper
    step(warmup)
    parts = {}
    launch = wp.launch

    def timed_launch(kernel, *args, **kwargs):
        return _timed(parts, kernel.key, launch)(kernel, *args, **kwargs)

    wp.launch = timed_launch
    try:
        t0 = time.perf_counter()
        step(steps)
        parts["step"] = time.perf_counter() - t0
    finally:
        wp.launch = launch
    out["newton"] = {name: 1e3 * s / steps for name, s in parts.items()}
    return out


def cantilever_table(cells=(2, 4, 8)):
    """Tip deflection of the test cantilever (tests/test_fem_cantilever.py) against beam theory, float64."""
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
    # tests/ goes on the path only for this table (the test module imports pytest)
    from test_fem_cantilever import BEAM, tip_deflection

    rows = []
    for n in cells:
        t0 = time.perf_counter()
        d = tip_deflection(n, "linear")
        rows.append(
            {
                "cells_across": n,
                "elements": 60 * n**3,
                "tip": d,
                "beam": BEAM,
                "error": abs(d - BEAM) / BEAM,
                "seconds": time.perf_counter() - t0,
            }
        )
    return rows


def machine_info(device: str) -> dict:
    cpu = platform.processor() or "?"
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return {
        "cpu_model": cpu,
        "cpu_cores": os.cpu_count(),
        "load_average": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        "warp_version": wp.__version__,
        "device_name": wp.get_device(device).name,
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--k", type=int, nargs="*", default=[6, 13], help="cells across the thinnest side (6: 1e4, 13: 1e5)")
    p.add_argument("--device", default="cpu", help="Warp device (cpu or cuda)")
    p.add_argument("--explicit-steps", type=int, default=None, help="timed explicit steps (default 5e6 / elements)")
    p.add_argument("--implicit-steps", type=int, default=None, help="timed implicit steps (default 5e5 / elements)")
    p.add_argument("--warmup", type=int, default=5)
    p.add_argument("--repeats", type=int, default=5, help="alternating blocks of pdsim corotated and Newton")
    p.add_argument("--no-newton", action="store_true", help="skip the Newton peer")
    p.add_argument(
        "--newton-particle-radius",
        type=float,
        default=None,
        help="time Newton with its particle-particle contact on at this radius [m] (default: contact off)",
    )
    p.add_argument("--pair-only", action="store_true", help="only the alternated pdsim corotated / Newton pair")
    p.add_argument("--profile", action="store_true", help="also where one explicit step's time goes (both codes)")
    p.add_argument("--cantilever", action="store_true", help="also print the cantilever convergence table")
    p.add_argument("--json", action="store_true", help="one JSON line per size")
    args = p.parse_args(argv)

    wp.config.quiet = True
    wp.init()
    results = []

    def emit(row: dict) -> None:
        """Adds the machine to ``row``, keeps it and prints it (JSON or the table)."""
        row.update(machine_info(args.device))
        results.append(row)
        if args.json:
            print(json.dumps(row))
        else:
            _print_row(row)

    for k in args.k:
        mesh = bench_mesh(k)
        m = mesh.element_count
        n_exp = args.explicit_steps or max(10, int(5.0e6 / m))
        n_imp = args.implicit_steps or max(3, int(5.0e5 / m))
        row = {"k": k, "elements": m, "vertices": mesh.vertex_count, "device": args.device}
        row["load_average_before"] = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
        if not args.no_newton:
            alt = _alternated(
                mesh,
                device=args.device,
                steps=n_exp,
                warmup=args.warmup,
                repeats=args.repeats,
                particle_radius=args.newton_particle_radius,
            )
            row["alternated"] = alt if alt is not None else "newton not installed"
        if args.profile:
            row["profile"] = step_profile(mesh, device=args.device, steps=n_exp, warmup=args.warmup)
        if args.pair_only:
            emit(row)
            continue
        row["explicit_corotated"] = _time_pdsim(
            mesh, integrator="explicit", measure="corotated", device=args.device, steps=n_exp, warmup=args.warmup
        )
        row["explicit_linear"] = _time_pdsim(
            mesh, integrator="explicit", measure="linear", device=args.device, steps=n_exp, warmup=args.warmup
        )
        for mode in ("assembled", "matrix_free"):
            row[f"implicit_{mode}"] = _time_pdsim(
                mesh,
                integrator="implicit",
                measure="corotated",
                device=args.device,
                steps=n_imp,
                warmup=args.warmup,
                stiffness=mode,
            )
        if not args.no_newton:
            dt = row["explicit_corotated"]["dt"]
            for name in ("SolverSemiImplicit", "SolverXPBD"):
                r = _time_newton(
                    mesh,
                    solver_name=name,
                    device=args.device,
                    steps=n_exp,
                    warmup=args.warmup,
                    dt=dt,
                    particle_radius=args.newton_particle_radius,
                )
                if r is None:
                    row["newton"] = "not installed"
                    break
                row[f"newton_{name}"] = r
        emit(row)
    if args.cantilever:
        rows = cantilever_table()
        if args.json:
            print(json.dumps({"cantilever": rows}))
        else:
            print("cantilever (linear, float64): cells across, elements, tip [m], beam theory [m], error, seconds")
            for r in rows:
                print(
                    f"  {r['cells_across']:3d} {r['elements']:7d} {r['tip']:.6g} {r['beam']:.6g} "
                    f"{100 * r['error']:.2f} % {r['seconds']:.2f} s"
                )
    return 0


def _print_row(row):
    print(f"k={row['k']}: {row['elements']} elements, {row['vertices']} vertices, device {row['device']}")
    alt = row.get("alternated")
    if isinstance(alt, dict):
        contact = "off" if alt["newton_particle_radius"] is None else f"on, radius {alt['newton_particle_radius']} m"
        print(
            f"  alternated, {alt['repeats']} blocks of {alt['steps_per_block']} steps each (Newton particle contact "
            f"{contact}):"
        )
        for key, label in (("pdsim", "pdsim explicit corotated"), ("newton", "Newton SolverSemiImplicit")):
            r = alt[key]
            print(
                f"    {label:32s} {r['ms_per_step']:9.3f} ms/step {r['element_updates_per_s'] / 1e6:8.2f} M elem/s"
                f"  (median block; CPU {r['cpu_ms_per_step']:.3f} ms/step; "
                f"max |u| {alt['max_displacement'][key]:.3g} m)"
            )
        lo, hi = alt["ratio_range"]
        print(
            f"    pdsim / Newton per element update: {alt['ratio']:.2f}x (blocks {lo:.2f}-{hi:.2f}x), "
            f"in CPU time {alt['ratio_cpu']:.2f}x"
        )
    for key, label in (
        ("explicit_corotated", "pdsim explicit corotated"),
        ("explicit_linear", "pdsim explicit linear"),
        ("implicit_assembled", "pdsim implicit BE, assembled K"),
        ("implicit_matrix_free", "pdsim implicit BE, matrix-free K"),
        ("newton_SolverSemiImplicit", "Newton SolverSemiImplicit"),
        ("newton_SolverXPBD", "Newton SolverXPBD (2 it)"),
    ):
        r = row.get(key)
        if not isinstance(r, dict):
            continue
        extra = ""
        if "cg_iterations_per_step" in r:
            extra = f", {r['cg_iterations_per_step']:.1f} CG it/step, {r['ms_per_cg_iteration']:.3f} ms/it"
        if "finite" in r and not r["finite"]:
            extra += ", NOT FINITE"
        print(
            f"  {label:34s} {r['ms_per_step']:9.3f} ms/step {r['element_updates_per_s'] / 1e6:8.2f} M elem/s"
            f"  (dt {r['dt']:.3g} s, {r['steps']} steps){extra}"
        )
    prof = row.get("profile")
    if prof:
        print("  where one explicit step's time goes [ms per step]:")
        for key in ("pdsim_corotated", "pdsim_linear", "newton"):
            if prof.get(key):
                parts = ", ".join(f"{name} {ms:.3f}" for name, ms in sorted(prof[key].items(), key=lambda kv: -kv[1]))
                print(f"    {key}: {parts}")
    if row.get("newton") == "not installed":
        print("  Newton: not installed (pip install newton)")
    print(
        f"  {row['cpu_model']}, {row['cpu_cores']} cores, load {row['load_average_before']:.2f} before, "
        f"{row['load_average']:.2f} after, Warp {row['warp_version']}, {row['date']}"
    )


if __name__ == "__main__":
    sys.exit(main())
