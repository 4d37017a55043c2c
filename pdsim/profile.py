"""Wall time of a run's phases: what ``pdsim run --profile`` and ``Scene.run(profile=True)`` print at the end and
write into the run report (``<stem>.report.json`` beside the cache).

A :class:`RunProfile` sums ``time.perf_counter`` intervals [s] of the main thread into these phases:

- ``build``: the scene script's ``build_scene`` (when the command line times it), the solvers, the time step, the
  watchdogs, opening the cache and its writer;
- ``simulate``: the frames' steps, less the watchdog checks made inside them;
- ``surfaces``: gathering each frame's views: device reads, fragment labels and the render-surface rebuilds (with the
  surfaces built on a worker thread: the time the main thread waits for them);
- ``write``: the USD writer, the frame layers and the top-level layer, checkpoints, packing the cache at the end;
- ``checks``: the pre-flight and the watchdogs' checks (their reductions and host reads);
- ``other``: the rest of the run's wall time (argument checks, resume, the progress bar).

On the CPU backend every launch is synchronous, so each phase holds its own work. On CUDA, launches are
asynchronous: the run waits for the device at the end of each frame's steps and before each watchdog check starts its
clock (pdsim.device.wait_for; the views and the check read the device right after, so the waits cost nothing), so
that simulate holds the steps' device time. Time a worker thread spends on the run's behalf is kept apart
(:meth:`add_worker`): it overlaps the main thread's phases and is not part of the shares.
"""

from __future__ import annotations

import contextlib
import json
import os
import time

PHASES = ("build", "simulate", "surfaces", "write", "checks", "other")


class RunProfile:
    """Seconds [s] per phase of one run (see the module); :meth:`phase` times a block, :meth:`finish` closes it."""

    def __init__(self):
        self.started = self._mark = time.perf_counter()
        self.seconds = dict.fromkeys(PHASES[:-1], 0.0)
        self.worker_seconds: dict[str, float] = {}
        self.wall_seconds: float | None = None
        self.frames = 0
        self._nested: list[float] = []  # per open phase, the time of the phases timed inside it [s]

    def lap(self, name: str | None = None) -> None:
        """Adds the wall time since the previous lap (or the start) to phase ``name`` (None: to none of them, left to
        ``other``) and starts the next lap: a run's consecutive stretches timed with one line each."""
        now = time.perf_counter()
        if name is not None:
            self.seconds[name] += now - self._mark
        self._mark = now

    @contextlib.contextmanager
    def phase(self, name: str):
        """Adds the wall time of the ``with`` block to phase ``name``, less the time of phases timed inside it (a
        checkpoint, timed as write, first finishes the frame in flight, whose surfaces and write are timed as such):
        each second counts in one phase."""
        t0 = time.perf_counter()
        self._nested.append(0.0)
        try:
            yield
        finally:
            elapsed = time.perf_counter() - t0
            self.seconds[name] += elapsed - self._nested.pop()
            if self._nested:
                self._nested[-1] += elapsed

    def move(self, source: str, target: str, seconds: float) -> None:
        """Moves ``seconds`` [s] timed inside phase ``source`` to phase ``target`` (a nested phase timed elsewhere:
        the watchdog checks inside the steps)."""
        self.seconds[source] -= seconds
        self.seconds[target] += seconds

    def add_worker(self, name: str, seconds: float) -> None:
        """Adds ``seconds`` [s] that a worker thread spent on ``name`` (e.g. "surfaces") beside the main thread."""
        self.worker_seconds[name] = self.worker_seconds.get(name, 0.0) + float(seconds)

    def finish(self, frames: int) -> float:
        """Closes the profile of a run that simulated ``frames`` frames; returns its wall time [s]."""
        self.wall_seconds = time.perf_counter() - self.started
        self.frames = int(frames)
        return self.wall_seconds

    def phases(self) -> dict[str, float]:
        """Seconds [s] of every phase of PHASES, ``other`` being the wall time the others leave (at least 0)."""
        wall = self.wall_seconds if self.wall_seconds is not None else time.perf_counter() - self.started
        out = dict(self.seconds)
        out["other"] = max(wall - sum(out.values()), 0.0)
        return out

    def as_dict(self) -> dict:
        """Plain JSON values: wall_seconds, frames, seconds and share (of the wall time) per phase, worker_seconds."""
        phases = self.phases()
        wall = self.wall_seconds if self.wall_seconds is not None else sum(phases.values())
        return {
            "wall_seconds": wall,
            "frames": self.frames,
            "seconds": phases,
            "share": {k: (v / wall if wall > 0.0 else 0.0) for k, v in phases.items()},
            "worker_seconds": dict(self.worker_seconds),
        }

    def table(self) -> str:
        """The phases as lines of text: seconds, share of the wall time, seconds per frame."""
        d = self.as_dict()
        frames = max(d["frames"], 1)
        lines = [f"pdsim: profile: {d['wall_seconds']:.2f} s wall, {d['frames']} frames"]
        for k in PHASES:
            s = d["seconds"][k]
            lines.append(f"  {k:<9} {s:9.2f} s  {d['share'][k]:6.1%}  {1000.0 * s / frames:9.1f} ms/frame")
        for k, s in d["worker_seconds"].items():
            lines.append(f"  {k:<9} {s:9.2f} s  on a worker thread, beside the phases above")
        return "\n".join(lines)


def report_path(out) -> str:
    """The run report's path for cache ``out``: ``<stem>.report.json`` beside it."""
    out = os.fspath(out)
    return os.path.splitext(out)[0] + ".report.json"


def write_report(path, report: dict) -> None:
    """Writes the run report ``report`` (plain JSON values) to ``path`` (through a temporary file, then renamed)."""
    tmp = f"{os.fspath(path)}.tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(report, f, indent=1)
        f.write("\n")
    os.replace(tmp, path)
