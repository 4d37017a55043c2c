"""The corotated element's rotation (kernels/fem/elements.py: rotation_iterative) against the SVD's polar rotation.

The iteration stops either when its Newton step is below the tolerance (1e-6 rad in float32, 1e-12 rad in float64)
or right after a Newton step of length w whose cubic bound |H^-1|_F |B|_F w^3 is below it. Both must leave the
rotation within the tolerance of the polar rotation of F, from warm starts near it (the explicit step's case: one
iteration) to cold starts far from it (several iterations, the SVD beyond 16)."""

import functools

import numpy as np
import pytest
import warp as wp
from scipy.spatial.transform import Rotation

from pdsim.kernels.fem.elements import fem_funcs, fem_types

TOLERANCE = {"float32": 1.0e-6, "float64": 1.0e-12}


@functools.cache
def _rotation_kernel(dtype):
    _, mat33, _ = fem_types(dtype)
    quat = wp.types.quaternion(dtype)
    rotation_iterative = fem_funcs(dtype)["rotation_iterative"]

    @wp.kernel(module="unique")
    def rotations(a: wp.array(dtype=mat33), q0: wp.array(dtype=quat), r_out: wp.array(dtype=mat33)):
        i = wp.tid()
        r, _q = rotation_iterative(a[i], q0[i])
        r_out[i] = r

    return rotations


def _samples(n, seed):
    """n deformation gradients A = Q S (S symmetric positive definite: strains 1e-4 to 0.5, or principal stretches
    0.2 to 3 in a random frame), their polar rotations Q (float64), and warm starts turned from Q by 1e-6 to 0.5 rad
    about random axes (the last tenth: cold starts at the identity, up to 170 degrees away)."""
    rng = np.random.default_rng(seed)
    s = np.empty((n, 3, 3))
    half = n // 2
    e = rng.normal(size=(half, 3, 3)) * 10.0 ** rng.uniform(-4, np.log10(0.5), size=(half, 1, 1))
    s[:half] = np.eye(3) + 0.25 * (e + e.transpose(0, 2, 1))
    frame = Rotation.random(n - half, random_state=rng).as_matrix()
    stretch = 10.0 ** rng.uniform(np.log10(0.2), np.log10(3.0), size=(n - half, 3))
    s[half:] = frame @ (stretch[:, :, None] * frame.transpose(0, 2, 1))
    keep = np.linalg.eigvalsh(s).min(axis=1) > 0.05
    s = s[keep]
    q = Rotation.random(len(s), random_state=rng)
    a = q.as_matrix() @ s
    axis = rng.normal(size=(len(s), 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = 10.0 ** rng.uniform(-6, np.log10(0.5), size=(len(s), 1))
    start = Rotation.from_rotvec(axis * angle) * q
    cold = len(s) - len(s) // 10
    turn = rng.uniform(0.0, np.radians(170.0), size=(len(s) - cold, 1))
    q_cold = Rotation.from_rotvec(axis[cold:] * turn)
    a[cold:] = q_cold.as_matrix() @ s[cold:]
    q_exact = np.concatenate([q.as_matrix()[:cold], q_cold.as_matrix()])
    quat = start.as_quat()
    quat[cold:] = [0.0, 0.0, 0.0, 1.0]
    return a, q_exact, quat


def _angle(r, q):
    """The angle [rad] between rotations R and Q, as asin of half the axial vector of R Q^T - (R Q^T)^T (no
    cancellation for small angles); pi where R Q^T turns by more than a right angle."""
    m = r @ q.transpose(0, 2, 1)
    w = np.stack([m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]], axis=1)
    angle = np.arcsin(np.clip(0.5 * np.linalg.norm(w, axis=1), 0.0, 1.0))
    return np.where(np.trace(m, axis1=1, axis2=2) > 1.0, angle, np.pi)


def _explicit_step_samples(n, seed):
    """n deformation gradients of an explicit step's regime: strains 1e-6 to 0.1 in a random frame, any rotation Q,
    and warm starts turned from Q by 1e-8 to 1e-2 rad (the rotation of one step). Returns (a, q_exact, quat) as
    _samples."""
    rng = np.random.default_rng(seed)
    e = rng.normal(size=(n, 3, 3)) * 10.0 ** rng.uniform(-6, -1, size=(n, 1, 1))
    s = np.eye(3) + 0.5 * (e + e.transpose(0, 2, 1))
    q = Rotation.random(n, random_state=rng)
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    start = Rotation.from_rotvec(axis * 10.0 ** rng.uniform(-8, -2, size=(n, 1))) * q
    return q.as_matrix() @ s, q.as_matrix(), start.as_quat()


SAMPLES = {"wide": lambda: _samples(4000, seed=3), "explicit_step": lambda: _explicit_step_samples(4000, seed=5)}


def _rotations(precision, samples):
    """(R from the kernel [n, 3, 3] float64, the exact polar rotations) for the samples."""
    dtype = wp.float64 if precision == "float64" else wp.float32
    np_dtype = np.float64 if precision == "float64" else np.float32
    _, mat33, _ = fem_types(dtype)
    a, q_exact, quat = SAMPLES[samples]()
    out = wp.zeros(len(a), dtype=mat33, device="cpu")
    wp.launch(
        _rotation_kernel(dtype),
        dim=len(a),
        inputs=[
            wp.array(a.astype(np_dtype), dtype=mat33, device="cpu"),
            wp.array(quat.astype(np_dtype), dtype=wp.types.quaternion(dtype), device="cpu"),
            out,
        ],
        device="cpu",
    )
    return out.numpy().astype(np.float64), q_exact


@pytest.mark.parametrize("samples", list(SAMPLES))
@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_rotation_iterative_is_the_polar_rotation_within_its_tolerance(precision, samples):
    r, q_exact = _rotations(precision, samples)
    angle = _angle(r, q_exact)
    # float32: the tolerance plus the rounding of R and of a (a few float32 epsilons)
    allowed = TOLERANCE[precision] + (4.0 * float(np.finfo(np.float32).eps) if precision == "float32" else 1.0e-14)
    assert angle.max() <= allowed, f"{precision} {samples}: worst angle {angle.max():.3g} rad > {allowed:.3g}"
