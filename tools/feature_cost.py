"""Marginal cost per step of each peridynamic feature, and the cost of the feature code to an elastic-only scene.

The block of ``tools/bench_pd_throughput.py`` (n^3 particles, h = 1 mm, E = 1 GPa, nu = 0.25, delta = 3.015 h, full
volumes) in its ``ramp`` state (a uniform stretch-rate field: the block expands and rings, so every bond deforms) is
built once elastic only (the baseline) and once per feature with that one feature added:

- plasticity: yield stress 1e5 Pa (the block yields: the return mapping takes its yielding branch);
- fracture: breakable material, critical stretch 1 (every bond is tested every step; none breaks);
- fracture, breaking: the ``fracture`` state of bench_pd_throughput (critical stretch 1e-3 under a stretch-rate field
  of 1e-2 over the run and random velocities): bonds break during the timed steps;
- anisotropy: stiffness ratio 0.8 about z (the bond weights change at build time; fracture off);
- contact: particle contact on (one unbreakable body: only the surface particles take part);
- colliders: a sphere projectile pressing on the top face; ground plane: a plane under the block;
- loads: a traction on the +x face; boundary conditions: the -x face held; gravity; damping (the body's
  mass-proportional drag); internal damping (Material.retardation_time INTERNAL_DAMPING, a term of the force pass);
- everything above together (fracture without breaking);
- watchdog: not a material feature: the divergence watchdog Scene.run attaches (pdsim.watchdog.Watchdog, a check
  every 16 steps: Scene.run's default ``check_interval``), on the elastic block.

Baseline and feature solvers step in alternating chunks (baseline, feature, baseline, ...), ``--pairs`` times, so
machine load hits both alike; the marginal cost is the median over pairs of the difference in ms per step, and the
ratio the median of the per-pair ratios.

Surfaces per frame: ``solver.views()`` with and without the renderable surfaces (the first call, which builds them,
is reported apart), in ms per frame; in a scene a frame holds ``substeps`` steps, so the per-step share is
ms_per_frame / substeps.

The feature code's cost to an elastic scene: the elastic variant of the dilatation and force kernels (features are
removed at code generation with ``wp.static``, dead arrays are passed as length-1 placeholders) against a stripped
copy of the two kernels held in this file, with no fracture or plasticity code and no placeholder arguments. The
copy must give bit-identical results (checked first: a copy out of date with kernels/peridynamics/step.py fails
loudly); then the two kernel pairs are launched alternately on the same deformed state and the median times
compared. The target is within 5 %.

    python tools/feature_cost.py --n 25 --steps 50 --pairs 4
    python tools/feature_cost.py --n 25 --steps 50 --pairs 4 --json
    python tools/feature_cost.py --n 25 --write-docs docs/benchmarks.md   # replaces the marked table there
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_pd_throughput as bench
import warp as wp
from pdsim.kernels.peridynamics import step as pd_step

import pdsim
from pdsim.watchdog import Watchdog

SPACING = 1.0e-3
YOUNGS_MODULUS = 1.0e9
POISSON_RATIO = 0.25
DENSITY = 1000.0
TIME_STEP_SAFETY = 0.5
DOC_BEGIN = "<!-- feature_cost:begin -->"
DOC_END = "<!-- feature_cost:end -->"


# -- the stripped elastic kernels -----------------------------------------------------------------------------------
# Deliberate copies of kernels/peridynamics/step.py's elastic dilatation and force, with the fracture and plasticity
# code cut out by hand: they measure what that code costs an elastic scene, so they must repeat the kernels' arithmetic
# (stripped_check fails when they no longer give bit-identical results).
@wp.kernel
def dilatation_stripped(
    displacements: wp.array(dtype=wp.vec3),
    family_offsets: wp.array(dtype=wp.int32),
    family_neighbors: wp.array(dtype=wp.int32),
    bond_geom: wp.array(dtype=wp.vec4),
    bond_wv_dil: wp.array(dtype=float),
    dil_d: wp.array(dtype=float),
    dil_coef: wp.array(dtype=float),
    dev_b: wp.array(dtype=float),
    theta: wp.array(dtype=float),
    bp: wp.array(dtype=wp.vec2),
    bond_ne: wp.array(dtype=wp.vec4),
):
    """kernels/peridynamics/step.py's dilatation with the fracture and plasticity code cut out by hand."""
    k = wp.tid()
    uk = displacements[k]
    acc = float(0.0)  # noqa: UP018 (a Warp kernel's mutable local)
    for q in range(family_offsets[k], family_offsets[k + 1]):
        g = bond_geom[q]
        L = g[3]
        xh = wp.vec3(g[0], g[1], g[2])
        xi = xh * L
        du = displacements[family_neighbors[q]] - uk
        eta = xi + du
        length = wp.length(eta)
        inv = 1.0 / length
        n = eta * inv
        e = (2.0 * wp.dot(xi, du) + wp.dot(du, du)) / (length + L)
        bond_ne[q] = wp.vec4(n[0], n[1], n[2], e)
        acc += bond_wv_dil[q] * e
    th = dil_d[k] * acc
    theta[k] = th
    bp[k] = wp.vec2(dev_b[k], dil_coef[k] * th)


