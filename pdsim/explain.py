"""What a scene will run: per solver and body, the method, the live features, the kernels one step launches (in
order, with their launch dimensions), the device state allocated, and the time step and substeps per frame.

:func:`explain_scene` builds the scene's solvers exactly as :meth:`pdsim.Scene.run` does (on copies of the scene's
colliders and ground plane, so the scene itself is left as it was), chooses the time step with the same policy, and
records one step of every solver with ``warp.launch`` wrapped: the kernel list is what the solvers really launch, not a
description of it. The recorded step is taken on the freshly built solvers (whose state is then discarded), so
launches that depend on the time (velocity kicks due later, boundary conditions released later) show as they are at
t = 0; those are listed under "not every step". Building the solvers is the expensive part (families, surface
corrections, kernel compilation on a cold cache); nothing else is simulated.

``pdsim run --explain`` prints :func:`explain_scene`; :func:`scene_plan` returns the same facts as a dict.
"""

from __future__ import annotations

import contextlib
import copy
import math
import sys
import time

import warp as wp

from .bodies import PointBody
from .divergence import attach_watchdogs, schedule_watchdogs
from .errors import ParameterError
from .rigid import rigid_bodies_of
from .run import method_contact, rest_bounds, speed_limit
from .scene_script import load_scene_script
from .solver import PointSolver
from .timestep import frame_steps, projectile_step_limit

__all__ = ["capture_launches", "explain_scene", "scene_plan"]


# -- launch capture ---------------------------------------------------------------------------------------------------
class LaunchRecord:
    """The device work seen while a ``capture_launches`` block runs: ``entries``, a list of dicts in call order with
    ``kind`` ("kernel", "hash_grid_build", "copy", "mesh_refit"), ``name`` (the kernel's key), ``dim`` and ``owner``
    (the label current when it was made)."""

    def __init__(self):
        self.entries: list[dict] = []
        self.owner = ""

    def kernels(self, owner: str | None = None) -> list[tuple[str, object]]:
        """(kernel name, dim) of every kernel launch, in order (of one owner when given)."""
        return [
            (e["name"], e["dim"])
            for e in self.entries
            if e["kind"] == "kernel" and (owner is None or e["owner"] == owner)
        ]


def _dim(value):
    if isinstance(value, (list, tuple)):
        return tuple(int(v) for v in value)
    return int(value)


@contextlib.contextmanager
def capture_launches():
    """Context manager recording every ``warp.launch`` (kernel key and dim) and every hash-grid build, array copy and
    mesh refit made inside it; yields a :class:`LaunchRecord`. The launches still run."""
    record = LaunchRecord()
    launch, copy_fn = wp.launch, wp.copy
    grid_build, mesh_refit = wp.HashGrid.build, wp.Mesh.refit

    def recording_launch(kernel, *args, **kwargs):
        dim = kwargs.get("dim", args[0] if args else None)
        name = getattr(kernel, "key", str(kernel))
        record.entries.append({"kind": "kernel", "name": name, "dim": _dim(dim), "owner": record.owner})
        return launch(kernel, *args, **kwargs)

    def recording_copy(dest, src, *args, **kwargs):
        record.entries.append({"kind": "copy", "name": "warp.copy", "dim": _dim(src.size), "owner": record.owner})
        return copy_fn(dest, src, *args, **kwargs)

    def recording_build(self, points, radius):
        record.entries.append(
            {"kind": "hash_grid_build", "name": "HashGrid.build", "dim": _dim(points.shape[0]), "owner": record.owner}
        )
        return grid_build(self, points, radius)

    def recording_refit(self):
        record.entries.append(
            {"kind": "mesh_refit", "name": "Mesh.refit", "dim": _dim(self.points.shape[0]), "owner": record.owner}
        )
        return mesh_refit(self)

    wp.launch, wp.copy = recording_launch, recording_copy
    wp.HashGrid.build, wp.Mesh.refit = recording_build, recording_refit
    try:
        yield record
    finally:
        wp.launch, wp.copy = launch, copy_fn
        wp.HashGrid.build, wp.Mesh.refit = grid_build, mesh_refit


