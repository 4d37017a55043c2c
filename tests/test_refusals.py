"""Refusals that must be fast: a spacing asking for 150 million particles is refused before any sampling, in under
5 s, and a spacing that fits is not refused early. (The lattice leader driven out of the float32 range is a case of
tools/errors_catalogue.py, run by tests/test_errors_catalogue.py.)"""

from __future__ import annotations

import time

import pytest

import pdsim
import pdsim.memory

MAT = pdsim.Material(density=1000.0, youngs_modulus=1.0e5, poisson_ratio=0.3)


def test_150_million_particles_refused_in_under_5_s(monkeypatch):
    """A 1 m x 1.5 m x 1 m box at a spacing giving 1.5e8 particles, with 100 GB of free host memory: ParameterError
    naming the spacing, about 1.5e8 particles and a spacing that fits, within 5 s (no sampling: lattice counts from
    the bounding box)."""
    monkeypatch.setattr(pdsim.memory, "free_host_memory", lambda: 100.0e9)
    spacing = (1.5 / 150.0e6) ** (1.0 / 3.0)
    scene = pdsim.Scene()
    start = time.perf_counter()
    with pytest.raises(pdsim.ParameterError) as info:
        scene.add_peridynamic_body(pdsim.box((1.0, 1.5, 1.0)), MAT, spacing)
    elapsed = time.perf_counter() - start
    message = str(info.value)
    assert elapsed < 5.0, f"refused after {elapsed:.1f} s"
    assert message.startswith(f"spacing={spacing!r} is invalid") and "about 1.51e+08 particles" in message, message
    assert "spacing >= " in message and "\n" not in message
    assert scene.bodies == []


def test_spacing_that_fits_is_not_refused_early(monkeypatch):
    """The early check refuses only what cannot fit: 2e5 particles with 100 GB free are sampled as before."""
    monkeypatch.setattr(pdsim.memory, "free_host_memory", lambda: 100.0e9)
    body = pdsim.Scene().add_peridynamic_body(pdsim.box((0.2, 0.2, 0.2)), MAT, 0.01)
    assert body.particle_count == 8000
