"""Recorded launches on the CPU (kernels/launch.py: launch_inputs): a launch repeated with the same arrays and values
replays a recording; any other array or value launches afresh, so a replay never runs stale arguments."""

import numpy as np
import warp as wp

from pdsim.default_scene import build_scene
from pdsim.kernels import launch as kl


@wp.kernel
def _shift(x: wp.array(dtype=float), s: float, out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = x[i] + s


def _replays(monkeypatch) -> list:
    """Counts the replays of recorded launches (wp.Launch.launch) from now on."""
    calls = []
    original = wp.Launch.launch

    def counted(self, *args, **kwargs):
        calls.append(self.kernel.key)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(wp.Launch, "launch", counted)
    return calls


def _bits(a: wp.array) -> bytes:
    return a.numpy().tobytes()


def test_repeated_launch_replays_and_a_changed_input_launches_afresh(monkeypatch):
    replays = _replays(monkeypatch)
    x = wp.array(np.array([-0.0, 1.0, 2.5], dtype=np.float32), device="cpu")
    out = wp.zeros(3, dtype=float, device="cpu")
    for _ in range(3):  # the first plain, the second recorded, the third replayed
        kl.launch(_shift, 3, device="cpu", x=x, s=0.5, out=out)
    assert replays == [_shift.key, _shift.key]
    assert out.numpy().tolist() == [0.5, 1.5, 3.0]
    # another value of a scalar: the result follows it, first time and repeated; -0.0 and 0.0 are told apart
    for s, expected in ((-0.0, [-0.0, 1.0, 2.5]), (0.0, [0.0, 1.0, 2.5])):
        for _ in range(3):
            kl.launch(_shift, 3, device="cpu", x=x, s=s, out=out)
            reference = wp.zeros(3, dtype=float, device="cpu")
            wp.launch(_shift, dim=3, inputs=[x, s, reference], device="cpu")
            assert _bits(out) == _bits(reference) == np.array(expected, dtype=np.float32).tobytes()
    # another output array, the same values: the new array is written, not the first one
    out.zero_()
    other = wp.full(3, 7.0, dtype=float, device="cpu")
    for _ in range(3):
        kl.launch(_shift, 3, device="cpu", x=x, s=0.0, out=other)
    assert other.numpy().tolist() == [0.0, 1.0, 2.5]
    assert out.numpy().tolist() == [0.0, 0.0, 0.0] and _bits(out) == bytes(12)
    assert len(kl._recorded[_shift]) <= kl.RECORDED_PER_KERNEL


def test_a_wrapped_launch_sees_every_launch(monkeypatch):
    """A tool that wraps wp.launch (pdsim run --explain) is called for every launch, none replayed past it."""
    seen = []
    original = wp.launch

    def wrapper(kernel, *args, **kwargs):
        seen.append(kernel.key)
        return original(kernel, *args, **kwargs)

    replays = _replays(monkeypatch)
    monkeypatch.setattr(wp, "launch", wrapper)
    x = wp.zeros(2, dtype=float, device="cpu")
    for _ in range(4):
        kl.launch(_shift, 2, device="cpu", x=x, s=1.0, out=x)
    assert seen == [_shift.key] * 4 and replays == []
    assert x.numpy().tolist() == [4.0, 4.0]


def _cantilever_state(monkeypatch, plain: bool) -> bytes:
    """The default scene's beam after steps of two lengths (a change of dt between them), every launch plain
    (``plain``: wp.launch wrapped, so nothing is replayed) or with replays."""
    if plain:
        original = wp.launch

        def plain_launch(*args, **kwargs):  # a wrapper: launch_inputs then replays nothing
            return original(*args, **kwargs)

        monkeypatch.setattr(wp, "launch", plain_launch)
    solver = build_scene().build_solvers(device="cpu")[0]
    for dt in (2.0e-4,) * 6 + (3.0e-4,) * 6:
        solver.step(dt)
    state = np.concatenate([solver.kin.u.numpy().ravel(), solver.kin.v.numpy().ravel()]).tobytes()
    monkeypatch.undo()
    return state


def test_steps_with_replays_match_plain_launches_bit_for_bit(monkeypatch):
    assert _cantilever_state(monkeypatch, plain=False) == _cantilever_state(monkeypatch, plain=True)
