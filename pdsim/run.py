"""Running a scene: the frame loop that drives a :class:`pdsim.Scene`'s solvers and streams each finished frame to a
USD cache, with the watchdog, checkpoints and resume.

:func:`run_scene` is what ``Scene.run`` and ``pdsim run`` call. It checks the run's settings and the scene
(pdsim.preflight), builds the solvers, takes the time step from pdsim.timestep, attaches the watchdogs
(pdsim.divergence), opens the cache (pdsim.output.usd.UsdCache) and its writer, then loops over the frames
(:func:`_frame_loop`). :func:`advance_frame` is one frame of steps of a set of solvers; :func:`method_contact` the
contact between methods.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import time
import warnings
from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from . import memory
from .capture import FrameGraphs
from .checkpoint import (
    CHECKPOINT_FORMAT,
    CheckpointAbandoned,
    RunInterrupted,
    checkpoint_path,
    load_checkpoint,
    remove_stale_temporaries,
    save_checkpoint,
)
from .checks import check_frames, check_range, check_time_step, format_bytes
from .colliders import collider_names
from .contact import MethodContact
from .device import device_of, wait_for
from .divergence import attach_watchdogs, schedule_watchdogs
from .errors import FeatureNotAvailableError, InstabilityError, OutputWriteError, ParameterError, PdsimError
from .frame_worker import SurfaceWorker
from .output.usd import UsdCache
from .output.usd_files import pdsim_info
from .output.views import copied_view
from .output.writer import ViewWriter
from .preflight import preflight
from .rigid import rigid_bodies_of
from .profile import RunProfile, report_path, write_report
from .solver import PointSolver
from .timestep import frame_steps, projectile_step_limit


@dataclass
class RunReport:
    """What a run did: frames written, substeps per frame, time step [s], wall time [s], particle count."""

    path: str
    frames_written: int
    substeps_per_frame: int
    dt: float
    stable_dt: float
    wall_seconds: float
    particle_count: int
    bond_count: int
    summary: str = ""  # what the solvers simulated, e.g. "2560 particles, 309440 bonds"
    first_frame: int = 0  # first frame this run wrote (after --resume: the frame after the checkpoint's)
    checks: int = 0  # watchdog checks made
    profile: dict | None = None  # wall time per phase (pdsim.profile.RunProfile.as_dict)
    estimate: dict | None = None  # the pre-flight's cost estimates (pdsim.preflight.PreflightReport.estimate)


@dataclass
class _Options:
    """A run's settings after their checks (Scene.run's arguments)."""

    out: str
    frames: int
    dt: float | None
    dt_factor: float
    check_interval: int
    checkpoint_interval_s: float | None
    crack_events: bool = False
    surface_thread: bool = True


CACHE_LAYOUTS = ("file", "clips")


def _check_options(scene, out, frames, dt, dt_factor, check_interval, checkpoint_interval_s, color_attribute):
    out = os.fspath(out)
    if os.path.splitext(out)[1].lower() not in (".usdc", ".usda", ".usd"):
        raise ParameterError("out", out, "a path ending in .usdc, .usda or .usd")
    if not os.path.isdir(os.path.dirname(os.path.abspath(out))):
        raise ParameterError("out", out, "a path in an existing folder")
    if os.path.isdir(out):
        raise ParameterError("out", out, "a file path, not a folder")
    frame_count = scene.frames if frames is None else check_frames(frames)
    if dt is not None:
        dt = check_time_step(dt)
    dt_factor = check_range("dt_factor", dt_factor, 0.0, None)
    if dt is not None and dt_factor != 1.0:
        raise ParameterError("dt_factor", dt_factor, f"1 when dt={dt!r} is given (give one of the two)")
    if isinstance(check_interval, bool) or int(check_interval) != check_interval or check_interval < 1:
        raise ParameterError("check_interval", check_interval, "an integer >= 1 (steps between watchdog checks)")
    if checkpoint_interval_s is not None:
        checkpoint_interval_s = check_range("checkpoint_interval_s", checkpoint_interval_s, 0.0, None, lo_open=False)
    if color_attribute is not None and not isinstance(color_attribute, str):
        raise ParameterError("color_attribute", color_attribute, "an attribute name such as 'damage', or None")
    return _Options(out, frame_count, dt, dt_factor, int(check_interval), checkpoint_interval_s)


def crack_event_sources(solvers) -> list:
    """The crack-event collectors of ``solvers`` (``Scene.run(crack_events=True)``); FeatureNotAvailableError naming
    the bodies of a method that gives none."""
    sources = []
    for s in solvers:
        source = s.crack_events()
        if source is None:
            names = ", ".join(repr(b.name) for b in s.bodies)
            raise FeatureNotAvailableError(
                f"crack_events=True: the {s.method} bodies {names} give no crack events (only peridynamic bodies "
                "record the bonds that break); run without crack_events, or make those bodies peridynamic"
            )
        sources.append(source)
    return sources


def rest_bounds(scene) -> tuple[np.ndarray, np.ndarray]:
    """World bounds [m] of the bodies at rest and of the projectiles' start (they size the ground's quad)."""
    corners = []
    for b in scene.bodies:
        x = np.asarray(
            getattr(b, "point_rest_positions", None) if hasattr(b, "point_rest_positions") else b.rest_positions
        )
        corners += [x.min(axis=0), x.max(axis=0)]
    corners += [np.asarray(c.pose(0.0)[0]) for c in scene.colliders if hasattr(c, "pose")]
    return np.min(corners, axis=0), np.max(corners, axis=0)


def speed_limit(scene, solvers) -> float:
    """A speed no particle of a sane run reaches: 20 times the largest of the solvers' speed scales (wave, initial and
    prescribed speeds) and a free fall through 1 km. An explicit run past its stable step grows exponentially and
    exceeds it within a few steps."""
    fall = math.sqrt(2.0 * float(np.linalg.norm(scene.gravity)) * 1.0e3)
    return 20.0 * max([fall] + [s.speed_scale() for s in solvers])


class _FrameRun:
    """One run's open cache, writer, solvers and watchdogs: writes frames and checkpoints."""

    def __init__(self, scene, solvers, watchdogs, steps, options, bounds, names, fingerprint):
        self.scene, self.solvers, self.watchdogs, self.steps = scene, solvers, watchdogs, steps
        self.options, self.bounds, self.fingerprint = options, bounds, fingerprint
        self.rigid = [(c, n) for c, n in zip(scene.colliders, names)]
        if scene.ground is not None:
            self.rigid.append((scene.ground, None))
        self.ck_path = checkpoint_path(options.out)
        self.profile = RunProfile()
        self.cache = self.writer = None
        self.frame = 0  # the frame being simulated
        self.events = crack_event_sources(solvers) if options.crack_events else []
        self.worker = SurfaceWorker(threaded=options.surface_thread)
        self.last_written = None  # the last frame written to the cache by this run

    def start_frame(self, frame: int) -> None:
        """Takes frame ``frame``'s views of the current state (the solvers' deferred views, copies of the state they
        need, start building on the surface thread); :meth:`finish_frame` writes them."""
        t = frame * self.scene.frame_time
        with self.profile.phase("surfaces"):  # the solvers advance meanwhile: copies of the state
            views = [copied_view(v) for s in self.solvers for v in s.frame_views()]
        views += [copied_view(v) for e in self.events for v in e.collect()]
        for collider, name in self.rigid:  # copies too: the frame is written after the next one has advanced
            view = copied_view(collider.view(t, bounds=self.bounds))
            if name is not None:
                view.name = name
            views.append(view)
        with self.profile.phase("surfaces"):  # without the surface thread, the build runs here
            self.worker.submit(frame, views, t)

    def finish_frame(self, timeout: float | None = None) -> bool:
        """Writes the frame started by :meth:`start_frame` once its views are built; False when they are not built
        within ``timeout`` [s] (None: no limit), True otherwise (also when no frame is in flight). The profile counts
        the wait for the surface thread as surfaces, and the thread's own build time apart (RunProfile.add_worker)."""
        if self.worker.pending is None:
            return True
        built_before = self.worker.build_seconds
        with self.profile.phase("surfaces"):
            built = self.worker.wait(timeout)
        if built is None:
            return False
        if self.worker.threaded:
            self.profile.add_worker("surfaces", self.worker.build_seconds - built_before)
        frame, views, t = built
        with self.profile.phase("write"):
            self.writer.write(frame, views)
            self.cache.end_frame(frame, time=t)
        self.last_written = frame
        return True

    def write_checkpoint(self, frame: int, substep: int, abandon=None):
        """The run's state after ``substep`` steps of frame ``frame + 1`` (frame ``frame`` finished); ``abandon``:
        see pdsim.checkpoint.save_checkpoint."""
        if self.options.checkpoint_interval_s is None:
            return None
        self.cache.save()  # the top-level layer on disk reaches ``frame``: a resume reopens the cache there
        state = {
            "format": CHECKPOINT_FORMAT,
            "fingerprint": self.fingerprint,
            "run": {
                "frame": frame,
                "substep": substep,
                "dt": self.steps.dt,
                "substeps": self.steps.substeps,
                "frames": self.options.frames,
                "cache_run": self.cache.run_id,
            },
            "writer": self.writer.checkpoint(),
            "solvers": {str(i): s.checkpoint() for i, s in enumerate(self.solvers)},
            "watchdogs": {str(i): ({} if w is None else w.checkpoint()) for i, w in enumerate(self.watchdogs)},
            "colliders": _collider_states(self.scene.colliders),
        }
        if self.events:
            state["events"] = {str(i): e.checkpoint() for i, e in enumerate(self.events)}
        return save_checkpoint(self.ck_path, state, abandon=abandon)


