"""The time-step rule, in one place: the run (pdsim.run), ``pdsim run --explain`` (pdsim.explain) and the pre-flight
checks (pdsim.preflight) all take the step from here.

The rule: the automatic step is ``time_step_safety`` x the smallest stable step of the scene's solvers, times the
user's ``dt_factor``, at most the step in which the fastest projectile's surface travels PROJECTILE_TRAVEL spacings
of the finest body (so that no projectile passes through a body between two steps), and at most one frame; a user
``dt`` replaces it (with a warning when it is past the stable estimate or the projectiles' limit). The frame is then
cut into ``substeps = ceil(frame_time / step)`` equal steps, so the step used is ``frame_time / substeps`` <= the
chosen step.

Before the solvers exist (the pre-flight), the stable step is estimated from the bodies: 0.3 m h / c_p for a
peridynamic body (m = horizon / spacing), 0.5 h_min / c_p for an FEM body, h_min its smallest element height after
the mass scaling (pdsim.fem.body.mass_scaled_heights; times ``implicit_step_ratio`` with the implicit integrator), no
limit for the lattice.
"""

from __future__ import annotations

import itertools
import math
import warnings
from dataclasses import dataclass

import numpy as np

from .colliders import RigidProjectile, rotation_between
from .fem.body import mass_scaled_heights
from .fem.mesh import element_heights
from .fem.model import EXPLICIT_STEP_FACTOR

MAX_SUBSTEPS_PER_FRAME = 10_000_000
# most a projectile's surface may travel in one automatic step [spacings of the finest body]: a particle a projectile
# reaches is then inside it by at most half a spacing, and pushed out, at the step it reaches it
PROJECTILE_TRAVEL = 0.5
# Silling-Askari step ~ 0.3 m h / c_p (measured 0.55 / 0.92 / 1.76 h / c_p at m = 1.5 / 3 / 6: docs/stability.md)
PD_STEP_COEFFICIENT = 0.3


@dataclass(frozen=True)
class FrameSteps:
    """How a frame is stepped: ``dt`` [s] (frame_time / substeps), ``substeps`` per frame, the ``stable_dt`` [s] it
    was derived from and the ``automatic`` step [s] (time_step_safety x stable_dt)."""

    dt: float
    substeps: int
    stable_dt: float
    automatic: float

    travel_limit: float = math.inf  # the projectiles' limit on the automatic step [s] (inf without projectiles)

    @property
    def factor(self) -> float:
        """The step used over the automatic one (1 at the automatic step)."""
        return self.dt / self.automatic if self.automatic > 0.0 and math.isfinite(self.automatic) else 1.0


def chosen_step(
    frame_time: float, stable_dt: float, safety: float, *, dt=None, dt_factor: float = 1.0, travel_limit=math.inf
) -> float:
    """The step [s] before the frame is cut into substeps: ``dt`` when given, else
    ``min(dt_factor * safety * stable_dt, travel_limit, frame_time)``."""
    if dt is not None:
        return float(dt)
    return min(dt_factor * (safety * stable_dt), travel_limit, frame_time)


def substeps_for(frame_time: float, step: float) -> int:
    """Substeps of a frame of ``frame_time`` [s] at a step of at most ``step`` [s] (at least 1)."""
    return max(1, math.ceil(frame_time / step - 1.0e-9))


def frame_steps(
    frame_time: float,
    stable_dt: float,
    safety: float,
    *,
    dt=None,
    dt_factor: float = 1.0,
    travel_limit: float = math.inf,
    warn: bool = False,
) -> FrameSteps:
    """The rule (module docstring) for a frame of ``frame_time`` [s]; ``travel_limit`` [s] is the projectiles' limit
    (:func:`projectile_step_limit`). ``warn`` warns when the step is past the automatic one (``dt_factor`` > 1), or a
    user ``dt`` is past the stable estimate (the watchdog still catches a divergence) or the projectiles' limit."""
    automatic = safety * stable_dt
    step = chosen_step(frame_time, stable_dt, safety, dt=dt, dt_factor=dt_factor, travel_limit=travel_limit)
    if warn and dt is None and dt_factor > 1.0:
        warnings.warn(
            f"dt_factor={dt_factor:g}: the time step is {dt_factor:g}x the automatic one ({automatic:.3g} s, "
            f"{safety:g} x the stable estimate {stable_dt:.3g} s); the watchdog stops the run if it diverges",
            stacklevel=4,
        )
    elif warn and dt is not None and dt > stable_dt:
        warnings.warn(
            f"time step {dt:.3g} s exceeds the stable estimate {stable_dt:.3g} s; the watchdog checks the run for "
            "divergence every few steps",
            stacklevel=4,
        )
    if warn and dt is not None and dt > travel_limit:
        warnings.warn(
            f"time step {dt:.3g} s lets a projectile travel more than {PROJECTILE_TRAVEL:g} spacings per step (at most "
            f"{travel_limit:.3g} s keeps it within): it can pass through thin parts without touching them",
            stacklevel=4,
        )
    substeps = substeps_for(frame_time, step)
    return FrameSteps(frame_time / substeps, substeps, stable_dt, automatic, travel_limit)


