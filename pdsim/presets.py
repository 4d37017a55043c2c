"""Named material presets: glass, concrete, wood, clay, steel and aluminium.

Each preset is a function returning a :class:`pdsim.Material` in SI units. ``real=True`` gives typical measured
values from the literature (the ranges are in each docstring). The default, ``real=False``, gives the *animation*
values: the same density, Poisson's ratio and behaviour (brittle, ductile, soft) with the stiffness scaled down so
that a 1 cm spacing runs at an affordable time step.

Why the animation values differ. The automatic step of the peridynamic solid is about 0.55 h / c (h the spacing, c
the bar wave speed sqrt(E / rho); docs/accuracy.md, section 4): glass, concrete, wood along the grain and metals all
have c = 3.5 to 5.3 km/s, so h = 1 cm needs steps of 1-1.5 us, 27,000 to 40,000 steps per frame at 24 fps. The
animation presets multiply Young's modulus by ``STIFFNESS_SCALE`` = 1e-4 (the wave speed by 1e-2: 35-53 m/s, 270 to
400 steps per frame at h = 1 cm). The scaled presets give their strength as a strain (``critical_stretch``, a yield
strain through ``yield_stress``), because an impact at speed v strains a body by about v / c: with c 100 times lower,
the real breaking strains (1e-4 to 1e-3) would make every touch shatter. Each animation preset says which strains it
uses and why; the real values are kept for slow-motion shots (``Scene(frame_time=...)`` of microseconds) and
engineering checks.

Spacing. The particles across the thinnest part of a body set the accuracy of its stiffness (docs/accuracy.md: 10 %
at about 5 across, 5 % at 10) and its cost. With a real ``fracture_energy`` G the critical stretch, and so the
tensile strength, depends on the horizon delta: s_c = sqrt(G / (c_G delta)). :func:`spacing_for_strength` gives the
spacing at which the real G reproduces the real tensile strength: glass 0.08 mm, wood split along the grain 4 mm,
concrete 11 cm. So a building-scale concrete wall at real values is affordable while a glass pane is not. The
animation presets use a critical stretch instead, so a coarse preview breaks at the same strain as the final run.
"""

from __future__ import annotations

import math

from .checks import check_range, check_vec3
from .errors import ParameterError
from .materials import Anisotropy, Material

STIFFNESS_SCALE = 1.0e-4  # Young's modulus (and stresses) of the animation presets over the real ones
# Silling-Askari compressive bonus alpha of the brittle presets (s0 = s_c - alpha s_min). It makes them unbreakable
# in uniaxial compression (nu < alpha) while keeping them about as weak in pure shear as in tension: simple shear
# breaks them at 1.33 times the unbonused shear strain, where alpha = 1 would hold them to 2 sqrt(s_c) instead of
# 2 s_c, ten times it at s_c = 0.01 (tests/test_pd_plastic_fracture.py, test_compressive_bonus_in_simple_shear).
COMPRESSIVE_BONUS = 0.25

# Typical tensile strengths [Pa] of the real materials (for spacing_for_strength and the guide's table); wood: across
# the grain (the strength that splitting along the grain needs).
TENSILE_STRENGTH = {
    "glass": 45.0e6,
    "concrete": 3.0e6,
    "wood": 3.0e6,
}


def _brittle(name, density, youngs_modulus, poisson_ratio, *, fracture_energy, critical_stretch, real) -> Material:
    """A brittle preset: the real ``youngs_modulus`` [Pa] and ``fracture_energy`` [J/m^2] with ``real``, else the
    modulus times STIFFNESS_SCALE and a ``critical_stretch`` [-]; both with the COMPRESSIVE_BONUS."""
    strength = {"fracture_energy": fracture_energy} if real else {"critical_stretch": critical_stretch}
    return Material(
        density=density,
        youngs_modulus=youngs_modulus if real else youngs_modulus * STIFFNESS_SCALE,
        poisson_ratio=poisson_ratio,
        compressive_bonus=COMPRESSIVE_BONUS,
        name=name,
        **strength,
    )


