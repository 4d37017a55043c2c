"""A frame's steps replayed as one captured graph (docs/architecture.md, GPU path).

A frame of a scene is ``substeps`` steps of the same length. Nothing inside a step reads the device from the host
(the watchdog and the counters are read at the frame's end), and nothing a step launches changes from one frame to
the next: the time lives in the kinematics' device clock, the projectiles' poses and the watchdog's collider speeds
in tables written once before the frame, and each step reads its row by its place in the frame. So the launches of
a frame can be captured once (``wp.ScopedCapture``) and replayed every later frame (``wp.capture_launch``): on CUDA a
CUDA graph (one launch per frame instead of one per kernel), on the CPU Warp's recorded operation stream (the same
code path, used by the tests).

:class:`FrameGraphs` decides per frame:

- the solvers' first frame runs directly (it allocates what the step allocates once, loads the kernels and reads the
  collision radii), the second is captured and launched, the later ones replay the capture; a change of the
  configuration (step length, substeps, the arrays' roles: a lattice's buffers after an odd number of steps, its
  leaders after a category change) captures again (each configuration's graph is kept);
- a frame in which a velocity kick (or a lattice category change) falls runs directly (a launch of that step only);
- a solver whose step does host work (``graph_capture_blocker``: FEM fracture, the implicit FEM integrator, an FEM
  body stepping alone above its explicit limit, peridynamics on several CPU threads, lattice bodies with tracked
  particles) makes every frame run directly, with a warning naming the reason once
  per run (``fallback`` keeps it).

The host's bookkeeping of replayed steps (time, step count, the watchdog's accounting) is advanced by each solver's
``after_replay``, by the same float64 additions the steps make.
"""

from __future__ import annotations

import warnings

import warp as wp

__all__ = ["FrameGraphs"]


class FrameGraphs:
    """Captures and replays the frames of a scene's solvers with mass.

    Args:
        device: the Warp device of the solvers.
        enabled: True captures on any device (on the CPU: Warp's recorded replay), False never, None (default) on
            CUDA devices only.

    Attributes:
        captures, replays, direct_frames: frames captured (then launched), replayed, and run directly.
        fallback: why the frames run directly (a solver's graph_capture_blocker), or None.
    """

    def __init__(self, device, enabled: bool | None = None):
        self.device = wp.get_device(device)
        self.enabled = self.device.is_cuda if enabled is None else bool(enabled)
        self._graphs: dict = {}
        self._seen: set = set()
        self.captures = 0
        self.replays = 0
        self.direct_frames = 0
        self.fallback: str | None = None

    def blocker(self, solvers, dt: float) -> str | None:
        """The first reason a solver gives why its steps cannot be captured, or None."""
        for s in solvers:
            reason = s.graph_capture_blocker(dt)
            if reason:
                return reason
        return None

    @staticmethod
    def _key(solvers, dt: float, substeps: int, coupling) -> tuple[tuple, list]:
        """(key, objects): what the captured launches depend on, step length, substeps, the contact between methods
        and each solver's ``graph_key()`` (its arrays in their current roles), the objects by identity; the objects
        are kept with the graph, so that no identity in a key is reused by a new object while the graph lives."""
        parts = [float(dt), int(substeps), coupling]
        for s in solvers:
            parts += [s, *s.graph_key()]
        plain = (int, float, str, bool, type(None))
        key = tuple(p if isinstance(p, plain) else ("id", id(p)) for p in parts)
        return key, [p for p in parts if not isinstance(p, plain)]

    def advance(self, solvers, dt: float, substeps: int, coupling, run_steps) -> str:
        """One frame of ``substeps`` steps of ``dt`` [s] of ``solvers`` (the PointSolvers stepping together, or one
        lattice solver; their tables already written by ``begin_frame``); ``run_steps()`` launches the steps
        directly. Returns what was done: "direct", "captured" or
        "replayed"."""
        if not self.enabled:
            run_steps()
            return "direct"
        reason = self.blocker(solvers, dt)
        if reason:
            if self.fallback != reason:
                self.fallback = reason
                warnings.warn(
                    f"graph capture of the frame's steps is off for this run: {reason}; every step is launched from "
                    "the host (docs/architecture.md, GPU path)",
                    stacklevel=3,
                )
            self.direct_frames += 1
            run_steps()
            return "direct"
        if any(s.frame_needs_direct(dt, substeps) for s in solvers):
            self.direct_frames += 1
            run_steps()
            return "direct"
        key, objects = self._key(solvers, dt, substeps, coupling)
        first = frozenset(id(s) for s in solvers)
        if first not in self._seen:  # these solvers' first frame: one-time allocations, kernel loads, radius reads
            self._seen.add(first)
            self.direct_frames += 1
            run_steps()
            return "direct"
        watchdogs = [s.watchdog for s in solvers if getattr(s, "watchdog", None) is not None]
        for w in watchdogs:
            w.frame_checks_only = True
        try:
            entry = self._graphs.get(key)
            if entry is None:
                with wp.ScopedCapture(device=self.device) as capture:
                    run_steps()  # records the launches; the host bookkeeping advances as in a direct frame
                self._graphs[key] = (capture.graph, objects)
                wp.capture_launch(capture.graph)
                self.captures += 1
                return "captured"
            wp.capture_launch(entry[0])
            for s in solvers:
                s.after_replay(dt, substeps)
            self.replays += 1
            return "replayed"
        finally:
            for w in watchdogs:
                w.frame_checks_only = False
