"""Free resources of this machine: host memory, a CUDA device's memory, disk space."""

from __future__ import annotations

import shutil

import warp as wp


def free_host_memory() -> float | None:
    """Host memory available to this process [B]: psutil's ``available`` when installed, else MemAvailable of
    /proc/meminfo, lowered to the cgroup's limit minus its usage when a container sets one; None when unknown."""
    free = None
    try:
        import psutil

        free = float(psutil.virtual_memory().available)
    except ImportError:
        try:
            with open("/proc/meminfo") as f:
                for line in f:
                    if line.startswith("MemAvailable:"):
                        free = float(line.split()[1]) * 1024.0
                        break
        except OSError:
            free = None
    for limit_file, usage_file in (
        ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
        ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes"),
    ):
        try:
            with open(limit_file) as f:
                limit = f.read().strip()
            with open(usage_file) as f:
                usage = float(f.read().strip())
        except (OSError, ValueError):
            continue
        if limit.isdigit() and float(limit) < 2.0**60:  # "max" or a huge number: no limit
            room = max(float(limit) - usage, 0.0)
            free = room if free is None else min(free, room)
        break
    return free


def free_device_memory(device) -> float | None:
    """Free memory of a CUDA device [B] (``wp.get_device(device).free_memory``); None on the CPU."""
    d = wp.get_device(device)
    return float(d.free_memory) if d.is_cuda else None


def free_disk_space(folder: str) -> float:
    """Free space [B] of the file system that holds ``folder`` (shutil.disk_usage)."""
    return float(shutil.disk_usage(folder).free)