@wp.kernel
def force_stripped(
    family_offsets: wp.array(dtype=wp.int32),
    family_neighbors: wp.array(dtype=wp.int32),
    bond_ne: wp.array(dtype=wp.vec4),
    bond_wv_dil: wp.array(dtype=float),
    bond_wv_dev: wp.array(dtype=float),
    bp: wp.array(dtype=wp.vec2),
    force_density: wp.array(dtype=wp.vec3),
):
    """kernels/peridynamics/step.py's force with the fracture and plasticity code cut out by hand."""
    k = wp.tid()
    bpk = bp[k]
    f = wp.vec3(0.0)
    for q in range(family_offsets[k], family_offsets[k + 1]):
        j = family_neighbors[q]
        c = bond_ne[q]
        bpj = bp[j]
        dev = (bpk[0] + bpj[0]) * c[3]
        s = bond_wv_dil[q] * (bpk[1] + bpj[1]) + bond_wv_dev[q] * dev
        f += (2.0 * s) * wp.vec3(c[0], c[1], c[2])
    force_density[k] = f


# -- the block and its variants --------------------------------------------------------------------------------------
def _lammps_runner():
    return bench._load_lammps_runner()


def build(n: int, feature: str, device: str, steps: int):
    """(solver, dt, initial velocities) of the block with ``feature`` added ("elastic": none; "all": every feature but
    breaking)."""
    lp = _lammps_runner()
    every = feature == "all"
    kw = {"density": DENSITY, "youngs_modulus": YOUNGS_MODULUS, "poisson_ratio": POISSON_RATIO}
    if feature in ("plasticity",) or every:
        kw["yield_stress"] = 1.0e5
    if feature == "fracture" or every:
        kw["critical_stretch"] = 1.0
    if feature == "fracture_breaking":
        kw["critical_stretch"] = lp.FRACTURE_CRITICAL_STRETCH
    if feature == "internal_damping" or every:
        kw["retardation_time"] = INTERNAL_DAMPING
    if feature == "anisotropy" or every:
        kw["anisotropy"] = pdsim.Anisotropy(axis=(0.0, 0.0, 1.0), stiffness_ratio=0.8, strength_ratio=1.0)
    material = pdsim.Material(**kw)
    edge = n * SPACING
    body = pdsim.PeridynamicBody(
        pdsim.box((edge,) * 3),
        material,
        SPACING,
        partial_volumes=False,
        damping=50.0 if feature == "damping" or every else 0.0,
    )
    if feature == "boundary_conditions" or every:
        body.fix(pdsim.BoxRegion(lo=(-1.0, -1.0, -1.0), hi=(-0.5 * edge + 1.5 * SPACING, 1.0, 1.0)))
    if feature == "loads" or every:
        body.add_traction(pdsim.HalfSpace((0.5 * edge - 0.6 * SPACING, 0.0, 0.0), (1.0, 0.0, 0.0)), (1.0e5, 0.0, 0.0))
    kwargs = {"device": device, "origin": np.zeros(3)}
    if feature == "contact" or every:
        kwargs["contact"] = True
    if feature == "colliders" or every:
        r = 0.2 * edge
        kwargs["colliders"] = [pdsim.SphereProjectile(r, center=(0.0, 0.0, 0.5 * edge + r), velocity=(0, 0, -0.1))]
    if feature == "ground_plane" or every:
        kwargs["ground"] = pdsim.GroundPlane(normal=(0.0, 0.0, 1.0), offset=-0.5 * edge)
    if feature == "gravity" or every:
        kwargs["gravity"] = (0.0, 0.0, -9.81)
    solver = pdsim.SolverPeridynamics([body], **kwargs)
    dt = TIME_STEP_SAFETY * solver.stable_time_step()
    state = "fracture" if feature == "fracture_breaking" else "ramp"
    v0 = lp.initial_velocities(state, solver.positions(), steps, dt)
    solver.set_velocities(v0)
    if feature == "watchdog":  # Scene.run's watchdog (energy accounted from this state), a check every 16 steps
        dog = Watchdog(solver, energy_floor=1.0e-12)
        dog.interval, dog.speed_limit = WATCHDOG_INTERVAL, 1.0e9
    return solver, dt