def _metal(
    name, density, youngs_modulus, poisson_ratio, real_plasticity, *, hardening_ratio, failure, real
) -> Material:
    """A ductile preset: with ``real`` the real modulus [Pa] and ``real_plasticity`` (yield stress, hardening modulus
    [Pa]); else the modulus times STIFFNESS_SCALE, a yield strain of 1 % and a hardening modulus of
    ``hardening_ratio`` times the modulus. ``failure``: the plastic strain at which bonds tear [-]."""
    if real:
        e, yield_stress, hardening = youngs_modulus, *real_plasticity
    else:
        e = youngs_modulus * STIFFNESS_SCALE
        yield_stress, hardening = 0.01 * e, hardening_ratio * e
    return Material(
        density=density,
        youngs_modulus=e,
        poisson_ratio=poisson_ratio,
        yield_stress=yield_stress,
        hardening_modulus=hardening,
        failure_plastic_strain=failure,
        name=name,
    )


def glass(*, real: bool = False) -> Material:
    """Soda-lime (float, window) glass: brittle.

    Real values and typical ranges: density 2500 kg/m^3 (2440-2530); E = 70 GPa (68-74); nu = 0.22 (0.21-0.24);
    fracture toughness K_Ic 0.7-0.8 MPa m^0.5, so G = K_Ic^2 / E = 8 J/m^2 (7-10); tensile (bending) strength of
    annealed glass 30-100 MPa, set by surface flaws (Weibull modulus of the strength about 5-10); compressive strength
    about 1 GPa (compressive_bonus 0.25, :data:`COMPRESSIVE_BONUS`: bonds in a compressed neighbourhood hold longer,
    and uniaxial compression alone breaks none).

    Animation values (``real=False``): E = 7 MPa (1e-4 of the real one: 53 m/s wave speed, about 400 steps per frame
    at 24 fps and h = 1 cm); critical_stretch 0.005 instead of G: the real G gives s_c = 5.6e-5 at h = 1 cm, and with a
    wave speed 100x lower a strain 100x larger keeps an impact's strain over the breaking strain (v / (c s_c)) at its
    real value. 0.5 % stays invisible before the break.
    """
    return _brittle("glass", 2500.0, 70.0e9, 0.22, fracture_energy=8.0, critical_stretch=0.005, real=real)


def concrete(*, real: bool = False) -> Material:
    """Normal-strength concrete (C30/37): brittle in tension, about ten times stronger in compression.

    Real values and typical ranges: density 2400 kg/m^3 (2200-2500); E = 30 GPa (25-40); nu = 0.2 (0.15-0.22);
    fracture energy G_F = 120 J/m^2 (70-150); tensile strength 2-4 MPa (Weibull modulus about 8-12); compressive
    strength 20-50 MPa (compressive_bonus 0.25). Its characteristic length E G_F / f_t^2 is about 0.4 m: the spacing at
    which the real G_F gives the real tensile strength is 11 cm (:func:`spacing_for_strength`), affordable for a wall
    or a slab.

    Animation values: E = 3 MPa (1e-4: 35 m/s wave speed, about 270 steps per frame at 24 fps and h = 1 cm);
    critical_stretch 0.002: concrete's real breaking strain f_t / E = 1e-4 is the smallest of the presets and stays
    below glass's; raised 20x (less than glass's 90x) it keeps concrete the weaker, crumblier of the two brittle
    presets at animation speeds.
    """
    return _brittle("concrete", 2400.0, 30.0e9, 0.2, fracture_energy=120.0, critical_stretch=0.002, real=real)


