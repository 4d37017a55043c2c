"""The damage at which a particle is drawn as a chip comes from its body's material (Material.chip_damage): the
rendered surface (pdsim/fragment_surfaces, step 7), the share of chips a run reports (chip_shares) and the checks of
the field."""

import numpy as np
import pytest
from bond_helpers import break_bonds_across_planes

import pdsim
from pdsim.errors import ParameterError
from pdsim.materials import CHIP_DAMAGE

H = 0.02  # [m]
CENTRE = np.array([500.0, -300.0, 40.0])  # [m]: far from the origin


def _box_cut(chip_damage, axes=(0, 1)):
    """A 16 cm box (8 x 8 x 8 particles on the lattice at H, placed at CENTRE) of a breakable material with
    ``chip_damage``, every bond across the planes through its centre normal to ``axes`` broken by hand (nothing run):
    cut into quarters by default, into eighths with axes (0, 1, 2); returns (solver, rest positions relative to the
    centre)."""
    material = pdsim.Material(
        density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.25, critical_stretch=0.01, chip_damage=chip_damage
    )
    body = pdsim.PeridynamicBody(pdsim.box((0.16, 0.16, 0.16), center=tuple(CENTRE)), material, H)
    solver = pdsim.SolverPeridynamics([body])
    x = body.rest_positions - CENTRE
    break_bonds_across_planes(solver, x, axes=axes)
    return solver, x


def _drawn(solver, regions, pieces, chips):
    """The solver's chip share, and its render surface's regions and fragments, are those given."""
    assert solver.chip_shares() == {"box": pytest.approx(chips, abs=1e-9)}
    _, surface = solver.views()
    surfaces = solver._surfaces[0]
    assert surfaces.damage_threshold == solver.bodies[0].material.chip_damage
    assert surfaces.fragment_count == regions
    assert len(np.unique(surface.face_attributes["fragment"])) == pieces


def test_the_edge_where_two_cracks_meet_is_drawn_in_its_pieces_from_chip_damage_07():
    """The box cut into quarters: the particles on the edge where the two cuts meet (one column of 2 x 2 particles
    through the box) have damage 0.60 away from the box's faces (between the lattice counts 0.62 of an edge and 0.38
    of one face), the most of any particle. With chip_damage 0.5 (the default) those 32 particles, 6.25 % of the
    box, are chips: the surface has 4 shells and 32 chips (36 regions). With 0.7 nothing is a chip: the 4 quarters
    alone, and no share of chips reported."""
    for chip_damage, chips, regions in ((CHIP_DAMAGE, 32 / 512, 36), (0.7, 0.0, 4)):
        solver, x = _box_cut(chip_damage)
        damage = solver.damage()
        edge = (np.abs(x[:, 0]) < H) & (np.abs(x[:, 1]) < H)
        deep = edge & (np.abs(x[:, 2]) < 0.08 - 3.0 * H)
        assert damage[deep] == pytest.approx(0.60, abs=0.01)
        assert damage.max() == pytest.approx(damage[edge].max()) and damage[~edge].max() < 0.5
        _drawn(solver, regions, 4, chips)


def test_the_corner_where_three_cracks_meet_is_drawn_in_its_pieces_from_the_presets_chip_damage():
    """The box cut into eighths: the 8 particles at the corner where the three cuts meet have damage 0.75, the most of
    any particle (the edges where two cuts meet: at most 0.66). With chip_damage 0.7 they are chips: 8 shells and 8
    chips (16 regions, 1.6 % of the box as chips). With the brittle presets' pdsim.presets.CHIP_DAMAGE (0.8) nothing
    is a chip: each of the 8 pieces keeps its corner."""
    for chip_damage, chips, regions in ((0.7, 8 / 512, 16), (pdsim.presets.CHIP_DAMAGE, 0.0, 8)):
        solver, x = _box_cut(chip_damage, axes=(0, 1, 2))
        damage = solver.damage()
        corner = np.all(np.abs(x) < H, axis=1)
        assert corner.sum() == 8
        assert damage[corner] == pytest.approx(0.75, abs=0.01)
        assert damage[~corner].max() < 0.67
        _drawn(solver, regions, 8, chips)


def test_chip_damage_checks():
    """chip_damage lies in (0, 1] (the error names the field and the range), and a material that never breaks
    keeps the default (it has no damage to draw)."""
    for bad in (0.0, -0.1, 1.5, float("nan")):
        with pytest.raises(ParameterError, match="chip_damage"):
            pdsim.Material(density=1.0, youngs_modulus=1.0, poisson_ratio=0.2, critical_stretch=0.01, chip_damage=bad)
    assert pdsim.Material(1.0, 1.0, 0.2, critical_stretch=0.01, chip_damage=1.0).chip_damage == 1.0
    with pytest.raises(ParameterError, match=r"chip_damage.*never breaks"):
        pdsim.Material(density=1.0, youngs_modulus=1.0, poisson_ratio=0.2, chip_damage=0.7)
    assert pdsim.Material(density=1.0, youngs_modulus=1.0, poisson_ratio=0.2).chip_damage == CHIP_DAMAGE


def test_brittle_presets_draw_chips_from_08_and_plain_ones_from_05():
    """The brittle presets with their break pattern take pdsim.presets.CHIP_DAMAGE (0.8); without it (pattern=False)
    the default 0.5."""
    for name in pdsim.presets.BRITTLE:
        assert pdsim.presets.preset(name).chip_damage == pdsim.presets.CHIP_DAMAGE == 0.8
        assert pdsim.presets.preset(name, pattern=False).chip_damage == CHIP_DAMAGE == 0.5
