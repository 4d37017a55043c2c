"""Parameter sweeps and wedges on Dask (``pip install -e ".[sweep]"``).

Two entry points, each running one task per point on ``dask.distributed``:

- :func:`run_sweep` runs a validation problem (:mod:`pdsim.reference_problems`) over a grid of knobs and returns one
record per point (error, run time, peak memory, knobs).
- :func:`run_wedge` runs a scene script once per variant of its settings and writes one USD cache per variant,
  plus ``wedge.json`` listing them.

Where the tasks run (``scheduler=``):

- ``None`` (default): a ``LocalCluster`` on this machine, one worker process per core, one thread per worker (Warp's
  CPU kernels are single-threaded, so a worker with more threads only contends), closed at the end.
- ``"tcp://host:8786"``: the scheduler of a farm (``dask scheduler`` on one machine, ``dask worker tcp://host:8786
  --nthreads 1`` on each worker machine, pdsim installed in each). The workers must see the scene script and the
  output folder at the same paths (a shared file system).
- a ``distributed.Client`` or a cluster object (``LocalCluster(processes=False)`` for a light in-process run): used
  as given and left open.

Each task imports pdsim in its worker. A script that uses the default LocalCluster starts worker processes, so it
must make its calls under ``if __name__ == "__main__":``. A point that fails does not stop the others: its record
carries ``failed`` (the exception's type and message) and ``error`` NaN (sweeps), or ``failed`` and no ``path``
(wedges).

Wedge settings (``settings={"material.fracture_energy": [1, 2, 5], "scene.fps": [24, 48]}``: every combination of
the values runs, in the order of the product). A setting's name says where its value goes:

- ``NAME`` (no dot): a keyword argument of the script's ``build_scene(**overrides)`` - the way to change anything
  the script uses while building (a spacing, a size, a speed), e.g. ``spacing=[0.02, 0.01]`` with
  ``def build_scene(spacing=0.02): ...``. The function must name the keyword (or take ``**kwargs``).
- ``scene.ATTR``: the scene after building; ATTR is one of ``fps`` (the playback rate; a real-time scene keeps
  frame_time = 1/fps), ``frames``, ``frame_time`` [s], ``time_scale``, ``time_step_safety``, ``gravity`` [m/s^2].
- ``material.FIELD``: every body's material is replaced by a copy with FIELD changed (any field of
  :class:`pdsim.Material`, e.g. ``fracture_energy``, ``youngs_modulus``; the Material's checks apply).
- ``body.NAME.material.FIELD``: the same for one body (by its name in the scene).
- ``body.NAME.ATTR``: an attribute of one body that is read when the solver is built: peridynamic ``damping``,
  ``horizon_factor``, ``surface_correction``, ``partial_volumes``; FEM ``damping``, ``measure``, ``integrator``,
  ``tensile_strength``, ``implicit_step_ratio``; lattice ``steps_per_frame``. Attributes fixed when the body is
  built (its ``spacing``, mesh or shape) are refused with a message saying to make them a ``build_scene`` keyword.

Names and values are checked before any task is submitted (the scene is built once here with the first values of
the keyword settings), so a typo fails at once with :class:`pdsim.ParameterError` naming the setting.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import inspect
import itertools
import json
import math
import os
import re
import socket
import sys
import time
from contextlib import contextmanager

import numpy as np
import warp as wp

from . import reference_problems
from .checks import check_frames, check_range
from .errors import ParameterError
from .fem.body import INTEGRATORS, MEASURES
from .materials import Material
from .peridynamics.body import SURFACE_CORRECTIONS
from .scene import Scene
from .scene_script import load_scene_script

__all__ = [
    "apply_settings",
    "bench_accuracy",
    "build_variant",
    "grid_points",
    "parse_settings",
    "run_sweep",
    "run_sweeps",
    "run_wedge",
    "wedge_variants",
]

SCENE_SETTINGS = ("fps", "frames", "frame_time", "time_scale", "time_step_safety", "gravity")
BODY_SETTINGS = {
    "peridynamics": ("damping", "horizon_factor", "surface_correction", "partial_volumes"),
    "fem": ("damping", "measure", "integrator", "tensile_strength", "implicit_step_ratio"),
    "lattice": ("steps_per_frame",),
}
WORKER_ENV = {
    "OMP_NUM_THREADS": "1",  # one thread per worker: numpy's BLAS too
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "MALLOC_MMAP_THRESHOLD_": "131072",  # large arrays always mmapped, so freed memory leaves the process (its peak
}  # resident memory per point then measures that point, not what earlier points left in glibc's heap)
BUILT_WITH_BODY = ("spacing", "shape", "mesh", "edge_length", "lattice", "rest_positions", "volumes", "name")


# -- Dask --------------------------------------------------------------------------------------------------------------
def _import_distributed():
    try:
        import distributed
    except ImportError:
        raise ParameterError(
            "scheduler", "dask.distributed", 'installed: pip install -e ".[sweep]" (dask[distributed])'
        ) from None
    return distributed


@contextmanager
def _client(scheduler, workers: int | None):
    """A distributed.Client for ``scheduler`` (see the module docstring); closes what it opened."""
    distributed = _import_distributed()
    if isinstance(scheduler, distributed.Client):
        yield scheduler
        return
    if scheduler is None:
        n = workers or max(1, os.cpu_count() or 1)
        cluster = distributed.LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            env=WORKER_ENV,
        )
        client = distributed.Client(cluster)
        try:
            yield client
        finally:
            client.close()
            cluster.close()
        return
    if isinstance(scheduler, str) or hasattr(scheduler, "scheduler_address"):
        try:
            client = distributed.Client(scheduler)
        except (OSError, TimeoutError) as exc:
            raise ParameterError("scheduler", scheduler, f"a reachable Dask scheduler ({exc})") from None
        try:
            yield client
        finally:
            client.close()
        return
    raise ParameterError("scheduler", scheduler, "None, a scheduler address 'tcp://host:8786', a Client or a cluster")


def _warm_worker() -> str:
    """Imports pdsim's methods and loads their kernels in a worker with tiny runs, so that no point's time includes
    the first imports of its process (Warp's kernel cache on disk makes the loads quick)."""
    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING
    reference_problems.cantilever(1, method="fem")
    reference_problems.pd_energy_density(1.6, surface_correction="none")
    reference_problems.lattice_laplace(5)
    return _worker_id()


def _worker_id() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


# -- sweeps ------------------------------------------------------------------------------------------------------------
def grid_points(grid) -> list[dict]:
    """The points of a grid: a dict knob -> list of values (every combination, the last knob varying fastest; a
    value that is not a list or tuple is held fixed) or a list of dicts (the points as given)."""
    if isinstance(grid, dict):
        names = list(grid)
        values = [v if isinstance(v, (list, tuple)) else [v] for v in grid.values()]
        if any(len(v) == 0 for v in values):
            raise ParameterError("grid", grid, "a non-empty list of values per knob")
        return [dict(zip(names, combo)) for combo in itertools.product(*values)]
    if isinstance(grid, (list, tuple)) and all(isinstance(p, dict) for p in grid):
        return [dict(p) for p in grid]
    raise ParameterError("grid", grid, "a dict knob -> list of values, or a list of dicts of knobs")


def _problem_function(problem):
    if isinstance(problem, str):
        if problem not in reference_problems.PROBLEMS:
            raise ParameterError("problem", problem, "one of " + ", ".join(sorted(reference_problems.PROBLEMS)))
        return reference_problems.PROBLEMS[problem].function
    if callable(problem):
        return problem
    raise ParameterError("problem", problem, "a problem name of pdsim.reference_problems.PROBLEMS or a function")


def _check_knobs(function, points: list[dict]) -> None:
    params = inspect.signature(function).parameters
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return
    for point in points:
        for knob in point:
            if knob not in params:
                names = ", ".join(params)
                raise ParameterError("grid", knob, f"a knob of {function.__name__}: one of {names}")


def _run_point(problem, knobs: dict) -> dict:
    """One sweep point, in a worker: runs the problem and returns its record (or a failure record)."""
    try:
        rec = reference_problems.run_problem(problem, **knobs)
    except Exception as exc:  # noqa: BLE001 - a failing point is reported, the sweep goes on
        name = problem if isinstance(problem, str) else getattr(problem, "__name__", "problem")
        rec = {"problem": name, "knobs": dict(knobs), "error": math.nan, "failed": f"{type(exc).__name__}: {exc}"}
    rec["worker"] = _worker_id()
    return rec


def run_sweep(problem, grid, *, scheduler=None, workers: int | None = None, warm: bool = True) -> list[dict]:
    """Runs a validation problem at every point of ``grid``, one Dask task per point; returns the records in the
    order of the points (:func:`grid_points`).

    Args:
        problem: a name of ``pdsim.reference_problems.PROBLEMS`` (e.g. "cantilever") or a function returning a record (a
            module-level function the workers can import, or one cloudpickle sends by value).
        grid: {knob: [values]} (every combination) or [{knob: value}, ...]. Knobs are the problem function's
            keyword arguments, the refinement included: ``{"n": [2, 3, 4], "method": ["fem"]}``.
        scheduler: None (a LocalCluster here, closed afterwards), a scheduler address "tcp://host:8786", a
            distributed.Client or a cluster (see the module docstring).
        workers: worker processes of the default LocalCluster (default: one per core).
        warm: first load pdsim and its kernels in every worker (see :func:`run_sweeps`).

    Each record: ``problem``, ``method``, ``knobs``, ``error`` [-], ``seconds``, ``peak_rss_mb``, ``memory_mb``,
    ``points`` ... (pdsim.reference_problems), plus ``worker`` (host:pid); a failed point has ``failed`` and NaN error.

    Example, on a farm: ``run_sweep("cantilever", {"n": [2, 4, 8], "method": ["fem", "pd"]},
    scheduler="tcp://host:8786")``.
    """
    return run_sweeps([(problem, grid)], scheduler=scheduler, workers=workers, warm=warm)[0]


def run_sweeps(jobs, *, scheduler=None, workers: int | None = None, warm: bool = True) -> list[list[dict]]:
    """Several sweeps at once on one cluster: ``jobs`` is a list of (problem, grid) as for :func:`run_sweep`; every
    point of every job is submitted before any is gathered, so the workers stay busy. With ``warm`` every worker
    first imports pdsim and loads its kernels (tiny runs), so no point pays for its process's first imports.
    Returns one list of records per job, in order."""
    prepared = []
    for problem, grid in jobs:
        function = _problem_function(problem)
        points = grid_points(grid)
        _check_knobs(function, points)
        prepared.append((problem if isinstance(problem, str) else function, points))
    with _client(scheduler, workers) as client:
        if warm:
            client.run(_warm_worker)
        futures = [[client.submit(_run_point, target, p, pure=False) for p in points] for target, points in prepared]
        return [client.gather(f) for f in futures]


# -- wedges ------------------------------------------------------------------------------------------------------------
_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


def _parse_value(text: str):
    t = text.strip()
    low = t.lower()
    if low in ("true", "false"):
        return low == "true"
    if low == "none":
        return None
    if re.fullmatch(r"[+-]?\d+", t):
        return int(t)
    if _NUMBER.match(t):
        return float(t)
    if t[:1] in "[(" and t[-1:] in "])":
        return tuple(_parse_value(x) for x in t[1:-1].split(";") if x.strip())
    return t


def parse_settings(items) -> dict[str, list]:
    """Settings from command-line words ``NAME=V1,V2,...`` (``--set material.fracture_energy=1,2,5``): values
    separated by commas, each an int, a float, true/false, none, a vector in brackets with ';' between numbers
    ("(0;0;-9.81)") or else a string. Returns {NAME: [values]}; a name given twice is an error."""
    out: dict[str, list] = {}
    for item in items:
        if not isinstance(item, str) or "=" not in item:
            raise ParameterError("--set", item, "NAME=VALUE[,VALUE...]")
        name, _, values = item.partition("=")
        name = name.strip()
        if not name or name in out:
            raise ParameterError("--set", item, "a setting name given once")
        parsed = [_parse_value(v) for v in values.split(",") if v.strip()]
        if not parsed:
            raise ParameterError("--set", item, "at least one value after '='")
        out[name] = parsed
    return out


def wedge_variants(settings: dict) -> list[dict]:
    """Every combination of the settings' values ({name: [values]}), the last setting varying fastest."""
    if not isinstance(settings, dict) or not settings:
        raise ParameterError("settings", settings, "a non-empty dict {name: [values]}")
    for name, values in settings.items():
        if not isinstance(name, str) or not name:
            raise ParameterError("settings", name, "setting names as strings")
        if not isinstance(values, (list, tuple)) or len(values) == 0:
            raise ParameterError(name, values, "a non-empty list of values")
    return [dict(zip(settings, combo)) for combo in itertools.product(*settings.values())]


def _keyword_names(build_scene) -> tuple[set, bool]:
    params = inspect.signature(build_scene).parameters
    any_kw = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())
    names = {n for n, p in params.items() if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}
    return names, any_kw