# -- device state ---------------------------------------------------------------------------------------------------
def _is_warp_array(obj) -> bool:
    return isinstance(obj, wp.array)


def _array_bytes(a) -> int:
    return int(a.size) * int(wp.types.type_size_in_bytes(a.dtype))


def _dtype_name(a) -> str:
    name = wp.types.type_repr(a.dtype) if hasattr(wp.types, "type_repr") else getattr(a.dtype, "__name__", "?")
    return name.rpartition(".")[2]


def _walk_state(root, prefix: str, out: dict, seen: set, depth: int = 0):
    """Collects Warp arrays (``out``: id -> (path, array)) and other Warp objects reachable from ``root`` through
    attributes, dicts, lists and tuples of pdsim objects (not into numpy arrays or bodies)."""
    if depth > 6 or id(root) in seen:
        return
    seen.add(id(root))
    if _is_warp_array(root):
        out.setdefault(id(root), (prefix, root))
        return
    if isinstance(root, (wp.HashGrid, wp.Mesh)):
        out.setdefault(id(root), (prefix, root))
        return
    if isinstance(root, dict):
        items = [(f"{prefix}[{k!r}]" if isinstance(k, (str, int)) else f"{prefix}[...]", v) for k, v in root.items()]
    elif isinstance(root, (list, tuple)):
        items = [(f"{prefix}[{i}]", v) for i, v in enumerate(root)]
    elif type(root).__module__.startswith(("pdsim", "kernels")) and hasattr(root, "__dict__"):
        if isinstance(root, PointBody) or type(root).__name__.endswith("Body"):
            return  # bodies hold host data (numpy)
        items = [(f"{prefix}.{k}" if prefix else k, v) for k, v in vars(root).items()]
    else:
        return
    for path, value in items:
        _walk_state(value, path, out, seen, depth + 1)


def device_state(solver) -> dict:
    """The Warp arrays a solver holds: ``arrays`` (list of dicts: path, dtype, shape, bytes; aliases counted once),
    ``total_bytes``, ``objects`` (hash grids and meshes: path and type; their memory is not counted)."""
    found: dict = {}
    _walk_state(solver, "", found, set())
    arrays, objects, by_ptr = [], [], {}
    for path, obj in found.values():
        if isinstance(obj, (wp.HashGrid, wp.Mesh)):
            objects.append({"path": path, "type": type(obj).__name__})
            continue
        key = (obj.ptr, obj.size, str(obj.dtype)) if obj.ptr else ("host", id(obj))
        if key in by_ptr:  # an alias (e.g. force = state.force_density): listed once
            by_ptr[key]["aliases"].append(path)
            continue
        entry = {
            "path": path,
            "dtype": _dtype_name(obj),
            "shape": tuple(int(s) for s in obj.shape),
            "bytes": _array_bytes(obj),
            "aliases": [],
        }
        by_ptr[key] = entry
        arrays.append(entry)
    arrays.sort(key=lambda e: (-e["bytes"], e["path"]))
    return {"arrays": arrays, "total_bytes": int(sum(e["bytes"] for e in arrays)), "objects": objects}


# -- the plan -------------------------------------------------------------------------------------------------------
def _fresh_copy(obj):
    """A shallow copy of a collider with its dict and list attributes copied too, so that stepping the copy (impulse
    accumulators, pose caches) leaves the scene's object as it was."""
    if obj is None:
        return None
    dup = copy.copy(obj)
    for key, value in list(vars(dup).items()):
        if isinstance(value, (dict, list)):
            setattr(dup, key, copy.copy(value))
    return dup


