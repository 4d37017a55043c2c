"""Stress sweeps of the three methods through ``Scene.run`` and its watchdog; writes the stability map of
docs/stability.md (section "Stability map").

    python tools/stress.py [--quick] [--methods peridynamics fem lattice] [--json FILE] [--markdown FILE]

Every run is a tiny scene (a few hundred particles, elements or lattice points) built the way a user builds it and run
by ``Scene.run`` (automatic step times ``dt_factor``, checks every 16 steps, a cache written to a temporary folder).
Each run is classified:

- **stable**: it finished, no value in the cache is NaN or Inf, and the energy audit passed at every frame;
- **caught**: the watchdog raised InstabilityError; the cache holds the frames before it, all finite;
- **silently wrong**: it finished but the cache holds a NaN or Inf, or the energy audit failed (this must never
  happen);
- **error**: any other exception (must never happen either).

The energy audit (on the host, from the solvers' own energy methods): at each frame end, with E = kinetic + strain +
contact + gravitational energy of every solver, E(0) the initial kinetic energy and W the energy put in by loads,
boundary conditions, kicks and moving colliders (the watchdog's accounting, an upper bound of the net work), the run
must keep

    E(t) - E(0) <= W(t) + tolerance (|E(0)| + W(t) + |U_g(t)|) + 1e-9 J,   tolerance 30 % (step factor <= 1), 55 %

with U_g the gravity potential relative to the rest configuration (a body that falls moves |U_g| about). Velocity
Verlet's measured energy legitimately sits above E(0) at large steps (pdsim.watchdog.TOTAL_TOLERANCE: 2-3 % at the
automatic step, 15-20 % at 2x). The watchdog's own frame-end bound is 5 % stricter (25 %, 50 %), so a run that
passes it fails the audit only if the host and device energies disagree; its fast bound (every 16 steps) allows
100 %.

The lattice is massless and position-based (no energy): its audit is that no displacement exceeds 10 times the body's
size (the watchdog stops at 1000 times).

Cases (``CASES``; ``--quick`` the subset tests/stress runs):

- ``map_dt``: time-step factor (0.1 .. 4 x automatic) x Young's modulus (1e3 .. 1e11 Pa), a breakable block resting
  on the ground under gravity with a velocity perturbation of 1e-3 of its wave speed (peridynamics, FEM);
- ``map_impact``: impact speed (10 .. 200 m/s) x Young's modulus: the same block thrown at the ground;
- ``nu``: Poisson's ratio 0.0 .. 0.49 (unbreakable block dropped from 0.2 m);
- ``compress``: the top of a block pushed down to 30 % of its height (prescribed velocity, bottom fixed);
- ``twist``: a bar fixed at one end, the other end spun by an initial angular velocity that stores a 360 degree
  twist's energy (the largest twist reached is reported); the lattice: a bar twisted 360 degrees by leader paths;
- ``slivers``: FEM blocks with jittered meshes (slivers) at the automatic step;
- ``projectile``: a sphere projectile through a breakable plate at 10 .. 200 m/s (peridynamics, FEM);
- ``loads``, ``kick``: a traction and a body force on a block fixed at its base; a velocity kick on a free block;
- ``lattice_map``: the mixed-coordinate rule's relaxation (0.5 .. 1.95) x K (0 .. 100 1/m);
- ``random``: seeded random scenes (material, size, speed, gravity, fracture, step factor); the seeds are recorded.
"""

from __future__ import annotations

import argparse
import datetime
import inspect
import json
import math
import os
import platform
import shutil
import sys
import tempfile
import textwrap
import time
import warnings
from dataclasses import asdict, dataclass, field

import numpy as np
import warp as wp
from pxr import Usd, UsdGeom

import pdsim
import pdsim.run
from pdsim.default_scene import build_scene
from pdsim.lattice import Lattice, LatticeBody, LatticeFracture, LatticeRuleMixedCoordinate
from pdsim.run import advance_frame
from pdsim.watchdog import Watchdog

SPACING = 0.01  # [m] of the peridynamic blocks; FEM cells and lattice spacing alike
BLOCK = (0.08, 0.08, 0.04)  # [m]
STEPS = 600  # automatic steps simulated per run (frames x steps per frame, whatever the step factor)
FRAMES = 6
# energy audit tolerance, relative to the energy moved about, |E(0)| + W + |U_g|: at or below the automatic step and
# above it (the watchdog's frame-end bound, pdsim.watchdog.TOTAL_TOLERANCE, plus 5 %)
AUDIT_REL = {"automatic": 0.30, "larger": 0.55}
AUDIT_ABS = 1.0e-9  # [J]
DENSITY = 1000.0  # [kg/m^3]

DT_FACTORS = (0.1, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0)
MODULI = (1.0e3, 1.0e5, 1.0e7, 1.0e9, 1.0e11)
IMPACTS = (10.0, 50.0, 100.0, 200.0)
POISSON = (0.0, 0.25, 0.45, 0.49)
RELAXATIONS = (0.5, 1.0, 1.5, 1.95)
LATTICE_K = (0.0, 10.0, 100.0)


