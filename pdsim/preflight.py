"""Pre-flight checks: what can be known about a scene before anything is allocated on the device or simulated.

:func:`preflight` looks at the scene's bodies (their rest points, shapes and meshes, all already on the host), its
colliders and ground plane, the run's time step and frame count and the output path, and raises one clear, one-line
error (ParameterError or GeometryError naming what is wrong and what is allowed) for a scene that could only fail
later: after minutes of allocation, with a native crash, or as a "diverged" run whose cause is not the time step.
``Scene.build_solvers`` calls it first; ``Scene.run`` calls it with the output path, time step and frame count.

Checks, in order (cheap and fundamental first):

1. the run's settings: frames, dt, the output path (suffix, existing folder, not a folder, writable, the frame
   folder free);
2. unique USD prim names (``"body 1"`` and ``"body_1"`` are both written as ``/World/body_1``);
3. counts: points and bonds within int32 indices, peridynamic constants within float32 (a body 1e6x too small);
4. substeps per frame: a user dt, or the automatic step estimated per body, must give at most
   MAX_SUBSTEPS_PER_FRAME substeps;
5. the cost estimate (pdsim/cost.py: time per frame, total time, the render surfaces' memory, the cache's size),
   printed when asked (``show``), and a warning naming the knobs when the run would take more than an hour; then
   memory: the estimate (bytes per particle, bond, vertex and element, measured, plus the render surfaces) against
   the free host memory (psutil, else /proc/meminfo and the cgroup limit) and, on CUDA, the device's free memory;
6. FEM element quality of meshes built directly as TetMesh (meshes from pdsim's loaders were checked on load);
7. bodies starting below the ground plane;
8. bodies overlapping each other, and colliders (projectiles, static meshes) starting inside a body;
9. free disk space against the estimated cache size (render surfaces included).

Everything is vectorised numpy (or one Warp inside-test launch per pair of bodies whose boxes overlap); nothing is
written to disk (the writability probe removes its file).
"""

from __future__ import annotations

import math
import os
import re
import tempfile
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from . import memory
from .cost import HOUR, body_counts, estimate_cost, fem_edge_length, format_seconds
from .checks import check_frames, check_range, check_time_step, format_bytes, unit_hint
from .colliders import BoxProjectile, MeshCollider, MeshProjectile, SphereProjectile, _rotate, collider_names
from .kernels.rigid import SHAPE_BOX, SHAPE_SPHERE
from .rigid import RigidBody
from .device import default_device
from .errors import GeometryError, ParameterError
from .fem.mesh import quality_problem
from .geometry import SolidShape
from .sampling import MAX_LATTICE_POINTS, lattice_counts, points_inside
from .timestep import MAX_SUBSTEPS_PER_FRAME, chosen_step, estimated_stable_step, projectile_step_limit

MAX_INDEX = 2**31 - 1  # particles, vertices, bonds and elements are indexed with int32 on the device

# Memory model: peak resident bytes of Scene.build_solvers on the CPU backend, fitted on cubes of 1.7e3 to 1.1e5
# particles and 0.2e6 to 3e7 bonds (tools/preflight_calibration.py): peridynamics 345 B per particle + 52 B per bond
# elastic, 67 B per bond with fracture and plasticity; FEM about 510 B per element with its vertices. Rounded up.
# The CPU's pair form of the bond passes (pdsim/peridynamics/pairs.py) adds its pair arrays and their build: 99-110 B
# per bond, particles included, against 53-59 for the directed form (20^3 and 30^3 blocks, elastic and breaking:
# `python tools/bench_pd_throughput.py --memory --n 20 [--fracture] [--directed]`), and 107-113 B breaking with
# plasticity (`--fracture --plastic`; 71 B directed), so the bond figure is the pair form's, rounded up.
PD_BYTES_PER_PARTICLE = 400
PD_BYTES_PER_BOND = 115
FEM_BYTES_PER_VERTEX = 400
FEM_BYTES_PER_ELEMENT = 450
LATTICE_BYTES_PER_POINT = 200
LATTICE_BYTES_PER_LINK = 24
HOST_BYTES_PER_POINT_ON_DEVICE = 400  # host arrays kept beside a CUDA solver's (rest positions, volumes, masses)
FLOAT32_LIMIT = 1.0e30  # largest peridynamic constant accepted (float32 holds 3.4e38; kernels multiply it further)


