"""The reference cases a-g of shared/seeds/pbd_lattice.txt (and a 3D tear) as ready-made lattice bodies and scenes;
the scripts scenes/lattice_*.py run them. Lengths in lattice units (spacing 1, the paper's "units", read as metres),
leader speeds in units per step, one step per frame. Parameters the paper does not give are documented in
docs/lattice.md (section "Reference cases").
"""

from __future__ import annotations

import numpy as np

from pdsim.lattice import (
    Lattice,
    LatticeBody,
    LatticeFracture,
    LatticeNeighbourhood,
    LatticeRule,
    LatticeRuleMixedCoordinate,
)

__all__ = [
    "FRACTURE_DISTANCES",
    "POISSON_K",
    "TABLE1_SPEED",
    "case_a_scene",
    "case_b_scene",
    "case_c_scene",
    "case_d_scene",
    "case_e_scene",
    "case_f_scene",
    "case_g_scene",
    "dogbone_shape",
    "fracture_specimen",
    "run_lattice_scene",
    "saint_venant_body",
    "tear_3d_scene",
    "tensile_specimen",
]

TABLE1_SPEED = 0.35  # units/step (Table 1)
POISSON_K = 0.01  # 1/unit, mixed-coordinate rule of cases b and c
FRACTURE_DISTANCES = (2.0, 2.5)  # units, link-loss thresholds of shell 1 and shell 2 (cases d, f, g)


def tensile_specimen(
    lattice: Lattice,
    counts,
    *,
    gradient: int = 1,
    rule: LatticeRule | None = None,
    fracture: LatticeFracture | None = None,
    frame_rule: str = "average",
    speed: float = TABLE1_SPEED,
    stop_step: int | None = 10,
    release_step: int | None = None,
    axis: int = 0,
    name: str = "specimen",
    origin=None,
    track=None,
) -> LatticeBody:
    """The paper's tensile specimen: a block of ``counts`` points whose first layer along ``axis`` is clamped and
    whose last layer moves along ``axis`` at ``speed`` [units/step] until ``stop_step`` and turns into followers at
    ``release_step``. A layer is every point within 0.6 spacing of the extreme coordinate (both row parities of a
    hexagonal lattice)."""
    body = LatticeBody.block(
        lattice,
        counts,
        origin=origin,
        neighbourhood=LatticeNeighbourhood(gradient=gradient),
        rule=rule,
        fracture=fracture,
        frame_rule=frame_rule,
        name=name,
    )
    x = body.rest_positions[: body.body_count, axis]
    h = 0.6 * lattice.spacing
    body.clamp(x < x.min() + h)
    v = np.zeros(3)
    v[axis] = speed
    body.add_leaders(x > x.max() - h, velocity=v, stop_step=stop_step, release_step=release_step)
    if track is not None:
        body.track(track)
    return body