def wood(*, real: bool = False, grain=(1.0, 0.0, 0.0)) -> Material:
    """Softwood (spruce, pine; 12 % moisture): stiff and strong along the grain, weak across it, so it splits along
    the grain.

    The base values are those across the grain; an :class:`pdsim.Anisotropy` about ``grain`` (the fibre direction in
    the body's material frame; turn it with the body's ``material_rotation``) makes bonds along the fibres stiffer
    (``stiffness_ratio``) and able to stretch further (``strength_ratio``). Both ratios follow the cos^2 law of
    :class:`pdsim.Anisotropy`.

    Real values and typical ranges: density 450 kg/m^3 (350-550); E along the grain 11 GPa (9-14), across 0.5 GPa
    (0.3-0.9), ratio 22; nu 0.3 (an isotropic stand-in for the 0.02-0.5 of the orthotropic ratios); tensile strength
    along 80 MPa (60-100), across 3 MPa (1.5-4); fracture energy for splitting (crack plane along the grain) 250 J/m^2
    (150-500); across the grain the fibres must break and the energy is one to two orders of magnitude higher. The
    breaking strain is 0.6 % across (3 MPa / 0.5 GPa) and 0.7 % along (80 MPa / 11 GPa): strength_ratio 1.2.

    Animation values: E across 50 kPa, bonds along the grain 22 x stiffer (1e-4 of the real moduli; the stiff bonds
    set the step: about 300 steps per frame at 24 fps and h = 1 cm); critical_stretch 0.006 across (the real breaking
    strain: wood's is already large enough to stay whole under a light touch); strength_ratio 3 rather than 1.2:
    with the cos^2 law oblique bonds share the reinforcement only in part, and 3 brings the splitting load down to
    about 0.1 of the load that breaks the fibres (tests/test_guide_materials.py; real wood: 3 / 80 = 0.04).
    """
    axis = tuple(check_vec3("grain", grain))
    if real:
        layered = Anisotropy(axis=axis, stiffness_ratio=22.0, strength_ratio=1.2)
        return Material(
            density=450.0,
            youngs_modulus=0.5e9,
            poisson_ratio=0.3,
            fracture_energy=250.0,
            anisotropy=layered,
            name="wood",
        )
    layered = Anisotropy(axis=axis, stiffness_ratio=22.0, strength_ratio=3.0)
    return Material(
        density=450.0,
        youngs_modulus=0.5e9 * STIFFNESS_SCALE,
        poisson_ratio=0.3,
        critical_stretch=0.006,
        anisotropy=layered,
        name="wood",
    )


def clay(*, real: bool = False) -> Material:
    """Plastic (modelling or pottery) clay: soft, flows at a low stress, keeps its new shape and tears only after very
    large strains.

    Real values and typical ranges: density 1800 kg/m^3 (1600-2000); E = 1 MPa (0.1-10, with the water content);
    nu = 0.45 (0.4-0.49: nearly incompressible); yield stress 20 kPa (von Mises; sqrt(3) times an undrained shear
    strength of 5-50 kPa); no hardening; a stretched clay strand tears at plastic strains of order 1
    (failure_plastic_strain 2).

    Clay is soft already (24 m/s wave speed, about 260 steps per frame at 24 fps and h = 1 cm; nu near 0.5 shortens
    the step), so the animation values equal the real ones.
    """
    del real  # the same values either way (see the docstring)
    return Material(
        density=1800.0,
        youngs_modulus=1.0e6,
        poisson_ratio=0.45,
        yield_stress=20.0e3,
        hardening_modulus=0.0,
        failure_plastic_strain=2.0,
        name="clay",
    )


