"""Stopping a run in time: a checkpoint write can be abandoned (SIGTERM during a slow checkpoint write stops the run
within 2 s, its temporary file removed), and a killed run's temporary files are removed by the next run on the same
output."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from pxr import Usd

import pdsim
from pdsim.checkpoint import (
    CheckpointAbandoned,
    checkpoint_path,
    load_checkpoint,
    save_checkpoint,
    temporary_path,
)

SLOW_SCRIPT = """
import time

import pdsim
import pdsim.checkpoint as ck
from pdsim.cli import run_script

ck.CHUNK_BYTES = 4096
_real = ck._ChunkedFile.write_chunk


def _slow(self, chunk):  # a slow disk: 4 kB per 50 ms, so a checkpoint takes well over 2 s
    time.sleep(0.05)
    _real(self, chunk)


ck._ChunkedFile.write_chunk = _slow


def build_scene():
    scene = pdsim.Scene(fps=100.0, frames=50, name="slow")
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e5, poisson_ratio=0.3)
    beam = scene.add_peridynamic_body(pdsim.box((0.3, 0.1, 0.1), center=(0.15, 0.0, 0.5)), material, 0.02, name="b")
    beam.fix(pdsim.BoxRegion(lo=(-1.0, -1.0, -1.0), hi=(0.05, 1.0, 2.0)))
    return scene


if __name__ == "__main__":
    run_script(build_scene)
"""


def test_sigterm_during_a_slow_checkpoint_write_exits_within_2_s(tmp_path):
    """SIGTERM while a checkpoint is being written (at 80 kB/s): the process exits with 143 within 2 s, the
    checkpoint's temporary file is gone and the cache plays the finished frames."""
    script = tmp_path / "slow.py"
    script.write_text(SLOW_SCRIPT)
    out = tmp_path / "out.usdc"
    tmp = temporary_path(checkpoint_path(out))
    proc = subprocess.Popen(
        [sys.executable, str(script), "--out", str(out), "--quiet", "--device", "cpu", "--checkpoint-interval", "0"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 240.0
        while not (tmp.is_file() and tmp.stat().st_size > 8192) and proc.poll() is None:
            assert time.monotonic() < deadline, "no checkpoint write started"
            time.sleep(0.02)
        assert proc.poll() is None, proc.communicate()
        sent = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=30)
        elapsed = time.monotonic() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
    _, stderr = proc.communicate()
    assert proc.returncode == 143, stderr
    assert elapsed < 2.0, f"stopped {elapsed:.2f} s after SIGTERM"
    assert not tmp.exists()
    assert "interrupted" in stderr and "holds frames 0..1" in stderr, stderr
    stage = Usd.Stage.Open(str(out))
    assert stage.GetEndTimeCode() == 1.0


def test_abandoned_checkpoint_keeps_the_previous_one(tmp_path):
    """save_checkpoint with ``abandon`` true after the first chunk: CheckpointAbandoned, no temporary file, the
    previous checkpoint loads as it was."""
    path = tmp_path / "a.checkpoint.npz"
    save_checkpoint(path, {"x": np.arange(10.0)})
    calls = []

    def abandon():
        calls.append(1)
        return len(calls) > 1

    with pytest.raises(CheckpointAbandoned):
        save_checkpoint(path, {"x": np.zeros(3_000_000)}, abandon=abandon)  # 24 MB: several chunks
    assert not temporary_path(path).exists()
    assert np.array_equal(load_checkpoint(path)["x"], np.arange(10.0))


def test_next_run_removes_a_killed_runs_temporary_files(tmp_path):
    """The temporary files a SIGKILL leaves (the checkpoint's .tmp, the top-level layer's, a frame layer's) are
    removed by the next run on the same output; nothing else beside the cache is touched."""
    out = tmp_path / "out.usdc"
    stale = [
        temporary_path(checkpoint_path(out)),
        tmp_path / ".out.usdc.tmp.usdc",
        tmp_path / "out.frames" / "run-old" / ".frame.000003.tmp.usdc",
    ]
    for p in stale:
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(b"x" * 1000)
    other = tmp_path / "notes.txt"
    other.write_text("mine")
    scene = pdsim.Scene(fps=100.0, frames=1, name="tiny")
    scene.add_peridynamic_body(
        pdsim.box((0.3, 0.1, 0.1)), pdsim.Material(density=1000.0, youngs_modulus=1.0e5, poisson_ratio=0.3), 0.05
    )
    scene.run(out, device="cpu", progress=False)
    assert [p for p in stale if p.exists()] == []
    assert other.read_text() == "mine"