def fracture_specimen(lattice: Lattice, *, gradient: int = 1, frame_rule: str = "average", name: str, origin=None):
    """Cases d, f, g: a square 15x13 or hexagonal 15x17 specimen (the sizes implied by the paper's point numbers 103
    and 133: two columns left of the leaders, at mid-height), centroid rule, links lost beyond FRACTURE_DISTANCES,
    fictitious points at the rest offset, pulled at 0.35 units/step for 10 steps. Tracks that particle."""
    ny = 17 if lattice.type.value == "hexagonal" else 13
    return tensile_specimen(
        lattice,
        (15, ny),
        gradient=gradient,
        fracture=LatticeFracture(FRACTURE_DISTANCES),
        frame_rule=frame_rule,
        name=name,
        origin=origin,
        track=[15 * (ny // 2) + 12],
    )


def saint_venant_body(*, count: int = 20, speed: float = TABLE1_SPEED, stop_step: int | None = 10) -> LatticeBody:
    """Case e: a count x count square whose four central points are leaders diverging along the bisectors of the
    corners at ``speed`` [units/step]."""
    body = LatticeBody.block(Lattice.square(1.0), (count, count), name="saint_venant")
    x = body.rest_positions[: body.body_count]
    centre = x.mean(axis=0)
    s = speed / np.sqrt(2.0)
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            j = body.nearest_particle(centre + 0.5 * np.array([sx, sy, 0.0]))
            body.add_leaders([j], velocity=(sx * s, sy * s, 0.0), stop_step=stop_step)
    body.track([body.nearest_particle(centre + np.array([3.5, 3.5, 0.0])), body.nearest_particle(x.max(axis=0))])
    return body


def _scene(name: str, frames: int, bodies):
    from pdsim.scene import Scene

    scene = Scene(fps=24, frames=frames, name=name)
    for b in bodies:
        scene.add_body(b)
    return scene


def case_a_scene():
    """Table 1: 10x10 square, left column clamped, right column pulled 10 steps then released, 401 steps."""
    body = tensile_specimen(Lattice.square(1.0), (10, 10), release_step=11, name="square_10x10", track=[66])
    return _scene("lattice_case_a", 401, [body])


def _poisson(gradient: int, name: str, origin=None):
    rule = LatticeRuleMixedCoordinate(k=POISSON_K)
    return tensile_specimen(
        Lattice.square(1.0), (10, 10), gradient=gradient, rule=rule, name=name, origin=origin, track=[66]
    )


def case_b_scene():
    """Case a without release (leaders stop after 10 steps), 100 steps, mixed-coordinate rule K = 0.01 /unit."""
    return _scene("lattice_case_b", 100, [_poisson(1, "poisson_first_gradient")])


def case_c_scene():
    """Case b with second gradient, beside case b's first-gradient specimen (14 units above) for comparison."""
    bodies = [_poisson(2, "poisson_second_gradient"), _poisson(1, "poisson_first_gradient", origin=(0.0, 14.0, 0.0))]
    return _scene("lattice_case_c", 100, bodies)


def case_d_scene():
    """Fracture of the square specimen, first gradient (bottom) and second gradient (20 units above), 100 steps."""
    sq = Lattice.square(1.0)
    bodies = [
        fracture_specimen(sq, gradient=1, name="fracture_first_gradient"),
        fracture_specimen(sq, gradient=2, name="fracture_second_gradient", origin=(0.0, 20.0, 0.0)),
    ]
    return _scene("lattice_case_d", 100, bodies)


def case_e_scene():
    """Saint-Venant: four internal leaders of a 20x20 square diverge for 10 steps; 40 steps."""
    return _scene("lattice_case_e", 40, [saint_venant_body()])


def case_f_scene():
    """Fracture of the hexagonal 15x17 specimen (first gradient, averaging frame) beside the square one, 400 steps."""
    bodies = [
        fracture_specimen(Lattice.hexagonal(1.0), name="hexagonal_first_gradient"),
        fracture_specimen(Lattice.square(1.0), name="square_first_gradient", origin=(0.0, 20.0, 0.0)),
        fracture_specimen(Lattice.hexagonal(1.0), gradient=2, name="hexagonal_second_gradient", origin=(25.0, 0.0, 0)),
    ]
    return _scene("lattice_case_f", 400, bodies)


def case_g_scene():
    """Hexagonal fracture, second gradient, frame rule "average" (bottom) against "single" (20 units above)."""
    hexagonal = Lattice.hexagonal(1.0)
    bodies = [
        fracture_specimen(hexagonal, gradient=2, frame_rule="average", name="frame_average"),
        fracture_specimen(hexagonal, gradient=2, frame_rule="single", name="frame_single", origin=(0.0, 20.0, 0.0)),
    ]
    return _scene("lattice_case_g", 100, bodies)


def dogbone_shape(*, length: float = 24.0, radius: float = 4.0, neck_radius: float = 1.8, name: str = "dogbone"):
    """A round tensile bar along x (a closed mesh, trimesh.creation.revolve): radius(x) = radius - (radius -
    neck_radius) exp(-(x / 3)^2) [units], from -length/2 to length/2."""
    import trimesh

    from pdsim.geometry import shape_from_arrays

    x = np.linspace(-0.5 * length, 0.5 * length, 49)
    r = radius - (radius - neck_radius) * np.exp(-((x / 3.0) ** 2))
    profile = np.column_stack([np.r_[0.0, r, 0.0], np.r_[x[0], x, x[-1]]])
    mesh = trimesh.creation.revolve(profile, sections=32)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    return shape_from_arrays(mesh.vertices, mesh.faces, name=name)


def tear_3d_scene(*, spacing: float = 1.0, frames: int = 100, steps_per_frame: int = 20):
    """3D: a round dog-bone bar (dogbone_shape: length 24, radius 4, neck 1.8 units) filled with a simple cubic
    lattice; the last 2.5 units at each end are the grips, one clamped, the other pulled along x at 0.005 units/step
    for 1200 steps (slowly, so that the strain reaches the neck before the grip links give way); links longer than
    1.3 spacings are lost. The bar necks and tears in the middle (about step 800), then both halves relax."""
    body = LatticeBody(
        Lattice.simple_cubic(spacing),
        dogbone_shape(),
        fracture=LatticeFracture((1.3 * spacing,)),
        steps_per_frame=steps_per_frame,
        name="dogbone",
    )
    x = body.rest_positions[: body.body_count, 0]
    body.clamp(x < x.min() + 2.5 * spacing)
    body.add_leaders(x > x.max() - 2.5 * spacing, velocity=(0.005 * spacing, 0.0, 0.0), stop_step=1200)
    return _scene("lattice_3d_tear", frames, [body])


def run_lattice_scene(build_scene, *, frames, pe2_frames=None, argv=None) -> int:
    """Runs a case scene into a cache and writes its paper-style figures (tools/lattice_plots.py)."""
    import os
    import sys

    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tools"))
    from lattice_plots import run_lattice_scene as run

    return run(build_scene, frames=frames, pe2_frames=pe2_frames, argv=argv)
