"""Scenes: bodies, colliders and gravity, run frame by frame into a USD animation cache."""

from __future__ import annotations

import dataclasses
import math
import os
import time
import warnings
from dataclasses import dataclass

import numpy as np

from .colliders import GroundPlane
from .errors import ParameterError
from .geometry import SolidShape
from .materials import Material
from .peridynamics import PeridynamicBody
from .preflight import check_prim_names, preflight
from .validate import check_frames, check_range, check_time_step

UP_AXES = {"Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


def warn_if_above_estimate(dt: float, dt_crit: float):
    """Warns when a user time step exceeds the (conservative) stable estimate; divergence is still detected."""
    if dt > dt_crit:
        warnings.warn(
            f"time step {dt:.3g} s exceeds the stable estimate {dt_crit:.3g} s; the watchdog checks the run for "
            "divergence every few steps",
            stacklevel=3,
        )


def default_device() -> str:
    """'cuda' when a CUDA device is present, else 'cpu'."""
    import warp as wp

    return "cuda" if wp.get_cuda_device_count() > 0 else "cpu"


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


class Scene:
    """A simulation scene.

    Time: the cache plays at ``fps`` frames per second (timeCodesPerSecond = framesPerSecond = fps); each frame
    advances the simulation by ``frame_time`` simulated seconds, 1/fps unless slow motion (or fast motion) is asked
    for with one of ``time_scale`` or ``frame_time``. A 50 us impact written over 48 frames played at 24 fps:
    ``Scene(fps=24, frames=48, frame_time=50e-6 / 48)``; 5x slow motion: ``Scene(fps=24, time_scale=0.2)``.

    Args:
        fps: playback frames per second of the cache, in (0, 1000].
        frames: number of frames to simulate and write after frame 0 (the rest pose), integer >= 1.
        time_scale: simulated seconds per played second, > 0 (0.2: 5x slow motion); frame_time = time_scale / fps.
        frame_time: simulated seconds per frame [s], > 0. Give at most one of time_scale and frame_time.
        gravity: gravitational acceleration [m/s^2]; default 9.81 m/s^2 down the up axis.
        up_axis: "Z" (default) or "Y"; written to the stage and used for the default gravity and ground plane.
        time_step_safety: automatic dt = safety * Silling-Askari estimate, in (0, 1]; default 0.7.
        name: scene label.
        graph_capture: replay each frame's steps as one captured graph (pdsim/frame_graph.py): None (default) on CUDA
            devices, False never (every step launched from the host), True on any device (the CPU replays Warp's
            recorded operations). Scenes whose steps do host work (FEM fracture, the implicit FEM integrator) run
            uncaptured with a warning naming the reason.
    """

    def __init__(
        self,
        *,
        fps: float = 24.0,
        frames: int = 48,
        gravity=None,
        up_axis: str = "Z",
        time_step_safety: float = 0.7,
        name: str = "scene",
        time_scale: float | None = None,
        frame_time: float | None = None,
        graph_capture: bool | None = None,
    ):
        if graph_capture not in (None, True, False):
            raise ParameterError("graph_capture", graph_capture, "None (on CUDA devices), True or False")
        self.graph_capture = graph_capture
        if up_axis not in UP_AXES:
            raise ParameterError("up_axis", up_axis, "'Y' or 'Z'")
        self.fps = check_range("fps", fps, 0.0, 1000.0, hi_open=False)
        if time_scale is not None and frame_time is not None:
            raise ParameterError(
                "time_scale", time_scale, f"None when frame_time={frame_time!r} is given (give one of the two)"
            )
        if time_scale is not None:
            self.frame_time = check_range("time_scale", time_scale, 0.0, None) / self.fps
        elif frame_time is not None:
            self.frame_time = check_range("frame_time", frame_time, 0.0, None)
        else:
            self.frame_time = 1.0 / self.fps
        if not self.frame_time > 0.0 or not math.isfinite(self.frame_time):
            raise ParameterError("frame_time", self.frame_time, "a finite time > 0 [s]")
        self.frames = check_frames(frames)
        self.up_axis = up_axis
        up = np.asarray(UP_AXES[up_axis])
        self._gravity_is_default = gravity is None
        g = -9.81 * up if gravity is None else np.asarray(gravity, dtype=np.float64)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ParameterError("gravity", gravity, "3 finite numbers [m/s^2]")
        self.gravity = tuple(float(x) for x in g)
        self.time_step_safety = check_range("time_step_safety", time_step_safety, 0.0, 1.0, hi_open=False)
        self.name = name
        self.bodies: list = []
        self.ground: GroundPlane | None = None
        self.contact: bool | dict | None = None  # None: automatic (on with several bodies or breakable ones)
        self.colliders: list = []

    # -- building -----------------------------------------------------------------------------------------------
    def add_body(self, body):
        """Adds a body of any method (PeridynamicBody, FemBody, LatticeBody); names must be unique."""
        if not getattr(type(body), "method", ""):
            raise ParameterError("body", body, "a pdsim body (PeridynamicBody, FemBody, LatticeBody)")
        if any(b.name == body.name for b in self.bodies):
            raise ParameterError("name", body.name, "a body name not already used in this scene")
        check_prim_names([*self.bodies, body], self.colliders)  # "body 1" and "body_1" are one USD prim
        self.bodies.append(body)
        return body

    def add_peridynamic_body(self, shape: SolidShape, material: Material, spacing: float, **kwargs) -> PeridynamicBody:
        """Fills ``shape`` with particles of ``spacing`` [m] and adds it (keyword options: see PeridynamicBody)."""
        return self.add_body(PeridynamicBody(shape, material, spacing, **kwargs))

    def add_fem_body(self, shape, material: Material, **kwargs):
        """Adds a tetrahedral FEM body (a SolidShape meshed with fTetWild, or a TetMesh; options: see FemBody)."""
        from .fem import FemBody

        return self.add_body(FemBody(shape, material, **kwargs))

    def add_ground_plane(self, *, height: float = 0.0, friction: float = 0.5) -> GroundPlane:
        """A ground plane perpendicular to the up axis at ``height`` [m], Coulomb ``friction`` >= 0."""
        h = check_range("height", height, None, None)
        mu = check_range("friction", friction, 0.0, None, lo_open=False)
        ground = GroundPlane(normal=UP_AXES[self.up_axis], offset=h, friction=mu)
        check_prim_names(self.bodies, self.colliders, ground)  # a body named "ground" clashes with /World/ground
        self.ground = ground
        return self.ground

    def enable_contact(self, enabled: bool = True, **options) -> None:
        """Short-range repulsion between particles that share no live bond (separate bodies, fragments). Automatic
        by default: on when the scene has several bodies or a body that can break. ``options`` go to
        pdsim.contact.ParticleContact (e.g. friction=0.3, distance_factor=1.35)."""
        self.contact = (options or True) if enabled else False

    def add_collider(self, collider):
        """Adds a static MeshCollider or a kinematic projectile (SphereProjectile, BoxProjectile, MeshProjectile)."""
        from .colliders import Collider

        if not isinstance(collider, Collider):
            raise ParameterError("collider", collider, "a pdsim collider (MeshCollider, SphereProjectile, ...)")
        check_prim_names(self.bodies, [*self.colliders, collider], self.ground)
        self.colliders.append(collider)
        return collider

    def _contact_setting(self, bodies):
        """Automatic contact for the bodies of one method with mass: on with several bodies or a breakable one."""
        if self.contact is not None:
            return self.contact
        if any(getattr(b, "method", "") == "lattice" for b in bodies):
            return None  # massless: no contact
        breakable = any(getattr(b, "fractures", False) for b in bodies)
        return True if (len(bodies) > 1 or breakable) else None

    # -- running ------------------------------------------------------------------------------------------------
    def origin(self) -> np.ndarray:
        """Origin [m] of the solvers' local frame: the centre of the bodies' rest bounding box. Solvers store rest
        positions relative to it, so a scene translated anywhere in the world simulates the same digits."""
        from .kinematics import scene_origin

        bounds = []
        for b in self.bodies:
            x = np.asarray(
                getattr(b, "point_rest_positions", None) if hasattr(b, "point_rest_positions") else b.rest_positions,
                dtype=np.float64,
            )
            bounds.append((x.min(axis=0), x.max(axis=0)))
        return scene_origin(bounds)

    def context(self, *, device: str | None = None):
        """The SolverContext every solver of this scene is built with."""
        from .solver import SolverContext

        ctx = SolverContext(
            device=device or default_device(),
            gravity=self.gravity,
            ground=self.ground,
            contact=self.contact,
            colliders=list(self.colliders),
            origin=self.origin(),
            gravity_is_default=self._gravity_is_default,
            contact_is_default=self.contact is None,
        )
        return ctx

    def build_solvers(self, *, device: str | None = None, check: bool = True) -> list:
        """One solver per method, each over all bodies of that method (CUDA when present unless ``device`` given).
        First the pre-flight checks (pdsim.preflight.preflight: overlaps, ground, names, memory, substeps, mesh
        quality; ``check=False`` skips them when the caller ran them already); then each method checks that it can
        honour what the scene asks of it (FeatureNotAvailableError)."""
        from .solver import solver_for

        if not self.bodies:
            raise ParameterError("bodies", [], "a scene with at least one body")
        if check:
            preflight(self, device=device)
        groups: dict[type, list] = {}
        for b in self.bodies:
            groups.setdefault(solver_for(b), []).append(b)
        ctx = self.context(device=device)
        contexts = {}
        for cls, bodies in groups.items():
            # automatic contact is decided per method (None: automatic, resolved on that method's bodies)
            contact = self._contact_setting(bodies) if self.contact is None else self.contact
            contexts[cls] = dataclasses.replace(ctx, contact=contact)
            cls.check_features(bodies, contexts[cls])
        return [cls(bodies, contexts[cls]) for cls, bodies in groups.items()]

    def build_solver(self, *, device: str | None = None):
        """The solver of a scene whose bodies are all of one type."""
        solvers = self.build_solvers(device=device)
        if len(solvers) != 1:
            raise ParameterError("bodies", [type(b).__name__ for b in self.bodies], "bodies of a single type")
        return solvers[0]

    def run(
        self,
        out: str | os.PathLike,
        *,
        frames: int | None = None,
        device: str | None = None,
        dt: float | None = None,
        dt_factor: float = 1.0,
        progress: bool = True,
        save_interval_s: float = 0.0,
        color_attribute: str | None = None,
        color_range=None,
        fragments_as_prims: bool = False,
        resume: bool = False,
        checkpoint_interval_s: float | None = 60.0,
        check_interval: int = 16,
        stop=None,
        on_frame=None,
    ) -> RunReport:
        """Simulates the scene and writes a USD animation cache to ``out`` (.usdc, .usda or .usd) and the folder of its
        frame layers ``<stem>.frames/`` beside it (docs/cache_format.md).

        Frame 0 is the rest pose; frames 1..frames follow, each ``frame_time`` simulated seconds after the previous
        one, played at ``fps``; each frame's simulated time is written to ``/World.pdsim:time``. The cache is streamed:
        each finished frame is on disk (a crash loses at most the frame being written). When ``out`` already holds a
        cache, this run replaces it only when it finishes; a run that fails leaves the earlier cache as it was and its
        own finished frames in ``<stem>.partial<suffix>``. Colliders are written as meshes under
        ``/World/colliders/<name>`` (projectiles with their pose at each frame's time) and the ground plane as
        ``/World/ground``.

        The watchdog (pdsim.kinematics.Watchdog, docs/stability.md) checks every ``check_interval`` steps and at each
        frame end that the state is finite, no point is faster than the speed limit, the energy has not grown past
        what the run started with plus the work put in, and strains are bounded; it raises InstabilityError naming the
        frame, the body and the likely cause, and the cache keeps every finished frame.

        Checkpoints (pdsim/checkpoint.py): at frame ends, every ``checkpoint_interval_s`` seconds of wall time (0:
        every frame; None: never), and when ``stop`` is requested, the run writes ``<stem>.checkpoint.npz`` beside
        ``out``; ``resume=True`` continues from it, bit for bit as an uninterrupted run on the CPU, in the same cache
        ``out`` (the frames the interrupted run wrote after its checkpoint are replaced). A finished run removes its
        checkpoint.

        Args:
            out: output path.
            frames: overrides the scene's frame count (integer >= 1).
            device: Warp device; CUDA when present unless given.
            dt: time step [s]; automatic (safety * stable estimate) when None. Substeps per frame are
                ceil(frame_time / dt), so the step used is at most dt.
            dt_factor: multiplies the automatic step, > 0 (default 1; above 1 warns: the run is past the stable
                estimate times the safety factor and may diverge, which the watchdog catches). Not with ``dt``.
            save_interval_s: minimum wall time between rewrites of the top-level layer [s]; 0 (default): every frame.
            color_attribute: attribute to colour points and meshes by (``primvars:displayColor``), e.g. "damage";
                None (default): no colours.
            color_range: (lo, hi) of real values mapped onto the colour ramp; default (0, 1).
            fragments_as_prims: write each fragment of a fracturing surface as its own Mesh
                ``/World/<surface>/fragment_<id>`` (invisible before it appears).
            resume: continue from ``<stem>.checkpoint.npz`` and append to the cache it was written with (ParameterError
                when there is none, it belongs to another scene, or that cache is gone).
            checkpoint_interval_s: wall time between checkpoints [s], >= 0, or None for none (default 60 s).
            check_interval: steps between watchdog checks, integer >= 1 (default 16; also at every frame end).
            stop: a pdsim.checkpoint.StopRequest (or anything with ``requested`` and ``signal``), polled at every step
                and frame end; once requested the run stops at the next step boundary, writes a checkpoint (unless
                checkpoints are off) and raises pdsim.checkpoint.RunInterrupted (a KeyboardInterrupt).
            on_frame: callable(frame, solvers) run after each frame is written (diagnostics such as energy audits;
                each solver's ``watchdog.last`` holds its frame-end check).
        """
        from .checkpoint import CHECKPOINT_FORMAT, RunInterrupted, checkpoint_path, load_checkpoint, save_checkpoint
        from .colliders import collider_names
        from .errors import InstabilityError
        from .output.usd import UsdCache
        from .output.writer import ViewWriter

        out = os.fspath(out)
        if os.path.splitext(out)[1].lower() not in (".usdc", ".usda", ".usd"):
            raise ParameterError("out", out, "a path ending in .usdc, .usda or .usd")
        if not os.path.isdir(os.path.dirname(os.path.abspath(out))):
            raise ParameterError("out", out, "a path in an existing folder")
        if os.path.isdir(out):
            raise ParameterError("out", out, "a file path, not a folder")
        frame_count = self.frames if frames is None else check_frames(frames)
        if dt is not None:
            dt = check_time_step(dt)
        dt_factor = check_range("dt_factor", dt_factor, 0.0, None)
        if dt is not None and dt_factor != 1.0:
            raise ParameterError("dt_factor", dt_factor, f"1 when dt={dt!r} is given (give one of the two)")
        if isinstance(check_interval, bool) or int(check_interval) != check_interval or check_interval < 1:
            raise ParameterError("check_interval", check_interval, "an integer >= 1 (steps between watchdog checks)")
        check_interval = int(check_interval)
        if checkpoint_interval_s is not None:
            checkpoint_interval_s = check_range(
                "checkpoint_interval_s", checkpoint_interval_s, 0.0, None, lo_open=False
            )
        if color_attribute is not None and not isinstance(color_attribute, str):
            raise ParameterError("color_attribute", color_attribute, "an attribute name such as 'damage', or None")
        names = collider_names(self.colliders)
        wall0 = time.perf_counter()
        preflight(self, device=device, out=out, dt=dt, frames=frame_count)  # before anything is allocated or written
        solvers = self.build_solvers(device=device, check=False)
        stable_dt = min(s.stable_time_step() for s in solvers)
        frame_dt = self.frame_time
        automatic = self.time_step_safety * stable_dt
        if dt is None:
            dt = min(dt_factor * automatic, frame_dt)
            if dt_factor > 1.0:
                warnings.warn(
                    f"dt_factor={dt_factor:g}: the time step is {dt_factor:g}x the automatic one ({automatic:.3g} s, "
                    f"{self.time_step_safety:g} x the stable estimate {stable_dt:.3g} s); the watchdog stops the run "
                    "if it diverges",
                    stacklevel=2,
                )
        else:
            warn_if_above_estimate(dt, stable_dt)
        substeps = max(1, math.ceil(frame_dt / dt - 1.0e-9))
        dt = frame_dt / substeps
        speed_limit = self._speed_limit(solvers)

        # world bounds of the bodies at rest and of the projectiles' start: they size the ground's quad
        corners = []
        for b in self.bodies:
            x = np.asarray(
                getattr(b, "point_rest_positions", None) if hasattr(b, "point_rest_positions") else b.rest_positions
            )
            corners += [x.min(axis=0), x.max(axis=0)]
        corners += [np.asarray(c.pose(0.0)[0]) for c in self.colliders if hasattr(c, "pose")]
        bounds = (np.min(corners, axis=0), np.max(corners, axis=0))
        rigid = [(c, n) for c, n in zip(self.colliders, names)]
        if self.ground is not None:
            rigid.append((self.ground, None))

        fingerprint = self._fingerprint(solvers, names)
        ck_path = checkpoint_path(out)
        start, first_substep, cache_run = 0, 0, None
        if resume:
            state = load_checkpoint(ck_path)
            start, first_substep, cache_run = self._restore_run(state, solvers, fingerprint, dt, substeps, frame_count)
        watchdogs = self._attach_watchdogs(solvers, dt=dt, stable_dt=stable_dt, bounds=bounds)
        self._schedule_watchdogs(solvers, watchdogs, dt=dt, speed_limit=speed_limit, every=check_interval, stop=stop)
        if resume:
            for i, w in enumerate(watchdogs):
                if w is not None:
                    w.restore(state["watchdogs"][str(i)])

        def write_frame(frame: int) -> None:
            t = frame * frame_dt
            views = [v for s in solvers for v in s.views()]
            for collider, name in rigid:
                view = collider.view(t, bounds=bounds)
                if name is not None:
                    view.name = name
                views.append(view)
            writer.write(frame, views)
            cache.end_frame(frame, time=t)

        def write_checkpoint(frame: int, substep: int):
            """The run's state after ``substep`` steps of frame ``frame + 1`` (frame ``frame`` finished)."""
            if checkpoint_interval_s is None:
                return None
            cache.save()  # the top-level layer on disk reaches ``frame``: a resume reopens the cache there
            state = {
                "format": CHECKPOINT_FORMAT,
                "fingerprint": fingerprint,
                "run": {
                    "frame": frame,
                    "substep": substep,
                    "dt": dt,
                    "substeps": substeps,
                    "frames": frame_count,
                    "cache_run": cache.run_id,
                },
                "writer": writer.checkpoint(),
                "solvers": {str(i): s.checkpoint() for i, s in enumerate(solvers)},
                "watchdogs": {str(i): ({} if w is None else w.checkpoint()) for i, w in enumerate(watchdogs)},
                "colliders": _collider_states(self.colliders),
            }
            return save_checkpoint(ck_path, state)

        metadata = {"frameTime": frame_dt, "timeScale": frame_dt * self.fps, "scene": str(self.name)}
        try:
            cache = UsdCache(
                out,
                fps=self.fps,
                up_axis=self.up_axis,
                save_interval_s=save_interval_s,
                metadata=metadata,
                append_frame=start if resume else None,
                append_run=cache_run,
            )
        except (ValueError, FileNotFoundError) as exc:
            if not resume:
                raise
            raise ParameterError(
                "resume", out, f"a cache holding the run the checkpoint belongs to, at its frame {start} ({exc})"
            ) from None
        with cache:
            writer = ViewWriter(
                cache,
                color_attribute=color_attribute,
                color_range=color_range,
                fragments_as_prims=fragments_as_prims,
                velocity_scale=frame_dt * self.fps,  # velocities per played second (USD's time codes per second)
            )
            if resume:
                writer.restore(state["writer"])
            coupling = self.method_contact(solvers)
            if not resume:
                write_frame(0)
            bar = _progress(frame_count - start, enabled=progress, desc=f"pdsim {self.name}")
            last_checkpoint = time.monotonic()
            frame = start
            try:
                for frame in range(start + 1, frame_count + 1):
                    for w in watchdogs:
                        if w is not None:
                            w.frame = frame
                    try:
                        self._advance_checked(solvers, dt, substeps, coupling, speed_limit, first=first_substep)
                    except RunInterrupted as exc:
                        done = getattr(exc, "in_frame", None)
                        if done is None:
                            raise
                        # stopped at a step boundary inside the frame, ``done`` steps into it
                        written = write_checkpoint(frame - 1, first_substep + done)
                        raise RunInterrupted(exc.signal, checkpoint=written, last_frame=frame - 1) from None
                    first_substep = 0
                    write_frame(frame)
                    if on_frame is not None:
                        on_frame(frame, solvers)
                    bar.update(1)
                    stopping = stop is not None and stop.requested
                    now = time.monotonic()
                    due = checkpoint_interval_s is not None and now - last_checkpoint >= checkpoint_interval_s
                    if (stopping or due) and frame < frame_count:
                        written = write_checkpoint(frame, 0)
                        last_checkpoint = time.monotonic()
                        if stopping:
                            raise RunInterrupted(stop.signal, checkpoint=written, last_frame=frame)
            except InstabilityError as exc:
                kept = self._frames_note(cache.top_level_path, frame - 1)
                raise InstabilityError(f"{exc}; {kept}") from exc
            except KeyboardInterrupt as exc:
                last = -1 if cache.last_frame is None else cache.last_frame
                exc.cache = str(cache.top_level_path)
                exc.last_frame = last
                exc.note = self._frames_note(cache.top_level_path, last)
                raise
            finally:
                bar.close()
            written = cache.frames_written
        if ck_path.is_file():
            ck_path.unlink()
        return RunReport(
            path=out,
            frames_written=written,
            substeps_per_frame=substeps,
            dt=dt,
            stable_dt=stable_dt,
            wall_seconds=time.perf_counter() - wall0,
            particle_count=sum(s.point_count for s in solvers),
            bond_count=sum(s.bond_count for s in solvers),
            summary="; ".join(s.summary() for s in solvers),
            first_frame=start + 1 if resume else 0,
            checks=sum(w.checks for w in watchdogs if w is not None),
        )

    # -- the frame loop ---------------------------------------------------------------------------------------------
    def _advance_checked(self, solvers, dt, substeps, coupling, speed_limit, *, first=0):
        """One frame from sub-step ``first``: solvers without mass (the lattice) advance the whole frame (when
        ``first`` is 0), the others ``substeps - first`` steps (Scene.advance_frame; their watchdogs check every few
        steps inside it and may raise a stop request), then every solver's ``check_state`` (the frame-end check, with
        the watchdogs' strain pass)."""
        from .solver import PointSolver

        points = [s for s in solvers if isinstance(s, PointSolver)]
        for s in points:
            if s.watchdog is not None:
                s.watchdog.frame_start_step = int(s.step_count)
        graphs = self._frame_graphs(solvers)
        if first == 0:
            for s in solvers:
                if not isinstance(s, PointSolver):
                    self._frame_alone(s, dt, substeps, graphs)
        if points and substeps > first:
            self.advance_frame(points, dt, substeps - first, coupling, graphs=graphs)
        for s in solvers:
            if s.watchdog is not None:
                s.watchdog.full_check = True
            s.check_state(speed_limit)

    def method_contact(self, solvers):
        """Contact between bodies of different methods (pdsim.contact.MethodContact): on when the scene holds a
        particle method and a mesh method and contact is not switched off; None otherwise."""
        from .contact import MethodContact

        if self.contact is False:
            return None
        particles = [s for s in solvers if callable(getattr(s, "contact_particles", None))]
        meshes = [s for s in solvers if callable(getattr(s, "contact_mesh", None))]
        if not particles or not meshes:
            return None
        return MethodContact(particles, meshes)

    def _frame_graphs(self, solvers):
        """The FrameGraphs (pdsim/frame_graph.py) of this run's solvers, following ``graph_capture``: kept on the
        first solver (it lives as long as the solvers do) for the same set of solvers."""
        from .frame_graph import FrameGraphs

        first = solvers[0]
        cached = getattr(first, "_frame_graphs", None)
        if cached is None or len(cached[0]) != len(solvers) or any(a is not b for a, b in zip(cached[0], solvers)):
            device = first.kin.device if hasattr(first, "kin") else first.device
            cached = (list(solvers), FrameGraphs(device, self.graph_capture))
            first._frame_graphs = cached
        return cached[1]

    @staticmethod
    def _frame_alone(solver, dt: float, substeps: int, graphs=None) -> None:
        """A frame of a solver without mass (the lattice: a frame of its own steps), replayed as a graph where
        ``graphs`` can."""
        if graphs is None:
            solver.simulate(dt, substeps)
        else:
            graphs.advance([solver], dt, substeps, None, lambda: solver.simulate(dt, substeps))

    @staticmethod
    def advance_frame(solvers, dt: float, substeps: int, coupling=None, graphs=None) -> None:
        """One frame of ``substeps`` steps of ``dt`` [s]: the solvers of methods with mass step together, phase by
        phase, so that ``coupling`` (contact between methods) acts within each step; the others (the lattice)
        advance by a frame. The frame's tables (projectile poses, the watchdog's collider speeds) are written to the
        device first; no step reads the device. ``graphs`` (a pdsim.frame_graph.FrameGraphs) replays the steps as a
        captured graph where it can; None launches them from the host."""
        from .solver import PointSolver

        coupled = [s for s in solvers if isinstance(s, PointSolver)]
        for s in solvers:
            if not isinstance(s, PointSolver):
                Scene._frame_alone(s, dt, substeps, graphs)
        if not coupled:
            return
        for s in coupled:
            s.begin_frame(dt, substeps)

        def run_steps():
            if len(coupled) == 1 and coupling is None:
                coupled[0].simulate(dt, substeps)
                return
            for _ in range(substeps):
                for s in coupled:
                    s.begin_step(dt)
                for s in coupled:
                    s.compute_forces()
                if coupling is not None:
                    coupling.apply(dt)
                for s in coupled:
                    s.end_step(dt)

        if graphs is None:
            run_steps()
        else:
            graphs.advance(coupled, dt, substeps, coupling, run_steps)

    @staticmethod
    def _write_frame(writer, cache, solvers, frame: int) -> None:
        views = [v for s in solvers for v in s.views()]
        writer.write(frame, views)
        cache.end_frame(frame)

    def _speed_limit(self, solvers) -> float:
        """A speed no particle of a sane run reaches: 20 times the largest of the solvers' speed scales (wave,
        initial and prescribed speeds) and a free fall through 1 km. An explicit run past its stable step grows
        exponentially and exceeds it within a few steps."""
        fall = math.sqrt(2.0 * float(np.linalg.norm(self.gravity)) * 1.0e3)
        return 20.0 * max([fall] + [s.speed_scale() for s in solvers])

    @staticmethod
    def _frames_note(top, last: int) -> str:
        """Where the finished frames are, for messages: the cache (resumed runs included) holds frames 0..last."""
        top = os.fspath(top)
        return f"{top} holds frames 0..{last}" if last >= 0 else f"{top} holds no finished frame"

    def _fingerprint(self, solvers, collider_names) -> dict:
        """What a checkpoint must match to be resumed by this scene (plain JSON values)."""
        bodies = []
        for b in self.bodies:
            count = getattr(b, "point_count", None)
            if count is None:
                count = getattr(b, "particle_count", 0)
            bodies.append([str(b.name), str(getattr(type(b), "method", "")), int(count)])
        return {
            "scene": str(self.name),
            "fps": float(self.fps),
            "frame_time": float(self.frame_time),
            "solvers": [type(s).__name__ for s in solvers],
            "bodies": bodies,
            "colliders": [str(n) for n in collider_names],
            "ground": self.ground is not None,
        }

    def _restore_run(self, state, solvers, fingerprint, dt, substeps, frame_count):
        """Checks a checkpoint against this scene and puts it back: (last finished frame, sub-steps done in the next
        one, the run id of the cache it was written with)."""
        import json

        from .checkpoint import CHECKPOINT_FORMAT

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
        same_step = int(run["substeps"]) == substeps and float(run["dt"]) == dt
        if not same_step:
            if substep:
                raise ParameterError(
                    "dt", dt, f"the checkpoint's time step {float(run['dt']):.6g} s (it stopped inside a frame)"
                )
            warnings.warn(
                f"resuming with a time step of {dt:.3g} s where the checkpoint ran {float(run['dt']):.3g} s: the "
                "frames differ from those of an uninterrupted run",
                stacklevel=3,
            )
        for i, s in enumerate(solvers):
            s.restore(state["solvers"][str(i)])
        _restore_colliders(self.colliders, state.get("colliders", {}))
        return frame, substep, str(run["cache_run"])

    # -- the watchdog --------------------------------------------------------------------------------------------------
    def _scene_speeds(self, bounds) -> dict:
        """Speeds [m/s] the scene gives its bodies: ``motion`` (initial, prescribed and kick speeds, projectiles) and
        ``fall`` (from the highest point to the ground, or through the scene's height without one)."""
        g = float(np.linalg.norm(self.gravity))
        motion = 0.0
        for b in self.bodies:
            if hasattr(b, "prescribed_speed"):
                motion = max(motion, float(b.prescribed_speed()))
        for c in self.colliders:
            if hasattr(c, "pose"):
                spin = float(np.linalg.norm(getattr(c, "angular_velocity", np.zeros(3))))
                radius = float(c._bounding_radius()) if hasattr(c, "_bounding_radius") else 0.0
                motion = max(motion, float(np.linalg.norm(getattr(c, "velocity", np.zeros(3)))) + spin * radius)
        fall = 0.0
        if g > 0.0:
            up = -np.asarray(self.gravity, dtype=np.float64) / g
            lo, hi = (np.asarray(x, dtype=np.float64) for x in bounds)
            corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            heights = corners @ up
            height = float(heights.max() - heights.min())
            if self.ground is not None:
                n = np.asarray(self.ground.normal, dtype=np.float64)
                n = n / np.linalg.norm(n)
                if float(n @ up) > 0.5:
                    height = max(0.0, float(heights.max()) - float(self.ground.offset) / float(n @ up))
            fall = math.sqrt(2.0 * g * height)
        return {"motion": motion, "fall": fall}

    def _attach_watchdogs(self, solvers, *, dt, stable_dt, bounds) -> list:
        """A pdsim.kinematics.Watchdog on every solver with mass (None for the others), with the scene's energy
        tolerance, projectile speeds and cause finder."""
        from .kinematics import TOTAL_TOLERANCE, Watchdog
        from .solver import PointSolver

        speeds = self._scene_speeds(bounds)
        projectiles = [c for c in self.colliders if hasattr(c, "pose") and callable(getattr(c, "pose", None))]
        surface_speed = _surface_speed(projectiles) if projectiles else None
        automatic = self.time_step_safety * stable_dt
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
                    surface_speed=surface_speed,
                    explain=lambda solver, index, position, what, ctx=ctx: self._explain(
                        solver, index, position, what, ctx
                    ),
                    energy=getattr(s, "integrator", "explicit") == "explicit",
                    total_tolerance=TOTAL_TOLERANCE["automatic" if context["factor"] <= 1.0 + 1.0e-9 else "larger"],
                )
            )
        return out

    def _schedule_watchdogs(self, solvers, watchdogs, *, dt, speed_limit, every, stop) -> None:
        """Checks every ``every`` steps with ``speed_limit``; the first watchdog polls ``stop`` at the scene's step
        boundaries (an explicit FEM solver stepping alone splits a step above its stable limit into ``stride``
        steps of its own)."""
        from .solver import PointSolver

        points = [s for s in solvers if isinstance(s, PointSolver)]
        alone = len(points) == 1  # stepping by its own simulate (Scene.advance_frame)
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

    def _explain(self, solver, index, position, what: str, ctx: dict) -> str:
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
        g = float(np.linalg.norm(self.gravity))
        for b in candidates:
            material = getattr(b, "material", None)
            if material is None:
                continue
            c = float(material.p_wave_speed)
            x = np.asarray(getattr(b, "point_rest_positions", getattr(b, "rest_positions", np.zeros((1, 3)))))
            height = float(np.ptp(x @ (np.asarray(self.gravity) / g))) if g > 0 else 0.0
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
        near = self._contact_near(solver, index, position)
        if near:
            return (
                f"contact: it started where '{body.name if body is not None else 'a body'}' touches {near}; try "
                f"--dt-factor 0.5, or a stiffer material or slower impact ({step})"
            )
        return (
            f"the time step: the automatic step ({self.time_step_safety:g} x the stable estimate; {step}) is too "
            "large for this scene; try --dt-factor 0.5 (or a lower time_step_safety)"
        )

    def _contact_near(self, solver, index, position) -> str:
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
        if self.ground is not None:
            n = np.asarray(self.ground.normal, dtype=np.float64)
            n = n / np.linalg.norm(n)
            if float(p @ n) - float(self.ground.offset) < 2.0 * h:
                return "the ground plane"
        for c in self.colliders:
            if hasattr(c, "pose"):
                centre = c.pose(solver.time)[0]
                radius = float(c._bounding_radius()) if hasattr(c, "_bounding_radius") else 0.0
                if float(np.linalg.norm(p - centre)) < radius + 2.0 * h:
                    return f"the collider '{c.name or type(c).__name__}'"
        contact = getattr(solver, "contact", None)
        if contact is not None:
            try:
                import warp as wp

                local = (kin.rest_world + kin.u.numpy().astype(np.float64)) - solver.origin
                x = wp.array(local.astype(np.float32), dtype=wp.vec3, device=solver.device)
                if contact.diagnostics(x).count[index] > 0:
                    return "another body or fragment (particle contact)"
            except Exception:  # noqa: BLE001 - a diagnosis must not hide the instability
                return ""
        return ""


