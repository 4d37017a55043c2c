"""Particle contact in dynamic fracture: stability and energy; writes docs/stability.md (section Contact) and
docs/contact_energy.png.

    python tools/contact_stability.py [--quick] [--out docs] [--before REV]

Two cases, built the way a user builds them: ``pdsim.Scene`` defaults (no gravity), so contact is on automatically for
the breakable body and the step is automatic (``time_step_safety`` x the smallest stable estimate of the solvers):

1. ``kalthoff_winkler``: a Kalthoff-Winkler-like steel plate (rho 8000, E 190 GPa, nu 0.3, G0 22 kJ/m^2; 100 x 200 mm,
   two particle layers thick) with two 50 mm edge notches 52 mm apart, hit between them at 32 m/s by a kinematic box
   projectile 50 mm wide. The block between the notches is driven forward, so the notch faces slide over each other
   (mode II): once they have slid by about 0.2 h, particles that were diagonal neighbours across a notch come within
   their contact distance (1.27 h), the first contacts of the run.
2. ``glass_plate``: a pre-cracked glass plate (E 72 GPa, nu 0.22, rho 2500, G0 3.8 J/m^2; 30 x 30 mm, three layers
   thick) with an edge notch a quarter of the width long, pulled apart obliquely: grips on its top and bottom two
   layers (unbreakable) move at (+-3, +-3, 0) m/s, ramped up over one P-wave transit. A pull normal to the crack
   (mode I) opens the faces cleanly and never brings two particles into contact (measured at h = 0.5 and 1 mm, grip
   speeds 0.05 to 20 m/s: zero contacts); the 45 degree pull shears the plate apart and its fragments touch.

For each run the tool records, every ``--sample`` steps, the kinetic, strain and contact energies, the work put in and
the number of particles in contact, and stops at the end time or at the first ``check_state`` failure (non-finite
state, or a speed above 20 x the solver's speed scale, the Scene's rule). The work put in:

- projectile: kinematic (not pushed back), moving at the constant velocity v_p and the only external force on the
  plate, so the plate's momentum change P(t) - P(0) is the impulse it delivered and W = v_p . (P(t) - P(0)) its work
  (exact; the hard floor's Jacobi projection conserves momentum only approximately);
- grips: the trapezoid integral over every step of the reaction force (``solver.reaction_forces()``) times the grip
  velocity, plus the grips' own kinetic energy on their driven axes, 1/2 m_grip |v_grip(t)|^2 (the reactions are the
  forces the grips exert on the rest of the body and leave out the grips' inertia).

Energy conservation then bounds the body's energy: E(t) = KE + strain + contact <= E(0) + W(t), fracture, the contact
dashpot and the inelastic floor and collider only taking energy out; the figure reported is the largest
(E(t) - E(0)) / W(t) of the run.

``--before REV`` also runs both cases, in a child process, with kernels/contact.py and pdsim/contact.py as they were at
git revision REV (the rest of the working tree as it is): default e153a59, the last commit before the float32 fix.
``--quick`` uses the resolution of tests/test_contact_stability.py (h = 4 mm steel, 1 mm glass) instead of h = 2 mm
and 0.5 mm.
"""

from __future__ import annotations

import argparse
import atexit
import dataclasses
import datetime
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
import types
from dataclasses import dataclass, field

import numpy as np
import pdsim.kernels
import trimesh
import warp as wp

import pdsim
from pdsim.run import advance_frame
from pdsim.sampling import simple_cubic_lattice

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BEFORE_REVISION = "e153a59"  # last commit with the pair modulus 2 C_k C_j / (C_k + C_j) evaluated as written

STEEL = pdsim.Material(density=8000.0, youngs_modulus=190.0e9, poisson_ratio=0.3, fracture_energy=2.2e4, name="steel")
GLASS = pdsim.Material(density=2500.0, youngs_modulus=72.0e9, poisson_ratio=0.22, fracture_energy=3.8, name="glass")
IMPACT_SPEED = 32.0  # [m/s]
GRIP_VELOCITY = (3.0, 3.0, 0.0)  # [m/s], top grip; the bottom one moves the opposite way

RESOLUTIONS = {  # spacing [m] and end time [s] of each case
    "full": {"kalthoff_winkler": (2.0e-3, 100.0e-6), "glass_plate": (0.5e-3, 50.0e-6)},
    "quick": {"kalthoff_winkler": (4.0e-3, 100.0e-6), "glass_plate": (1.0e-3, 60.0e-6)},
}