def _frame_loop(run: _FrameRun, start: int, first_substep: int, *, coupling, limit, bar, stop, on_frame) -> None:
    """Frames ``start + 1 .. frames``: step, write, checkpoint when due or asked to stop (RunInterrupted).

    Frame N's render surfaces build on the surface thread while frame N + 1 simulates; frame N is written when both
    are done (before any checkpoint, which thus sees every frame up to its own written). ``on_frame`` runs when a
    frame is simulated, its views taken."""
    frames, every = run.options.frames, run.options.checkpoint_interval_s
    last_checkpoint = time.monotonic()
    for frame in range(start + 1, frames + 1):
        run.frame = frame
        for w in run.watchdogs:
            if w is not None:
                w.frame = frame
        checked = _check_seconds(run.watchdogs)
        try:
            with run.profile.phase("simulate"):
                advance_checked(
                    run.scene, run.solvers, run.steps.dt, run.steps.substeps, coupling, limit, first=first_substep
                )
                wait_for([device_of(s) for s in run.solvers])  # the steps timed here, not at the first read
        except RunInterrupted as exc:
            done = getattr(exc, "in_frame", None)
            if done is None:
                raise
            # stopped at a step boundary inside the frame, ``done`` steps into it
            written = _checkpoint(run, frame - 1, first_substep + done, stop)
            raise RunInterrupted(exc.signal, checkpoint=written, last_frame=run.last_written) from None
        except BaseException:  # a divergence, an error, Ctrl-C: the frames simulated before it are still written
            run.finish_frame()
            raise
        run.profile.move("simulate", "checks", _check_seconds(run.watchdogs) - checked)
        first_substep = 0
        run.finish_frame()
        run.start_frame(frame)
        if on_frame is not None:
            on_frame(frame, run.solvers)
        bar.update(1)
        stopping = stop is not None and stop.requested
        due = every is not None and time.monotonic() - last_checkpoint >= every
        if (stopping or due) and frame < frames:
            with run.profile.phase("write"):
                written = _checkpoint(run, frame, 0, stop)
            last_checkpoint = time.monotonic()
            if stopping or (stop is not None and stop.requested):  # asked during the checkpoint: it is the last
                raise RunInterrupted(stop.signal, checkpoint=written, last_frame=run.last_written)
    run.finish_frame()