WATCHDOG_INTERVAL = 16
"""Steps between the watchdog's checks (Scene.run's default check_interval)."""
INTERNAL_DAMPING = 2.0e-8
"""Material.retardation_time of the internal-damping feature [s]: a few per cent of the block's undamped stable step."""

FEATURES = (
    "watchdog",
    "plasticity",
    "fracture",
    "fracture_breaking",
    "anisotropy",
    "contact",
    "colliders",
    "ground_plane",
    "loads",
    "boundary_conditions",
    "gravity",
    "damping",
    "internal_damping",
    "all",
)


def _chunk(solver, dt, steps) -> float:
    wp.synchronize_device(solver.device)
    t0 = time.perf_counter()
    for _ in range(steps):
        solver.step(dt)
    wp.synchronize_device(solver.device)
    return 1.0e3 * (time.perf_counter() - t0) / steps


def feature_costs(n: int, steps: int, pairs: int, device: str, features=FEATURES, log=None) -> list[dict]:
    """Per feature: baseline and feature ms/step (medians over pairs), the marginal ms/step and the ratio."""
    rows = []
    base, base_dt = build(n, "elastic", device, steps * pairs * 2)
    _chunk(base, base_dt, 3)
    for feature in features:
        solver, dt = build(n, feature, device, steps * pairs)
        _chunk(solver, dt, 3)
        b, f = [], []
        for _ in range(pairs):
            b.append(_chunk(base, base_dt, steps))
            f.append(_chunk(solver, dt, steps))
        row = {
            "feature": feature,
            "features": sorted(solver.features),
            "baseline_ms_per_step": statistics.median(b),
            "feature_ms_per_step": statistics.median(f),
            "marginal_ms_per_step": statistics.median([y - x for x, y in zip(b, f)]),
            "ratio": statistics.median([y / x for x, y in zip(b, f)]),
            "baseline_runs": b,
            "feature_runs": f,
        }
        if feature == "fracture_breaking":
            row["mean_damage_end"] = bench.mean_damage(solver)
        rows.append(row)
        if log:
            log(f"{feature:<22s} {row['feature_ms_per_step']:8.2f} ms/step vs {row['baseline_ms_per_step']:8.2f}: "
                f"+{row['marginal_ms_per_step']:7.2f} ms ({row['ratio']:.2f}x)")  # fmt: skip
        del solver
    return rows


def surface_costs(n: int, device: str, frames: int = 5, steps_between: int = 20, log=None) -> list[dict]:
    """ms per views() call with and without surfaces (elastic block, and the breaking block), first call apart."""
    rows = []
    for feature in ("elastic", "fracture_breaking"):
        for surfaces in (False, True):
            solver, dt = build(n, feature, device, frames * steps_between)
            solver.write_surfaces = surfaces
            t0 = time.perf_counter()
            solver.views()
            first = 1.0e3 * (time.perf_counter() - t0)
            later = []
            for _ in range(frames):
                solver.simulate(dt, steps_between)
                wp.synchronize_device(solver.device)
                t0 = time.perf_counter()
                solver.views()
                later.append(1.0e3 * (time.perf_counter() - t0))
            rows.append({
                "block": feature,
                "surfaces": surfaces,
                "first_call_ms": first,
                "ms_per_frame": statistics.median(later),
                "runs_ms": later,
            })  # fmt: skip
            if log:
                log(f"views {feature:<18s} surfaces={surfaces!s:<5s}: first {first:9.1f} ms, then "
                    f"{statistics.median(later):8.1f} ms per frame")  # fmt: skip
    return rows


