"""`Scene.run(resume=True)` continues the same cache (docs/cache_format.md, "Resumed runs").

An interrupted run plus its resume leave one cache `out` that a renderer reads exactly as the cache of an
uninterrupted run: every attribute of every prim (points, velocities, normals, topology, primvars, extents,
reactions, transforms, visibility, `pdsim:time`) equal bit for bit at every time code 0..N, the same time samples
(topology only where it changed), the same prims, and no USD validation error. Covered: peridynamics with fracture,
contact, grips and fragment surfaces (also as one prim per fragment; also with crack events and debris instances), a
scene 200 m away from the origin with default settings, the FEM splitting its mesh, a resume from a checkpoint older
than the last written frame (the later frames and the fragment prims they defined are replaced), a resumed run
stopped again and resumed once more, and a run that replaces an earlier cache (the resumed frames stay in
`<stem>.partial<suffix>` until the run succeeds). Each resumed run packs the cache into one file at its end, as an
uninterrupted run does. Runs on the CPU, where a resumed run is bit-identical to an uninterrupted one.
"""

from __future__ import annotations

import shutil
import signal

import numpy as np
import pytest
from test_watchdog_resume import _StopAfter  # a deterministic SIGTERM at the n-th poll

import pdsim
from pdsim.checkpoint import RunInterrupted, checkpoint_path
from pdsim.output.usd import UsdCache
from pdsim.output.usd_files import usd_problems


class _StopAt:
    """A stop request armed when frame ``frame`` is written (pass :meth:`on_frame` to Scene.run) that becomes true
    ``polls`` polls later: 1 stops at that frame's end, more stop inside the next frame, at a step boundary."""

    def __init__(self, frame: int, polls: int = 1):
        self.frame, self.polls, self.calls, self.at, self.signal = frame, polls, 0, None, None

    def on_frame(self, frame, solvers):
        if frame == self.frame:
            self.at = self.calls + self.polls

    @property
    def requested(self) -> bool:
        self.calls += 1
        if self.at is not None and self.calls >= self.at:
            self.signal = signal.SIGTERM
        return self.signal is not None


def _pd_bar(shift=(0.0, 0.0, 0.0), *, frames=8, ground=True):
    """A breakable bar (288 particles, contact on) pulled apart by ramped grips, under gravity; its surface's topology
    changes at frames 1, 2, 3 and 7 (damage, then fragments)."""

    def at(*p):
        return tuple(float(a) + float(b) for a, b in zip(shift, p, strict=True))

    scene = pdsim.Scene(fps=24, frames=frames, frame_time=1.0e-3, name="grips")
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e7, poisson_ratio=0.25, critical_stretch=0.005)
    body = scene.add_peridynamic_body(
        pdsim.box((0.16, 0.06, 0.03), center=at(0.0, 0.0, 0.0151)), material, spacing=0.01, name="bar"
    )
    ramp = pdsim.TimeCurve.ramp(2.0e-3)
    left = pdsim.BoxRegion(lo=at(-1, -1, -1), hi=at(-0.07, 1, 1))
    right = pdsim.BoxRegion(lo=at(0.07, -1, -1), hi=at(1, 1, 1))
    body.set_velocity(left, (-2.0, 0, 0), axes="x", curve=ramp, name="l")
    body.set_velocity(right, (2.0, 0, 0), axes="x", curve=ramp, name="r")
    if ground:
        scene.add_ground_plane(height=float(shift[2]))
    return scene


def _fem_bar():
    """An FEM bar pulled apart until elements split (the surface's vertices and topology change)."""
    scene = pdsim.Scene(fps=24.0, frames=8, frame_time=1.0e-3, gravity=(0.0, 0.0, 0.0), name="fem")
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)
    body = scene.add_body(
        pdsim.FemBody(pdsim.box_tet_mesh((0.08, 0.02, 0.02), (8, 2, 2)), material, tensile_strength=2.0e3, name="bar")
    )
    body.set_velocity(pdsim.BoxRegion(lo=(-1, -1, -1), hi=(-0.0399, 1, 1)), (-0.5, 0.0, 0.0))
    body.set_velocity(pdsim.BoxRegion(lo=(0.0399, -1, -1), hi=(1, 1, 1)), (0.5, 0.0, 0.0))
    return scene