@dataclass
class PreflightReport:
    """What the pre-flight found: counts, estimates and the free resources they were checked against.

    points: particles, vertices and lattice points; bonds: estimated peridynamic bonds (interior count, an upper
    bound) and lattice links; elements: FEM elements. host_bytes / device_bytes: estimated peak memory [B]
    (device_bytes 0 on the CPU, where host_bytes holds everything); free_host_bytes / free_device_bytes [B] (None when
    unknown). dt_estimate: estimated automatic step [s] (inf without methods with mass), dt: the step the run would
    use (the user's, or the automatic estimate with the scene's safety factor), substeps: per frame. cache_bytes /
    free_disk_bytes: estimated cache size and free space [B] (None without an output path). seconds: wall time of the
    checks. warnings: what was warned about. estimate: what the run will cost (pdsim.cost.estimate_cost: seconds per
    frame, build and total seconds, render-surface vertices and memory, cache bytes, the calibration)."""

    points: int = 0
    bonds: int = 0
    elements: int = 0
    host_bytes: float = 0.0
    device_bytes: float = 0.0
    free_host_bytes: float | None = None
    free_device_bytes: float | None = None
    dt_estimate: float = math.inf
    dt: float = math.inf
    substeps: int = 1
    cache_bytes: float | None = None
    free_disk_bytes: float | None = None
    seconds: float = 0.0
    warnings: list = field(default_factory=list)
    estimate: dict = field(default_factory=dict)


# ---------------------------------------------------------------------------------------------------------- names
def usd_identifier(name: str) -> str:
    """The USD prim name pdsim writes for ``name``: pxr's Tf.MakeValidIdentifier, without importing pxr (each byte of
    the UTF-8 name that is not a letter, digit or underscore becomes '_', a leading digit too; '' gives '_')."""
    raw = re.sub(rb"[^A-Za-z0-9_]", b"_", str(name).encode("utf-8")).decode("ascii")
    if not raw:
        return "_"
    return "_" + raw[1:] if raw[0].isdigit() else raw


def prim_names(bodies, colliders=(), ground=None) -> list[tuple[str, str]]:
    """(prim path, what writes it) of everything a scene writes: per body its points ``/World/<name>``, its surface
    ``<name>_surface`` (peridynamics, FEM) and render mesh ``<name>_render`` (FEM with a render mesh); the ground
    ``/World/ground``; the colliders under ``/World/colliders``."""
    out = []
    for b in bodies:
        name = str(b.name)
        out.append((f"/World/{usd_identifier(name)}", f"body '{name}'"))
        method = getattr(type(b), "method", "")
        if method in ("peridynamics", "fem"):
            out.append((f"/World/{usd_identifier(name + '_surface')}", f"the surface of body '{name}'"))
        if method == "fem" and getattr(b, "render_mesh", None) is not None:
            out.append((f"/World/{usd_identifier(name + '_render')}", f"the render mesh of body '{name}'"))
    if ground is not None:
        out.append((f"/World/{usd_identifier(getattr(ground, 'name', None) or 'ground')}", "the ground plane"))
    if colliders:
        out.append(("/World/colliders", "the colliders' group"))
        for name in collider_names(colliders):
            out.append((f"/World/colliders/{usd_identifier(name)}", f"collider '{name}'"))
    return out


def check_prim_names(bodies, colliders=(), ground=None) -> None:
    """ParameterError naming both owners when two things of a scene are written to the same USD prim."""
    seen: dict[str, str] = {}
    for path, who in prim_names(bodies, colliders, ground):
        if path in seen:
            named = [w for w in (who, seen[path]) if "'" in w]  # a body or collider (not the ground or the group)
            name = named[0].split("'")[1] if named else who
            raise ParameterError(
                "name",
                name,
                f"a name whose USD prim is free: {who} and {seen[path]} are both written as {path} (USD names keep "
                "letters, digits and '_' and turn every other character into '_'); rename one",
            )
        seen[path] = who


# ---------------------------------------------------------------------------------------------------------- bodies
def _method(body) -> str:
    return getattr(type(body), "method", "")


def _bonds_per_particle(body) -> float:
    """Bonds of an interior particle: lattice points within the search radius, 4/3 pi r^3 - 1 with r = m (+ 1/2 with
    partial volumes) spacings; an upper bound of the mean (surface particles have fewer)."""
    r = body.horizon_factor + (0.5 if getattr(body, "partial_volumes", True) else 0.0)
    return 4.0 / 3.0 * math.pi * r**3 - 1.0