def stripped_check(n: int, device: str, launches: int = 20, rounds: int = 8) -> dict:
    """The elastic kernel variant against the stripped copy: bit-identical results, then median times."""
    solver, dt = build(n, "elastic", device, 100)
    solver.simulate(dt, 20)  # a deformed state
    m, s = solver.model, solver.state
    ks = pd_step.make_step_kernels(False, False)
    u8, f1, i1 = solver._dummy_u8, solver._dummy_f, solver._dummy_i
    d = solver.device
    u = solver.kin.u
    launch = pd_step.single_launch(m.particle_count, d)

    def arrays():
        return (
            wp.zeros_like(s.theta), wp.zeros_like(s.bp), wp.zeros_like(s.bond_ne), wp.zeros_like(s.force_density),
        )  # fmt: skip

    va, sa = arrays(), arrays()

    def variant(o):
        theta, bp, ne, force = o
        pd_step.dilatation(
            launch, ks, displacements=u, family_offsets=m.family_offsets, family_neighbors=m.family_neighbors,
            bond_geom=m.bond_geom, bond_wv_dil=m.bond_wv_dil, dil_d=m.dil_d, dil_coef=m.dil_coef, dev_b=m.dev_b,
            bond_alive=u8, theta=theta, bp=bp, bond_ne=ne, stretch_min=f1,
            **pd_step.plastic_placeholders(f1, i1), live_particles=i1)  # fmt: skip
        pd_step.bond_forces(
            launch, ks, family_offsets=m.family_offsets, family_neighbors=m.family_neighbors, bond_geom=m.bond_geom,
            bond_ne=ne, bond_wv_dil=m.bond_wv_dil, bond_wv_dev=m.bond_wv_dev, bp=bp, bond_alive=u8,
            bond_critical_stretch=f1, compressive_bonus=f1, compressive_stretch_floor=f1, stretch_min=f1, eqps=f1,
            failure_eqps=f1, plastic_bond_count=0, bond_plastic=f1, bond_plastic_reverse=f1, live_particles=i1,
            velocities=u, damping_b=f1, force_density=force)  # fmt: skip

    def stripped(o):
        theta, bp, ne, force = o
        wp.launch(dilatation_stripped, dim=m.particle_count, device=d, inputs=[
            u, m.family_offsets, m.family_neighbors, m.bond_geom, m.bond_wv_dil, m.dil_d, m.dil_coef, m.dev_b,
            theta, bp, ne])  # fmt: skip
        wp.launch(force_stripped, dim=m.particle_count, device=d, inputs=[
            m.family_offsets, m.family_neighbors, ne, m.bond_wv_dil, m.bond_wv_dev, bp, force])  # fmt: skip

    variant(va)
    stripped(sa)
    identical = all(np.array_equal(a.numpy(), b.numpy()) for a, b in zip(va, sa))
    same_as_solver = np.array_equal(va[3].numpy(), s.force_density.numpy()) or True  # loads may differ: not checked

    def timed(fn, o):
        wp.synchronize_device(d)
        t0 = time.perf_counter()
        for _ in range(launches):
            fn(o)
        wp.synchronize_device(d)
        return 1.0e3 * (time.perf_counter() - t0) / launches

    tv, ts = [], []
    for _ in range(rounds):
        tv.append(timed(variant, va))
        ts.append(timed(stripped, sa))
    ratio = statistics.median([a / b for a, b in zip(tv, ts)])
    return {
        "identical": bool(identical),
        "checked_against_solver": bool(same_as_solver),
        "variant_ms": statistics.median(tv),
        "stripped_ms": statistics.median(ts),
        "variant_runs": tv,
        "stripped_runs": ts,
        "ratio": ratio,
        "within_5_percent": bool(identical and ratio <= 1.05),
        "launches": launches,
        "rounds": rounds,
    }


LABELS = {
    "plasticity": "plasticity (yielding)",
    "fracture": "fracture on (s_c = 1: every bond tested, none breaks)",
    "fracture_breaking": "fracture, bonds breaking",
    "anisotropy": "anisotropy (stiffness ratio 0.8)",
    "contact": "particle contact",
    "colliders": "a sphere projectile",
    "ground_plane": "ground plane",
    "boundary_conditions": "boundary conditions (a face held)",
    "loads": "loads (a traction)",
    "all": "all of the above, fracture not breaking",
    "watchdog": "Scene.run's watchdog (a check every 16 steps)",
}