# -- scenes ------------------------------------------------------------------------------------------------------------
def _material(E: float, nu: float = 0.25, breakable: bool = False, method: str = "peridynamics") -> pdsim.Material:
    """rho 1000 kg/m^3; breakable: critical stretch 0.01 (peridynamics; the FEM takes tensile_strength 0.01 E on the
    body instead)."""
    kw = {"critical_stretch": 0.01} if breakable and method == "peridynamics" else {}
    return pdsim.Material(density=DENSITY, youngs_modulus=E, poisson_ratio=nu, **kw)


def _add_block(scene, method: str, material, *, size=BLOCK, bottom=0.0001, breakable=False, cells=None, jitter=0.0):
    """A block on (or ``bottom`` [m] above) the ground plane z = 0."""
    centre = (0.0, 0.0, bottom + 0.5 * size[2])
    if method == "peridynamics":
        return scene.add_peridynamic_body(pdsim.box(size, center=centre), material, spacing=SPACING, name="block")
    cells = cells or tuple(max(1, round(s / (2 * SPACING))) for s in size)
    mesh = pdsim.box_tet_mesh(size, cells, center=centre, jitter=jitter)
    strength = 0.01 * material.youngs_modulus if breakable else None
    return scene.add_body(pdsim.FemBody(mesh, material, tensile_strength=strength, name="block"))


def _timed_scene(build, dt_factor: float = 1.0, steps: int = STEPS, frames: int = FRAMES):
    """Sets the scene's frame time so that the run covers ``steps`` automatic steps over ``frames`` frames."""
    scene = build()
    solvers = scene.build_solvers(device="cpu", **_no_preflight(scene))
    stable = min(s.stable_time_step() for s in solvers)
    if math.isfinite(stable):
        scene.frame_time = scene.time_step_safety * stable * steps / frames
    scene.frames = frames
    return scene


def _no_preflight(scene) -> dict:
    """build_solvers(check=False) where the scene has the pre-flight checks (they run again in Scene.run)."""
    return {"check": False} if "check" in inspect.signature(scene.build_solvers).parameters else {}


def block_case(method, E, *, nu=0.25, breakable=True, impact=0.0, drop=0.0, gravity=True, perturb=1.0e-3):
    """A block resting on (``impact`` [m/s]: thrown at, ``drop`` [m]: dropped on) the ground, with a random velocity
    perturbation of ``perturb`` x its P-wave speed."""

    def build():
        scene = pdsim.Scene(fps=24, frames=FRAMES, gravity=None if gravity else (0.0, 0.0, 0.0), name="block")
        material = _material(E, nu, breakable, method)
        body = _add_block(scene, method, material, bottom=0.0001 + drop, breakable=breakable)
        rng = np.random.default_rng(7)
        v = rng.normal(0.0, perturb * material.p_wave_speed, (body.point_count, 3))
        body.set_initial_velocity(v + np.array([0.0, 0.0, -impact]))
        scene.add_ground_plane()
        return scene

    return build


COMPRESS_BLOCK = (0.06, 0.06, 0.08)  # [m]: 8 particle layers high


def compress_case(method, E, nu=0.3):
    """The top layer of a 6 x 6 x 8 cm block pushed down at constant speed to 30 % of the height over the run; the
    bottom layer fixed (the sides free)."""
    h = COMPRESS_BLOCK[2]

    def build():
        scene = pdsim.Scene(fps=24, frames=FRAMES, gravity=(0.0, 0.0, 0.0), name="compress")
        scene.enable_contact()  # particles squeezed together repel (as a user would set it for large compression)
        material = _material(E, nu)
        body = _add_block(scene, method, material, size=COMPRESS_BLOCK, bottom=0.0)
        body.fix(pdsim.BoxRegion(lo=(-1, -1, -1), hi=(1, 1, 0.6 * SPACING)))  # the bottom layer
        body.press_region = pdsim.BoxRegion(lo=(-1, -1, h - 0.6 * SPACING), hi=(1, 1, 1))  # the top layer
        return scene

    def finish(scene):
        duration = scene.frame_time * scene.frames
        body = scene.bodies[0]
        body.set_velocity(body.press_region, (0.0, 0.0, -0.7 * h / duration), axes="z", name="press")
        return scene

    return build, finish


TWIST_FRAMES = 60  # frames of the twist runs: the end turns less than half a turn between two
TWIST_AMPLITUDE = 2.0 * math.pi * 1.1  # [rad]: the end's twist amplitude aimed at (a little over 360 degrees)


