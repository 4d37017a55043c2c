"""The brittle presets break into shards, not dust, at the preview spacing: a 30 cm sphere of each dropped onto the
ground at 6 m/s, and the same sphere on the ground hit by a dynamic steel ball (5 cm radius, 4.1 kg) coming down at
22 m/s (tools/preview_final.py; docs/fracture.md, "Presets at preview and final spacing")."""

import dataclasses
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from bond_helpers import bond_ends, break_bonds_across_planes

import pdsim
from pdsim.rigid import RigidBody
import preview_final as pf  # tools/preview_final.py (tests/conftest.py puts tools/ on the path)

# The cases that do not meet the figures as the render draws the sphere (none since plaster took ceramic's wave
# speed, 2026-12-06: the plaster hit drew 22.7 % of what broke out as chips or small pieces before). Strict: a case
# listed here that starts to pass fails until it is moved out.
NOT_MET: dict[tuple[str, str], str] = {}
# The figures at the presets' strength seed 0 (tools/preview_final.py --spacings 0.02): broken out, dust and
# fragments over 5 % by the live bonds, the share of the sphere drawn as chips and the drawn pieces over 5 %.
FIGURES = {
    ("glass", "drop"): (0.557, 0.001, 5, 0.055, 6),
    ("ceramic", "drop"): (0.646, 0.000, 4, 0.009, 4),
    ("stone", "drop"): (0.647, 0.000, 4, 0.006, 4),
    ("plaster", "drop"): (0.647, 0.000, 5, 0.007, 5),
    ("glass", "hit"): (0.626, 0.006, 5, 0.074, 5),
    ("ceramic", "hit"): (0.591, 0.003, 6, 0.067, 5),
    ("stone", "hit"): (0.492, 0.000, 3, 0.045, 4),
    ("plaster", "hit"): (0.413, 0.008, 5, 0.147, 6),
}
# The critical stretches at the 2 cm reference spacing that the ceramic, stone and plaster presets state.
STATED_STRETCH = {"ceramic": 0.006, "stone": 0.006, "plaster": 0.006}
CASES = [
    pytest.param(p, c, marks=pytest.mark.xfail(strict=True, reason=NOT_MET[p, c])) if (p, c) in NOT_MET else (p, c)
    for p in pf.BRITTLE
    for c in pf.CASES
]


@pytest.mark.parametrize(("preset", "case"), CASES)
def test_brittle_preset_breaks_into_shards_at_preview_spacing(preset, case):
    """At the preview spacing (2 cm: 15 particles across the sphere, 1,791 particles) after 40 ms: at most 20 % of
    the broken-out mass is dust and at least 3 fragments each hold more than 5 % of the body's mass, both as the live
    bonds join the particles (dust: fragments of fewer than 8 particles) and as the render draws them (dust: the
    chips, particles whose damage reaches the preset's chip_damage 0.8, and pieces of fewer than 8 particles). Every
    case meets both (the plaster hit, at 18.5 % drawn dust, nearest the limit; NOT_MET, FIGURES)."""
    r = pf.measure(preset, case, pf.PREVIEW_SPACING)
    assert r["particles"] == 1791
    assert r["dust"] <= 0.20, r
    assert r["big"] >= 3, r
    assert r["drawn_dust"] <= 0.20, r
    assert r["drawn_big"] >= 3, r


@pytest.mark.parametrize(("preset", "case"), sorted(FIGURES))
def test_brittle_preset_figures(preset, case):
    """The figures at strength seed 0 (FIGURES): broken out and dust within 0.005 absolute and the fragment count
    exact, by the live bonds; the share drawn as chips within 0.005 and the drawn pieces exact. By the live bonds
    every case meets the shard figures (dust at most 20 % of what broke out, at least 3 fragments over 5 %; over
    seeds 0-9 see docs/fracture.md), and as drawn each keeps 4 to 6 pieces over 5 % with 0.6 to 15 % of the sphere
    as chips (93-97 % for the drops before the cells, 19-35 % with chip_damage 0.5, 4-27 % with 0.7)."""
    r = pf.measure(preset, case, pf.PREVIEW_SPACING)
    broken_out, dust, big, chips, drawn_big = FIGURES[preset, case]
    assert r["broken_out"] == pytest.approx(broken_out, abs=0.005), r
    assert r["dust"] == pytest.approx(dust, abs=0.005), r
    assert r["big"] == big, r
    assert r["chips"] == pytest.approx(chips, abs=0.005), r
    assert r["drawn_big"] == drawn_big, r
    assert pf.meets(r), r


