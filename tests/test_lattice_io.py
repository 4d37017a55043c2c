"""Lattice bodies: construction of the five plane Bravais lattices and the cubic ones, neighbourhoods, frames and their
sources, bad input rejected with ParameterError, the scene protocol, the USD cache and its primvars, the figures, and
the rule variants (distance weighting, fictitious distance), CPU backend."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
import warp as wp
from pdsim.kernels.lattice import rules as kl

import pdsim
from pdsim.lattice import (
    Lattice,
    LatticeBody,
    LatticeFracture,
    LatticeKind,
    LatticeNeighbourhood,
    LatticeRule,
    LatticeRuleDistanceWeighted,
    LatticeRuleMixedCoordinate,
    SolverLattice,
)


@wp.func
def _update_axial_only(centroid: wp.vec3, u_old: wp.vec3, rest: wp.vec3, params: kl.LatticeRuleParams) -> wp.vec3:
    """A custom rule for the tests: the centroid's x, the old y and z."""
    return wp.vec3(centroid[0], u_old[1], u_old[2])


@dataclass(frozen=True, kw_only=True)
class _AxialOnlyRule(LatticeRule):
    def warp_functions(self):
        return kl.lattice_weight_uniform, _update_axial_only


PLANE = {
    "square": (Lattice.square(1.0), 4),
    "hexagonal": (Lattice.hexagonal(1.0), 6),
    "rectangular": (Lattice.rectangular(1.0, aspect=1.5), 4),
    "centred_rectangular": (Lattice.centred_rectangular(1.0, aspect=1.5), 6),
    "oblique": (Lattice.oblique(1.0, ratio=1.2, angle=75.0), 6),
    "simple_cubic": (Lattice.simple_cubic(1.0), 6),
    "body_centred_cubic": (Lattice.body_centred_cubic(1.0), 14),
    "face_centred_cubic": (Lattice.face_centred_cubic(1.0), 12),
}


@pytest.mark.parametrize("name", list(PLANE))
def test_coordination_numbers_and_symmetric_neighbourhoods(name):
    """Each lattice's first shell is its Wigner-Seitz faces (square 4, hexagonal 6, rectangular 4, centred
    rectangular 6, oblique 6, simple cubic 6, BCC 14, FCC 12); every shell set is closed under negation, and neighbour
    links are symmetric (j lists k iff k lists j)."""
    lattice, z = PLANE[name]
    offs, shell = LatticeNeighbourhood(gradient=2).offsets(lattice)
    assert (shell == 0).sum() == z
    assert np.array_equal(offs[0::2], -offs[1::2])
    shape = pdsim.box((6.0, 6.0, 6.0)) if lattice.dim == 3 else pdsim.BoxRegion((-3, -3, -1), (3, 3, 1))
    body = LatticeBody(lattice, shape, neighbourhood=LatticeNeighbourhood(gradient=2))
    n = body.particle_count
    owner = np.repeat(np.arange(n), np.diff(body.row_offsets))
    pairs = set(zip(owner.tolist(), body.link_neighbor.tolist(), strict=True))
    assert all((k, j) in pairs for j, k in pairs)
    assert np.all(body.rest_positions[:, 2] == 0.0) if lattice.dim == 2 else True


def test_square_chebyshev_shells_match_figure_3():
    """Chebyshev metric on the square lattice: shell 1 = the 8 points at Chebyshev distance 1, shell 2 = the 16 at
    distance 2 (the paper's Figure 3); coordination second gradient = 4 + 8 (graph distance 2)."""
    sq = Lattice.square(1.0)
    _, s = LatticeNeighbourhood(metric="chebyshev", gradient=2).offsets(sq)
    assert (s == 0).sum() == 8 and (s == 1).sum() == 16
    _, s = LatticeNeighbourhood(gradient=2).offsets(sq)
    assert (s == 0).sum() == 4 and (s == 1).sum() == 8