def twist_case(method, E, nu=0.3):
    """A bar (x from 0 to 0.32 m, 4 x 4 cm) fixed at x < h, set twisting in its first torsional mode: each point turns
    about the x axis at omega(x) = omega_end x / L with omega_end = TWIST_AMPLITUDE x the mode's angular frequency
    (pi / 2) c_s / L, so the free end swings to a twist of about 400 degrees and back (the largest twist of the end
    reached is reported)."""
    size = (0.32, 0.04, 0.04)

    def build():
        scene = pdsim.Scene(fps=24, frames=FRAMES, gravity=(0.0, 0.0, 0.0), name="twist")
        material = _material(E, nu)
        centre = (0.5 * size[0], 0.0, 0.0)
        if method == "peridynamics":
            body = scene.add_peridynamic_body(pdsim.box(size, center=centre), material, spacing=SPACING, name="bar")
        else:
            mesh = pdsim.box_tet_mesh(size, (16, 2, 2), center=centre)
            body = scene.add_body(pdsim.FemBody(mesh, material, name="bar"))
        body.fix(pdsim.BoxRegion(lo=(-1, -1, -1), hi=(0.6 * SPACING, 1, 1)))
        x = body.point_rest_positions
        shear_speed = math.sqrt(material.youngs_modulus / (2.0 * (1.0 + nu)) / material.density)
        omega = TWIST_AMPLITUDE * 0.5 * math.pi * shear_speed / size[0] * np.clip(x[:, 0] / size[0], 0.0, 1.0)
        v = np.zeros_like(x)
        v[:, 1] = -omega * x[:, 2]
        v[:, 2] = omega * x[:, 1]
        body.set_initial_velocity(v)
        return scene

    return build


def projectile_case(method, E, speed):
    """A sphere projectile (radius 2 cm) through the middle of a breakable plate (8 x 8 x 2 cm) at ``speed``."""

    def build():
        scene = pdsim.Scene(fps=24, frames=FRAMES, gravity=(0.0, 0.0, 0.0), name="projectile")
        material = _material(E, 0.25, True, method)
        _add_block(scene, method, material, size=(0.08, 0.08, 0.02), bottom=0.0, breakable=True)
        scene.add_collider(
            pdsim.SphereProjectile(0.02, center=(0.0, 0.0, 0.045), velocity=(0.0, 0.0, -speed), name="ball")
        )
        return scene

    return build


def load_case(method, E):
    """A block fixed at its bottom layer, its top face pulled sideways by a traction of 1e-3 E ramped up over the
    first third of the run, and a body force of 100 m/s^2 along x on the whole body (loads put energy in)."""

    def build():
        scene = pdsim.Scene(fps=24, frames=FRAMES, gravity=(0.0, 0.0, 0.0), name="loads")
        body = _add_block(scene, method, _material(E, 0.3), bottom=0.0)
        body.fix(pdsim.BoxRegion(lo=(-1, -1, -1), hi=(1, 1, 0.6 * SPACING)))
        return scene

    def finish(scene):
        duration = scene.frame_time * scene.frames
        body = scene.bodies[0]
        top = pdsim.BoxRegion(lo=(-1, -1, BLOCK[2] - 0.5 * SPACING), hi=(1, 1, 1))
        body.add_traction(top, (1.0e-3 * E, 0.0, 0.0), curve=pdsim.TimeCurve.ramp(duration / 3.0))
        body.add_body_force((100.0, 0.0, 0.0))
        return scene

    return build, finish


def kick_case(method, E):
    """A free block (no gravity) kicked at 5 m/s on its top half at a third of the run (a kick puts energy in)."""

    def build():
        scene = pdsim.Scene(fps=24, frames=FRAMES, gravity=(0.0, 0.0, 0.0), name="kick")
        _add_block(scene, method, _material(E, 0.3), bottom=0.0)
        return scene

    def finish(scene):
        body = scene.bodies[0]
        top = pdsim.BoxRegion(lo=(-1, -1, 0.5 * BLOCK[2]), hi=(1, 1, 1))
        body.add_velocity_kick((5.0, 0.0, 0.0), time=scene.frame_time * scene.frames / 3.0, region=top)
        return scene

    return build, finish


def sliver_case(E, jitter):
    def build():
        scene = pdsim.Scene(fps=24, frames=FRAMES, name="slivers")
        body = _add_block(scene, "fem", _material(E, 0.3), bottom=0.02, cells=(4, 4, 2), jitter=jitter)
        body.set_initial_velocity((0.0, 0.0, -1.0))
        scene.add_ground_plane()
        return scene

    return build


