"""The solver contract: what the scene drives, whatever the method.

A method plugs into pdsim with a body class (declaring ``method``) and a :class:`Solver` subclass registered for it
(``SOLVERS``). The scene groups its bodies by method, builds one solver per method with a :class:`SolverContext`,
chooses one time step for all of them (scene.py holds the time-step policy) and, once a frame, asks each solver for
method-neutral output views.

Methods with mass derive from :class:`PointSolver`, whose step is split in three phases so that the scene can couple
methods inside a step (contact between bodies of different methods):

    begin_step(dt)     conditions, kick-drift, colliders           (displacements and velocities at t + dt)
    compute_forces()   internal forces and loads at t + dt          (``force`` holds them afterwards)
    end_step(dt)       second half kick; time advances

``step(dt)`` runs the three in turn.

Checkpoints: ``checkpoint() -> dict`` and ``restore(dict)`` capture and put back everything a run needs to continue
bit for bit (pdsim/checkpoint.py, ``pdsim run --resume``); PointSolver's cover the shared kinematics and each method
adds its own state (bonds, plastic state, contact, topology after fracture, lattice state).
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from .errors import FeatureNotAvailableError, ParameterError


@dataclass
class SolverContext:
    """What the scene gives every solver: Warp device, gravity [m/s^2], ground plane, particle contact setting
    (None/False off, True or an options dict on), colliders, and the origin [m] of the local frame in which the
    solvers store rest positions (world = origin + local)."""

    device: str = "cpu"
    gravity: tuple = (0.0, 0.0, 0.0)
    ground: object = None
    contact: object = None
    colliders: list = field(default_factory=list)
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    gravity_is_default: bool = True  # the scene's gravity was not given explicitly
    contact_is_default: bool = True  # the scene's contact is automatic (Scene.enable_contact not called)


class Solver(ABC):
    """Base of every method's solver.

    Class attributes: ``method`` (the body classes' ``method``), ``supported_features`` (every setting the method can
    honour; :meth:`check_features` raises FeatureNotAvailableError for the rest). Instance attributes: ``features``
    (the live ones), ``time`` [s], ``step_count``.
    """

    method: ClassVar[str] = ""
    supported_features: ClassVar[frozenset] = frozenset()

    _force_time: float = 0.0
    time: float = 0.0
    step_count: int = 0
    watchdog = None  # a pdsim.watchdog.Watchdog the scene attached, used by check_state

    @classmethod
    def requested_features(cls, bodies, context: SolverContext) -> dict:
        """{feature: who asks for it} of what a scene asks this method for (subclasses add body-level settings)."""
        asked = {}
        if context.ground is not None:
            asked["ground_plane"] = "the scene's ground plane (Scene.add_ground_plane)"
        if context.colliders:
            asked["colliders"] = "the scene's colliders (Scene.add_collider)"
        if any(g != 0.0 for g in context.gravity):
            asked["gravity"] = "the scene's gravity"
        return asked

    @classmethod
    def check_features(cls, bodies, context: SolverContext) -> None:
        """Raises FeatureNotAvailableError naming the body, the setting and what to use instead when a scene asks
        this method for a feature it cannot honour."""
        for feature, source in cls.requested_features(bodies, context).items():
            if feature not in cls.supported_features:
                names = ", ".join(f"'{b.name}'" for b in bodies)
                raise FeatureNotAvailableError(
                    f"{cls.method} bodies ({names}) cannot honour {source} ({feature}); {cls.instead(feature)}"
                )

    @classmethod
    def instead(cls, feature: str) -> str:
        """What a user can do instead of an unsupported feature (one sentence)."""
        return "remove the setting or use a method that supports it (see docs/guide.md)"

    @abstractmethod
    def stable_time_step(self) -> float:
        """Largest stable step [s] of the method's explicit integration (no safety factor), inf when unbounded."""

    @abstractmethod
    def simulate(self, dt: float, steps: int) -> None:
        """Runs ``steps`` steps of ``dt`` [s]."""

    @abstractmethod
    def check_state(self, speed_limit: float) -> None:
        """Raises InstabilityError when the state is not finite or a speed exceeds ``speed_limit`` [m/s]."""

    @abstractmethod
    def speed_scale(self) -> float:
        """A speed [m/s] that the run's motion is measured against (wave, initial, prescribed, projectile speeds)."""

    @abstractmethod
    def views(self) -> list:
        """Method-neutral output views of the current state (pdsim/output/views.py)."""

    def frame_views(self) -> list:
        """The views of :meth:`views`, where some may be DeferredViews (pdsim/output/views.py) that build their
        values later from copies of the current state; the run builds those on its worker thread."""
        return self.views()

    @property
    @abstractmethod
    def point_count(self) -> int:
        """Particles or vertices simulated."""

    @property
    def bond_count(self) -> int:
        """Bonds (peridynamics, lattice links) or 0."""
        return 0

    def summary(self) -> str:
        """What the solver simulates, in a few words."""
        return f"{self.point_count} points"

    def reaction_forces(self) -> dict:
        """{(body name, condition name): force [N], float64 [3]} the boundary conditions exert now."""
        return {}

    def crack_events(self):
        """An object whose ``collect()`` returns, per frame, an EventsView per body of the bonds broken since the last
        call (``Scene.run(crack_events=True)``), or None where the method does not give crack events."""
        return None

    # -- checkpoints ----------------------------------------------------------------------------------------------
    def checkpoint(self) -> dict:
        """Everything a run needs to continue from the current state exactly as if it had not stopped: a nested dict
        of numpy arrays and plain scalars (int, float, str, bool, None), e.g. {"time": t, "u": array, ...}. Arrays
        are host copies of the device state, bit for bit (pdsim/checkpoint.py writes them to ``<stem>.checkpoint.npz``).
        The contract: ``restore(checkpoint())`` on a solver built from the same bodies leaves it stepping exactly as
        the one checkpointed (bit-identical on the CPU)."""
        raise FeatureNotAvailableError(f"{type(self).__name__} ({self.method}) cannot write checkpoints")

    def restore(self, state: dict) -> None:
        """Puts the state of :meth:`checkpoint` back into this solver (built from the same bodies and context)."""
        raise FeatureNotAvailableError(f"{type(self).__name__} ({self.method}) cannot restore checkpoints")


