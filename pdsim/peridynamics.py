"""State-based peridynamic solid: bodies, the model built from them, and the explicit solver.

The elastic model is the one derived in shared/seeds/pd_supplement.txt (kernels/pd_bonds.py lists the formulas). Its
three parameters come from matching two reference deformations, an isotropic expansion (theta = 3 zeta,
W = 9/2 kappa zeta^2) and a shear (W = 1/2 mu zeta^2). The supplement evaluates the family sums as integrals over a
full sphere, which gives the constants

    d = 9 / (4 pi delta^4),   b = 15 mu / (2 pi delta^5),   a = kappa d / 2,   g = (5 mu / 6) d / b = delta / 4.

Particles near a free surface have truncated families and would be too soft (the surface effect).
``surface_correction`` chooses the remedy:

- ``"directional"`` (default): Madenci and Oterkus's per-axis correction. Each particle's response to a reference
  deformation along x, y and z is compared with the continuum value (dilatation: uniaxial stretch; deviatoric sum:
  uniaxial stress), and each bond is scaled by an ellipsoidal interpolation of its two particles' factors
  (kernels/pd_bonds.py, compute_directional_bond_factors).
- ``"family"``: the supplement's two matching conditions applied to each particle's own discrete family instead of
  the continuum sphere, d_k = 3 / (delta sum_j V_j beta_j) and b_k = 15 mu / (2 m_k) with
  m_k = sum_j w L^2 V_j beta_j. This is exact for expansion, but it over-stiffens thin parts.
- ``"none"``: the supplement's constants.

docs/accuracy.md measures all three.

The model's elastic energy density is W_k = c0 theta_k^2 + b_k sum_j w e^2 V_j beta_j with c0 = kappa/2 - 5 mu/6.
Its derivative with respect to each bond extension (Lambda held fixed) is exactly the supplement's force state, so
the integrator conserves energy up to the dependence of Lambda on rotation, which is negligible at small strain.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from .errors import InstabilityError, ParameterError
from .geometry import SolidShape
from .materials import Material, _check_range
from .regions import region_mask
from .sampling import fill_solid, morton_order

SURFACE_CORRECTIONS = ("directional", "family", "none")


class PeridynamicBody:
    """A solid discretised into particles on a simple-cubic lattice, simulated with state-based peridynamics.

    Args:
        shape: the solid to fill (see pdsim.geometry).
        material: elastic constants and density.
        spacing: lattice spacing h [m], > 0 and at most the shape's smallest extent.
        horizon_factor: horizon delta = horizon_factor * h, in [1.5, 8]; default 3.015 (about 3 spacings, ties avoided).
        name: label of the body in the USD cache; defaults to the shape's name.
        surface_correction: "directional" (Madenci-Oterkus per-direction factors, default), "family" (per-particle
            calibration of d and b on the isotropic reference deformations) or "none" (the supplement's constants).
        partial_volumes: count neighbours near the horizon by the fraction of their cell inside it (default True).
        damping: mass-proportional viscous damping coefficient c [1/s], >= 0 (a = f / rho - c v).
        material_rotation: 3x3 rotation from the material frame (where ``material.anisotropy.axis`` is given) to world
            space; identity by default. Turning a body and its material_rotation together gives the same result.
        device: Warp device used to sample the shape ("cpu" by default; sampling is a one-off).

    Particles are sorted along a Morton curve so that neighbours are close in memory.
    """

    def __init__(
        self,
        shape: SolidShape,
        material: Material,
        spacing: float,
        *,
        horizon_factor: float = 3.015,
        name: str | None = None,
        surface_correction: str = "directional",
        partial_volumes: bool = True,
        damping: float = 0.0,
        material_rotation=None,
        device: str = "cpu",
    ):
        if not isinstance(material, Material):
            raise ParameterError("material", material, "a pdsim.Material")
        if not isinstance(shape, SolidShape):
            raise ParameterError("shape", shape, "a pdsim SolidShape (pdsim.box, pdsim.load_mesh, ...)")
        if surface_correction not in SURFACE_CORRECTIONS:
            raise ParameterError("surface_correction", surface_correction, " or ".join(map(repr, SURFACE_CORRECTIONS)))
        self.shape = shape
        self.material = material
        self.spacing = _check_range("spacing", spacing, 0.0, None)
        self.horizon_factor = _check_range("horizon_factor", horizon_factor, 1.5, 8.0, lo_open=False, hi_open=False)
        self.name = name or shape.name
        self.surface_correction = surface_correction
        self.partial_volumes = bool(partial_volumes)
        self.damping = _check_range("damping", damping, 0.0, None, lo_open=False)
        self.material_rotation = _rotation_matrix(material_rotation)
        self.notches: list = []  # BoxRegion or SolidShape: bonds crossing them start broken
        positions, volumes = fill_solid(shape, self.spacing, device=device)
        order = morton_order(positions, self.spacing)
        self.rest_positions = positions[order]
        self.volumes = volumes[order]
        n = len(self.rest_positions)
        self.kind = np.zeros(n, dtype=np.int32)
        self.prescribed_velocity = np.zeros((n, 3), dtype=np.float64)
        self.prescribed_axes = np.ones((n, 3), dtype=np.float64)
        self.initial_velocity = np.zeros((n, 3), dtype=np.float64)
        self.unbreakable = np.zeros(n, dtype=bool)

    @property
    def particle_count(self) -> int:
        return len(self.rest_positions)

    @classmethod
    def build_solver(cls, bodies, *, device, gravity, ground, contact=None, colliders=()):
        """The scene's solver for all its peridynamic bodies."""
        return SolverPeridynamics(
            bodies, device=device, gravity=gravity, ground=ground, contact=contact, colliders=colliders
        )

    @property
    def horizon(self) -> float:
        """delta = horizon_factor * spacing [m]."""
        return self.horizon_factor * self.spacing

    def _select(self, region, field_name: str) -> np.ndarray:
        mask = region_mask(region, self.rest_positions, field=field_name)
        if not mask.any():
            raise ParameterError(field_name, region, f"a region containing at least one particle of '{self.name}'")
        return mask

    def fix(self, region) -> int:
        """Holds the particles whose reference position lies in ``region`` at rest; returns how many."""
        mask = self._select(region, "region")
        self.kind[mask] = 1
        self.prescribed_velocity[mask] = 0.0
        return int(mask.sum())

    def set_velocity(self, region, velocity, *, axes: str = "xyz") -> int:
        """Moves the particles in ``region`` at the constant ``velocity`` [m/s] (a displacement-driven boundary).
        ``axes`` names the prescribed components ("xyz" by default; "x" makes a roller grip that pulls along x and
        leaves y and z free)."""
        v = np.asarray(velocity, dtype=np.float64)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise ParameterError("velocity", velocity, "a sequence of 3 finite numbers [m/s]")
        if not axes or any(a not in "xyz" for a in axes) or len(set(axes)) != len(axes):
            raise ParameterError("axes", axes, "a non-empty combination of 'x', 'y', 'z'")
        mask = self._select(region, "region")
        self.kind[mask] = 2
        self.prescribed_velocity[mask] = v
        self.prescribed_axes[mask] = [float(c in axes) for c in "xyz"]
        return int(mask.sum())

    def add_notch(self, cut) -> None:
        """Pre-cut: every bond whose reference segment crosses ``cut`` (a BoxRegion, e.g. a thin slab; a SolidShape's
        surface; or an open triangle surface given as (vertices, faces)) starts broken. Needs a material that breaks
        or a scene that tracks damage; any body with a notch is simulated with fracture on."""
        from .geometry import SolidShape as _Shape
        from .regions import BoxRegion

        if isinstance(cut, tuple) and len(cut) == 2:  # an open surface: (vertices [n, 3], triangles [m, 3])
            v = np.asarray(cut[0], dtype=np.float64)
            f = np.asarray(cut[1], dtype=np.int64)
            if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or f.size == 0:
                raise ParameterError("cut", "(vertices, faces)", "arrays of shape [n, 3] and [m, 3], m >= 1")
            cut = _Shape(vertices=v, faces=f.astype(np.int32), name="notch")
        if not isinstance(cut, BoxRegion | _Shape):
            raise ParameterError("cut", cut, "a BoxRegion, a SolidShape or a (vertices, faces) surface")
        self.notches.append(cut)

    def set_unbreakable(self, region) -> int:
        """Bonds touching a particle in ``region`` never break (e.g. grips, supports); returns the particle count."""
        mask = self._select(region, "region")
        self.unbreakable[mask] = True
        return int(mask.sum())

    @property
    def fractures(self) -> bool:
        """True when this body's bonds can break or start broken."""
        return self.material.breaks or bool(self.notches)

    def set_initial_velocity(self, velocity, region=None) -> int:
        """Initial velocity [m/s]: a vector for all particles (or those in ``region``), or an array [n, 3]."""
        v = np.asarray(velocity, dtype=np.float64)
        if v.shape == (self.particle_count, 3) and region is None:
            mask = np.ones(self.particle_count, dtype=bool)
            values = v
        elif v.shape == (3,):
            mask = np.ones(self.particle_count, dtype=bool) if region is None else self._select(region, "region")
            values = np.broadcast_to(v, (int(mask.sum()), 3))
        else:
            raise ParameterError("velocity", velocity, f"3 numbers or an array of shape ({self.particle_count}, 3)")
        if not np.all(np.isfinite(values)):
            raise ParameterError("velocity", velocity, "finite values")
        self.initial_velocity[mask] = values
        return int(mask.sum())


def _rotation_matrix(value) -> np.ndarray:
    """Validates a 3x3 rotation matrix (orthonormal, det +1); None gives the identity."""
    if value is None:
        return np.eye(3)
    R = np.asarray(value, dtype=np.float64)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)) or not np.allclose(R @ R.T, np.eye(3), atol=1.0e-6):
        raise ParameterError("material_rotation", value, "a 3x3 rotation matrix (orthonormal)")
    if np.linalg.det(R) < 0.0:
        raise ParameterError("material_rotation", value, "a proper rotation (determinant +1)")
    return R