def check_particle_request(
    shape: SolidShape, spacing: float, horizon_factor: float, partial_volumes: bool, name: str | None = None
) -> float:
    """Before any sampling: the particle count a peridynamic body of ``spacing`` [m] gets in ``shape``, estimated from
    the lattice over its bounding box times the fraction of the box the shape fills, and ParameterError (one line: the
    estimate, the memory, the spacing that fits) when its solver's memory (PD_BYTES_PER_PARTICLE and
    PD_BYTES_PER_BOND per estimated bond) exceeds the largest free memory of the host and the CUDA devices. Returns
    the estimate. Values the body itself refuses (a spacing <= 0, ...) pass here untouched."""
    try:
        h = float(spacing)
        r = float(horizon_factor) + (0.5 if partial_volumes else 0.0)
    except (TypeError, ValueError):
        return 0.0
    if not (h > 0.0 and math.isfinite(h) and 1.5 <= r <= 9.0):
        return 0.0
    lo, hi = shape.bounds
    box_volume = float(np.prod(hi - lo))
    fill = min(max(shape.volume / box_volume, 0.0), 1.0) if box_volume > 0.0 else 1.0
    candidates = float(np.prod(lattice_counts(shape, h)))
    if candidates > MAX_LATTICE_POINTS:
        return candidates * fill  # the body's own check (pdsim.sampling.check_lattice_size) refuses it, as fast
    n = candidates * fill
    need = n * (PD_BYTES_PER_PARTICLE + (4.0 / 3.0 * math.pi * r**3 - 1.0) * PD_BYTES_PER_BOND)
    free = [f for f in (memory.free_host_memory(), *_free_cuda_memory()) if f is not None]
    if not free or need <= max(free):
        return n
    room = max(free)
    fits = h * (need / room) ** (1.0 / 3.0)
    raise ParameterError(
        "spacing",
        spacing,
        f"a spacing whose body fits in memory: '{name or shape.name}' at this spacing would hold about {n:.3g} "
        f"particles needing about {format_bytes(need)}, and the most free memory here is {format_bytes(room)}; "
        f"spacing >= {fits:.3g} m fits (memory grows as 1/spacing^3)" + unit_hint(float(np.max(hi - lo)), h, count=n),
    )


def _free_cuda_memory() -> list[float | None]:
    """Free memory [B] of each CUDA device (none on a machine without CUDA)."""
    return [memory.free_device_memory(f"cuda:{i}") for i in range(wp.get_cuda_device_count())]


def _body_counts(body) -> tuple[int, float, int]:
    """(points, bonds or links (estimated), elements) of a body."""
    method = _method(body)
    if method == "peridynamics":
        n = int(body.particle_count)
        return n, n * _bonds_per_particle(body), 0
    if method == "fem":
        return int(body.vertex_count), 0.0, int(body.element_count)
    return int(getattr(body, "particle_count", 0)), float(getattr(body, "link_count", 0)), 0


def _body_bytes(body) -> float:
    """Estimated peak memory of a body's part of its solver [B]."""
    n, bonds, elements = _body_counts(body)
    method = _method(body)
    if method == "peridynamics":
        return n * PD_BYTES_PER_PARTICLE + bonds * PD_BYTES_PER_BOND
    if method == "fem":
        return n * FEM_BYTES_PER_VERTEX + elements * FEM_BYTES_PER_ELEMENT
    return n * LATTICE_BYTES_PER_POINT + bonds * LATTICE_BYTES_PER_LINK


def _knob(body) -> tuple[str, float]:
    """The setting that sizes a body, as (field, value): a peridynamic or lattice spacing [m], or an FEM mesh's edge
    length [m] (estimated from its volume per element)."""
    if _method(body) == "fem":
        return "edge_length", fem_edge_length(body.mesh)
    return "spacing", float(body.spacing)


def _size(body) -> float:
    """Largest extent of a body's rest points [m]."""
    x = _rest_points(body)
    return float(np.max(x.max(axis=0) - x.min(axis=0))) if len(x) else 0.0


def _rest_points(body) -> np.ndarray:
    if hasattr(body, "point_rest_positions"):
        return np.asarray(body.point_rest_positions, dtype=np.float64)
    return np.asarray(getattr(body, "rest_positions", np.zeros((0, 3))), dtype=np.float64)


