"""Contact values that travel with the material (pdsim.Material contact_restitution, contact_friction): each side of a
pair brings its own, and the pair combines them by one rule (pdsim/contact.py combine_restitution: the larger;
combine_friction: the geometric mean), against the ground plane and between the particles of two bodies."""

import math

import numpy as np
import pytest

import pdsim
from pdsim import presets
from pdsim.colliders import GroundPlane
from pdsim.contact import ParticleContact, combine_friction, combine_restitution
from pdsim.errors import ParameterError

H = 0.01


def _material(e=None, mu=None):
    return pdsim.Material(
        density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.25, contact_restitution=e, contact_friction=mu
    )


def _ground_solver(material, size_cells, center_z, velocity, ground, gravity):
    """A PD block of ``size_cells`` particles per axis (h = 1 cm) of ``material`` above ``ground``."""
    size = np.asarray(size_cells, dtype=np.float64) * H
    body = pdsim.PeridynamicBody(pdsim.box(tuple(size), center=(0.0, 0.0, center_z)), material, H, name="block")
    body.set_initial_velocity(velocity)
    return pdsim.SolverPeridynamics([body], ground=ground, gravity=gravity, device="cpu", threads=1)


def test_combining_rule_and_checks():
    """The larger restitution, the geometric mean of the frictions, the other side's where one brings none (NaN)."""
    np.testing.assert_array_equal(combine_restitution([0.1, 0.8, np.nan, 0.3], [0.6, 0.2, 0.4, np.nan]),
                                  [0.6, 0.8, 0.4, 0.3])  # fmt: skip
    np.testing.assert_allclose(combine_friction([0.4, np.nan, 0.0], [0.9, 0.5, 0.7]), [0.6, 0.5, 0.0])
    assert np.isnan(combine_friction(np.nan, np.nan))
    for field, value in (("contact_restitution", 0.0), ("contact_restitution", 1.2), ("contact_friction", -0.1)):
        with pytest.raises(ParameterError, match=field):
            pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.25, **{field: value})
    assert _material(1.0, 0.0).contact_restitution == 1.0


@pytest.mark.parametrize(("e_material", "e_ground"), [(0.1, None), (0.6, 0.1), (0.1, 0.6)])
def test_drop_rebounds_at_the_combined_restitution(e_material, e_ground):
    """A rigid particle (a one-cell PD block: no bonds, no elastic energy of its own) of a material with restitution
    ``e_material`` thrown at a ground plane of restitution ``e_ground`` (None: the ground brings none) at 2 m/s (no
    gravity) leaves at the pair's combined restitution, the larger of the two, within 0.05 over four phases of a step
    at which the contact starts (the method of tests/test_contact_law.py). With the ground's value alone (the rule
    ignored) the (0.6, 0.1) case would leave at 0.1 and fail; with the material's alone the (0.1, 0.6) case would."""
    expected = max(e_material, e_ground or 0.0)
    dt = 1.28e-4
    rebounds = []
    for phase in np.arange(4) / 4.0:
        solver = _ground_solver(_material(e_material), (1, 1, 1), 0.5 * H + 1.0e-3 + phase * 2.0 * dt,
                                (0.0, 0.0, -2.0), GroundPlane(restitution=e_ground, friction=0.0),
                                (0.0, 0.0, 0.0))  # fmt: skip
        for _ in range(60):
            solver.step(dt)
        rebounds.append(float(solver.velocities()[0, 2]) / 2.0)
    print(f"material {e_material}, ground {e_ground}: rebound {min(rebounds):.3f} to {max(rebounds):.3f}")
    np.testing.assert_allclose(rebounds, expected, atol=0.05)