# -- work put in ------------------------------------------------------------------------------------------------------
class ProjectileWork:
    """W = v_p . (P(t) - P(0)) of a kinematic projectile moving at constant velocity v_p (see the module docstring)."""

    per_step = False

    def __init__(self, solver, velocity):
        self.solver = solver
        self.velocity = np.asarray(velocity, dtype=np.float64)
        self.p0 = solver.linear_momentum()

    def step(self, dt: float) -> None:
        pass

    def value(self) -> float:
        return float(np.dot(self.velocity, self.solver.linear_momentum() - self.p0))


class GripWork:
    """Work of a body's prescribed-velocity conditions: trapezoid integral of reaction . grip velocity (call
    ``step(dt)`` after every step) plus the grips' kinetic energy on their driven axes (see the module docstring)."""

    per_step = True

    def __init__(self, solver, body):
        self.solver = solver
        self.body = body
        masses = solver.masses()[solver.slice_of(body)]
        self.grip_mass = [float(masses[body.point_condition == i].sum()) for i in range(len(body.conditions))]
        self.integral = 0.0
        self.kinetic0 = self._grip_kinetic(solver.time)
        self.power = self._power()

    def _velocity(self, condition, t: float) -> np.ndarray:
        active = condition.start <= t < condition.release
        return condition.velocity * condition.axes * float(condition.curve(t)) if active else np.zeros(3)

    def _grip_kinetic(self, t: float) -> float:
        return sum(
            0.5 * m * float(np.dot(v, v))
            for m, v in zip(self.grip_mass, (self._velocity(c, t) for c in self.body.conditions))
        )

    def _power(self) -> float:
        t = self.solver.time
        forces = self.solver.reaction_forces()
        return sum(float(np.dot(forces[(self.body.name, c.name)], self._velocity(c, t))) for c in self.body.conditions)

    def step(self, dt: float) -> None:
        power = self._power()
        self.integral += 0.5 * (self.power + power) * dt
        self.power = power

    def value(self) -> float:
        return self.integral + self._grip_kinetic(self.solver.time) - self.kinetic0


# -- cases ------------------------------------------------------------------------------------------------------------
@dataclass
class Case:
    """A built scene, its solvers and the work tracker; ``solver`` is the one peridynamic solver."""

    name: str
    title: str
    spacing: float
    scene: pdsim.Scene
    solvers: list
    solver: object
    work: object
    particle_count: int = 0


def slotted_plate(size, spacing: float, slots) -> pdsim.SolidShape:
    """A box of edge lengths ``size`` [m] centred at the origin with slots cut through its thickness from its edge
    x = -size[0] / 2: each slot (y_centre, width, x_end) [m] removes the band |y - y_centre| < width / 2 for
    x < x_end (manifold3d booleans through trimesh)."""
    lx, _, lz = size
    plate = trimesh.creation.box(extents=size)
    cutters = []
    for y, width, x_end in slots:
        length = x_end + 0.5 * lx + spacing  # from beyond the edge to x_end
        cutter = trimesh.creation.box(extents=(length, width, 2.0 * lz))
        cutter.apply_translation((x_end - 0.5 * length, y, 0.0))
        cutters.append(cutter)
    mesh = trimesh.boolean.difference([plate, *cutters], engine="manifold")
    return pdsim.shape_from_arrays(mesh.vertices, mesh.faces, name="plate")


KW_PLATE = (0.1, 0.2, None)  # [m]: x (the impact direction), y; the thickness is two particle layers


def notch_lines(spacing: float, notch_width: float = 0.0) -> list[float]:
    """y [m] of the Kalthoff-Winkler plate's two notches (the upper one first) at particle spacing ``spacing`` [m]:
    for a slot (``notch_width`` > 0) the particle layer nearest y = +-25 mm, its centre; for the zero-width cut the
    plane half a spacing beyond that layer, between two layers."""
    lx, ly, _ = KW_PLATE
    layers = np.unique(np.round(simple_cubic_lattice(pdsim.box((lx, ly, spacing)), spacing)[:, 1], 9))
    centres = [float(layers[np.argmin(np.abs(layers - sign * 0.025))]) for sign in (1.0, -1.0)]
    if notch_width > 0.0:
        return centres
    return [y + math.copysign(0.5 * spacing, y) for y in centres]


