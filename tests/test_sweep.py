"""Sweeps and wedges on Dask (pdsim/sweep.py): a tiny sweep and a tiny wedge (2 variants, 2 frames) through a
LocalCluster in this process (processes=False, one worker, one thread: light), and the checks of setting names
and values that run before any task is submitted."""

import json
import os
import textwrap

import pytest

pytest.importorskip("distributed")

from pdsim import sweep
from pdsim.errors import ParameterError

SCENE = textwrap.dedent(
    '''
    """A tiny breakable block falling onto the ground: 8 x 8 x 4 particles, frames of 1 ms."""
    import pdsim


    def build_scene(spacing=0.0125, name="tiny"):
        scene = pdsim.Scene(fps=24, frames=5, frame_time=1.0e-3, name=name)
        material = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.25, fracture_energy=2.0)
        block = scene.add_peridynamic_body(pdsim.box((0.1, 0.1, 0.05), center=(0, 0, 0.2), name="block"), material,
                                           spacing=spacing)
        block.set_initial_velocity((0.0, 0.0, -1.0))
        scene.add_ground_plane()
        return scene
    '''
)


@pytest.fixture(scope="module")
def client():
    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None)
    c = Client(cluster)
    yield c
    c.close()
    cluster.close()


@pytest.fixture
def scene_script(tmp_path):
    path = tmp_path / "tiny_scene.py"
    path.write_text(SCENE)
    return str(path)


def test_tiny_sweep_returns_one_record_per_point(client):
    """Two points of the FEM cantilever and one of the patch test: records in grid order, with error, time, memory
    and knobs; a point that fails is reported, not raised."""
    records = sweep.run_sweep("cantilever", {"n": [1, 2], "method": ["fem"]}, scheduler=client)
    assert [r["knobs"]["n"] for r in records] == [1, 2]
    for r in records:
        assert r["problem"] == "cantilever" and r["method"] == "fem"
        assert 0.0 < r["error"] < 1.0 and r["seconds"] > 0.0 and r["peak_rss_mb"] > 0.0
        assert "worker" in r and "failed" not in r
    assert records[1]["error"] < records[0]["error"]
    bad = sweep.run_sweep("fem_patch_test", [{"n": 3}, {"n": 1}], scheduler=client)
    assert "failed" not in bad[0] and bad[0]["error"] < 1e-9
    assert bad[1]["failed"].startswith("ParameterError") and bad[1]["error"] != bad[1]["error"]  # NaN


def test_sweep_checks_problem_and_knobs():
    with pytest.raises(ParameterError, match="problem"):
        sweep.run_sweep("nope", {"n": [1]})
    with pytest.raises(ParameterError, match="knob of cantilever"):
        sweep.run_sweep("cantilever", {"cells": [1]})
    assert sweep.grid_points({"a": [1, 2], "b": ["x", "y"], "c": 3}) == [
        {"a": 1, "b": "x", "c": 3},
        {"a": 1, "b": "y", "c": 3},
        {"a": 2, "b": "x", "c": 3},
        {"a": 2, "b": "y", "c": 3},
    ]


def test_tiny_wedge_writes_one_cache_per_variant(client, scene_script, tmp_path):
    """material.fracture_energy = 1, 5 on every body, 2 frames each: two caches with their frame layers, the
    manifest wedge.json, and records in variant order."""
    from pxr import Usd

    out = tmp_path / "wedge"
    records = sweep.run_wedge(scene_script, {"material.fracture_energy": [1.0, 5.0]}, out, scheduler=client, frames=2)
    assert [r["settings"] for r in records] == [{"material.fracture_energy": 1.0}, {"material.fracture_energy": 5.0}]
    paths = [r["path"] for r in records]
    assert len(set(paths)) == 2
    for r, p in zip(records, paths):
        assert "failed" not in r, r
        assert os.path.isfile(p) and r["frames_written"] == 3  # the rest pose and 2 frames
        assert "fracture_energy=" in os.path.basename(p)
        stage = Usd.Stage.Open(p)
        assert stage.GetEndTimeCode() == 2
    manifest = json.loads((out / "wedge.json").read_text())
    assert manifest["settings"] == {"material.fracture_energy": [1.0, 5.0]}
    assert [v["path"] for v in manifest["variants"]] == paths