def test_a_dropped_sphere_cracks_along_its_cells_walls():
    """The glass drop at the preview spacing: of the bonds that broke, 73 % cross a cell wall, where 36 % of all bonds
    do (asserted: over 60 %, and 1.5 times the share of all bonds); with the cells' interiors as strong as their
    walls (strength_cell_ratio 1: the same cells, no pattern), the broken bonds cross walls as often as all bonds do
    (36 %), and 93 % of all bonds break instead of 50 %."""
    from pdsim.peridynamics.model import _strength_cells

    shares = {}
    for ratio in (pdsim.presets.CELL_RATIO, 1.0):
        scene = pf.build_case("drop", dataclasses.replace(pdsim.presets.glass(), strength_cell_ratio=ratio), 0.02)
        solver, _ = pf.run_scene(scene)
        k, j = bond_ends(solver.model)
        body = scene.bodies[0]
        cell, _ = _strength_cells([body], [body.particle_count])
        wall = cell[k] != cell[j]
        broken = solver.state.bond_alive.numpy()[: len(k)] == 0
        shares[ratio] = (wall[broken].mean(), wall.mean(), broken.mean())
    walls, everywhere, broken = shares[pdsim.presets.CELL_RATIO]
    assert walls > 0.6 and walls > 1.5 * everywhere, shares
    assert shares[1.0][0] < 1.2 * shares[1.0][1], shares
    assert broken < 0.7 < shares[1.0][2], shares


def test_brittle_presets_share_glass_impact_strain_ratio():
    """Glass, porcelain, ceramic, stone and plaster (animation values) take, at the 2 cm reference spacing, the
    critical stretch that gives a 6 m/s
    impact the same strain over breaking strain, v / (c s_c) with c = sqrt(E / rho), as glass: within 5 % of
    pdsim.presets.IMPACT_STRAIN_RATIO (23; porcelain 22.2), where the former ceramic, stone and plaster strains gave 35,
    46 and 73; and their breaking stresses E s_c keep the real materials' order (glass, porcelain > stone > ceramic >
    plaster)."""
    ratio = {}
    stress = {}
    horizon = pdsim.presets.REFERENCE_HORIZON_FACTOR * pdsim.presets.REFERENCE_SPACING
    for name in ("glass", "porcelain", "ceramic", "stone", "plaster"):
        m = pdsim.presets.preset(name)
        s_c = m.critical_stretch_for(horizon)
        ratio[name] = pf.SPEED / (np.sqrt(m.youngs_modulus / m.density) * s_c)
        stress[name] = m.youngs_modulus * s_c
    for name, value in ratio.items():
        assert value == pytest.approx(pdsim.presets.IMPACT_STRAIN_RATIO, rel=0.05), (name, value)
    assert stress["glass"] >= stress["porcelain"] > stress["stone"] > stress["ceramic"] > stress["plaster"], stress


def test_plain_presets_fail_the_shard_figures():
    """The plain glass (pattern=False) dropped as above turns what breaks out to dust (the dust figure over 20 % or
    fewer than 3 large fragments): the pattern settings, not the case, give the shards."""
    solver, _ = pf.run_scene(pf.build_case("drop", pdsim.presets.glass(pattern=False), pf.PREVIEW_SPACING))
    r = pf.figures(solver)
    assert r["dust"] > 0.20 or r["big"] < 3, r


@pytest.mark.parametrize("case", pf.CASES)
def test_the_cases_break_alike_far_from_the_origin(case):
    """The glass drop and hit at the preview spacing, moved 1.1 km away ((1000, -500, 250) m, the ground plane
    with them), give the figures of the cases at the origin: broken out, dust, the drawn chips and drawn dust within
    1e-3, the fragment counts, n80 and drawn pieces exact (measured: the same to the fourth decimal)."""
    figures = []
    for offset in ((0.0, 0.0, 0.0), (1000.0, -500.0, 250.0)):
        scene = pf.build_case(case, pdsim.presets.glass(), pf.PREVIEW_SPACING, offset=offset)
        solver, _ = pf.run_scene(scene)
        figures.append(pf.figures(solver))
    near, far = figures
    for key in ("broken_out", "dust", "chips", "drawn_dust"):
        assert far[key] == pytest.approx(near[key], abs=1.0e-3), (key, near, far)
    for key in ("fragments", "big", "n80", "drawn_big"):
        assert far[key] == near[key], (key, near, far)
    assert near["broken_out"] > 0.3, near  # the case breaks: the comparison is of a broken sphere