def test_anisotropic_metric_and_euclidean_radius():
    """metric_scale stretches the metric ball: Euclidean radius 1 with scale 2 along x reaches (+-2, 0) but not
    (0, +-2) on the square lattice; radius sqrt(2) gives the 8-neighbourhood."""
    sq = Lattice.square(1.0)
    offs, _ = LatticeNeighbourhood(metric="euclidean", radius=1.0, metric_scale=(2.0, 1.0, 1.0)).offsets(sq)
    rows = {tuple(o) for o in offs.tolist()}
    assert (2, 0) in rows and (0, 2) not in rows and (0, 1) in rows
    offs, _ = LatticeNeighbourhood(metric="euclidean", radius=math.sqrt(2.0)).offsets(sq)
    assert len(offs) == 8


def test_frame_depth_and_sources():
    """The frame completes every body point's neighbourhood: one layer (first gradient), two (second). On the square
    lattice a side frame point follows the one body point below it; on the hexagonal lattice a frame point above a
    flat edge averages its two nearest body points, and the single rule keeps the first (lowest index)."""
    sq = Lattice.square(1.0)
    b1 = LatticeBody.block(sq, (5, 4))
    b2 = LatticeBody.block(sq, (5, 4), neighbourhood=LatticeNeighbourhood(gradient=2))
    assert b1.frame_count == 2 * (5 + 4)
    assert b2.frame_count == 2 * (5 + 4) * 2 + 4  # two layers; the second gradient's (1, 1) offsets add the corners
    top = b1.nearest_particle((2.0, 4.0, 0.0), frame=True)
    assert b1.kind[top] == LatticeKind.FRAME
    src = b1.frame_sources[b1.frame_offsets[top] : b1.frame_offsets[top + 1]]
    assert np.allclose(b1.rest_positions[src], [[2.0, 3.0, 0.0]])
    hx = Lattice.hexagonal(1.0)
    avg = LatticeBody.block(hx, (6, 5))
    one = LatticeBody.block(hx, (6, 5), frame_rule="single")
    f = avg.nearest_particle((2.5, 5 * math.sqrt(3) / 2, 0.0), frame=True)
    s_avg = avg.frame_sources[avg.frame_offsets[f] : avg.frame_offsets[f + 1]]
    s_one = one.frame_sources[one.frame_offsets[f] : one.frame_offsets[f + 1]]
    assert len(s_avg) == 2 and list(s_one) == [s_avg.min()]