@pytest.mark.parametrize("floor", ["ground", "mesh"])
def test_block_sliding_with_a_material_friction_stops_at_v2_over_2_mu_g(floor):
    """A 3 x 3 x 2 h PD block of a material with contact_friction 0.64 sliding at 1 m/s on a floor of friction 0.25
    (the ground plane's inelastic projection, or a static MeshCollider slab; gravity 9.81 m/s^2) takes the pair's
    friction sqrt(0.64 x 0.25) = 0.4 and stops after v^2 / (2 mu g) = 12.7 cm within 5 % (the floor's 0.25 alone
    would give 20.4 cm, the material's 0.64 alone 8.0 cm)."""
    g, v = 9.81, 1.0
    mu = math.sqrt(0.64 * 0.25)
    size = np.array([3, 3, 2]) * H
    body = pdsim.PeridynamicBody(pdsim.box(tuple(size), center=(0.0, 0.0, H)), _material(None, 0.64), H, name="b")
    body.set_initial_velocity((v, 0.0, 0.0))
    floors = {"ground": {"ground": GroundPlane(friction=0.25)},
              "mesh": {"colliders": [pdsim.MeshCollider(pdsim.box((1.0, 0.4, 0.1), center=(0.2, 0.0, -0.05)),
                                                        friction=0.25)]}}  # fmt: skip
    solver = pdsim.SolverPeridynamics([body], gravity=(0.0, 0.0, -g), device="cpu", threads=1, **floors[floor])
    dt = 0.7 * solver.stable_time_step()
    x0 = solver.positions()[:, 0].mean()
    for _ in range(int(1.2 * v / (mu * g) / dt)):
        solver.step(dt)
    moved = solver.positions()[:, 0].mean() - x0
    print(f"stopped after {moved:.4f} m, v^2 / (2 mu g) = {v**2 / (2.0 * mu * g):.4f} m")
    assert abs(solver.velocities()[:, 0].mean()) < 0.01 * v
    assert moved == pytest.approx(v**2 / (2.0 * mu * g), rel=0.05)


def test_particle_pair_takes_the_combined_friction_and_damping():
    """Two particles of different bodies overlapping and sliding past each other: the pair's force is the one of the
    scene-level law at the combined values (restitution: the larger, i.e. the smaller damping ratio; friction: the
    geometric mean), the same as a contact built with those values for the whole scene."""
    rest = np.array([[0.0, 0.0, 0.0], [0.009, 0.0, 0.0]])
    common = {"body_id": [0, 1], "radius": 0.005, "volume": 1.0e-6, "density": 1000.0, "bulk_modulus": 1.0e6,
              "shear_modulus": 6.0e5, "horizon": 0.03, "shield_interior": False, "floor_factor": 0.0}  # fmt: skip
    v = np.array([[-0.5, 0.3, 0.0], [0.5, -0.3, 0.0]], dtype=np.float32)

    def force(contact):
        import warp as wp

        x = wp.array(rest.astype(np.float32), dtype=wp.vec3)
        f = wp.zeros(2, dtype=wp.vec3)
        contact.apply(x, wp.zeros(2, dtype=wp.vec3), wp.array(v, dtype=wp.vec3), f)
        return f.numpy()

    per_material = ParticleContact(rest, **common, restitution=0.9, friction=0.05,
                                   point_restitution=[0.2, 0.5], point_friction=[0.25, 0.64])  # fmt: skip
    combined = ParticleContact(rest, **common, restitution=0.5, friction=0.4)
    scene_only = ParticleContact(rest, **common, restitution=0.9, friction=0.05)
    f_material, f_combined = force(per_material), force(combined)
    np.testing.assert_allclose(f_material, f_combined, rtol=1e-5)
    f_scene = force(scene_only)  # the scene's values alone: friction 0.05 instead of 0.4
    assert abs(f_material[0, 1] - f_scene[0, 1]) > 0.5 * abs(f_material[0, 1])
    assert abs(f_material[0, 0] - f_scene[0, 0]) > 0.01 * abs(f_material[0, 0])