def test_hit_speed_loads_the_glass_sphere_as_the_drop_does():
    """hertz_load's peak forces hold the energy balance of an elastic Hertz contact: the work of F = k x^1.5 up to the
    peak overlap, 0.4 F_max d_max, equals the kinetic energy 0.5 m v^2 of the sphere (drop) or of the ball and sphere's
    reduced mass (hit), to 1e-9 relative, with d_max from F_max; and at HIT_SPEED the hit's peak force on the glass
    sphere is 0.93 of the drop's (asserted within 0.85 and 1.0), where at 6 m/s it was 0.20 (within 0.15 and 0.25)."""
    glass = pdsim.presets.glass()
    e_star = glass.youngs_modulus / (1.0 - glass.poisson_ratio**2)  # the ball and the ground rigid
    sphere = glass.density * np.pi / 6.0 * pf.DIAMETER**3
    ball = pf.BALL_DENSITY * 4.0 / 3.0 * np.pi * pf.BALL_RADIUS**3
    radius = pf.DIAMETER / 2.0
    cases = {
        "drop": (radius, sphere, pf.SPEED),
        "hit": (radius * pf.BALL_RADIUS / (radius + pf.BALL_RADIUS), ball * sphere / (ball + sphere), pf.HIT_SPEED),
    }
    force = {}
    for case, (r_eff, mass, speed) in cases.items():
        force[case] = pf.hertz_load(glass, case)["force"]
        overlap = (3.0 * force[case] / (4.0 * e_star * np.sqrt(r_eff))) ** (2.0 / 3.0)
        assert 0.4 * force[case] * overlap == pytest.approx(0.5 * mass * speed**2, rel=1e-9), case
    assert 0.85 < force["hit"] / force["drop"] < 1.0, force
    slow = pf.hertz_load(glass, "hit", hit_speed=6.0)["force"] / force["drop"]
    assert 0.15 < slow < 0.25, slow


def test_hit_ball_is_dynamic_and_bounces():
    """The hit's ball is a dynamic rigid body of steel (7850 kg/m^3, 5 cm radius: 4.11 kg) at 22 m/s: after the 40 ms of
    the run on a glass sphere it moves up (it bounced off: 2.5 m/s, 1.5 m/s of it upwards), where a kinematic ball would
    still come down at 22 m/s, and the momentum it lost went into the sphere and the ground, not nowhere: its speed
    stays below a quarter of the 22 m/s."""
    scene = pf.build_case("hit", pdsim.presets.glass(), pf.PREVIEW_SPACING)
    (ball,) = [c for c in scene.colliders if isinstance(c, RigidBody)]
    assert ball.mass == pytest.approx(7850.0 * 4.0 / 3.0 * np.pi * 0.05**3, rel=1e-9)
    pf.run_scene(scene)
    v = ball.state_values()["velocity"]
    assert v[2] > 0.0, v
    assert np.linalg.norm(v) < 0.25 * pf.HIT_SPEED, v


def test_figures_count_dust_big_pieces_and_n80():
    """figures() on hand-made labels: a body of 100 unit-mass particles with a main piece of 50, pieces of 20, 12 and
    10 and 8 single particles: broken out 50 %, dust 8 / 50, big pieces (> 5 kg) 4, n80 = 3 (20 + 12 + 10 = 42 >=
    40). With the body's volume set so that a 4 cm cube holds 11 kg, the pieces in metres are 20 and 12: dust_m
    18 / 50, n80_m = 2 (20 < 0.8 * 32 <= 32); fragments over 1 % (1 kg): 4."""

    class Fake(_Bonded):
        def __init__(self):
            super().__init__(100, [])

        def fragment_ids(self):
            return np.concatenate([np.zeros(50), np.full(20, 1), np.full(12, 2), np.full(10, 3), 4 + np.arange(8)])

    r = pf.figures(Fake(), volume=100.0 * pf.PIECE_SIZE**3 / 11.0)
    assert r["broken_out"] == pytest.approx(0.5)
    assert r["dust"] == pytest.approx(8 / 50)
    assert r["big"] == 4
    assert r["n80"] == 3
    assert r["dust_m"] == pytest.approx(18 / 50)
    assert r["n80_m"] == 2
    assert r["big1"] == 4