@dataclass(frozen=True)
class GroundPlane:
    """A static plane n . x = offset that free particles cannot cross (inelastic contact with Coulomb friction)."""

    normal: tuple = (0.0, 0.0, 1.0)
    offset: float = 0.0
    friction: float = 0.5


@dataclass
class PeridynamicModel:
    """Immutable data of all peridynamic bodies of a scene, concatenated (bonds never join two bodies).

    Arrays are Warp arrays on the solver's device; particle_count rows for per-particle data, bond_count for bonds.
    """

    particle_count: int
    bond_count: int
    body_offsets: np.ndarray  # first particle of each body, shape [body_count + 1]
    rest_positions: object  # [m], vec3
    volumes: object  # [m^3]
    inv_density: object  # [m^3/kg]
    spacing: object  # h per particle [m]
    horizon: object  # delta per particle [m]
    radius: object  # collision radius h/2 [m]
    damping: object  # [1/s]
    kind: object  # 0 free, 1 fixed, 2 prescribed velocity
    prescribed_velocity: object  # [m/s]
    prescribed_axes: object  # 1 for each prescribed velocity component, 0 for a free one
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
    bonus_alpha: object = None  # compressive bonus alpha per particle [-]
    failure_eqps: object = None  # ductile failure plastic strain per particle [-]
    yield_stress: object = None  # sigma_Y0 per plastic particle [Pa]
    hardening: object = None  # H per plastic particle [Pa]
    psi_scale: object = None  # family share of the continuum deviatoric norm per plastic particle [-]
    bond_reverse: object = None  # index of bond j -> k for each plastic bond k -> j
    density_host: np.ndarray = field(repr=False, default=None)
    volumes_host: np.ndarray = field(repr=False, default=None)
    rest_host: np.ndarray = field(repr=False, default=None)


