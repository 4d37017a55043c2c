"""The watchdog, checkpoints and --resume, signals (docs/stability.md).

- ``pdsim run --dt-factor 3`` on a breakable and on an unbreakable block stops with the watchdog's one-line message
  (frame, body, likely cause), exit status 3, and a cache holding every frame before the failing one;
- the watchdog checks every 16 steps, not once a frame, and a collapsing soft body is blamed on its stiffness, not
  the time step;
- SIGTERM and SIGINT stop ``pdsim run`` with one line and status 143 / 130, leaving a readable cache and a checkpoint;
- ``--resume`` (CLI, after SIGTERM) and ``Scene.run(resume=True)`` (after a stop inside a frame, for each method:
  peridynamics with fracture, contact and grips; FEM with fracture splitting the mesh; the lattice) reproduce the
  uninterrupted run bit for bit on the CPU (the cached positions of every frame);
- resuming refuses a missing checkpoint and one of another scene; --dt-factor refuses bad values.

The scenes are tiny (a few hundred particles) so each test takes seconds.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import pdsim
from pdsim.checkpoint import RunInterrupted, checkpoint_path

BLOCK_SCRIPT = """
import numpy as np
import pdsim


def build_scene():
    scene = pdsim.Scene(fps=24, frames={frames}, frame_time=2.0e-3, name="block")
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e7, poisson_ratio=0.25{fracture})
    body = scene.add_peridynamic_body(
        pdsim.box((0.08, 0.08, 0.04), center=(0.0, 0.0, 0.0201)), material, spacing=0.01, name="block"
    )
    body.set_initial_velocity(np.random.default_rng(1).normal(0.0, 0.01, (body.particle_count, 3)))
    scene.add_ground_plane()
    return scene