def _split_settings(build_scene, variant: dict) -> tuple[dict, dict]:
    """(keyword arguments of build_scene, settings applied after building); unknown plain names raise."""
    names, any_kw = _keyword_names(build_scene)
    keywords, after = {}, {}
    for name, value in variant.items():
        if "." in name:
            after[name] = value
        elif name in names or any_kw:
            keywords[name] = value
        else:
            known = ", ".join(sorted(names)) or "none"
            raise ParameterError(
                "setting",
                name,
                f"a keyword of build_scene (it takes: {known}), or scene.ATTR, material.FIELD, body.NAME.ATTR",
            )
    return keywords, after


def _replace_material(material, field_name: str, value, setting: str):
    fields = {f.name for f in dataclasses.fields(Material)}
    if field_name not in fields:
        raise ParameterError("setting", setting, "material.FIELD with FIELD one of " + ", ".join(sorted(fields)))
    if isinstance(value, list):
        value = tuple(value)
    return dataclasses.replace(material, **{field_name: value})


def _set_scene(scene, attr: str, value, setting: str) -> None:
    if attr == "fps":
        real_time = math.isclose(scene.frame_time * scene.fps, 1.0, rel_tol=1e-12)
        scene.fps = check_range("fps", value, 0.0, 1000.0, hi_open=False)
        if real_time:
            scene.frame_time = 1.0 / scene.fps
    elif attr == "frames":
        scene.frames = check_frames(value)
    elif attr == "frame_time":
        scene.frame_time = check_range("frame_time", value, 0.0, None)
    elif attr == "time_scale":
        scene.frame_time = check_range("time_scale", value, 0.0, None) / scene.fps
    elif attr == "time_step_safety":
        scene.time_step_safety = check_range("time_step_safety", value, 0.0, 1.0, hi_open=False)
    elif attr == "gravity":
        g = np.asarray(value, dtype=np.float64)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ParameterError(setting, value, "3 finite numbers [m/s^2]")
        scene.gravity = tuple(float(x) for x in g)
        scene._gravity_is_default = False
    else:
        raise ParameterError("setting", setting, "scene.ATTR with ATTR one of " + ", ".join(SCENE_SETTINGS))


