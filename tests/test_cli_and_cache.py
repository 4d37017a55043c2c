"""The pdsim command line and the USD cache it writes: version, a full tiny run, the shipped default scene, user
mistakes (one line, no traceback), and crash safety (divergence and Ctrl-C leave a readable cache of the finished
frames)."""

from __future__ import annotations

import re
import subprocess
import sys
import warnings

import numpy as np
import pytest

import pdsim
from pdsim.output.usd_files import usd_problems, world_points

FPS = 100.0

SCENE_SCRIPT = f"""
import pdsim


def build_scene():
    scene = pdsim.Scene(fps={FPS}, frames=10, up_axis="Z", name="tiny")
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e5, poisson_ratio=0.3)
    body = scene.add_peridynamic_body(pdsim.box((0.3, 0.1, 0.1), center=(0.15, 0.0, 0.5)), material, spacing=0.05,
                                      name="beam")
    body.fix(pdsim.BoxRegion(lo=(-1.0, -1.0, -1.0), hi=(0.05, 1.0, 2.0)))  # the first layer at x = 0.025
    scene.add_ground_plane(height=0.0)
    return scene
"""


def _cli(*args, cwd, timeout=180):
    """Runs ``python -m pdsim.cli ARGS`` (works in any virtual environment)."""
    return subprocess.run(
        [sys.executable, "-m", "pdsim.cli", *map(str, args)],
        check=False,
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd,
    )


def _pdsim_stderr_lines(stderr: str) -> list[str]:
    """stderr lines of the pdsim CLI, without the line that Warp's native library prints itself (unconditionally, from
    C++) when it finds no CUDA driver; pdsim cannot silence it."""
    return [ln for ln in stderr.splitlines() if ln.strip() and not ln.startswith("Warp CUDA warning:")]


def _assert_one_line_error(proc, *fragments):
    """Non-zero exit, no traceback anywhere, exactly one 'pdsim: error: ...' line on stderr holding every fragment."""
    assert proc.returncode != 0, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr
    lines = _pdsim_stderr_lines(proc.stderr)
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("pdsim: error:")
    for frag in fragments:
        assert frag in lines[0], f"{frag!r} not in {lines[0]!r}"


@pytest.fixture
def scene_script(tmp_path):
    path = tmp_path / "tiny_scene.py"
    path.write_text(SCENE_SCRIPT)
    return path


def _open_stage(path):
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    assert stage is not None
    return stage


def _points(stage, name):
    from pxr import UsdGeom

    prim = stage.GetPrimAtPath(f"/World/{name}")
    assert prim.IsValid() and prim.IsA(UsdGeom.Points)
    return UsdGeom.Points(prim)


def _all_positions(points):
    """{frame: world positions [n, 3]} over every time sample of the points attribute (through the prim's transform:
    the cache stores points relative to a double-precision translate)."""
    attr = points.GetPointsAttr()
    return {int(t): world_points(points.GetPrim(), t) for t in attr.GetTimeSamples()}


# ------------------------------------------------------------------------------------------------------------- CLI


def test_version(tmp_path):
    """`pdsim --version` prints 'pdsim <version>' and exits 0."""
    proc = _cli("--version", cwd=tmp_path)
    assert proc.returncode == 0
    assert proc.stdout.strip() == f"pdsim {pdsim.__version__}"


def test_no_command_prints_help(tmp_path):
    """`pdsim` without a command prints the usage and exits 2 (no traceback)."""
    proc = _cli(cwd=tmp_path)
    assert proc.returncode == 2
    assert "usage: pdsim" in proc.stdout
    assert "Traceback" not in proc.stdout + proc.stderr