"""


def _script(tmp_path, *, frames=6, breakable=False, name="scene.py"):
    path = tmp_path / name
    path.write_text(BLOCK_SCRIPT.format(frames=frames, fracture=", critical_stretch=0.01" if breakable else ""))
    return path


def _cli_args(*args):
    return [sys.executable, "-m", "pdsim.cli", *map(str, args)]


def _cli(*args, cwd, timeout=240):
    return subprocess.run(_cli_args(*args), check=False, capture_output=True, text=True, timeout=timeout, cwd=cwd)


def _lines(stderr: str) -> list[str]:
    """pdsim's stderr lines (without Warp's own CUDA-driver notice)."""
    return [ln for ln in stderr.splitlines() if ln.strip() and not ln.startswith("Warp CUDA warning:")]


def _positions(path, name: str, first: int = 0, last: int = -1) -> dict:
    """{frame: points [n, 3] float32} of the Points prim /World/<name> over frames first..last (-1: all)."""
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(path))
    assert stage is not None, path
    attr = UsdGeom.Points(stage.GetPrimAtPath(f"/World/{name}")).GetPointsAttr()
    out = {}
    for t in attr.GetTimeSamples():
        if t >= first and (last < 0 or t <= last):
            out[int(t)] = np.asarray(attr.Get(t))
    return out


def _mesh_points(path, name: str, first: int = 0, last: int = -1) -> dict:
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(path))
    attr = UsdGeom.Mesh(stage.GetPrimAtPath(f"/World/{name}")).GetPointsAttr()
    return {int(t): np.asarray(attr.Get(t)) for t in attr.GetTimeSamples() if t >= first and (last < 0 or t <= last)}


def _assert_identical(reference: dict, resumed: dict):
    assert sorted(resumed) == sorted(reference)
    for frame, x in reference.items():
        assert resumed[frame].dtype == x.dtype
        assert np.array_equal(resumed[frame], x), f"frame {frame} differs by {np.abs(resumed[frame] - x).max()} m"


def _assert_cache_until(path, name: str, last: int):
    """The cache opens, holds frames 0..last with finite positions, and passes the USD validators."""
    from pdsim.output.usd_files import usd_problems

    frames = _positions(path, name)
    assert sorted(frames) == list(range(last + 1))
    assert all(np.isfinite(x).all() for x in frames.values())
    assert usd_problems(path) == []


# ------------------------------------------------------------------------------------------------------ the watchdog


@pytest.mark.parametrize("breakable", [True, False], ids=["breakable", "unbreakable"])
def test_dt_factor_3_stops_with_the_watchdog_message(tmp_path, breakable):
    """`pdsim run --dt-factor 3`: one warning line, then one error line naming the frame, the step, the body and the
    time step as the likely cause; exit status 3; the cache holds exactly the frames before the failing one, all
    finite. With fracture on the divergence breaks the block apart (speeds stay far below the speed limit), and the
    energy check catches it."""
    script = _script(tmp_path, breakable=breakable)
    out = tmp_path / "x.usdc"
    proc = _cli("run", script, "--out", out, "--dt-factor", 3, "--device", "cpu", "--quiet", cwd=tmp_path)
    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr
    lines = _lines(proc.stderr)
    assert len(lines) == 2, proc.stderr
    assert lines[0].startswith("pdsim: warning: dt_factor=3")
    error = lines[1]
    assert error.startswith("pdsim: error: the simulation diverged in frame ")
    m = re.search(r"diverged in frame (\d+) at t=\S+ s \(step (\d+)\)", error)
    assert m, error
    frame, step = int(m.group(1)), int(m.group(2))
    assert frame >= 1 and step >= 1
    assert "in body 'block'" in error
    assert "likely cause: the time step" in error and "stable estimate" in error
    assert f"holds frames 0..{frame - 1}" in error
    if breakable:
        assert "energy" in error
    _assert_cache_until(out, "block", frame - 1)


def test_checks_every_16_steps_and_names_the_frame(tmp_path):
    """With 60 steps a frame at 3x the automatic step, the divergence is caught at a multiple of 16 steps inside the
    first frame (not at its end), and InstabilityError names frame 1."""
    scene = pdsim.Scene(fps=24, frames=3, frame_time=1.0e-2, gravity=(0.0, 0.0, 0.0), name="fine")
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e7, poisson_ratio=0.25)
    body = scene.add_peridynamic_body(pdsim.box((0.06, 0.06, 0.04), center=(0.0, 0.0, 0.0)), material, spacing=0.01)
    body.set_initial_velocity(np.random.default_rng(2).normal(0.0, 0.01, (body.particle_count, 3)))
    with pytest.warns(UserWarning, match="dt_factor=3"), pytest.raises(pdsim.InstabilityError) as ei:
        report = scene.run(tmp_path / "fine.usdc", device="cpu", dt_factor=3.0, progress=False)
        pytest.fail(f"no divergence: {report}")
    message = str(ei.value)
    step = int(re.search(r"\(step (\d+)\)", message).group(1))
    assert "in frame 1 " in message
    assert step % 16 == 0 and step < 60, message


def test_a_collapsing_soft_body_is_blamed_on_its_stiffness(tmp_path):
    """A 1 kPa cube dropped on the ground (its P-wave speed 1.2 m/s, the impact 2.8 m/s) collapses at the automatic
    step: its particles pass through each other. The watchdog stops the run on the bond stretch and names stiffness,
    not the time step, as the cause (a smaller step does not help)."""
    scene = pdsim.Scene(fps=24, frames=12, name="soft")
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e3, poisson_ratio=0.3)
    scene.add_peridynamic_body(pdsim.box((0.2, 0.2, 0.2), center=(0.0, 0.0, 0.3)), material, 0.025, name="cube")
    scene.add_ground_plane()
    with pytest.raises(pdsim.InstabilityError) as ei:
        scene.run(tmp_path / "soft.usdc", device="cpu", progress=False)
    message = str(ei.value)
    assert "bond stretch" in message and "in body 'cube'" in message
    assert "likely cause: stiffness" in message and "a smaller step does not help" in message
    assert "leave it automatic" not in message


def test_dt_factor_is_validated(tmp_path):
    """--dt-factor 0, -1, 'abc', inf, or with --dt: one-line error, exit status 1, no cache."""
    script = _script(tmp_path)
    out = tmp_path / "x.usdc"
    for value in ("0", "-1", "abc", "inf"):
        proc = _cli("run", script, "--out", out, "--dt-factor", value, "--device", "cpu", "--quiet", cwd=tmp_path)
        assert proc.returncode == 1, proc.stderr
        lines = _lines(proc.stderr)
        assert len(lines) == 1 and lines[0].startswith("pdsim: error: dt-factor=") and "> 0" in lines[0], lines
    proc = _cli("run", script, "--out", out, "--dt", 1e-5, "--dt-factor", 2, "--device", "cpu", cwd=tmp_path)
    assert proc.returncode == 1 and "--dt" in _lines(proc.stderr)[0]
    assert not out.exists()
    with pytest.raises(pdsim.ParameterError, match="dt_factor"):
        pdsim.Scene().run(tmp_path / "y.usdc", dt_factor=0.0)


# ------------------------------------------------------------------------------------------------ signals and resume


def _wait_for_frame(out, frame: int, proc, timeout: float = 120.0):
    """Waits until the run writing ``out`` has finished ``frame`` (its frame layer is on disk)."""
    folder = out.with_name(f"{out.stem}.frames")
    name = f"frame.{frame:06d}.usdc"
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if proc.poll() is not None:
            pytest.fail(f"the run ended before frame {frame}: {proc.stderr.read()}")
        if folder.is_dir() and any((run / name).is_file() for run in folder.iterdir()):
            return
        time.sleep(0.02)
    pytest.fail(f"frame {frame} not written within {timeout} s")


def _signal_run(tmp_path, script, out, signum):
    proc = subprocess.Popen(
        _cli_args("run", script, "--out", out, "--device", "cpu", "--quiet", "--checkpoint-interval", "0"),
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        _wait_for_frame(out, 2, proc)
        proc.send_signal(signum)
        _, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    return proc.returncode, stderr


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_signals_stop_with_one_line_and_a_readable_cache(tmp_path, signum):
    """SIGTERM (143) and SIGINT (130) stop `pdsim run` within a few steps: one line on stderr naming the cache, the
    finished frames and the checkpoint; the cache opens with frames 0..last, finite and valid; the checkpoint is on
    disk."""
    script = _script(tmp_path, frames=400)
    out = tmp_path / "sig.usdc"
    code, stderr = _signal_run(tmp_path, script, out, signum)
    assert code == 128 + int(signum), stderr
    assert "Traceback" not in stderr
    lines = _lines(stderr)
    assert len(lines) == 1, stderr
    m = re.match(
        rf"pdsim: interrupted; {re.escape(str(out))} holds the frames finished so far \(.*\.\.(\d+)\)", lines[0]
    )
    assert m, lines[0]
    assert lines[0].endswith(f"[{signal.Signals(signum).name}]")
    assert "--resume" in lines[0]
    last = int(m.group(1))
    assert last >= 2
    _assert_cache_until(out, "block", last)
    assert checkpoint_path(out).is_file()


def test_resume_after_sigterm_is_bit_identical(tmp_path):
    """A run stopped by SIGTERM and continued with `pdsim run --resume` gives, frame by frame, the same positions as
    the uninterrupted run, bit for bit (CPU), in the one cache --out; the finished run removes the checkpoint and
    leaves no other top-level layer beside the cache."""
    frames = 60
    script = _script(tmp_path, frames=frames, breakable=True)
    reference = tmp_path / "reference.usdc"
    proc = _cli("run", script, "--out", reference, "--device", "cpu", "--quiet", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr

    out = tmp_path / "resumed.usdc"
    code, stderr = _signal_run(tmp_path, script, out, signal.SIGTERM)
    assert code == 143, stderr
    proc = _cli("run", script, "--out", out, "--device", "cpu", "--quiet", "--resume", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "resumed" in proc.stdout and f"the cache holds frames 0..{frames}" in proc.stdout
    assert not checkpoint_path(out).exists()
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("resumed")) == ["resumed.usdc"]  # packed
    _assert_identical(_positions(reference, "block"), _positions(out, "block"))


def test_kill_9_during_a_resumed_run_keeps_every_finished_frame(tmp_path):
    """A run stopped at a step boundary, resumed with `pdsim run --resume`, and the resumed run killed with SIGKILL a
    few frames later: `out` (the one cache) opens with frames 0..k, k past the checkpoint's frame, the frames of the
    first run unchanged bit for bit, all finite and valid."""
    import runpy

    script = _script(tmp_path, frames=400, breakable=True)
    out = tmp_path / "k.usdc"
    with pytest.raises(RunInterrupted):  # the script's scene, stopped in this process (as by SIGTERM) in frame 3
        runpy.run_path(str(script))["build_scene"]().run(out, device="cpu", progress=False, stop=_StopAfter(40))
    before = _positions(out, "block")
    last = max(before)
    proc = subprocess.Popen(
        _cli_args("run", script, "--out", out, "--device", "cpu", "--quiet", "--resume"),
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        _wait_for_frame(out, last + 3, proc)
        proc.kill()
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL
    after = _positions(out, "block")
    k = max(after)
    assert k >= last + 2
    _assert_cache_until(out, "block", k)
    for frame, x in before.items():
        assert np.array_equal(after[frame], x), frame


class _StopAfter:
    """A stop request that becomes true at its ``n``-th poll (a deterministic SIGTERM)."""

    def __init__(self, n: int):
        self.n, self.calls, self.signal = n, 0, None

    @property
    def requested(self) -> bool:
        self.calls += 1
        if self.calls >= self.n:
            self.signal = signal.SIGTERM
        return self.signal is not None


def _pd_grips():
    """A breakable bar (288 particles, contact on) pulled apart by ramped grips, under gravity, on the ground."""
    scene = pdsim.Scene(fps=24, frames=8, frame_time=1.0e-3, name="grips")
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e7, poisson_ratio=0.25, critical_stretch=0.005)
    body = scene.add_peridynamic_body(
        pdsim.box((0.16, 0.06, 0.03), center=(0.0, 0.0, 0.0151)), material, spacing=0.01, name="bar"
    )
    ramp = pdsim.TimeCurve.ramp(2.0e-3)
    body.set_velocity(pdsim.BoxRegion(lo=(-1, -1, -1), hi=(-0.07, 1, 1)), (-2.0, 0, 0), axes="x", curve=ramp, name="l")
    body.set_velocity(pdsim.BoxRegion(lo=(0.07, -1, -1), hi=(1, 1, 1)), (2.0, 0, 0), axes="x", curve=ramp, name="r")
    scene.add_ground_plane()
    return scene, "bar", "bar_surface"


def _fem_bar():
    """An FEM bar pulled apart until elements split (the mesh's vertices and topology change before the stop)."""
    scene = pdsim.Scene(fps=24.0, frames=8, frame_time=1.0e-3, gravity=(0.0, 0.0, 0.0), name="fem")
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)
    body = scene.add_body(
        pdsim.FemBody(pdsim.box_tet_mesh((0.08, 0.02, 0.02), (8, 2, 2)), material, tensile_strength=2.0e3, name="bar")
    )
    body.set_velocity(pdsim.BoxRegion(lo=(-1, -1, -1), hi=(-0.0399, 1, 1)), (-0.5, 0.0, 0.0))
    body.set_velocity(pdsim.BoxRegion(lo=(0.0399, -1, -1), hi=(1, 1, 1)), (0.5, 0.0, 0.0))
    return scene, "bar", "bar_surface"