def _check_seconds(watchdogs) -> float:
    """Wall time [s] of the watchdogs' checks so far."""
    return sum(w.seconds for w in watchdogs if w is not None)


STOP_CHECKPOINT_BUDGET_S = 0.8  # a checkpoint still being written this long after a stop request is abandoned [s]


def _checkpoint(run: _FrameRun, frame: int, substep: int, stop):
    """``run.write_checkpoint``, abandoned when a stop request has waited longer than STOP_CHECKPOINT_BUDGET_S (so
    that SIGTERM stops a large run within 2 s): then the previous checkpoint file, or None."""
    overdue = getattr(stop, "overdue", None)  # a StopRequest's; other stop objects never abandon a checkpoint
    abandon = None if overdue is None else (lambda: overdue(STOP_CHECKPOINT_BUDGET_S))
    while not run.finish_frame(None if abandon is None else 0.05):  # the frame in flight first
        if abandon():  # its surfaces are still building: the checkpoint would come too late
            run.worker.abandon()
            return run.ck_path if run.ck_path.is_file() else None
    try:
        return run.write_checkpoint(frame, substep, abandon=abandon)
    except CheckpointAbandoned:
        return run.ck_path if run.ck_path.is_file() else None


def run_scene(
    scene,
    out,
    *,
    frames=None,
    device=None,
    dt=None,
    dt_factor=1.0,
    progress=True,
    save_interval_s=0.0,
    color_attribute=None,
    color_range=None,
    fragments_as_prims=False,
    render_points=False,
    debris_particles=0,
    crack_events=False,
    resume=False,
    checkpoint_interval_s=60.0,
    check_interval=16,
    stop=None,
    on_frame=None,
    layout="file",
    profile=False,
    surface_thread=True,
) -> RunReport:
    """Simulates ``scene`` and writes its USD cache to ``out``; the arguments and what the run guarantees are those
    of :meth:`pdsim.Scene.run`. ``profile``: False, True (print the phases' wall time at the end and write the run
    report ``<stem>.report.json``) or a pdsim.profile.RunProfile started by the caller (as True, and the time
    before the run it holds counts)."""
    prof = profile if isinstance(profile, RunProfile) else RunProfile()
    pack = cache_layout(layout)
    options = _check_options(scene, out, frames, dt, dt_factor, check_interval, checkpoint_interval_s, color_attribute)
    if isinstance(debris_particles, bool) or int(debris_particles) != debris_particles or debris_particles < 0:
        raise ParameterError("debris_particles", debris_particles, "an integer >= 0 (0: no debris)")
    options.crack_events = bool(crack_events)
    options.surface_thread = bool(surface_thread)
    out = options.out
    remove_stale_temporaries(out)  # what a killed run on this output left (at most one checkpoint's .tmp)
    names = collider_names(scene.colliders)
    wall0 = time.perf_counter()
    prof.lap()
    # before any allocation; prints the cost estimate before its memory and disk checks
    checked = preflight(scene, device=device, out=out, dt=options.dt, frames=options.frames, pack=pack, show=progress)
    prof.lap("checks")
    solvers = scene.build_solvers(device=device, check=False)
    stable_dt = min(s.stable_time_step() for s in solvers)
    travel = projectile_step_limit(scene, options.frames)
    steps = frame_steps(
        scene.frame_time,
        stable_dt,
        scene.time_step_safety,
        dt=options.dt,
        dt_factor=options.dt_factor,
        travel_limit=travel,
        warn=True,
    )
    limit = speed_limit(scene, solvers)
    bounds = rest_bounds(scene)
    fingerprint = _fingerprint(scene, solvers, names)
    start, first_substep, cache_run, state = 0, 0, None, None
    if resume:
        state = load_checkpoint(checkpoint_path(out))
        start, first_substep, cache_run = _restore_run(scene, state, solvers, fingerprint, steps, options.frames)
    watchdogs = attach_watchdogs(scene, solvers, dt=steps.dt, stable_dt=stable_dt, bounds=bounds)
    schedule_watchdogs(solvers, watchdogs, dt=steps.dt, speed_limit=limit, every=options.check_interval, stop=stop)
    if resume:
        for i, w in enumerate(watchdogs):
            if w is not None:
                w.restore(state["watchdogs"][str(i)])
    run = _FrameRun(scene, solvers, watchdogs, steps, options, bounds, names, fingerprint)
    run.profile = prof
    run.frame = start
    if resume:
        for i, e in enumerate(run.events):  # the breaks of the frame a stop interrupted count with that frame
            if str(i) in state.get("events", {}):
                e.restore(state["events"][str(i)])
    metadata = {"frameTime": scene.frame_time, "timeScale": scene.frame_time * scene.fps, "scene": str(scene.name)}
    try:
        run.cache = UsdCache(
            out,
            fps=scene.fps,
            up_axis=scene.up_axis,
            save_interval_s=save_interval_s,
            metadata=metadata,
            append_frame=start if resume else None,
            append_run=cache_run,
            pack=pack,
        )
    except (ValueError, FileNotFoundError) as exc:
        if not resume:
            raise
        raise ParameterError(
            "resume", out, f"a cache holding the run the checkpoint belongs to, at its frame {start} ({exc})"
        ) from None
    with write_errors(run.cache), run.cache as cache:
        run.writer = ViewWriter(
            cache,
            color_attribute=color_attribute,
            color_range=color_range,
            fragments_as_prims=fragments_as_prims,
            velocity_scale=scene.frame_time * scene.fps,  # velocities per played second (USD's time codes per second)
            render_points=render_points,
            debris_particles=debris_particles,
        )
        if resume:
            run.writer.restore(state["writer"])
        coupling = method_contact(scene, solvers)
        prof.lap("build")
        if not resume:
            run.start_frame(0)
        bar = _progress(options.frames - start, enabled=progress, desc=f"pdsim {scene.name}")
        try:
            _frame_loop(
                run, start, first_substep, coupling=coupling, limit=limit, bar=bar, stop=stop, on_frame=on_frame
            )
        except InstabilityError as exc:
            raise InstabilityError(f"{exc}; {frames_note(cache.top_level_path, run.frame - 1)}") from exc
        except KeyboardInterrupt as exc:
            last = -1 if cache.last_frame is None else cache.last_frame
            exc.cache = str(cache.top_level_path)
            exc.last_frame = last
            exc.note = frames_note(cache.top_level_path, last)
            raise
        finally:
            bar.close()
        written = cache.frames_written
        prof.lap()
    prof.lap("write")  # the cache closed (and packed)
    _warn_crumbled(solvers)
    if run.ck_path.is_file():
        run.ck_path.unlink()
    prof.finish(run.frame - start)
    report = RunReport(
        path=out,
        frames_written=written,
        substeps_per_frame=steps.substeps,
        dt=steps.dt,
        stable_dt=stable_dt,
        wall_seconds=time.perf_counter() - wall0,
        particle_count=sum(s.point_count for s in solvers),
        bond_count=sum(s.bond_count for s in solvers),
        summary="; ".join(s.summary() for s in solvers),
        first_frame=start + 1 if resume else 0,
        checks=sum(w.checks for w in watchdogs if w is not None),
        profile=prof.as_dict(),
        estimate=dict(checked.estimate),
    )
    if profile:
        write_report(report_path(out), dataclasses.asdict(report))
        print(prof.table())
    return report


