"""The streamed cache writer: bounded memory (peak RSS independent of the frame count), crash safety under kill -9
(every finished frame but at most one is readable), and re-runs that fail leave the earlier cache at the same path
intact. Children run in subprocesses so that their memory and their death are their own."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import pdsim
from pdsim.output.usd_files import usd_problems, world_points

ROOT = Path(__file__).resolve().parents[1]

# a synthetic writer loop: N points, FRAMES frames written through the ViewWriter, printing "done <frame>" after each
# finished frame and, at the end, the peak resident set size [kB] of the process
WRITER = textwrap.dedent(
    """
    import resource, sys, time
    import numpy as np
    from pdsim.output.usd import UsdCache
    from pdsim.output.views import PointsView
    from pdsim.output.writer import ViewWriter

    n, frames, out, pause = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], float(sys.argv[4])

    base = np.random.default_rng(0).random((n, 3))

    def positions(frame):
        return base + frame

    widths = np.full(n, 0.01)
    with UsdCache(out, fps=24.0) as cache:
        writer = ViewWriter(cache)
        for f in range(frames):
            x = positions(f)
            writer.write(f, [PointsView("cloud", x, np.full((n, 3), f, float), widths, {"damage": np.full(n, f)})])
            cache.end_frame(f, time=f / 24.0)
            print("done", f, flush=True)
            if pause:
                time.sleep(pause)
    print("maxrss", resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, flush=True)
    """
)


def _writer(tmp_path, *args, **kwargs):
    script = tmp_path / "writer.py"
    script.write_text(WRITER)
    return subprocess.Popen(
        [sys.executable, str(script), *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        **kwargs,
    )


def _peak_rss_mb(tmp_path, frames: int) -> float:
    proc = _writer(tmp_path, 20_000, frames, tmp_path / f"rss{frames}.usdc", 0)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    line = next(ln for ln in out.splitlines() if ln.startswith("maxrss"))
    return int(line.split()[1]) / 1024.0


def test_memory_does_not_grow_with_frames(tmp_path):
    """Peak RSS of a process writing 20k points (positions, velocities, one primvar) for 500 frames exceeds that of
    50 frames by less than 50 MB (measured: about 1-2 MB, against 160 KB x 450 frames = 72 MB of extra samples that
    an in-memory stage would hold); the 500-frame cache plays its last frame."""
    from pxr import Usd

    rss50 = _peak_rss_mb(tmp_path, 50)
    rss500 = _peak_rss_mb(tmp_path, 500)
    print(f"\npeak RSS: 50 frames {rss50:.1f} MB, 500 frames {rss500:.1f} MB")
    assert rss500 - rss50 < 50.0
    stage = Usd.Stage.Open(str(tmp_path / "rss500.usdc"))
    assert stage.GetEndTimeCode() == 499
    x = world_points(stage.GetPrimAtPath("/World/cloud"), 499)
    np.testing.assert_allclose(x, np.random.default_rng(0).random((20_000, 3)) + 499, atol=1e-6)


@pytest.mark.parametrize("kill_after", [3, 17])
def test_kill_9_leaves_every_finished_frame(tmp_path, kill_after):
    """A writer process killed with SIGKILL while writing (no pause between frames, so the kill lands inside a frame's
    writing most of the time) leaves a cache that opens with every frame it reported finished: endTimeCode >= the
    last reported frame (frames finished after the report may be there too), and every frame 0..end holds exactly
    the data written for it; it passes UsdValidation."""
    from pxr import Usd

    out = tmp_path / "killed.usdc"
    proc = _writer(tmp_path, 2_000, 100_000, out, 0)
    last = -1
    for line in proc.stdout:
        if line.startswith("done"):
            last = int(line.split()[1])
            if last >= kill_after:
                os.kill(proc.pid, signal.SIGKILL)
                break
    proc.wait(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    stage = Usd.Stage.Open(str(out))
    end = int(stage.GetEndTimeCode())
    assert end >= last
    prim = stage.GetPrimAtPath("/World/cloud")
    assert prim.GetAttribute("points").GetTimeSamples() == [float(f) for f in range(end + 1)]
    for f in range(end + 1):
        np.testing.assert_allclose(
            world_points(prim, f), np.random.default_rng(0).random((2_000, 3)) + f, atol=1e-6, err_msg=f"frame {f}"
        )  # float32 points relative to the cloud's centre: steps of 6e-8 m over its 1 m
    assert stage.GetPrimAtPath("/World").GetAttribute("pdsim:time").Get(end) == pytest.approx(end / 24.0)
    del stage
    assert usd_problems(out) == []


def _scene(speed: float):
    scene = pdsim.Scene(fps=24.0, frames=5, gravity=(0.0, 0.0, 0.0), name="rerun")
    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e5, poisson_ratio=0.25)
    body = scene.add_peridynamic_body(pdsim.box((0.06, 0.03, 0.03)), mat, 0.01, name="block")
    body.set_initial_velocity((speed, 0.0, 0.0))
    return scene


def _frames_of(path):
    """{frame: world positions} and the endTimeCode of the cache at path, read fresh from disk."""
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    stage.Reload()
    prim = stage.GetPrimAtPath("/World/block")
    times = prim.GetAttribute("points").GetTimeSamples()
    return {int(t): world_points(prim, t) for t in times}, stage.GetEndTimeCode()


def test_failing_rerun_keeps_the_earlier_cache(tmp_path, monkeypatch):
    """A scene run writes a cache; a second run to the same path that raises at frame 3 leaves the first cache intact
    (same frames, same data, same end), keeps its own frames 0..2 in rerun.partial.usdc and says so on the exception;
    a third, successful run replaces the cache with one packed file, and the failed run's partial cache and the frames
    folder are gone."""
    out = tmp_path / "rerun.usdc"
    _scene(0.1).run(out, device="cpu", progress=False)
    first, first_end = _frames_of(out)
    assert first_end == 5 and sorted(first) == list(range(6))

    real = pdsim.SolverPeridynamics.simulate
    calls = {"n": 0}

    def simulate(self, dt, steps):
        calls["n"] += 1
        if calls["n"] == 3:
            raise RuntimeError("solver failed at frame 3")
        return real(self, dt, steps)

    monkeypatch.setattr(pdsim.SolverPeridynamics, "simulate", simulate)
    with pytest.raises(RuntimeError, match="frame 3") as info:
        _scene(0.5).run(out, device="cpu", progress=False)
    assert any("rerun.partial.usdc" in note for note in getattr(info.value, "__notes__", []))
    again, again_end = _frames_of(out)
    assert again_end == first_end and sorted(again) == sorted(first)
    for f in first:
        np.testing.assert_array_equal(again[f], first[f])
    partial, partial_end = _frames_of(tmp_path / "rerun.partial.usdc")
    assert partial_end == 2 and sorted(partial) == [0, 1, 2]
    assert not np.allclose(partial[2], first[2])  # the failed run's own data
    assert usd_problems(out) == []

    monkeypatch.setattr(pdsim.SolverPeridynamics, "simulate", real)
    _scene(0.5).run(out, device="cpu", progress=False)
    third, third_end = _frames_of(out)
    assert third_end == 5
    np.testing.assert_allclose(third[2], partial[2], atol=1e-6)
    assert not (tmp_path / "rerun.partial.usdc").exists()
    assert not (tmp_path / "rerun.frames").exists()
    assert usd_problems(out) == []


def test_save_interval_throttles_only_the_top_level_layer(tmp_path):
    """save_interval_s > 0 spaces out the rewrites of the top-level layer (a 1 s interval over a 0.5 s run: written
    at the end only) while the frame layers are written as frames finish."""
    from pdsim.output.usd import UsdCache

    out = tmp_path / "throttled.usdc"
    cache = UsdCache(out, fps=24.0, save_interval_s=1.0)
    pts = cache.add_points("p", widths=np.ones(4))
    t0 = time.monotonic()
    for f in range(3):
        cache.write_points(pts, f, np.zeros((4, 3)) + f)
        cache.end_frame(f)
    assert time.monotonic() - t0 < 1.0
    assert not out.exists()
    assert len(list(cache.run_dir.glob("frame.*.usdc"))) == 3
    cache.close()
    assert _frames_of_points(out) == [0.0, 1.0, 2.0]


def _frames_of_points(path):
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    return stage.GetPrimAtPath("/World/p").GetAttribute("points").GetTimeSamples()