def _check_body_value(body, attr: str, value, setting: str):
    if attr in ("damping",):
        return check_range(setting, value, 0.0, None, lo_open=False)
    if attr == "horizon_factor":
        return check_range(setting, value, 1.5, 8.0, lo_open=False, hi_open=False)
    if attr == "surface_correction":
        if value not in SURFACE_CORRECTIONS:
            raise ParameterError(setting, value, " or ".join(map(repr, SURFACE_CORRECTIONS)))
        return value
    if attr == "partial_volumes":
        if not isinstance(value, bool):
            raise ParameterError(setting, value, "true or false")
        return value
    if attr == "measure":
        if value not in MEASURES:
            raise ParameterError(setting, value, " or ".join(map(repr, MEASURES)))
        return value
    if attr == "integrator":
        if value not in INTEGRATORS:
            raise ParameterError(setting, value, " or ".join(map(repr, INTEGRATORS)))
        return value
    if attr == "tensile_strength":
        return None if value is None else check_range(setting, value, 0.0, None)
    if attr == "implicit_step_ratio":
        return check_range(setting, value, 1.0, None, lo_open=False)
    if attr == "steps_per_frame":
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ParameterError(setting, value, "an integer >= 1")
        return value
    raise ParameterError(setting, value, "a settable attribute")  # not reached: names are checked first


