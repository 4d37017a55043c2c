"""Clean errors of a run: write errors during the run (disk full on a frame layer, the top-level layer or a
checkpoint; a folder turned read-only) are one line naming the path, the error and the free space, and the finished
frames stay readable; exceptions of a user's scene script print the script's file, line and frames, exit 2."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom

import pdsim
import pdsim.checkpoint
import pdsim.output.usd_stream
from pdsim.errors import OutputWriteError
from pdsim.output.usd_values import export_layer

MAT = {"density": 1000.0, "youngs_modulus": 1.0e5, "poisson_ratio": 0.3}


def _scene(frames=4) -> pdsim.Scene:
    scene = pdsim.Scene(fps=100.0, frames=frames, name="tiny")
    beam = scene.add_peridynamic_body(
        pdsim.box((0.3, 0.1, 0.1), center=(0.15, 0.0, 0.5)), pdsim.Material(**MAT), 0.05, name="beam"
    )
    beam.fix(pdsim.BoxRegion(lo=(-1.0, -1.0, -1.0), hi=(0.05, 1.0, 2.0)))
    return scene


def _failing_export(monkeypatch, fails, err=errno.ENOSPC):
    """Makes the cache's layer export raise OSError(err) for a target ``fails(target)`` accepts."""
    real = pdsim.output.usd_stream.export_layer

    def export(layer, target):
        if fails(target):
            raise OSError(err, os.strerror(err), str(target))
        real(layer, target)

    monkeypatch.setattr(pdsim.output.usd_stream, "export_layer", export)


def _frames_on_disk(path) -> list[int]:
    """Frames whose beam points the cache at ``path`` holds, read back through pxr."""
    stage = Usd.Stage.Open(str(path))
    points = next(UsdGeom.Points(p) for p in stage.Traverse() if p.IsA(UsdGeom.Points))
    frames = range(int(stage.GetStartTimeCode()), int(stage.GetEndTimeCode()) + 1)
    return [f for f in frames if len(np.asarray(points.GetPointsAttr().Get(f))) > 0]


def _check_message(message: str, path_part: str, last: int, error="No space left on device"):
    assert "\n" not in message
    assert message.startswith("could not write ") and path_part in message, message
    assert error in message and " free on " in message, message
    assert f"holds frames 0..{last}" in message, message


def test_disk_full_on_a_frame_layer_keeps_the_finished_frames(tmp_path, monkeypatch):
    """ENOSPC on frame 3's layer: OutputWriteError naming frame.000003, the error and the free space; frames 0..2 read
    back."""
    _failing_export(monkeypatch, lambda t: t.name.startswith("frame.000003"))
    out = tmp_path / "out.usdc"
    with pytest.raises(OutputWriteError) as info:
        _scene().run(out, device="cpu", progress=False)
    _check_message(str(info.value), "frame.000003.usdc", 2)
    assert _frames_on_disk(out) == [0, 1, 2]


def test_disk_full_on_the_top_level_layer(tmp_path, monkeypatch):
    """ENOSPC on the top-level layer from frame 2 on: the message names out.usdc; the layer on disk (frames 0..1)
    stays readable."""
    out = tmp_path / "out.usdc"
    writes = []

    def fails(target):
        if target.name == out.name:
            writes.append(target)
            return len(writes) > 2
        return False

    _failing_export(monkeypatch, fails)
    with pytest.raises(OutputWriteError) as info:
        _scene().run(out, device="cpu", progress=False)
    _check_message(str(info.value), f"{out}:", 1)
    assert _frames_on_disk(out) == [0, 1]


def test_disk_full_on_a_checkpoint(tmp_path, monkeypatch):
    """ENOSPC while writing a checkpoint: the message names the checkpoint's temporary file; no temporary file stays;
    the finished frames read back."""
    out = tmp_path / "out.usdc"

    def write_chunk(self, chunk):  # a write to a full disk: OSError(ENOSPC) without a file name
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(pdsim.checkpoint._ChunkedFile, "write_chunk", write_chunk)
    with pytest.raises(OutputWriteError) as info:
        _scene().run(out, device="cpu", progress=False, checkpoint_interval_s=0.0)
    monkeypatch.undo()
    _check_message(str(info.value), ".out.checkpoint.npz.tmp:", 1)
    assert not list(tmp_path.glob(".*.tmp*")), list(tmp_path.iterdir())
    assert _frames_on_disk(out) == [0, 1]


def test_read_only_folder(tmp_path, monkeypatch):
    """EROFS (the folder turned read-only) on frame 2: the message names the error."""
    _failing_export(monkeypatch, lambda t: t.name.startswith("frame.000002"), err=errno.EROFS)
    out = tmp_path / "out.usdc"
    with pytest.raises(OutputWriteError) as info:
        _scene().run(out, device="cpu", progress=False)
    _check_message(str(info.value), "frame.000002.usdc", 1, error="Read-only file system")
    assert _frames_on_disk(out) == [0, 1]


