"""CPU threads of the peridynamic bond passes: how many (``resolve_threads``) and the contiguous particle ranges a
pass is split into, one launch per range run at once (``ParticleRanges``)."""

from __future__ import annotations

import itertools
import os
import threading

import numpy as np
import warp as wp

from ..errors import ParameterError
from ..kernels.launch import launch_wrapped
from ..kernels.peridynamics import step as pd_step

THREADS_ENV = "PDSIM_THREADS"
"""Environment variable: CPU threads of the peridynamic bond passes when a solver is built without ``threads``."""

MIN_BONDS_PER_THREAD = 50_000
"""The default thread count gives each thread at least this many bonds: starting and joining a pass on a pool thread
costs some 50 us, about what one thread spends on 5,000 bonds in one pass."""

MIN_POINTS_PER_THREAD = 10_000
"""The kick and drift (a few nanoseconds per point: 557 us for 64,000 points in one launch) run on the bond passes'
ranges only when each range holds at least this many points on average: handing a launch to a pool thread and joining
it costs some 40 us (one launch over 1,000 points: 14 us; over two ranges: 53 us; tools/bench_kick_ranges.py), so the
split pays from about 5,000 points per range; twice that leaves a margin on a loaded machine."""

RANGE_PARTICLE_COST = 4
"""Cost of a particle's own work (reads, the per-particle arithmetic, its writes) in bond visits, added to its bond
count when the particles are split into ranges of equal cost."""


def available_cores() -> int:
    """CPU cores this process may run on (its affinity mask where the platform has one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def resolve_threads(threads, device, bond_count: int = 0) -> int:
    """The thread count of the bond passes: ``threads`` (an integer >= 1), else the environment variable
    PDSIM_THREADS, else every core in the process's affinity but no more than one per MIN_BONDS_PER_THREAD bonds;
    1 on a CUDA device (where ``threads`` must be None or 1: the GPU runs each pass as one launch)."""
    if threads is not None:
        if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1:
            raise ParameterError("threads", threads, "None or an integer >= 1 (CPU threads of the bond passes)")
        threads = int(threads)
        if device.is_cuda and threads != 1:
            raise ParameterError(
                "threads", threads, f"None or 1 on the CUDA device {device} (each bond pass is one GPU launch)"
            )
        return threads
    if device.is_cuda:
        return 1
    env = os.environ.get(THREADS_ENV, "").strip()
    if env:
        try:
            value = int(env)
        except ValueError:
            value = 0
        if value < 1:
            raise ParameterError(THREADS_ENV, env, "an integer >= 1 (CPU threads of the peridynamic bond passes)")
        return value
    return max(1, min(available_cores(), int(bond_count) // MIN_BONDS_PER_THREAD))


def equal_cost_bounds(offsets_host: np.ndarray, count: int) -> list[int]:
    """Bounds 0 = b_0 < b_1 < ... < b_m = n of at most ``count`` contiguous ranges of the n particles whose costs
    (the bond count from the prefix sums ``offsets_host``, plus RANGE_PARTICLE_COST per particle) are about equal;
    each range holds at least one particle (one range for n = 0)."""
    n = len(offsets_host) - 1
    count = max(1, min(int(count), n))
    cost = offsets_host.astype(np.int64) + RANGE_PARTICLE_COST * np.arange(n + 1, dtype=np.int64)
    targets = cost[-1] * np.arange(1, count) / count
    above = np.clip(np.searchsorted(cost, targets), 1, n)  # the first cut at or past each target, or the one
    cuts = np.where(targets - cost[above - 1] < cost[above] - targets, above - 1, above).tolist()  # nearer
    for i in range(len(cuts)):  # one per range (a handful): each range keeps at least one particle
        cuts[i] = min(max(cuts[i], cuts[i - 1] + 1 if i else 1), n - (count - 1 - i))
    return [0, *cuts, n]


class _Worker:
    """A thread that runs one callable per hand-off: started by releasing one lock, joined by acquiring another (two
    lock operations each way, the cheapest hand-off in CPython; a ThreadPoolExecutor's future, queue and condition
    cost more per pass: tools/bench_kick_ranges.py, docs/benchmarks.md)."""

    def __init__(self):
        self._start = threading.Lock()
        self._start.acquire()
        self._done = threading.Lock()
        self._done.acquire()
        self._task = None
        self._error: BaseException | None = None
        threading.Thread(target=self._loop, name="pdsim-pd", daemon=True).start()

    def submit(self, task) -> None:
        self._task = task
        self._start.release()

    def join(self) -> BaseException | None:
        """Waits for the task submitted last; returns what it raised, or None."""
        self._done.acquire()
        error, self._error = self._error, None
        return error

    def _loop(self) -> None:
        while True:
            self._start.acquire()
            try:
                self._task()
            except BaseException as exc:  # noqa: BLE001 - handed to the thread that joins, raised there
                self._error = exc
            finally:
                self._task = None
                self._done.release()


class _Workers:
    """The process's pool threads of the range launches: ``run(first, others)`` runs ``first`` on the calling thread
    and each of ``others`` on a worker thread, and returns when all are done (raising what one of them raised); one
    caller at a time."""

    def __init__(self, count: int):
        self._busy = threading.Lock()
        self._workers = [_Worker() for _ in range(count)]

    def run(self, first, others: list) -> None:
        with self._busy:
            workers = self._workers[: len(others)]
            for worker, task in zip(workers, others):
                worker.submit(task)
            try:
                first()
            finally:  # every range has finished before this returns or raises (they write the same arrays)
                errors = [worker.join() for worker in workers]
            for error in errors:
                if error is not None:
                    raise error


_pools: dict[tuple[int, int], _Workers] = {}
_pools_lock = threading.Lock()


def _executor(workers: int) -> _Workers:
    """The process's ``workers`` pool threads for range launches (shared by solvers, created on first use; a process
    forked from one that had a pool gets its own, as the parent's threads do not exist in it)."""
    key = (os.getpid(), workers)
    with _pools_lock:
        pool = _pools.get(key)
        if pool is None:
            pool = _pools[key] = _Workers(workers)
        return pool