def test_run_writes_cache(tmp_path, scene_script):
    """`pdsim run SCENE.py --out X.usdc --frames 3 --device cpu`: exit 0, a summary line; the cache has frames + 1 time
    samples (0..3, the rest pose at 0) on points, velocities and the displacement primvar; stage metadata
    timeCodesPerSecond = framesPerSecond = scene fps, startTimeCode 0, endTimeCode 3, upAxis Z, metersPerUnit 1,
    defaultPrim /World; widths (one per particle, = spacing); the fixed particles stay at rest, the others sag under
    gravity; validate_usd finds no error."""
    from pxr import UsdGeom

    out = tmp_path / "X.usdc"
    frames = 3
    proc = _cli("run", scene_script, "--out", out, "--frames", frames, "--device", "cpu", "--quiet", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr
    assert f"pdsim: wrote {out}" in proc.stdout
    assert out.is_file()
    assert not list(tmp_path.glob(".*.tmp*")), "temporary file left behind"

    stage = _open_stage(out)
    assert stage.GetTimeCodesPerSecond() == FPS
    assert stage.GetFramesPerSecond() == FPS
    assert stage.GetStartTimeCode() == 0.0
    assert stage.GetEndTimeCode() == float(frames)
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetDefaultPrim().GetPath() == "/World"

    points = _points(stage, "beam")
    n = 6 * 2 * 2
    assert points.GetPointsAttr().GetTimeSamples() == [float(f) for f in range(frames + 1)]
    assert points.GetVelocitiesAttr().GetTimeSamples() == [float(f) for f in range(frames + 1)]
    widths = np.asarray(points.GetWidthsAttr().Get())
    assert widths.shape == (n,)
    np.testing.assert_allclose(widths, 0.05, rtol=1e-6)
    primvars = UsdGeom.PrimvarsAPI(points)
    disp = primvars.GetPrimvar("displacement")
    assert disp and disp.GetInterpolation() == UsdGeom.Tokens.vertex
    assert disp.GetAttr().GetTimeSamples() == [float(f) for f in range(frames + 1)]
    assert primvars.GetPrimvar("dilatation")

    xs = _all_positions(points)
    for x in xs.values():
        assert x.shape == (n, 3) and np.isfinite(x).all()
    rest = xs[0]
    fixed = rest[:, 0] < 0.05
    assert fixed.sum() == 4
    np.testing.assert_allclose(xs[frames][fixed], rest[fixed], atol=1e-6)
    assert xs[frames][~fixed, 2].mean() < rest[~fixed, 2].mean()  # sagging under gravity
    d = np.asarray(disp.Get(frames))
    np.testing.assert_allclose(d, xs[frames] - rest, atol=1e-6)
    np.testing.assert_allclose(np.asarray(disp.Get(0)), 0.0, atol=1e-6)  # rest pose (float32 rounding only)

    # the fixed end's reaction force [N] is written every frame, and it holds the beam up (positive z)
    reaction = [a for a in points.GetPrim().GetAttributes() if a.GetName().startswith("pdsim:reaction:")]
    assert len(reaction) == 1
    assert reaction[0].GetTimeSamples() == [float(f) for f in range(frames + 1)]
    assert np.all(np.isfinite([reaction[0].Get(f) for f in range(frames + 1)]))
    assert reaction[0].Get(frames)[2] > 0.0

    assert usd_problems(out) == []


def test_default_scene_builds_and_runs_two_frames(tmp_path):
    """pdsim.default_scene.build_scene() returns a Scene with one body, fixed particles and a ground plane; `pdsim run
    --frames 2` (no script: the default scene) writes a valid cache with frames 0..2 (the scene's own 72 frames are not
    run here)."""
    from pdsim.default_scene import build_scene

    scene = build_scene()
    assert isinstance(scene, pdsim.Scene)
    assert len(scene.bodies) == 1 and scene.ground is not None
    body = scene.bodies[0]
    assert body.particle_count > 0 and body.constrained.any() and (~body.constrained).any()

    out = tmp_path / "default.usdc"
    proc = _cli("run", "--out", out, "--frames", 2, "--device", "cpu", "--quiet", cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr
    stage = _open_stage(out)
    assert stage.GetEndTimeCode() == 2.0
    assert stage.GetTimeCodesPerSecond() == scene.fps
    points = _points(stage, body.name)
    assert points.GetPointsAttr().GetTimeSamples() == [0.0, 1.0, 2.0]
    for x in _all_positions(points).values():
        assert x.shape == (body.particle_count, 3) and np.isfinite(x).all()
    assert usd_problems(out) == []


def test_scene_not_py(tmp_path):
    """A scene script that is not a .py file: non-zero exit, one-line error naming the file and '*.py'."""
    path = tmp_path / "scene.txt"
    path.write_text(SCENE_SCRIPT)
    proc = _cli("run", path, "--out", tmp_path / "x.usdc", cwd=tmp_path)
    _assert_one_line_error(proc, "scene.txt", "*.py")
    assert not (tmp_path / "x.usdc").exists()


def test_scene_missing(tmp_path):
    """A scene script that does not exist: non-zero exit, one-line error naming the file and 'an existing file'."""
    proc = _cli("run", tmp_path / "nope.py", "--out", tmp_path / "x.usdc", cwd=tmp_path)
    _assert_one_line_error(proc, "nope.py", "an existing file")


def test_scene_without_build_scene(tmp_path):
    """A .py script that defines no build_scene(): non-zero exit, one-line error naming the file and build_scene."""
    path = tmp_path / "empty_scene.py"
    path.write_text("import pdsim\n\nSCENE = None\n")
    proc = _cli("run", path, "--out", tmp_path / "x.usdc", cwd=tmp_path)
    _assert_one_line_error(proc, "empty_scene.py", "build_scene()")


def test_out_folder_missing(tmp_path, scene_script):
    """--out into a folder that does not exist: non-zero exit, one-line error naming out, no traceback."""
    proc = _cli(
        "run",
        scene_script,
        "--out",
        tmp_path / "missing" / "x.usdc",
        "--frames",
        1,
        "--device",
        "cpu",
        "--quiet",
        cwd=tmp_path,
    )
    _assert_one_line_error(proc, "out=", "existing folder")


def test_device_cuda_without_cuda(tmp_path, scene_script):
    """`--device cuda` where Warp finds no CUDA device: non-zero exit, one line naming device 'cuda' and 'no CUDA
    device', no traceback, no cache. (Skipped on a machine with a CUDA device.)"""
    import warp as wp

    if wp.get_cuda_device_count() > 0:
        pytest.skip("this machine has a CUDA device")
    out = tmp_path / "x.usdc"
    proc = _cli("run", scene_script, "--out", out, "--frames", 1, "--device", "cuda", "--quiet", cwd=tmp_path)
    _assert_one_line_error(proc, "device='cuda'", "no CUDA device")
    assert not out.exists()


# ---------------------------------------------------------------------------------------------------- crash safety


def _unstable_scene():
    """A 0.3 m cube (216 particles) with a random initial velocity perturbation, no gravity, and its stable estimate."""
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e5, poisson_ratio=0.3)

    def body():
        b = pdsim.PeridynamicBody(
            pdsim.box((0.3, 0.3, 0.3), center=(0.0, 0.0, 0.5)), material, spacing=0.05, name="cube"
        )
        b.set_initial_velocity(np.random.default_rng(1).normal(0.0, 0.01, (b.particle_count, 3)))
        return b

    stable = pdsim.SolverPeridynamics([body()], device="cpu").stable_time_step()
    return body, stable


def test_divergence_raises_and_leaves_finite_cache(tmp_path, monkeypatch, device):
    """Scene.run with dt = 3x the Silling-Askari stable estimate (2 substeps a frame, fps chosen so the step is exactly
    that) on a randomly perturbed cube diverges: it warns that dt exceeds the estimate, raises InstabilityError (a
    PdsimError) naming the step and the estimate, and the cache on disk opens, holds frames 0..last with only finite
    positions, and has endTimeCode = last = the frame before the failing one (>= 0)."""
    make_body, stable = _unstable_scene()
    factor, substeps = 3.0, 2
    scene = pdsim.Scene(fps=1.0 / (substeps * factor * stable), frames=40, gravity=(0.0, 0.0, 0.0), name="unstable")
    scene.add_body(make_body())

    seen = {"dt": [], "failed_step": None}
    real_simulate = pdsim.SolverPeridynamics.simulate
    real_check = pdsim.SolverPeridynamics.check_state

    def simulate(self, dt, steps):
        seen["dt"].append((dt, steps))
        return real_simulate(self, dt, steps)

    def check_state(self, speed_limit):
        try:
            return real_check(self, speed_limit)
        except pdsim.InstabilityError:
            seen["failed_step"] = self.step_count
            raise

    monkeypatch.setattr(pdsim.SolverPeridynamics, "simulate", simulate)
    monkeypatch.setattr(pdsim.SolverPeridynamics, "check_state", check_state)

    out = tmp_path / "unstable.usdc"
    with (
        pytest.warns(UserWarning, match="exceeds the stable estimate"),
        pytest.raises(pdsim.InstabilityError) as ei,
    ):
        scene.run(out, device=device, dt=factor * stable, progress=False)
    assert isinstance(ei.value, pdsim.PdsimError)
    assert "diverged" in str(ei.value) and "stable estimate" in str(ei.value)

    dt_used, steps = seen["dt"][0]
    assert steps == substeps
    assert dt_used == pytest.approx(factor * stable, rel=1e-6)
    failed_step = seen["failed_step"]
    assert failed_step is not None and failed_step % substeps == 0
    assert f"(step {failed_step})" in str(ei.value)
    last = failed_step // substeps - 1
    assert 0 <= last < 40

    assert out.is_file()
    assert not list(tmp_path.glob(".*.tmp*")), "temporary file left behind"
    stage = _open_stage(out)
    assert stage.GetStartTimeCode() == 0.0
    assert stage.GetEndTimeCode() == float(last)
    points = _points(stage, "cube")
    assert points.GetPointsAttr().GetTimeSamples() == [float(f) for f in range(last + 1)]
    xs = _all_positions(points)
    assert all(np.isfinite(x).all() for x in xs.values())
    assert usd_problems(out) == []


def _interrupt_on_third_call(monkeypatch):
    """Makes SolverPeridynamics.simulate raise KeyboardInterrupt on its 3rd call (while simulating frame 3)."""
    real_simulate = pdsim.SolverPeridynamics.simulate
    calls = {"n": 0}

    def simulate(self, dt, steps):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return real_simulate(self, dt, steps)

    monkeypatch.setattr(pdsim.SolverPeridynamics, "simulate", simulate)
    return calls


def _assert_two_finished_frames(out, name="beam"):
    stage = _open_stage(out)
    assert stage.GetStartTimeCode() == 0.0
    assert stage.GetEndTimeCode() == 2.0
    points = _points(stage, name)
    assert points.GetPointsAttr().GetTimeSamples() == [0.0, 1.0, 2.0]
    assert all(np.isfinite(x).all() for x in _all_positions(points).values())
    assert usd_problems(out) == []


def test_keyboard_interrupt_in_scene_run(tmp_path, monkeypatch, scene_script, device):
    """A KeyboardInterrupt raised inside Scene.run (3rd simulate call) propagates, and the cache on disk holds exactly
    the two finished frames after the rest pose (endTimeCode 2), readable and valid."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("tiny_scene_for_interrupt", scene_script)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    scene = module.build_scene()
    calls = _interrupt_on_third_call(monkeypatch)
    out = tmp_path / "interrupted.usdc"
    with pytest.raises(KeyboardInterrupt):
        scene.run(out, frames=5, device=device, progress=False)
    assert calls["n"] == 3
    _assert_two_finished_frames(out)


def test_keyboard_interrupt_cli_returns_130(tmp_path, monkeypatch, capsys, scene_script):
    """pdsim.cli.main (in-process) with a KeyboardInterrupt on the 3rd simulate call returns 130, says on stderr that
    the cache holds the finished frames, and the cache has frames 0..2 (endTimeCode 2)."""
    from pdsim import cli

    calls = _interrupt_on_third_call(monkeypatch)
    out = tmp_path / "interrupted.usdc"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the automatic time step must not warn
        code = cli.main(["run", str(scene_script), "--out", str(out), "--frames", "5", "--device", "cpu", "--quiet"])
    assert code == 130
    assert calls["n"] == 3
    err = capsys.readouterr().err
    assert re.search(r"interrupted; .*interrupted\.usdc holds the frames finished so far", err)
    assert "Traceback" not in err
    _assert_two_finished_frames(out)


def test_run_explain_prints_the_plan_and_writes_nothing(tmp_path):
    """`pdsim run --explain`: exit 0, prints the live features and the kernels one step launches (the default scene
    launches dilatation and force), and writes no cache."""
    proc = _cli("run", "--explain", "--device", "cpu", "--out", tmp_path / "x.usdc", cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "live features" in proc.stdout and "dilatation" in proc.stdout and "force" in proc.stdout
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "option, value, shown, allowed",
    [
        ("--frames", "2.5", "frames='2.5'", "integer >= 1"),
        ("--frames", "0", "frames=0", "integer >= 1"),
        ("--dt", "-1e-5", "dt=-1e-05", "(0, inf)"),  # a word argparse would take for an option
        ("--dt", "0", "dt=0", "(0, inf)"),
        ("--dt", "abc", "dt='abc'", "> 0"),
        ("--dt-factor", "-2", "dt-factor='-2'", "> 0"),
        ("--check-interval", "-3", "check-interval='-3'", "integer >= 1"),
    ],
)
def test_bad_run_option_is_one_line_error(tmp_path, capsys, scene_script, option, value, shown, allowed):
    """A bad number for a run option (negative, fractional, not a number) is the one-line pdsim error naming the
    option, the value and the allowed range, exit 1; no cache is written."""
    from pdsim.cli import main

    out = tmp_path / "x.usdc"
    assert main(["run", str(scene_script), "--out", str(out), "--quiet", option, value]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("pdsim: error:") and "\n" not in err, err
    assert shown in err and allowed in err, err
    assert not out.exists()