def _body_facts(body) -> dict:
    """Per body: name, method, point count and the body-level settings that turn features on."""
    facts = {"name": body.name, "method": getattr(body, "method", type(body).__name__), "type": type(body).__name__}
    n = getattr(body, "point_count", None) or getattr(body, "particle_count", None)
    if n is not None:
        facts["points"] = int(n)
    mat = getattr(body, "material", None)
    feats = []
    if mat is not None:
        facts["material"] = getattr(mat, "name", None) or type(mat).__name__
        if getattr(mat, "yields", False) or getattr(body, "plasticity", None) is not None:
            feats.append("plasticity")
        if getattr(body, "fractures", False):
            feats.append("fracture")
        if getattr(mat, "anisotropy", None) is not None:
            feats.append("anisotropy")
    if getattr(body, "conditions", None):
        feats.append("boundary_conditions")
    loads = getattr(body, "loads", None)
    if loads:
        feats.append("loads")
    if getattr(body, "kicks", None):
        feats.append("velocity_kicks")
    if getattr(body, "notches", None):
        feats.append("notches")
    if float(getattr(body, "damping", 0.0) or 0.0) > 0.0:
        feats.append("damping")
    for attr in ("spacing", "horizon"):
        value = getattr(body, attr, None)
        if isinstance(value, (int, float)):
            facts[attr] = float(value)
    for attr in ("measure", "integrator"):
        if isinstance(getattr(body, attr, None), str):
            facts[attr] = getattr(body, attr)
    if getattr(body, "method", "") == "fem":
        mesh = getattr(body, "mesh", None)
        if mesh is not None and hasattr(mesh, "element_count"):
            facts["elements"] = int(mesh.element_count)
    facts["features"] = feats
    return facts


def _solver_label(solver, index: int) -> str:
    return f"{index}:{type(solver).__name__}"


def _one_step(rec, labels, solvers, coupling, step_dt) -> None:
    """One step of every solver, as Scene.advance_frame takes it (the launches go to ``rec`` under each owner)."""
    coupled = [(lab, s) for lab, s in zip(labels, solvers) if isinstance(s, PointSolver)]
    for lab, s in zip(labels, solvers):
        if not isinstance(s, PointSolver):
            rec.owner = lab
            s.step()  # a lattice step (a frame is steps_per_frame of them)
    rigid = rigid_bodies_of([s for _, s in coupled])
    if len(coupled) == 1 and coupling is None and rigid is None:
        rec.owner = coupled[0][0]
        coupled[0][1].step(step_dt)
    elif coupled:  # the phases of Scene.advance_frame, one step
        if rigid is not None:
            rec.owner = "rigid_bodies"
            rigid.begin_step(step_dt)
        for lab, s in coupled:
            rec.owner = lab
            s.begin_step(step_dt)
        for lab, s in coupled:
            rec.owner = lab
            s.compute_forces()
        if coupling is not None:
            rec.owner = "method_contact"
            coupling.apply(step_dt)
        for lab, s in coupled:
            rec.owner = lab
            s.end_step(step_dt)
        if coupling is not None:
            rec.owner = "method_contact"
            coupling.end_step(step_dt)
        if rigid is not None:
            rec.owner = "rigid_bodies"
            rigid.end_step(step_dt)