def kalthoff_winkler(
    spacing: float = 4.0e-3,
    *,
    device: str = "cpu",
    time_step_safety: float = 0.7,
    contact: bool = True,
    projectile_height: float = 0.05,
    notch_width: float = 0.0,
    sampling_seed: int | None = None,
    contact_options: dict | None = None,
) -> Case:
    """The Kalthoff-Winkler-like steel plate of the module docstring at particle spacing ``spacing`` [m]; ``contact``
    False switches the scene's contact off (Scene.enable_contact(False)); ``projectile_height`` [m]: the box's extent
    across the notches (default 50 mm, the notches' spacing).

    ``notch_width`` [m]: 0 (default) cuts each notch as a plane of zero width between two particle layers (every bond
    crossing it starts dead; the faces' particles start h apart, in contact range); > 0 makes each notch a slot of
    that width centred on the particle layer nearest y = +-25 mm: the particles whose centres lie in it are removed
    (slotted_plate; one layer for a width below 2 h) and the bonds that cross it start dead, so the faces' particles
    start 2 h apart (one layer removed) and touch only when the slot closes. The notches run to x = 0 either way.
    ``sampling_seed``: None (default) puts the particles on the lattice; an integer jitters them (sampling
    "jittered", that seed). ``contact_options`` (with ``contact``): Scene.enable_contact's options, e.g.
    {"distance_factor": 2.2}."""
    h = spacing
    lx, ly, lz = KW_PLATE
    lz = 2.0 * h
    tip = -0.5 * lx + 0.05
    centres = notch_lines(h, notch_width)
    if notch_width > 0.0:
        tip -= 1.0e-3 * h  # off a lattice plane (x = 0 is one at h = 4 mm): the particles there stay, on both sides
        shape = slotted_plate((lx, ly, lz), h, [(y, notch_width, tip) for y in centres])
        half = 0.5 * notch_width
    else:
        shape = pdsim.box((lx, ly, lz))
        half = 1.0e-5
    sampling = {} if sampling_seed is None else {"sampling": "jittered", "sampling_seed": sampling_seed}
    body = pdsim.PeridynamicBody(shape, STEEL, h, name="plate", **sampling)
    for y in centres:
        body.add_notch(pdsim.BoxRegion(lo=(-1.0, y - half, -1.0), hi=(tip, y + half, 1.0)))
    scene = pdsim.Scene(gravity=(0.0, 0.0, 0.0), time_step_safety=time_step_safety)
    if not contact:
        scene.enable_contact(False)
    elif contact_options:
        scene.enable_contact(True, **contact_options)
    scene.add_body(body)
    # a 20 x 50 x 50 mm box 0.1 mm off the impacted face x = -lx / 2
    velocity = (IMPACT_SPEED, 0.0, 0.0)
    projectile = pdsim.BoxProjectile(
        (0.02, projectile_height, 0.05),
        center=(-0.5 * lx - 0.01 - 1.0e-4, 0.0, 0.0),
        velocity=velocity,
        device=device,
    )
    scene.add_collider(projectile)
    solvers = scene.build_solvers(device=device)
    solver = solvers[0]
    title = f"Kalthoff-Winkler steel plate, h = {h * 1e3:g} mm, {IMPACT_SPEED:g} m/s"
    work = ProjectileWork(solver, velocity)
    return Case("kalthoff_winkler", title, h, scene, solvers, solver, work, solver.particle_count)


def glass_plate(
    spacing: float = 1.0e-3, *, device: str = "cpu", time_step_safety: float = 0.7, breakable: bool = True
) -> Case:
    """The pre-cracked glass plate pulled apart obliquely of the module docstring at particle spacing ``spacing``
    [m]. ``breakable=False``: the same plate, grips and loading without fracture or notch (and so without automatic
    contact), whose energy balance checks the grips' work measure."""
    h = spacing
    size, thick = 0.03, 3.0 * h
    material = GLASS if breakable else dataclasses.replace(GLASS, fracture_energy=None)
    body = pdsim.PeridynamicBody(pdsim.box((size, size, thick)), material, h, name="plate")
    if breakable:
        body.add_notch(pdsim.BoxRegion(lo=(-size, -1.0e-5, -1.0), hi=(-0.25 * size, 1.0e-5, 1.0)))
    grip = 0.5 * size - 2.0 * h  # two particle layers
    ramp = pdsim.TimeCurve.ramp(size / GLASS.p_wave_speed)
    v = np.asarray(GRIP_VELOCITY)
    for sign, name in ((1.0, "top"), (-1.0, "bottom")):
        region = pdsim.HalfSpace((0.0, sign * grip, 0.0), (0.0, sign, 0.0))
        body.set_velocity(region, tuple(sign * v), axes="xy", curve=ramp, name=name)
        body.set_unbreakable(region)
    scene = pdsim.Scene(gravity=(0.0, 0.0, 0.0), time_step_safety=time_step_safety)
    scene.add_body(body)
    solvers = scene.build_solvers(device=device)
    solver = solvers[0]
    speed = float(np.linalg.norm(v))
    title = f"pre-cracked glass plate pulled apart at 45 deg, h = {h * 1e3:g} mm, {speed:.3g} m/s per grip"
    if not breakable:
        title = f"unbreakable glass plate pulled at 45 deg, h = {h * 1e3:g} mm, {speed:.3g} m/s per grip"
    return Case("glass_plate", title, h, scene, solvers, solver, GripWork(solver, body), solver.particle_count)


