"""Velocity-Verlet integration with boundary conditions.

One step of length dt, with a_n the acceleration from the previous force evaluation:
    integrate_kick_drift:  v <- v + dt/2 a_n ; x <- x + dt v      (then boundary conditions and colliders)
    (dilatation and force kernels at the new positions)
    integrate_kick:        a_{n+1} = f / rho + g - c v ; v <- v + dt/2 a_{n+1}
Particle kinds: 0 free, 1 fixed (held at its reference position), 2 prescribed velocity on the axes whose entry of
``prescribed_axes`` is 1 (the other components move freely, e.g. a roller grip).
"""

import warp as wp

PARTICLE_FREE = wp.constant(0)
PARTICLE_FIXED = wp.constant(1)
PARTICLE_PRESCRIBED = wp.constant(2)


@wp.kernel
def integrate_kick_drift(
    positions: wp.array(dtype=wp.vec3),
    velocities: wp.array(dtype=wp.vec3),
    accelerations: wp.array(dtype=wp.vec3),
    rest_positions: wp.array(dtype=wp.vec3),
    kind: wp.array(dtype=wp.int32),
    prescribed_velocity: wp.array(dtype=wp.vec3),
    prescribed_axes: wp.array(dtype=wp.vec3),
    dt: float,
):
    """First half kick and drift; fixed particles stay at rest, prescribed components move at their velocity."""
    i = wp.tid()
    c = kind[i]
    if c == PARTICLE_FIXED:
        positions[i] = rest_positions[i]
        velocities[i] = wp.vec3(0.0)
    elif c == PARTICLE_PRESCRIBED:
        m = prescribed_axes[i]
        free = velocities[i] + (0.5 * dt) * accelerations[i]
        v = wp.cw_mul(m, prescribed_velocity[i]) + wp.cw_mul(wp.vec3(1.0) - m, free)
        velocities[i] = v
        positions[i] = positions[i] + dt * v
    else:
        v = velocities[i] + (0.5 * dt) * accelerations[i]
        velocities[i] = v
        positions[i] = positions[i] + dt * v


@wp.kernel
def integrate_kick(
    velocities: wp.array(dtype=wp.vec3),
    force_density: wp.array(dtype=wp.vec3),
    inv_density: wp.array(dtype=float),
    kind: wp.array(dtype=wp.int32),
    prescribed_axes: wp.array(dtype=wp.vec3),
    gravity: wp.vec3,
    damping: wp.array(dtype=float),
    dt: float,
    accelerations: wp.array(dtype=wp.vec3),
):
    """a = f / rho + g - damping v (v at the half step); second half kick for free particles and for the free
    components of prescribed ones."""
    i = wp.tid()
    v = velocities[i]
    a = force_density[i] * inv_density[i] + gravity - damping[i] * v
    accelerations[i] = a
    c = kind[i]
    if c == PARTICLE_FREE:
        velocities[i] = v + (0.5 * dt) * a
    elif c == PARTICLE_PRESCRIBED:
        velocities[i] = v + (0.5 * dt) * wp.cw_mul(wp.vec3(1.0) - prescribed_axes[i], a)


@wp.kernel
def max_speed_and_finite(
    positions: wp.array(dtype=wp.vec3),
    velocities: wp.array(dtype=wp.vec3),
    result: wp.array(dtype=float),
):
    """result[0] = max |v| over particles; result[1] = 1 when any position or velocity is not finite."""
    i = wp.tid()
    x = positions[i]
    v = velocities[i]
    s = wp.length(v)
    if wp.isnan(s) or wp.isinf(s) or wp.isnan(wp.length(x)) or wp.isinf(wp.length(x)):
        result[1] = 1.0
    else:
        wp.atomic_max(result, 0, s)