def test_paper_numbering_and_shapes():
    """Body points are numbered left to right, bottom to top (index 66 of a 10x10 block is the paper's j = 67 at
    (6, 6)); bodies fill polygons, regions and closed meshes (the z = 0 section for 2D lattices)."""
    body = LatticeBody.block(Lattice.square(1.0), (10, 10))
    assert np.allclose(body.rest_positions[66], (6.0, 6.0, 0.0))
    assert np.all(np.diff(body.rest_positions[:10, 0]) > 0) and body.rest_positions[10, 1] == 1.0
    tri = LatticeBody(Lattice.square(1.0), np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]]), origin=(0.5, 0.5, 0))
    assert tri.body_count == 45  # points (i + 0.5, j + 0.5) with i + j <= 8
    disk = LatticeBody(Lattice.hexagonal(1.0), pdsim.sphere(4.0))
    assert np.all(np.linalg.norm(disk.rest_positions[: disk.body_count], axis=1) < 4.0)
    ball = LatticeBody(Lattice.face_centred_cubic(1.0), pdsim.sphere(3.0))
    r = np.linalg.norm(ball.rest_positions[: ball.body_count], axis=1)
    assert r.max() < 3.0 and ball.body_count == pytest.approx(4.0 / 3.0 * math.pi * 27 * 4, rel=0.15)


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: Lattice.square(0.0), "spacing"),
        (lambda: Lattice.rectangular(1.0, aspect=9.0), "aspect"),
        (lambda: Lattice.oblique(1.0, angle=10.0), "angle"),
        (lambda: LatticeNeighbourhood(metric="manhattan"), "metric"),
        (lambda: LatticeNeighbourhood(gradient=3), "gradient"),
        (lambda: LatticeNeighbourhood(shell_weights=(1.0, -1.0)), "shell_weights"),
        (lambda: LatticeRuleDistanceWeighted(exponent=-1.0), "exponent"),
        (lambda: LatticeRuleMixedCoordinate(axis=(0.0, 0.0, 0.0)), "axis"),
        (lambda: LatticeFracture(distances=(1.0, 2.0, 3.0)), "distances"),
        (lambda: LatticeFracture(2.0, fictitious_distance=0.0), "fictitious_distance"),
        (lambda: LatticeBody.block(Lattice.square(1.0), (0, 3)), "counts"),
        (lambda: LatticeBody.block(Lattice.square(1.0), (3, 3), frame_rule="median"), "frame_rule"),
        (lambda: LatticeBody.block(Lattice.square(1.0), (3, 3), steps_per_frame=0), "steps_per_frame"),
        (lambda: LatticeBody.block(Lattice.square(1.0), (3, 3), fracture=LatticeFracture((0.9,))), "distances"),
        (lambda: LatticeBody(Lattice.square(1.0), "circle"), "shape"),
        (lambda: LatticeBody.block(Lattice.square(1.0), (3, 3)).add_leaders([99]), "region"),
        (lambda: LatticeBody.block(Lattice.square(1.0), (3, 3)).add_leaders([0], velocity=(1.0, 0.0)), "velocity"),
        (
            lambda: LatticeBody.block(Lattice.square(1.0), (3, 3)).add_leaders(
                [0], path=[(2, (0, 0, 0)), (1, (1, 0, 0))]
            ),
            "path",
        ),
        (lambda: LatticeBody.block(Lattice.square(1.0), (3, 3)).add_leaders([0], release_step=0), "release_step"),
        (lambda: LatticeBody.block(Lattice.square(1.0), (3, 3)).change_kind([0], LatticeKind.FRAME, at_step=2), "kind"),
    ],
)
def test_bad_input_is_rejected(make, field):
    """Out-of-range lattice, neighbourhood, rule, fracture, body and leader parameters raise ParameterError naming
    the field."""
    with pytest.raises(pdsim.ParameterError) as err:
        make()
    assert err.value.field == field


def test_leader_paths_release_and_category_changes():
    """A leader follows its keyframed path (linear in between, held after), turns into a follower at its release
    step, and change_kind makes a follower a leader that holds its displacement from that step on."""
    body = LatticeBody.block(Lattice.square(1.0), (6, 3))
    body.clamp([0, 6, 12])
    path_leader = body.add_leaders([5], path=[(0, (0, 0, 0)), (4, (2.0, 0, 0)), (6, (2.0, 1.0, 0))], release_step=9)
    frozen = body.change_kind([3], LatticeKind.LEADER, at_step=5)
    body.track(np.r_[path_leader, frozen])
    solver = SolverLattice([body])
    solver.run_steps(12)
    ids, x, _ = solver.trajectories()
    u = x - x[0]
    a, f = int(np.nonzero(ids == 5)[0][0]), int(np.nonzero(ids == 3)[0][0])
    expected = [[0.5, 0, 0], [1.0, 0, 0], [2, 0, 0], [2, 0.5, 0], [2, 1, 0], [2, 1, 0]]
    np.testing.assert_allclose(u[[1, 2, 4, 5, 6, 8], a], expected, atol=1e-6)
    assert np.linalg.norm(u[9, a] - u[8, a]) > 1e-3  # released at step 9: it follows its neighbours
    assert np.linalg.norm(u[4, f] - u[3, f]) > 0.0  # a follower until step 4
    np.testing.assert_array_equal(u[5:, f], np.repeat(u[4:5, f], 8, axis=0))  # a leader holding still from step 5
    assert solver.kinds()[5] == LatticeKind.FOLLOWER and solver.kinds()[3] == LatticeKind.LEADER