class _NoProgress:
    def update(self, n):
        pass

    def close(self):
        pass


def _progress(total: int, *, enabled: bool, desc: str):
    if not enabled:
        return _NoProgress()
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="frame", dynamic_ncols=True)


def _surface_speed(projectiles):
    """(t, dt) -> the largest speed [m/s] of a projectile's surface over the step ending at t: its centre's speed plus
    its spin times its bounding radius (from ``pose``)."""
    from .colliders import _quat_mul, _rotation_vector

    def speed(t: float, dt: float) -> float:
        if dt <= 0.0:
            return 0.0
        best = 0.0
        for c in projectiles:
            p0, q0 = c.pose(t - dt)
            p1, q1 = c.pose(t)
            w = _rotation_vector(_quat_mul(q1, q0 * np.array([-1.0, -1.0, -1.0, 1.0]))) / dt
            radius = float(c._bounding_radius()) if hasattr(c, "_bounding_radius") else 0.0
            best = max(best, float(np.linalg.norm(p1 - p0)) / dt + float(np.linalg.norm(w)) * radius)
        return best

    return speed


def _collider_states(colliders) -> dict:
    """The colliders' state a resumed run needs: each projectile's last evaluated pose (its velocity over the next
    step is taken from it)."""
    out = {}
    for i, c in enumerate(colliders):
        last = getattr(c, "_last", None)
        if last is not None:
            out[str(i)] = {"time": float(last[0]), "position": np.asarray(last[1]), "rotation": np.asarray(last[2])}
    return out


def _restore_colliders(colliders, states: dict) -> None:
    for i, c in enumerate(colliders):
        st = states.get(str(i))
        if st is not None and hasattr(c, "_last"):
            c._last = (float(st["time"]), np.asarray(st["position"]), np.asarray(st["rotation"]))