class _Bonded:
    """A stand-in solver: ``n`` unit-mass particles, the undirected bonds ``pairs`` (both directions stored, as the
    solver's families), ``broken`` of them broken, the damage of each particle ``damage`` and the material's
    ``chip_damage``."""

    def __init__(self, n, pairs, broken=(), damage=None, chip_damage=0.5):
        pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        first = np.concatenate([pairs[:, 0], pairs[:, 1]])
        second = np.concatenate([pairs[:, 1], pairs[:, 0]])
        alive = np.concatenate([np.ones(len(pairs), dtype=bool)] * 2)
        for a, b in broken:
            alive[((first == a) & (second == b)) | ((first == b) & (second == a))] = False
        order = np.argsort(first, kind="stable")
        self._alive = alive[order]
        offsets = np.concatenate([[0], np.cumsum(np.bincount(first, minlength=n))])
        self.model = SimpleNamespace(
            family_offsets=SimpleNamespace(numpy=lambda: offsets),
            family_neighbors=SimpleNamespace(numpy=lambda: second[order]),
        )
        self.bodies = [SimpleNamespace(material=SimpleNamespace(chip_damage=chip_damage))]
        self._n = n
        self._damage = np.zeros(n) if damage is None else np.asarray(damage, dtype=np.float64)

    def body_slice(self, _):
        return slice(0, self._n)

    def masses(self):
        return np.ones(self._n)

    def damage(self):
        return self._damage

    def bond_alive(self):
        return self._alive


def test_drawn_figures_count_chips_and_the_pieces_between_them():
    """drawn_figures() on a hand-made body of 30 unit-mass particles: a chain 0-14 whose bond 6-7 is broken and a chain
    15-29 whose particles 15-17 have damage 1.0, 0.7 and 0.5 (chips, the 0.5 itself included). Drawn: chips 3 / 30,
    pieces of 7, 8 and 12 particles, all over 5 % of the body; the broken-out mass (all but the 12) is 18, of which dust
    is the 3 chips and the piece of 7 (fewer than 8 particles): 10 / 18. With the material's chip_damage at 0.7 instead,
    particle 17 joins the piece of 12 (13 particles): chips 2 / 30, broken out 17, dust 9 / 17."""
    pairs = [(i, i + 1) for i in range(14)] + [(i, i + 1) for i in range(15, 29)]
    damage = np.zeros(30)
    damage[15:18] = [1.0, 0.7, 0.5]
    damage[18] = 0.49
    r = pf.drawn_figures(_Bonded(30, pairs, broken=[(6, 7)], damage=damage))
    assert r["chips"] == pytest.approx(3 / 30)
    assert r["drawn_big"] == 3
    assert r["drawn_dust"] == pytest.approx(10 / 18)
    r = pf.drawn_figures(_Bonded(30, pairs, broken=[(6, 7)], damage=damage, chip_damage=0.7))
    assert r["chips"] == pytest.approx(2 / 30)
    assert r["drawn_big"] == 3
    assert r["drawn_dust"] == pytest.approx(9 / 17)


@pytest.mark.parametrize("name", pdsim.presets.BRITTLE)
def test_brittle_presets_hold_their_fracture_energy_at_every_spacing(name):
    """Each brittle preset (animation values, with and without its pattern) gives its strength as a fracture energy:
    its bonds' critical stretch, as the solver sets it (the plain material: no strength scatter), is the preset's
    stated stretch at the 2 cm reference spacing and sqrt 2 times it at 1 cm (1e-6 relative: float32), so
    G = c_G delta s_c^2 is the same at both (s_c fixed in strain would halve it at 1 cm and fail here). A material
    given a critical_stretch keeps exactly that one at every spacing."""
    presets = pdsim.presets
    shape = pdsim.box((0.12, 0.12, 0.12), center=(1000.0, -500.0, 20.0))
    stretch = {}
    for spacing in (0.02, 0.01):
        for material in (presets.preset(name, pattern=False), presets.preset(name)):
            body = pdsim.PeridynamicBody(shape, material, spacing)
            assert body.horizon == pytest.approx(presets.REFERENCE_HORIZON_FACTOR * spacing, rel=1e-12)
            g = material.crack_energy_modulus * body.horizon * material.critical_stretch_for(body.horizon) ** 2
            assert g == pytest.approx(material.fracture_energy, rel=1e-12)
        solver = pdsim.SolverPeridynamics([pdsim.PeridynamicBody(shape, presets.preset(name, pattern=False), spacing)])
        stretch[spacing] = solver.model.bond_critical_stretch.numpy()[: solver.model.bond_count]
    reference = presets.preset(name).critical_stretch_for(presets.REFERENCE_HORIZON_FACTOR * presets.REFERENCE_SPACING)
    assert np.allclose(stretch[0.02], reference, rtol=1e-6, atol=0.0)
    assert np.allclose(stretch[0.01], np.sqrt(2.0) * reference, rtol=1e-6, atol=0.0)
    fixed = dataclasses.replace(presets.preset(name), fracture_energy=None, critical_stretch=0.004)
    assert fixed.critical_stretch_for(0.06) == fixed.critical_stretch_for(0.03) == 0.004


