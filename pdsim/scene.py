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
from .validate import check_frames, check_range, check_time_step

UP_AXES = {"Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


def warn_if_above_estimate(dt: float, dt_crit: float):
    """Warns when a user time step exceeds the (conservative) stable estimate; divergence is still detected."""
    if dt > dt_crit:
        warnings.warn(
            f"time step {dt:.3g} s exceeds the stable estimate {dt_crit:.3g} s; the run is checked for "
            "divergence every frame",
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
    ):
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
        self.ground = GroundPlane(normal=UP_AXES[self.up_axis], offset=h, friction=mu)
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
        )
        return ctx

    def build_solvers(self, *, device: str | None = None) -> list:
        """One solver per method, each over all bodies of that method (CUDA when present unless ``device`` given).
        Each method first checks that it can honour what the scene asks of it (FeatureNotAvailableError)."""
        from .solver import solver_for

        if not self.bodies:
            raise ParameterError("bodies", [], "a scene with at least one body")
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
        progress: bool = True,
        save_interval_s: float = 0.0,
        color_attribute: str | None = None,
        color_range=None,
        fragments_as_prims: bool = False,
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

        Args:
            out: output path.
            frames: overrides the scene's frame count (integer >= 1).
            device: Warp device; CUDA when present unless given.
            dt: time step [s]; automatic (safety * stable estimate) when None. Substeps per frame are
                ceil(frame_time / dt), so the step used is at most dt.
            save_interval_s: minimum wall time between rewrites of the top-level layer [s]; 0 (default): every frame.
            color_attribute: attribute to colour points and meshes by (``primvars:displayColor``), e.g. "damage";
                None (default): no colours.
            color_range: (lo, hi) of real values mapped onto the colour ramp; default (0, 1).
            fragments_as_prims: write each fragment of a fracturing surface as its own Mesh
                ``/World/<surface>/fragment_<id>`` (invisible before it appears).
        """
        from .colliders import collider_names
        from .output import UsdCache
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
        if color_attribute is not None and not isinstance(color_attribute, str):
            raise ParameterError("color_attribute", color_attribute, "an attribute name such as 'damage', or None")
        names = collider_names(self.colliders)
        wall0 = time.perf_counter()
        solvers = self.build_solvers(device=device)
        stable_dt = min(s.stable_time_step() for s in solvers)
        frame_dt = self.frame_time
        if dt is None:
            dt = min(self.time_step_safety * stable_dt, frame_dt)
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

        metadata = {"frameTime": frame_dt, "timeScale": frame_dt * self.fps, "scene": str(self.name)}
        with UsdCache(
            out, fps=self.fps, start_frame=0, up_axis=self.up_axis, save_interval_s=save_interval_s, metadata=metadata
        ) as cache:
            writer = ViewWriter(
                cache,
                color_attribute=color_attribute,
                color_range=color_range,
                fragments_as_prims=fragments_as_prims,
                velocity_scale=frame_dt * self.fps,  # velocities per played second (USD's time codes per second)
            )
            coupling = self.method_contact(solvers)
            write_frame(0)
            bar = _progress(frame_count, enabled=progress, desc=f"pdsim {self.name}")
            try:
                for frame in range(1, frame_count + 1):
                    self.advance_frame(solvers, dt, substeps, coupling)
                    for s in solvers:
                        s.check_state(speed_limit)
                    write_frame(frame)
                    bar.update(1)
            finally:
                bar.close()
            written = cache.frames_written
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
        )

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

    @staticmethod
    def advance_frame(solvers, dt: float, substeps: int, coupling=None) -> None:
        """One frame of ``substeps`` steps of ``dt`` [s]: the solvers of methods with mass step together, phase by
        phase, so that ``coupling`` (contact between methods) acts within each step; the others (the lattice)
        advance by a frame."""
        from .solver import PointSolver

        coupled = [s for s in solvers if isinstance(s, PointSolver)]
        for s in solvers:
            if not isinstance(s, PointSolver):
                s.simulate(dt, substeps)
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