@contextlib.contextmanager
def write_errors(cache):
    """Turns an OSError of a write during a run (disk full, a folder turned read-only: a frame layer, the top-level
    layer, a checkpoint) into a one-line OutputWriteError naming the path, the error, the free space [B] of its file
    system and the finished frames the cache keeps."""
    try:
        yield
    except PdsimError:
        raise  # already one line naming what to do (a cache that cannot be packed: pdsim.output.usd_files.CacheError)
    except OSError as exc:
        raise write_failure(exc, cache) from None


def write_failure(exc: OSError, cache) -> OutputWriteError:
    """The OutputWriteError of ``exc`` (see :func:`write_errors`)."""
    path = os.fspath(exc.filename) if exc.filename is not None else str(cache.top_level_path)
    folder = os.path.dirname(os.path.abspath(path))
    while folder and not os.path.isdir(folder):
        folder = os.path.dirname(folder)
    try:
        free = f"{format_bytes(memory.free_disk_space(folder))} free on {folder}"
    except OSError:
        free = f"free space of {folder} unknown"
    what = exc.strerror or str(exc)
    kept = frames_note(cache.top_level_path, _last_frame_on_disk(cache))
    return OutputWriteError(f"could not write {path}: {what} ({free}); {kept}")


def _last_frame_on_disk(cache) -> int:
    """The last frame the cache's top-level layer on disk names for this run (-1: none), read from the file: after a
    failed write it may be behind the last finished frame."""
    top = cache.top_level_path
    try:
        info = pdsim_info(top) if top.is_file() else {}
    except ValueError:
        info = {}
    if info.get("run") != cache.run_id:
        return -1
    return int(cache.start_frame) + int(info.get("framesWritten", 0)) - 1


