"""Checkpoints of a run and what resuming needs: the checkpoint file and stop requests from signals.

A run (``Scene.run``, ``pdsim run``) writes ``<stem>.checkpoint.npz`` beside its cache at frame ends (every
``checkpoint_interval_s`` seconds of wall time, or every frame with 0) and when a stop is requested (SIGTERM, Ctrl-C):
every solver's ``checkpoint()`` (pdsim/solver.py: displacements, velocities, accelerations, bond flags, plastic
state, contact scales, FEM topology after splits, lattice state), the watchdog's energy accounting, the projectiles'
last poses, the frame and sub-step reached, the cache's run id and what the USD writer needs to continue the same
prims (pdsim.output.writer.ViewWriter.checkpoint), and a fingerprint of the scene. The file is written to a temporary
name and renamed (atomic): a kill leaves the previous checkpoint or the new one, never half of one. It is written in
chunks, and a stop request that has waited longer than the run's stop budget abandons it (the temporary file is
removed, the previous checkpoint stays), so that SIGTERM stops a large run within seconds. A run that finishes
removes it; a run starting on the same output removes the temporary files a killed run left.

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
import time
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


CHUNK_BYTES = 4 << 20  # a checkpoint is written in chunks of this size [B]; a stop request is checked between them


class CheckpointAbandoned(Exception):
    """A checkpoint write given up on request (``save_checkpoint(..., abandon=...)``); its temporary file is removed
    and the previous checkpoint, if any, stays."""


class _ChunkedFile:
    """A binary file that writes in chunks of CHUNK_BYTES and raises CheckpointAbandoned before a chunk when
    ``abandon()`` is true."""

    def __init__(self, f, abandon):
        self._f, self._abandon = f, abandon

    def write(self, data) -> int:
        view = memoryview(data).cast("B")
        for i in range(0, len(view), CHUNK_BYTES):
            if self._abandon is not None and self._abandon():
                raise CheckpointAbandoned("checkpoint write abandoned on a stop request")
            self.write_chunk(view[i : i + CHUNK_BYTES])
        return len(view)

    def write_chunk(self, chunk) -> None:
        self._f.write(chunk)

    def read(self, *args) -> bytes:  # numpy takes an object with read() for a file object
        return self._f.read(*args)

    def tell(self) -> int:
        return self._f.tell()

    def seek(self, *args) -> int:
        return self._f.seek(*args)

    def flush(self) -> None:
        self._f.flush()


def temporary_path(path) -> Path:
    """The temporary file a checkpoint at ``path`` is written to before it is renamed (``.<name>.tmp``)."""
    path = Path(path)
    return path.with_name(f".{path.name}.tmp")


def save_checkpoint(path, state: dict, abandon=None) -> Path:
    """Writes the nested dict ``state`` (numpy arrays, plain scalars, lists of scalars, dicts) to the .npz ``path``
    atomically (a temporary file beside it, then ``os.replace``). Arrays are stored bit for bit, scalars as JSON
    (floats round-trip exactly). ``abandon`` (a callable or None) is asked before each chunk of CHUNK_BYTES: when it
    returns true the write stops, the temporary file is removed and CheckpointAbandoned is raised; so is any error
    (the previous checkpoint at ``path`` stays)."""
    path = Path(path)
    arrays: dict = {}
    meta: dict = {}
    _flatten(state, "", arrays, meta)
    tmp = temporary_path(path)
    try:
        with open(tmp, "wb") as f:
            out = _ChunkedFile(f, abandon)
            np.savez(out, **{f"a/{k}": v for k, v in arrays.items()}, **{_META: np.array(json.dumps(meta))})
            if abandon is not None and abandon():
                raise CheckpointAbandoned("checkpoint write abandoned on a stop request")
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        if tmp.exists():
            tmp.unlink()
        if isinstance(exc, OSError) and exc.filename is None:  # a failed write (disk full): name the file
            raise OSError(exc.errno, exc.strerror or str(exc), str(tmp)) from exc
        raise
    return path


def remove_stale_temporaries(out) -> list[Path]:
    """Removes the temporary files a killed run left beside the cache ``out`` (its checkpoint's ``.tmp``, the
    top-level and partial layers' ``.tmp`` exports, those in the frame folders); returns them. Called by a run on
    ``out`` before it writes anything."""
    out = Path(out)
    stem, suffix = out.stem, out.suffix
    found = [temporary_path(checkpoint_path(out))]
    found += [out.with_name(f".{name}.tmp{suffix}") for name in (out.name, f"{stem}.partial{suffix}")]
    frames = out.with_name(f"{stem}.frames")
    if frames.is_dir():
        found += [p for p in frames.glob("*/.*.tmp.usd*") if p.is_file()]
    removed = []
    for p in found:
        if p.is_file():
            p.unlink()
            removed.append(p)
    return removed


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
        self.time = None  # time.monotonic() [s] of the request
        self._previous = {}

    @property
    def requested(self) -> bool:
        return self.signal is not None

    def request(self, signum=signal.SIGTERM) -> None:
        self.signal = signum
        self.time = time.monotonic()

    def overdue(self, budget_s: float) -> bool:
        """True when a stop was requested more than ``budget_s`` seconds ago (a checkpoint still being written then
        is abandoned, so that the run stops in time)."""
        return self.time is not None and time.monotonic() - self.time > budget_s

    def _handler(self, signum, frame):
        if self.signal is not None:  # a second signal: stop now
            raise RunInterrupted(signum)
        self.request(signum)

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
    "CheckpointAbandoned",
    "RunInterrupted",
    "StopRequest",
    "checkpoint_path",
    "load_checkpoint",
    "remove_stale_temporaries",
    "save_checkpoint",
    "signal_exit_code",
]
