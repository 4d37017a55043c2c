"""A brittle tile dropped onto the ground: it lands on a corner at 6 m/s (a fall of 1.8 m), cracks spread from the
corner across the tile and it breaks (peridynamics with fracture, ground plane, slow motion).

The tile (0.3 m x 0.2 m x 0.04 m, a brittle animation material: E 200 MPa, 2000 kg/m^3, critical stretch 0.2 %,
Silling-Askari compressive bonus 1, Weibull strength scatter of modulus 4, cells of 15 cm whose interiors are 5 times
stronger than their walls, debris damping, jittered particles) is
tilted 30 degrees about x and 20 degrees about y so that one corner strikes first; it starts just above the ground at
(3, -2, 0.2) m, already falling at 6 m/s, under gravity, onto a ground plane with friction 0.5. Each frame advances
0.24 s / frames of simulated time (48 frames: 0.24 s shown over 2 s).

At full resolution the tile breaks along its cells' walls into four pieces over 5 % of it as drawn, with 10 % of it
drawn as chips (before the cells: three pieces in a bed of chips, 43 % of the tile): the figures and their commands
are in docs/fracture.md, "Tile drop" and "As the render draws them".

Run:  python scenes/drop_shatter.py --out drop_shatter.usdc   or   pdsim run scenes/drop_shatter.py --out drop.usdc
"""

import numpy as np

import pdsim

CENTER = np.array([3.0, -2.0, 0.2])  # the tile's centre at the start [m]
SIZE = (0.3, 0.2, 0.04)  # [m]

PREVIEW = {"spacing": 0.02, "frames": 24}  # tools/make_gallery.py and tests/test_gallery.py: a coarse quick run


def tilted_tile(size=SIZE, center=CENTER, angles=(30.0, 20.0)) -> pdsim.SolidShape:
    """A box turned by ``angles`` [degrees] about x, then y, centred at ``center`` [m] (trimesh)."""
    import trimesh

    mesh = trimesh.creation.box(extents=size)
    rx = trimesh.transformations.rotation_matrix(np.radians(angles[0]), [1.0, 0.0, 0.0])
    ry = trimesh.transformations.rotation_matrix(np.radians(angles[1]), [0.0, 1.0, 0.0])
    mesh.apply_transform(ry @ rx)
    mesh.apply_translation(np.asarray(center) - 0.5 * (mesh.bounds[0] + mesh.bounds[1]))
    return pdsim.shape_from_arrays(mesh.vertices, mesh.faces, name="tile")


def build_scene(*, spacing: float = 0.01, frames: int = 48, speed: float = 6.0, duration: float = 0.24) -> pdsim.Scene:
    """The tile at particle ``spacing`` [m] (at most 4 cm), falling at ``speed`` [m/s]; ``frames`` frames over
    ``duration`` [s] of simulated time."""
    scene = pdsim.Scene(fps=24, frames=frames, frame_time=duration / frames, name="drop_shatter")
    ceramic = pdsim.Material(
        density=2000.0,
        youngs_modulus=2.0e8,
        poisson_ratio=0.2,
        critical_stretch=0.002,
        compressive_bonus=1.0,
        strength_weibull_modulus=4.0,  # scattered bond strength, jittered particles, calm debris: shards, not dust
        debris_damping=60.0,
        strength_cell_size=0.15,  # cells of 15 cm, their interiors 5 times stronger: cracks along the cells' walls
        name="ceramic",
    )
    shape = tilted_tile()
    lowest = float(shape.vertices[:, 2].min())
    tile = scene.add_peridynamic_body(shape, ceramic, spacing, sampling="jittered")
    tile.set_initial_velocity((0.0, 0.0, -speed))
    scene.add_ground_plane(height=lowest - 0.01, friction=0.5)
    return scene


if __name__ == "__main__":
    from pdsim.cli import run_script

    run_script(build_scene)