def cache_layout(layout) -> bool:
    """Whether a run of cache ``layout`` packs its cache into one file at the end: ``"file"`` (one self-contained
    file, the default) packs, ``"clips"`` (the top-level layer plus its run folder, docs/cache_format.md) does not;
    ParameterError for anything else."""
    if layout not in CACHE_LAYOUTS:
        raise ParameterError(
            "layout",
            layout,
            "'file' (one self-contained file, default) or 'clips' (a top-level layer and its frames folder)",
        )
    return layout == "file"


# -- stepping -----------------------------------------------------------------------------------------------------
def advance_checked(scene, solvers, dt, substeps, coupling, limit, *, first=0):
    """One frame from sub-step ``first``: solvers without mass (the lattice) advance the whole frame (when ``first``
    is 0), the others ``substeps - first`` steps (:func:`advance_frame`; their watchdogs check every few steps inside
    it and may raise a stop request), then every solver's ``check_state`` (the frame-end check, with the watchdogs'
    strain pass), then every solver's ``end_frame`` where it has one."""
    points = [s for s in solvers if isinstance(s, PointSolver)]
    for s in points:
        if s.watchdog is not None:
            s.watchdog.frame_start_step = int(s.step_count)
    graphs = frame_graphs(solvers, scene.graph_capture)
    if first == 0:
        for s in solvers:
            if not isinstance(s, PointSolver):
                _frame_alone(s, dt, substeps, graphs)
    if points and substeps > first:
        advance_frame(points, dt, substeps - first, coupling, graphs=graphs)
    for s in solvers:
        if s.watchdog is not None:
            s.watchdog.full_check = True
        s.check_state(limit)
    for s in solvers:
        if callable(getattr(s, "end_frame", None)):
            s.end_frame()  # frame-end work of a solver (the peridynamic rigid hand-off)