def test_wedge_command_line(client, scene_script, tmp_path, capsys):
    """`pdsim wedge SCENE --set NAME=V1,V2 --out DIR --scheduler ADDRESS`: the same wedge through the command line,
    pointed at a scheduler by its address (here the in-process cluster's), one cache per variant; bad input is a
    one-line error naming the option before any task runs."""
    from pxr import Usd

    from pdsim.cli import main

    out = tmp_path / "cli_wedge"
    address = client.scheduler.address
    argv = ["wedge", scene_script, "--set", "spacing=0.025,0.0125", "--out", str(out), "--frames", "1"]
    assert main([*argv, "--scheduler", address]) == 0
    printed = capsys.readouterr().out
    manifest = json.loads((out / "wedge.json").read_text())
    paths = [v["path"] for v in manifest["variants"]]
    assert len(paths) == 2 and all(p in printed for p in paths)
    counts = []
    for p in paths:
        stage = Usd.Stage.Open(p)
        assert stage.GetEndTimeCode() == 1
        points = next(x for x in stage.Traverse() if x.GetTypeName() == "Points")
        counts.append(len(points.GetAttribute("points").Get(1)))
    assert counts[1] == 8 * counts[0]  # half the spacing: eight times the particles
    for bad, field in (
        (["wedge", scene_script, "--out", str(out)], "set"),
        (["wedge", scene_script, "--set", "spacing=0.02"], "out"),
        (["wedge", scene_script, "--set", "spacing", "--out", str(out)], "--set"),
        (["wedge", scene_script, "--set", "spacing=0.02", "--out", str(out), "--frames", "1.5"], "frames"),
        (["wedge", scene_script, "--set", "spacingg=0.02", "--out", str(out)], "keyword of build_scene"),
    ):
        assert main(bad) == 1
        err = capsys.readouterr().err.strip()
        assert err.startswith("pdsim: error:") and field in err and "\n" not in err, err


def test_bench_command_checks_its_name(capsys):
    from pdsim.cli import main

    assert main(["bench", "speed"]) == 1
    assert "accuracy" in capsys.readouterr().err


def test_wedge_settings_are_applied_and_checked(scene_script):
    """Keyword settings go to build_scene, dotted ones onto the built scene; unknown names and bad values fail
    before any task runs, with the setting named."""
    from pdsim.cli import load_scene_script

    build = load_scene_script(scene_script)
    scene = sweep.build_variant(
        build,
        {
            "spacing": 0.025,
            "scene.fps": 48,
            "material.youngs_modulus": 2.0e6,
            "body.block.damping": 3.0,
            "body.block.material.fracture_energy": 7.0,
        },
    )
    block = scene.bodies[0]
    assert block.spacing == 0.025 and block.damping == 3.0
    assert block.material.youngs_modulus == 2.0e6 and block.material.fracture_energy == 7.0
    assert scene.fps == 48 and scene.frame_time == 1.0e-3  # frame_time was set explicitly: kept
    with pytest.raises(ParameterError, match="keyword of build_scene"):
        sweep.run_wedge(scene_script, {"spacingg": [0.01]}, "unused")
    with pytest.raises(ParameterError, match="build_scene"):
        sweep.build_variant(build, {"body.block.spacing": 0.01})  # fixed when the body is built
    with pytest.raises(ParameterError, match="block"):
        sweep.build_variant(build, {"body.nobody.damping": 1.0})
    with pytest.raises(ParameterError, match="fracture_energy"):
        sweep.build_variant(build, {"material.fracture_energi": 1.0})
    with pytest.raises(ParameterError, match="fracture_energy"):
        sweep.run_wedge(scene_script, {"material.fracture_energy": [1.0, -2.0]}, "unused")
    with pytest.raises(ParameterError, match=r"scene\.ATTR"):
        sweep.build_variant(build, {"scene.speed": 1.0})


def test_parse_settings():
    assert sweep.parse_settings(["material.fracture_energy=1,2,5", "scene.gravity=(0;0;-9.81)", "x=a,true"]) == {
        "material.fracture_energy": [1, 2, 5],
        "scene.gravity": [(0, 0, -9.81)],
        "x": ["a", True],
    }
    with pytest.raises(ParameterError):
        sweep.parse_settings(["novalue"])
    with pytest.raises(ParameterError):
        sweep.parse_settings(["a=1", "a=2"])