def test_material_values_act_across_crack_faces_within_one_body():
    """Two particles of one body (rest 2 cm apart, pressed to 9 mm, sliding past each other) with their bonds handed
    over (track_bonds): with their bond alive (intact neighbours) the pair's force is the scene's law alone; with it
    broken (a crack face) the combined material values, as between two bodies. With no bond between them (beyond
    each other's horizon), a particle that has lost all its bonds (damage 1 >= 0.25) makes the pair a crack face, an
    undamaged pair (damage 0) keeps the scene's law. Forces equal to 1e-5 (relative) to the contact built with the
    scene's or the combined values alone, and the two differ by over half the tangential force."""
    import warp as wp

    rest = np.array([[0.0, 0.0, 0.0], [0.02, 0.0, 0.0], [-0.05, 0.0, 0.0], [0.07, 0.0, 0.0]])
    x = rest.copy()
    x[1, 0] = 0.009
    v = np.array([[-0.5, 0.3, 0.0], [0.5, -0.3, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]], dtype=np.float32)
    common = {"body_id": [0, 0, 0, 0], "radius": 0.005, "volume": 1.0e-6, "density": 1000.0, "bulk_modulus": 1.0e6,
              "shear_modulus": 6.0e5, "horizon": 0.03, "shield_interior": False, "floor_factor": 0.0}  # fmt: skip

    def force(neighbors, alive, **values):
        contact = ParticleContact(rest, **common, **values)
        counts = np.array([1, 1, 1, 1])
        offsets = wp.array(np.concatenate([[0], np.cumsum(counts)]).astype(np.int32), dtype=wp.int32)
        contact.track_bonds(
            offsets,
            wp.array(np.asarray(neighbors, dtype=np.int32), dtype=wp.int32),
            wp.array(np.asarray(alive, dtype=np.uint8), dtype=wp.uint8),
            wp.ones(4, dtype=wp.uint8),
        )
        f = wp.zeros(4, dtype=wp.vec3)
        contact.apply(wp.array(x.astype(np.float32), dtype=wp.vec3), wp.zeros(4, dtype=wp.vec3),
                      wp.array(v, dtype=wp.vec3), f)  # fmt: skip
        return f.numpy()[:2]

    material = {"restitution": 0.9, "friction": 0.05, "point_restitution": [0.2, 0.5, 0.2, 0.5],
                "point_friction": [0.25, 0.64, 0.25, 0.64]}  # fmt: skip
    bonded = [1, 0, 3, 2]  # families: 0-1 and 2-3 bonded
    unbonded = [2, 3, 0, 1]  # 0-2 and 1-3 bonded: no bond between 0 and 1
    combined = force(bonded, [1, 1, 1, 1], restitution=0.5, friction=0.4)
    scene = force(bonded, [1, 1, 1, 1], restitution=0.9, friction=0.05)
    assert abs(combined[0, 1] - scene[0, 1]) > 0.5 * abs(combined[0, 1])
    np.testing.assert_allclose(force(bonded, [1, 1, 1, 1], **material), scene, rtol=1e-5)  # intact
    np.testing.assert_allclose(force(bonded, [0, 0, 1, 1], **material), combined, rtol=1e-5)  # broken
    np.testing.assert_allclose(force(unbonded, [0, 1, 0, 1], **material), combined, rtol=1e-5)  # damage 1
    np.testing.assert_allclose(force(unbonded, [1, 1, 1, 1], **material), scene, rtol=1e-5)  # damage 0