def method_contact(scene, solvers):
    """Contact of mesh methods (pdsim.contact.MethodContact): on when contact is not switched off and the scene holds
    a mesh method with a particle method, or mesh surfaces that can meet (several FEM bodies, or one that cracks);
    None otherwise. The scene's contact options ``restitution`` and ``friction`` (Scene.enable_contact) set its law,
    and its ``time_step_safety`` the fraction of the elements' stable steps the contact's stiffness is sized on."""
    if scene.contact is False:
        return None
    particles = [s for s in solvers if callable(getattr(s, "contact_particles", None))]
    meshes = [s for s in solvers if callable(getattr(s, "contact_mesh", None))]
    surfaces = any(getattr(s, "surfaces_could_meet", lambda: False)() for s in meshes) or len(meshes) > 1
    if not meshes or not (particles or surfaces):
        return None
    options = scene.contact if isinstance(scene.contact, dict) else {}
    law = {key: options[key] for key in ("restitution", "friction") if key in options}
    return MethodContact(particles, meshes, surfaces=surfaces, step_safety=scene.time_step_safety, **law)


def frame_graphs(solvers, graph_capture):
    """The FrameGraphs (pdsim/capture.py) of a run's solvers, following the scene's ``graph_capture``: kept on the
    first solver (it lives as long as the solvers do) for the same set of solvers."""
    first = solvers[0]
    cached = getattr(first, "_frame_graphs", None)
    if cached is None or len(cached[0]) != len(solvers) or any(a is not b for a, b in zip(cached[0], solvers)):
        device = device_of(first)
        cached = (list(solvers), FrameGraphs(device, graph_capture))
        first._frame_graphs = cached
    return cached[1]


