"""Crack events: the bonds that broke since the last look, gathered on the device into compact arrays.

A bond k -> j counts once, from its lower particle (k < j; both directed copies break in the same step). The bonds
that broke are flagged (:func:`flag_broken_bonds`), an exclusive prefix sum of the flags gives each its row
(``wp.utils.array_scan``: the same rows on every device and thread count), and :func:`gather_broken_bonds` writes
each row: the bond's midpoint, its direction when it broke and the elastic energy it held then. The force pass keeps
a broken bond's cached (n, e) (kernels/peridynamics/step.py: a broken bond is skipped by every later pass), so the
direction and extension read at the frame's end are those of the step in which the bond broke.

Energy of a bond k <-> j when it broke [J]: V_k b_k (w V beta G^dev)_kj (e_kj - e^p_kj)^2 + the same from j's side,
the two terms of the bond in the particles' elastic energies W V (kernels/peridynamics/step.py, energy), which the
break removes.
"""

import warp as wp

from ..launch import launch


@wp.kernel
def flag_broken_bonds(
    family_offsets: wp.array(dtype=wp.int32),
    family_neighbors: wp.array(dtype=wp.int32),
    bond_alive: wp.array(dtype=wp.uint8),
    bond_alive_before: wp.array(dtype=wp.uint8),
    flags: wp.array(dtype=wp.int32),
):
    """flags[q] = 1 for each bond q of particle k = tid that was alive in ``bond_alive_before`` and is broken now, with
    k < j (each bond once), else 0."""
    k = wp.tid()
    for q in range(family_offsets[k], family_offsets[k + 1]):
        f = int(0)
        if bond_alive_before[q] != wp.uint8(0) and bond_alive[q] == wp.uint8(0) and k < family_neighbors[q]:
            f = 1
        flags[q] = f


@wp.func
def bond_energy(
    q: int,
    k: int,
    volumes: wp.array(dtype=float),
    dev_b: wp.array(dtype=float),
    bond_wv_dev: wp.array(dtype=float),
    bond_ne: wp.array(dtype=wp.vec4),
    plastic_bond_count: int,
    bond_plastic: wp.array(dtype=float),
):
    """V_k b_k (w V beta G^dev)_q (e_q - e^p_q)^2 [J]: the directed bond q's term in particle k's elastic energy."""
    e = bond_ne[q][3]
    if q < plastic_bond_count:
        e = e - bond_plastic[q]
    return volumes[k] * dev_b[k] * bond_wv_dev[q] * e * e


@wp.kernel
def gather_broken_bonds(
    family_offsets: wp.array(dtype=wp.int32),
    family_neighbors: wp.array(dtype=wp.int32),
    flags: wp.array(dtype=wp.int32),
    rows: wp.array(dtype=wp.int32),
    rest_positions: wp.array(dtype=wp.vec3),
    displacements: wp.array(dtype=wp.vec3),
    volumes: wp.array(dtype=float),
    dev_b: wp.array(dtype=float),
    bond_wv_dev: wp.array(dtype=float),
    bond_ne: wp.array(dtype=wp.vec4),
    plastic_bond_count: int,
    bond_plastic: wp.array(dtype=float),
    event_positions: wp.array(dtype=wp.vec3),
    event_normals: wp.array(dtype=wp.vec3),
    event_energies: wp.array(dtype=float),
):
    """For each flagged bond q of particle k = tid: row rows[q] gets the bond's midpoint (rest + u, in the frame of
    ``rest_positions``) [m], its unit direction n_kj when it broke and its energy then (both directions' terms; the
    reverse bond j -> k is found in j's family) [J]."""
    k = wp.tid()
    for q in range(family_offsets[k], family_offsets[k + 1]):
        if flags[q] == 0:
            continue
        j = family_neighbors[q]
        r = rows[q]
        event_positions[r] = 0.5 * (rest_positions[k] + displacements[k] + rest_positions[j] + displacements[j])
        c = bond_ne[q]
        event_normals[r] = wp.vec3(c[0], c[1], c[2])
        energy = bond_energy(q, k, volumes, dev_b, bond_wv_dev, bond_ne, plastic_bond_count, bond_plastic)
        for p in range(family_offsets[j], family_offsets[j + 1]):
            if family_neighbors[p] == k:
                energy += bond_energy(p, j, volumes, dev_b, bond_wv_dev, bond_ne, plastic_bond_count, bond_plastic)
        event_energies[r] = energy


def broken_bond_flags(count, family_offsets, family_neighbors, bond_alive, bond_alive_before, flags, device):
    """flags (int32 per bond) of the bonds of the ``count`` particles that broke since ``bond_alive_before``
    (flag_broken_bonds)."""
    launch(
        flag_broken_bonds,
        count,
        device=device,
        family_offsets=family_offsets,
        family_neighbors=family_neighbors,
        bond_alive=bond_alive,
        bond_alive_before=bond_alive_before,
        flags=flags,
    )


def event_rows(flags, rows) -> None:
    """rows = the exclusive prefix sum of ``flags`` (each flagged bond's row in the event arrays)."""
    wp.utils.array_scan(flags, rows, inclusive=False)


def broken_bond_events(count, device, **arguments):
    """The events of the flagged bonds of the ``count`` particles (gather_broken_bonds; arguments by parameter
    name)."""
    launch(gather_broken_bonds, count, device=device, **arguments)
