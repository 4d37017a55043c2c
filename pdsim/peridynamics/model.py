"""The peridynamic model (immutable after build) and state (per step), and the kernels' launches that build the
model: families, bond geometry, surface corrections, fracture and plasticity constants."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from ..kernels import neighbors as kn
from ..kernels.peridynamics import bonds as kb
from ..kernels.peridynamics import step as pd_step
from ..materials import strength_cells
from ..regions import BoxRegion
from .body import PeridynamicBody


@dataclass
class PeridynamicModel:
    """Immutable data of all peridynamic bodies of a scene, concatenated (bonds never join two bodies).

    Arrays are Warp arrays on the solver's device; particle_count rows for per-particle data, bond_count for bonds.
    """

    particle_count: int
    bond_count: int
    body_offsets: np.ndarray  # first particle of each body, shape [body_count + 1]
    rest_positions: object  # [m], vec3, in the local frame (world - origin)
    volumes: object  # [m^3]
    inv_density: object  # [m^3/kg]
    spacing: object  # h per particle [m]
    horizon: object  # delta per particle [m]
    radius: object  # collision radius h/2 [m]
    family_offsets: object  # CSR row starts, int32 [particle_count + 1]
    family_neighbors: object  # int32 [bond_count]
    bond_geom: object  # (xi / L, L), vec4 [bond_count]
    bond_wv: object  # w V_j beta [m^3], [bond_count]
    bond_wv_dil: object  # w V_j beta G^dil: dilatation weight (bond_wv unless the directional correction is on)
    bond_wv_dev: object  # w V_j beta G^dev: deviatoric weight (bond_wv unless the directional correction is on)
    dil_d: object  # d_k [1/m^4]
    dev_b: object  # b_k [Pa/m^5]
    dil_c0: object  # c0 = kappa/2 - 5 mu/6 [Pa]
    dil_coef: object  # d_k c0 [Pa/m^4]
    weighted_volume: object  # m_k = sum_j w L^2 V_j beta [m^5]
    fracture: bool = False  # some body can break: bond_alive and the fracture branches are live
    plastic: bool = False  # some body yields: plastic arrays exist for the first plastic_bond_count bonds
    plastic_particle_count: int = 0  # yielding bodies come first in the particle order
    plastic_bond_count: int = 0
    bond_critical_stretch: object = None  # s_c per bond (anisotropy and unbreakable regions applied) [-]
    bond_alive_initial: object = None  # uint8 per bond: 0 for bonds cut by notches
    compressive_bonus: object = None  # Material.compressive_bonus alpha per particle [-]
    compressive_stretch_floor: object = None  # Material.compressive_bonus_cap / alpha per particle (1e30: no cap) [-]
    failure_eqps: object = None  # ductile failure plastic strain per particle [-]
    yield_stress: object = None  # sigma_Y0 per plastic particle [Pa]
    hardening: object = None  # H per plastic particle [Pa]
    psi_scale: object = None  # family share of the continuum deviatoric norm per plastic particle [-]
    bond_reverse: object = None  # index of bond j -> k for each plastic bond k -> j
    debris_rate: object = None  # debris damping rate c per particle [1/s] (None: no body damps its debris)
    debris_damage: object = None  # damage above which debris damping acts, per particle [-]
    retardation: np.ndarray = None  # Material.retardation_time tau per particle [s], host (None: no internal damping)
    damping_b: object = None  # tau_k b_k per particle [Pa s/m^5]: the force pass's internal damping (None: none)
    density_host: np.ndarray = field(repr=False, default=None)
    volumes_host: np.ndarray = field(repr=False, default=None)
    rest_host: np.ndarray = field(repr=False, default=None)


@dataclass
class PeridynamicState:
    """Per-step data of the bonds (displacements, velocities and accelerations live in the solver's PointKinematics):
    dilatation theta [-],
    bp = (b_k, P_k) per particle, force density [N/m^3]; per bond the deformed (n, e) cached by the dilatation pass
    for the force pass."""

    theta: object
    bp: object
    force_density: object
    bond_ne: object
    bond_alive: object = None  # uint8 per bond (fracture)
    stretch_min: object = None  # most compressive live stretch per particle, this step (fracture)
    bond_plastic: object = None  # plastic extension per plastic bond [m]
    bond_plastic_reverse: object = None  # the reverse bond's plastic extension per plastic bond [m] (a mirror)
    eqps: object = None  # equivalent plastic strain per particle [-]


DIRECTIONAL_STRETCH = 1.0e-3
DIRECTIONAL_CALIBRATION = "uniaxial_stress"  # or "uniaxial_stretch" (Madenci-Oterkus); docs/accuracy.md compares


def _directional_factors(rest_h, delta_h, nu_h, offsets, neighbors, bond_geom, bond_wv, device):
    """Correction factors per particle and axis (Madenci-Oterkus): the continuum value over the discrete family value
    of the dilatation under a uniaxial stretch zeta along the axis (theta = zeta), and of the deviatoric sum
    sum_j w e^2 V_j beta under uniaxial stress along the axis: stretch zeta with lateral contraction -nu zeta
    (continuum pi delta^5 zeta^2 ((1 + nu)^2 / 5 - 2 nu (1 + nu) / 3 + nu^2)). Madenci and Oterkus use the uniaxial
    stretch for both; calibrating the deviatoric sum on uniaxial stress also corrects the Poisson coupling that thin
    parts feel in tension and bending (about halves the bar-stiffness error, docs/accuracy.md), while the dilatation
    keeps the well-conditioned stretch target (theta under uniaxial stress, (1 - 2 nu) zeta, vanishes as nu -> 1/2).
    Returns two arrays of shape [n, 3]; 1 where a family is empty."""
    n = len(rest_h)
    zeta = DIRECTIONAL_STRETCH
    ks = pd_step.make_step_kernels(False, False)
    launch = pd_step.single_launch(n, device)
    ones = wp.array(np.ones(n, dtype=np.float32), dtype=float, device=device)
    zeros = wp.zeros(n, dtype=float, device=device)
    sum_dil = wp.zeros(n, dtype=float, device=device)
    sum_dev = wp.zeros(n, dtype=float, device=device)
    zeros_out = wp.zeros(n, dtype=float, device=device)  # dilatation of the stress state: only its bond cache is used
    bp = wp.zeros(n, dtype=wp.vec2, device=device)
    nb = bond_wv.shape[0]
    bond_ne = wp.zeros(nb, dtype=wp.vec4, device=device)
    u8, f1, i1 = pd_step.placeholders(device)
    f_dil = np.ones((n, 3))
    f_dev = np.ones((n, 3))
    d_cont = 9.0 / (4.0 * math.pi * delta_h**4)
    nu = nu_h if DIRECTIONAL_CALIBRATION == "uniaxial_stress" else np.zeros_like(nu_h)
    dev_cont = math.pi * delta_h**5 * zeta**2 * ((1.0 + nu) ** 2 / 5.0 - 2.0 * nu * (1.0 + nu) / 3.0 + nu**2)

    def elastic_sums(scale, theta_out):
        """Writes sum_j w e V beta into theta_out and caches the bonds' (n, e) for the displacements
        rest * (scale - 1) of a homogeneous deformation
        (the elastic kernels with d = 1, c0 = 0, b = 1)."""
        pos = wp.array((rest_h * (scale - 1.0)).astype(np.float32), dtype=wp.vec3, device=device)
        pd_step.dilatation(
            launch,
            ks,
            displacements=pos,
            family_offsets=offsets,
            family_neighbors=neighbors,
            bond_geom=bond_geom,
            bond_wv_dil=bond_wv,
            dil_d=ones,
            dil_coef=zeros,
            dev_b=zeros,
            bond_alive=u8,
            theta=theta_out,
            bp=bp,
            bond_ne=bond_ne,
            stretch_min=f1,
            **pd_step.plastic_placeholders(f1, i1),
            live_particles=i1,
        )

    for axis in range(3):
        stretch = np.ones((len(rest_h), 3))
        stretch[:, axis] = 1.0 + zeta
        stress = np.repeat((1.0 - nu * zeta)[:, None], 3, axis=1)
        stress[:, axis] = 1.0 + zeta
        elastic_sums(stretch, sum_dil)  # dilatation factor: uniaxial stretch
        elastic_sums(stress, zeros_out)  # deviatoric factor: uniaxial stress (only the bond cache is used)
        pd_step.strain_energy_density(
            launch,
            ks,
            family_offsets=offsets,
            bond_ne=bond_ne,
            bond_wv_dev=bond_wv,
            bond_alive=u8,
            plastic_bond_count=0,
            bond_plastic=f1,
            theta=zeros,
            dev_b=ones,
            dil_c0=zeros,
            energy_density=sum_dev,
        )
        sd = sum_dil.numpy().astype(np.float64)
        sv = sum_dev.numpy().astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            f_dil[:, axis] = np.where(sd > 0, zeta / (d_cont * sd), 1.0)
            f_dev[:, axis] = np.where(sv > 0, dev_cont / sv, 1.0)
    return f_dil, f_dev


def _strength_fields(bodies, counts, device) -> dict:
    """The init_bond_fracture arguments of the bodies' strength fields (Material.strength_correlation_length): each
    particle's rest position in its body's frame (relative to the centre of the shape's bounding box, turned back by
    the body's material_rotation; float64 on the host, then float32), the first of its body's modes (-1: no field)
    and the modes of every body with a field, concatenated (kb.strength_field_modes)."""
    count = kb.STRENGTH_FIELD_MODES
    first, modes, local = [], [], []
    for c, b in zip(counts, bodies, strict=True):  # per body (a handful), not per particle
        ell = b.material.strength_correlation_length
        if ell is None:
            first.append(np.full(c, -1, dtype=np.int32))
            local.append(np.zeros((c, 3)))
            continue
        first.append(np.full(c, count * len(modes), dtype=np.int32))
        modes.append(kb.strength_field_modes(ell, b.material.strength_seed, count))
        centre = 0.5 * (b.shape.bounds[0] + b.shape.bounds[1])
        local.append((b.rest_positions - centre) @ b.material_rotation)  # R^T (x - c), row by row
    table = np.concatenate(modes) if modes else np.zeros((1, 4), dtype=np.float32)
    return {
        "field_positions": wp.array(np.concatenate(local).astype(np.float32), dtype=wp.vec3, device=device),
        "field_first_mode": wp.array(np.concatenate(first), dtype=wp.int32, device=device),
        "field_modes": wp.array(table, dtype=wp.vec4, device=device),
        "field_mode_count": count,
    }


def _strength_cells(bodies, counts) -> tuple[np.ndarray, np.ndarray]:
    """Each particle's cell (pdsim.materials.strength_cells of its body's rest positions in the body's frame, as
    _strength_fields; numbered apart for each body; -1 for a body without cells) and its body's strength_cell_ratio
    (1 without cells)."""
    cells, ratios, base = [], [], 0
    for c, b in zip(counts, bodies, strict=True):  # per body (a handful), not per particle
        material = b.material
        if material.strength_cell_size is None:
            cells.append(np.full(c, -1, dtype=np.int64))
            ratios.append(np.ones(c))
            continue
        centre = 0.5 * (b.shape.bounds[0] + b.shape.bounds[1])
        label = strength_cells(material, b.shape.bounds, (b.rest_positions - centre) @ b.material_rotation)
        cells.append(base + label)
        ratios.append(np.full(c, material.strength_cell_ratio))
        base += int(label.max()) + 1
    return np.concatenate(cells).astype(np.int32), np.concatenate(ratios)


def build_model(bodies: list[PeridynamicBody], device, origin=(0.0, 0.0, 0.0)) -> PeridynamicModel:
    """Concatenates the bodies, builds their families and per-bond / per-particle constants (all in kernels)."""
    counts = [b.particle_count for b in bodies]
    body_offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    n = int(body_offsets[-1])

    def per_particle(values):
        return np.concatenate([np.full(c, v, dtype=np.float64) for c, v in zip(counts, values, strict=False)])

    rest_h = np.concatenate([b.rest_positions for b in bodies])
    vol_h = np.concatenate([b.volumes for b in bodies])
    rho_h = per_particle([b.material.density for b in bodies])
    h_h = per_particle([b.spacing for b in bodies])
    delta_h = per_particle([b.horizon for b in bodies])
    search_h = delta_h + np.where(per_particle([b.partial_volumes for b in bodies]) > 0, 0.5 * h_h, 0.0)
    kappa_h = per_particle([b.material.bulk_modulus for b in bodies])
    mu_h = per_particle([b.material.shear_modulus for b in bodies])
    body_id_h = np.repeat(np.arange(len(bodies), dtype=np.int32), counts)

    f32 = np.float32

    def arr(a):
        """A float32 Warp array on the model's device."""
        return wp.array(np.asarray(a, dtype=f32), dtype=float, device=device)

    local_h = rest_h - np.asarray(origin, dtype=np.float64)  # the local frame: float32 keeps the body's precision
    rest = wp.array(local_h.astype(f32), dtype=wp.vec3, device=device)
    volumes = arr(vol_h)
    horizon = arr(delta_h)
    spacing = arr(h_h)
    body_id = wp.array(body_id_h, dtype=wp.int32, device=device)
    offsets, neighbors, bond_count = kn.build_families(rest, body_id, arr(search_h), device)

    bond_geom = wp.zeros(max(bond_count, 1), dtype=wp.vec4, device=device)
    bond_wv = wp.zeros(max(bond_count, 1), dtype=float, device=device)
    partial = wp.array(
        per_particle([b.partial_volumes for b in bodies]).astype(np.int32), dtype=wp.int32, device=device
    )
    kb.bond_geometry(
        n,
        rest_positions=rest,
        volumes=volumes,
        horizon=horizon,
        spacing=spacing,
        partial_volumes=partial,
        family_offsets=offsets,
        family_neighbors=neighbors,
        bond_geom=bond_geom,
        bond_wv=bond_wv,
        device=device,
    )

    volume_sum = wp.zeros(n, dtype=float, device=device)
    weighted_volume = wp.zeros(n, dtype=float, device=device)
    kb.family_moments(
        n,
        family_offsets=offsets,
        bond_geom=bond_geom,
        bond_wv=bond_wv,
        horizon=horizon,
        volume_sum=volume_sum,
        weighted_volume=weighted_volume,
        device=device,
    )
    vs = volume_sum.numpy().astype(np.float64)
    m = weighted_volume.numpy().astype(np.float64)
    correction = np.concatenate([np.full(c, b.surface_correction) for c, b in zip(counts, bodies, strict=False)])
    family = correction == "family"
    with np.errstate(divide="ignore", invalid="ignore"):
        d_family = np.where(vs > 0, 3.0 / (delta_h * vs), 0.0)
        b_family = np.where(m > 0, 15.0 * mu_h / (2.0 * m), 0.0)
    d_cont = 9.0 / (4.0 * math.pi * delta_h**4)
    b_cont = 15.0 * mu_h / (2.0 * math.pi * delta_h**5)
    d_k = np.where(family, d_family, d_cont)
    b_k = np.where(family, b_family, b_cont)
    c0 = 0.5 * kappa_h - 5.0 * mu_h / 6.0

    if np.any(correction == "directional"):
        directional = correction == "directional"
        nu_h = per_particle([b.material.poisson_ratio for b in bodies])
        f_dil, f_dev = _directional_factors(local_h, delta_h, nu_h, offsets, neighbors, bond_geom, bond_wv, device)
        f_dil[~directional] = 1.0
        f_dev[~directional] = 1.0
        bond_wv_dil = wp.zeros_like(bond_wv)
        bond_wv_dev = wp.zeros_like(bond_wv)
        kb.directional_bond_weights(
            n,
            family_offsets=offsets,
            family_neighbors=neighbors,
            bond_geom=bond_geom,
            bond_wv=bond_wv,
            factor_dil=wp.array(f_dil.astype(f32), dtype=wp.vec3, device=device),
            factor_dev=wp.array(f_dev.astype(f32), dtype=wp.vec3, device=device),
            bond_wv_dil=bond_wv_dil,
            bond_wv_dev=bond_wv_dev,
            device=device,
        )
    else:
        bond_wv_dil = bond_wv_dev = bond_wv

    anisotropic = np.concatenate([np.full(c, b.material.anisotropy is not None) for c, b in zip(counts, bodies)])
    axis_h = np.zeros((n, 3))
    stiff_h = np.ones(n)
    strength_h = np.ones(n)
    for c, b, lo in zip(counts, bodies, body_offsets[:-1]):  # per body (a handful), not per particle
        an = b.material.anisotropy
        if an is not None:
            axis_h[lo : lo + c] = b.material_rotation @ np.asarray(an.axis)
            stiff_h[lo : lo + c] = an.stiffness_ratio
            strength_h[lo : lo + c] = an.strength_ratio
    axis = wp.array(axis_h.astype(f32), dtype=wp.vec3, device=device)
    if np.any(anisotropic & (stiff_h != 1.0)):
        if bond_wv_dil is bond_wv:
            bond_wv_dil, bond_wv_dev = wp.clone(bond_wv), wp.clone(bond_wv)
        kb.anisotropic_stiffness(
            n,
            family_offsets=offsets,
            bond_geom=bond_geom,
            axis=axis,
            stiffness_ratio=arr(stiff_h),
            bond_wv_dil=bond_wv_dil,
            bond_wv_dev=bond_wv_dev,
            device=device,
        )

    extra = {}
    fracture = any(b.fractures for b in bodies)
    if fracture:
        sc_h = np.concatenate([np.full(c, b.material.critical_stretch_for(b.horizon)) for c, b in zip(counts, bodies)])
        sc_h = np.minimum(sc_h, 1.0e30)
        unbreak = np.concatenate([b.unbreakable for b in bodies]).astype(np.int32)
        bond_sc = wp.zeros(max(bond_count, 1), dtype=float, device=device)
        kb.bond_strengths(
            n,
            family_offsets=offsets,
            family_neighbors=neighbors,
            bond_geom=bond_geom,
            critical_stretch=arr(sc_h),
            unbreakable=wp.array(unbreak, dtype=wp.int32, device=device),
            axis=axis,
            strength_ratio=arr(strength_h),
            local_index=wp.array((np.arange(n) - np.repeat(body_offsets[:-1], counts)).astype(np.int32), device=device),
            weibull_modulus=arr(per_particle([b.material.strength_weibull_modulus or 0.0 for b in bodies])),
            strength_seed=wp.array(
                per_particle([b.material.strength_seed for b in bodies]).astype(np.int32), device=device
            ),
            **_strength_fields(bodies, counts, device),
            bond_critical_stretch=bond_sc,
            device=device,
        )
        if any(b.material.strength_cell_size is not None for b in bodies):
            cell, ratio = _strength_cells(bodies, counts)
            kb.cell_strengths(
                n,
                family_offsets=offsets,
                family_neighbors=neighbors,
                cell=wp.array(cell, dtype=wp.int32, device=device),
                cell_ratio=arr(ratio),
                bond_critical_stretch=bond_sc,
                device=device,
            )
        alive = wp.array(np.ones(max(bond_count, 1), dtype=np.uint8), dtype=wp.uint8, device=device)
        for c, b, lo in zip(counts, bodies, body_offsets[:-1]):
            for cut in b.notches:
                _cut_bonds(cut, int(lo), c, rest, offsets, neighbors, alive, device, origin)
        fail_h = np.concatenate(
            [np.full(c, b.material.failure_plastic_strain or 1.0e30) for c, b in zip(counts, bodies)]
        )
        extra.update(
            fracture=True,
            bond_critical_stretch=bond_sc,
            bond_alive_initial=alive,
            compressive_bonus=arr(per_particle([b.material.compressive_bonus for b in bodies])),
            compressive_stretch_floor=arr(per_particle([compressive_stretch_floor(b.material) for b in bodies])),
            failure_eqps=arr(fail_h),
        )
        if any(b.material.debris_damping > 0.0 for b in bodies):  # kernels/peridynamics/damping.py
            extra.update(
                debris_rate=arr(per_particle([b.material.debris_damping for b in bodies])),
                debris_damage=arr(per_particle([b.material.debris_damage for b in bodies])),
            )
    if any(b.material.retardation_time > 0.0 for b in bodies):  # the force pass (kernels/peridynamics/step.py)
        tau_h = per_particle([b.material.retardation_time for b in bodies])
        extra["retardation"] = np.asarray(tau_h, dtype=np.float64)  # the stable step's, on the host
        extra["damping_b"] = arr(tau_h * b_k)
    plastic_bodies = [b for b in bodies if b.material.yields]
    if plastic_bodies:
        n_p = int(sum(b.particle_count for b in plastic_bodies))  # yielding bodies come first (see SolverPeridynamics)
        nb_p = int(offsets.numpy()[n_p])
        reverse = wp.zeros(max(nb_p, 1), dtype=wp.int32, device=device)
        pd_step.reverse_bonds(n_p, offsets, neighbors, reverse, device)
        psi = wp.zeros(n, dtype=float, device=device)
        kb.plastic_norm_scale(
            n,
            family_offsets=offsets,
            bond_geom=bond_geom,
            bond_wv=bond_wv,
            bond_wv_dev=bond_wv_dev,
            horizon=horizon,
            b_ratio=arr(b_k / b_cont),
            psi_scale=psi,
            device=device,
        )
        extra.update(
            plastic=True,
            plastic_particle_count=n_p,
            plastic_bond_count=nb_p,
            yield_stress=arr(per_particle([b.material.yield_stress or 0.0 for b in bodies])),
            hardening=arr(per_particle([b.material.hardening_modulus for b in bodies])),
            psi_scale=psi,
            bond_reverse=reverse,
        )

    return PeridynamicModel(
        particle_count=n,
        bond_count=bond_count,
        body_offsets=body_offsets,
        rest_positions=rest,
        volumes=volumes,
        inv_density=arr(1.0 / rho_h),
        spacing=spacing,
        horizon=horizon,
        radius=arr(0.5 * h_h),
        family_offsets=offsets,
        family_neighbors=neighbors,
        bond_geom=bond_geom,
        bond_wv=bond_wv,
        bond_wv_dil=bond_wv_dil,
        bond_wv_dev=bond_wv_dev,
        dil_d=arr(d_k),
        dev_b=arr(b_k),
        dil_c0=arr(c0),
        dil_coef=arr(d_k * c0),
        weighted_volume=weighted_volume,
        density_host=rho_h,
        volumes_host=vol_h,
        rest_host=rest_h,
        **extra,
    )


def _cut_bonds(cut, first: int, count: int, rest, offsets, neighbors, alive, device, origin):
    """Breaks the bonds of particles [first, first + count) whose reference segment crosses ``cut`` (world
    coordinates; ``rest`` is in the local frame, world - ``origin``)."""
    o = np.asarray(origin, dtype=np.float64)
    if isinstance(cut, BoxRegion):
        lo = wp.vec3(*(np.asarray(cut.lo) - o))
        hi = wp.vec3(*(np.asarray(cut.hi) - o))
        pd_step.cut_bonds_by_box(first, count, rest, offsets, neighbors, lo, hi, alive, device)
    else:
        mesh = wp.Mesh(
            points=wp.array((cut.vertices - o).astype(np.float32), dtype=wp.vec3, device=device),
            indices=wp.array(cut.faces.astype(np.int32).ravel(), dtype=wp.int32, device=device),
        )
        pd_step.cut_bonds_by_mesh(first, count, mesh.id, rest, offsets, neighbors, alive, device)


def compressive_stretch_floor(material) -> float:
    """The one place where Material.compressive_bonus_cap k becomes the kernel's floor on the compressive stretch the
    bonus reads, k / alpha with alpha = Material.compressive_bonus [-]: the force kernel takes
    s0 = s_c - alpha max(s_min, -(k / alpha) s_c), which is s_c + min(-alpha s_min, k s_c); 1e30 (no floor) without a
    cap or a bonus, which leaves the plain rule's arithmetic unchanged."""
    cap, alpha = material.compressive_bonus_cap, material.compressive_bonus
    return 1.0e30 if cap is None or alpha <= 0.0 else min(cap / alpha, 1.0e30)
