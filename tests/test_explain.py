"""pdsim.explain: the kernels it lists are exactly those each step launches (checked against an independent capture
of ``warp.launch`` while Scene.run simulates a frame of the same scene), its time step is Scene.run's, its state
account adds up, and explaining a scene leaves the scene as it was. Tiny scenes, CPU."""

import numpy as np
import pytest

import pdsim
from pdsim.explain import explain_scene, scene_plan

H = 0.01


def _elastic_scene():
    scene = pdsim.Scene(fps=24, frames=2, name="tiny_elastic")
    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.25, name="soft")
    bar = scene.add_peridynamic_body(pdsim.box((0.08, 0.04, 0.04), center=(0.0, 0.0, 0.1)), mat, H, damping=2.0)
    bar.fix(pdsim.BoxRegion(lo=(-1.0, -1.0, -1.0), hi=(-0.03, 1.0, 1.0)))
    bar.add_traction(pdsim.HalfSpace((0.039, 0.0, 0.1), (1.0, 0.0, 0.0)), (0.0, 0.0, -100.0))
    scene.add_ground_plane(height=0.0)
    return scene


def _all_features_scene():
    scene = pdsim.Scene(fps=24, frames=2, gravity=(0.0, 0.0, 0.0), name="tiny_features")
    layered = pdsim.Anisotropy(axis=(0.0, 0.0, 1.0), strength_ratio=0.5, stiffness_ratio=0.8)
    ductile = pdsim.Material(
        density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3, yield_stress=5.0e3, critical_stretch=0.05,
        anisotropy=layered, name="ductile",
    )  # fmt: skip
    brittle = pdsim.Material(
        density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.25, critical_stretch=0.01, name="brittle"
    )
    a = scene.add_peridynamic_body(pdsim.box((0.04, 0.04, 0.04), center=(0.0, 0.0, 0.0), name="a"), ductile, H)
    scene.add_peridynamic_body(pdsim.box((0.04, 0.04, 0.04), center=(0.06, 0.0, 0.0), name="b"), brittle, H)
    a.fix(pdsim.BoxRegion(lo=(-1.0, -1.0, -1.0), hi=(-0.01, 1.0, 1.0)))
    scene.add_collider(pdsim.SphereProjectile(0.01, center=(0.0, 0.0, 0.05), velocity=(0.0, 0.0, -1.0)))
    return scene


def _run_launches(scene, path):
    """(kernel key, dim) of every warp.launch made while ``scene.run`` simulates one frame (the independent record)."""
    import warp as wp

    seen = []
    original = wp.launch

    def recording(kernel, *args, **kwargs):
        seen.append((kernel.key, kwargs.get("dim", args[0] if args else None)))
        return original(kernel, *args, **kwargs)

    wp.launch = recording
    try:
        report = scene.run(str(path), frames=1, device="cpu", progress=False, checkpoint_interval_s=None)
    finally:
        wp.launch = original
    return seen, report


def _occurrences(block, seq) -> int:
    """Non-overlapping occurrences of ``block`` as a contiguous run in ``seq``."""
    count, i, n = 0, 0, len(block)
    while i + n <= len(seq):
        if seq[i : i + n] == block:
            count += 1
            i += n
        else:
            i += 1
    return count


@pytest.mark.parametrize("build", [_elastic_scene, _all_features_scene], ids=["elastic", "all_features"])
def test_listed_kernels_are_those_each_step_of_a_run_launches(build, tmp_path):
    """Every step of Scene.run (but the first, where the watchdog has no earlier step to account yet) launches
    exactly the kernels explain lists, in that order; the watchdog's check kernels appear in the run too."""
    plan = scene_plan(build(), "cpu")
    (solver,) = plan["solvers"]
    assert solver["method"] == "peridynamics"
    block = solver["step_kernels"]
    assert block
    launches, report = _run_launches(build(), tmp_path / "run.usdc")
    assert report.substeps_per_frame == plan["substeps_per_frame"]
    assert _occurrences(block, launches) >= plan["substeps_per_frame"] - 1
    names = [k for k, _ in launches]
    for name, _ in solver["check_kernels"]:
        assert name in names
    text = explain_scene(build(), "cpu")
    for name, dim in block:
        short = name.rpartition("__locals__")[2]
        assert any(short in line and f"dim {dim}" in line for line in text.splitlines()), (short, dim)