def scene_plan(
    scene,
    device: str | None = "cpu",
    *,
    dt: float | None = None,
    dt_factor: float = 1.0,
    check_interval: int = 16,
) -> dict:
    """The facts :func:`explain_scene` prints, as a dict: scene fields, ``dt``, ``stable_dt``, ``substeps_per_frame``,
    ``build_seconds``, ``check_interval``, ``watchdog`` (whether one was attached, as Scene.run does) and ``solvers``
    (per solver: ``method``, ``class``, ``summary``, ``features``, ``bodies``, ``step_kernels`` (list of (name, dim)
    in launch order), ``step_operations`` (every recorded entry: kernels and hash-grid builds, copies, refits),
    ``check_kernels`` (the watchdog check every ``check_interval`` steps), ``per_frame_kernels`` (the frame-end
    check), ``state``), ``method_contact_kernels`` and ``rigid_body_kernels``.

    The solvers are built and watched as Scene.run builds and watches them; one step is taken untimed (work the
    watchdog defers to the next step shows from the second step on), then one step is recorded."""
    if not getattr(scene, "bodies", None):
        raise ParameterError("scene", scene, "a pdsim.Scene with at least one body")
    if dt is not None and not (dt > 0.0 and math.isfinite(dt)):
        raise ParameterError("dt", dt, "a finite time step > 0 [s] or None")
    if not (dt_factor > 0.0 and math.isfinite(dt_factor)):
        raise ParameterError("dt_factor", dt_factor, "a finite number > 0")
    if isinstance(check_interval, bool) or int(check_interval) != check_interval or check_interval < 1:
        raise ParameterError("check_interval", check_interval, "an integer >= 1")
    work = copy.copy(scene)
    work.colliders = [_fresh_copy(c) for c in scene.colliders]
    work.ground = _fresh_copy(scene.ground)
    t0 = time.perf_counter()
    solvers = work.build_solvers(device=device)
    wp.synchronize()
    build_seconds = time.perf_counter() - t0
    stable_dt = min(s.stable_time_step() for s in solvers)
    frame_dt = float(scene.frame_time)
    travel = projectile_step_limit(scene, scene.frames)
    steps = frame_steps(frame_dt, stable_dt, scene.time_step_safety, dt=dt, dt_factor=dt_factor, travel_limit=travel)
    substeps, step_dt = steps.substeps, steps.dt
    limit = speed_limit(work, solvers)

    labels = [_solver_label(s, i) for i, s in enumerate(solvers)]
    coupling = method_contact(work, solvers)
    # as the run: a watchdog per solver with mass, checking every check_interval steps
    dogs = attach_watchdogs(work, solvers, dt=step_dt, stable_dt=stable_dt, bounds=rest_bounds(work))
    schedule_watchdogs(solvers, dogs, dt=step_dt, speed_limit=limit, every=int(check_interval), stop=None)
    states = [device_state(s) for s in solvers]  # what the run holds before its first step
    with capture_launches() as first:  # untimed: the first step (work deferred to the next step is not in it)
        _one_step(first, labels, solvers, coupling, step_dt)
    with capture_launches() as rec:
        _one_step(rec, labels, solvers, coupling, step_dt)
    with capture_launches() as check_rec:  # the watchdog's check, every check_interval steps
        for lab, s in zip(labels, solvers):
            check_rec.owner = lab
            if getattr(s, "watchdog", None) is not None:
                s.check_state(limit)
    with capture_launches() as frame_rec:  # the frame-end check Scene.run makes after each frame
        for lab, s in zip(labels, solvers):
            frame_rec.owner = lab
            dog = getattr(s, "watchdog", None)
            if dog is not None:
                dog.full_check = True
            s.check_state(limit)
    wp.synchronize()

    out_solvers = []
    for lab, s, st in zip(labels, solvers, states):
        after = device_state(s)
        before_paths = {e["path"] for e in st["arrays"]}
        first_step = [e for e in after["arrays"] if e["path"] not in before_paths]
        entry = {
            "method": s.method,
            "class": type(s).__name__,
            "summary": s.summary(),
            "features": sorted(getattr(s, "features", set())),
            "bodies": [_body_facts(b) for b in s.bodies],
            "stable_dt": float(s.stable_time_step()),
            "step_kernels": rec.kernels(lab),
            "step_operations": [e for e in rec.entries if e["owner"] == lab],
            "first_step_kernels": first.kernels(lab),
            "check_kernels": check_rec.kernels(lab),
            "per_frame_kernels": frame_rec.kernels(lab),
            "state": st,
            "allocated_in_first_step": first_step,
        }
        if not isinstance(s, PointSolver):
            entry["steps_per_frame"] = int(getattr(s, "steps_per_frame", 1))
        out_solvers.append(entry)
    return {
        "scene": getattr(scene, "name", "scene"),
        "device": str(solvers[0].device) if hasattr(solvers[0], "device") else str(device),
        "frames": int(scene.frames),
        "fps": float(scene.fps),
        "frame_time": frame_dt,
        "dt": step_dt,
        "dt_given": dt is not None,
        "stable_dt": float(stable_dt),
        "time_step_safety": float(scene.time_step_safety),
        "dt_factor": float(dt_factor),
        "substeps_per_frame": substeps,
        "check_interval": int(check_interval),
        "watchdog": any(d is not None for d in dogs),
        "build_seconds": build_seconds,
        "solvers": out_solvers,
        "method_contact_kernels": rec.kernels("method_contact"),
        "rigid_body_kernels": rec.kernels("rigid_bodies"),
    }


