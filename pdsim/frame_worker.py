"""The run's surface thread: builds a frame's deferred views (the render surfaces) while the next frame simulates.

A solver's :meth:`~pdsim.solver.Solver.frame_views` may return :class:`~pdsim.output.views.DeferredView` items that
hold copies of the state they need. :class:`SurfaceWorker` builds one frame's list of views on a daemon thread
(manifold3d, numpy and scipy release the GIL, so it runs beside the simulation's kernels) and hands the finished
list back in the main thread, where the frame is written. One frame is in flight at a time, so frames are built and
written in order, each exactly as it would be built in the main thread. An error in the thread is raised again in
the main thread by :meth:`SurfaceWorker.wait`, with a note naming the frame. The thread is a daemon: a run stopped
while a frame is being built does not wait for it at exit.
"""

from __future__ import annotations

import threading
import time

from .output.views import DeferredView, resolve_views

__all__ = ["SurfaceWorker"]


class _Frame:
    """One frame's views being built: the thread, its result or error."""

    def __init__(self, frame: int, views: list, payload):
        self.frame, self.payload = frame, payload
        self.views: list | None = None
        self.error: BaseException | None = None
        self.done = threading.Event()
        self.seconds = 0.0  # wall time of the build [s]
        self.thread = threading.Thread(target=self._build, args=(views,), name=f"pdsim-surfaces-{frame}", daemon=True)

    def _build(self, views: list) -> None:
        t0 = time.perf_counter()
        try:
            self.views = resolve_views(views)
        except BaseException as exc:  # noqa: BLE001 - handed to the main thread, raised there by SurfaceWorker.wait
            self.error = exc
        finally:
            self.seconds = time.perf_counter() - t0
            self.done.set()


class SurfaceWorker:
    """Builds one frame's deferred views at a time, on a daemon thread (``threaded=True``) or in the calling thread.

    Attributes:
        build_seconds: wall time spent building deferred views so far [s] (in either thread).
    """

    def __init__(self, *, threaded: bool = True):
        self.threaded = bool(threaded)
        self._frame: _Frame | None = None
        self.build_seconds = 0.0

    @property
    def pending(self) -> int | None:
        """The frame whose views are in flight, or None."""
        return None if self._frame is None else self._frame.frame

    def submit(self, frame: int, views: list, payload=None) -> None:
        """Starts building ``views`` (the frame's views, some of them DeferredViews) of frame ``frame``; ``payload``
        comes back with them from :meth:`wait`. The previous frame must have been collected by :meth:`wait`.

        Raises:
            RuntimeError: a frame is still in flight.
        """
        if self._frame is not None:
            raise RuntimeError(f"frame {self._frame.frame}'s views are still in flight; wait() for them first")
        job = _Frame(frame, views, payload)
        self._frame = job
        if self.threaded and any(isinstance(v, DeferredView) for v in views):
            job.thread.start()
        else:
            job._build(views)

    def wait(self, timeout: float | None = None):
        """The frame in flight, built: (frame, views, payload); None when none is in flight or when it is not done
        within ``timeout`` [s] (None: wait as long as it takes; it then stays in flight).

        Raises:
            the error its build raised, with a note naming the frame.
        """
        job = self._frame
        if job is None or not job.done.wait(timeout):
            return None
        self._frame = None
        self.build_seconds += job.seconds
        if job.error is not None:
            job.error.add_note(f"(raised while building the views of frame {job.frame} on the run's surface thread)")
            raise job.error
        return job.frame, job.views, job.payload

    def abandon(self) -> None:
        """Forgets the frame in flight (its thread finishes on its own; nothing of it is written)."""
        self._frame = None