CASES = {"kalthoff_winkler": kalthoff_winkler, "glass_plate": glass_plate}


# -- running ----------------------------------------------------------------------------------------------------------
@dataclass
class Record:
    """Samples of a run: time [s], kinetic, strain and contact energies and work put in [J], particles in contact and
    the largest contact count of a particle; ``diverged_at`` [s] and ``error`` when check_state raised."""

    name: str
    title: str = ""
    particle_count: int = 0
    spacing_mm: float = 0.0
    modulus: float = 0.0
    dt: float = 0.0
    steps: int = 0
    wall_s: float = 0.0
    time: list = field(default_factory=list)
    kinetic: list = field(default_factory=list)
    strain: list = field(default_factory=list)
    contact: list = field(default_factory=list)
    work: list = field(default_factory=list)
    in_contact: list = field(default_factory=list)
    max_count: list = field(default_factory=list)
    diverged_at: float | None = None
    error: str = ""

    @property
    def total(self) -> np.ndarray:
        return np.asarray(self.kinetic) + np.asarray(self.strain) + np.asarray(self.contact)

    def energy_ratio(self) -> tuple[float, float]:
        """Largest (E(t) - E(0)) / W(t) over the samples with W > 1 % of its peak (earlier ones are round-off), and
        the time [s] of that sample."""
        w = np.asarray(self.work)
        gain = self.total - self.total[0]
        use = np.flatnonzero(w > 0.01 * w.max()) if w.max() > 0 else np.zeros(0, dtype=int)
        if use.size == 0:
            return math.nan, math.nan
        ratio = gain[use] / w[use]
        worst = int(np.argmax(ratio))
        return float(ratio[worst]), float(self.time[use[worst]])

    def first_contact(self) -> float | None:
        """Time [s] of the first sample with a particle in contact."""
        hits = [t for t, n in zip(self.time, self.in_contact) if n > 0]
        return hits[0] if hits else None


def _local_positions(solver):
    x = solver.positions() - np.asarray(solver.origin, dtype=np.float64)
    return wp.array(x.astype(np.float32), dtype=wp.vec3, device=solver.device)


def run(case: Case, end_time: float, *, sample_every: int = 10) -> Record:
    """Steps ``case`` to ``end_time`` [s] at the automatic step with pdsim.run.advance_frame, ``sample_every`` steps per
    call (one step per call for per-step work trackers), sampling after each; stops at the first check_state
    failure."""
    solvers, s = case.solvers, case.solver
    dt = case.scene.time_step_safety * min(x.stable_time_step() for x in solvers)
    limit = 20.0 * max(x.speed_scale() for x in solvers)
    modulus = 0.0 if s.contact is None else float(s.contact.modulus.numpy().max())
    rec = Record(
        case.name, case.title, case.particle_count, case.spacing * 1e3, modulus, dt=dt, steps=math.ceil(end_time / dt)
    )

    def sample():
        rec.time.append(s.time)
        rec.kinetic.append(s.kinetic_energy())
        rec.strain.append(s.strain_energy())
        rec.contact.append(s.contact_energy())
        rec.work.append(case.work.value())
        count = np.zeros(1, dtype=np.int32) if s.contact is None else s.contact.diagnostics(_local_positions(s)).count
        rec.in_contact.append(int((count > 0).sum()))
        rec.max_count.append(int(count.max()))

    sample()
    start, done = time.perf_counter(), 0
    while done < rec.steps:
        n = min(sample_every, rec.steps - done)
        if case.work.per_step:
            for _ in range(n):
                advance_frame(solvers, dt, 1)
                case.work.step(dt)
        else:
            advance_frame(solvers, dt, n)
        done += n
        try:
            for x in solvers:
                x.check_state(limit)
        except pdsim.InstabilityError as e:
            rec.diverged_at, rec.error = s.time, str(e)
            break
        sample()
    rec.wall_s = time.perf_counter() - start
    return rec