def apply_settings(scene, settings: dict) -> None:
    """Applies the dotted settings (``scene.ATTR``, ``material.FIELD``, ``body.NAME.ATTR``,
    ``body.NAME.material.FIELD``; see the module docstring) to a built scene, checking names and values."""
    for name, value in settings.items():
        parts = name.split(".")
        head = parts[0]
        if head == "scene" and len(parts) == 2:
            _set_scene(scene, parts[1], value, name)
        elif head == "material" and len(parts) == 2:
            bodies = [b for b in scene.bodies if hasattr(b, "material")]
            if not bodies:
                raise ParameterError("setting", name, "a scene with at least one body that has a material")
            for b in bodies:
                b.material = _replace_material(b.material, parts[1], value, name)
        elif head == "body" and len(parts) >= 3:
            by_name = {b.name: b for b in scene.bodies}
            body = by_name.get(parts[1])
            if body is None:
                raise ParameterError("setting", name, "body.NAME.... with NAME one of " + ", ".join(sorted(by_name)))
            if parts[2] == "material" and len(parts) == 4:
                if not hasattr(body, "material"):
                    raise ParameterError("setting", name, f"a body with a material ('{body.name}' has none)")
                body.material = _replace_material(body.material, parts[3], value, name)
            elif len(parts) == 3:
                attr = parts[2]
                allowed = BODY_SETTINGS.get(getattr(body, "method", ""), ())
                if attr in BUILT_WITH_BODY:
                    raise ParameterError(
                        "setting",
                        name,
                        f"a setting read after building: '{attr}' is fixed when the body is built; make it a keyword "
                        f"of build_scene (def build_scene({attr}=...)) and set it as '{attr}'",
                    )
                if attr not in allowed:
                    raise ParameterError(
                        "setting", name, f"body.{body.name}.ATTR with ATTR one of " + ", ".join((*allowed, "material"))
                    )
                setattr(body, attr, _check_body_value(body, attr, value, name))
                if getattr(body, "integrator", None) == "implicit" and getattr(body, "measure", None) == "green":
                    raise ParameterError(name, value, "a setting that does not pair the implicit integrator with green")
            else:
                raise ParameterError("setting", name, "body.NAME.ATTR or body.NAME.material.FIELD")
        else:
            raise ParameterError(
                "setting", name, "NAME (a build_scene keyword), scene.ATTR, material.FIELD or body.NAME.ATTR"
            )