# -- text -----------------------------------------------------------------------------------------------------------
def _bytes(n: int) -> str:
    for unit, scale in (("GB", 1 << 30), ("MB", 1 << 20), ("kB", 1 << 10)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{n} B"


def _dim_text(dim) -> str:
    return "x".join(str(d) for d in dim) if isinstance(dim, tuple) else str(dim)


def _short_kernel(name: str) -> str:
    """The kernel's own name: keys of kernels built in a factory read ``<factory>__locals__<name>`` and some carry a
    hash suffix."""
    name = name.rpartition("__locals__")[2]
    head, sep, tail = name.rpartition("_")
    if sep and len(tail) >= 8 and all(c in "0123456789abcdef" for c in tail):
        return head
    return name


def _kernel_lines(entries, indent: str) -> list[str]:
    lines = []
    for i, e in enumerate(entries, 1):
        if e["kind"] == "kernel":
            lines.append(f"{indent}{i:2d}. {_short_kernel(e['name']):<34s} dim {_dim_text(e['dim'])}")
        else:
            lines.append(f"{indent}{i:2d}. ({e['name']}, {e['kind'].replace('_', ' ')} of {_dim_text(e['dim'])})")
    return lines


def _group_state(arrays) -> dict[str, list]:
    groups: dict[str, list] = {}
    for a in arrays:
        path = a["path"]
        head = path.split(".")[0].split("[")[0] if ("." in path or "[" in path) else "solver"
        groups.setdefault(head, []).append(a)
    return groups


_NOT_EVERY_STEP = {
    "velocity_kicks": "add_velocity: once per velocity kick, in the step that reaches its time",
    "fracture": "per frame with output: damage and fragment labels (compute_damage, connected components on the host)",
    "contact": "every step: the contact pass rebuilds its hash grid on the current positions (listed above)",
}


def format_plan(plan: dict) -> str:
    """Text of a :func:`scene_plan` result."""
    lines = [
        f"scene '{plan['scene']}': {plan['frames']} frames at {plan['fps']:g} fps, {plan['frame_time']:.4g} s of "
        f"simulated time per frame; device {plan['device']}",
    ]
    factor = plan["dt_factor"] * plan["time_step_safety"]
    how = "given" if plan["dt_given"] else f"{factor:g} x the stable estimate"
    lines.append(
        f"time step {plan['dt']:.4g} s ({how}; stable estimate {plan['stable_dt']:.4g} s), "
        f"{plan['substeps_per_frame']} substeps per frame, {plan['substeps_per_frame'] * plan['frames']} steps in all"
    )
    lines.append(f"solvers built in {plan['build_seconds']:.2f} s")
    for s in plan["solvers"]:
        lines.append("")
        lines.append(f"{s['method']} ({s['class']}): {s['summary']}")
        lines.append(f"  live features: {', '.join(s['features']) or 'none'}")
        lines.append(f"  stable time step: {s['stable_dt']:.4g} s")
        for b in s["bodies"]:
            extra = []
            if "points" in b:
                extra.append(f"{b['points']} points")
            if "elements" in b:
                extra.append(f"{b['elements']} elements")
            if "spacing" in b:
                extra.append(f"spacing {b['spacing']:.4g} m")
            if "horizon" in b:
                extra.append(f"horizon {b['horizon']:.4g} m")
            if "material" in b:
                extra.append(f"material {b['material']}")
            extra += [f"{b[k]} {k}" for k in ("measure", "integrator") if k in b]
            feats = ", ".join(b["features"]) or "elastic only"
            lines.append(f"  body '{b['name']}' ({b['method']}): {', '.join(extra)}; {feats}")
        if "steps_per_frame" in s:
            lines.append(f"  {s['steps_per_frame']} lattice steps per frame; one step launches:")
        else:
            others = len(s["step_operations"]) - len(s["step_kernels"])
            more = f" and {others} other device operation{'s' if others != 1 else ''}" if others else ""
            lines.append(f"  one step: {len(s['step_kernels'])} kernel launches{more}, in order:")
        lines += _kernel_lines(s["step_operations"], "    ")
        if s["first_step_kernels"] != s["step_kernels"]:
            names = ", ".join(_short_kernel(k) for k, _ in s["first_step_kernels"])
            lines.append(f"  (the run's first step differs: {names})")
        if s["check_kernels"]:
            names = ", ".join(_short_kernel(k) for k, _ in s["check_kernels"])
            lines.append(f"  every {plan['check_interval']} steps, the watchdog's check: {names}")
        if s["per_frame_kernels"]:
            names = ", ".join(_short_kernel(k) for k, _ in s["per_frame_kernels"])
            lines.append(f"  at each frame end, the watchdog's full check: {names}; then the output views")
        notes = [text for feat, text in _NOT_EVERY_STEP.items() if feat in s["features"] and feat != "contact"]
        if notes:
            lines.append("  not every step:")
            lines += [f"    - {t}" for t in notes]
        st = s["state"]
        lines.append(f"  device state: {len(st['arrays'])} arrays, {_bytes(st['total_bytes'])}")
        for head, arrays in sorted(_group_state(st["arrays"]).items(), key=lambda kv: -sum(a["bytes"] for a in kv[1])):
            total = sum(a["bytes"] for a in arrays)
            lines.append(f"    {head}: {len(arrays)} arrays, {_bytes(total)}")
            for a in arrays:
                alias = f" (also {', '.join(a['aliases'])})" if a["aliases"] else ""
                shape = "x".join(str(d) for d in a["shape"])
                lines.append(f"      {a['path']:<36s} {a['dtype']:>8s}[{shape}] {_bytes(a['bytes']):>9s}{alias}")
        if st["objects"]:
            objs = ", ".join(f"{o['path']} ({o['type']})" for o in st["objects"])
            lines.append(f"    plus Warp objects (memory not counted): {objs}")
        if s["allocated_in_first_step"]:
            first = ", ".join(f"{a['path']} ({_bytes(a['bytes'])})" for a in s["allocated_in_first_step"])
            lines.append(f"    allocated by the first step: {first}")
    if plan["method_contact_kernels"]:
        lines.append("")
        lines.append("contact between methods, each step:")
        lines += [f"  {_short_kernel(k)} dim {_dim_text(d)}" for k, d in plan["method_contact_kernels"]]
    if plan["rigid_body_kernels"]:
        lines.append("")
        lines.append("dynamic rigid bodies, each step (their contact with the points is in the solvers' steps):")
        lines += [f"  {_short_kernel(k)} dim {_dim_text(d)}" for k, d in plan["rigid_body_kernels"]]
    return "\n".join(lines)


def explain_scene(
    scene,
    device: str | None = "cpu",
    *,
    dt: float | None = None,
    dt_factor: float = 1.0,
    check_interval: int = 16,
) -> str:
    """What ``scene`` will run, as text: per solver (one per method) its bodies, live features, the kernels one step
    launches in order with their dims (recorded by wrapping ``warp.launch`` during a step of freshly built solvers,
    watched as Scene.run watches them), the watchdog's checks, the device arrays allocated (bytes), and the time step
    and substeps per frame (the rule of pdsim.timestep; ``dt`` and ``dt_factor`` as ``pdsim run --dt`` and
    ``--dt-factor``; ``check_interval`` as ``--check-interval``). The scene is not modified."""
    return format_plan(scene_plan(scene, device, dt=dt, dt_factor=dt_factor, check_interval=check_interval))


if __name__ == "__main__":  # pragma: no cover - python -m pdsim.explain scenes/x.py [device]
    print(explain_scene(load_scene_script(sys.argv[1])(), sys.argv[2] if len(sys.argv) > 2 else "cpu"))