def _install_revision(revision: str) -> None:
    """Replaces pdsim.contact and pdsim.kernels.contact by their text at git ``revision`` (before anything imports
    them: call first)."""
    folder = tempfile.mkdtemp(prefix="pdsim_contact_")
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    for name, path in (("pdsim.kernels.contact", "kernels/contact.py"), ("pdsim.contact", "pdsim/contact.py")):
        if name in sys.modules:
            raise RuntimeError(f"{name} is already imported")
        source = subprocess.run(
            ["git", "-C", ROOT, "show", f"{revision}:{path}"], capture_output=True, text=True, check=True
        ).stdout
        filename = os.path.join(folder, f"{revision}_{path.replace('/', '_')}")
        with open(filename, "w") as f:
            f.write(source)  # Warp reads kernel source from the file
        module = types.ModuleType(name)
        module.__package__ = name.rpartition(".")[0]
        module.__file__ = filename
        sys.modules[name] = module
        exec(compile(source, filename, "exec"), module.__dict__)
        setattr(pdsim.kernels if name.startswith("pdsim.kernels") else pdsim, name.rpartition(".")[2], module)


def _record_dict(rec: Record) -> dict:
    return {k: getattr(rec, k) for k in Record.__dataclass_fields__}


def run_before(revision: str, resolution: str) -> dict:
    """Both cases with the contact code of ``revision``, in a child process: {case: record dict} or {"error": ...}."""
    cmd = [sys.executable, os.path.abspath(__file__), "--child", revision, "--resolution", resolution]
    proc = subprocess.run(cmd, check=False, capture_output=True, text=True, cwd=ROOT)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("{")]
    if proc.returncode != 0 or not lines:
        return {"error": (proc.stderr.strip().splitlines() or ["no output"])[-1]}
    return json.loads(lines[-1])


def _child(revision: str, resolution: str) -> None:
    _install_revision(revision)
    out = {}
    for name, (h, end) in RESOLUTIONS[resolution].items():
        out[name] = _record_dict(run(CASES[name](h), end))
    h, end = RESOLUTIONS[resolution]["kalthoff_winkler"]  # the user's report: also at half the automatic step
    out["kalthoff_winkler_half_step"] = _record_dict(run(kalthoff_winkler(h, time_step_safety=0.35), end))
    print(json.dumps(out))


# -- report -----------------------------------------------------------------------------------------------------------
def _plot(records: dict, before: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(records), figsize=(10, 3.6))
    for ax, (name, rec) in zip(np.atleast_1d(axes), records.items()):
        t = np.asarray(rec.time) * 1e6
        ax.plot(t, rec.work, "k--", lw=1.2, label="work put in W")
        ax.plot(t, rec.total - rec.total[0], "C3", lw=1.5, label="E - E(0)")
        ax.plot(t, rec.kinetic, "C0", lw=1.0, label="kinetic")
        ax.plot(t, rec.strain, "C2", lw=1.0, label="strain")
        ax.plot(t, rec.contact, "C1", lw=1.0, label="contact")
        b = before.get(name, {})
        if b.get("diverged_at"):
            ax.axvline(b["diverged_at"] * 1e6, color="grey", lw=0.8, ls=":", label="old code: non-finite")
        ax.set_title(rec.title, fontsize=8)
        ax.set_xlabel("t [us]")
        ax.set_ylabel("energy [J]")
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _fmt_time(t) -> str:
    return "-" if t is None else f"{t * 1e6:.1f} us"


def _wrap(text: str) -> str:
    return textwrap.fill(text, width=118, break_long_words=False, break_on_hyphens=False)