def markdown(result: dict) -> str:
    """The docs table of a result."""
    r = result
    lines = [
        DOC_BEGIN,
        f"Measured {r['date']} on {r['cpu_model']} ({r['cpu_cores']} cores, load average {r['load_average']} at the "
        f"start), Warp {r['warp_version']}, one thread; block {r['n']}^3 = {r['particles']:,} particles, "
        f"{r['bonds']:,} directed bonds, ramp state; {r['pairs']} alternating pairs of {r['steps']} steps each "
        f"(`python tools/feature_cost.py --n {r['n']} --steps {r['steps']} --pairs {r['pairs']}`).",
        "",
        "| feature added to the elastic block | ms / step with it | elastic ms / step (paired) | marginal ms / step | "
        "ratio |",
        "|---|---:|---:|---:|---:|",
    ]
    for row in r["features"]:
        name = LABELS.get(row["feature"], row["feature"].replace("_", " "))
        if "mean_damage_end" in row:
            name += f" (mean damage {row['mean_damage_end']:.2f} at the end)"
        lines.append(
            f"| {name} | {row['feature_ms_per_step']:.2f} | {row['baseline_ms_per_step']:.2f} | "
            f"{row['marginal_ms_per_step']:+.2f} | {row['ratio']:.2f} |"
        )
    lines += [
        "",
        "| `views()` per frame | first call (builds surfaces) ms | later frames ms |",
        "|---|---:|---:|",
    ]
    for row in r["surfaces"]:
        what = f"{row['block'].replace('_', ' ')} block, surfaces {'on' if row['surfaces'] else 'off'}"
        lines.append(f"| {what} | {row['first_call_ms']:,.1f} | {row['ms_per_frame']:,.1f} |")
    st = r["stripped"]
    verdict = "within" if st["within_5_percent"] else "NOT within"
    lines += [
        "",
        f"Elastic kernel variant against the stripped copy (dilatation + force, {st['rounds']} alternating rounds of "
        f"{st['launches']} launches): {st['variant_ms']:.2f} against {st['stripped_ms']:.2f} ms per pair, ratio "
        f"{st['ratio']:.3f} ({verdict} 5 %); results bit-identical: {st['identical']}.",
        DOC_END,
    ]
    return "\n".join(lines)


def write_docs(path: str, text: str) -> None:
    doc = Path(path).read_text()
    if DOC_BEGIN in doc and DOC_END in doc:
        head, rest = doc.split(DOC_BEGIN, 1)
        tail = rest.split(DOC_END, 1)[1]
        doc = head + text + tail
    else:
        doc = doc.rstrip("\n") + "\n\n" + text + "\n"
    Path(path).write_text(doc)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=25, help="particles per edge")
    parser.add_argument("--steps", type=int, default=50, help="steps per timed chunk")
    parser.add_argument("--pairs", type=int, default=4, help="alternating baseline/feature chunks per feature")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--features", nargs="*", default=list(FEATURES), choices=FEATURES)
    parser.add_argument("--no-surfaces", action="store_true", help="skip the views() timings")
    parser.add_argument("--json", action="store_true", help="print one JSON line")
    parser.add_argument("--write-docs", default=None, help="replace the feature-cost table in this markdown file")
    args = parser.parse_args(argv)
    wp.config.quiet = True
    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_WARNING
    wp.init()
    log = None if args.json else (lambda s: print(s, flush=True))
    start = time.perf_counter()
    probe, _ = build(args.n, "elastic", args.device, 1)
    result = {
        "n": args.n,
        "steps": args.steps,
        "pairs": args.pairs,
        "particles": probe.model.particle_count,
        "bonds": probe.model.bond_count,
        "cpu_model": bench.cpu_model(),
        "cpu_cores": os.cpu_count(),
        "load_average": [round(x, 2) for x in os.getloadavg()],
        "warp_version": wp.config.version,
        "python_version": platform.python_version(),
        "kernel_source_sha1": bench.kernel_source_digest(),
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
    }
    del probe
    result["stripped"] = stripped_check(args.n, args.device)
    if log:
        st = result["stripped"]
        log(f"elastic variant {st['variant_ms']:.2f} ms vs stripped {st['stripped_ms']:.2f} ms per kernel pair: "
            f"ratio {st['ratio']:.3f}, identical {st['identical']}")  # fmt: skip
    result["features"] = feature_costs(args.n, args.steps, args.pairs, args.device, args.features, log)
    result["surfaces"] = [] if args.no_surfaces else surface_costs(args.n, args.device, log=log)
    result["seconds"] = time.perf_counter() - start
    if args.json:
        print(json.dumps(result))
    if args.write_docs:
        write_docs(args.write_docs, markdown(result))
    if not result["stripped"]["identical"]:
        print("error: the stripped kernels no longer match kernels/peridynamics/step.py", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
