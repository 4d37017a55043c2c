"""Material definitions: elastic constants now, with room for yield and fracture fields."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp
from scipy.spatial import cKDTree

from .checks import check_range
from .errors import ParameterError
from .kernels.peridynamics import bonds as kb

# the damage at which a broken particle is drawn as a chip of its own by default (Material.chip_damage)
CHIP_DAMAGE = 0.5


@dataclass(frozen=True)
class Anisotropy:
    """Direction-dependent stiffness and strength about one material axis (grain of wood, normal of rock layers).

    A bond whose reference direction n makes cos^2 = (n . a)^2 with the axis a (in the body's material frame, turned
    into world space by the body's ``material_rotation``) has its stiffness scaled by 1 - (1 - stiffness_ratio) cos^2
    and its critical stretch by 1 - (1 - strength_ratio) cos^2. strength_ratio < 1 makes planes normal to the axis
    weak (cracks run along them); both ratios in (0, 1] (weaker along the axis) or > 1 (stronger). The cos^2 law
    also weakens oblique bonds: a bond 40 degrees off the axis keeps only 1 - 0.59 (1 - ratio) of its strength, so
    for cracks that follow the layers under oblique load use a small strength_ratio (about 0.1).

    Args:
        axis: material axis a, 3 numbers (normalised here).
        stiffness_ratio: bond stiffness along a over across it, > 0.
        strength_ratio: critical stretch along a over across it, > 0.
    """

    axis: tuple = (0.0, 0.0, 1.0)
    stiffness_ratio: float = 1.0
    strength_ratio: float = 1.0

    def __post_init__(self):
        a = tuple(float(x) for x in self.axis) if hasattr(self.axis, "__len__") else ()
        norm = math.sqrt(sum(x * x for x in a)) if len(a) == 3 else 0.0
        if len(a) != 3 or not math.isfinite(norm) or norm == 0.0:
            raise ParameterError("axis", self.axis, "3 finite numbers, not all zero")
        object.__setattr__(self, "axis", tuple(x / norm for x in a))
        object.__setattr__(self, "stiffness_ratio", check_range("stiffness_ratio", self.stiffness_ratio, 0.0, None))
        object.__setattr__(self, "strength_ratio", check_range("strength_ratio", self.strength_ratio, 0.0, None))


@dataclass(frozen=True)
class Material:
    """An isotropic (optionally anisotropic) elastic solid that may yield and break.

    Args:
        density: mass density rho [kg/m^3], > 0.
        youngs_modulus: Young's modulus E [Pa], > 0.
        poisson_ratio: Poisson's ratio nu [-], in (-1, 0.5).
        name: optional label used in output.
        yield_stress: uniaxial yield stress sigma_Y [Pa], > 0; None (default) for a purely elastic material.
        hardening_modulus: linear hardening H [Pa], >= 0: sigma_Y grows by H times the equivalent plastic strain.
        fracture_energy: G0 [J/m^2], > 0; the critical stretch follows from it and the horizon. Give this or
            ``critical_stretch``, not both; neither means the material never breaks.
        critical_stretch: s_c [-], > 0, used as given (independent of the horizon).
        compressive_bonus: alpha >= 0 of the Silling-Askari rule s0 = s_c - alpha s_min (compression strengthens;
            s_min <= 0 is the most compressive live stretch of the bond's two particles).
        compressive_bonus_cap: k >= 0, an upper bound on that bonus relative to the bond's own critical stretch:
            s0 = s_c + min(-alpha s_min, k s_c), so no bond holds beyond (1 + k) s_c however hard its neighbourhood
            is squeezed (a ball pressed into a brittle plate otherwise stretches the material under it far beyond
            s_c before it breaks). None (default): no bound (the plain Silling-Askari rule).
        failure_plastic_strain: ductile failure: a stretched bond also breaks once the equivalent plastic strain of
            one of its particles passes this value (> 0; needs yield_stress).
        anisotropy: optional :class:`Anisotropy`.
        strength_weibull_modulus: statistical strength: each bond's critical stretch is multiplied by its own
            Weibull variate of shape m (this value, in [1, 100]) and unit median, P(factor < x) = 1 -
            2^(-x^m), drawn per undirected bond from the bond's two body-local particle indices and
            ``strength_seed`` (both directed copies get the same factor; the same seed gives the same bonds). Small m
            scatters more (m = 4: 90 % of the factors between 0.52 and 1.44; m = 10: between 0.77 and 1.16). None
            (default): every bond has the nominal strength. Needs a material that breaks.
        strength_seed: seed of the strength scatter, an integer in [0, 2^31 - 1] (default 0).
        strength_correlation_length: l [m] > 0: the strength scatter becomes a spatial random field of the material
            instead of one draw per bond: a Gaussian field with correlation exp(-r^2 / (2 l^2)) (64 random Fourier
            modes drawn from ``strength_seed``, kernels/peridynamics/bonds.py) mapped to the same Weibull marginal,
            evaluated at each bond's midpoint in the body's rest frame (the particles relative to the centre of the
            shape's bounding box, turned back by the body's ``material_rotation``). Weak spots then have a material
            size and sit at the same places in the body at every spacing and wherever the body is placed. None
            (default): one factor per bond. Needs ``strength_weibull_modulus``.
        strength_cell_size: L [m] > 0: the body is split into cells, the Voronoi cells of random points (a Poisson
            process of one point per L^3, drawn from ``strength_seed`` over the body's bounding box grown by L, in
            the body's rest frame as the strength field), and every bond whose two particles lie in the same cell is
            ``strength_cell_ratio`` times stronger: cracks then run along the cell walls, and a body that breaks
            everywhere breaks into pieces of about the cell's size, at every spacing and wherever the body is placed
            (pdsim.materials.strength_cells). A flaw network given in advance, as a pre-fractured rigid-body shot's
            Voronoi pieces; the pieces are shaped by the cells, not by the load, until a load exceeds the cells'
            interior strength. None (default): no cells. Needs a material that breaks.
        strength_cell_ratio: the cells' interior bonds' strength over the walls' bonds' [-], in [1, 1000] (default
            5); used with ``strength_cell_size``.
        debris_damping: rate c [1/s] >= 0 at which particles that lost most of their bonds (damage above
            ``debris_damage``) are pulled towards the mean velocity of the neighbours they are still bonded to, or,
            once loose, of their reference family (the material they broke from): a = c (v_bar - v)
            (kernels/peridynamics/damping.py). It calms the high-frequency debris
            that a brittle crack sheds without touching intact material (damage 0). 0 (default): off. The
            step must keep c dt < 1. Needs a material that breaks.
        retardation_time: tau [s] >= 0 of the material's internal damping (a Kelvin-Voigt solid: the viscous stress is
            tau times the elastic stress of the strain rate; peridynamic bodies, kernels/peridynamics/step.py).
            A vibration of frequency f [Hz] has the damping ratio pi f tau, so its amplitude falls tenfold in
            ln(10) / (2 pi^2 f^2 tau) seconds: a piece's high notes die first, and its rigid motion is never damped.
            It calms pieces that would otherwise ring for the whole shot (a freed piece then comes to rest and can
            be handed to the rigid solver, pdsim.RigidHandoff). The stable step shrinks by the factor
            sqrt(1 + z^2) - z, z = tau / dt0 (dt0 the undamped stable step), and the automatic step takes it into
            account. 0 (default): none.
        debris_damage: damage threshold in (0, 1) above which ``debris_damping`` acts (default 0.7: a particle on a
            clean crack face has lost about half its bonds and is left alone).
        chip_damage: the damage in (0, 1] at which the rendered surface of a peridynamic body of this material draws
            a particle as a chip of its own instead of inside its piece's shell (pdsim.fragment_surfaces, step 7).
            The default :data:`CHIP_DAMAGE` (0.5) draws a crumbling region as chips as soon as half its bonds are
            gone, while a particle next to one clean crack face (damage about 0.38 on the lattice at the default
            horizon) stays in its piece. A particle on the edge where two flat crack faces meet at a right angle has
            damage about 0.62 and one at a corner of three 0.77: 0.7, as the brittle presets with cells take, keeps
            the edges of their cell-shaped pieces in the pieces. Needs a material that breaks.
        sampling_jitter: the particle jitter, in (0, 1] of the spacing, that a peridynamic body of this material
            takes when its ``sampling`` is not given (pdsim.PeridynamicBody: sampling="jittered" with this jitter);
            None (default): the lattice. Needs a material that breaks (it keeps cracks off the lattice planes).
        contact_restitution: normal restitution e in (0, 1] of this material's contacts (the one contact law,
            pdsim/contact.py, reaches e = 0 only as its damping grows without bound). A pair takes the larger of its
            two sides' values (pdsim.contact.combine_restitution); None (default): the material brings none and the
            pair takes the other side's (another body, the ground) or, when neither has one, the scene's
            (Scene.enable_contact; the ground's restitution). Taken by every penalty pair: peridynamic particles
            with each other, with FEM surfaces and with the ground plane, and FEM surface pairs; the ground's and
            colliders' projections of FEM vertices, kinematic colliders and rigid bodies stay inelastic
            (docs/stability.md, "One contact law").
        contact_friction: Coulomb coefficient mu >= 0 of this material's contacts. A pair takes the geometric mean
            sqrt(mu_a mu_b) of its two sides (pdsim.contact.combine_friction); None (default): as for
            ``contact_restitution``, the other side's value or the scene's. Taken by every contact of peridynamic
            particles and FEM vertices (with each other, the ground plane, colliders and rigid bodies).
        rigid_handoff: the rigid hand-off of peridynamic bodies of this material that do not set their own
            (``PeridynamicBody(rigid_handoff=None)``): True turns it on with the defaults (pdsim.RigidHandoff():
            a fragment that has stopped deforming and settled becomes a rigid body); False (default) off. The
            brittle presets set True. It acts only where the material breaks; FEM bodies refuse it.

    Features a material does not use cost nothing: the solver allocates and launches plasticity only for materials
    with a yield stress and fracture only for materials that can break.
    """

    density: float
    youngs_modulus: float
    poisson_ratio: float
    name: str = "material"
    yield_stress: float | None = None
    hardening_modulus: float = 0.0
    fracture_energy: float | None = None
    critical_stretch: float | None = None
    compressive_bonus: float = 0.0
    compressive_bonus_cap: float | None = None
    failure_plastic_strain: float | None = None
    anisotropy: Anisotropy | None = None
    strength_weibull_modulus: float | None = None
    strength_seed: int = 0
    debris_damping: float = 0.0
    debris_damage: float = 0.7
    retardation_time: float = 0.0
    chip_damage: float = CHIP_DAMAGE
    strength_correlation_length: float | None = None
    strength_cell_size: float | None = None
    strength_cell_ratio: float = 5.0
    sampling_jitter: float | None = None
    contact_restitution: float | None = None
    contact_friction: float | None = None
    rigid_handoff: bool = False

    def __post_init__(self):
        object.__setattr__(self, "density", check_range("density", self.density, 0.0, None))
        object.__setattr__(self, "youngs_modulus", check_range("youngs_modulus", self.youngs_modulus, 0.0, None))
        object.__setattr__(self, "poisson_ratio", check_range("poisson_ratio", self.poisson_ratio, -1.0, 0.5))
        if self.yield_stress is not None:
            object.__setattr__(self, "yield_stress", check_range("yield_stress", self.yield_stress, 0.0, None))
        object.__setattr__(
            self,
            "hardening_modulus",
            check_range("hardening_modulus", self.hardening_modulus, 0.0, None, lo_open=False),
        )
        if self.fracture_energy is not None and self.critical_stretch is not None:
            raise ParameterError(
                "critical_stretch",
                self.critical_stretch,
                "None when fracture_energy is given (set fracture_energy=None to give a critical stretch instead)",
            )
        if self.fracture_energy is not None:
            object.__setattr__(self, "fracture_energy", check_range("fracture_energy", self.fracture_energy, 0.0, None))
        if self.critical_stretch is not None:
            object.__setattr__(
                self, "critical_stretch", check_range("critical_stretch", self.critical_stretch, 0.0, None)
            )
        object.__setattr__(
            self,
            "compressive_bonus",
            check_range("compressive_bonus", self.compressive_bonus, 0.0, None, lo_open=False),
        )
        if self.compressive_bonus_cap is not None:
            object.__setattr__(
                self,
                "compressive_bonus_cap",
                check_range("compressive_bonus_cap", self.compressive_bonus_cap, 0.0, None, lo_open=False),
            )
        if self.failure_plastic_strain is not None:
            if self.yield_stress is None:
                raise ParameterError(
                    "failure_plastic_strain", self.failure_plastic_strain, "None unless yield_stress is set"
                )
            object.__setattr__(
                self,
                "failure_plastic_strain",
                check_range("failure_plastic_strain", self.failure_plastic_strain, 0.0, None),
            )
        if self.anisotropy is not None and not isinstance(self.anisotropy, Anisotropy):
            raise ParameterError("anisotropy", self.anisotropy, "a pdsim.Anisotropy or None")
        if self.strength_weibull_modulus is not None:
            m = check_range(
                "strength_weibull_modulus", self.strength_weibull_modulus, 1.0, 100.0, lo_open=False, hi_open=False
            )
            object.__setattr__(self, "strength_weibull_modulus", m)
        seed = self.strength_seed
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or not 0 <= int(seed) <= 2**31 - 1:
            raise ParameterError("strength_seed", seed, "an integer in [0, 2147483647]")
        object.__setattr__(self, "strength_seed", int(seed))
        object.__setattr__(
            self, "debris_damping", check_range("debris_damping", self.debris_damping, 0.0, None, lo_open=False)
        )
        if not isinstance(self.rigid_handoff, bool):
            raise ParameterError("rigid_handoff", self.rigid_handoff, "True or False (the bodies' rigid hand-off)")
        tau = check_range("retardation_time", self.retardation_time, 0.0, None, lo_open=False)
        object.__setattr__(self, "retardation_time", tau)
        object.__setattr__(self, "debris_damage", check_range("debris_damage", self.debris_damage, 0.0, 1.0))
        chip = check_range("chip_damage", self.chip_damage, 0.0, 1.0, hi_open=False)
        object.__setattr__(self, "chip_damage", chip)
        if self.strength_correlation_length is not None:
            if self.strength_weibull_modulus is None:
                raise ParameterError(
                    "strength_correlation_length",
                    self.strength_correlation_length,
                    "None unless strength_weibull_modulus is set",
                )
            ell = check_range("strength_correlation_length", self.strength_correlation_length, 0.0, None)
            object.__setattr__(self, "strength_correlation_length", ell)
        if self.strength_cell_size is not None:
            size = check_range("strength_cell_size", self.strength_cell_size, 0.0, None)
            object.__setattr__(self, "strength_cell_size", size)
        ratio = check_range("strength_cell_ratio", self.strength_cell_ratio, 1.0, 1000.0, lo_open=False, hi_open=False)
        object.__setattr__(self, "strength_cell_ratio", ratio)
        if self.sampling_jitter is not None:
            jitter = check_range("sampling_jitter", self.sampling_jitter, 0.0, 1.0, hi_open=False)
            object.__setattr__(self, "sampling_jitter", jitter)
        if self.contact_restitution is not None:
            e = check_range("contact_restitution", self.contact_restitution, 0.0, 1.0, hi_open=False)
            object.__setattr__(self, "contact_restitution", e)
        if self.contact_friction is not None:
            mu = check_range("contact_friction", self.contact_friction, 0.0, None, lo_open=False)
            object.__setattr__(self, "contact_friction", mu)
        if self.strength_cell_size is not None and not self.breaks:
            raise ParameterError(
                "strength_cell_size",
                self.strength_cell_size,
                "None for a material that never breaks (give critical_stretch or fracture_energy)",
            )
        scatter = self.strength_weibull_modulus is not None or self.debris_damping > 0.0
        if self.chip_damage != CHIP_DAMAGE and not self.breaks:
            raise ParameterError(
                "chip_damage",
                self.chip_damage,
                f"{CHIP_DAMAGE} (the default) for a material that never breaks "
                "(give critical_stretch or fracture_energy)",
            )
        if self.sampling_jitter is not None and not self.breaks:
            raise ParameterError(
                "sampling_jitter",
                self.sampling_jitter,
                "None for a material that never breaks (give critical_stretch or fracture_energy)",
            )
        if scatter and not self.breaks:
            field_name = "strength_weibull_modulus" if self.strength_weibull_modulus is not None else "debris_damping"
            raise ParameterError(
                field_name,
                getattr(self, field_name),
                "None / 0 for a material that never breaks (give critical_stretch or fracture_energy)",
            )

    @property
    def yields(self) -> bool:
        """True when the material has a yield stress (plasticity is simulated)."""
        return self.yield_stress is not None

    @property
    def breaks(self) -> bool:
        """True when bonds of this material can break (a fracture energy, a critical stretch or a failure strain)."""
        return (
            self.fracture_energy is not None
            or self.critical_stretch is not None
            or (self.failure_plastic_strain is not None)
        )

    def critical_stretch_for(self, horizon: float) -> float:
        """Critical stretch s_c [-] for a horizon delta [m]: given directly, or from G0 as
        s_c = sqrt(G0 / (c_G delta)) (:attr:`crack_energy_modulus`); inf for a material that never breaks by
        stretch (tests/test_pd_plastic_fracture.py checks this calibration against the discrete energy of a cut)."""
        if self.critical_stretch is not None:
            return self.critical_stretch
        if self.fracture_energy is None:
            return math.inf
        return math.sqrt(self.fracture_energy / (self.crack_energy_modulus * horizon))

    @property
    def crack_energy_modulus(self) -> float:
        """c_G = 3 mu + (3/4)^4 (kappa - 5 mu / 3) [Pa]: the energy per unit area [J/m^2] to open a crack through
        bonds all stretched to s_c is G = c_G delta s_c^2 (the ordinary state-based model's critical stretch
        s_c = sqrt(G / (c_G delta)) of Madenci and Oterkus, Peridynamic Theory and Its Applications, 2014; the
        discrete model's energy of a cut matches it within 0.3 % at 3.015 spacings, tests/test_pd_plastic_fracture.py
        test_fracture_energy_calibration)."""
        mu, kappa = self.shear_modulus, self.bulk_modulus
        return 3.0 * mu + (0.75**4) * (kappa - 5.0 * mu / 3.0)

    @property
    def bulk_modulus(self) -> float:
        """kappa = E / (3 (1 - 2 nu)) [Pa]."""
        return self.youngs_modulus / (3.0 * (1.0 - 2.0 * self.poisson_ratio))

    @property
    def shear_modulus(self) -> float:
        """mu = E / (2 (1 + nu)) [Pa]."""
        return self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))

    @property
    def lame_lambda(self) -> float:
        """lambda = kappa - 2 mu / 3 [Pa]."""
        return self.bulk_modulus - 2.0 * self.shear_modulus / 3.0

    @property
    def p_wave_modulus(self) -> float:
        """M = kappa + 4 mu / 3 = lambda + 2 mu [Pa]."""
        return self.bulk_modulus + 4.0 * self.shear_modulus / 3.0

    @property
    def p_wave_speed(self) -> float:
        """Dilatational (P) wave speed sqrt(M / rho) [m/s]."""
        return math.sqrt(self.p_wave_modulus / self.density)

    @property
    def bar_wave_speed(self) -> float:
        """Thin-bar (one-dimensional stress) wave speed sqrt(E / rho) [m/s]."""
        return math.sqrt(self.youngs_modulus / self.density)

    @property
    def shear_wave_speed(self) -> float:
        """Shear (S) wave speed sqrt(mu / rho) [m/s]."""
        return math.sqrt(self.shear_modulus / self.density)


def strength_factors(material: Material, points, *, device="cpu") -> np.ndarray:
    """The factors [-] by which ``material``'s strength field (``strength_correlation_length``) multiplies the
    critical stretch of a bond whose midpoint is at each of ``points`` [m], shape [n, 3], given in the body's rest
    frame (relative to the centre of the shape's bounding box); float64 [n]. The same kernel function sets the bonds'
    strengths (kernels/peridynamics/bonds.py)."""
    if material.strength_correlation_length is None:
        raise ParameterError("material", material.name, "a material with a strength_correlation_length")
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or not np.all(np.isfinite(p)):
        raise ParameterError("points", f"shape {p.shape}", "finite points of shape [n, 3]")
    modes = kb.strength_field_modes(material.strength_correlation_length, material.strength_seed)
    out = wp.zeros(max(len(p), 1), dtype=float, device=device)
    kb.strength_field(
        len(p),
        points=wp.array(p.astype(np.float32), dtype=wp.vec3, device=device),
        modes=wp.array(modes, dtype=wp.vec4, device=device),
        mode_count=len(modes),
        modulus=float(material.strength_weibull_modulus),
        factor=out,
        device=device,
    )
    return out.numpy()[: len(p)].astype(np.float64)


def cell_points(material: Material, bounds) -> np.ndarray:
    """The random points whose Voronoi cells are ``material``'s cells (``strength_cell_size`` L) in a body whose
    shape has the bounding box ``bounds`` [m] (2 x 3): a Poisson process of mean density 1 / L^3 drawn from
    ``strength_seed`` over the box of half-size (bounds[1] - bounds[0]) / 2 + L, in the body's rest frame (relative
    to the box's centre, as :func:`strength_factors`), so that they depend on the material, the seed and the shape's
    size alone: not on the spacing, nor on where the body is placed. A body turned by a ``material_rotation`` can
    reach past that box at its corners; the particles there take the cells of the points nearest them, at the box's
    edge. float64 [count, 3]."""
    if material.strength_cell_size is None:
        raise ParameterError("material", material.name, "a material with a strength_cell_size")
    size = material.strength_cell_size
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    half = 0.5 * (hi - lo) + size
    rng = np.random.default_rng([material.strength_seed, CELL_STREAM])
    count = max(1, int(rng.poisson(np.prod(2.0 * half) / size**3)))
    return (2.0 * rng.random((count, 3)) - 1.0) * half


def strength_cells(material: Material, bounds, points) -> np.ndarray:
    """The cell of each of ``points`` [m], shape [n, 3] in the body's rest frame: the index of the nearest of
    :func:`cell_points` (``bounds``: the shape's bounding box [m], 2 x 3). int64 [n]."""
    seeds = cell_points(material, bounds)
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or not np.all(np.isfinite(p)):
        raise ParameterError("points", f"shape {p.shape}", "finite points of shape [n, 3]")
    return cKDTree(seeds).query(p)[1].astype(np.int64)


CELL_STREAM = 0x63656C6C  # the random stream of the cell points, apart from the other uses of strength_seed

# A few presets with round numbers; soft enough that animation time steps stay affordable.
RUBBER = Material(density=1100.0, youngs_modulus=5.0e6, poisson_ratio=0.45, name="rubber")
SOFT_SOLID = Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3, name="soft_solid")
