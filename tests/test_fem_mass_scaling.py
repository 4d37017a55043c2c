"""Selective mass scaling of the tetrahedral FEM solid (FemBody ``mass_scaling``, pdsim.fem.body.mass_scaling_factors):
on a mesh holding a few elements far smaller than the rest, their density is raised so that the explicit step is that
of an element of 0.2 of the median height. The mesh is one of fTetWild's meshes of the gallery's slab
(tests/data/fem_slab_small_elements_ftetwild.vtu: 2,775 elements, the smallest 0.025 of the median height; fTetWild's
output varies from run to run, and such a mesh made the slab's preview run 149 s instead of 12 s)."""

from pathlib import Path

import numpy as np
import pytest

import pdsim
from pdsim.fem import FemBody, SolverFem
from pdsim.fem.mesh import box_tet_mesh
from pdsim.fem.mesh_files import load_tet_mesh
from pdsim.timestep import estimated_stable_step

from fem_helpers import critical_step

MAT = pdsim.Material(density=2000.0, youngs_modulus=2.0e6, poisson_ratio=0.25)  # the gallery slab's
MESH = Path(__file__).parent / "data" / "fem_slab_small_elements_ftetwild.vtu"


def _mesh():
    return load_tet_mesh(str(MESH), name="slab")


def _volumes_and_heights(mesh):
    """Element volumes [m^3] and heights 3 V / largest face area [m], computed here from the corners."""
    x = mesh.vertices[mesh.tets]
    volume = np.abs(np.einsum("ij,ij->i", x[:, 1] - x[:, 0], np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]))) / 6.0
    faces = [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)]
    area = np.stack(
        [0.5 * np.linalg.norm(np.cross(x[:, b] - x[:, a], x[:, c] - x[:, a]), axis=1) for a, b, c in faces], axis=1
    )
    return volume, 3.0 * volume / area.max(axis=1)


def test_mass_scaling_lifts_the_step_of_small_elements_for_the_mass_it_states():
    """By default (mass_scaling 0.2) the step is 0.5 x 0.2 x the median height / c_p, 8.1 times the unscaled step
    0.5 h_min / c_p; the lumped masses sum to rho V plus sum (factor - 1) rho V with factor (0.2 median / h)^2 for the
    44 elements under the floor (about 1e-4 of the body's mass), computed here from the corners; the body's own point
    masses (loads) agree; the run's summary states it; the pre-flight's step estimate (pdsim.timestep) is the solver's.
    mass_scaling 0 gives the unscaled step and rho V exactly."""
    mesh = _mesh()
    volume, h = _volumes_and_heights(mesh)
    floor = 0.2 * np.median(h)
    factor = np.maximum(1.0, (floor / h) ** 2)
    added = float(((factor - 1.0) * MAT.density * volume).sum())
    mass = MAT.density * float(volume.sum())
    body = FemBody(mesh, MAT)
    solver = SolverFem([body], precision="float64")
    assert solver.explicit_time_step() == pytest.approx(0.5 * floor / MAT.p_wave_speed, rel=1e-9)
    assert solver.explicit_time_step() > 8.0 * 0.5 * h.min() / MAT.p_wave_speed
    assert int((factor > 1.0).sum()) == 44
    assert solver.masses().sum() == pytest.approx(mass + added, rel=1e-12)
    assert 5.0e-5 < added / mass < 2.0e-4
    assert body.point_masses().sum() == pytest.approx(mass + added, rel=1e-12)
    assert "mass scaling gave 44 elements under 0.2 of the median element height 0.0095 % more mass" in (
        solver.summary()
    )
    plain_body = FemBody(mesh, MAT, mass_scaling=0.0)
    plain = SolverFem([plain_body], precision="float64")
    assert plain.explicit_time_step() == pytest.approx(0.5 * h.min() / MAT.p_wave_speed, rel=1e-9)
    # the pre-flight's estimate (before any solver exists: the step count, the cost) is the solver's step
    for b, s in ((body, solver), (plain_body, plain)):
        assert estimated_stable_step(b) == pytest.approx(s.explicit_time_step(), rel=1e-12)
    assert plain.masses().sum() == pytest.approx(mass, rel=1e-12)
    assert "mass scaling" not in plain.summary()