def _fem_pieces_pressed(rigid_ball: bool = False):
    """An FEM slab on the ground cracked by a kinematic sphere (or, with ``rigid_ball``, a falling rigid steel ball),
    its pieces pressed into each other (the surface contact's hard floor acts: tools/fem_piece_contact.py)."""
    scene = pdsim.Scene(fps=240.0, frames=6, gravity=(0.0, 0.0, -9.81), name="fem_pieces")
    scene.add_ground_plane(height=0.0, friction=0.5)
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)
    mesh = pdsim.box_tet_mesh((0.16, 0.04, 0.02), (8, 2, 1), center=(0.0, 0.0, 0.011))
    scene.add_body(pdsim.FemBody(mesh, material, name="slab", tensile_strength=3.0e4))
    if rigid_ball:
        scene.add_rigid_body(pdsim.SphereShape(0.015), density=7850.0, position=(0.0, 0.0, 0.04),
                             velocity=(0.0, 0.0, -3.0), name="ball")  # fmt: skip
    else:
        scene.add_collider(pdsim.SphereProjectile(0.02, center=(0.0, 0.0, 0.045), velocity=(0.0, 0.0, -1.5)))
    return scene


def test_a_rigid_ball_resumed_inside_a_frame_is_bit_identical(tmp_path):
    """The slab under a falling rigid ball stopped two steps into frame 4 and resumed: the cache, the ball's pose and
    velocities included, equals the uninterrupted run's bit for bit. The stop is honoured at the start of a solver's
    step, after the rigid bodies' first half kick and drift of that step, which are undone
    (pdsim.rigid.RigidBodies.undo_begin_step): without that the checkpoint held the ball half a step ahead of the
    slab, and the resumed ball moved on by 0.3 mm and 6.6e-4 m/s (g dt / 2) from the uninterrupted one."""
    _assert_resume_is_bit_identical(lambda: _fem_pieces_pressed(rigid_ball=True), tmp_path, 3, 6)


def _lattice_block():
    from pdsim.lattice import Lattice, LatticeBody, LatticeFracture

    scene = pdsim.Scene(fps=24.0, frames=6, name="lattice")
    h = 0.01
    body = LatticeBody.block(Lattice.simple_cubic(h), (8, 4, 3), name="block", fracture=LatticeFracture((1.6 * h,)))
    x = body.rest_positions[: body.body_count, 0]
    body.clamp(x < x.min() + 0.5 * h)
    body.add_leaders(x > x.max() - 0.5 * h, velocity=(0.35 * h, 0.0, 0.0), stop_step=10)
    scene.add_body(body)
    return scene


def _as_comparable(value):
    """A USD value as something ``==`` compares exactly (arrays: float32/int32 numpy arrays, bit for bit)."""
    if value is None or isinstance(value, bool | int | float | str):
        return value
    try:
        a = np.asarray(value)
    except (TypeError, ValueError):
        return str(value)
    if a.dtype == object:
        return str(value)
    return a


def _read(path) -> dict:
    """Everything a renderer reads from the cache at ``path`` with ``Usd.Stage.Open``: per attribute of every prim, its
    time samples and its value at every time code from the start to the end, plus the stage's time range."""
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    assert stage is not None, path
    start, end = int(stage.GetStartTimeCode()), int(stage.GetEndTimeCode())
    out = {"range": (start, end, stage.GetTimeCodesPerSecond())}
    for prim in stage.TraverseAll():
        for attr in prim.GetAttributes():
            key = f"{prim.GetPath()}.{attr.GetName()}"
            values = [_as_comparable(attr.Get(Usd.TimeCode(t))) for t in range(start, end + 1)]
            out[key] = (list(attr.GetTimeSamples()), values)
    return out


