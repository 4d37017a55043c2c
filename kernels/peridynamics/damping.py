"""Debris damping of brittle peridynamic bodies (Material.debris_damping; the material's internal damping,
Material.retardation_time, is a term of the force pass: kernels/peridynamics/step.py).

A brittle crack sheds particles that lost most of their bonds; released from a strained neighbourhood they carry a
share of its elastic energy as high-frequency motion that no coarse discretisation resolves (chips that fly off
faster than anything that hit the body). The kernel adds a drag towards the velocity of the material the particle
broke from: for a particle k with damage phi_k = 1 - sum_live w V beta / sum_all w V beta above its threshold,

    f_k += rho_k c_k (v_bar_k - v_k),    v_bar_k = sum_j w V_j beta v_j / sum_j w V_j beta

over its live bonds when it has any (a particle that hangs on a fragment by a few bonds stops rattling against it),
and over its whole reference family when it has none (a loose particle follows the material it came from instead
of flying off). Intact material (phi_k = 0) and particles below the threshold get nothing, so an intact body's
motion and energy are exactly those of the undamped model. The force is not paired (a chip's neighbours feel no
reaction): it removes momentum from the debris only, which holds a small share of the body's mass. By damping the
rattling of nearly free particles it also keeps some of them on their fragments (docs/fracture.md measures the
effect). Stability of the explicit step needs c dt < 1.
"""

import warp as wp

from ..launch import range_inputs


# add_debris_damping repeats compute_damage's sums of live and total bond weight (kernels/peridynamics/step.py) on
# purpose: it gathers the neighbours' velocities in the same loop, where sharing compute_damage's would take a second
# pass over the family.
@wp.kernel
def add_debris_damping(
    first: int,
    particles: wp.array(dtype=wp.int32),
    family_offsets: wp.array(dtype=wp.int32),
    family_neighbors: wp.array(dtype=wp.int32),
    bond_wv: wp.array(dtype=float),
    bond_alive: wp.array(dtype=wp.uint8),
    velocities: wp.array(dtype=wp.vec3),
    inv_density: wp.array(dtype=float),
    rate: wp.array(dtype=float),
    damage_threshold: wp.array(dtype=float),
    force_density: wp.array(dtype=wp.vec3),
):
    """Adds rho_k c_k (v_bar_k - v_k) to the force density [N/m^3] of each listed particle whose damage exceeds its
    threshold (module docstring): particle k = particles[first + tid], a gather over its family (it writes only its
    own row, so launches over disjoint ranges of the list can run at the same time). The list holds every particle,
    or those not in a rigid fragment and the rigid ones above the threshold (pdsim/peridynamics/handoff.py)."""
    k = particles[first + wp.tid()]
    c = rate[k]
    if c <= 0.0:
        return
    total = float(0.0)
    live = float(0.0)
    v_all = wp.vec3(0.0)
    v_live = wp.vec3(0.0)
    for q in range(family_offsets[k], family_offsets[k + 1]):
        wv = bond_wv[q]
        vj = velocities[family_neighbors[q]]
        total += wv
        v_all += wv * vj
        if bond_alive[q] != wp.uint8(0):
            live += wv
            v_live += wv * vj
    if total <= 0.0:
        return
    if 1.0 - live / total > damage_threshold[k]:
        v_bar = v_all / total
        if live > 0.0:
            v_bar = v_live / live
        force_density[k] = force_density[k] + (c / inv_density[k]) * (v_bar - velocities[k])


def debris_damping(launch, **arguments):
    """Adds the debris drag to force_density [N/m^3] of the particles of the list ``particles`` through
    ``launch(kernel, inputs)`` over the list's positions (a range launch: pdsim/peridynamics/ranges.py,
    ParticleRanges.launch, or kernels/peridynamics/step.py, single_launch) (add_debris_damping)."""
    launch(add_debris_damping, range_inputs(add_debris_damping, arguments))