def _lattice_block():
    from pdsim.lattice import Lattice, LatticeBody, LatticeFracture

    scene = pdsim.Scene(fps=24.0, frames=8, name="lattice")
    h = 0.01
    body = LatticeBody.block(Lattice.simple_cubic(h), (12, 5, 3), name="block", fracture=LatticeFracture((1.6 * h,)))
    x = body.rest_positions[: body.body_count, 0]
    body.clamp(x < x.min() + 0.5 * h)
    body.add_leaders(x > x.max() - 0.5 * h, velocity=(0.35 * h, 0.0, 0.0), stop_step=10)
    scene.add_body(body)
    return scene, "block", None


@pytest.mark.parametrize(
    ("build", "polls"), [(_pd_grips, 5), (_fem_bar, 4), (_lattice_block, 4)], ids=["peridynamics", "fem", "lattice"]
)
def test_resume_after_a_stop_is_bit_identical(tmp_path, build, polls):
    """Scene.run stopped by a stop request (inside a frame for the peridynamic bar: 19 steps a frame, checked every
    16) writes a checkpoint and raises RunInterrupted; Scene.run(resume=True) continues and every frame's cached
    positions (points, and the surface mesh where there is one) equal the uninterrupted run's bit for bit."""
    scene, points, surface = build()
    reference = tmp_path / "reference.usdc"
    report = scene.run(reference, device="cpu", progress=False, checkpoint_interval_s=None)
    assert not checkpoint_path(reference).exists()

    out = tmp_path / "x.usdc"
    with pytest.raises(RunInterrupted) as ei:
        build()[0].run(out, device="cpu", progress=False, checkpoint_interval_s=60.0, stop=_StopAfter(polls))
    assert ei.value.checkpoint is not None and checkpoint_path(out).is_file()
    resumed = build()[0].run(out, device="cpu", progress=False, resume=True)
    assert resumed.first_frame == ei.value.last_frame + 1
    assert resumed.summary == report.summary  # the same topology at the end (FEM: the same splits)
    _assert_identical(_positions(reference, points), _positions(out, points))
    if surface is not None:
        _assert_identical(_mesh_points(reference, surface), _mesh_points(out, surface))