def lattice_case(relaxation: float, k: float, twist: bool = False):
    """A 12 x 5 x 5 simple-cubic block (spacing 1 cm) with fracture and the mixed-coordinate rule, clamped at one end
    and pulled at 0.1 spacing a step at the other (``twist``: the other end's points turned 360 degrees about the
    bar's axis by leader paths over 72 steps)."""

    def build():
        scene = pdsim.Scene(fps=24, frames=FRAMES, name="lattice")
        h = SPACING
        body = LatticeBody.block(
            Lattice.simple_cubic(h),
            (12, 5, 5),
            name="block",
            rule=LatticeRuleMixedCoordinate(k=k, relaxation=relaxation),
            fracture=None if twist else LatticeFracture((1.6 * h,)),
            steps_per_frame=12,
        )
        x = body.rest_positions[: body.body_count]
        body.clamp(x[:, 0] < x[:, 0].min() + 0.5 * h)
        end = x[:, 0] > x[:, 0].max() - 0.5 * h
        if not twist:
            body.add_leaders(end, velocity=(0.1 * h, 0.0, 0.0), stop_step=40)
            return _added(scene, body)
        centre = 0.5 * (x.min(axis=0) + x.max(axis=0))
        for i in np.flatnonzero(end):
            r = x[i] - centre
            keys = []
            for step in range(0, 73, 6):
                a = 2.0 * math.pi * step / 72
                y = r[1] * math.cos(a) - r[2] * math.sin(a)
                z = r[1] * math.sin(a) + r[2] * math.cos(a)
                keys.append((step, (0.0, y - r[1], z - r[2])))
            mask = np.zeros(body.body_count, dtype=bool)
            mask[i] = True
            body.add_leaders(mask, path=keys)
        return _added(scene, body)

    return build


def _added(scene, body):
    scene.add_body(body)
    return scene


# -- cases -------------------------------------------------------------------------------------------------------------
@dataclass
class Case:
    """One run: ``build`` returns the Scene (frame time set to cover STEPS automatic steps unless ``timed`` is
    False), run at ``dt_factor`` x the automatic step."""

    group: str
    method: str
    params: dict
    build: object
    dt_factor: float = 1.0
    finish: object = None  # callable(scene) -> scene after the frame time is set (prescribed speeds)
    timed: bool = True

    @property
    def label(self) -> str:
        return f"{self.group}/{self.method}/" + ",".join(
            f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in self.params.items()
        )


def cases(quick: bool = False, methods=("peridynamics", "fem", "lattice"), random_count: int = 12) -> list[Case]:
    """The sweep (all of it, or the CI subset with ``quick``)."""
    out: list[Case] = []
    solid = [m for m in methods if m in ("peridynamics", "fem")]
    factors = (1.0, 2.0, 3.0) if quick else DT_FACTORS
    moduli = (1.0e3, 1.0e7, 1.0e11) if quick else MODULI
    for m in solid:
        for E in moduli:
            for f in factors:
                if quick and E != 1.0e7 and f != 1.0:
                    continue
                out.append(Case("map_dt", m, {"E": E, "dt_factor": f}, block_case(m, E), dt_factor=f))
        for E in moduli:
            for v in (10.0, 200.0) if quick else IMPACTS:
                if quick and E == 1.0e3:
                    continue
                out.append(Case("map_impact", m, {"E": E, "speed": v}, block_case(m, E, impact=v)))
        for nu in (0.49,) if quick else POISSON:
            out.append(Case("nu", m, {"E": 1.0e7, "nu": nu}, block_case(m, 1.0e7, nu=nu, breakable=False, drop=0.2)))
        for E in (1.0e7,) if quick else (1.0e5, 1.0e9):
            build, finish = compress_case(m, E)
            out.append(Case("compress", m, {"E": E}, build, finish=finish))
            out.append(Case("twist", m, {"E": E}, twist_case(m, E)))
        for v in (200.0,) if quick else IMPACTS:
            out.append(Case("projectile", m, {"E": 1.0e9, "speed": v}, projectile_case(m, 1.0e9, v)))
        for E in (1.0e7,) if quick else (1.0e5, 1.0e9):
            build, finish = load_case(m, E)
            out.append(Case("loads", m, {"E": E}, build, finish=finish))
            build, finish = kick_case(m, E)
            out.append(Case("kick", m, {"E": E}, build, finish=finish))
    if "fem" in methods:
        for j in (0.29,) if quick else (0.1, 0.2, 0.29):
            for f in (1.0,) if quick else (1.0, 2.0):
                out.append(Case("slivers", "fem", {"jitter": j, "dt_factor": f}, sliver_case(1.0e7, j), dt_factor=f))
    if "lattice" in methods:
        for w in (1.0, 1.95) if quick else RELAXATIONS:
            for k in (0.0, 100.0) if quick else LATTICE_K:
                out.append(Case("lattice_map", "lattice", {"relaxation": w, "K": k}, lattice_case(w, k), timed=False))
        out.append(Case("twist", "lattice", {"relaxation": 1.0}, lattice_case(1.0, 0.0, twist=True), timed=False))
    for seed in range(random_count if not quick else 0):
        out.append(random_case(seed, solid))
    return out