@dataclass
class PeridynamicState:
    """Per-step data: positions [m], velocities [m/s], accelerations [m/s^2], dilatation theta [-],
    bp = (b_k, P_k) per particle, force density [N/m^3]; per bond the deformed (n, e) and Lambda cached by the
    dilatation pass for the force pass."""

    positions: object
    velocities: object
    accelerations: object
    theta: object
    bp: object
    force_density: object
    bond_ne: object
    bond_lambda: object
    bond_alive: object = None  # uint8 per bond (fracture)
    stretch_min: object = None  # most compressive live stretch per particle, this step (fracture)
    bond_plastic: object = None  # plastic extension per plastic bond [m]
    eqps: object = None  # equivalent plastic strain per particle [-]


def _build_families(rest, body_id, radius, device):
    """CSR families via a hash grid: returns (offsets, neighbors) Warp arrays."""
    import warp as wp

    from .kernels import neighbors as kn

    n = rest.shape[0]
    cell = float(radius.numpy().max())
    dim = int(max(8, min(128, round(n ** (1.0 / 3.0)))))
    grid = wp.HashGrid(dim, dim, dim, device=device)
    grid.build(rest, cell)
    counts = wp.zeros(n, dtype=wp.int32, device=device)
    wp.launch(kn.count_family, dim=n, inputs=[grid.id, rest, body_id, radius, counts], device=device)
    offsets = wp.zeros(n + 1, dtype=wp.int32, device=device)
    wp.utils.array_scan(counts, offsets[1:], inclusive=True)
    bond_count = int(offsets.numpy()[-1])
    neighbors = wp.zeros(max(bond_count, 1), dtype=wp.int32, device=device)
    wp.launch(kn.fill_family, dim=n, inputs=[grid.id, rest, body_id, radius, offsets, neighbors], device=device)
    return offsets, neighbors, bond_count


DIRECTIONAL_STRETCH = 1.0e-3
DIRECTIONAL_CALIBRATION = "uniaxial_stress"  # or "uniaxial_stretch" (Madenci-Oterkus); docs/accuracy.md compares


def _placeholders(device):
    """Length-1 arrays passed for the arguments of features a kernel variant compiles out."""
    import warp as wp

    return (
        wp.zeros(1, dtype=wp.uint8, device=device),
        wp.zeros(1, dtype=float, device=device),
        wp.zeros(1, dtype=wp.int32, device=device),
    )


def make_step_kernels(*, fracture: bool, plastic: bool):
    from .kernels import pd_step

    return pd_step.make_step_kernels(fracture, plastic)


def _directional_factors(rest_h, delta_h, nu_h, offsets, neighbors, bond_geom, bond_wv, device):
    """Correction factors per particle and axis (Madenci-Oterkus): the continuum value over the discrete family value
    of the dilatation under a uniaxial stretch zeta along the axis (theta = zeta), and of the deviatoric sum
    sum_j w e^2 V_j beta under uniaxial stress along the axis: stretch zeta with lateral contraction -nu zeta
    (continuum pi delta^5 zeta^2 ((1 + nu)^2 / 5 - 2 nu (1 + nu) / 3 + nu^2)). Madenci and Oterkus use the uniaxial
    stretch for both; calibrating the deviatoric sum on uniaxial stress also corrects the Poisson coupling that thin
    parts feel in tension and bending (about halves the bar-stiffness error, docs/accuracy.md), while the dilatation
    keeps the well-conditioned stretch target (theta under uniaxial stress, (1 - 2 nu) zeta, vanishes as nu -> 1/2).
    Returns two arrays of shape [n, 3]; 1 where a family is empty."""
    import warp as wp

    n = len(rest_h)
    zeta = DIRECTIONAL_STRETCH
    ks = make_step_kernels(fracture=False, plastic=False)
    ones = wp.array(np.ones(n, dtype=np.float32), dtype=float, device=device)
    zeros = wp.zeros(n, dtype=float, device=device)
    sum_dil = wp.zeros(n, dtype=float, device=device)
    sum_dev = wp.zeros(n, dtype=float, device=device)
    zeros_out = wp.zeros(n, dtype=float, device=device)  # dilatation of the stress state: only its bond cache is used
    bp = wp.zeros(n, dtype=wp.vec2, device=device)
    nb = bond_wv.shape[0]
    bond_ne = wp.zeros(nb, dtype=wp.vec4, device=device)
    bond_lambda = wp.zeros(nb, dtype=float, device=device)
    u8, f1, _ = _placeholders(device)
    f_dil = np.ones((n, 3))
    f_dev = np.ones((n, 3))
    d_cont = 9.0 / (4.0 * math.pi * delta_h**4)
    nu = nu_h if DIRECTIONAL_CALIBRATION == "uniaxial_stress" else np.zeros_like(nu_h)
    dev_cont = math.pi * delta_h**5 * zeta**2 * ((1.0 + nu) ** 2 / 5.0 - 2.0 * nu * (1.0 + nu) / 3.0 + nu**2)

    def elastic_sums(scale, theta_out):
        """Writes sum_j w e Lambda V beta into theta_out and caches the bonds' (n, e) for positions rest * scale
        (the elastic kernels with d = 1, c0 = 0, b = 1)."""
        pos = wp.array((rest_h * scale).astype(np.float32), dtype=wp.vec3, device=device)
        inputs = [pos, offsets, neighbors, bond_geom, bond_wv, ones, zeros, zeros, u8]
        wp.launch(ks.dilatation, dim=n, device=device, inputs=[*inputs, theta_out, bp, bond_ne, bond_lambda, f1])

    for axis in range(3):
        stretch = np.ones((len(rest_h), 3))
        stretch[:, axis] = 1.0 + zeta
        stress = np.repeat((1.0 - nu * zeta)[:, None], 3, axis=1)
        stress[:, axis] = 1.0 + zeta
        elastic_sums(stretch, sum_dil)  # dilatation factor: uniaxial stretch
        elastic_sums(stress, zeros_out)  # deviatoric factor: uniaxial stress (only the bond cache is used)
        wp.launch(
            ks.energy, dim=n, device=device, inputs=[offsets, bond_ne, bond_wv, u8, 0, f1, zeros, ones, zeros, sum_dev]
        )
        sd = sum_dil.numpy().astype(np.float64)
        sv = sum_dev.numpy().astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            f_dil[:, axis] = np.where(sd > 0, zeta / (d_cont * sd), 1.0)
            f_dev[:, axis] = np.where(sv > 0, dev_cont / sv, 1.0)
    return f_dil, f_dev