def test_strong_dashpot_on_many_contacts_only_takes_energy_out():
    """A particle in contact with its 12 neighbours of another body (an fcc shell 12.5 mm away, contact distance
    13.5 mm) moving at 1 m/s among them (they are held), with a restitution of 0.05 (damping ratio 1.95) on every
    pair, stepped with velocity Verlet at 0.7 of the contact's stable step for 400 steps: the energy (kinetic plus
    contact) never rises above its start (to 1e-6 relative), over half of the centre's kinetic energy is taken out, and
    the dashpot cap scales the centre's dashpots by 1 / (T sum_j zeta c_crit V / m) < 1 (float32, 1e-4). Without the cap
    (the centre's dashpots at 13.5 times the explicit bound) the centre's
    velocity flips and grows each step and the energy rises."""
    import warp as wp

    shell = np.array([[a, b, 0.0] for a in (-1, 1) for b in (-1, 1)] + [[a, 0.0, b] for a in (-1, 1) for b in (-1, 1)]
                     + [[0.0, a, b] for a in (-1, 1) for b in (-1, 1)]) / np.sqrt(2.0)  # fmt: skip
    rest = np.vstack([np.zeros(3), 0.0125 * shell]) + np.array([1000.0, -200.0, 50.0])  # far from the origin
    n = len(rest)
    rho, vol = 1000.0, 1.0e-6
    contact = ParticleContact(rest - rest[0], body_id=[0] + [1] * 12, radius=0.005, volume=vol, density=rho,
                              bulk_modulus=1.0e6, shear_modulus=6.0e5, horizon=0.03, shield_interior=False,
                              floor_factor=0.0, point_restitution=np.full(n, 0.05))  # fmt: skip
    x = (rest - rest[0]).astype(np.float32)
    v = np.vstack([[1.0, 0.3, 0.0], np.zeros((12, 3))]).astype(np.float32)
    dt = 0.7 * contact.stable_time_step()

    def accel(x, v):
        f = wp.zeros(n, dtype=wp.vec3)
        contact.apply(wp.array(x, dtype=wp.vec3), wp.zeros(n, dtype=wp.vec3), wp.array(v, dtype=wp.vec3), f)
        return f.numpy() / rho

    def energy(x, v):
        return 0.5 * rho * vol * float(np.sum(v.astype(np.float64) ** 2)) + contact.potential_energy(
            wp.array(x, dtype=wp.vec3)
        )

    e0 = energy(x, v)
    a = accel(x, v)
    most = e0
    for _ in range(400):  # the centre moves, the shell is held
        v[0] += 0.5 * dt * a[0]
        x[0] += dt * v[0]
        a = accel(x, v)
        v[0] += 0.5 * dt * a[0]
        most = max(most, energy(x, v))
    assert most <= e0 * (1.0 + 1.0e-6), (most, e0)
    kinetic = 0.5 * rho * vol * (1.0 + 0.3**2)
    assert energy(x, v) < e0 - 0.5 * kinetic  # the dashpots took most of the centre's kinetic energy out
    # the cap's scale at the start: all 12 pairs in contact, each with zeta c_crit V / m from the kernel's formula
    contact.apply(wp.array((rest - rest[0]).astype(np.float32), dtype=wp.vec3), wp.zeros(n, dtype=wp.vec3),
                  wp.array(np.vstack([[1.0, 0.3, 0.0], np.zeros((12, 3))]).astype(np.float32), dtype=wp.vec3),
                  wp.zeros(n, dtype=wp.vec3))  # fmt: skip
    c = contact._modulus_host[0]
    budget = 12.0 * c * 0.01**3
    m = rho * vol
    zeta = contact.point_damping_ratio.numpy()[0]
    rate = 12.0 * zeta * 2.0 * np.sqrt(c * vol * (0.5 * m) / vol) * vol / m
    expected = 1.0 / (rate * np.sqrt(2.0 * rho / budget))
    assert expected < 0.1
    assert contact._damp.numpy()[0] == pytest.approx(expected, rel=1e-4)


def _preset_rebound(material) -> float:
    """Centre-of-mass rebound over impact speed of a 2 x 2 x 2 h block of ``material`` (the preset's animation
    values, plain pattern) thrown at 1 m/s at the default ground plane (friction 0.5, no restitution of its own),
    no gravity."""
    solver = _ground_solver(material, (2, 2, 2), H + 1.0e-3, (0.0, 0.0, -1.0), GroundPlane(), (0.0, 0.0, 0.0))
    dt = 0.7 * solver.stable_time_step()
    for _ in range(int(0.02 / dt)):
        solver.step(dt)
    return float(solver.velocities()[:, 2].mean())


def test_rubber_rebounds_higher_than_ceramic():
    """A small rubber-preset block and a small ceramic-preset block (2 x 2 x 2 particles, h = 1 cm) thrown at the
    ground at 1 m/s leave it at their presets' restitutions (rubber 0.8, ceramic 0.15; the ground brings none) within
    0.1 (a deformable block also gives back some of the elastic energy it stores in the impact): rubber far higher.
    Without the material values both would stay on the ground (the ground's inelastic projection)."""
    rubber = _preset_rebound(presets.rubber())
    ceramic = _preset_rebound(presets.ceramic(pattern=False))
    print(f"rebound / impact speed: rubber {rubber:.3f}, ceramic {ceramic:.3f}")
    assert rubber == pytest.approx(presets.CONTACT["rubber"][0], abs=0.1)
    assert ceramic == pytest.approx(presets.CONTACT["ceramic"][0], abs=0.1)
    assert rubber > ceramic + 0.5


