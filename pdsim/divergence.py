"""Watching a run: the watchdogs (pdsim.watchdog.Watchdog) a run attaches to its solvers, with the scene's speeds,
energy tolerance and projectiles, and the likely cause of a divergence that the watchdog's message names."""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from .colliders import rotation_between
from .solver import PointSolver
from .watchdog import TOTAL_TOLERANCE, Watchdog


def scene_speeds(scene, bounds) -> dict:
    """Speeds [m/s] the scene gives its bodies: ``motion`` (initial, prescribed and kick speeds, projectiles) and
    ``fall`` (from the highest point to the ground, or through the scene's height without one)."""
    g = float(np.linalg.norm(scene.gravity))
    motion = 0.0
    for b in scene.bodies:
        if hasattr(b, "prescribed_speed"):
            motion = max(motion, float(b.prescribed_speed()))
    for c in scene.colliders:
        if hasattr(c, "pose"):
            spin = float(np.linalg.norm(getattr(c, "angular_velocity", np.zeros(3))))
            radius = float(c._bounding_radius()) if hasattr(c, "_bounding_radius") else 0.0
            motion = max(motion, float(np.linalg.norm(getattr(c, "velocity", np.zeros(3)))) + spin * radius)
    fall = 0.0
    if g > 0.0:
        up = -np.asarray(scene.gravity, dtype=np.float64) / g
        lo, hi = (np.asarray(x, dtype=np.float64) for x in bounds)
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        heights = corners @ up
        height = float(heights.max() - heights.min())
        if scene.ground is not None:
            n = np.asarray(scene.ground.normal, dtype=np.float64)
            n = n / np.linalg.norm(n)
            if float(n @ up) > 0.5:
                height = max(0.0, float(heights.max()) - float(scene.ground.offset) / float(n @ up))
        fall = math.sqrt(2.0 * g * height)
    return {"motion": motion, "fall": fall}


def attach_watchdogs(scene, solvers, *, dt, stable_dt, bounds) -> list:
    """A pdsim.watchdog.Watchdog on every solver with mass (None for the others), with the scene's energy
    tolerance, projectile speeds and cause finder."""
    speeds = scene_speeds(scene, bounds)
    projectiles = [
        c for c in scene.colliders if callable(getattr(c, "pose", None)) or callable(getattr(c, "speed_bound", None))
    ]
    surface = surface_speed(projectiles) if projectiles else None
    automatic = scene.time_step_safety * stable_dt
    context = {
        "dt": dt,
        "stable_dt": stable_dt,
        "automatic": automatic,
        "factor": dt / automatic if automatic > 0.0 and math.isfinite(automatic) else 1.0,
        "speeds": speeds,
        "projectiles": projectiles,
    }
    out = []
    for s in solvers:
        if not isinstance(s, PointSolver):
            out.append(None)
            continue
        mass = float(np.sum(s.masses()))
        waves = [float(b.material.p_wave_speed) for b in s.bodies if hasattr(b, "material")]
        c = max(waves, default=0.0)
        floor = 0.5 * mass * (1.0e-6 * c) ** 2 + 1.0e-12  # round-off; the bounds scale with the energy flows
        overlap = False
        if getattr(s, "contact", None) is not None and s.time == 0.0:
            overlap = s.contact_energy() > 0.0
        ctx = dict(context, overlap=overlap)
        out.append(
            Watchdog(
                s,
                energy_floor=floor,
                surface_speed=surface,
                explain=lambda solver, index, position, what, ctx=ctx: likely_cause(
                    scene, solver, index, position, what, ctx
                ),
                energy=getattr(s, "integrator", "explicit") == "explicit",
                total_tolerance=TOTAL_TOLERANCE["automatic" if context["factor"] <= 1.0 + 1.0e-9 else "larger"],
            )
        )
    return out


def schedule_watchdogs(solvers, watchdogs, *, dt, speed_limit, every, stop) -> None:
    """Checks every ``every`` steps with ``speed_limit``; the first watchdog polls ``stop`` at the scene's step
    boundaries (an explicit FEM solver stepping alone splits a step above its stable limit into ``stride``
    steps of its own)."""
    points = [s for s in solvers if isinstance(s, PointSolver)]
    alone = len(points) == 1  # stepping by its own simulate (pdsim.run.advance_frame)
    first = True
    for s, w in zip(solvers, watchdogs):
        if w is None:
            continue
        w.interval, w.speed_limit = int(every), float(speed_limit)
        limit = getattr(getattr(s, "model", None), "explicit_dt", None)
        if alone and getattr(s, "integrator", None) == "explicit" and limit:
            w.stride = max(1, math.ceil(dt / limit - 1.0e-9))
        if first:
            w.stop = stop
            first = False


