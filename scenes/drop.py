"""A rubber ball thrown against a post held at its base, bouncing off the ground (the README's example).

Run:  python scenes/drop.py --out drop.usdc      or      pdsim run scenes/drop.py --out drop.usdc
"""

import pdsim

PREVIEW = {}  # tools/make_gallery.py and tests/test_gallery.py: the scene is small enough as it is


def build_scene() -> pdsim.Scene:
    scene = pdsim.Scene(fps=24, frames=48, up_axis="Z", name="drop")  # gravity 9.81 m/s^2 down the up axis
    rubber = pdsim.Material(density=1100.0, youngs_modulus=2.0e6, poisson_ratio=0.4)
    ball = pdsim.sphere(0.15, center=(0.0, 0.0, 0.6), name="ball")  # or pdsim.load_mesh("model.obj", scale=0.5)
    body = scene.add_peridynamic_body(ball, rubber, spacing=0.03, damping=0.5)
    body.set_initial_velocity((1.0, 0.0, 0.0))
    post = scene.add_peridynamic_body(
        pdsim.cylinder(0.08, 0.4, center=(0.6, 0.0, 0.2), name="post"), rubber, spacing=0.03
    )
    post.fix(pdsim.BoxRegion(lo=(-9, -9, -1), hi=(9, 9, 0.05)))  # hold its base
    scene.add_ground_plane(height=0.0, friction=0.5)
    return scene


if __name__ == "__main__":
    from pdsim.cli import run_script

    run_script(build_scene)  # accepts the same options as `pdsim run`