def test_features_bodies_and_state_of_a_scene_with_every_feature():
    plan = scene_plan(_all_features_scene(), "cpu")
    (s,) = plan["solvers"]
    for feature in ("fracture", "plasticity", "anisotropy", "contact", "colliders", "boundary_conditions"):
        assert feature in s["features"]
    bodies = {b["name"]: b for b in s["bodies"]}
    assert set(bodies) == {"a", "b"}
    assert {"plasticity", "fracture", "anisotropy", "boundary_conditions"} <= set(bodies["a"]["features"])
    assert bodies["b"]["features"] == ["fracture"]
    names = [k.rpartition("__locals__")[2] for k, _ in s["step_kernels"]]
    for kernel in ("kick_drift", "collide_sphere", "pair_dilatation", "pair_plastic_norm", "pair_force", "kick"):
        assert kernel in names
    assert any(e["kind"] == "hash_grid_build" for e in s["step_operations"])  # the contact pass's grid
    state = s["state"]
    assert state["total_bytes"] == sum(a["bytes"] for a in state["arrays"])
    by_path = {a["path"]: a for a in state["arrays"]}
    bonds = int(s["summary"].split(", ")[1].split()[0])
    assert by_path["state.bond_ne"]["shape"] == (bonds,)
    assert by_path["state.bond_ne"]["bytes"] == 16 * bonds
    assert by_path["state.bond_alive"]["bytes"] == bonds


def test_time_step_and_substeps_follow_scene_run(tmp_path):
    scene = _elastic_scene()
    plan = scene_plan(scene, "cpu")
    report = scene.run(str(tmp_path / "tiny.usdc"), frames=1, device="cpu", progress=False, checkpoint_interval_s=None)
    assert plan["substeps_per_frame"] == report.substeps_per_frame
    assert plan["dt"] == pytest.approx(report.dt, rel=1e-12)
    assert plan["stable_dt"] == pytest.approx(report.stable_dt, rel=1e-6)
    given = scene_plan(scene, "cpu", dt=1.0e-4)
    assert given["substeps_per_frame"] == int(np.ceil(scene.frame_time / 1.0e-4 - 1e-9))
    text = explain_scene(scene, "cpu")
    assert f"{plan['substeps_per_frame']} substeps per frame" in text


def test_explaining_leaves_the_scene_as_it_was():
    scene = _all_features_scene()
    scene.add_ground_plane(height=-0.05)
    ball = scene.colliders[0]
    ground = scene.ground
    before = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in vars(ball).items()}
    explain_scene(scene, "cpu")
    assert scene.colliders[0] is ball and scene.ground is ground
    assert not hasattr(ground, "_impulse") or not ground._impulse  # the copy's impulse accumulator, not the scene's
    for key, value in before.items():
        now = vars(ball)[key]
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(now, value)
        else:
            assert now is value or now == value, key


def test_fem_scene_is_explained_too(tmp_path):
    scene = pdsim.Scene(fps=24, frames=1, name="tiny_fem")
    mesh = pdsim.box_tet_mesh((0.2, 0.05, 0.05), (4, 1, 1), center=(0.1, 0.0, 0.1))
    body = scene.add_fem_body(mesh, pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3))
    body.fix(pdsim.BoxRegion(lo=(-1.0, -1.0, -1.0), hi=(1.0e-6, 1.0, 1.0)))
    plan = scene_plan(scene, "cpu")
    (s,) = plan["solvers"]
    assert s["method"] == "fem"
    assert s["step_kernels"]
    launches, report = _run_launches(scene, tmp_path / "fem.usdc")
    assert _occurrences(s["step_kernels"], launches) >= report.substeps_per_frame - 1
    assert "fem (SolverFem)" in explain_scene(scene, "cpu")