def likely_cause(scene, solver, index, position, what: str, ctx: dict) -> str:
    """The likely cause of a divergence (for the watchdog's message): the time step, stiffness, overlap or
    contact, with what to do."""
    dt, stable, factor = ctx["dt"], ctx["stable_dt"], ctx["factor"]
    step = f"dt = {dt:.3g} s, stable estimate {stable:.3g} s"
    if factor > 1.0 + 1.0e-6:
        return (
            f"the time step: it is {factor:.3g}x the automatic one ({step}); run at the automatic step "
            "(no --dt / --dt-factor, or --dt-factor <= 1)"
        )
    kin = solver.kin
    body = None
    if index is not None and len(kin.bodies):
        b = int(np.searchsorted(kin.body_offsets, index, side="right") - 1)
        body = kin.bodies[min(max(b, 0), len(kin.bodies) - 1)]
    candidates = [body] if body is not None else list(kin.bodies)
    speeds = ctx["speeds"]
    v = max(speeds["motion"], speeds["fall"])
    g = float(np.linalg.norm(scene.gravity))
    for b in candidates:
        material = getattr(b, "material", None)
        if material is None:
            continue
        c = float(material.p_wave_speed)
        x = np.asarray(getattr(b, "point_rest_positions", getattr(b, "rest_positions", np.zeros((1, 3)))))
        height = float(np.ptp(x @ (np.asarray(scene.gravity) / g))) if g > 0 else 0.0
        sag = material.density * g * height / material.youngs_modulus
        if v >= 0.5 * c:
            return (
                f"stiffness: '{b.name}' (E = {material.youngs_modulus:.3g} Pa) is too soft for the scene's speeds: "
                f"it moves at up to {v:.3g} m/s (impact, fall or prescribed) against its wave speed {c:.3g} m/s, "
                "so its particles pass through each other at any time step; a smaller step does not help: raise "
                f"youngs_modulus (to at least {4.0 * material.youngs_modulus * (v / c) ** 2:.3g} Pa) or lower the "
                f"speeds ({step})"
            )
        if sag >= 0.3:
            return (
                f"stiffness: '{b.name}' (E = {material.youngs_modulus:.3g} Pa) cannot carry its own weight "
                f"(rho g H / E = {sag:.2g}); a smaller step does not help: raise youngs_modulus ({step})"
            )
    collapse = "bond stretch" in what or "volume ratio" in what
    if collapse and not ctx.get("overlap"):
        return (
            "large deformation: the particles or elements of "
            f"'{body.name if body is not None else 'a body'}' were squeezed past each other (the deformation is "
            "larger than the discretisation resolves); a smaller step does not help: use a finer spacing or mesh, "
            f"contact (Scene.enable_contact) to keep particles apart, or a gentler load ({step})"
        )
    if ctx.get("overlap"):
        return (
            "overlap: particles of different bodies (or fragments) start closer than their contact distance, so "
            f"contact pushes them apart violently; move the bodies apart ({step})"
        )
    near = contact_near(scene, solver, index, position)
    if near:
        return (
            f"contact: it started where '{body.name if body is not None else 'a body'}' touches {near}; try "
            f"--dt-factor 0.5, or a stiffer material or slower impact ({step})"
        )
    return (
        f"the time step: the automatic step ({scene.time_step_safety:g} x the stable estimate; {step}) is too "
        "large for this scene; try --dt-factor 0.5 (or a lower time_step_safety)"
    )


def contact_near(scene, solver, index, position) -> str:
    """What the point at ``position`` [m] touches: the ground, a collider or another body (empty when nothing)."""
    if position is None or index is None:
        return ""
    p = np.asarray(position, dtype=np.float64)
    kin = solver.kin
    b = int(np.searchsorted(kin.body_offsets, index, side="right") - 1)
    body = kin.bodies[min(max(b, 0), len(kin.bodies) - 1)] if len(kin.bodies) else None
    h = float(getattr(body, "spacing", 0.0) or 0.0)
    if h <= 0.0:
        x = kin.rest_world
        h = float(np.linalg.norm(np.ptp(x, axis=0))) / 10.0
    if scene.ground is not None:
        n = np.asarray(scene.ground.normal, dtype=np.float64)
        n = n / np.linalg.norm(n)
        if float(p @ n) - float(scene.ground.offset) < 2.0 * h:
            return "the ground plane"
    for c in scene.colliders:
        if hasattr(c, "pose"):
            centre = c.pose(solver.time)[0]
            radius = float(c._bounding_radius()) if hasattr(c, "_bounding_radius") else 0.0
            if float(np.linalg.norm(p - centre)) < radius + 2.0 * h:
                return f"the collider '{c.name or type(c).__name__}'"
    contact = getattr(solver, "contact", None)
    if contact is not None:
        try:
            local = (kin.rest_world + kin.u.numpy().astype(np.float64)) - solver.origin
            x = wp.array(local.astype(np.float32), dtype=wp.vec3, device=solver.device)
            if contact.diagnostics(x).count[index] > 0:
                return "another body or fragment (particle contact)"
        except Exception:  # noqa: BLE001 - a diagnosis must not hide the instability
            return ""
    return ""


def surface_speed(projectiles):
    """(t, dt) -> the largest speed [m/s] of a projectile's surface over the step ending at t: its centre's speed plus
    its spin times its bounding radius (from ``pose``)."""

    def speed(t: float, dt: float) -> float:
        if dt <= 0.0:
            return 0.0
        best = 0.0
        for c in projectiles:
            if callable(getattr(c, "speed_bound", None)):  # a dynamic rigid body (pdsim/rigid.py)
                best = max(best, float(c.speed_bound(t)))
                continue
            p0, q0 = c.pose(t - dt)
            p1, q1 = c.pose(t)
            w = rotation_between(q0, q1) / dt
            radius = float(c._bounding_radius()) if hasattr(c, "_bounding_radius") else 0.0
            best = max(best, float(np.linalg.norm(p1 - p0)) / dt + float(np.linalg.norm(w)) * radius)
        return best

    return speed