def build_model(bodies: list[PeridynamicBody], device) -> PeridynamicModel:
    """Concatenates the bodies, builds their families and per-bond / per-particle constants (all in kernels)."""
    import warp as wp

    from .kernels import pd_bonds as kb

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

    rest = wp.array(rest_h.astype(f32), dtype=wp.vec3, device=device)
    volumes = arr(vol_h)
    horizon = arr(delta_h)
    spacing = arr(h_h)
    body_id = wp.array(body_id_h, dtype=wp.int32, device=device)
    offsets, neighbors, bond_count = _build_families(rest, body_id, arr(search_h), device)

    bond_geom = wp.zeros(max(bond_count, 1), dtype=wp.vec4, device=device)
    bond_wv = wp.zeros(max(bond_count, 1), dtype=float, device=device)
    partial = wp.array(
        per_particle([b.partial_volumes for b in bodies]).astype(np.int32), dtype=wp.int32, device=device
    )
    wp.launch(
        kb.compute_bond_geometry,
        dim=n,
        inputs=[rest, volumes, horizon, spacing, partial, offsets, neighbors, bond_geom, bond_wv],
        device=device,
    )

    volume_sum = wp.zeros(n, dtype=float, device=device)
    weighted_volume = wp.zeros(n, dtype=float, device=device)
    wp.launch(
        kb.compute_family_moments,
        dim=n,
        inputs=[offsets, bond_geom, bond_wv, horizon, volume_sum, weighted_volume],
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
        f_dil, f_dev = _directional_factors(rest_h, delta_h, nu_h, offsets, neighbors, bond_geom, bond_wv, device)
        f_dil[~directional] = 1.0
        f_dev[~directional] = 1.0
        bond_wv_dil = wp.zeros_like(bond_wv)
        bond_wv_dev = wp.zeros_like(bond_wv)
        wp.launch(
            kb.compute_directional_bond_factors,
            dim=n,
            inputs=[
                offsets,
                neighbors,
                bond_geom,
                bond_wv,
                wp.array(f_dil.astype(f32), dtype=wp.vec3, device=device),
                wp.array(f_dev.astype(f32), dtype=wp.vec3, device=device),
                bond_wv_dil,
                bond_wv_dev,
            ],
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
        wp.launch(
            kb.scale_anisotropic_stiffness,
            dim=n,
            inputs=[offsets, bond_geom, axis, arr(stiff_h), bond_wv_dil, bond_wv_dev],
            device=device,
        )

    extra = {}
    fracture = any(b.fractures for b in bodies)
    if fracture:
        from .kernels import pd_step as ks

        sc_h = np.concatenate([np.full(c, b.material.critical_stretch_for(b.horizon)) for c, b in zip(counts, bodies)])
        sc_h = np.minimum(sc_h, 1.0e30)
        unbreak = np.concatenate([b.unbreakable for b in bodies]).astype(np.int32)
        bond_sc = wp.zeros(max(bond_count, 1), dtype=float, device=device)
        wp.launch(
            kb.init_bond_fracture,
            dim=n,
            inputs=[
                offsets,
                neighbors,
                bond_geom,
                arr(sc_h),
                wp.array(unbreak, dtype=wp.int32, device=device),
                axis,
                arr(strength_h),
                bond_sc,
            ],
            device=device,
        )
        alive = wp.array(np.ones(max(bond_count, 1), dtype=np.uint8), dtype=wp.uint8, device=device)
        for c, b, lo in zip(counts, bodies, body_offsets[:-1]):
            for cut in b.notches:
                _cut_bonds(cut, int(lo), c, rest, offsets, neighbors, alive, device)
        fail_h = np.concatenate(
            [np.full(c, b.material.failure_plastic_strain or 1.0e30) for c, b in zip(counts, bodies)]
        )
        extra.update(
            fracture=True,
            bond_critical_stretch=bond_sc,
            bond_alive_initial=alive,
            bonus_alpha=arr(per_particle([b.material.compressive_bonus for b in bodies])),
            failure_eqps=arr(fail_h),
        )
    plastic_bodies = [b for b in bodies if b.material.yields]
    if plastic_bodies:
        from .kernels import pd_step as ks

        n_p = int(sum(b.particle_count for b in plastic_bodies))  # yielding bodies come first (see SolverPeridynamics)
        nb_p = int(offsets.numpy()[n_p])
        reverse = wp.zeros(max(nb_p, 1), dtype=wp.int32, device=device)
        wp.launch(ks.find_reverse_bonds, dim=n_p, inputs=[offsets, neighbors, reverse], device=device)
        psi = wp.zeros(n, dtype=float, device=device)
        wp.launch(
            kb.compute_plastic_norm_scale,
            dim=n,
            inputs=[offsets, bond_geom, bond_wv, bond_wv_dev, horizon, arr(b_k / b_cont), psi],
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

    kind_h = np.concatenate([b.kind for b in bodies]).astype(np.int32)
    presc_h = np.concatenate([b.prescribed_velocity for b in bodies])
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
        damping=arr(per_particle([b.damping for b in bodies])),
        kind=wp.array(kind_h, dtype=wp.int32, device=device),
        prescribed_velocity=wp.array(presc_h.astype(f32), dtype=wp.vec3, device=device),
        prescribed_axes=wp.array(
            np.concatenate([b.prescribed_axes for b in bodies]).astype(f32), dtype=wp.vec3, device=device
        ),
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


def _cut_bonds(cut, first: int, count: int, rest, offsets, neighbors, alive, device):
    """Breaks the bonds of particles [first, first + count) whose reference segment crosses ``cut``."""
    import warp as wp

    from .kernels import pd_step as ks
    from .regions import BoxRegion

    if isinstance(cut, BoxRegion):
        wp.launch(
            ks.break_bonds_crossing_box,
            dim=count,
            inputs=[first, rest, offsets, neighbors, wp.vec3(*cut.lo), wp.vec3(*cut.hi), alive],
            device=device,
        )
    else:
        mesh = wp.Mesh(
            points=wp.array(cut.vertices.astype(np.float32), dtype=wp.vec3, device=device),
            indices=wp.array(cut.faces.astype(np.int32).ravel(), dtype=wp.int32, device=device),
        )
        wp.launch(
            ks.break_bonds_crossing_mesh,
            dim=count,
            inputs=[first, mesh.id, rest, offsets, neighbors, alive],
            device=device,
        )


class SolverPeridynamics:
    """Explicit velocity-Verlet solver for the peridynamic bodies of a scene.

    Args:
        bodies: the peridynamic bodies (concatenated into one model).
        device: Warp device ("cpu", "cuda", "cuda:0", ...).
        gravity: acceleration [m/s^2], 3 numbers.
        ground: optional ground plane collider.
        contact: short-range repulsion between particles that share no live bond (separate bodies, fragments):
            None or False (off), True (defaults) or a dict of ParticleContact options (pdsim/contact.py).
        colliders: static mesh colliders and kinematic projectiles (pdsim/contact.py).

    The step launches: kick-drift (+ ground plane), dilatation, force density, kick. No allocation happens per step.
    ``features`` lists the optional parts that are live (and launched) for this scene.
    """

    def __init__(
        self,
        bodies: list[PeridynamicBody],
        *,
        device="cpu",
        gravity=(0.0, 0.0, 0.0),
        ground=None,
        contact=None,
        colliders=(),
    ):
        import warp as wp

        if not bodies:
            raise ParameterError("bodies", bodies, "at least one PeridynamicBody")
        # yielding bodies first, so plastic state is a prefix of the particle and bond arrays (allocated only there)
        self.bodies = sorted(bodies, key=lambda b: not b.material.yields)
        self.device = wp.get_device(device)
        self.gravity = wp.vec3(*[float(g) for g in gravity])
        self.ground = ground
        self.model = build_model(self.bodies, self.device)
        n = self.model.particle_count
        d = self.device
        init_v = np.concatenate([b.initial_velocity for b in self.bodies]).astype(np.float32)
        self.state = PeridynamicState(
            positions=wp.clone(self.model.rest_positions),
            velocities=wp.array(init_v, dtype=wp.vec3, device=d),
            accelerations=wp.zeros(n, dtype=wp.vec3, device=d),
            theta=wp.zeros(n, dtype=float, device=d),
            bp=wp.zeros(n, dtype=wp.vec2, device=d),
            force_density=wp.zeros(n, dtype=wp.vec3, device=d),
            bond_ne=wp.zeros(max(self.model.bond_count, 1), dtype=wp.vec4, device=d),
            bond_lambda=wp.zeros(max(self.model.bond_count, 1), dtype=float, device=d),
        )
        m = self.model
        if m.fracture:
            self.state.bond_alive = wp.clone(m.bond_alive_initial)
            self.state.stretch_min = wp.zeros(n, dtype=float, device=d)
            self._damage = wp.zeros(n, dtype=float, device=d)
        if m.plastic:
            self.state.bond_plastic = wp.zeros(max(m.plastic_bond_count, 1), dtype=float, device=d)
            self.state.eqps = wp.zeros(n, dtype=float, device=d)
        self._kernels = make_step_kernels(fracture=m.fracture, plastic=m.plastic)
        self.colliders = list(colliders)
        self.contact = None
        if contact is not None and contact is not False:
            from .contact import ParticleContact

            options = {} if contact is True else dict(contact)
            self.contact = ParticleContact.from_bodies(self.bodies, device=self.device, **options)
        self._dummy_u8, self._dummy_f, self._dummy_i = _placeholders(d)
        self._energy_density = wp.zeros(n, dtype=float, device=d)
        self._check = wp.zeros(2, dtype=float, device=d)
        self._handles = []  # USD prims of the bodies, set by add_outputs
        self._surfaces = []  # FragmentSurfaces per body, set by add_outputs
        self._fragments = None  # FragmentTracker, created on first use when some body can break
        self.features = {"elastic"}
        if any(gi != 0.0 for gi in gravity):
            self.features.add("gravity")
        if ground is not None:
            self.features.add("ground_plane")
        if any(b.damping > 0 for b in self.bodies):
            self.features.add("damping")
        if m.fracture:
            self.features.add("fracture")
        if m.plastic:
            self.features.add("plasticity")
        if any(b.material.anisotropy is not None for b in self.bodies):
            self.features.add("anisotropy")
        if self.contact is not None:
            self.features.add("contact")
        if self.colliders:
            self.features.add("colliders")
        self.time = 0.0
        self.step_count = 0
        self._update_accelerations(0.0)

    # -- time step -----------------------------------------------------------------------------------------------
    def stable_time_step(self) -> float:
        """Silling-Askari critical time step min_k sqrt(2 rho_k / sum_j V_j C_kj) [s] (no safety factor)."""
        import warp as wp

        from .kernels import pd_bonds as kb

        m = self.model
        row = wp.zeros(m.particle_count, dtype=float, device=self.device)
        wp.launch(
            kb.compute_stiffness_row_sum,
            dim=m.particle_count,
            inputs=[
                m.family_offsets,
                m.family_neighbors,
                m.bond_wv_dil,
                m.bond_wv_dev,
                m.dev_b,
                m.dil_d,
                m.dil_c0,
                row,
            ],
            device=self.device,
        )
        s = row.numpy().astype(np.float64)
        ok = s > 0
        if not ok.any():
            return math.inf
        dt_bonds = float(np.sqrt(2.0 * m.density_host[ok] / s[ok]).min())
        return dt_bonds if self.contact is None else min(dt_bonds, self.contact.stable_time_step())

    # -- stepping ------------------------------------------------------------------------------------------------
    def _feature_arrays(self):
        """Arguments shared by the step kernels: live feature arrays or length-1 placeholders."""
        m, s = self.model, self.state
        u8, f1, i1 = self._dummy_u8, self._dummy_f, self._dummy_i
        alive = s.bond_alive if m.fracture else u8
        plastic = s.bond_plastic if m.plastic else f1
        reverse = m.bond_reverse if m.plastic else i1
        return alive, plastic, reverse

    def _compute_force_density(self, positions):
        import warp as wp

        m, s, ks = self.model, self.state, self._kernels
        f1 = self._dummy_f
        alive, plastic, reverse = self._feature_arrays()
        frac = m.fracture
        wp.launch(
            ks.dilatation,
            dim=m.particle_count,
            inputs=[
                positions,
                m.family_offsets,
                m.family_neighbors,
                m.bond_geom,
                m.bond_wv_dil,
                m.dil_d,
                m.dil_coef,
                m.dev_b,
                alive,
                s.theta,
                s.bp,
                s.bond_ne,
                s.bond_lambda,
                s.stretch_min if frac else f1,
            ],
            device=self.device,
        )
        if m.plastic_particle_count > 0:
            wp.launch(
                ks.plastic_update,
                dim=m.plastic_particle_count,
                inputs=[
                    m.family_offsets,
                    m.bond_geom,
                    m.bond_wv,
                    m.bond_wv_dev,
                    alive,
                    s.bond_ne,
                    s.bond_lambda,
                    s.theta,
                    m.dev_b,
                    m.horizon,
                    m.weighted_volume,
                    m.yield_stress,
                    m.hardening,
                    m.psi_scale,
                    plastic,
                    s.eqps,
                ],
                device=self.device,
            )
        wp.launch(
            ks.force,
            dim=m.particle_count,
            inputs=[
                m.family_offsets,
                m.family_neighbors,
                m.bond_geom,
                s.bond_ne,
                s.bond_lambda,
                m.bond_wv_dil,
                m.bond_wv_dev,
                s.bp,
                alive,
                m.bond_critical_stretch if frac else f1,
                m.bonus_alpha if frac else f1,
                s.stretch_min if frac else f1,
                s.eqps if m.plastic else f1,
                m.failure_eqps if frac else f1,
                m.plastic_bond_count,
                plastic,
                reverse,
                s.force_density,
            ],
            device=self.device,
        )
        if self.contact is not None:
            self.contact.apply(positions, s.velocities, s.force_density, m.kind)

    def _update_accelerations(self, dt: float):
        import warp as wp

        from .kernels import integration as ki

        m, s = self.model, self.state
        self._compute_force_density(s.positions)
        wp.launch(
            ki.integrate_kick,
            dim=m.particle_count,
            inputs=[
                s.velocities,
                s.force_density,
                m.inv_density,
                m.kind,
                m.prescribed_axes,
                self.gravity,
                m.damping,
                dt,
                s.accelerations,
            ],
            device=self.device,
        )

    def step(self, dt: float):
        """Advances all bodies by one velocity-Verlet step of ``dt`` [s]."""
        import warp as wp

        from .kernels import integration as ki

        m, s = self.model, self.state
        wp.launch(
            ki.integrate_kick_drift,
            dim=m.particle_count,
            inputs=[
                s.positions,
                s.velocities,
                s.accelerations,
                m.rest_positions,
                m.kind,
                m.prescribed_velocity,
                m.prescribed_axes,
                dt,
            ],
            device=self.device,
        )
        if self.ground is not None:
            g = self.ground
            wp.launch(
                ki.collide_ground_plane,
                dim=m.particle_count,
                inputs=[
                    s.positions,
                    s.velocities,
                    m.kind,
                    m.radius,
                    wp.vec3(*g.normal),
                    float(g.offset),
                    float(g.friction),
                ],
                device=self.device,
            )
        for collider in self.colliders:
            collider.apply(s.positions, s.velocities, m.radius, m.kind, self.time + dt, dt)
        self._update_accelerations(dt)
        self.time += dt
        self.step_count += 1

    def simulate(self, dt: float, steps: int):
        """Runs ``steps`` steps of ``dt`` [s]."""
        for _ in range(int(steps)):
            self.step(dt)

    def check_state(self, speed_limit: float):
        """Raises InstabilityError if a position or velocity is not finite or a speed exceeds ``speed_limit`` [m/s]."""
        import warp as wp

        from .kernels import integration as ki

        s = self.state
        self._check.zero_()
        wp.launch(
            ki.max_speed_and_finite,
            dim=self.model.particle_count,
            inputs=[s.positions, s.velocities, self._check],
            device=self.device,
        )
        vmax, bad = self._check.numpy()
        if bad > 0 or vmax > speed_limit:
            what = "non-finite positions or velocities" if bad > 0 else f"a particle speed of {vmax:.3g} m/s"
            raise InstabilityError(
                f"the simulation diverged at t={self.time:.6g} s (step {self.step_count}): {what}; the time step is "
                f"too large for this material and spacing (stable estimate {self.stable_time_step():.3g} s): use a "
                "smaller --dt or leave it automatic"
            )

    # -- scene integration --------------------------------------------------------------------------------------------
    @property
    def particle_count(self) -> int:
        return self.model.particle_count

    @property
    def bond_count(self) -> int:
        return self.model.bond_count

    def contact_energy(self) -> float:
        """Contact penalty energy [J] (0 without contact)."""
        return 0.0 if self.contact is None else self.contact.potential_energy(self.state.positions)

    def speed_scale(self) -> float:
        """Largest of the bodies' P-wave speeds, initial speeds, prescribed speeds and projectile speeds [m/s]."""
        speeds = [float(np.linalg.norm(getattr(c, "velocity", np.zeros(3)))) for c in self.colliders]
        for b in self.bodies:
            speeds += [
                b.material.p_wave_speed,
                float(np.abs(b.initial_velocity).max(initial=0.0)),
                float(np.abs(b.prescribed_velocity).max(initial=0.0)),
            ]
        return max(speeds)

    def _primvar_kinds(self) -> dict:
        kinds = {"displacement": "float", "dilatation": "float"}
        if self.model.fracture:
            kinds["damage"] = "float"
            kinds["fragment"] = "int"
        if self.model.plastic:
            kinds["plastic_strain"] = "float"
        return kinds

    def add_outputs(self, cache, *, surfaces: bool = True):
        """Declares one UsdGeom.Points per body, with widths = spacing and the primvars written per frame
        (displacement [m], dilatation, and damage / fragment / plastic_strain when those features are live), and,
        with ``surfaces``, the body's renderable surface ``/World/<body>_surface``: a closed triangle shell per
        fragment (pdsim/surfaces.py), its topology rewritten only on frames where the fragments changed."""
        from .surfaces import FragmentSurfaces

        self._handles = [
            cache.add_points(
                b.name, widths=np.full(b.particle_count, b.spacing, dtype=np.float32), primvars=self._primvar_kinds()
            )
            for b in self.bodies
        ]
        self._surfaces = []
        if surfaces:
            self._surfaces = [
                FragmentSurfaces(b.shape, b.rest_positions, b.spacing, b.name, device=str(self.device))
                for b in self.bodies
            ]
            for surf in self._surfaces:
                surf.add_outputs(cache)

    def fragment_ids(self) -> np.ndarray:
        """Fragment id per particle (connected components of live bonds, numbered per body by the body-local index
        of the fragment's first particle, so ids stay stable over an animation); recomputed only when bonds broke
        since the last call. Zeros when no body can break."""
        from .fragments import FragmentTracker

        m = self.model
        if not m.fracture:
            return np.zeros(m.particle_count, dtype=np.int32)
        if self._fragments is None:
            self._fragments = FragmentTracker(m.family_offsets, m.family_neighbors, m.body_offsets, compact=False)
        self._fragments.update(self.state.bond_alive)
        return self._fragments.labels

    def write_outputs(self, cache, frame: int):
        """Writes positions, velocities and the primvars of every body at ``frame``, and the surfaces."""
        x = self.positions()
        v = self.velocities()
        values = {
            "displacement": np.linalg.norm(x.astype(np.float64) - self.model.rest_host, axis=1).astype(np.float32),
            "dilatation": self.state.theta.numpy(),
        }
        if self.model.fracture:
            values["damage"] = self.damage().astype(np.float32)
            values["fragment"] = self.fragment_ids()
        if self.model.plastic:
            values["plastic_strain"] = self.plastic_strain().astype(np.float32)
        for i, handle in enumerate(self._handles):
            sl = self.body_slice(i)
            cache.write_points(handle, frame, x[sl], velocities=v[sl], primvars={k: a[sl] for k, a in values.items()})
        for i, surf in enumerate(self._surfaces):
            sl = self.body_slice(i)
            if self.model.fracture:
                surf.update_topology(values["fragment"][sl])
            surf.write(cache, frame, x[sl])

    # -- host-side views and diagnostics (vectorised numpy) ---------------------------------------------------------
    def positions(self) -> np.ndarray:
        """Current positions [m], shape [particle_count, 3]."""
        return self.state.positions.numpy()

    def velocities(self) -> np.ndarray:
        """Current velocities [m/s], shape [particle_count, 3]."""
        return self.state.velocities.numpy()

    def set_positions(self, positions: np.ndarray):
        """Overwrites positions [m] (shape [particle_count, 3]) and recomputes forces and dilatation."""
        import warp as wp

        p = np.asarray(positions, dtype=np.float32)
        if p.shape != (self.model.particle_count, 3):
            raise ParameterError("positions", p.shape, f"shape ({self.model.particle_count}, 3)")
        wp.copy(self.state.positions, wp.array(p, dtype=wp.vec3, device=self.device))
        self._update_accelerations(0.0)

    def set_velocities(self, velocities: np.ndarray):
        """Overwrites velocities [m/s], shape [particle_count, 3]."""
        import warp as wp

        v = np.asarray(velocities, dtype=np.float32)
        if v.shape != (self.model.particle_count, 3):
            raise ParameterError("velocities", v.shape, f"shape ({self.model.particle_count}, 3)")
        wp.copy(self.state.velocities, wp.array(v, dtype=wp.vec3, device=self.device))

    def dilatation(self) -> np.ndarray:
        """theta per particle at the current positions [-]."""
        return self.state.theta.numpy().astype(np.float64)

    def force_density(self) -> np.ndarray:
        """Internal force density per particle [N/m^3], shape [particle_count, 3]."""
        return self.state.force_density.numpy().astype(np.float64)

    def strain_energy_density(self) -> np.ndarray:
        """Elastic W_k at the current positions [J/m^3] (uses the bond geometry cached by the last force pass, which
        is always that of the current positions)."""
        import warp as wp

        m, s = self.model, self.state
        alive, plastic, _ = self._feature_arrays()
        wp.launch(
            self._kernels.energy,
            dim=m.particle_count,
            inputs=[
                m.family_offsets,
                s.bond_ne,
                m.bond_wv_dev,
                alive,
                m.plastic_bond_count,
                plastic,
                s.theta,
                m.dev_b,
                m.dil_c0,
                self._energy_density,
            ],
            device=self.device,
        )
        return self._energy_density.numpy().astype(np.float64)

    def damage(self) -> np.ndarray:
        """Damage phi_k = 1 - live / all bond weight per particle [-] (zeros when no body can break)."""
        import warp as wp

        from .kernels import pd_step

        m = self.model
        if not m.fracture:
            return np.zeros(m.particle_count)
        wp.launch(
            pd_step.compute_damage,
            dim=m.particle_count,
            inputs=[m.family_offsets, m.bond_wv, self.state.bond_alive, self._damage],
            device=self.device,
        )
        return self._damage.numpy().astype(np.float64)

    def plastic_strain(self) -> np.ndarray:
        """Equivalent plastic strain per particle [-] (zeros when no body yields)."""
        if not self.model.plastic:
            return np.zeros(self.model.particle_count)
        return self.state.eqps.numpy().astype(np.float64)

    def bond_alive(self) -> np.ndarray:
        """Live flag per bond (bool [bond_count]); all True when no body can break."""
        if not self.model.fracture:
            return np.ones(self.model.bond_count, dtype=bool)
        return self.state.bond_alive.numpy()[: self.model.bond_count] != 0

    def strain_energy(self) -> float:
        """Total elastic energy sum_k V_k W_k [J]."""
        return float(np.dot(self.model.volumes_host, self.strain_energy_density()))

    def masses(self) -> np.ndarray:
        """Particle masses rho V [kg]."""
        return self.model.density_host * self.model.volumes_host

    def kinetic_energy(self) -> float:
        """1/2 sum m v^2 [J]."""
        v = self.velocities().astype(np.float64)
        return float(0.5 * np.dot(self.masses(), np.einsum("ij,ij->i", v, v)))

    def linear_momentum(self) -> np.ndarray:
        """sum m v [kg m/s]."""
        return self.masses() @ self.velocities().astype(np.float64)

    def angular_momentum(self, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        """sum m (x - origin) x v [kg m^2/s]."""
        x = self.positions().astype(np.float64) - np.asarray(origin, dtype=np.float64)
        return self.masses() @ np.cross(x, self.velocities().astype(np.float64))

    def slice_of(self, body: PeridynamicBody) -> slice:
        """Rows of ``body`` in the concatenated particle arrays (yielding bodies are stored first)."""
        return self.body_slice(next(i for i, b in enumerate(self.bodies) if b is body))

    def body_slice(self, index: int) -> slice:
        """Rows of the solver's body ``index`` (in ``self.bodies`` order) in the concatenated particle arrays."""
        return slice(int(self.model.body_offsets[index]), int(self.model.body_offsets[index + 1]))


def warn_if_above_estimate(dt: float, dt_crit: float):
    """Warns when a user time step exceeds the (conservative) stable estimate; divergence is still detected."""
    if dt > dt_crit:
        warnings.warn(
            f"time step {dt:.3g} s exceeds the stable estimate {dt_crit:.3g} s; the run is checked for "
            "divergence every frame",
            stacklevel=3,
        )


def check_time_step(dt: float) -> float:
    """Validates a user time step [s]."""
    return _check_range("dt", dt, 0.0, None)


__all__ = [
    "GroundPlane",
    "InstabilityError",
    "PeridynamicBody",
    "PeridynamicModel",
    "PeridynamicState",
    "SolverPeridynamics",
]