# -- the user's scene script ---------------------------------------------------------------------------------------
HEADER = """import pdsim


def build_scene():
    scene = pdsim.Scene(fps=100.0, frames=2, name="tiny")
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e5, poisson_ratio=0.3)
    beam = scene.add_peridynamic_body(pdsim.box((0.3, 0.1, 0.1), center=(0.15, 0.0, 0.5)), material, 0.05, name="b")
"""
SCRIPTS = {
    # name: (script text, line of the error, message fragment)
    "syntax": ("import pdsim\n\n\ndef build_scene(:\n    pass\n", 4, "SyntaxError: invalid syntax"),
    "build": (HEADER + "    return helper(scene)\n\n\ndef helper(scene):\n    return scene.bodies[5]\n", 12,
              "IndexError: list index out of range"),
    "import": ("import pdsim\nimport no_such_module_xyz\n", 2, "No module named 'no_such_module_xyz'"),
    "region": (HEADER + "    beam.fix(lambda x: x[:, 7] < 0.05)\n    return scene\n", 8,
               "IndexError: index 7 is out of bounds"),
}  # fmt: skip


def _check_script_error(proc, script, line: int, fragment: str):
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip() and not ln.startswith("Warp CUDA warning:")]
    assert lines[0].startswith(f"pdsim: error in scene script {script}, line {line}: "), lines[0]
    assert fragment in lines[0], lines[0]
    frames = [ln for ln in lines if ln.lstrip().startswith("File ")]
    assert all(str(script) in ln for ln in frames), proc.stderr  # the user's frames only
    assert "Traceback (most recent call last)" not in proc.stderr
    assert "site-packages" not in proc.stderr and f"{os.sep}pdsim{os.sep}" not in proc.stderr


@pytest.mark.parametrize("name", list(SCRIPTS))
def test_scene_script_exception_cli(name, tmp_path):
    """pdsim run SCRIPT: a syntax error, an exception in build_scene, a missing import and an exception in a region
    function print the script's file, line and message and only the script's frames; exit 2; no cache."""
    text, line, fragment = SCRIPTS[name]
    script = tmp_path / f"{name}.py"
    script.write_text(text)
    proc = subprocess.run(
        [sys.executable, "-m", "pdsim.cli", "run", str(script), "--out", str(tmp_path / "o.usdc"), "--quiet"],
        capture_output=True, text=True, timeout=300, cwd=tmp_path, check=False,
    )  # fmt: skip
    _check_script_error(proc, script, line, fragment)
    assert not (tmp_path / "o.usdc").exists()


def test_scene_script_exception_run_script(tmp_path):
    """A script run on its own (run_script): an exception in build_scene exits 2 with the script's frames only."""
    text, line, fragment = SCRIPTS["build"]
    script = tmp_path / "own.py"
    script.write_text(
        text + "\n\nif __name__ == '__main__':\n    from pdsim.cli import run_script\n\n    run_script(build_scene)\n"
    )
    proc = subprocess.run(
        [sys.executable, str(script), "--out", str(tmp_path / "o.usdc"), "--quiet"],
        capture_output=True, text=True, timeout=300, cwd=tmp_path, check=False,
    )  # fmt: skip
    _check_script_error(proc, script, line, fragment)


def test_pdsim_error_keeps_exit_1(tmp_path):
    """pdsim's own errors (PdsimError) keep exit 1 and their one line."""
    script = tmp_path / "bad.py"
    script.write_text(HEADER.replace("0.05, name", "-1.0, name") + "    return scene\n")
    proc = subprocess.run(
        [sys.executable, "-m", "pdsim.cli", "run", str(script), "--out", str(tmp_path / "o.usdc"), "--quiet"],
        capture_output=True, text=True, timeout=300, cwd=tmp_path, check=False,
    )  # fmt: skip
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip() and not ln.startswith("Warp CUDA warning:")]
    assert proc.returncode == 1 and len(lines) == 1 and lines[0].startswith("pdsim: error: "), proc.stderr


def test_usd_write_failure_is_an_oserror_naming_the_file():
    """A layer export USD itself fails (a Tf error: here a folder no one may create files in) is an OSError with the
    errno named in USD's text and the target's path, which the run turns into its one-line message."""
    target = Path("/sys/pdsim_probe.usdc")
    with pytest.raises(OSError) as info:
        export_layer(Sdf.Layer.CreateAnonymous("probe.usdc"), target)
    assert info.value.errno == errno.EACCES and info.value.filename == str(target), repr(info.value)
