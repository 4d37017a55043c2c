"""The run's surface thread (pdsim/frame_worker.py): frame N's render surfaces build on a thread while frame N + 1
simulates, and the cache is the one the main thread alone writes, bit for bit (and the one written without clip
reuse); errors of the thread are raised in the main thread; a stop while a slow surface build is in flight still
stops at once."""

from __future__ import annotations

import threading
import time

import pytest
from test_resume_cache import _assert_same_cache, _pd_bar, _StopAt

from pdsim.checkpoint import RunInterrupted
from pdsim.fragment_surfaces import FragmentSurfaces
from pdsim.frame_worker import SurfaceWorker
from pdsim.output.views import DeferredView, MeshView


@pytest.fixture(scope="module")
def threaded_cache(tmp_path_factory):
    """The cache of a breaking bar (surface topology changes at frames 1, 2, 3 and 7) as a run writes it by default:
    surface thread on, clip reuse on."""
    out = tmp_path_factory.mktemp("threaded") / "threaded.usdc"
    _pd_bar().run(out, device="cpu", progress=False, checkpoint_interval_s=None)
    return out


def test_threaded_cache_equals_the_main_thread_cache(tmp_path, threaded_cache):
    """The breaking bar written with the surface thread equals, at every time code and attribute, bit for bit, the
    cache written with every surface built in the main thread."""
    inline = tmp_path / "inline.usdc"
    _pd_bar().run(inline, device="cpu", progress=False, checkpoint_interval_s=None, surface_thread=False)
    _assert_same_cache(inline, threaded_cache, 8)


def test_cache_with_clip_reuse_equals_the_cache_without(tmp_path, monkeypatch, threaded_cache):
    """The breaking bar's cache with clip reuse (pdsim/fragment_surfaces/booleans.py) equals, attribute by attribute
    and frame by frame, the cache with every region clipped again on every rebuild."""
    real = FragmentSurfaces.__init__

    def no_reuse(self, *args, **kwargs):
        real(self, *args, **{**kwargs, "reuse": False})

    monkeypatch.setattr(FragmentSurfaces, "__init__", no_reuse)
    without = tmp_path / "no_reuse.usdc"
    _pd_bar().run(without, device="cpu", progress=False, checkpoint_interval_s=None)
    _assert_same_cache(without, threaded_cache, 8)


def test_surfaces_build_on_the_worker_thread_while_the_caller_goes_on():
    """A deferred view runs on the worker's thread; submit returns before it is built; wait hands back the views in
    order with the payload."""
    started, release = threading.Event(), threading.Event()
    seen = {}

    def build():
        seen["thread"] = threading.current_thread().name
        started.set()
        release.wait(5.0)
        return "built"

    worker = SurfaceWorker()
    worker.submit(3, ["points", DeferredView("a_surface", build)], payload=0.5)
    assert started.wait(5.0) and worker.pending == 3
    assert worker.wait(timeout=0.01) is None  # not done yet: still in flight
    release.set()
    assert worker.wait() == (3, ["points", "built"], 0.5)
    assert seen["thread"] == "pdsim-surfaces-3" and seen["thread"] != threading.current_thread().name
    assert worker.pending is None


def test_an_error_in_the_surface_thread_is_raised_in_the_main_thread(tmp_path, monkeypatch):
    """A render-surface build that fails on the thread fails the run in the main thread with its own error and a note
    naming the frame."""

    def broken(self, positions, velocities=None):
        raise RuntimeError("region 3 of 'bar' is not a manifold")

    monkeypatch.setattr(FragmentSurfaces, "view", broken)
    with pytest.raises(RuntimeError, match="not a manifold") as ei:
        _pd_bar(frames=3).run(tmp_path / "x.usdc", device="cpu", progress=False, checkpoint_interval_s=None)
    assert any("frame 0" in note and "surface thread" in note for note in ei.value.__notes__)


def test_a_stop_during_a_slow_surface_build_stops_at_once(tmp_path, monkeypatch):
    """A stop request while the surfaces of the frame before take 20 s: the run stops within the checkpoint budget
    (0.8 s), keeps no checkpoint of a frame it could not write, and the cache ends at the last frame written."""
    real = FragmentSurfaces.view
    release = threading.Event()

    def slow(self, positions, velocities=None):
        if threading.current_thread() is not threading.main_thread() and slow.calls >= 3:
            release.wait(20.0)
        slow.calls += 1
        return real(self, positions, velocities)

    slow.calls = 0
    monkeypatch.setattr(FragmentSurfaces, "view", slow)

    class _StopNow(_StopAt):
        def overdue(self, seconds):
            return time.monotonic() - self.armed > seconds

        @property
        def requested(self):
            asked = super().requested
            if asked and not hasattr(self, "armed"):
                self.armed = time.monotonic()
            return asked

    stop = _StopNow(3, 1)
    t0 = time.monotonic()
    with pytest.raises(RunInterrupted) as ei:
        _pd_bar().run(tmp_path / "x.usdc", device="cpu", progress=False, stop=stop, on_frame=stop.on_frame)
    assert time.monotonic() - stop.armed < 2.0 and time.monotonic() - t0 < 15.0
    assert ei.value.checkpoint is None  # frame 3's surfaces were still building: no checkpoint could be written
    assert ei.value.last_frame == 2
    release.set()  # the abandoned build finishes (nothing of it is written)


def test_mesh_view_is_snapshotted():
    """copied_view copies the arrays of a view, so the writer sees the values of when the view was taken."""
    import numpy as np

    from pdsim.output.views import copied_view

    pts = np.zeros((3, 3))
    view = MeshView("s", pts, None, 1, np.array([[0, 1, 2]]), {"crack": np.zeros(1, np.int32)})
    frozen = copied_view(view)
    pts += 1.0
    view.face_attributes["crack"][0] = 1
    assert frozen.points.max() == 0.0 and frozen.face_attributes["crack"][0] == 0