class ParticleRanges:
    """Contiguous particle ranges of about equal cost (bond count plus RANGE_PARTICLE_COST per particle), one per
    thread, and the launch of one pass over them.

    Each step kernel takes the first particle of its launch and writes only its own particles' rows and their bonds'
    rows (the families are stored per particle; the mirror of the plastic extensions writes one slot per bond, at its
    reverse bond, that only the next pass reads: kernels/peridynamics/step.py), and a pass reads only what earlier
    passes wrote, so the ranges of one pass are independent: ``launch`` starts one Warp launch per range, the calling
    thread running the first while pool threads run the others (a CPU kernel runs with the GIL released), and returns
    when all are done. A particle's arithmetic does not depend on its range, so results are bit-identical for any
    thread count. On a CUDA device there is one range: one launch over all particles. ``bounds`` gives the ranges
    explicitly (the pair passes' thread spans, pdsim/peridynamics/pairs.py) instead of equal cost over ``threads``.

    Warp (1.19) passes each launch's thread index as an argument of the generated CPU function and builds each
    launch's argument block afresh, so concurrent CPU launches are safe; what is not safe is loading a module from
    several threads at once, so the kernels' modules are loaded from the calling thread before the first threaded launch
    (``_load``). While the device records a graph
    (``wp.ScopedCapture``, pdsim/capture.py) the ranges are launched one after another from the calling thread,
    which is the only thread a capture records; a CPU replay then runs them on one thread."""

    def __init__(self, offsets_host: np.ndarray, threads: int, device, bounds: list[int] | None = None):
        n = len(offsets_host) - 1
        self.device = device
        self.particle_count = n
        if bounds is None:
            bounds = equal_cost_bounds(offsets_host, threads)
        self.ranges = [(int(a), int(b - a)) for a, b in itertools.pairwise(bounds)]
        self._loaded = set()
        self._commands = {}  # kernel key -> (inputs key, recorded launches, inputs)

    def point_launch(self):
        """:meth:`launch` where the ranges average MIN_POINTS_PER_THREAD particles or more (the shared kinematics'
        kick and drift split over them), else None (one launch each)."""
        count = len(self.ranges)
        return self.launch if count > 1 and self.particle_count >= MIN_POINTS_PER_THREAD * count else None

    def _load(self, kernel) -> None:
        module = kernel.module
        if id(module) not in self._loaded:
            wp.load_module(module, device=self.device)
            self._loaded.add(id(module))

    def launch(self, kernel, inputs: list) -> None:
        """``kernel`` over every particle: one launch per range with inputs ``[first, *inputs]``, joined."""
        device = self.device
        if device.is_cuda or device.is_capturing or launch_wrapped():
            # one launch on a GPU; in order from this thread while a graph is recorded; through wp.launch while a
            # tool records or times launches by wrapping it (pdsim/explain.py, tools/bench_pd_throughput.py)
            for first, count in self.ranges:
                if count:
                    pd_step.launch_range(kernel, first, count, inputs, device)
            return
        launches = self._recorded(kernel, inputs)
        if len(launches) <= 1:
            for cmd in launches:
                cmd.launch()
            return
        _executor(len(launches) - 1).run(launches[0].launch, [cmd.launch for cmd in launches[1:]])

    def _recorded(self, kernel, inputs: list) -> list:
        """The recorded launches (``wp.launch(..., record_cmd=True)``) of ``kernel`` over the ranges with ``inputs``,
        kept while the inputs are the same arrays and values: replaying one costs a few microseconds of Python,
        where ``wp.launch`` checks and packs every argument again, and the pool threads take turns on the GIL for
        that Python part. The entry keeps the inputs alive, so an array's id cannot be reused while it is cached."""
        key = tuple(id(x) if isinstance(x, wp.array) else x for x in inputs)
        entry = self._commands.get(kernel.key)
        if entry is None or entry[0] != key:
            self._load(kernel)
            cmds = [
                pd_step.launch_range(kernel, first, count, inputs, self.device, record_cmd=True)
                for first, count in self.ranges
                if count
            ]
            entry = (key, cmds, list(inputs))
            self._commands[kernel.key] = entry
        return entry[1]