def finest_spacing(bodies) -> float:
    """The smallest particle spacing (peridynamics) or element height (FEM) [m] of ``bodies``; inf without such
    bodies."""
    sizes = [math.inf]
    for b in bodies:
        method = getattr(type(b), "method", "")
        if method == "peridynamics":
            sizes.append(float(b.spacing))
        elif method == "fem":
            sizes.append(float(np.min(element_heights(b.mesh.vertices, b.mesh.tets))))
    return min(sizes)


def projectile_speed(projectile, duration: float) -> float:
    """The largest speed [m/s] of a projectile's surface over [0, ``duration``] s: its origin's speed plus its spin
    times its bounding radius. Ballistic motion: at the ends of the interval (the speed of a constant acceleration is
    largest there); a path: finite differences over max(256, 1 per 0.1 ms) samples. A dynamic rigid body
    (pdsim/rigid.py): its ``speed_bound``."""
    if callable(getattr(projectile, "speed_bound", None)):
        return float(projectile.speed_bound(duration))
    radius = float(projectile._bounding_radius())
    if projectile.path is None:
        ends = [projectile.velocity, projectile.velocity + projectile.gravity * duration]
        spin = float(np.linalg.norm(projectile.angular_velocity))
        return max(float(np.linalg.norm(v)) for v in ends) + spin * radius
    count = int(min(max(256, duration / 1.0e-4), 100_000))
    times = np.linspace(0.0, duration, count + 1)
    poses = [projectile.pose(t) for t in times]
    step = duration / count
    speed = 0.0
    for (p0, q0), (p1, q1) in itertools.pairwise(poses):
        spin = float(np.linalg.norm(rotation_between(q0, q1))) / step
        speed = max(speed, float(np.linalg.norm(p1 - p0)) / step + spin * radius)
    return speed


def projectile_step_limit(scene, frames: int) -> float:
    """The largest step [s] at which no projectile's surface travels more than PROJECTILE_TRAVEL spacings of the
    scene's finest body in one step over the ``frames`` frames; inf without projectiles or moving ones."""
    projectiles = [
        c for c in scene.colliders if isinstance(c, RigidProjectile) or callable(getattr(c, "speed_bound", None))
    ]
    h = finest_spacing(scene.bodies)
    if not projectiles or not math.isfinite(h):
        return math.inf
    speed = max(projectile_speed(c, frames * float(scene.frame_time)) for c in projectiles)
    return PROJECTILE_TRAVEL * h / speed if speed > 0.0 else math.inf


def estimated_stable_step(body) -> float:
    """A body's stable explicit step [s] estimated before its solver is built, without the safety factor (module
    docstring); inf for bodies without mass (the lattice)."""
    method = getattr(type(body), "method", "")
    cp = float(getattr(getattr(body, "material", None), "p_wave_speed", math.inf))
    if method == "peridynamics":
        return PD_STEP_COEFFICIENT * body.horizon_factor * body.spacing / cp
    if method == "fem":
        heights = mass_scaled_heights(element_heights(body.mesh.vertices, body.mesh.tets), body.mass_scaling)
        dt = EXPLICIT_STEP_FACTOR * float(np.min(heights)) / cp
        if getattr(body, "integrator", "explicit") == "implicit":
            dt *= float(getattr(body, "implicit_step_ratio", 1.0))
        return dt
    return math.inf
