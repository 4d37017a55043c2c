"""Restitution of dynamic rigid bodies (pdsim/rigid.py, kernels/rigid.py: the penalty form of the one contact law):
a rigid sphere and a rigid box dropped flat on the ground, and two spheres meeting head-on, rebound at the restitution
set, within 0.05."""

from __future__ import annotations

import numpy as np
import pytest

import pdsim
from pdsim.rigid import BoxShape, RigidBodies, RigidBody, SphereShape

G = 9.81


def _drop(shape, *, body_e, ground_e, device="cpu", dt=1.0e-3, height=0.1):
    """The body (density 1000 kg/m^3) released with its lowest point ``height`` [m] above the ground under gravity;
    (impact speed, rebound speed) [m/s]: the largest downward and, after it, the largest upward speed over twice the
    fall's time."""
    half = shape.radius if isinstance(shape, SphereShape) else 0.5 * shape.size[2]
    ground = pdsim.GroundPlane(normal=(0.0, 0.0, 1.0), offset=0.0, restitution=ground_e)
    body = RigidBody(shape, density=1000.0, position=(0.0, 0.0, half + height), restitution=body_e)
    system = RigidBodies([body], ground=ground, colliders=[], gravity=(0.0, 0.0, -G), origin=np.zeros(3), device=device)
    vz = []
    for _ in range(int(2.0 * np.sqrt(2.0 * height / G) / dt)):
        system.simulate(dt, 1)
        vz.append(body.state_values()["velocity"][2])
    vz = np.asarray(vz)
    i = int(np.argmin(vz))
    return float(-vz[i]), float(vz[i:].max())


@pytest.mark.parametrize("e", [0.1, 0.6])
@pytest.mark.parametrize("shape", [SphereShape(0.05), BoxShape((0.2, 0.2, 0.1))], ids=["sphere", "box"])
def test_a_rigid_body_dropped_on_the_ground_rebounds_at_its_restitution(shape, e, device):
    """Dropped from 10 cm (impact at 1.39 m/s, steps of 1 ms), a sphere and a box landing flat leave the ground at e
    times their impact speed within 0.05, whether e is the body's or the ground's (the pair takes the larger of the
    two sides', here the one given). Measured: 0.069 for e = 0.1 and 0.585 for e = 0.6 (the law's, as a particle on
    the ground's penalty form: tests/test_contact_law.py). Without a restitution on either side the contact is
    inelastic: the body stays on the ground (rebound below 1 mm/s)."""
    v_in, v_out = _drop(shape, body_e=e, ground_e=None, device=device)
    print(f"{type(shape).__name__} e = {e}: impact {v_in:.3f} m/s, rebound {v_out:.4f} m/s, ratio {v_out / v_in:.3f}")
    assert v_in == pytest.approx(np.sqrt(2.0 * G * 0.1), rel=0.01)
    assert v_out / v_in == pytest.approx(e, abs=0.05)
    v_in, v_out = _drop(shape, body_e=None, ground_e=e, device=device)
    assert v_out / v_in == pytest.approx(e, abs=0.05)
    _, v_out = _drop(shape, body_e=None, ground_e=None, device=device)
    assert v_out < 1.0e-3


@pytest.mark.parametrize("e", [0.1, 0.6])
def test_two_rigid_spheres_meeting_head_on_part_at_their_restitution_with_momentum_conserved(e, device):
    """Two steel spheres (5 cm, the second twice as dense) meeting head-on at 2 m/s in space, each of restitution e:
    their relative speed after the contact is e times the one before within 0.05 (both passes of the pair find the same
    contact and share it), and the linear momentum is conserved to 1e-12 of its size."""
    a = RigidBody(SphereShape(0.05), density=7850.0, position=(-0.15, 0.0, 0.0), velocity=(2.0, 0.0, 0.0),
                  friction=0.0, restitution=e)  # fmt: skip
    b = RigidBody(SphereShape(0.05), density=15700.0, position=(0.0, 0.0, 0.0), friction=0.0, restitution=e)
    system = RigidBodies([a, b], ground=None, colliders=[], gravity=(0.0, 0.0, 0.0), origin=np.zeros(3), device=device)
    p0 = system.linear_momentum()
    system.simulate(1.0e-3, 200)
    assert np.allclose(system.linear_momentum(), p0, rtol=0.0, atol=1e-12 * np.linalg.norm(p0))
    v_rel = b.state_values()["velocity"][0] - a.state_values()["velocity"][0]
    print(f"two spheres e = {e}: relative speed after / before {v_rel / 2.0:.3f}")
    assert v_rel / 2.0 == pytest.approx(e, abs=0.05)