def _frame_alone(solver, dt: float, substeps: int, graphs=None) -> None:
    """A frame of a solver without mass (the lattice: a frame of its own steps), replayed as a graph where ``graphs``
    can."""
    if graphs is None:
        solver.simulate(dt, substeps)
    else:
        graphs.advance([solver], dt, substeps, None, lambda: solver.simulate(dt, substeps))


def advance_frame(solvers, dt: float, substeps: int, coupling=None, graphs=None) -> None:
    """One frame of ``substeps`` steps of ``dt`` [s]: the solvers of methods with mass step together, phase by phase,
    so that ``coupling`` (contact between methods) acts within each step; the others (the lattice) advance by a frame.
    The frame's tables (projectile poses, the watchdog's collider speeds) are written to the device first; no step
    reads the device. ``graphs`` (a pdsim.capture.FrameGraphs) replays the steps as a captured graph where it
    can; None launches them from the host."""
    coupled = [s for s in solvers if isinstance(s, PointSolver)]
    for s in solvers:
        if not isinstance(s, PointSolver):
            _frame_alone(s, dt, substeps, graphs)
    if not coupled:
        return
    for s in coupled:
        s.begin_frame(dt, substeps)
    rigid = rigid_bodies_of(coupled)  # dynamic rigid bodies (pdsim/rigid.py): they step around the solvers' steps

    def run_steps():
        if len(coupled) == 1 and coupling is None and rigid is None:
            coupled[0].simulate(dt, substeps)
            return
        for _ in range(substeps):
            if rigid is not None:
                rigid.begin_step(dt)
            try:
                for s in coupled:
                    s.begin_step(dt)  # a stop request is honoured at the start of a solver's step
            except RunInterrupted:
                if rigid is not None:
                    rigid.undo_begin_step()
                raise
            for s in coupled:
                s.compute_forces()
            if coupling is not None:
                coupling.apply(dt)
            for s in coupled:
                s.end_step(dt)
            if coupling is not None:
                coupling.end_step(dt)
            if rigid is not None:
                rigid.end_step(dt)

    if graphs is None:
        run_steps()
    else:
        graphs.advance(coupled, dt, substeps, coupling, run_steps)


# -- checkpoints and resume -----------------------------------------------------------------------------------------
def frames_note(top, last: int) -> str:
    """Where the finished frames are, for messages: the cache (resumed runs included) holds frames 0..last."""
    top = os.fspath(top)
    return f"{top} holds frames 0..{last}" if last >= 0 else f"{top} holds no finished frame"


def _fingerprint(scene, solvers, names) -> dict:
    """What a checkpoint must match to be resumed by this scene (plain JSON values)."""
    bodies = []
    for b in scene.bodies:
        count = getattr(b, "point_count", None)
        if count is None:
            count = getattr(b, "particle_count", 0)
        bodies.append([str(b.name), str(getattr(type(b), "method", "")), int(count)])
    return {
        "scene": str(scene.name),
        "fps": float(scene.fps),
        "frame_time": float(scene.frame_time),
        "solvers": [type(s).__name__ for s in solvers],
        "bodies": bodies,
        "colliders": [str(n) for n in names],
        "ground": scene.ground is not None,
    }