def test_distance_weighted_rule_and_fictitious_distance():
    """The distance-weighted rule keeps a lattice at rest and, pulled like case a, still moves the central particle
    towards the leaders, faster than the centroid rule in the first steps (stretched links weigh more). After a
    fracture, fictitious points at 0.5 times the rest offset keep the free edge of the clamped piece pulled in
    (plastic-like; measured -3.73 units after 300 steps), while at the rest offset (1.0) the edge returns to within
    0.05 units of rest (elastic-like; measured 0.006)."""
    sq = Lattice.square(1.0)
    res = {}
    for name, rule in (("centroid", None), ("weighted", LatticeRuleDistanceWeighted())):
        body = LatticeBody.block(sq, (10, 10), rule=rule)
        body.clamp(body.rest_positions[:100, 0] < 0.5)
        body.add_leaders(body.rest_positions[:100, 0] > 8.5, velocity=(0.35, 0, 0), stop_step=10)
        solver = SolverLattice([body])
        solver.run_steps(6)
        res[name] = solver.displacements()[66, 0]
    assert 0.0 < res["centroid"] < res["weighted"]
    edge = {}
    for s in (0.5, 1.0):
        body = LatticeBody.block(sq, (10, 6), fracture=LatticeFracture((1.5,), fictitious_distance=s))
        x = body.rest_positions[: body.body_count, 0]
        body.clamp(x < 0.5)
        body.add_leaders(x > 8.5, velocity=(0.5, 0, 0), stop_step=10)
        solver = SolverLattice([body])
        solver.run_steps(300)
        assert len(np.unique(solver.fragments()[: body.body_count])) == 2
        owners, ghosts = solver.fictitious_points()
        assert len(owners) == (~solver.link_alive()).sum() and ghosts.shape == (len(owners), 3)
        col = np.nonzero(np.isclose(x, 8.0))[0]
        edge[s] = solver.displacements()[col, 0].mean()
    assert abs(edge[1.0]) < 0.05
    assert edge[0.5] < -1.0


def test_scene_runs_lattice_into_a_valid_usd_cache(tmp_path):
    """A Scene with a lattice body (steps_per_frame = 3) runs through the scene protocol: the lattice never limits the
    time step (stable_time_step is inf), each frame advances 3 steps, and the cache holds per-frame points with the
    primvars kind, pe1, pe1_intact, pe2, displacement, broken_links and fragment; it passes pxr.UsdValidation. The
    paper-style figures (PE1, PE2 contours, trajectory) are drawn from it when matplotlib is installed."""
    from lattice_plots import read_lattice_cache, write_case_plots

    from pdsim.output.usd_files import usd_problems

    scene = pdsim.Scene(fps=24, frames=4, name="lattice")
    body = LatticeBody.block(Lattice.hexagonal(1.0), (8, 6), steps_per_frame=3, fracture=LatticeFracture((1.6,)))
    x = body.rest_positions[: body.body_count, 0]
    body.clamp(x < 0.6)
    body.add_leaders(x > x.max() - 0.6, velocity=(0.3, 0, 0))
    body.track([20])
    scene.add_body(body)
    solver = scene.build_solver(device="cpu")
    assert solver.stable_time_step() == math.inf and solver.speed_scale() == 0.0
    out = tmp_path / "lattice.usdc"
    report = scene.run(out, device="cpu", progress=False)
    assert report.frames_written == 5 and report.particle_count == body.particle_count
    assert usd_problems(out) == []
    (cached,) = read_lattice_cache(out)
    assert set(cached.primvars) >= {"kind", "pe1", "pe1_intact", "pe2", "displacement", "broken_links", "fragment"}
    assert np.allclose(cached.positions[0], body.rest_positions, atol=1e-6)
    leaders = body.kind == LatticeKind.LEADER
    moving = leaders & (body.rest_positions[:, 0] > 1.0)
    np.testing.assert_allclose(cached.positions[2, moving, 0] - cached.positions[0, moving, 0], 1.8, atol=1e-5)
    assert np.all(cached.primvars["kind"][0][body.body_count :] == LatticeKind.FRAME)
    assert cached.primvars["pe1"][0].max() == 0.0 and cached.primvars["pe1"][4].max() > 0.0
    pytest.importorskip("matplotlib")  # figures need matplotlib (not a pdsim dependency)
    plots = write_case_plots(out, tmp_path / "plots", frames=[0, 2, 4], tracked={body.name: [20]})
    assert len(plots) == 3 and all((tmp_path / "plots" / p).stat().st_size > 10_000 for p in plots)