def _solid(body):
    """(sample points [m] [k, 3], their volumes [m^3] [k], closed surface SolidShape) of a body with mass: the
    particles and the input shape (peridynamics), or the element centroids and the boundary of the mesh (FEM; its
    vertices lie on its surface, where an inside test is ambiguous); None for other methods."""
    method = _method(body)
    if method == "peridynamics":
        return np.asarray(body.rest_positions), np.asarray(body.volumes), body.shape
    if method == "fem":
        mesh = body.mesh
        centroids = mesh.vertices[mesh.tets].mean(axis=1)
        surface = SolidShape(vertices=mesh.vertices, faces=mesh.boundary_faces(), name=body.name)
        return centroids, np.abs(mesh.volumes), surface
    return None


def _points_word(body) -> str:
    return {"peridynamics": "particles", "fem": "elements"}.get(_method(body), "points")


# ---------------------------------------------------------------------------------------------------------- checks
def check_output(out) -> str:
    """Checks an output path: suffix .usdc/.usda/.usd, an existing folder this process can write to (probed with a
    file it removes), not a folder itself, and its frame folder ``<stem>.frames`` not blocked by a file. Returns the
    path as str; ParameterError naming ``out`` otherwise."""
    out = os.fspath(out)
    if os.path.splitext(out)[1].lower() not in (".usdc", ".usda", ".usd"):
        raise ParameterError("out", out, "a path ending in .usdc, .usda or .usd")
    folder = os.path.dirname(os.path.abspath(out))
    if not os.path.isdir(folder):
        raise ParameterError("out", out, "a path in an existing folder")
    if os.path.isdir(out):
        raise ParameterError("out", out, "a file path, not a folder")
    try:
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".pdsim-write-test-")
        os.close(fd)
        os.remove(probe)
    except OSError as exc:
        raise ParameterError(
            "out", out, f"a path in a folder this process can write to ({folder}: {exc.strerror or exc})"
        ) from None
    stem = os.path.splitext(os.path.basename(out))[0]
    frames_dir = os.path.join(folder, f"{stem}.frames")
    if os.path.exists(frames_dir) and not os.path.isdir(frames_dir):
        raise ParameterError(
            "out", out, f"a path whose frame folder {frames_dir} is free (a file of that name is there)"
        )
    return out


def _check_float32(body) -> None:
    """A peridynamic body so small that its constants b = 15 mu / (2 pi delta^5) overflow float32."""
    if _method(body) != "peridynamics":
        return
    delta = float(body.horizon)
    mu = float(body.material.shear_modulus)
    kappa = float(body.material.bulk_modulus)
    b = 15.0 * max(mu, kappa) / (2.0 * math.pi * delta**5)
    if b > FLOAT32_LIMIT:
        delta_min = (15.0 * max(mu, kappa) / (2.0 * math.pi * FLOAT32_LIMIT)) ** 0.2
        size = _size(body)
        raise ParameterError(
            "spacing",
            body.spacing,
            f"a spacing >= {delta_min / body.horizon_factor:.3g} m for '{body.name}': at spacing {body.spacing:.3g} m "
            f"its peridynamic constants ({b:.3g} Pa/m^5) overflow float32; the body is {size:.3g} m across: is its "
            "mesh in the wrong units? (load_mesh(..., scale=...) turns it into metres)",
        )