def _assert_same_cache(reference, resumed, frames: int):
    """The cache ``resumed`` plays exactly as ``reference``: same time codes 0..frames, same prims and attributes,
    same time samples, every value equal bit for bit at every time code; and it passes the USD validators."""
    ref, got = _read(reference), _read(resumed)
    assert got["range"] == ref["range"] == (0, frames, ref["range"][2])
    assert sorted(got) == sorted(ref)
    time = got["/World.pdsim:time"]
    assert time[0] == list(range(frames + 1))  # one pdsim:time sample at every frame 0..N
    checked = 0
    for key, entry in ref.items():
        if key == "range":
            continue
        samples, values = entry
        got_samples, got_values = got[key]
        assert got_samples == samples, f"{key}: time samples {got_samples} != {samples}"
        for t, (a, b) in enumerate(zip(values, got_values, strict=True)):
            if isinstance(a, np.ndarray):
                assert isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape, f"{key} at {t}"
                assert np.array_equal(a, b), f"{key} differs at frame {t} by {np.abs(a - b).max()}"
                checked += a.size
            else:
                assert a == b, f"{key} at frame {t}: {b!r} != {a!r}"
    assert checked > 0
    assert usd_problems(resumed) == []


def _first_frame(prim) -> float:
    """The first frame a prim has geometry: its first time code with points, or the start when it never has any."""
    from pxr import UsdGeom

    attr = UsdGeom.PointBased(prim).GetPointsAttr() if prim.IsA(UsdGeom.PointBased) else None
    samples = [] if attr is None else [t for t in attr.GetTimeSamples() if len(attr.Get(t) or []) > 0]
    return samples[0] if samples else 0.0


def _run_reference(build, tmp_path, **kw):
    reference = tmp_path / "reference.usdc"
    build().run(reference, device="cpu", progress=False, checkpoint_interval_s=None, **kw)
    return reference


def _interrupt(build, out, frame, polls=1, **kw) -> RunInterrupted:
    """Runs ``build()`` into ``out`` and stops it ``polls`` stop polls after frame ``frame`` was written."""
    stop = _StopAt(frame, polls)
    with pytest.raises(RunInterrupted) as ei:
        build().run(out, device="cpu", progress=False, stop=stop, on_frame=stop.on_frame, **kw)
    assert ei.value.checkpoint is not None and checkpoint_path(out).is_file()
    assert ei.value.last_frame == frame
    return ei.value


def _assert_resume_is_bit_identical(build, tmp_path, stop_frame: int, frames: int, polls: int = 2):
    """A run of ``build()`` stopped ``polls`` stop polls after frame ``stop_frame`` was written, then resumed, leaves
    no checkpoint and the same cache bit for bit as the uninterrupted run (frames 0..``frames``)."""
    reference = _run_reference(build, tmp_path)
    out = tmp_path / "out.usdc"
    _interrupt(build, out, stop_frame, polls, checkpoint_interval_s=60.0)
    build().run(out, device="cpu", progress=False, resume=True)
    assert not checkpoint_path(out).exists()
    _assert_same_cache(reference, out, frames)


@pytest.mark.parametrize(
    ("build", "stop_frame", "frames", "options"),
    [
        (_pd_bar, 4, 8, {}),
        (_pd_bar, 2, 8, {"fragments_as_prims": True, "color_attribute": "damage"}),
        (_pd_bar, 2, 8, {"crack_events": True, "debris_particles": 20}),
        (_fem_bar, 3, 8, {}),
        (_fem_pieces_pressed, 3, 6, {}),
    ],
    ids=["peridynamics", "peridynamics-fragment-prims", "peridynamics-events-debris", "fem", "fem-pieces-in-contact"],
)
def test_resumed_cache_plays_as_the_uninterrupted_one(tmp_path, build, stop_frame, frames, options):
    """Stopped inside a frame (at a step boundary, two stop polls after a frame end), then resumed: `out` alone holds
    frames 0..N, equal to the uninterrupted run's cache at every time code, bit for bit. The surfaces' topology
    changes at frames 1, 2, 3 and 7 (peridynamics; the FEM bar's at frame 1): the resumed run starts where it does not
    change, so an extra topology sample (or normals from smooth groups recomputed at the restart) would show."""
    reference = _run_reference(build, tmp_path, **options)
    out = tmp_path / "out.usdc"
    stopped = _interrupt(build, out, stop_frame, 2, checkpoint_interval_s=60.0, **options)
    report = build().run(out, device="cpu", progress=False, resume=True, **options)
    assert report.first_frame == stopped.last_frame + 1 and report.path == str(out)
    assert report.frames_written == frames - stopped.last_frame
    assert not checkpoint_path(out).exists()
    # one packed file: the resumed run appended to the run folder, then packed it and removed it
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("out")) == ["out.usdc"]
    _assert_same_cache(reference, out, frames)


