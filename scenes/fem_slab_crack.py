"""A brittle slab with a round hole, pulled apart: cracks start at the two sides of the hole, where the stress
concentrates (about three times the far-field stress), run across the slab normal to the pull, and it breaks in two
(tetrahedral FEM with fracture).

The slab (1.0 m x 0.5 m x 0.05 m, hole of radius 0.08 m, meshed by fTetWild) stands in the x-z plane. Its left end
is clamped; its right end is pulled along x at 5 cm/s. Both pieces are written as closed shells of the mesh "slab" in
the cache, the topology time-sampled on the frames where it cracked.

Run:  python scenes/fem_slab_crack.py --out slab.usdc      or      pdsim run scenes/fem_slab_crack.py --out slab.usdc
"""

import os

import pdsim
from pdsim.fem import FemBody

MESH_CACHE = os.path.join(os.path.expanduser("~"), ".cache", "pdsim", "meshes")  # fTetWild output varies per run


def slab_with_hole(size=(1.0, 0.05, 0.5), radius=0.08, center=(0.0, 0.0, 0.6)) -> pdsim.SolidShape:
    """A box with a cylindrical hole through its thin (y) axis, as a closed surface (trimesh boolean, manifold3d)."""
    import numpy as np
    import trimesh

    box = trimesh.creation.box(extents=size)
    hole = trimesh.creation.cylinder(radius=radius, height=4.0 * size[1], sections=48)
    hole.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    solid = trimesh.boolean.difference([box, hole], engine="manifold")
    solid.apply_translation(center)
    return pdsim.shape_from_arrays(solid.vertices, solid.faces, name="slab")


PREVIEW = {"edge_length": 0.05, "frames": 24}  # tools/make_gallery.py and tests/test_gallery.py: a quick run


def build_scene(*, edge_length: float = 0.03, frames: int = 48, mesh=None) -> pdsim.Scene:
    """The scene; ``mesh``: a ready TetMesh of the slab (tools/fem_slab_meshes.py) instead of fTetWild's at
    ``edge_length``."""
    scene = pdsim.Scene(fps=24, frames=frames, up_axis="Z", gravity=(0.0, 0.0, 0.0), name="fem_slab_crack")
    material = pdsim.Material(density=2000.0, youngs_modulus=2.0e6, poisson_ratio=0.25, name="brittle")
    meshing = {"edge_length": edge_length, "mesh_cache": MESH_CACHE} if mesh is None else {}
    slab = FemBody(
        slab_with_hole() if mesh is None else mesh,
        material,
        measure="corotated",
        tensile_strength=3.0e4,  # [Pa]: a strain of about 1.5 %
        damping=2.0,
        **meshing,
    )
    slab.fix(pdsim.BoxRegion(lo=(-1.0, -1.0, -1.0), hi=(-0.49, 1.0, 2.0)))
    slab.set_velocity(pdsim.BoxRegion(lo=(0.49, -1.0, -1.0), hi=(1.0, 1.0, 2.0)), (0.05, 0.0, 0.0))
    scene.add_body(slab)
    return scene


if __name__ == "__main__":
    from pdsim.cli import run_script

    run_script(build_scene)  # accepts the same options as `pdsim run`