def random_case(seed: int, methods=("peridynamics", "fem"), *, max_steps_factor: float = 10.0) -> Case:
    """A random scene from ``seed``: method, modulus (1e3 .. 1e11 Pa, log-uniform), Poisson ratio (0 .. 0.49),
    breakable or not, impact speed (0 .. 200 m/s), gravity on or off, step factor (0.1 .. 3; at least
    1 / ``max_steps_factor``, which bounds the run's steps to that multiple of STEPS)."""
    rng = np.random.default_rng(seed)
    method = methods[int(rng.integers(len(methods)))]
    E = float(10.0 ** rng.uniform(3.0, 11.0))
    nu = float(rng.uniform(0.0, 0.49))
    breakable = bool(rng.integers(2))
    impact = float(rng.choice([0.0, rng.uniform(0.0, 200.0)]))
    gravity = bool(rng.integers(2))
    factor = max(float(rng.choice([1.0, rng.uniform(0.1, 3.0)])), 1.0 / max_steps_factor)
    params = {"seed": seed, "E": E, "nu": nu, "breakable": breakable, "speed": impact, "gravity": gravity}
    build = block_case(method, E, nu=nu, breakable=breakable, impact=impact, gravity=gravity)
    return Case("random", method, dict(params, dt_factor=factor), build, dt_factor=factor)


# -- running and classifying -------------------------------------------------------------------------------------------
@dataclass
class Record:
    """What one run did. ``outcome``: stable, caught, silently wrong or error; ``audit``: the largest
    (E - E(0) - W) / (|E(0)| + W) over the frames (the lattice: the largest displacement over the body size);
    ``extra``: case-specific numbers (the twist reached [deg], ...)."""

    label: str
    group: str
    method: str
    params: dict
    outcome: str = ""
    audit: float = float("-inf")
    frames: int = 0
    last_frame: int = -1
    steps: int = 0
    dt: float = 0.0
    wall_s: float = 0.0
    message: str = ""
    extra: dict = field(default_factory=dict)


def _energy(solver) -> float | None:
    """E = kinetic + strain + contact + gravitational energy [J] of a solver with mass (None for the lattice)."""
    if not hasattr(solver, "kinetic_energy"):
        return None
    e = solver.kinetic_energy() + solver.strain_energy()
    if hasattr(solver, "contact_energy"):
        e += solver.contact_energy()
    return e + _gravity_potential(solver)


def _gravity_potential(solver) -> float:
    """-sum m g . u [J]: the gravity potential relative to the rest configuration."""
    g = np.asarray(solver.kin.gravity_host, dtype=np.float64)
    return -float(solver.masses() @ (solver.kin.displacements() @ g))


def _cache_finite(path) -> bool:
    """Every point of every Points and Mesh prim at every time sample of the cache is finite."""
    stage = Usd.Stage.Open(str(path))
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.PointBased):
            attr = UsdGeom.PointBased(prim).GetPointsAttr()
            for t in attr.GetTimeSamples():
                x = attr.Get(t)
                if x is not None and len(x) and not np.isfinite(np.asarray(x)).all():
                    return False
    return True