def _section(records: dict, before: dict, revision: str | None, command: str, wall_s: float, balance: float) -> str:
    most = max(max(rec.max_count) for rec in records.values())
    materials = {"kalthoff_winkler": STEEL.name, "glass_plate": GLASS.name}
    moduli = ", ".join(
        f"{rec.modulus:.2g} for {materials.get(rec.name, rec.name)} at h = {rec.spacing_mm:g} mm".replace("e+", "e")
        for rec in records.values()
    )
    half = before.get("kalthoff_winkler_half_step", {})
    half_txt = ""
    if half.get("diverged_at") is not None:
        half_txt = f" (measured here: at half the automatic step too, at {_fmt_time(half['diverged_at'])})"
    paragraphs = [
        "**What diverged.** Automatic particle contact (on for any breakable body) made dynamic fracture runs go "
        "non-finite at their first contact, whatever the step: in the user's report a Kalthoff-Winkler steel plate "
        "(h = 2 mm, 32 m/s) at t = 14.5 us, also at half the automatic step, and a pre-cracked glass plate "
        "(h = 0.5 mm) at 28 us; both ran cleanly with contact off.",
        "**Why.** The contact modulus C_k = S_k / (12 (2 r_k)^3) [N/m^6] (S_k the bond stiffness row sum) grows as "
        f"E / h^5 ({moduli}). The pair modulus was evaluated as 2 C_k C_j / (C_k + C_j), whose product C_k C_j "
        "overflows float32 (3.4e38) for any C above 1.8e19, so the first pair to come within its contact distance "
        "got an infinite force (and inf x 0 = NaN in its dashpot). The step was never the issue, which is why "
        "halving it did not help" + half_txt + ". The contacts come from crack or notch faces sliding over each "
        "other: particles that were diagonal neighbours across the cut come within their contact distance 1.27 h "
        "after a slide of about 0.2 h.",
        "**The fix** (kernels/contact.py). The pair modulus is evaluated as 2 / (1/C_k + 1/C_j), and only products "
        "C V [N/m^4] (and the dashpot's sqrt(C V m / V)) are formed, all far inside float32's range. Also, as a "
        "guard rather than a fix: each particle's contact stiffness row sum is capped at 12 contacts' worth (a "
        "per-particle scale from the previous step, applied symmetrically per pair, so momentum stays exact), so "
        "`ParticleContact.stable_time_step()` bounds the contact springs whatever the number of contacts, and the "
        "Scene's automatic step (safety 0.7 < 1/sqrt(2)) keeps bonds plus contact inside the Silling-Askari bound. "
        f"The cap did not engage in these runs: no particle had more than {most} contacts (the cap is 12).",
        "**Measured** (automatic step, Scene defaults; W = work put in, E = kinetic + strain + contact energy; the "
        "ratio is the largest (E(t) - E(0)) / W(t) of the run, with the time it occurred; energy conservation keeps "
        "it below 1, as fracture, the contact dashpot and the inelastic floor and collider only take energy out):",
    ]
    lines = ["## Contact", "", "*Written by `tools/contact_stability.py` with the command below.*", ""]
    for paragraph in paragraphs:
        lines += [_wrap(paragraph), ""]
    lines += [
        "| case | particles | dt | end | before: non-finite at | after: first contact | after: end reached "
        "| max (E - E0) / W | W at end | max contacts per particle | run time |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, rec in records.items():
        b = before.get(name)
        if b is None:
            before_txt = "not run"
        elif b.get("diverged_at") is not None:
            before_txt = _fmt_time(b["diverged_at"])
        else:
            before_txt = f"ran to {_fmt_time(b['time'][-1])}"
        end_ok = "yes" if rec.diverged_at is None else f"no ({_fmt_time(rec.diverged_at)})"
        ratio, at = rec.energy_ratio()
        lines.append(
            f"| {rec.title} | {rec.particle_count} | {rec.dt * 1e9:.1f} ns | {_fmt_time(rec.time[-1])} "
            f"| {before_txt} | {_fmt_time(rec.first_contact())} | {end_ok} | {ratio:.3f} (t = {_fmt_time(at)}) "
            f"| {rec.work[-1]:.4g} J | {max(rec.max_count)} | {rec.wall_s:.1f} s |"
        )
    notes = []
    if revision:
        same = all(
            before.get(n, {}).get("diverged_at") is not None
            and abs(before[n]["diverged_at"] - (rec.first_contact() or -1.0)) < 0.5 * rec.dt
            for n, rec in records.items()
        )
        notes.append(
            f'"Before" is the same run with kernels/contact.py and pdsim/contact.py as of revision {revision} (the '
            "rest of the tree as measured), stopped at its first non-finite state"
            + (", which each time is the sample of the fixed run's first contact." if same else ".")
        )
        if "error" in before:
            notes.append(f"The before-run failed to start: {before['error']}.")
    notes.append(
        "The projectile's work is v_p . (P(t) - P(0)) (a kinematic projectile at constant velocity, the only "
        "external force); the grips' is the integral of reaction force times grip velocity plus the grips' own "
        f"kinetic energy (checked on the glass plate with fracture and notch off, h = 1 mm: at 30 us |E - E(0) - W| "
        f"= {balance:.1e} W). The glass plate is "
        "pulled at 45 degrees because a pull normal to the crack (mode I) separates the faces without a single "
        "contact (measured at h = 0.5 and 1 mm, 0.05 to 20 m/s), so the old code ran it."
    )
    for note in notes:
        lines += ["", _wrap(note)]
    lines += [
        "",
        "![energy against time](contact_energy.png)",
        "",
        _wrap(
            f"Machine: {platform.system()} {platform.machine()}, {os.cpu_count()} logical CPUs (shared with other "
            f"runs), Python {platform.python_version()}, Warp {_warp_version()}, device cpu; "
            f"{datetime.date.today().isoformat()}; {wall_s:.0f} s in all. Command:"
        ),
        "",
        f"    {command}",
        "",
    ]
    return "\n".join(lines)


def _warp_version() -> str:
    return wp.config.version


def _write_section(path: str, section: str) -> None:
    """Replaces the '## Contact' section of ``path`` (up to the next '## ' heading), or appends it."""
    text = "# Stability\n\nMeasured stability checks of the solvers.\n\n"
    if os.path.exists(path):
        with open(path) as f:
            text = f.read()
    lines = text.splitlines(keepends=True)
    start = next((i for i, line in enumerate(lines) if line.rstrip() == "## Contact"), None)
    if start is None:
        new = text.rstrip("\n") + "\n\n" + section
    else:
        end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")), len(lines))
        tail = "".join(lines[end:])
        new = "".join(lines[:start]) + section + ("\n" + tail if tail else "")
    with open(path, "w") as f:
        f.write(new.rstrip("\n") + "\n")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the tests' resolution (h = 4 mm steel, 1 mm glass)")
    parser.add_argument("--out", default=os.path.join(ROOT, "docs"), help="folder of stability.md and the PNG")
    parser.add_argument("--before", default=BEFORE_REVISION, help="git revision of the old contact code ('' skips)")
    parser.add_argument("--child", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--resolution", default="full", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        _child(args.child, args.resolution)
        return

    wp.config.quiet = True
    resolution = "quick" if args.quick else "full"
    start = time.perf_counter()
    records = {}
    for name, (h, end) in RESOLUTIONS[resolution].items():
        case = CASES[name](h)
        rec = run(case, end)
        records[name] = rec
        print(
            f"{name}: {case.particle_count} particles, dt {rec.dt:.3g} s, {len(rec.time) - 1} samples to "
            f"{rec.time[-1] * 1e6:.1f} us, diverged_at {rec.diverged_at}, first contact {rec.first_contact()}, "
            f"max (E - E0) / W {rec.energy_ratio()[0]:.3f}, {rec.wall_s:.1f} s",
            flush=True,
        )
    check = run(glass_plate(1.0e-3, breakable=False), 30.0e-6)  # the grips' work measure, without fracture
    balance = np.abs(check.total[-1] - check.total[0] - check.work[-1]) / check.work[-1]
    print(f"work check (unbreakable glass plate): |E - E0 - W| / W = {balance:.1e} at 30 us", flush=True)
    before = {}
    if args.before:
        before = run_before(args.before, resolution)
        for name, b in before.items():
            print(f"before ({args.before}) {name}: {b if name == 'error' else b.get('diverged_at')}", flush=True)
    wall = time.perf_counter() - start
    os.makedirs(args.out, exist_ok=True)
    _plot(records, before, os.path.join(args.out, "contact_energy.png"))
    command = "python tools/contact_stability.py" + (" --quick" if args.quick else "")
    if args.before != BEFORE_REVISION:
        command += f" --before '{args.before}'"
    section = _section(records, before, args.before or None, command, wall, balance)
    _write_section(os.path.join(args.out, "stability.md"), section)
    print(f"wrote {args.out}/stability.md and contact_energy.png in {wall:.0f} s")


if __name__ == "__main__":
    main()
