"""Refusals that must be fast or name the right cause: a spacing asking for 150 million particles is refused before
any sampling, in under 5 s; a lattice leader driven out of the float32 range names its leader path, not the rule."""

from __future__ import annotations

import time

import pytest

import pdsim
import pdsim.memory
from pdsim.lattice import Lattice, LatticeBody

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


def test_lattice_leader_out_of_range_names_the_leader_path(tmp_path):
    """Leaders moving 1e38 m per step leave float32 within 4 steps (NaN displacements): the divergence message names
    leader path 0 and the units of its velocity, not the follower rule's k."""
    body = LatticeBody.block(Lattice.square(1.0), (8, 6), name="block")
    x = body.rest_positions[: body.body_count, 0]
    body.clamp(x < x.min() + 0.5)
    body.add_leaders(x > x.max() - 0.5, velocity=(1.0e38, 0.0, 0.0))
    scene = pdsim.Scene(frames=1)
    scene.add_body(body)
    with pytest.raises(pdsim.InstabilityError) as info:
        scene.run(tmp_path / "out.usdc", device="cpu", progress=False)
    message = str(info.value)
    assert "the leaders added with velocity (1e+38, 0, 0) m/step" in message, message
    assert "metres per step" in message
    assert "rule's k" not in message