def test_the_scaled_step_is_stable_and_would_not_be_without_the_added_mass():
    """The true critical step 2 / omega_max of velocity Verlet with the lumped masses (assembled, scipy's eigsh) is
    above the scaled automatic step on the scaled system (measured 1.67 times it) and below it on the unscaled one
    (0.36 times): the added mass, not a looser estimate, is what makes the longer step stable."""
    mesh = _mesh()
    scaled = SolverFem([FemBody(mesh, MAT, measure="linear")], precision="float64")
    plain = SolverFem([FemBody(mesh, MAT, measure="linear", mass_scaling=0.0)], precision="float64")
    auto = scaled.explicit_time_step()
    critical_scaled, critical_plain = critical_step(scaled, mesh.tets), critical_step(plain, mesh.tets)
    print("critical / scaled automatic step: scaled", critical_scaled / auto, "unscaled", critical_plain / auto)
    assert critical_scaled > 1.2 * auto
    assert critical_plain < 0.5 * auto


def test_a_vibrating_slab_moves_alike_with_and_without_mass_scaling():
    """The slab set vibrating (a smooth velocity field, 0.1 m/s, no constraints, no gravity), 10 ms in equal steps
    at most each run's automatic step (140 steps scaled, 1,134 unscaled): the displacements agree within 0.2 % of their
    RMS (measured 0.026 %), and the scaled run's energy stays within 2 % of its start (measured 5e-6)."""
    mesh = _mesh()
    x = mesh.vertices - mesh.vertices.mean(axis=0)
    velocity = 0.1 * np.stack([np.sin(3.0 * x[:, 2]), np.cos(2.0 * x[:, 0]), np.sin(4.0 * x[:, 0])], axis=1)
    runs = []
    for fraction in (0.2, 0.0):
        solver = SolverFem([FemBody(mesh, MAT, mass_scaling=fraction)], precision="float64")
        solver.set_velocities(velocity)
        e0 = solver.kinetic_energy()
        dt = solver.stable_time_step()
        steps = int(np.ceil(0.01 / dt))
        energy = []
        for _ in range(steps):
            solver.step(0.01 / steps)
            energy.append(solver.kinetic_energy() + solver.strain_energy())
        runs.append((solver.positions() - mesh.vertices, steps, np.abs(np.array(energy) - e0).max() / e0))
    (u_scaled, n_scaled, drift), (u_plain, n_plain, _) = runs
    rms = np.sqrt((u_plain**2).sum(axis=1).mean())
    difference = np.sqrt(((u_scaled - u_plain) ** 2).sum(axis=1).mean()) / rms
    print("steps", n_scaled, n_plain, "RMS difference / RMS displacement", difference, "energy drift", drift)
    assert n_plain > 7 * n_scaled
    assert difference < 2.0e-3
    assert drift < 0.02


def test_mass_scaling_leaves_a_mesh_without_small_elements_alone_and_refuses_bad_values():
    """A jittered box mesh (smallest element 0.51 of the median height) is not scaled: the same step and masses as
    with mass_scaling 0. Values outside [0, 1) are refused naming the field."""
    mesh = box_tet_mesh((0.4, 0.2, 0.2), (6, 3, 3), jitter=0.25, seed=2)
    a = SolverFem([FemBody(mesh, MAT)], precision="float64")
    b = SolverFem([FemBody(mesh, MAT, mass_scaling=0.0)], precision="float64")
    assert a.explicit_time_step() == b.explicit_time_step()
    np.testing.assert_array_equal(a.masses(), b.masses())
    for bad in (-0.1, 1.0, float("nan")):
        with pytest.raises(pdsim.ParameterError, match="mass_scaling"):
            FemBody(mesh, MAT, mass_scaling=bad)