def test_guide_table_quotes_the_presets_contact_values():
    """docs/guide.md's material table ends each row with the preset's contact restitution and friction."""
    import pathlib
    import re

    text = (pathlib.Path(__file__).parents[1] / "docs" / "guide.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| `(\w+)\((?:grain=\.\.\.)?\)` \|.* ([\d.]+) / ([\d.]+) \|$", text, re.MULTILINE)
    assert {name for name, _, _ in rows} == set(presets.PRESETS)
    for name, e, mu in rows:
        material = presets.preset(name)
        assert (float(e), float(mu)) == (material.contact_restitution, material.contact_friction), name


@pytest.mark.parametrize("restitution", [None, 0.3], ids=["impulse", "penalty"])
def test_rigid_box_slides_with_the_combined_friction(restitution):
    """A rigid box (0.2 x 0.2 x 0.1 m) resting on the ground (gravity 9.81 m/s^2) and sliding at 1 m/s, its friction
    0.16 against the ground's 1.0, takes the pair's sqrt(0.16 x 1.0) = 0.4 and stops after v^2 / (2 mu g) = 12.7 cm
    within 5 % (the rule it had before, the larger of the two, gave 1.0 and 5.1 cm), in the inelastic form and in the
    penalty form (a restitution of 0.3)."""
    from pdsim.rigid import BoxShape, RigidBodies, RigidBody

    g, v, mu = 9.81, 1.0, 0.4
    box = RigidBody(BoxShape((0.2, 0.2, 0.1)), density=1000.0, position=(0.0, 0.0, 0.05), velocity=(v, 0.0, 0.0),
                    friction=0.16, restitution=restitution)  # fmt: skip
    ground = pdsim.GroundPlane(normal=(0.0, 0.0, 1.0), offset=0.0, friction=1.0)
    system = RigidBodies([box], ground=ground, colliders=[], gravity=(0.0, 0.0, -g), origin=np.zeros(3), device="cpu")
    dt = 1.0e-3
    system.simulate(dt, int(1.2 * v / (mu * g) / dt))
    s = box.state_values()
    print(f"rigid box ({restitution}): {s['position'][0] / (v**2 / (2.0 * mu * g)):.4f} x v^2 / (2 mu g)")
    assert abs(s["velocity"][0]) < 0.01 * v
    assert s["position"][0] == pytest.approx(v**2 / (2.0 * mu * g), rel=0.05)
    assert RigidBody(BoxShape((0.1, 0.1, 0.1)), density=1000.0, restitution=0.0).friction == 0.5


def test_fem_block_slides_with_its_material_friction():
    """An FEM block (0.06 x 0.06 x 0.03 m, 3 x 3 x 2 cells) resting on the ground (gravity 9.81 m/s^2) and sliding at
    1 m/s, its material's contact_friction 0.64 against the ground's 0.25, takes sqrt(0.64 x 0.25) = 0.4 and stops
    after v^2 / (2 mu g) = 12.7 cm within 5 % (the ground's 0.25 alone: 20.4 cm)."""
    g, v, mu = 9.81, 1.0, 0.4
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.25, contact_friction=0.64)
    body = pdsim.FemBody(pdsim.box_tet_mesh((0.06, 0.06, 0.03), (3, 3, 2), center=(0.0, 0.0, 0.015)), material)
    body.set_initial_velocity((v, 0.0, 0.0))
    solver = pdsim.SolverFem([body], ground=GroundPlane(friction=0.25), gravity=(0.0, 0.0, -g), device="cpu")
    dt = 0.5 * solver.stable_time_step()
    x0 = solver.positions()[:, 0].mean()
    for _ in range(int(1.2 * v / (mu * g) / dt)):
        solver.step(dt)
    moved = solver.positions()[:, 0].mean() - x0
    print(f"stopped after {moved:.4f} m, v^2 / (2 mu g) = {v**2 / (2.0 * mu * g):.4f} m")
    assert abs(solver.velocities()[:, 0].mean()) < 0.01 * v
    assert moved == pytest.approx(v**2 / (2.0 * mu * g), rel=0.05)