def run_case(case: Case, folder: str) -> Record:
    """Runs ``case`` with Scene.run (CPU) into ``folder`` and classifies it (see the module docstring)."""
    rec = Record(case.label, case.group, case.method, dict(case.params))
    frames = TWIST_FRAMES if case.group == "twist" and case.method != "lattice" else FRAMES
    scene = _timed_scene(case.build, frames=frames) if case.timed else case.build()
    if case.finish is not None:
        scene = case.finish(scene)
    out = os.path.join(folder, f"run{abs(hash(case.label)) % 10**8}.usdc")
    audit = {"worst": float("-inf"), "twist": 0.0, "angle": 0.0, "last": 0.0}
    tolerance = AUDIT_REL["automatic" if case.dt_factor <= 1.0 else "larger"]
    size = None

    def on_frame(frame, solvers):
        nonlocal size
        e0 = w = e = budget = 0.0
        masses = False
        for s in solvers:
            energy = _energy(s)
            if energy is None:  # the lattice: displacement bound
                for b in range(len(s.bodies)):
                    x = s.bodies[b].rest_positions
                    size = float(np.linalg.norm(np.ptp(x, axis=0))) + s.bodies[b].spacing
                    umax = float(np.abs(s.displacements(b)).max())
                    if not np.isfinite(umax):
                        umax = float("inf")
                    audit["worst"] = max(audit["worst"], umax / size / 10.0 - 1.0)
                continue
            masses = True
            e += energy
            e0 += s.watchdog.initial_energy
            w += s.watchdog.last["work"]
            budget += abs(s.watchdog.initial_energy) + s.watchdog.last["work"] + abs(_gravity_potential(s))
        if masses:
            value = (e - e0 - w - AUDIT_ABS) / (budget + 1.0e-300) - tolerance
            audit["worst"] = max(audit["worst"], value)
        if case.group == "compress":
            audit["compressed"] = 70.0 * frame / scene.frames  # [%] of the height the press has moved
        if case.group == "twist" and case.method != "lattice":  # the end's twist, unwrapped frame to frame
            s = solvers[0]
            x = s.positions()
            rest = s.kin.rest_world
            radius = np.hypot(rest[:, 1], rest[:, 2])
            end = (rest[:, 0] > rest[:, 0].max() - 0.5 * SPACING) & (radius > 0.25 * radius.max())
            a0 = np.arctan2(rest[end, 2], rest[end, 1])
            a1 = np.arctan2(x[end, 2], x[end, 1])
            turn = float(np.angle(np.exp(1j * (a1 - a0))).mean())
            audit["angle"] += float(np.angle(np.exp(1j * (turn - audit["last"]))))
            audit["last"] = turn
            audit["twist"] = max(audit["twist"], abs(math.degrees(audit["angle"])))

    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            report = scene.run(
                out,
                device="cpu",
                dt_factor=case.dt_factor,
                progress=False,
                checkpoint_interval_s=None,
                on_frame=on_frame,
            )
            rec.frames, rec.steps, rec.dt = report.frames_written, report.substeps_per_frame * scene.frames, report.dt
            rec.outcome = "stable"
        except pdsim.InstabilityError as exc:
            rec.outcome = "caught"
            rec.message = str(exc)
        except Exception as exc:  # noqa: BLE001 - classified, never hidden
            rec.outcome = "error"
            rec.message = f"{type(exc).__name__}: {exc}"
    rec.wall_s = time.perf_counter() - start
    rec.audit = audit["worst"]
    if case.group == "twist" and case.method != "lattice":
        rec.extra["twist_deg"] = audit["twist"]
    if case.group == "compress":
        rec.extra["compressed_pct"] = audit.get("compressed", 0.0)
    path = out if os.path.exists(out) else None
    if path is not None:
        stage = Usd.Stage.Open(path)
        rec.last_frame = int(stage.GetEndTimeCode())
        finite = _cache_finite(path)
    else:
        finite = True
    if rec.outcome == "stable" and (not finite or rec.audit > 0.0):
        rec.outcome = "silently wrong"
        rec.message = "non-finite values in the cache" if not finite else f"energy audit {rec.audit:+.3g}"
    if rec.outcome == "caught" and not finite:
        rec.outcome = "silently wrong"
        rec.message = "non-finite values in the cache before the watchdog stopped the run"
    return rec


def run_all(case_list, *, log=print) -> list[Record]:
    folder = tempfile.mkdtemp(prefix="pdsim_stress_")
    records = []
    try:
        for i, case in enumerate(case_list):
            rec = run_case(case, folder)
            records.append(rec)
            log(
                f"[{i + 1}/{len(case_list)}] {rec.label}: {rec.outcome} ({rec.wall_s:.1f} s, audit {rec.audit:+.3f})"
                + (f" {rec.extra}" if rec.extra else "")
            )
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return records


# -- reporting ---------------------------------------------------------------------------------------------------------
SYMBOL = {"stable": "S", "caught": "C", "silently wrong": "**W**", "error": "**E**"}


def _grid(records, method, group, row_key, col_key, rows, cols, row_fmt, col_fmt) -> str:
    cell = {}
    for r in records:
        if r.method == method and r.group == group:
            cell[(r.params[row_key], r.params[col_key])] = SYMBOL[r.outcome]
    head = f"| {row_key} \\ {col_key} | " + " | ".join(col_fmt(c) for c in cols) + " |"
    lines = [head, "|" + "---|" * (len(cols) + 1)]
    for rv in rows:
        lines.append(f"| {row_fmt(rv)} | " + " | ".join(cell.get((rv, c), "-") for c in cols) + " |")
    return "\n".join(lines)