def _check_substeps(scene, dt, report: PreflightReport, frames: int, dt_factor: float = 1.0) -> None:
    frame_time = float(scene.frame_time)
    steps = [(estimated_stable_step(b), b) for b in scene.bodies]
    dt_est, binding = min(steps, key=lambda s: s[0]) if steps else (math.inf, None)
    report.dt_estimate = dt_est
    if dt is not None:
        substeps = frame_time / dt
        if substeps > MAX_SUBSTEPS_PER_FRAME:
            raise ParameterError(
                "dt",
                dt,
                f"a step giving at most {MAX_SUBSTEPS_PER_FRAME:.0e} substeps per frame: a frame of {frame_time:.3g} s "
                f"at dt={dt:.3g} s needs {substeps:.3g}; use dt >= {frame_time / MAX_SUBSTEPS_PER_FRAME:.3g} s, or "
                f"leave dt automatic (the stable step is about {dt_est:.3g} s)",
            )
        report.dt = dt
    else:
        travel = projectile_step_limit(scene, frames)
        report.dt = chosen_step(frame_time, dt_est, scene.time_step_safety, dt_factor=dt_factor, travel_limit=travel)
        substeps = frame_time / report.dt if report.dt > 0.0 else math.inf
        if substeps > MAX_SUBSTEPS_PER_FRAME and dt_factor < 1.0 and substeps * dt_factor <= MAX_SUBSTEPS_PER_FRAME:
            raise ParameterError(
                "dt_factor",
                dt_factor,
                f"a factor giving at most {MAX_SUBSTEPS_PER_FRAME:.0e} substeps per frame: the automatic step "
                f"{scene.time_step_safety * dt_est:.3g} s x {dt_factor:g} needs {substeps:.3g} substeps for a frame of "
                f"{frame_time:.3g} s; use dt_factor >= {dt_factor * substeps / MAX_SUBSTEPS_PER_FRAME:.3g}",
            )
        if substeps > MAX_SUBSTEPS_PER_FRAME:
            field_name, value = _knob(binding)
            cp = binding.material.p_wave_speed
            raise ParameterError(
                field_name,
                value,
                f"a discretisation whose stable time step fits a frame in at most {MAX_SUBSTEPS_PER_FRAME:.0e} "
                f"substeps: '{binding.name}' ({field_name} {value:.3g} m, p-wave speed {cp:.3g} m/s) steps about "
                f"{report.dt:.3g} s, so a frame of {frame_time:.3g} s needs {substeps:.3g}; coarsen it, use a softer "
                "material or a shorter frame_time (time_scale)" + unit_hint(_size(binding), value, what=field_name),
            )
    report.substeps = max(1, math.ceil(substeps - 1.0e-9))


def _memory_estimate(scene, device: str, report: PreflightReport, surface_bytes: list[float]) -> list[float]:
    """Fills the report's estimated peak memory and the free memory: the solvers' (on the device on CUDA) and the
    render surfaces' (``surface_bytes`` per body [B], on the host); returns the estimate per body [B] (the device's
    on CUDA)."""
    per_body = [_body_bytes(b) for b in scene.bodies]
    total = float(sum(per_body))
    on_cuda = str(device).startswith("cuda")
    if on_cuda:
        report.device_bytes = total
        report.host_bytes = float(report.points * HOST_BYTES_PER_POINT_ON_DEVICE + sum(surface_bytes))
        report.free_device_bytes = memory.free_device_memory(device)
    else:
        per_body = [p + s for p, s in zip(per_body, surface_bytes)]
        report.host_bytes = float(sum(per_body))
    report.free_host_bytes = memory.free_host_memory()
    return per_body


def _check_memory(scene, device: str, report: PreflightReport, per_body: list[float]) -> None:
    """The estimated peak memory (:func:`_memory_estimate`, ``per_body`` [B]) against the free memory."""
    total = float(sum(per_body))
    on_cuda = str(device).startswith("cuda")
    checks = [("host", report.host_bytes, report.free_host_bytes)]
    if on_cuda:
        checks.insert(0, (f"{device} device", report.device_bytes, report.free_device_bytes))
    for where, need, free in checks:
        if free is None or need <= free:
            continue
        k = int(np.argmax(per_body))
        body = scene.bodies[k]
        field_name, value = _knob(body)
        n, bonds, elements = _body_counts(body)
        counts = f"{n:,} {_points_word(body) if _method(body) != 'fem' else 'vertices'}"
        if bonds:
            counts += f", about {bonds:.3g} {'bonds' if _method(body) == 'peridynamics' else 'links'}"
        if elements:
            counts += f", {elements:,} elements"
        share = per_body[k] / total if total > 0 else 1.0
        # the body's memory scales as 1/length^3; the rest of the scene stays: solve for the length that fits
        rest = need - per_body[k] * (need / total if total > 0 else 1.0)
        room = free - rest
        fit = value * ((need - rest) / room) ** (1.0 / 3.0) if room > 0 else value * (need / free) ** (1.0 / 3.0)
        raise ParameterError(
            field_name,
            value,
            f"a {field_name} whose scene fits in the {format_bytes(free)} of free {where} memory: the scene needs "
            f"about {format_bytes(need)}, {share:.0%} of it for '{body.name}' ({counts}); {field_name} >= "
            f"{fit:.3g} m fits (memory grows as 1/{field_name}^3)" + unit_hint(_size(body), value, what=field_name),
        )