def test_a_tilted_box_dropped_on_a_box_with_restitution_comes_to_rest_on_it():
    """A 10 cm box released tilted (about 12 degrees) 10 cm above a 20 x 20 x 10 cm box resting on the ground, all
    pairs of restitution 0.3 (the penalty form between boxes and with the ground): after 1 s both are at rest
    (speeds below 0.01 m/s, spin below 0.01 rad/s: what remains is the leapfrog's g dt / 2) with the top box's centre
    one box height above the lower one's within 2 mm (the penalty's sag: g dt^2 / CONTACT_OMEGA_DT^2 per contact)."""
    q = np.array([0.1, 0.05, 0.0, 1.0])
    q /= np.linalg.norm(q)
    ground = pdsim.GroundPlane(normal=(0.0, 0.0, 1.0), offset=0.0, restitution=0.3)
    low = RigidBody(BoxShape((0.2, 0.2, 0.1)), density=1000.0, position=(0.0, 0.0, 0.05), restitution=0.3)
    top = RigidBody(BoxShape((0.1, 0.1, 0.1)), density=1000.0, position=(0.01, 0.0, 0.25), orientation=tuple(q),
                    restitution=0.3)  # fmt: skip
    stack = RigidBodies([low, top], ground=ground, colliders=[], gravity=(0.0, 0.0, -G), origin=np.zeros(3),
                        device="cpu")  # fmt: skip
    stack.simulate(1.0e-3, 1000)
    s_top, s_low = top.state_values(), low.state_values()
    for s in (s_top, s_low):
        assert np.linalg.norm(s["velocity"]) < 0.01
        assert np.linalg.norm(s["angular_velocity"]) < 0.01
    assert s_top["position"][2] - s_low["position"][2] == pytest.approx(0.1, abs=2.0e-3)
    assert s_low["position"][2] == pytest.approx(0.05, abs=2.0e-3)


def test_a_rigid_body_starting_inside_the_ground_with_a_restitution_is_lifted_onto_it_not_thrown():
    """A box placed 1 mm into the ground, its pair with the ground of restitution 0.6 (the penalty form), stepped at
    10 us as beside a fine peridynamic body: it is lifted onto the ground before the first step, with a warning, and
    stays there (speed below 0.01 m/s over 2000 steps). Left inside (the lift skipped), the spring threw it out at
    11.8 m/s (of the order of CONTACT_OMEGA_DT x 1 mm / 10 us = 15 m/s): the test fails there."""
    ground = pdsim.GroundPlane(normal=(0.0, 0.0, 1.0), offset=0.0, restitution=0.6)
    box = RigidBody(BoxShape((0.2, 0.2, 0.1)), density=1000.0, position=(0.0, 0.0, 0.049), name="box")
    with pytest.warns(UserWarning, match="1 mm inside the ground"):
        system = RigidBodies([box], ground=ground, colliders=[], gravity=(0.0, 0.0, -G), origin=np.zeros(3),
                             device="cpu")  # fmt: skip
    assert box.state_values()["position"][2] == pytest.approx(0.05, abs=1e-12)
    fastest = 0.0
    for _ in range(20):
        system.simulate(1.0e-5, 100)
        fastest = max(fastest, float(np.linalg.norm(box.state_values()["velocity"])))
    assert fastest < 0.01, fastest