def _restore_run(scene, state, solvers, fingerprint, steps, frame_count):
    """Checks a checkpoint against this scene and puts it back: (last finished frame, sub-steps done in the next one,
    the run id of the cache it was written with)."""
    if state.get("format") != CHECKPOINT_FORMAT:
        raise ParameterError(
            "resume",
            f"a checkpoint of format {state.get('format')!r}",
            f"a checkpoint of format {CHECKPOINT_FORMAT} (this version of pdsim's; rerun without --resume)",
        )
    saved = json.loads(json.dumps(state.get("fingerprint", {})))
    mine = json.loads(json.dumps(fingerprint))
    if saved != mine:
        diff = sorted(k for k in set(saved) | set(mine) if saved.get(k) != mine.get(k))
        raise ParameterError(
            "resume",
            f"a checkpoint of another scene (differs in {', '.join(diff)})",
            "a checkpoint written by this scene (same bodies, colliders, fps and frame time)",
        )
    run = state["run"]
    frame, substep = int(run["frame"]), int(run["substep"])
    if frame >= frame_count:
        raise ParameterError("frames", frame_count, f"more than {frame} (the checkpoint's last finished frame)")
    if not (int(run["substeps"]) == steps.substeps and float(run["dt"]) == steps.dt):
        if substep:
            raise ParameterError(
                "dt", steps.dt, f"the checkpoint's time step {float(run['dt']):.6g} s (it stopped inside a frame)"
            )
        warnings.warn(
            f"resuming with a time step of {steps.dt:.3g} s where the checkpoint ran {float(run['dt']):.3g} s: the "
            "frames differ from those of an uninterrupted run",
            stacklevel=4,
        )
    for i, s in enumerate(solvers):
        s.restore(state["solvers"][str(i)])
    _restore_colliders(scene.colliders, state.get("colliders", {}))
    return frame, substep, str(run["cache_run"])


CRUMBLED_SHARE = 0.5
"""A breakable body with at least this share of its mass drawn as chips at the end of a run is reported as crumbled
(docs/fracture.md, "As the render draws them")."""


PD_CHIP_MEANING = "reached its material's chip_damage and is drawn as chips"
"""What a peridynamic solver's ``chip_shares`` count; a solver with its own sense says it in ``CHIP_MEANING`` (the FEM:
the mass in pieces of one or two elements)."""


def _warn_crumbled(solvers) -> None:
    """A warning for each breakable body that ended the run with CRUMBLED_SHARE or more of its mass as rubble
    (``chip_shares`` of the solvers: a peridynamic body's particles whose damage reaches their material's chip_damage,
    an FEM body's pieces of one or two elements), which the artist sees as a heap of rubble rather than pieces."""
    for s in solvers:
        meaning = getattr(s, "CHIP_MEANING", PD_CHIP_MEANING)
        for name, share in getattr(s, "chip_shares", dict)().items():
            if share >= CRUMBLED_SHARE:
                warnings.warn(
                    f"body '{name}' crumbled: {100 * share:.0f} % of its mass {meaning} (rubble, not pieces). An "
                    "impact that strains a brittle material many times its breaking strain does this; a stronger "
                    "material crumbles less and breaks less (docs/guide.md, 'Shards, not dust')",
                    stacklevel=3,
                )


def _collider_states(colliders) -> dict:
    """The colliders' state a resumed run needs: each projectile's last evaluated pose (its velocity over the next
    step is taken from it)."""
    out = {}
    for i, c in enumerate(colliders):
        if getattr(c, "system", None) is not None:  # a dynamic rigid body (pdsim/rigid.py): its device state
            out[str(i)] = c.checkpoint()
            continue
        last = getattr(c, "_last", None)
        if last is not None:
            out[str(i)] = {"time": float(last[0]), "position": np.asarray(last[1]), "rotation": np.asarray(last[2])}
    return out


def _restore_colliders(colliders, states: dict) -> None:
    for i, c in enumerate(colliders):
        st = states.get(str(i))
        if st is not None and "rigid_state" in st:
            c.restore(st)
        elif st is not None and hasattr(c, "_last"):
            c._last = (float(st["time"]), np.asarray(st["position"]), np.asarray(st["rotation"]))


class _NoProgress:
    def update(self, n):
        pass

    def close(self):
        pass


def _progress(total: int, *, enabled: bool, desc: str):
    """The run's progress bar over ``total`` frames. Its remaining time is the frames left times the mean frame time
    so far (``smoothing=0``): a frame in which bonds break and surfaces are rebuilt can cost ten times one without,
    and tqdm's default average over the last few frames swings the estimate by as much at every break."""
    if not enabled:
        return _NoProgress()
    return tqdm(total=total, desc=desc, unit="frame", dynamic_ncols=True, smoothing=0)