def array_state(array) -> np.ndarray:
    """A host copy of a Warp array (numpy; vectors as [n, 3], bit for bit), or None for None."""
    return None if array is None else np.array(array.numpy(), copy=True)


def assign_state(array, values, name: str = "array") -> None:
    """Copies checkpointed ``values`` (numpy) into the Warp ``array`` in place (same shape required)."""
    if array is None or values is None:
        if (array is None) != (values is None):
            raise ParameterError(name, "checkpoint", "the state of a solver built from the same scene")
        return
    values = np.asarray(values)
    if tuple(array.numpy().shape) != tuple(values.shape):
        raise ParameterError(
            name, f"shape {values.shape}", f"shape {tuple(array.numpy().shape)} (a checkpoint of the same scene)"
        )
    array.assign(values)


class PointSolver(Solver):
    """A solver whose state lives on points with mass, integrated by the shared kinematics (pdsim/kinematics.py).

    Subclasses set ``self.kin`` (a PointKinematics), ``self.force`` (the force array the kick reads),
    ``self.inv_mass`` (per point, in the force array's unit) and implement :meth:`compute_forces` and
    :meth:`apply_colliders`."""

    supported_features: ClassVar[frozenset] = frozenset({"gravity", "ground_plane", "colliders", "loads"})

    def begin_step(self, dt: float) -> None:
        """Kick-drift of the shared kinematics, then the colliders at t + dt."""
        if self.watchdog is not None and self.kin.watchdog is not self.watchdog:
            self.watchdog.bind(self.kin)  # the kinematics were rebuilt (FEM fracture)
        self._force_time = self.time + dt
        self.kin.begin_step(self.time, dt)
        self.apply_colliders(self._force_time, dt)

    @abstractmethod
    def apply_colliders(self, time: float, dt: float) -> None:
        """Ground plane and colliders on the free points, at the positions of ``time`` [s]."""

    @abstractmethod
    def compute_forces(self) -> None:
        """Internal forces (and contact within the method) at the current displacements into ``self.force``, then
        the loads at the end of the step being taken (``self.kin.add_loads(self.force, self._force_time)``)."""

    def end_step(self, dt: float) -> None:
        """Second half kick; advances time and the step count."""
        self.kin.end_step(self.force, self.inv_mass, dt)
        self.time += dt
        self.step_count += 1

    def step(self, dt: float) -> None:
        """One velocity-Verlet step of ``dt`` [s]."""
        self.begin_step(dt)
        self.compute_forces()
        self.end_step(dt)

    def simulate(self, dt: float, steps: int) -> None:
        for _ in range(int(steps)):
            self.step(dt)

    # -- frames replayed as graphs (pdsim/capture.py) ----------------------------------------------------------
    def graph_capture_blocker(self, dt: float) -> str | None:
        """Why this solver's steps of ``dt`` [s] cannot be captured once and replayed every frame (work a step does
        on the host), or None (default: the shared kinematics, colliders and contact are capturable). A solver that
        launches from several CPU threads (``threads`` > 1, peridynamics on the CPU) cannot: a capture records the
        launches of its own thread only."""
        threads = getattr(self, "threads", 1)
        if isinstance(threads, int) and threads > 1:
            return f"{threads} CPU threads launch the bond passes (a capture records one thread's launches)"
        return None

    def begin_frame(self, dt: float, steps: int) -> None:
        """Writes the tables of the next ``steps`` steps of ``dt`` [s] to the device before the frame (projectile
        poses, the watchdog's collider speeds): one copy each, none inside the frame."""
        for c in getattr(self, "colliders", ()):
            if callable(getattr(c, "begin_frame", None)):
                c.begin_frame(self.time, dt, steps)
        if self.watchdog is not None:
            self.watchdog.begin_frame(dt, steps)

    def frame_needs_direct(self, dt: float, steps: int) -> bool:
        """True when the next ``steps`` steps of ``dt`` [s] hold a velocity kick (a launch of its step only), with a
        margin above the round-off of the accumulated time (a frame wrongly thought to hold one only runs directly)."""
        kin = self.kin
        if kin.next_kick < len(kin.kicks):
            end = self.time + steps * dt * (1.0 + 1.0e-9) + 1.0e-12
            return kin.kicks[kin.next_kick][0] < end
        return False

    def graph_key(self) -> tuple:
        """What the captured launches depend on (pdsim/capture.py keys its graphs by the identity of each object
        and keeps the objects alive with the graph): the kinematics and force arrays (FEM fracture rebuilds them), the
        watchdog's table and the projectiles' tables (reallocated when the substeps change)."""
        parts = [self.kin, getattr(self, "force", None), getattr(self, "topology_version", 0)]
        if self.watchdog is not None:
            parts.append(self.watchdog._speeds)
        for c in getattr(self, "colliders", ()):
            if callable(getattr(c, "begin_frame", None)):
                parts += [c._table.array, c._motion.array]
        return tuple(parts)

    def after_replay(self, dt: float, steps: int) -> None:
        """The host bookkeeping of ``steps`` steps of ``dt`` [s] that a graph replayed on the device: time (the same
        float64 additions as :meth:`begin_step` / :meth:`end_step`), step count, the kinematics' clock mirror and the
        watchdog's accounting."""
        t = self.time
        for _ in range(int(steps)):
            self._force_time = t + dt
            t = self._force_time
        self.time = t
        self.step_count += int(steps)
        self.kin.clock_host[0] = self.kin.clock_host[1] = t
        if self.watchdog is not None:
            self.watchdog.after_replay(dt, steps)

    def check_state(self, speed_limit: float) -> None:
        where = f"at t={self.time:.6g} s (step {self.step_count}) in {self.summary()}"
        if self.watchdog is not None:
            self.watchdog.check(speed_limit, where)
        else:
            self.kin.check(speed_limit, where)

    # -- checkpoints of the shared kinematics -----------------------------------------------------------------------
    def kinematics_checkpoint(self) -> dict:
        """The shared point state: u, v, a, the kinds and conditions in force (point_kind, active_kind,
        active_velocity), the force array, time, step count and the next kick."""
        kin = self.kin
        return {
            "time": float(self.time),
            "step_count": int(self.step_count),
            "force_time": float(self._force_time),
            "next_kick": int(kin.next_kick),
            "kin_time": float(kin.time),
            "point_count": int(kin.point_count),
            "u": array_state(kin.u),
            "v": array_state(kin.v),
            "a": array_state(kin.a),
            "point_kind": array_state(kin.point_kind),
            "active_kind": array_state(kin.active_kind),
            "active_velocity": array_state(kin.active_velocity),
            "force": array_state(self.force),
        }

    def kinematics_restore(self, state: dict) -> None:
        """Puts :meth:`kinematics_checkpoint` back (the kinematics must have the same point count)."""
        kin = self.kin
        for name in ("u", "v", "a", "point_kind", "active_kind", "active_velocity"):
            assign_state(getattr(kin, name), state[name], name)
        assign_state(self.force, state["force"], "force")
        kin.next_kick = int(state["next_kick"])
        kin.time = float(state["kin_time"])
        self.time = float(state["time"])
        self.step_count = int(state["step_count"])
        self._force_time = float(state["force_time"])

    def checkpoint(self) -> dict:
        return {"kinematics": self.kinematics_checkpoint()}

    def restore(self, state: dict) -> None:
        self.kinematics_restore(state["kinematics"])

    def reaction_forces(self) -> dict:
        return self.kin.reactions(self.force, self.time)

    @property
    def point_count(self) -> int:
        return self.kin.point_count

    def displacements(self) -> np.ndarray:
        """Displacements from the rest configuration [m], float64 [point_count, 3]."""
        return self.kin.displacements()

    def positions(self) -> np.ndarray:
        """World positions [m], float64 [point_count, 3]."""
        return self.kin.positions()

    def velocities(self) -> np.ndarray:
        """Velocities [m/s], float64 [point_count, 3]."""
        return self.kin.velocities()

    def masses(self) -> np.ndarray:
        """Point masses [kg]."""
        return self.kin.mass_host

    def kinetic_energy(self) -> float:
        """1/2 sum m v^2 [J]."""
        return self.kin.kinetic_energy()

    def linear_momentum(self) -> np.ndarray:
        """sum m v [kg m/s]."""
        return self.kin.linear_momentum()

    def angular_momentum(self, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        """sum m (x - origin) x v [kg m^2/s]."""
        return self.kin.angular_momentum(origin)


SOLVERS: dict[str, type] = {}


def register_solver(cls):
    """Class decorator: makes ``cls`` the solver of bodies whose ``method`` equals ``cls.method``."""
    SOLVERS[cls.method] = cls
    return cls


def solver_for(body) -> type:
    """The solver class of a body (its ``method``)."""
    method = getattr(body, "method", "")
    if method not in SOLVERS:
        # importing the method's package registers its solver
        importlib.import_module(f"pdsim.{method}") if method else None
    if method not in SOLVERS:
        raise FeatureNotAvailableError(f"no solver for bodies of method {method!r} ({type(body).__name__})")
    return SOLVERS[method]


__all__ = [
    "SOLVERS",
    "PointSolver",
    "Solver",
    "SolverContext",
    "array_state",
    "assign_state",
    "register_solver",
    "solver_for",
]
