"""The Warp device a run uses when none is named."""

from __future__ import annotations

import warp as wp

from .errors import ParameterError


def default_device() -> str:
    """'cuda' when a CUDA device is present, else 'cpu'."""
    return "cuda" if wp.get_cuda_device_count() > 0 else "cpu"


def resolve_device(name: str | None) -> str | None:
    """``name`` checked against this machine: 'cuda' without a CUDA device raises ParameterError; None stays None
    (the run's default, :func:`default_device`)."""
    if name != "cuda":
        return name
    if wp.get_cuda_device_count() == 0:
        raise ParameterError("device", "cuda", "'cpu' on this machine (no CUDA device found)")
    return "cuda"


def wait_for(devices) -> None:
    """Waits until the work launched on each CUDA device of ``devices`` (Warp devices or their names) is done; the CPU
    backend's launches are synchronous, so CPU devices are skipped."""
    for device in {str(d) for d in devices}:
        if wp.get_device(device).is_cuda:
            wp.synchronize_device(device)


def device_of(solver):
    """The Warp device a solver runs on (its kinematics' where it has them)."""
    return solver.kin.device if hasattr(solver, "kin") else solver.device
