"""A ductile dog-bone bar pulled apart: it yields, necks at its waist and tears in two.

The grips' speed ramps up over 0.15 s and the waist is 8 % thinner than the gauge section, so the plastic flow
localises at the waist (a sudden pull tears this perfectly plastic bar next to its grips).

Run:  python scenes/ductile_bar.py --out ductile_bar.usdc   or   pdsim run scenes/ductile_bar.py --out ductile_bar.usdc
"""

import numpy as np

import pdsim


def dogbone(length=0.4, grip_radius=0.045, gauge_radius=0.038, samples=48):
    """A turned tensile specimen along x: wide grips, a gauge section and an 8 % waist at the centre where the neck
    forms (a revolved profile, trimesh.creation.revolve)."""
    import trimesh

    x = np.linspace(-0.5 * length, 0.5 * length, samples)
    r = gauge_radius + (grip_radius - gauge_radius) * np.clip((np.abs(x) - 0.08) / 0.06, 0.0, 1.0) ** 2
    r *= 1.0 - 0.08 * np.exp(-((x / 0.02) ** 2))
    profile = np.column_stack([np.r_[0.0, r, 0.0], np.r_[x[0], x, x[-1]]])
    mesh = trimesh.creation.revolve(profile, sections=48)  # about z
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0.0, 1.0, 0.0]))  # along x
    return pdsim.shape_from_arrays(mesh.vertices, mesh.faces, name="bar")


PREVIEW = {"spacing": 0.0125, "frames": 30}  # tools/make_gallery.py and tests/test_gallery.py: a quicker run


def build_scene(*, spacing: float = 0.01, frames: int = 36) -> pdsim.Scene:
    scene = pdsim.Scene(fps=24, frames=frames, gravity=(0.0, 0.0, 0.0), name="ductile_bar")
    metal = pdsim.Material(
        density=1000.0,
        youngs_modulus=2.0e6,
        poisson_ratio=0.3,
        yield_stress=2.0e4,  # yields at 1 % strain, flows without hardening, so the neck localises
        failure_plastic_strain=0.6,
        name="ductile_metal",
    )
    bar = scene.add_peridynamic_body(dogbone(), metal, spacing=spacing, damping=5.0)
    grip = 0.2 - 0.03
    right = pdsim.HalfSpace((grip, 0.0, 0.0), (1.0, 0.0, 0.0))
    left = pdsim.HalfSpace((-grip, 0.0, 0.0), (-1.0, 0.0, 0.0))
    # the grips' speed ramps up over 0.15 s: a sudden pull starts plastic waves at the grips, and a material that
    # flows without hardening then tears there instead of at the waist
    for region, v in ((right, 0.1), (left, -0.1)):
        bar.set_velocity(region, (v, 0.0, 0.0), curve=pdsim.TimeCurve.ramp(0.15))
        bar.set_unbreakable(region)
    return scene


if __name__ == "__main__":
    from pdsim.cli import run_script

    run_script(build_scene)