def markdown(records, *, command: str, wall: float) -> str:
    """The "Stability map" section of docs/stability.md."""
    count = {k: sum(r.outcome == k for r in records) for k in SYMBOL}
    parts = [
        "## Stability map",
        "",
        "*Written by `tools/stress.py` with the command below.*",
        "",
        "Every cell is one run of `Scene.run` with its watchdog (checks every 16 steps and at frame ends), classified "
        "S = stable (finished, cache finite, energy audit passed at every frame), C = caught (InstabilityError, the "
        "cache holds the finite frames before it), **W** = silently wrong (finished with a NaN/Inf in the cache or "
        "a failed energy audit) and **E** = another error. W and E must be empty. The energy audit: E(t) - E(0) <= "
        "W(t) + tolerance x (|E(0)| + W(t) + |U_g(t)|) at every frame end, the tolerance 30 % at or below the "
        "automatic step and 55 % above it, with E = kinetic + strain + contact + gravitational energy, U_g the "
        "gravity potential relative to the rest configuration and W the work of loads, boundary conditions, kicks "
        "and moving colliders (the watchdog's accounting, an upper bound).",
        "",
        f"Totals: {count['stable']} stable, {count['caught']} caught, {count['silently wrong']} silently wrong, "
        f"{count['error']} errors, over {len(records)} runs.",
        "",
    ]
    moduli = sorted({r.params["E"] for r in records if r.group == "map_dt"})
    factors = sorted({r.params["dt_factor"] for r in records if r.group == "map_dt"})
    speeds = sorted({r.params["speed"] for r in records if r.group == "map_impact"})
    for method in ("peridynamics", "fem"):
        if not any(r.method == method for r in records):
            continue
        parts += [
            f"### {method}: time-step factor x stiffness",
            "",
            "A breakable block (8 x 8 x 4 cm, rho 1000 kg/m^3, nu 0.25) resting on the ground under gravity with a "
            "random velocity perturbation of 1e-3 of its wave speed, 600 automatic steps at factor x the automatic "
            "step."
            + (
                " Above the explicit FEM's stable limit (0.5 h_min / c_p, 1.43 x the automatic step) an FEM body alone "
                "splits a step into substeps of its own; this block cracks, so its pieces' contact (MethodContact) "
                "steps with it at the scene's step and the watchdog catches the run, naming the time step."
                if method == "fem"
                else ""
            ),
            "",
            _grid(
                records,
                method,
                "map_dt",
                "E",
                "dt_factor",
                moduli,
                factors,
                lambda v: f"{v:.0e} Pa",
                lambda v: f"{v:g}x",
            ),
            "",
            f"### {method}: impact speed x stiffness",
            "",
            "The same block thrown at the ground at the automatic step.",
            "",
            _grid(
                records,
                method,
                "map_impact",
                "E",
                "speed",
                moduli,
                speeds,
                lambda v: f"{v:.0e} Pa",
                lambda v: f"{v:g} m/s",
            ),
            "",
        ]
    lattice = [r for r in records if r.group == "lattice_map"]
    if lattice:
        rel = sorted({r.params["relaxation"] for r in lattice})
        ks = sorted({r.params["K"] for r in lattice})
        parts += [
            "### lattice: relaxation x K (mixed-coordinate rule)",
            "",
            "A 12 x 5 x 5 block with fracture, clamped at one end and pulled at 0.1 spacing a step at the other "
            "(the lattice has no time step or energy; its audit is a displacement below 10 x the body's size).",
            "",
            _grid(
                records,
                "lattice",
                "lattice_map",
                "relaxation",
                "K",
                rel,
                ks,
                lambda v: f"{v:g}",
                lambda v: f"{v:g} 1/m",
            ),
            "",
        ]
    others = [r for r in records if r.group not in ("map_dt", "map_impact", "lattice_map")]
    if others:
        parts += [
            "### Other stress cases",
            "",
            "| case | method | parameters | outcome | audit | note |",
            "|---|---|---|---|---|---|",
        ]
        for r in others:
            params = ", ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}" for k, v in r.params.items())
            note = ", ".join(f"{k} {v:.0f}" for k, v in r.extra.items())
            if r.outcome == "caught":
                m = r.message
                cause = m[m.find("likely cause: ") + 14 :].split(";")[0] if "likely cause: " in m else m[:80]
                note = (note + "; " if note else "") + cause[:90]
            audit = f"{r.audit:+.2f}" if math.isfinite(r.audit) else "-"
            parts.append(f"| {r.group} | {r.method} | {params} | {r.outcome} | {audit} | {note} |")
        parts.append("")
    caught = [r for r in records if r.outcome == "caught" and r.group in ("map_dt", "map_impact")]
    causes: dict = {}
    for r in caught:
        m = r.message
        key = m[m.find("likely cause: ") + 14 :].split(":")[0] if "likely cause: " in m else "?"
        causes[key] = causes.get(key, 0) + 1
    if causes:
        parts += [
            "Causes named by the watchdog in the maps' caught cells: "
            + ", ".join(f"{k} ({v})" for k, v in sorted(causes.items()))
            + ".",
            "",
        ]
    parts += [
        f"Machine: {platform.system()} {platform.machine()}, {os.cpu_count()} logical CPUs (shared with other runs), "
        f"Python {platform.python_version()}, Warp {_warp_version()}, device cpu; {datetime.date.today()}; "
        f"{wall:.0f} s in all. Command:",
        "",
        f"    {command}",
        "",
    ]
    return "\n".join(_wrap(p) for p in parts)


def _wrap(paragraph: str, width: int = 120) -> str:
    """Prose paragraphs wrapped at ``width`` (tables, headings and indented lines as they are)."""
    if not paragraph or paragraph.startswith(("|", "#", " ")) or "\n" in paragraph:
        return paragraph
    return textwrap.fill(paragraph, width=width, break_long_words=False, break_on_hyphens=False)


