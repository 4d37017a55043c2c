"""tools/rigid_handoff.py's stills: the two stills of an off/on comparison are drawn with one camera, the scene's
view fitted to the run with the hand-off off, whatever page they are written for (docs/fracture.md, "Rigid
hand-off": each still of a page other than the default one was once framed to its own run's extent)."""

from types import SimpleNamespace

import numpy as np
from PIL import Image

import rigid_handoff as rh  # tools/ (tests/conftest.py puts it on the path)


def test_both_stills_of_a_page_take_the_off_runs_camera(tmp_path, monkeypatch):
    """With write_preview replaced by a recorder: the off still gets the scene's VIEWS entry (looked up by the
    scene's name, not the page-suffixed file name), and the on still the camera that the off still was drawn with,
    as an explicit eye and target; the files are named by the page's stem."""
    import pdsim.preview

    calls = []

    def record(cache, path, frames, **options):
        calls.append((cache, options))
        Image.new("RGB", (4, 3), "white").save(path)
        eye, target = np.array([1.5, -2.25, 0.75]) * (len(calls)), np.array([0.125, 0.0, -0.5])
        return SimpleNamespace(camera=SimpleNamespace(eye=eye, target=target))

    monkeypatch.setattr(pdsim.preview, "write_preview", record)
    monkeypatch.setitem(rh.VIEWS, "scene_x", {"camera": "-35,15", "fit": "first"})
    out = rh.stills("scene_x", "scene_x_page", {"off": "off.usdc", "on": "on.usdc"}, 7, str(tmp_path))
    assert out == "scene_x_page_off_on.png"
    assert (tmp_path / "scene_x_page_off.png").exists() and (tmp_path / out).exists()
    (off_cache, off_options), (on_cache, on_options) = calls
    assert (off_cache, on_cache) == ("off.usdc", "on.usdc")
    assert off_options["camera"] == "-35,15" and off_options["fit"] == "first"
    assert on_options["camera"] == "eye=1.5,-2.25,0.75:target=0.125,0.0,-0.5"
    assert "fit" not in on_options
