"""Scenes: what a shot holds (bodies, colliders, the ground, gravity, contact, time settings) and how its solvers
are built. Running a scene is pdsim.run's: ``Scene.run`` hands the scene to :func:`pdsim.run.run_scene`."""

from __future__ import annotations

import dataclasses
import inspect
import math
import os

import numpy as np

from .checks import check_frames, check_range
from .colliders import Collider, GroundPlane
from .device import default_device
from .errors import ParameterError
from .fem import FemBody
from .geometry import SolidShape
from .kinematics import scene_origin
from .materials import Material
from .peridynamics import PeridynamicBody
from .preflight import check_particle_request, check_prim_names, preflight
from .rigid import RigidBody, build_rigid_bodies
from .run import RunReport, run_scene
from .solver import SolverContext, solver_for

UP_AXES = {"Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


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
        graph_capture: replay each frame's steps as one captured graph (pdsim/capture.py): None (default) on CUDA
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
        if not isinstance(name, str) or not name.strip() or "/" in name or os.sep in name:
            raise ParameterError(
                "name", name, "a non-empty scene name without '/' (it labels the cache and names <name>.usdc)"
            )
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
        """Fills ``shape`` with particles of ``spacing`` [m] and adds it (keyword options: see PeridynamicBody). A
        spacing whose particles could not fit in memory is refused before any sampling (estimated from the shape's
        bounding box and volume)."""
        if isinstance(shape, SolidShape):
            defaults = inspect.signature(PeridynamicBody).parameters
            check_particle_request(
                shape,
                spacing,
                kwargs.get("horizon_factor", defaults["horizon_factor"].default),
                bool(kwargs.get("partial_volumes", defaults["partial_volumes"].default)),
                kwargs.get("name") if isinstance(kwargs.get("name"), str) else None,
            )
        return self.add_body(PeridynamicBody(shape, material, spacing, **kwargs))

    def add_fem_body(self, shape, material: Material, **kwargs):
        """Adds a tetrahedral FEM body (a SolidShape meshed with fTetWild, or a TetMesh; options: see FemBody)."""
        return self.add_body(FemBody(shape, material, **kwargs))

    def add_ground_plane(
        self, *, height: float = 0.0, friction: float = 0.5, restitution: float | None = None
    ) -> GroundPlane:
        """A ground plane perpendicular to the up axis at ``height`` [m], Coulomb ``friction`` >= 0, and the normal
        ``restitution`` e in (0, 1] of the contact law (None: inelastic projection; pdsim.colliders.GroundPlane)."""
        h = check_range("height", height, None, None)
        mu = check_range("friction", friction, 0.0, None, lo_open=False)
        e = None if restitution is None else check_range("restitution", restitution, 0.0, 1.0, hi_open=False)
        ground = GroundPlane(normal=UP_AXES[self.up_axis], offset=h, friction=mu, restitution=e)
        check_prim_names(self.bodies, self.colliders, ground)  # a body named "ground" clashes with /World/ground
        self.ground = ground
        return self.ground

    def enable_contact(self, enabled: bool = True, **options) -> None:
        """Short-range repulsion between particles that share no live bond (separate bodies, fragments), and between
        FEM surfaces. Automatic by default: on when the scene has several bodies or a body that can break.
        ``options`` go to pdsim.contact.ParticleContact (e.g. friction=0.3, distance_factor=1.35); ``restitution``
        (in (0, 1]) and ``friction`` also set the contact between methods and between FEM surfaces
        (pdsim.contact.MethodContact), the one contact law of docs/stability.md. They are the values of pairs whose
        materials bring none (pdsim.Material contact_restitution, contact_friction, combined per pair)."""
        self.contact = (options or True) if enabled else False

    def add_collider(self, collider):
        """Adds a static MeshCollider or a kinematic projectile (SphereProjectile, BoxProjectile, MeshProjectile)."""
        if not isinstance(collider, Collider):
            raise ParameterError(
                "collider",
                type(collider).__name__,
                "a pdsim collider: MeshCollider(shape) for a static shape, SphereProjectile, BoxProjectile or "
                "MeshProjectile(shape) for a moving one",
            )
        check_prim_names(self.bodies, [*self.colliders, collider], self.ground)
        self.colliders.append(collider)
        return collider

    def add_rigid_body(
        self,
        shape,
        *,
        density=None,
        mass=None,
        position=None,
        orientation=(0.0, 0.0, 0.0, 1.0),
        velocity=(0.0, 0.0, 0.0),
        angular_velocity=(0.0, 0.0, 0.0),
        friction: float = 0.5,
        band: float | None = None,
        name: str | None = None,
        restitution: float | None = None,
    ) -> RigidBody:
        """A dynamic rigid body (pdsim.rigid.RigidBody): ``shape`` a pdsim.rigid.SphereShape(radius),
        BoxShape(size) or a closed mesh (SolidShape, ``load_mesh``); ``density`` [kg/m^3] or ``mass`` [kg]; its
        centre of mass ``position`` [m], ``orientation`` (x, y, z, w), ``velocity`` [m/s] and ``angular_velocity``
        [rad/s] at time 0; Coulomb ``friction``; ``restitution`` e in [0, 1] or None against the ground, static
        meshes and other rigid bodies (pdsim.rigid.RigidBody: the penalty form of the one contact law; inelastic
        where neither side brings one; against particles and FEM vertices inelastic). It falls under the scene's
        gravity and is in two-way contact with peridynamic and FEM bodies, the ground, static mesh colliders and the
        other rigid bodies; written to the cache as ``/World/colliders/<name>`` (a transform over its rest mesh, with
        its velocity and angular velocity)."""
        body = RigidBody(
            shape,
            density=density,
            mass=mass,
            position=position,
            orientation=orientation,
            velocity=velocity,
            angular_velocity=angular_velocity,
            friction=friction,
            band=band,
            name=name,
            restitution=restitution,
        )
        body.gravity = np.asarray(self.gravity, dtype=np.float64)
        return self.add_collider(body)

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
        if not self.bodies:
            raise ParameterError("bodies", [], "a scene with at least one body")
        if check:
            preflight(self, device=device)
        groups: dict[type, list] = {}
        for b in self.bodies:
            groups.setdefault(solver_for(b), []).append(b)
        ctx = self.context(device=device)
        self.rigid_bodies = build_rigid_bodies(self, ctx.origin, ctx.device)  # before the solvers bind them
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
        render_points: bool = False,
        debris_particles: int = 0,
        crack_events: bool = False,
        resume: bool = False,
        checkpoint_interval_s: float | None = 60.0,
        check_interval: int = 16,
        stop=None,
        on_frame=None,
        layout: str = "file",
        profile=False,
        surface_thread: bool = True,
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

        The watchdog (pdsim.watchdog.Watchdog, docs/stability.md) checks every ``check_interval`` steps and at each
        frame end that the state is finite, no point is faster than the speed limit, the energy has not grown past
        what the run started with plus the work put in, and strains are bounded; it raises InstabilityError naming the
        frame, the body and the likely cause, and the cache keeps every finished frame.

        Checkpoints (pdsim/checkpoint.py): at frame ends, every ``checkpoint_interval_s`` seconds of wall time (0:
        every frame; None: never), and when ``stop`` is requested, the run writes ``<stem>.checkpoint.npz`` beside
        ``out``; ``resume=True`` continues from it, bit for bit as an uninterrupted run on the CPU, in the same cache
        ``out`` (the frames the interrupted run wrote after its checkpoint are replaced). A finished run removes its
        checkpoint; a run removes the temporary files a killed run left beside ``out``.

        A write that fails during the run (disk full, the folder turned read-only) raises
        pdsim.errors.OutputWriteError naming the file, the error and the free space; the cache keeps every finished
        frame.

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
            render_points: False (default): a body's particles are written with ``purpose = guide`` where the body
                has a surface (renderers and Blender's importer leave them out, ``pdsim preview --points all`` draws
                them); True: they render too.
            debris_particles: fragments of fewer particles than this are written as instances of the point instancer
                ``/World/<body>_debris`` (position, velocity, orientation, size) instead of as faces of the surface;
                0 (default): none, every fragment stays in the surface (docs/cache_format.md, "Debris").
            crack_events: write the bonds that broke in each frame as the points ``/World/<body>_crack_events``
                (midpoint, released energy [J], crack-face normal; peridynamic bodies; docs/cache_format.md).
            resume: continue from ``<stem>.checkpoint.npz`` and append to the cache it was written with (ParameterError
                when there is none, it belongs to another scene, or that cache is gone).
            checkpoint_interval_s: wall time between checkpoints [s], >= 0, or None for none (default 60 s).
            check_interval: steps between watchdog checks, integer >= 1 (default 16; also at every frame end).
            stop: a pdsim.checkpoint.StopRequest (or anything with ``requested`` and ``signal``), polled at every step
                and frame end; once requested the run stops at the next step boundary, writes a checkpoint (unless
                checkpoints are off; a checkpoint write still going 0.8 s after the request is abandoned and the
                previous checkpoint kept, so that a StopRequest stops a large run within 2 s) and raises
                pdsim.checkpoint.RunInterrupted (a KeyboardInterrupt).
            on_frame: callable(frame, solvers) run after each frame is simulated and its views taken (diagnostics
                such as energy audits; each solver's ``watchdog.last`` holds its frame-end check); the frame is
                written once its render surfaces are built, before the next frame's views are taken.
            layout: ``"file"`` (default): the frames stream into ``<stem>.frames/`` while running and are packed into
                the one self-contained file ``out`` when the run finishes; ``"clips"``: ``out`` stays a top-level
                layer that refers to that folder (for caches too big to pack; docs/cache_format.md).
            profile: True: at the end print the wall time of each phase of the run (build, simulate, surfaces, write,
                checks, other; pdsim/profile.py) and write the run report ``<stem>.report.json`` beside ``out`` (the
                RunReport's fields: the phases, the pre-flight's cost estimate, ...); a pdsim.profile.RunProfile
                started earlier (as True, counting from its start). The returned RunReport holds the phases and the
                estimate either way.
            surface_thread: build each frame's render surfaces on a thread while the next frame simulates (default);
                False builds them in the main thread. The cache is the same either way.
        """
        return run_scene(
            self,
            out,
            frames=frames,
            device=device,
            dt=dt,
            dt_factor=dt_factor,
            progress=progress,
            save_interval_s=save_interval_s,
            color_attribute=color_attribute,
            color_range=color_range,
            fragments_as_prims=fragments_as_prims,
            render_points=render_points,
            debris_particles=debris_particles,
            crack_events=crack_events,
            resume=resume,
            checkpoint_interval_s=checkpoint_interval_s,
            check_interval=check_interval,
            stop=stop,
            on_frame=on_frame,
            layout=layout,
            profile=profile,
            surface_thread=surface_thread,
        )
