"""Checkpoints of a run and what resuming needs: the checkpoint file and stop requests from signals.

A run (``Scene.run``, ``pdsim run``) writes ``<stem>.checkpoint.npz`` beside its cache at frame ends (every
``checkpoint_interval_s`` seconds of wall time, or every frame with 0) and when a stop is requested (SIGTERM, Ctrl-C):
every solver's ``checkpoint()`` (pdsim/solver.py: displacements, velocities, accelerations, bond flags, plastic
state, contact scales, FEM topology after splits, lattice state), the watchdog's energy accounting, the projectiles'
last poses, the frame and sub-step reached, the cache's run id and what the USD writer needs to continue the same
prims (pdsim.output.writer.ViewWriter.checkpoint), and a fingerprint of the scene. The file is written to a temporary
name and renamed (atomic): a kill leaves the previous checkpoint or the new one, never half of one. A run that
finishes removes it.

``Scene.run(..., resume=True)`` (``pdsim run --resume``) rebuilds the scene, checks the fingerprint, restores the
state and continues in the same cache: pdsim.output.usd.UsdCache reopens it at the checkpoint's frame (dropping any
frames written after it) and the writer re-attaches to its prims. On the CPU the frames it writes are bit for bit those
of an uninterrupted run (the same float32 operations in the same order), so the cache plays as one uninterrupted run's.
docs/stability.md describes the files.
"""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import numpy as np

from .errors import ParameterError

CHECKPOINT_FORMAT = 2  # 2: the cache's run id and the writer's state (resumed runs append to the same cache)
_META = "__meta__"


def checkpoint_path(out) -> Path:
    """``<stem>.checkpoint.npz`` beside the cache ``out``."""
    out = Path(out)
    return out.with_name(f"{out.stem}.checkpoint.npz")


# -- the file -------------------------------------------------------------------------------------------------------
def _flatten(tree: dict, prefix: str, arrays: dict, meta: dict) -> None:
    for key, value in tree.items():
        if not isinstance(key, str) or "/" in key or not key:
            raise ValueError(f"checkpoint key {key!r} must be a non-empty string without '/'")
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            meta[name] = {"dict": True}
            _flatten(value, f"{name}/", arrays, meta)
        elif isinstance(value, np.ndarray):
            arrays[name] = value
        elif value is None or isinstance(value, bool | int | float | str):
            meta[name] = {"value": value}
        elif isinstance(value, np.generic):
            meta[name] = {"value": value.item()}
        elif isinstance(value, list | tuple) and all(
            v is None or isinstance(v, bool | int | float | str | list) for v in value
        ):
            meta[name] = {"value": list(value)}
        else:
            raise ValueError(f"checkpoint value {name!r} of type {type(value).__name__} is not storable")


def save_checkpoint(path, state: dict) -> Path:
    """Writes the nested dict ``state`` (numpy arrays, plain scalars, lists of scalars, dicts) to the .npz ``path``
    atomically (a temporary file beside it, then ``os.replace``). Arrays are stored bit for bit, scalars as JSON
    (floats round-trip exactly)."""
    path = Path(path)
    arrays: dict = {}
    meta: dict = {}
    _flatten(state, "", arrays, meta)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with open(tmp, "wb") as f:
            np.savez(f, **{f"a/{k}": v for k, v in arrays.items()}, **{_META: np.array(json.dumps(meta))})
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if tmp.exists():
            tmp.unlink()
        raise
    return path


def load_checkpoint(path) -> dict:
    """The nested dict :func:`save_checkpoint` wrote; ParameterError when the file is missing or unreadable."""
    path = Path(path)
    if not path.is_file():
        raise ParameterError(
            "resume", str(path), "a checkpoint written by an earlier run of this scene with this --out (none found)"
        )
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data[_META]))
            arrays = {k[2:]: np.array(data[k]) for k in data.files if k.startswith("a/")}
    except (OSError, ValueError, KeyError) as exc:
        raise ParameterError("resume", str(path), f"a readable pdsim checkpoint ({exc})") from None
    root: dict = {}

    def node(name: str) -> dict:
        d = root
        for part in name.split("/")[:-1]:
            d = d.setdefault(part, {})
        return d

    for name in sorted(meta, key=lambda n: n.count("/")):
        entry = meta[name]
        if entry.get("dict"):
            node(name).setdefault(name.rsplit("/", 1)[-1], {})
        else:
            node(name)[name.rsplit("/", 1)[-1]] = entry["value"]
    for name, value in arrays.items():
        node(name)[name.rsplit("/", 1)[-1]] = value
    return root


# -- stop requests ---------------------------------------------------------------------------------------------------
class RunInterrupted(KeyboardInterrupt):
    """A run stopped on request (SIGTERM, SIGINT) at a step boundary, after writing a checkpoint when checkpoints are
    on. Attributes: ``signal`` (number or None), ``cache`` (path of the cache holding the finished frames),
    ``last_frame`` (the last finished frame, -1 when none), ``checkpoint`` (path or None)."""

    def __init__(self, signum=None, *, cache=None, last_frame: int = -1, checkpoint=None):
        super().__init__(signum)
        self.signal = signum
        self.cache = cache
        self.last_frame = last_frame
        self.checkpoint = checkpoint


class StopRequest:
    """A flag the frame loop polls between chunks of steps (``Scene.run(..., stop=...)``): :meth:`install` makes
    SIGTERM and SIGINT set it (the first time; a second signal raises KeyboardInterrupt at once), :meth:`request` sets
    it by hand. ``signal`` is the number of the signal that set it (None: not requested)."""

    def __init__(self):
        self.signal = None
        self._previous = {}

    @property
    def requested(self) -> bool:
        return self.signal is not None

    def request(self, signum=signal.SIGTERM) -> None:
        self.signal = signum

    def _handler(self, signum, frame):
        if self.signal is not None:  # a second signal: stop now
            raise RunInterrupted(signum)
        self.signal = signum

    def install(self, signals=(signal.SIGINT, signal.SIGTERM)) -> StopRequest:
        """Installs the handlers (main thread only); :meth:`uninstall` puts the previous ones back."""
        for s in signals:
            self._previous[s] = signal.signal(s, self._handler)
        return self

    def uninstall(self) -> None:
        for s, h in self._previous.items():
            signal.signal(s, h)
        self._previous.clear()


def signal_exit_code(signum) -> int:
    """The shell's exit status for a process stopped by ``signum``: 128 + the number (130 SIGINT, 143 SIGTERM)."""
    return 128 + int(signum if signum is not None else signal.SIGINT)


__all__ = [
    "CHECKPOINT_FORMAT",
    "RunInterrupted",
    "StopRequest",
    "checkpoint_path",
    "load_checkpoint",
    "save_checkpoint",
    "signal_exit_code",
]