def build_variant(build_scene, variant: dict):
    """Builds a scene for one wedge variant: keyword settings go to ``build_scene``, dotted ones are applied
    after (:func:`apply_settings`)."""
    keywords, after = _split_settings(build_scene, variant)
    scene = build_scene(**keywords)
    if not isinstance(scene, Scene):
        raise ParameterError("build_scene()", type(scene).__name__, "a function returning a pdsim.Scene")
    apply_settings(scene, after)
    return scene


def _slug(variant: dict) -> str:
    words = []
    for name, value in variant.items():
        text = ";".join(map(str, value)) if isinstance(value, (list, tuple)) else str(value)
        words.append(f"{name.split('.')[-1]}={text}")
    slug = re.sub(r"[^A-Za-z0-9._=;-]+", "", "_".join(words))
    return slug[:80]


def _run_variant(scene_script: str, variant: dict, out_path: str, frames, device: str | None) -> dict:
    """One wedge variant, in a worker: builds the scene, runs it to ``out_path``; returns what it did."""
    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING
    rec = {"settings": dict(variant), "worker": _worker_id()}
    t0 = time.perf_counter()
    try:
        scene = build_variant(load_scene_script(scene_script), variant)
        report = scene.run(out_path, frames=frames, device=device, progress=False)
    except Exception as exc:  # noqa: BLE001 - a failing variant is reported, the wedge goes on
        rec.update(failed=f"{type(exc).__name__}: {exc}", seconds=time.perf_counter() - t0)
        return rec
    rec.update(
        path=report.path,
        frames_written=report.frames_written,
        dt=report.dt,
        substeps_per_frame=report.substeps_per_frame,
        seconds=report.wall_seconds,
        summary=report.summary,
    )
    return rec