def test_preset_stretch_stated_at_reference_spacing():
    """The animation presets' fracture energies give, at the 2 cm reference spacing, the stretches their docstrings
    state (glass and porcelain 0.005, concrete 0.002; ceramic, stone and plaster as tuned), and
    energy_for_stretch inverts Material.critical_stretch_for."""
    presets = pdsim.presets
    horizon = presets.REFERENCE_HORIZON_FACTOR * presets.REFERENCE_SPACING
    stated = {"glass": 0.005, "porcelain": 0.005, "concrete": 0.002, **STATED_STRETCH}
    for name, s_c in stated.items():
        assert presets.preset(name).critical_stretch_for(horizon) == pytest.approx(s_c, rel=1e-12), name
    m = presets.glass()
    assert presets.energy_for_stretch(m, 0.003, spacing=0.05) == pytest.approx(
        m.crack_energy_modulus * presets.REFERENCE_HORIZON_FACTOR * 0.05 * 0.003**2, rel=1e-12
    )
    with pytest.raises(pdsim.ParameterError, match="critical_stretch"):
        presets.energy_for_stretch(m, -0.1)


@pytest.mark.parametrize(("chip_damage", "chips"), [(0.5, 0.097), (0.7, 0.005), (pdsim.presets.CHIP_DAMAGE, 0.0)])
def test_a_clean_cut_into_quarters_draws_few_chips(chip_damage, chips):
    """The preview sphere of the cases (2 cm, 1,791 particles) cut into four quarters by hand (every bond across the
    planes x = 0 and y = 0 through its centre broken, nothing run): with chip_damage 0.5 (the default) 9.7 % of it is
    drawn as chips (the particles where the two cuts meet, damage about 0.6), with 0.7 0.5 %, with the presets' 0.8
    none, and the four quarters as pieces over 5 %: so a few clean cracks at this spacing draw at most about a tenth
    of a body as chips at the default, where the dropped spheres without cells draw over 90 % (docs/fracture.md,
    "Presets at preview and final spacing")."""
    material = dataclasses.replace(pdsim.presets.glass(), chip_damage=chip_damage)
    scene = pf.build_case("drop", material, pf.PREVIEW_SPACING)
    solver = scene.build_solvers(device="cpu")[0]
    break_bonds_across_planes(solver, solver.model.rest_positions.numpy() - pf.CENTRE, axes=(0, 1))
    r = pf.drawn_figures(solver)
    assert r["chips"] == pytest.approx(chips, abs=0.003), r
    assert r["drawn_big"] == 4, r