def test_shifted_scene_with_defaults(tmp_path):
    """The bar 200 m away from the origin (shifted by (200, -50, 30) m), every run setting at its default (checkpoints
    every 60 s, surfaces on): the resumed cache equals the uninterrupted one bit for bit, and its points lie at the
    shifted position."""
    shift = (200.0, -50.0, 30.0)

    def build():
        return _pd_bar(shift, frames=6, ground=False)

    reference = tmp_path / "reference.usdc"
    build().run(reference, device="cpu", progress=False)
    out = tmp_path / "shifted.usdc"
    _interrupt(build, out, 2, 3)
    build().run(out, device="cpu", progress=False, resume=True)
    _assert_same_cache(reference, out, 6)
    cache = _read(out)
    x = cache["/World/bar.points"][1][-1] + cache["/World/bar.xformOp:translate"][1][-1]  # world = local + translate
    assert np.allclose(x.mean(axis=0), shift, atol=0.1)


def test_resume_from_an_older_checkpoint_replaces_the_later_frames(tmp_path):
    """A checkpoint at frame 2 kept aside while the run went on to frame 6 (fragment prims appear after frame 2),
    whose later frame layers are then spoiled: resuming from the frame-2 checkpoint rewrites the cache at once to end
    at frame 2 (the later frame files and the fragment prims defined after frame 2 are gone), then writes frames
    3..8 again. The result equals the uninterrupted run's cache."""
    from pxr import Sdf, Usd, Vt

    options = {"fragments_as_prims": True}
    reference = _run_reference(_pd_bar, tmp_path, **options)
    out = tmp_path / "out.usdc"
    older = tmp_path / "older.npz"

    stop = _StopAt(6)

    def keep(frame, solvers):  # called after frame ``frame`` is written, before its checkpoint: the checkpoint of 2
        if frame == 3:
            shutil.copy(checkpoint_path(out), older)
        stop.on_frame(frame, solvers)

    with pytest.raises(RunInterrupted) as ei:
        _pd_bar().run(out, device="cpu", progress=False, stop=stop, checkpoint_interval_s=0.0, on_frame=keep, **options)
    stopped = ei.value
    assert stopped.last_frame == 6 and older.is_file()

    def fragment_prims(path, frame):
        stage = Usd.Stage.Open(str(path))
        return sorted(
            str(p.GetPath()) for p in stage.Traverse() if "fragment_" in p.GetName() and _first_frame(p) <= frame
        )

    defined_late = sorted(set(fragment_prims(out, 99)) - set(fragment_prims(out, 2)))
    assert defined_late, "no fragment prim appeared after frame 2: the scene does not test their removal"
    run_dir = next((tmp_path / "out.frames").iterdir())
    attr = Sdf.Path("/World/bar.points")
    for frame in range(3, stopped.last_frame + 1):  # spoil the later frames: a resume must not keep them
        layer = Sdf.Layer.OpenAsAnonymous(str(run_dir / f"frame.{frame:06d}.usdc"))
        x = np.asarray(layer.QueryTimeSample(attr, float(frame)), dtype=np.float32) + np.float32(1.0)
        layer.SetTimeSample(attr, float(frame), Vt.Vec3fArray.FromNumpy(x))
        layer.Export(str(run_dir / f"frame.{frame:06d}.usdc"))
        del layer
    shutil.copy(older, checkpoint_path(out))

    from pdsim.output.writer import ViewWriter

    restored = []
    original = ViewWriter.restore

    def spy(self, state):
        restored.append(_read(out)["range"][:2])  # the cache as reopened, before the resumed run writes a frame
        restored.append(sorted(p.name for p in run_dir.iterdir() if p.name.startswith("frame.")))
        restored.append([str(p.GetPath()) for p in self.cache.stage.Traverse()])
        return original(self, state)

    ViewWriter.restore = spy
    try:
        report = _pd_bar().run(out, device="cpu", progress=False, resume=True, **options)
    finally:
        ViewWriter.restore = original
    assert report.first_frame == 3
    assert restored[0] == (0, 2)
    assert restored[1] == [f"frame.{f:06d}.usdc" for f in range(3)]
    assert not set(defined_late) & set(restored[2])  # the prims defined after frame 2 were gone when it reopened
    _assert_same_cache(reference, out, 8)