def run_wedge(
    scene_script,
    settings: dict,
    out_dir,
    *,
    scheduler=None,
    frames: int | None = None,
    device: str | None = "cpu",
    workers: int | None = None,
    validate: bool = True,
) -> list[dict]:
    """Runs a scene script once per variant of ``settings`` (every combination of the values), one Dask task per
    variant, each writing its own cache ``<out_dir>/<stem>_vNN_<settings>.usdc``; writes ``<out_dir>/wedge.json``
    (script, settings and the records) and returns the records in variant order.

    Args:
        scene_script: path of a scene script defining ``build_scene()`` (keywords for the plain settings).
        settings: {name: [values]} (see the module docstring for names: ``material.fracture_energy``,
            ``scene.fps``, ``body.<name>.damping``, or a ``build_scene`` keyword such as ``spacing``).
        out_dir: folder for the caches (made when missing; on a farm, a folder the workers share).
        scheduler: None (a LocalCluster here), "tcp://host:8786", a distributed.Client or a cluster.
        frames: frames per run (default: each scene's own).
        device: Warp device of the runs ("cpu" default; None: CUDA where present).
        workers: worker processes of the default LocalCluster (default: one per core).
        validate: build the scene once here first to check every setting's name and values.

    Each record: ``settings``, ``path``, ``frames_written``, ``dt`` [s], ``substeps_per_frame``, ``seconds``
    (the run's wall time), ``summary``, ``worker``; a failed variant has ``failed`` instead of ``path``.
    """
    script = os.path.abspath(os.fspath(scene_script))
    build = load_scene_script(script)
    variants = wedge_variants(settings)
    if frames is not None:
        frames = check_frames(frames)
    for v in variants:
        _split_settings(build, v)  # unknown plain names fail here
    if validate:
        first_keywords, _ = _split_settings(build, variants[0])
        probe = build_variant(build, variants[0])
        dotted = {k: vals for k, vals in settings.items() if "." in k}
        for name, values in dotted.items():
            for value in values:
                apply_settings(probe, {name: value})
        del first_keywords, probe
    out_dir = os.path.abspath(os.fspath(out_dir))
    os.makedirs(out_dir, exist_ok=True)
    stem = os.path.splitext(os.path.basename(script))[0]
    paths = [os.path.join(out_dir, f"{stem}_v{i:02d}_{_slug(v)}.usdc") for i, v in enumerate(variants)]
    with _client(scheduler, workers) as client:
        futures = [
            client.submit(_run_variant, script, v, p, frames, device, pure=False) for v, p in zip(variants, paths)
        ]
        records = client.gather(futures)
    with open(os.path.join(out_dir, "wedge.json"), "w") as f:
        json.dump(
            {"scene_script": script, "settings": settings, "variants": records}, f, indent=1, default=_json_default
        )
    return records


def _json_default(value):
    if isinstance(value, tuple):
        return list(value)
    return str(value)


def bench_accuracy(argv=None) -> int:
    """``pdsim bench accuracy [options]``: runs tools/accuracy_map.py's ``main(argv)`` from the source checkout this
    pdsim is installed from (options: ``--quick``, ``--scheduler tcp://host:8786``, ``--workers N``, ``--out DIR``,
    ``--no-peers``, ``--from-json``); raises ParameterError where the checkout's tools/ folder is not beside the
    package (a wheel install)."""

    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tools", "accuracy_map.py")
    if not os.path.isfile(path):
        raise ParameterError("bench accuracy", path, "a pdsim source checkout with tools/accuracy_map.py")
    spec = importlib.util.spec_from_file_location("pdsim_accuracy_map", path)
    module = importlib.util.module_from_spec(spec)

    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return int(module.main(argv) or 0)