def test_resume_refuses_a_missing_or_foreign_checkpoint(tmp_path):
    """--resume without a checkpoint, with the checkpoint of another scene, or without the cache the checkpoint was
    written with, is a one-line ParameterError."""
    scene, _, _ = _lattice_block()
    out = tmp_path / "x.usdc"
    with pytest.raises(pdsim.ParameterError, match="none found"):
        scene.run(out, device="cpu", progress=False, resume=True)
    with pytest.raises(RunInterrupted):
        scene.run(out, device="cpu", progress=False, stop=_StopAfter(2))
    other, _, _ = _fem_bar()
    with pytest.raises(pdsim.ParameterError, match="another scene"):
        other.run(out, device="cpu", progress=False, resume=True)
    script = _script(tmp_path)
    proc = _cli("run", script, "--out", out, "--resume", "--device", "cpu", "--quiet", cwd=tmp_path)
    assert proc.returncode == 1
    lines = _lines(proc.stderr)
    assert len(lines) == 1 and lines[0].startswith("pdsim: error: resume=") and "another scene" in lines[0]
    out.unlink()  # the cache the checkpoint belongs to is gone: nothing to continue
    with pytest.raises(pdsim.ParameterError, match="a cache holding the run the checkpoint belongs to"):
        scene.run(out, device="cpu", progress=False, resume=True)


def test_checkpoint_file_round_trip(tmp_path):
    """save_checkpoint / load_checkpoint keep nested dicts, arrays bit for bit, floats exactly, None and lists."""
    from pdsim.checkpoint import load_checkpoint, save_checkpoint

    state = {
        "a": {"u": np.random.default_rng(0).normal(size=(5, 3)).astype(np.float32), "n": 3, "t": 0.1 + 0.2},
        "b": None,
        "segments": [["x.usdc", 0, 4]],
        "empty": {},
    }
    path = save_checkpoint(tmp_path / "c.npz", state)
    back = load_checkpoint(path)
    assert np.array_equal(back["a"]["u"], state["a"]["u"]) and back["a"]["u"].dtype == np.float32
    assert back["a"]["t"] == state["a"]["t"] and back["a"]["n"] == 3
    assert back["b"] is None and back["segments"] == [["x.usdc", 0, 4]] and back["empty"] == {}
    assert not [p for p in os.listdir(tmp_path) if p.startswith(".")]