def test_a_run_reports_a_body_that_crumbled(tmp_path):
    """Scene.run warns, naming the body and its share, when a breakable body ends the run with half its mass or more
    drawn as chips (pdsim/run.py, CRUMBLED_SHARE): the glass sphere without its cells dropped at 6 m/s (84 % chips
    after 40 ms), and not the same sphere after 2 ms, before it breaks, nor the preset with its cells (6 %)."""
    crumbles = dataclasses.replace(pdsim.presets.glass(), strength_cell_size=None)
    drop = pf.build_case("drop", crumbles, pf.PREVIEW_SPACING)
    with pytest.warns(UserWarning, match=r"body 'sphere' crumbled: 84 % of its mass"):
        drop.run(str(tmp_path / "drop.usdc"), progress=False)
    early = pf.build_case("drop", crumbles, pf.PREVIEW_SPACING, frames=1, duration=0.002)
    shards = pf.build_case("drop", pdsim.presets.glass(), pf.PREVIEW_SPACING)
    for name, scene in (("early", early), ("shards", shards)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            scene.run(str(tmp_path / f"{name}.usdc"), progress=False)
        assert not [w for w in caught if "crumbled" in str(w.message)], name


def test_the_figurine_shot_breaks_alike_at_preview_and_final_spacing():
    """The figurine shot (tools/shot_figurine.py: a 30 cm figurine from ../shared/meshes, the ceramic preset as
    shipped, hit by a 2.5 cm steel ball at 12 m/s, 6 frames) at its 1 cm preview spacing and at 0.5 cm (about a
    minute): the fragments holding 80 % of the broken-out mass agree within a factor of 1.5 (measured 1 and 1), the
    broken-out share within +-30 % (31.5 and 32.1 %), and both draw the same number of pieces over 5 % of the body
    (2: the preset's cells are 20 cm, two thirds of the figurine; before the cells, 4 pieces in a third of chips).
    docs/fracture.md, "Preview against final on the figurine shot"."""
    shot = str(Path(pf.__file__).parent / "shot_figurine.py")
    if not Path(shot).parent.joinpath("..", "..", "shared", "meshes", "homer.obj").resolve().is_file():
        pytest.skip("../shared/meshes is not beside the repository")
    (coarse,) = pf.scene_figures(shot, False, {"spacing": 0.01})
    (fine,) = pf.scene_figures(shot, False, {"spacing": 0.005})
    agree = pf.agreement(coarse, fine)
    assert agree["n80_ratio"] <= 1.5, (coarse, fine)
    assert abs(agree["broken_out_change"]) <= 0.3, (coarse, fine)
    assert coarse["drawn_big"] == fine["drawn_big"] >= 2, (coarse, fine)


def test_stray_is_zero_under_an_affine_motion_and_the_offset_of_a_displaced_particle():
    """tools/preview_final.py stray() on a 16 cm box of 8^3 particles 1 km from the origin: under a rotation, a
    stretch and a translation (an affine motion) every particle lies where its bonded neighbours place it (below
    1e-3 spacings: float32 positions); one interior particle moved 0.3 spacings off it is 0.3 spacings away (its
    family is symmetric, so no fit of its neighbours absorbs the move), within 0.01. The material never breaks, so
    every bond stays live however far the particles are moved."""
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.25)
    h = 0.02
    body = pdsim.PeridynamicBody(pdsim.box((0.16, 0.16, 0.16), center=(1000.0, -200.0, 30.0)), material, h)
    solver = pdsim.SolverPeridynamics([body])
    rest = solver.model.rest_positions.numpy().astype(np.float64)
    turn = np.array([[0.8, -0.6, 0.0], [0.6, 0.8, 0.0], [0.0, 0.0, 1.0]])
    affine = turn @ np.diag([1.05, 0.97, 1.02])
    centre = rest.mean(axis=0)
    u = (rest - centre) @ (affine - np.eye(3)).T + np.array([0.03, -0.01, 0.02])
    solver.set_displacements(u)
    assert np.nanmax(pf.stray(solver)) < 1.0e-3
    middle = int(np.argmin(np.linalg.norm(rest - centre, axis=1)))
    u[middle] += 0.3 * h * np.array([0.0, 0.6, 0.8])
    solver.set_displacements(u)
    assert pf.stray(solver)[middle] == pytest.approx(0.3, abs=0.01)


def test_the_presets_chip_damage_keeps_in_the_pieces_the_particles_that_move_with_them():
    """The plaster sphere hit by the ball at 2 cm (the case whose crushed zone is largest): the particles below the
    presets' chip_damage (0.8) lie, by median, within 0.25 spacings of where their bonded neighbours place them in
    every damage band (measured 0.09 to 0.11), as the undamaged ones do (0.08); those at or above it, the crushed
    material under the ball that the render draws as chips, lie further than any band below (measured 0.18 for
    0.8-0.85), and from 0.85 up over 0.3 (0.33 to 0.40). docs/fracture.md, "Presets at preview and final spacing"."""
    solver, _ = pf.run_scene(pf.build_case("hit", pdsim.presets.plaster(), pf.PREVIEW_SPACING))
    chip = pdsim.presets.CHIP_DAMAGE
    bands = pf.stray_by_damage(solver)
    below = [b for b in bands if b["band"][1] <= chip and b["particles"]]
    above = [b for b in bands if b["band"][0] >= chip and b["particles"]]
    assert len(below) == 5 and len(above) == 4, bands
    assert max(b["median"] for b in below) < 0.25, bands
    assert min(b["median"] for b in above) > max(b["median"] for b in below), bands
    assert min(b["median"] for b in above if b["band"][0] >= 0.85) > 0.3, bands