def steel(*, real: bool = False) -> Material:
    """Mild structural steel (S235-S355): ductile.

    Real values and typical ranges: density 7850 kg/m^3; E = 210 GPa (200-210); nu = 0.3; yield stress 250 MPa
    (235-355); linear hardening up to the tensile strength (400-550 MPa at 15-25 % strain), H about 1 GPa
    (0.5-2); the plastic strain in a neck reaches 0.3-1 before it tears (failure_plastic_strain 0.4).

    Animation values: E = 21 MPa (1e-4: 52 m/s wave speed, about 390 steps per frame at 24 fps and h = 1 cm); yield
    stress 210 kPa, a yield strain of 1 % instead of the real 0.12 %: a hit of a few m/s strains a body by v / c of
    several percent here, which would flatten a part with the real yield strain; 1 % keeps the spring-back invisible.
    Hardening H = 0.005 E (the real H / E); failure_plastic_strain 0.4 (real).
    """
    return _metal("steel", 7850.0, 210.0e9, 0.3, (250.0e6, 1.0e9), hardening_ratio=0.005, failure=0.4, real=real)


def aluminium(*, real: bool = False) -> Material:
    """Aluminium alloy 6061-T6: ductile, with less hardening and an earlier tear than mild steel.

    Real values and typical ranges: density 2700 kg/m^3; E = 69 GPa (68-71); nu = 0.33; yield stress 275 MPa
    (240-290); tensile strength 310 MPa at about 10 % strain, H about 0.5 GPa; elongation at break 8-17 %, plastic
    strain at tearing 0.2-0.5 (failure_plastic_strain 0.25).

    Animation values: E = 6.9 MPa (1e-4: 51 m/s wave speed, about 390 steps per frame at 24 fps and h = 1 cm);
    yield stress 69 kPa (1 % yield strain, for the reason given under :func:`steel`); H = 0.007 E (the real H / E);
    failure_plastic_strain 0.25 (real).
    """
    return _metal("aluminium", 2700.0, 69.0e9, 0.33, (275.0e6, 0.5e9), hardening_ratio=0.007, failure=0.25, real=real)


PRESETS = {
    "glass": glass,
    "concrete": concrete,
    "wood": wood,
    "clay": clay,
    "steel": steel,
    "aluminium": aluminium,
}


def preset(name: str, *, real: bool = False) -> Material:
    """The preset called ``name`` (one of :data:`PRESETS`)."""
    if name not in PRESETS:
        raise ParameterError("name", name, " or ".join(map(repr, PRESETS)))
    return PRESETS[name](real=real)


def spacing_for_strength(material: Material, tensile_strength: float, *, horizon_factor: float = 3.015) -> float:
    """The spacing h [m] at which ``material``'s fracture energy gives ``tensile_strength`` [Pa] in uniaxial tension.

    A bar pulled along a lattice axis breaks when its bonds along the axis reach s_c, at a stress of about E s_c, and
    s_c = sqrt(G / (c_G delta)) with c_G = 3 mu + (3/4)^4 (kappa - 5 mu / 3) (:meth:`Material.critical_stretch_for`).
    So delta = G / (c_G (f_t / E)^2) and h = delta / horizon_factor. A finer spacing makes the material stronger than
    ``tensile_strength``, a coarser one weaker (the strength scales as h^-1/2).
    """
    if material.fracture_energy is None:
        raise ParameterError("material", material.name, "a material with a fracture_energy")
    f_t = check_range("tensile_strength", tensile_strength, 0.0, None)
    m = check_range("horizon_factor", horizon_factor, 1.5, 8.0, lo_open=False, hi_open=False)
    mu, kappa = material.shear_modulus, material.bulk_modulus
    c_g = 3.0 * mu + 0.75**4 * (kappa - 5.0 * mu / 3.0)
    strain = f_t / material.youngs_modulus
    delta = material.fracture_energy / (c_g * strain * strain)
    if not math.isfinite(delta) or delta <= 0.0:
        raise ParameterError("material", material.name, "elastic constants that give a positive horizon")
    return delta / m


__all__ = [
    "COMPRESSIVE_BONUS",
    "PRESETS",
    "STIFFNESS_SCALE",
    "TENSILE_STRENGTH",
    "aluminium",
    "clay",
    "concrete",
    "glass",
    "preset",
    "spacing_for_strength",
    "steel",
    "wood",
]