def test_3d_mesh_body_tears_in_the_neck():
    """3D: the dog-bone bar of scenes/lattice_3d_tear.py (simple cubic lattice filling a closed mesh), pulled slowly,
    tears into two pieces at its neck (|x| < 2 units of the middle), not at a grip."""
    from lattice_paper import tear_3d_scene

    scene = tear_3d_scene(frames=50)
    solver = scene.build_solver(device="cpu")
    body = scene.bodies[0]
    solver.run_steps(1000)
    frag = solver.fragments()[: body.body_count]
    ids, counts = np.unique(frag, return_counts=True)
    big = ids[counts > 100]
    assert len(big) == 2
    n = body.particle_count
    owner = np.repeat(np.arange(n), np.diff(body.row_offsets))
    lost = ~solver.link_alive() & (owner < body.body_count) & (body.link_neighbor < body.body_count)
    assert lost.any() and np.abs(body.rest_positions[owner[lost], 0]).max() < 2.0


@pytest.mark.parametrize("case", ["a", "b", "c", "d", "e", "f", "g", "3d"])
def test_reference_scenes_run(case, tmp_path):
    """Every shipped lattice scene (scenes/lattice_case_*.py, scenes/lattice_3d_tear.py: the builders of
    scenes/lattice_paper.py) builds and runs two frames into a cache that passes pxr.UsdValidation, with one prim per
    body."""
    import lattice_paper as lattice_cases

    from pdsim.output.usd_files import usd_problems

    build = lattice_cases.tear_3d_scene if case == "3d" else getattr(lattice_cases, f"case_{case}_scene")
    scene = build()
    out = tmp_path / f"{case}.usdc"
    report = scene.run(out, frames=2, device="cpu", progress=False)
    assert report.frames_written == 3
    assert usd_problems(out) == []
    from pxr import Usd

    stage = Usd.Stage.Open(str(out))
    assert {p.GetName() for p in stage.GetPseudoRoot().GetChild("World").GetChildren()} == {
        b.name for b in scene.bodies
    }


def test_rules_are_pluggable_per_body():
    """Two bodies of one solver with different rules, one a user-defined Warp function pair: pulled diagonally, the
    custom-rule body's followers move only along x (y exactly 0) while the centroid body's move along both; a
    distance-weighted rule with exponent 0 in both shells is bit for bit the centroid rule; exponents per shell are
    passed to the kernel."""
    bodies = []
    for name, rule in (
        ("custom", _AxialOnlyRule()),
        ("centroid", None),
        ("weighted0", LatticeRuleDistanceWeighted(exponent=(0, 0))),
    ):
        body = LatticeBody.block(
            Lattice.square(1.0), (8, 8), rule=rule, name=name, neighbourhood=LatticeNeighbourhood(gradient=2)
        )
        x = body.rest_positions[: body.body_count, 0]
        body.clamp(x < 0.5)
        body.add_leaders(x > 6.5, velocity=(0.2, 0.2, 0.0))
        bodies.append(body)
    solver = SolverLattice(bodies)
    solver.run_steps(20)
    followers = bodies[0].kind == LatticeKind.FOLLOWER
    u_custom, u_centroid, u_w0 = (solver.displacements(i) for i in range(3))
    assert np.all(u_custom[followers, 1] == 0.0) and u_custom[followers, 0].max() > 0.1
    assert np.abs(u_centroid[followers, 1]).max() > 0.1
    np.testing.assert_array_equal(u_w0, u_centroid)
    assert LatticeRuleDistanceWeighted(exponent=(1.0, 2.0)).parameters(bodies[0])[0][2:] == (1.0, 2.0)