def _check_counts(scene, report: PreflightReport) -> None:
    for what, count in (("points", report.points), ("bonds", report.bonds), ("elements", report.elements)):
        if count > MAX_INDEX:
            big = max(scene.bodies, key=lambda b: _body_counts(b)[0])
            field_name, value = _knob(big)
            raise ParameterError(
                field_name,
                value,
                f"a {field_name} giving at most {MAX_INDEX:,} {what} (int32 indices): the scene has about "
                f"{count:.3g}, most of them in '{big.name}'" + unit_hint(_size(big), value, what=field_name),
            )


def _check_fem_quality(scene) -> None:
    for b in scene.bodies:
        mesh = getattr(b, "mesh", None) if _method(b) == "fem" else None
        if mesh is None or getattr(mesh, "checked", True):
            continue
        problem = quality_problem(mesh.vertices, mesh.tets, float(getattr(mesh, "min_quality", 0.02)), b.name)
        if problem:
            raise GeometryError(problem)


def _check_ground(scene) -> None:
    ground = scene.ground
    if ground is None:
        return
    n = np.asarray(ground.normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    offset = float(ground.offset)
    for b in scene.bodies:
        if _method(b) not in ("peridynamics", "fem"):
            continue
        x = _rest_points(b)
        heights = x @ n
        tol = 1.0e-6 * max(_size(b), 1.0e-12)
        below = heights < offset - tol
        if below.any():
            low = float(heights.min())
            word = "particles" if _method(b) == "peridynamics" else "vertices"
            raise GeometryError(
                f"body '{b.name}' starts below the ground plane (height {offset:g} m along the up axis "
                f"{scene.up_axis}): {int(below.sum())} of its {len(x)} {word} are below it, the lowest at "
                f"{low:.3g} m; lower the ground (add_ground_plane(height={low:.3g}) or less) or move the body up"
            )


def _inside_shape(shape, points: np.ndarray, device: str) -> np.ndarray:
    """Bool mask of ``points`` inside a closed SolidShape: a bounding-box filter, then the exact winding-number test
    (pdsim.sampling.points_inside) on the points in the box only."""
    lo, hi = shape.bounds
    mask = np.all((points > lo) & (points < hi), axis=1)
    if mask.any():
        idx = np.flatnonzero(mask)
        mask[idx] = points_inside(shape, points[idx], device=device)
    return mask


def _check_overlaps(scene, device: str) -> None:
    solids = [(b, _solid(b)) for b in scene.bodies]
    solids = [(b, s) for b, s in solids if s is not None]
    boxes = [(s[0].min(axis=0), s[0].max(axis=0)) for _, s in solids]
    for i, (a, (pts, vols, _)) in enumerate(solids):
        for j, (b, (_, _, shape)) in enumerate(solids):
            if i == j:
                continue
            lo, hi = shape.bounds
            if np.any(boxes[i][1] < lo) or np.any(boxes[i][0] > hi):
                continue
            inside = _inside_shape(shape, pts, device)
            if inside.any():
                k = int(np.flatnonzero(inside)[0])
                vol = float(vols[inside].sum())
                where = ", ".join(f"{c:.3g}" for c in pts[k])
                raise GeometryError(
                    f"bodies '{a.name}' and '{b.name}' overlap at the start: {int(inside.sum())} {_points_word(a)} of "
                    f"'{a.name}' ({vol:.3g} m^3, {vol / float(vols.sum()):.1%} of its volume) lie inside '{b.name}', "
                    f"e.g. at ({where}) m; move them apart (bodies may touch, not interpenetrate)"
                )
    for c, label in zip(scene.colliders, collider_names(scene.colliders)):
        test = _collider_inside(c, device)
        if test is None:
            continue
        for a, (pts, vols, _) in solids:
            inside = test(pts)
            if inside.any():
                kind = "projectile" if hasattr(c, "pose") else "rigid body" if isinstance(c, RigidBody) else "collider"
                raise GeometryError(
                    f"{kind} '{label}' starts inside body '{a.name}': {int(inside.sum())} {_points_word(a)} of "
                    f"'{a.name}' ({float(vols[inside].sum()):.3g} m^3) lie inside it at t = 0; start it outside the "
                    "body (its surface may touch)"
                )


def _collider_inside(c, device: str):
    """A function points [k, 3] -> bool mask of the points inside a collider's volume at t = 0, or None."""
    if isinstance(c, SphereProjectile):
        p, _ = c.pose(0.0)
        r = float(c.sphere_radius)
        return lambda x: np.einsum("ij,ij->i", x - p, x - p) < r * r
    if isinstance(c, BoxProjectile):
        p, q = c.pose(0.0)
        q_inv = np.asarray(q, dtype=np.float64) * np.array([-1.0, -1.0, -1.0, 1.0])
        half = np.asarray(c.half_extents)
        return lambda x: np.all(np.abs(_rotate(q_inv, x - p)) < half, axis=1)
    if isinstance(c, MeshProjectile):
        p, q = c.pose(0.0)
        v, f = c.body_mesh()
        shape = SolidShape(vertices=_rotate(np.asarray(q), v) + p, faces=np.asarray(f, dtype=np.int32), name="mesh")
        return lambda x: _inside_shape(shape, x, device)
    if isinstance(c, MeshCollider):
        shape = SolidShape(vertices=c.vertices, faces=np.asarray(c.faces, dtype=np.int32), name="mesh")
        return lambda x: _inside_shape(shape, x, device)
    if isinstance(c, RigidBody):  # its shape at its initial pose
        p, q = c.position, c.orientation
        q_inv = np.asarray(q, dtype=np.float64) * np.array([-1.0, -1.0, -1.0, 1.0])
        if c.kind == SHAPE_SPHERE:
            return lambda x: np.einsum("ij,ij->i", x - p, x - p) < float(c.size[0]) ** 2
        if c.kind == SHAPE_BOX:
            return lambda x: np.all(np.abs(_rotate(q_inv, x - p)) < c.size, axis=1)
        v = _rotate(np.asarray(q), c.body_vertices) + p
        shape = SolidShape(vertices=v, faces=np.asarray(c.body_faces, dtype=np.int32), name="mesh")
        return lambda x: _inside_shape(shape, x, device)
    return None


def _check_disk(out: str, frames: int, report: PreflightReport, pack: bool) -> None:
    """The estimated cache (render surfaces included, pdsim.cost) against the free space of its folder; a packed cache
    needs its frames folder and the packed file at once at the end of the run, so twice the estimate."""
    folder = os.path.dirname(os.path.abspath(out))
    need = float(report.estimate["cache_bytes"])
    free = memory.free_disk_space(folder)
    report.cache_bytes, report.free_disk_bytes = need, free
    peak = 2.0 * need if pack else need
    if peak > free:
        how = " (twice, while the frames are packed into one file; --layout clips needs it once)" if pack else ""
        raise ParameterError(
            "out",
            out,
            f"a folder with room for the cache: {frames} frames of {report.points:,} points and their render surfaces "
            "need about "
            f"{format_bytes(need)}{how}, and {folder} has {format_bytes(free)} free; free some space, write elsewhere "
            "or run fewer frames",
        )
    if need > 0.5 * free:
        msg = (
            f"the cache may need about {format_bytes(need)} ({frames} frames of {report.points:,} points) and "
            f"{folder} has {format_bytes(free)} free; fracture surfaces can make it larger"
        )
        report.warnings.append(msg)
        warnings.warn(msg, stacklevel=3)


def _warn_time(scene, report: PreflightReport, frames: int) -> None:
    """A warning naming the knobs when the estimated run time exceeds pdsim.cost.HOUR."""
    e = report.estimate
    total = e.get("total_seconds")
    if total is None or total <= HOUR:
        return
    big = max(scene.bodies, key=lambda b: _body_counts(b)[0])
    field_name, value = _knob(big)
    power = 3 if _method(big) == "lattice" else 4  # points, and steps per frame but for the lattice's fixed count
    gpu = "" if str(e["device"]).startswith("cuda") else ", or a GPU (--device cuda)"
    basis = "" if e["calibrated"] else f" from the CPU's calibration (none for {e['device']} yet)"
    msg = (
        f"this run may take about {format_seconds(total)}{basis}: {frames} frames of about "
        f"{format_seconds(e['seconds_per_frame'])} ({report.points:,} points, {report.substeps} steps per frame); a "
        f"larger {field_name} than {value:.3g} m for '{big.name}' (time grows about as 1/{field_name}^{power}), fewer "
        f"frames{gpu} make it shorter"
    )
    report.warnings.append(msg)
    warnings.warn(msg, stacklevel=3)


def format_estimate(report: PreflightReport, frames: int) -> str:
    """The cost estimate as one line of text (see pdsim.cost)."""
    e = report.estimate
    cal = e["calibration"]
    basis = f"{cal['device'].upper()} calibration of {cal['date']}"
    if not e["calibrated"]:
        basis = f"the {cal['device'].upper()}'s calibration of {cal['date']}: none for {e['device']} yet"
    memory_bytes = report.host_bytes + report.device_bytes
    if e["seconds_per_frame"] is None:
        time_part = "time unknown (no calibration of the implicit or static FEM step)"
    else:
        time_part = (
            f"{format_seconds(e['seconds_per_frame'])} per frame, {format_seconds(e['total_seconds'])} for {frames} "
            f"frames"
        )
        if e.get("rebuilds_left_out"):
            time_part += " (at rest: frames where a body breaks also rebuild its render surface, not counted here)"
    return (
        f"pdsim: estimate: {report.points:,} points, {report.substeps} steps per frame: {time_part}; peak memory "
        f"{format_bytes(memory_bytes)}; cache {format_bytes(e['cache_bytes'])} (render surfaces of about "
        f"{e['surface_vertices']:,.0f} vertices included) [{basis}]"
    )


def print_estimate(report: PreflightReport, frames: int) -> None:
    """Prints :func:`format_estimate` to stdout."""
    print(format_estimate(report, frames), flush=True)


# ---------------------------------------------------------------------------------------------------------- entry
def preflight(
    scene,
    *,
    device: str | None = None,
    out=None,
    dt: float | None = None,
    frames: int | None = None,
    dt_factor: float = 1.0,
    pack: bool = True,
    show: bool = False,
):
    """Checks that ``scene`` can run before anything is allocated or simulated; returns a :class:`PreflightReport`.

    Args:
        scene: the pdsim.Scene.
        device: the Warp device the run will use ("cpu", "cuda", "cuda:0"); CUDA when present when None.
        out: the output cache path, or None to skip the output checks (Scene.build_solvers).
        dt: the user's time step [s], or None for the automatic step.
        frames: frames to run (the scene's when None).
        dt_factor: multiplier of the automatic step (Scene.run's ``dt_factor``), > 0; ignored with ``dt``.
        pack: whether the run packs its cache into one file at its end (the disk then needs twice the cache).
        show: print the cost estimate (:func:`print_estimate`) as soon as it is known, before the memory and disk
            checks.

    Warns (warnings.warn) when the estimated run time exceeds an hour (:func:`_warn_time`).

    Raises:
        ParameterError: a setting out of range (frames, dt, out, a spacing or edge length whose scene does not fit
            in memory, int32 indices or MAX_SUBSTEPS_PER_FRAME substeps, clashing USD names).
        GeometryError: bodies overlapping, a projectile or collider starting inside a body, a body starting below the
            ground plane, an FEM mesh with degenerate elements.
    """
    t0 = time.perf_counter()
    report = PreflightReport()
    if not scene.bodies:
        raise ParameterError("bodies", [], "a scene with at least one body")
    frame_count = scene.frames if frames is None else check_frames(frames)
    if dt is not None:
        dt = check_time_step(dt)
    if out is not None:
        out = check_output(out)
    check_prim_names(scene.bodies, scene.colliders, scene.ground)
    for b in scene.bodies:
        n, bonds, elements = _body_counts(b)
        report.points += n
        report.bonds += int(bonds)
        report.elements += elements
        _check_float32(b)
    _check_counts(scene, report)
    if device is None:
        device = default_device()
    _check_substeps(scene, dt, report, frame_count, check_range("dt_factor", dt_factor, 0.0, None))
    counts = [body_counts(b, _bonds_per_particle) for b in scene.bodies]
    report.estimate = estimate_cost(counts, substeps=report.substeps, frames=frame_count, device=str(device))
    surface_bytes = [estimate_cost([c], substeps=1, frames=0, device=str(device))["surface_bytes"] for c in counts]
    per_body = _memory_estimate(scene, str(device), report, surface_bytes)
    if show:
        print_estimate(report, frame_count)
    _warn_time(scene, report, frame_count)
    _check_memory(scene, str(device), report, per_body)
    _check_fem_quality(scene)
    _check_ground(scene)
    _check_overlaps(scene, str(device))
    if out is not None:
        _check_disk(out, frame_count, report, pack)
    report.seconds = time.perf_counter() - t0
    return report


__all__ = [
    "MAX_SUBSTEPS_PER_FRAME",
    "PreflightReport",
    "check_output",
    "check_prim_names",
    "preflight",
    "prim_names",
    "usd_identifier",
]