def overhead(frames: int = 12, repeats: int = 5, *, log=print) -> dict:
    """CPU time of the shipped default scene (pdsim.default_scene) for ``frames`` frames through Scene.run, with the
    watchdog (checks every 16 steps and at frame ends) and without it (as before it: a finiteness and speed check at
    frame ends only), alternated ``repeats`` times; the fastest of each (process CPU time: Warp's CPU kernels run on
    the calling thread, and other processes on a shared machine then disturb the figure less than the wall time).
    Returns the times [s] and the overhead."""
    folder = tempfile.mkdtemp(prefix="pdsim_overhead_")
    times = {"watchdog": [], "none": []}
    real = pdsim.run.attach_watchdogs

    def without(scene, solvers, **kwargs):
        return [None for _ in solvers]

    try:
        build_scene().run(os.path.join(folder, "warm.usdc"), frames=1, device="cpu", progress=False)
        for _ in range(repeats):
            for mode in ("watchdog", "none"):
                pdsim.run.attach_watchdogs = real if mode == "watchdog" else without
                scene = build_scene()
                t0 = time.process_time()
                report = scene.run(
                    os.path.join(folder, f"{mode}.usdc"),
                    frames=frames,
                    device="cpu",
                    progress=False,
                    checkpoint_interval_s=None,
                )
                times[mode].append(time.process_time() - t0)
                steps = report.substeps_per_frame
                log(f"{mode}: {times[mode][-1]:.2f} s ({steps} steps a frame, {report.checks} checks)")
    finally:
        pdsim.run.attach_watchdogs = real
        shutil.rmtree(folder, ignore_errors=True)
    median = {k: float(np.median(v)) for k, v in times.items()}
    parts = _check_costs(build_scene(), report.substeps_per_frame)
    return {
        "frames": frames,
        "particles": report.particle_count,
        "steps_per_frame": report.substeps_per_frame,
        "cpu_times": times,
        "overhead_of_medians": median["watchdog"] / median["none"] - 1.0,
        **parts,
    }


def _check_costs(scene, steps_per_frame: int) -> dict:
    """CPU time [ms] of one fast check, one frame-end check and one step of ``scene``'s solver, and the share of a
    frame the checks take (a frame: steps_per_frame steps, a fast check every 16, a frame-end check)."""
    solver = scene.build_solvers(device="cpu", **_no_preflight(scene))[0]
    dt = scene.frame_time / steps_per_frame
    watchdog = Watchdog(solver, energy_floor=1.0e-9)
    advance_frame([solver], dt, 20)

    def cost(fn, n):
        t0 = time.process_time()
        for _ in range(n):
            fn()
        return (time.process_time() - t0) / n

    def full():
        watchdog.full_check = True
        watchdog.check(1.0e30, "")

    fast = cost(lambda: watchdog.check(1.0e30, ""), 40)
    frame_end = cost(full, 20)
    solver.watchdog = solver.kin.watchdog = None
    step = cost(lambda: advance_frame([solver], dt, 16), 4) / 16
    share = ((steps_per_frame // 16) * fast + frame_end) / (steps_per_frame * step)
    return {"fast_check_ms": fast * 1e3, "frame_end_check_ms": frame_end * 1e3, "step_ms": step * 1e3, "share": share}


def _warp_version() -> str:
    return wp.config.version


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="the CI subset (tests/stress)")
    p.add_argument("--methods", nargs="+", default=["peridynamics", "fem", "lattice"])
    p.add_argument("--random", type=int, default=12, help="random scenes (seeds 0 .. N-1)")
    p.add_argument("--json", help="write the records to this JSON file")
    p.add_argument("--markdown", help="write the Stability map section to this file")
    p.add_argument(
        "--overhead", type=int, metavar="FRAMES", help="only measure the watchdog's overhead on the default scene"
    )
    p.add_argument("--from-json", metavar="FILE", help="only write the markdown of the records of an earlier run")
    args = p.parse_args(argv)
    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING
    if args.overhead:
        result = overhead(args.overhead)
        print(json.dumps(result, indent=1))
        return 0
    command = "python tools/stress.py " + " ".join(argv if argv is not None else sys.argv[1:])
    if args.from_json:
        with open(args.from_json) as f:
            data = json.load(f)
        records = [Record(**r) for r in data["records"]]
        text = markdown(records, command=data["command"], wall=data["wall_s"])
        if args.markdown:
            with open(args.markdown, "w") as f:
                f.write(text)
        else:
            print(text)
        return 0
    start = time.perf_counter()
    records = run_all(cases(args.quick, tuple(args.methods), args.random))
    wall = time.perf_counter() - start
    if args.json:
        with open(args.json, "w") as f:
            payload = {"command": command.strip(), "wall_s": wall, "records": [asdict(r) for r in records]}
            json.dump(payload, f, indent=1, default=float)
    text = markdown(records, command=command.strip(), wall=wall)
    if args.markdown:
        with open(args.markdown, "w") as f:
            f.write(text)
    else:
        print(text)
    bad = [r for r in records if r.outcome in ("silently wrong", "error")]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
