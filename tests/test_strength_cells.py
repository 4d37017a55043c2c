"""The cell pattern of a material (Material.strength_cell_size, strength_cell_ratio): bonds inside a cell are stronger
than bonds across a cell wall, the cells are those of their points (nearest point, checked by brute force), and they
come from the material and the shape alone: the same at every spacing and wherever the body sits
(pdsim.materials.cell_points, strength_cells; kernels/peridynamics/bonds.py, strengthen_cell_interiors)."""

import dataclasses
import math

import numpy as np
import pytest
from bond_helpers import bond_ends
from scipy.spatial import cKDTree

import pdsim
from pdsim.errors import ParameterError
from pdsim.materials import cell_points, strength_cells
from pdsim.peridynamics.model import build_model

SC = 0.005
CELL = 0.05  # [m]
RATIO = 4.0


def _material(**changes) -> pdsim.Material:
    base = pdsim.Material(
        density=2500.0,
        youngs_modulus=7.0e6,
        poisson_ratio=0.22,
        critical_stretch=SC,
        strength_cell_size=CELL,
        strength_cell_ratio=RATIO,
    )
    return dataclasses.replace(base, **changes)


def _bonds(material, spacing, *, centre=(0.0, 0.0, 0.0)):
    """(particles relative to the shape's centre [m], bond ends k and j, bond factors s / s_c, the shape's bounds) of
    a 12 cm box at ``spacing``."""
    shape = pdsim.box((0.12, 0.12, 0.12), center=centre)
    body = pdsim.PeridynamicBody(shape, material, spacing)
    model = build_model([body], "cpu", origin=body.rest_positions.mean(axis=0))
    k, j = bond_ends(model)
    local = body.rest_positions - np.asarray(centre)
    factors = model.bond_critical_stretch.numpy()[: len(k)].astype(np.float64) / SC
    return local, k, j, factors, shape.bounds


def test_bonds_inside_a_cell_are_stronger_at_every_spacing_and_place():
    """A 12 cm box with cells of 5 cm at h = 2 cm and 1 cm: each particle's cell is its nearest cell point (brute
    force over all points, independent of the KD-tree); a bond is RATIO times s_c exactly where both its particles
    share a cell and s_c elsewhere, and both kinds occur, at both spacings; the cell points do not depend on the
    spacing, and a 1 cm particle well inside a cell takes the cell of the 2 cm particle beside it; the box placed at
    (1000, -500, 250) m gives the same bonds bit for bit. Without cells every bond is s_c (so the check can fail)."""
    mat = _material()
    local, k, j, f, bounds = _bonds(mat, 0.02)
    seeds = cell_points(mat, bounds)
    brute = np.argmin(((local[:, None, :] - seeds[None, :, :]) ** 2).sum(axis=2), axis=1)
    cells = strength_cells(mat, bounds, local)
    assert np.array_equal(cells, brute)
    inside = cells[k] == cells[j]
    assert 0.05 < inside.mean() < 0.95, inside.mean()  # both kinds (11 % inside at 2 cm)
    np.testing.assert_allclose(f[inside], RATIO, rtol=1.0e-6)
    np.testing.assert_allclose(f[~inside], 1.0, rtol=1.0e-6)

    local_f, k_f, j_f, f_f, bounds_f = _bonds(mat, 0.01)
    assert np.array_equal(cell_points(mat, bounds_f), seeds)  # the cells do not depend on the spacing
    cells_f = strength_cells(mat, bounds, local_f)
    inside_f = cells_f[k_f] == cells_f[j_f]
    np.testing.assert_allclose(f_f, np.where(inside_f, RATIO, 1.0), rtol=1.0e-6)
    # a 1 cm particle takes the cell of the 2 cm particle beside it wherever both lie well inside one cell
    dist, idx = cKDTree(local).query(local_f)
    d = np.sort(((local_f[:, None, :] - seeds[None, :, :]) ** 2).sum(axis=2), axis=1)
    deep = np.sqrt(d[:, 1]) - np.sqrt(d[:, 0]) > 2.0 * dist  # farther from the wall than from the 2 cm particle
    assert deep.sum() > 100
    assert np.array_equal(cells_f[deep], cells[idx[deep]])

    _, _, _, f_far, _ = _bonds(mat, 0.02, centre=(1000.0, -500.0, 250.0))
    assert np.array_equal(f_far, f)

    _, _, _, plain, _ = _bonds(dataclasses.replace(mat, strength_cell_size=None), 0.02)
    np.testing.assert_allclose(plain, 1.0, rtol=1.0e-6)


def test_cell_points_have_the_density_of_the_cell_size():
    """Over a 1 m box with cells of 5 cm (the box grown by one cell: 1.1^3 / 0.05^3 = 10,648 points expected) the
    Poisson count lies within 4 standard deviations of its mean for seeds 0-4, the points fill the grown box
    uniformly (each octant within 12 %: 4.7 standard deviations), and two seeds give different points."""
    bounds = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    expected = (1.0 + 2 * CELL) ** 3 / CELL**3
    for seed in range(5):
        p = cell_points(_material(strength_seed=seed), bounds)
        assert abs(len(p) - expected) < 4.0 * math.sqrt(expected), (seed, len(p))
        assert np.all(np.abs(p) <= 0.5 + CELL)
        octant = (p > 0).astype(int) @ np.array([1, 2, 4])
        shares = np.bincount(octant, minlength=8) / len(p)
        np.testing.assert_allclose(shares, 1.0 / 8.0, rtol=0.12)  # 4.7 standard deviations
    a, b = (cell_points(_material(strength_seed=s), bounds) for s in (0, 1))
    assert len(a) != len(b) or not np.array_equal(a, b)


def test_cell_options_are_validated():
    with pytest.raises(ParameterError, match="strength_cell_size"):
        _material(strength_cell_size=0.0)
    with pytest.raises(ParameterError, match="strength_cell_ratio"):
        _material(strength_cell_ratio=0.5)
    with pytest.raises(ParameterError, match="strength_cell_size"):
        pdsim.Material(density=1.0, youngs_modulus=1.0, poisson_ratio=0.2, strength_cell_size=0.1)
    with pytest.raises(ParameterError, match="material"):
        strength_cells(_material(strength_cell_size=None), np.zeros((2, 3)), np.zeros((1, 3)))
    with pytest.raises(ParameterError, match="points"):
        strength_cells(_material(), np.array([[0.0] * 3, [1.0] * 3]), np.zeros((1, 2)))