def test_a_resumed_run_stopped_again_keeps_its_frames_and_resumes_again(tmp_path):
    """A resumed run is itself stopped: `out` then plays frames 0..last (every finished frame of both runs, equal to
    the uninterrupted run's), and a second resume completes it."""
    reference = _run_reference(_pd_bar, tmp_path)
    out = tmp_path / "out.usdc"
    _interrupt(_pd_bar, out, 1, 3, checkpoint_interval_s=60.0)
    second = _interrupt(_pd_bar, out, 5, checkpoint_interval_s=60.0, resume=True)
    partial = _read(out)
    assert partial["range"][:2] == (0, second.last_frame)
    full = _read(reference)
    for key in ("/World/bar.points", "/World/bar.velocities", "/World/bar_surface.normals"):
        for t in range(second.last_frame + 1):
            assert np.array_equal(partial[key][1][t], full[key][1][t]), (key, t)
    assert usd_problems(out) == []
    _pd_bar().run(out, device="cpu", progress=False, resume=True)
    _assert_same_cache(reference, out, 8)


def test_resume_of_a_run_replacing_an_earlier_cache(tmp_path):
    """`out` held an earlier cache, so the stopped run wrote `out.partial.usdc`; the resumed run continues that
    partial cache (the earlier `out` stays untouched until it succeeds), then replaces `out` with it and removes the
    partial file and the earlier run's folder."""
    out = tmp_path / "out.usdc"
    _lattice_block().run(out, device="cpu", progress=False, frames=2)
    earlier = out.read_bytes()
    reference = _run_reference(_lattice_block, tmp_path)
    stopped = _interrupt(_lattice_block, out, 2, checkpoint_interval_s=60.0)
    partial = tmp_path / "out.partial.usdc"
    assert partial.is_file() and _read(partial)["range"][:2] == (0, stopped.last_frame)
    with pytest.raises(RunInterrupted):  # stopped again: the earlier cache is still `out`
        _lattice_block().run(out, device="cpu", progress=False, resume=True, stop=_StopAfter(2))
    assert out.read_bytes() == earlier and _read(out)["range"][:2] == (0, 2)
    _lattice_block().run(out, device="cpu", progress=False, resume=True)
    assert not partial.exists()
    assert not (tmp_path / "out.frames").exists()  # packed into out: no run folder left
    _assert_same_cache(reference, out, 6)


def test_reopening_checks_the_cache(tmp_path):
    """UsdCache(append_frame=) refuses a frame the cache has not finished, another fps or up axis, another run id,
    and a missing cache, each with a message naming what differs; a refused reopen changes nothing on disk."""
    path = tmp_path / "c.usdc"
    with UsdCache(path, fps=24.0) as cache:
        h = cache.add_points("p", widths=np.full(4, 0.1))
        for f in range(3):
            cache.write_points(h, f, np.full((4, 3), float(f)))
            cache.end_frame(f, time=f / 24.0)
        run = cache.run_id
    before = path.read_bytes()
    with pytest.raises(ValueError, match=r"append_frame=3 is not a finished frame .*frames 0\.\.2"):
        UsdCache(path, fps=24.0, append_frame=3)
    with pytest.raises(ValueError, match=r"fps=25\.0 differs"):
        UsdCache(path, fps=25.0, append_frame=1)
    with pytest.raises(ValueError, match="up_axis='Y' differs"):
        UsdCache(path, fps=24.0, up_axis="Y", append_frame=1)
    with pytest.raises(ValueError, match="holds the run 'run-x'"):
        UsdCache(path, fps=24.0, append_frame=1, append_run="run-x")
    with pytest.raises(FileNotFoundError):
        UsdCache(tmp_path / "none.usdc", fps=24.0, append_frame=1)
    assert path.read_bytes() == before
    with UsdCache(path, fps=24.0, append_frame=1, append_run=run) as cache:
        h = cache.existing("/World/p")
        assert h.point_count == 4 and cache.last_frame == 1
        cache.write_points(h, 2, np.full((4, 3), 7.0))
        cache.end_frame(2, time=2 / 24.0)
    values = _read(path)["/World/p.points"][1]
    assert [float(v[0, 0]) for v in values] == [0.0, 1.0, 7.0]