def _cube_on_slab_velocity(cube_material, slab_material, contact_options, cube_method) -> np.ndarray:
    """Mean velocity [m/s] of a 4 x 4 x 4 cm cube of ``cube_material`` (``cube_method`` "pd": peridynamic, h = 1 cm;
    "fem": 2 x 2 x 2 cubes of 6 tetrahedra) thrown at 1 m/s down and 0.5 m/s sideways onto an FEM slab
    (16 x 16 x 4 cm, 8 x 8 x 2 cubes) of ``slab_material`` 2 mm below it, after 25 ms (pdsim.contact.MethodContact:
    particles against FEM surfaces, FEM surface pairs), with the scene's ``contact_options``
    (Scene.enable_contact)."""
    from pdsim.run import advance_frame, method_contact

    scene = pdsim.Scene(fps=24.0, frames=1, gravity=(0.0, 0.0, 0.0))
    slab_c, cube_c = (0.0, 0.0, 0.02), (0.0, 0.0, 0.04 + 0.002 + 0.02)
    if cube_method == "pd":
        cube = scene.add_peridynamic_body(pdsim.box((0.04, 0.04, 0.04), center=cube_c), cube_material, H, name="cube")
    else:
        cube = scene.add_body(pdsim.FemBody(pdsim.box_tet_mesh((0.04, 0.04, 0.04), (2, 2, 2), center=cube_c),
                                            cube_material, name="cube"))  # fmt: skip
    scene.add_body(pdsim.FemBody(pdsim.box_tet_mesh((0.16, 0.16, 0.04), (8, 8, 2), center=slab_c), slab_material,
                                 name="slab"))  # fmt: skip
    cube.set_initial_velocity((0.5, 0.0, -1.0))
    scene.enable_contact(True, **contact_options)
    solvers = scene.build_solvers(device="cpu")
    coupling = method_contact(scene, solvers)
    dt = scene.time_step_safety * min(s.stable_time_step() for s in solvers)
    advance_frame(solvers, dt, int(0.025 / dt), coupling)
    if cube_method == "pd":
        return next(s for s in solvers if isinstance(s, pdsim.SolverPeridynamics)).velocities().mean(axis=0)
    fem = next(s for s in solvers if isinstance(s, pdsim.SolverFem))
    v, x = fem.velocities(), fem.positions()
    return v[x[:, 2] > 0.041].mean(axis=0)  # the cube's vertices (the slab's top is at 0.04 m)


@pytest.mark.parametrize("cube_method", ["pd", "fem"])
def test_contact_between_methods_takes_the_combined_material_values(cube_method):
    """A peridynamic or FEM cube (restitution 0.2, friction 0.25) thrown down and sideways onto an FEM slab (restitution
    0.5, friction 0.64) leaves with the velocity it has when the scene sets the combined values, restitution 0.5 and
    friction sqrt(0.25 x 0.64) = 0.4, for every pair (within 1e-3 m/s: float32 rounding of the geometric mean), and
    not with the scene's values alone (its friction 0, restitution 0.73: the sideways speed differs by more than
    0.05 m/s)."""
    plain = {"density": 1000.0, "youngs_modulus": 1.0e6, "poisson_ratio": 0.3}
    per_material = _cube_on_slab_velocity(
        pdsim.Material(**plain, contact_restitution=0.2, contact_friction=0.25),
        pdsim.Material(**plain, contact_restitution=0.5, contact_friction=0.64),
        {},
        cube_method,
    )
    combined = _cube_on_slab_velocity(pdsim.Material(**plain), pdsim.Material(**plain),
                                      {"restitution": 0.5, "friction": 0.4}, cube_method)  # fmt: skip
    scene_only = _cube_on_slab_velocity(pdsim.Material(**plain), pdsim.Material(**plain), {}, cube_method)
    print(f"cube velocity: material {per_material}, combined {combined}, scene only {scene_only}")
    assert per_material[2] > 0.1  # it has bounced
    np.testing.assert_allclose(per_material, combined, atol=1.0e-3)
    assert abs(per_material[0] - scene_only[0]) > 0.05
