"""The penalty of a point against a triangle (kernels/contact.py particle_mesh_contact, kernels/surface_contact.py
vertex_face_contact) is tied to the step through the pair's reduced mass: k = stiffness_rate m_red, so that one
contact oscillates at omega^2 = k (1 / m_point + 1 / m_face) = stiffness_rate, whatever the masses. The face point's
mass is 1 / sum_j w_j^2 / m_j (kernels/colliders.py face_point_mass). With the barycentric average sum_j w_j m_j in
its place, a light face vertex (the corner of a small element beside large ones, as fTetWild makes near curved
surfaces) oscillated at hundreds of times the rate. Where the elements around the pair take a longer stable step
than the run, the rate is that step's (SolverFem.contact_steps: the step of a vertex's smallest element, not the
mesh's smallest)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp

from pdsim.kernels import contact as kc
from pdsim.kernels import surface_contact as ksf

RATE = 1.0e6  # stiffness rate [1/s^2]
DEPTH = 2.0e-3  # overlap [m]
SKIN = 1.0e-2  # vertex sphere radius [m]
# A closed tetrahedron whose face 0 (a, b, c) lies in z = 0 with its outward normal +z; the point sits above
# (0.45, 0.45, 0): weights 0.1, 0.45, 0.45 on a, b, c.
TET_X = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.2, 0.2, -1.0]], dtype=np.float32)
TET_FACES = np.array([[0, 1, 2], [0, 3, 1], [1, 3, 2], [0, 2, 3]], dtype=np.int32)
WEIGHTS = np.array([0.1, 0.45, 0.45, 0.0])
ABOVE = (0.45, 0.45)


def _arr(values, dtype):
    return wp.array(np.asarray(values), dtype=dtype, device="cpu")


def _zeros(n, dtype):
    return wp.zeros(n, dtype=dtype, device="cpu")


def _expected_k(point_mass: float, face_masses: np.ndarray) -> float:
    """The penalty [N/m] that makes the pair oscillate at omega^2 = RATE."""
    return RATE / (1.0 / point_mass + float(np.sum(WEIGHTS**2 / face_masses)))


def _face_side(face_masses):
    mesh_x = _arr(TET_X, wp.vec3)
    mesh = wp.Mesh(points=mesh_x, indices=_arr(TET_FACES.ravel(), wp.int32), support_winding_number=True)
    return mesh, {
        "m_points": _arr(np.arange(4), wp.int32),
        "m_faces": _arr(TET_FACES.ravel(), wp.int32),
        "m_v": _zeros(4, wp.vec3),
        "m_mass": _arr(face_masses, float),
        "m_damping_ratio": _arr(np.full(4, np.nan), float),
        "m_friction": _arr(np.full(4, np.nan), float),
        "m_force": _zeros(4, wp.vec3),
        "m_work": _zeros(8, wp.float64),
    }


# a light vertex b (1e-4 of its neighbours) carrying 45 % of the contact point, and a uniform face for reference
FACES = [np.array([1.0, 1.0e-4, 1.0, 1.0]), np.array([1.0, 1.0, 1.0, 1.0])]


@pytest.mark.parametrize("face_masses", FACES, ids=["light corner", "uniform"])
def test_particle_against_a_face_oscillates_at_the_rate(face_masses):
    point_mass = 1.0
    mesh, face = _face_side(face_masses)
    p_force = _zeros(1, wp.vec3)
    kc.particle_mesh_forces(
        p_points=_arr([0], wp.int32),
        p_rest=_arr([[ABOVE[0], ABOVE[1], SKIN - DEPTH]], wp.vec3),
        p_u=_zeros(1, wp.vec3),
        p_v=_zeros(1, wp.vec3),
        p_mass=_arr([point_mass], float),
        p_to_force=_arr([1.0], float),
        p_radius=_arr([SKIN], float),
        mesh=mesh.id,
        stiffness_rate=RATE,
        damping_ratio=0.0,
        friction=0.0,
        p_damping_ratio=_arr([np.nan], float),
        p_friction=_arr([np.nan], float),
        p_force=p_force,
        dt=1.0e-4,
        p_work=_zeros(8, wp.float64),
        m_step=_arr(np.zeros(4), float),
        step_safety=0.7,
        device="cpu",
        **face,
    )
    f = p_force.numpy()[0]
    assert f[0] == pytest.approx(0.0, abs=1e-9) and f[1] == pytest.approx(0.0, abs=1e-9)
    assert f[2] / DEPTH == pytest.approx(_expected_k(point_mass, face_masses), rel=1e-4)
    np.testing.assert_allclose(face["m_force"].numpy()[:, 2], -WEIGHTS * f[2], rtol=1e-5, atol=1e-9)


def _vertex_face(face_masses, height: float, point_mass: float = 1.0, steps=(0.0, 0.0, 0.0, 0.0, 0.0)):
    """vertex_face_forces of one vertex at ``height`` [m] above the tetrahedron's top face (step 1e-4 s), with the
    points' element steps ``steps`` [s] (the vertex's, then the tetrahedron's four; 0: none longer than the run's) and
    a step safety of 0.5: (force on the vertex, forces on the face's vertices)."""
    mesh, face = _face_side(face_masses)
    v_force = _zeros(1, wp.vec3)
    ksf.vertex_face_forces(
        v_points=_arr([0], wp.int32),
        v_label=_arr([0], wp.int32),
        v_rest=_arr([[ABOVE[0], ABOVE[1], height]], wp.vec3),
        v_u=_zeros(1, wp.vec3),
        v_v=_zeros(1, wp.vec3),
        v_mass=_arr([point_mass], float),
        v_to_force=_arr([1.0], float),
        mesh=mesh.id,
        m_x=_arr(TET_X, wp.vec3),
        m_label=_arr(np.ones(4), wp.int32),
        m_to_force=_arr(np.ones(4), float),
        skin=SKIN,
        band=SKIN,
        stiffness_rate=RATE,
        damping_ratio=0.0,
        friction=0.0,
        v_damping_ratio=_arr([np.nan], float),
        v_friction=_arr([np.nan], float),
        v_force=v_force,
        dt=1.0e-4,
        v_work=_zeros(8, wp.float64),
        floor=1.0,
        pair_face=_arr([-1], wp.int32),
        pair_weights=_zeros(1, wp.vec3),
        pair_normal=_zeros(1, wp.vec3),
        v_step=_arr([steps[0]], float),
        m_step=_arr(steps[1:], float),
        step_safety=0.5,
        piece_lo=_zeros(1, wp.vec3),
        piece_hi=_zeros(1, wp.vec3),
        piece_count=0,  # no bounds: the vertex is searched
        device="cpu",
        **face,
    )
    return v_force.numpy()[0], face["m_force"].numpy()


@pytest.mark.parametrize("face_masses", FACES, ids=["light corner", "uniform"])
def test_vertex_against_a_face_of_another_piece_oscillates_at_the_rate(face_masses):
    point_mass = 1.0
    f, face_forces = _vertex_face(face_masses, SKIN - DEPTH, point_mass)
    assert f[2] / DEPTH == pytest.approx(_expected_k(point_mass, face_masses), rel=1e-4)
    np.testing.assert_allclose(face_forces[:, 2], -WEIGHTS * f[2], rtol=1e-5, atol=1e-9)
    # the pair's frequency: omega dt of one contact stays the law's CONTACT_OMEGA_DT at any step
    inv = 1.0 / point_mass + float(np.sum(WEIGHTS**2 / face_masses))
    assert math.sqrt(f[2] / DEPTH * inv) == pytest.approx(math.sqrt(RATE), rel=1e-4)


def test_the_stiffness_is_sized_on_the_longest_element_step_of_the_pair():
    """Where the elements around the pair take a longer stable step T than the run's dt (1e-4 s), the penalty is
    (dt / (0.5 T))^2 of the run's, T the longest step of the vertex and the face's three vertices (the softest
    elements around the pair; the tetrahedron's fourth vertex is not part of the face); a step shorter than the
    run's (0.5 T < dt) leaves it as it is."""
    masses = FACES[1]
    k = _expected_k(1.0, masses)
    for steps, factor in [
        ((4.0e-4, 0.0, 0.0, 0.0, 0.0), 0.25),
        ((0.0, 0.0, 1.0e-3, 4.0e-4, 0.0), 0.04),
        ((0.0, 0.0, 0.0, 0.0, 1.0e-2), 1.0),
        ((1.0e-4, 1.0e-4, 1.0e-4, 1.0e-4, 1.0e-4), 1.0),
    ]:
        f, _ = _vertex_face(masses, SKIN - DEPTH, steps=steps)
        assert f[2] / DEPTH == pytest.approx(factor * k, rel=1e-4), steps


def test_a_vertex_among_large_elements_gets_the_step_of_those_elements():
    """SolverFem.contact_steps: a coarse cube (1 cm cells) and a fine one (2.5 mm cells) in one solver, which runs
    at the fine cube's step; each vertex's step is its smallest element's, 0.5 h / c_p: the fine cube's vertices the
    solver's stable step, the coarse cube's four times it (the same material: the steps are in the ratio of the
    cells), to 1e-6."""
    import pdsim

    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)
    scene = pdsim.Scene(gravity=(0.0, 0.0, 0.0))
    scene.add_body(pdsim.FemBody(pdsim.box_tet_mesh((0.04,) * 3, (4, 4, 4)), material, name="coarse"))
    fine = pdsim.box_tet_mesh((0.01,) * 3, (4, 4, 4), center=(0.1, 0.0, 0.0))
    scene.add_body(pdsim.FemBody(fine, material, name="fine"))
    (solver,) = scene.build_solvers(device="cpu")
    steps = solver.contact_steps().numpy()
    coarse = slice(int(solver.body_offsets[0]), int(solver.body_offsets[1]))
    fine = slice(int(solver.body_offsets[1]), int(solver.body_offsets[2]))
    np.testing.assert_allclose(steps[fine], solver.stable_time_step(), rtol=1e-6)
    np.testing.assert_allclose(steps[coarse], 4.0 * solver.stable_time_step(), rtol=1e-6)
