"""Named material presets: glass, porcelain, ceramic, stone, concrete, plaster, wood, clay, steel, aluminium, rubber.

Each preset is a function returning a :class:`pdsim.Material` in SI units. ``real=True`` gives typical measured
values from the literature (the ranges are in each docstring). The default, ``real=False``, gives the *animation*
values: the same density, Poisson's ratio and behaviour (brittle, ductile, soft) with the stiffness scaled down so
that a 1 cm spacing runs at an affordable time step.

Why the animation values differ. The automatic step of the peridynamic solid is about 0.55 h / c (h the spacing, c
the bar wave speed sqrt(E / rho); docs/accuracy.md, section 4): glass, concrete, wood along the grain and metals all
have c = 3.5 to 5.3 km/s, so h = 1 cm needs steps of 1-1.5 us, 27,000 to 40,000 steps per frame at 24 fps. The
animation presets multiply Young's modulus by ``STIFFNESS_SCALE`` = 1e-4 (plaster's by
:data:`PLASTER_STIFFNESS_SCALE`; the wave speed by about 1e-2: 35-53 m/s, 270 to 440 steps per frame at h = 1 cm).
The scaled presets give their strength as a strain (``critical_stretch``, a yield strain through ``yield_stress``),
because an impact at speed v strains a body by about v / c: with c 100 times lower,
the real breaking strains (1e-4 to 1e-3) would make every touch shatter. Each animation preset says which strains it
uses and why; the real values are kept for slow-motion shots (``Scene(frame_time=...)`` of microseconds) and
engineering checks.

Break pattern. The brittle presets (glass, porcelain, ceramic, stone, concrete, plaster) carry, with ``pattern=True``
(default), the settings meant to make them break into shards rather than dust at an artist's preview spacing;
tests/test_preset_patterns.py records which drops and hits meet that (docs/fracture.md, "Presets at preview and final
spacing"): a strength field with a material correlation length (``strength_weibull_modulus``,
``strength_correlation_length``: the weak spots are the material's, the same at every spacing), jittered particles
(``sampling_jitter`` 0.5: no lattice planes for cracks to follow), cells of :data:`CELL_SIZE` whose interior bonds
are :data:`CELL_RATIO` times stronger than their walls (``strength_cell_size``, ``strength_cell_ratio``: cracks run
along the walls, and a body that breaks all over breaks into pieces of about the cell's size; change the size with
``dataclasses.replace(pdsim.presets.glass(), strength_cell_size=0.05)`` for smaller shards), particles drawn as
chips only from damage :data:`CHIP_DAMAGE` (``chip_damage``: the pieces' edges and corners stay in them), debris damping
(:data:`DEBRIS_DAMPING` per second of the animation values for glass and porcelain, less for the others, a fixed rate
so that it acts alike at every spacing) and the full compressive bonus capped at 1.5 s_c (:data:`SHARD_BONUS`,
:data:`SHARD_BONUS_CAP`; 2 to 2.5 s_c for ceramic, stone and plaster). Each preset's docstring gives its values and
why. ``pattern=False`` gives the plain material (uniform strength, no cells, chips from the default damage 0.5,
lattice sampling, no debris damping, the compressive bonus :data:`COMPRESSIVE_BONUS`), whose breaking strain at the
reference spacing is exactly the stated one. The other presets have no pattern settings (wood splits by its grain;
clay, steel and aluminium tear by plasticity; rubber never breaks), so ``pattern`` changes nothing for them.

Contact. Every preset carries a ``contact_restitution`` and a ``contact_friction`` (:data:`CONTACT`), the values its
contacts bring to a pair (combined with the other side's, pdsim/contact.py combine_restitution, combine_friction).

Rigid hand-off. The brittle presets carry ``rigid_handoff=True`` (with and without ``pattern``): a peridynamic body of
them that sets no ``rigid_handoff`` of its own hands its settled pieces to the rigid solver (pdsim.RigidHandoff's
defaults: a piece that has stopped vibrating and moves too slowly for any impact at its own speed to break it). The
pieces are then written as transforms of static meshes and no longer cost their bonds, but a settled piece that a
later projectile hits bounces off whole (docs/fracture.md, "Rigid hand-off"); ``PeridynamicBody(rigid_handoff=False)``
or ``dataclasses.replace(material, rigid_handoff=False)`` turns it off.

Spacing. The particles across the thinnest part of a body set the accuracy of its stiffness (docs/accuracy.md: 10 %
at about 5 across, 5 % at 10) and its cost. Every brittle preset gives its strength as a ``fracture_energy`` G, the
energy per unit area of crack, which the spacing does not change: the critical stretch follows from the horizon delta
as s_c = sqrt(G / (c_G delta)) (:attr:`pdsim.Material.crack_energy_modulus`), so at half the spacing s_c is sqrt 2
larger and opening a crack costs the same energy at every spacing (a fixed s_c would make the material half as tough
at h/2, and the same impact would open twice the crack area: docs/fracture.md, "Presets at preview and final
spacing"). The animation presets state their G as the critical stretch it gives at :data:`REFERENCE_SPACING` (2 cm,
the preview spacing of a 30 cm object) with the default horizon of :data:`REFERENCE_HORIZON_FACTOR` spacings
(:func:`energy_for_stretch`). A material built with ``critical_stretch`` keeps exactly that stretch at every spacing
(replace the preset's ``fracture_energy`` with None to give one). With the real G, :func:`spacing_for_strength`
gives the spacing at which it reproduces the real tensile strength: glass 0.08 mm, wood split along the grain 4 mm,
concrete 11 cm. So a building-scale concrete wall at real values is affordable while a glass pane is not.
"""

from __future__ import annotations

import dataclasses
import functools
import math

from .checks import check_range, check_vec3
from .errors import ParameterError
from .materials import Anisotropy, Material
from .peridynamics.body import DEFAULT_HORIZON_FACTOR

STIFFNESS_SCALE = 1.0e-4  # Young's modulus (and stresses) of the animation presets over the real ones
# Plaster's: 2 MPa for its real 12 GPa, the wave speed of ceramic (43 m/s) instead of 33 m/s at 1e-4. At 33 m/s the
# presets' hit (a 4.1 kg steel ball at 22 m/s, tools/preview_final.py) came at two thirds of the wave speed, where a
# real plaster body meets such a ball at 1/150 of it: the sphere was crushed into a bowl under the ball at the preview
# spacing and broke through at the final one (broken out 17 % against 48 % over strength seeds 0-4); at 43 m/s the
# means over seeds 0-9 agree within 30 % (51 % against 66 %; docs/fracture.md, "Presets at preview and final
# spacing").
PLASTER_STIFFNESS_SCALE = 2.0e6 / 12.0e9
# The brittle animation presets' strength is a fracture energy, stated as the critical stretch it gives at this
# spacing [m] with the default horizon (PeridynamicBody's horizon_factor): the preview spacing of a 30 cm object.
REFERENCE_SPACING = 0.02
REFERENCE_HORIZON_FACTOR = DEFAULT_HORIZON_FACTOR
# Silling-Askari compressive bonus alpha of the brittle presets (s0 = s_c - alpha s_min). It makes them unbreakable
# in uniaxial compression (nu < alpha) while keeping them about as weak in pure shear as in tension: simple shear
# breaks them at 1.33 times the unbonused shear strain, where alpha = 1 would hold them to 2 sqrt(s_c) instead of
# 2 s_c, ten times it at s_c = 0.01 (tests/test_pd_plastic_fracture.py, test_compressive_bonus_in_simple_shear).
COMPRESSIVE_BONUS = 0.25

# The brittle presets' break pattern (pattern=True; docs/fracture.md, "Presets at preview and final spacing"): the
# full compressive bonus capped at 1.5 s_c holds the material under a contact together (0.25 turns it to dust, the
# uncapped bonus keeps a dropped sphere whole, a cap of 3 left half of what a dropped glass sphere shed as dust;
# ceramic, stone and plaster take 2 to 2.5, their docstrings say why), debris damping at a fixed rate [1/s] of the
# animation values, per preset (glass: c dt 0.4 at the 2 cm preview spacing, 0.2 at 1 cm; times the wave-speed ratio
# 100 for the real values), jitter 0.5.
SHARD_BONUS = 1.0
SHARD_BONUS_CAP = 1.5
DEBRIS_DAMPING = 3000.0  # glass and porcelain; concrete half; ceramic, stone and plaster as tuned (their docstrings)
SAMPLING_JITTER = 0.5
# The brittle presets' cells (pattern=True; Material.strength_cell_size, strength_cell_ratio): bonds inside a cell of
# about 20 cm are 5 times stronger than those across its walls, so a body that breaks all over (a 6 m/s drop strains
# the animation values 23 times their breaking strain) breaks along the walls into pieces of about that size, alike
# at every spacing, instead of crumbling (docs/fracture.md, "Presets at preview and final spacing", measures the
# sizes and ratios tried).
CELL_SIZE = 0.2
CELL_RATIO = 5.0
# The damage at which the brittle presets' particles are drawn as chips (pattern=True; Material.chip_damage): their
# pieces are cells whose flat faces meet at edges and corners, where a particle still in its piece has lost about 0.62
# (an edge) and 0.75 (a corner of three faces) of its bonds; at the default 0.5 every such edge is drawn as a lining of
# chips. Below 0.8 a particle moves with the neighbours it is still bonded to (its median distance from where they
# place it is at most 0.22 spacings in every preset's drop and hit at 2 and 1 cm); from 0.8 up the hits' crushed
# particles come loose from them (docs/fracture.md, "Presets at preview and final spacing", measures both).
CHIP_DAMAGE = 0.8
# The animation values' impact strain over breaking strain, v / (c s_c) at v = 6 m/s (a 1.8 m fall), of glass (c =
# 53 m/s, s_c = 0.005 at the reference spacing): ceramic, stone and plaster take the critical stretch (at the
# reference spacing) that gives them the same ratio
# (s_c = 6 / (23 c), rounded), so a drop loads each of them as much as glass. With their former strains (0.004, 0.003,
# 0.0025) the ratio was 35, 46 and 73 and a dropped sphere of them turned to dust where glass broke into pieces
# (docs/fracture.md, "Presets at preview and final spacing"). The breaking stresses E s_c keep their order: glass
# 35 kPa, stone 30, ceramic 24, plaster 12. Porcelain (54 m/s) has glass's strain already; concrete keeps its
# 0.002 (walls and slabs).
IMPACT_STRAIN_RATIO = 23.0
# The brittle presets' internal damping (Material.retardation_time) [s] of the animation values; times
# sqrt(STIFFNESS_SCALE) for the real values (the same damping ratio at the frequencies 100 times higher). At the
# animation stiffness a 10 cm piece rings at about 280 Hz, 100 times below real glass, and without damping it rang for
# the whole of a 2 s shot: tau = 5e-6 s gives it the damping ratio pi f tau = 0.0044 and brings its ringing tenfold down
# in 0.3 s, so the rigid hand-off takes the pieces of a dropped glass sphere once they settle (all of what broke out by
# 3 s; docs/fracture.md, "Rigid hand-off"). It is tuned, not a measured loss factor: real glass has about 1e-3 at its
# own (100 times higher) frequencies, which would leave the animation's pieces ringing for seconds. Its damping ratio at
# the spacing's highest frequencies is tau / dt0 (dt0: the undamped stable step): 0.016 for glass at 2 cm, 0.032 at 1
# cm, and the stable step shrinks by about as much; the shard figures over strength seeds 0-4 stay within their scatter
# (docs/fracture.md, "Presets at preview and final spacing").
RETARDATION_TIME = 5.0e-6

# The presets' contact values (restitution e, Coulomb friction mu), the material's side of a contact pair: measured
# coefficients of restitution of balls and chips dropped on hard floors (glass, porcelain, stone and concrete shed
# most of the impact's energy: 0.1-0.2; plaster and clay crush: 0.05; wood 0.3-0.5; hardened steel on steel 0.5-0.6;
# aluminium a little lower; rubber balls 0.75-0.9) and the usual dry static friction tables (glass 0.4 against most
# surfaces once not perfectly clean, ceramic 0.5, stone, concrete and plaster 0.6, wood 0.5, metals on metals 0.4
# with the oxide layer, rubber 0.9 on hard dry surfaces).
CONTACT = {
    "glass": (0.1, 0.4),
    "porcelain": (0.15, 0.5),
    "ceramic": (0.15, 0.5),
    "stone": (0.1, 0.6),
    "concrete": (0.1, 0.6),
    "plaster": (0.05, 0.6),
    "wood": (0.3, 0.5),
    "clay": (0.05, 0.6),
    "steel": (0.5, 0.4),
    "aluminium": (0.4, 0.4),
    "rubber": (0.8, 0.9),
}


def _contact(preset_function):
    """The preset ``preset_function`` with its contact values (:data:`CONTACT`, by its name) set on the material
    it returns."""
    restitution, friction = CONTACT[preset_function.__name__]

    @functools.wraps(preset_function)
    def with_contact(*args, **kwargs) -> Material:
        material = preset_function(*args, **kwargs)
        return dataclasses.replace(material, contact_restitution=restitution, contact_friction=friction)

    return with_contact


# Typical tensile strengths [Pa] of the real materials (for spacing_for_strength and the guide's table); wood: across
# the grain (the strength that splitting along the grain needs).
TENSILE_STRENGTH = {
    "glass": 45.0e6,
    "concrete": 3.0e6,
    "wood": 3.0e6,
}


def energy_for_stretch(material: Material, critical_stretch: float, *, spacing: float = REFERENCE_SPACING) -> float:
    """The fracture energy G [J/m^2] at which ``material``'s elastic constants give the critical stretch
    ``critical_stretch`` [-] at ``spacing`` [m] with the default horizon: G = c_G delta s_c^2, delta =
    REFERENCE_HORIZON_FACTOR * spacing, c_G = :attr:`pdsim.Material.crack_energy_modulus`."""
    s_c = check_range("critical_stretch", critical_stretch, 0.0, None)
    h = check_range("spacing", spacing, 0.0, None)
    return material.crack_energy_modulus * REFERENCE_HORIZON_FACTOR * h * s_c * s_c


def _brittle(
    name,
    density,
    youngs_modulus,
    poisson_ratio,
    *,
    fracture_energy,
    critical_stretch,
    weibull_modulus,
    correlation_length,
    real,
    pattern,
    debris_damping=DEBRIS_DAMPING,
    bonus_cap=SHARD_BONUS_CAP,
    stiffness_scale=STIFFNESS_SCALE,
) -> Material:
    """A brittle preset: the real ``youngs_modulus`` [Pa] and ``fracture_energy`` [J/m^2] with ``real``, else the
    modulus times ``stiffness_scale`` (STIFFNESS_SCALE but for plaster) and the fracture energy that gives
    ``critical_stretch`` [-] at REFERENCE_SPACING (:func:`energy_for_stretch`). With ``pattern`` the break-pattern
    settings (module docstring): a strength field of Weibull modulus ``weibull_modulus`` and ``correlation_length``
    [m], jitter, ``debris_damping`` [1/s] (of the animation values; over the wave-speed ratio for the real values),
    the full bonus capped at ``bonus_cap`` s_c; without, the COMPRESSIVE_BONUS alone. Either way the internal damping
    RETARDATION_TIME (a property of the material, not of the break pattern) and the rigid hand-off (module
    docstring)."""
    speed_ratio = math.sqrt(stiffness_scale)  # animation wave speed over the real one
    if real:
        energy = fracture_energy
    else:
        elastic = Material(density, youngs_modulus * stiffness_scale, poisson_ratio)
        energy = energy_for_stretch(elastic, critical_stretch)
    damping = {"retardation_time": RETARDATION_TIME * (speed_ratio if real else 1.0)}
    if pattern:
        extra = {
            "compressive_bonus": SHARD_BONUS,
            "compressive_bonus_cap": bonus_cap,
            "strength_weibull_modulus": weibull_modulus,
            "strength_correlation_length": correlation_length,
            "strength_cell_size": CELL_SIZE,
            "strength_cell_ratio": CELL_RATIO,
            "chip_damage": CHIP_DAMAGE,
            "debris_damping": debris_damping / speed_ratio if real else debris_damping,
            "sampling_jitter": SAMPLING_JITTER,
        }
    else:
        extra = {"compressive_bonus": COMPRESSIVE_BONUS}
    return Material(
        density=density,
        youngs_modulus=youngs_modulus if real else youngs_modulus * stiffness_scale,
        poisson_ratio=poisson_ratio,
        name=name,
        fracture_energy=energy,
        rigid_handoff=True,
        **damping,
        **extra,
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


@_contact
def glass(*, real: bool = False, pattern: bool = True) -> Material:
    """Soda-lime (float, window) glass: brittle.

    Real values and typical ranges: density 2500 kg/m^3 (2440-2530); E = 70 GPa (68-74); nu = 0.22 (0.21-0.24);
    fracture toughness K_Ic 0.7-0.8 MPa m^0.5, so G = K_Ic^2 / E = 8 J/m^2 (7-10); tensile (bending) strength of
    annealed glass 30-100 MPa, set by surface flaws (Weibull modulus of the strength about 5-10); compressive strength
    about 1 GPa.

    Animation values (``real=False``): E = 7 MPa (1e-4 of the real one: 53 m/s wave speed, about 400 steps per frame
    at 24 fps and h = 1 cm); fracture energy 12.7 J/m^2 (the real 8 J/m^2 gives s_c = 5.6e-5 at h = 1 cm with the
    real E), the critical stretch 0.005 at the 2 cm reference spacing and 0.0071 at 1 cm: with a wave speed 100x
    lower a larger breaking strain keeps an impact's strain over the breaking strain (v / (c s_c)) within a factor of
    about 10 of its real value. 0.5 % stays invisible before the break.

    Break pattern (``pattern=True``, module docstring): strength field of Weibull modulus 6 (real glass: 5-10) and
    correlation length 5 cm (weak spots a shard apart on a figurine; resolved from a 2 cm spacing); without it the
    compressive bonus 0.25 (:data:`COMPRESSIVE_BONUS`: uniaxial compression alone breaks no bond).
    """
    return _brittle(
        "glass",
        2500.0,
        70.0e9,
        0.22,
        fracture_energy=8.0,
        critical_stretch=0.005,
        weibull_modulus=6.0,
        correlation_length=0.05,
        real=real,
        pattern=pattern,
    )


@_contact
def porcelain(*, real: bool = False, pattern: bool = True) -> Material:
    """Hard-paste porcelain (vitrified: cups, figurines, tiles): brittle, a little stiffer and lighter than glass.

    Real values and typical ranges: density 2400 kg/m^3 (2300-2500); E = 70 GPa (60-100); nu = 0.22 (0.2-0.25);
    fracture toughness 1-1.5 MPa m^0.5, G = 20 J/m^2 (15-30); bending strength 40-100 MPa (Weibull modulus 8-15).

    Animation values: E = 7 MPa (1e-4: 54 m/s wave speed); fracture energy 12.7 J/m^2, the critical stretch 0.005 at
    the 2 cm reference spacing, as glass (a real breaking strain of about 7e-4 in both). Break pattern: Weibull
    modulus 8, correlation length 5 cm.
    """
    return _brittle(
        "porcelain",
        2400.0,
        70.0e9,
        0.22,
        fracture_energy=20.0,
        critical_stretch=0.005,
        weibull_modulus=8.0,
        correlation_length=0.05,
        real=real,
        pattern=pattern,
    )


@_contact
def ceramic(*, real: bool = False, pattern: bool = True) -> Material:
    """Glazed stoneware and earthenware (mugs, plates, pots, vases): brittle, more porous and weaker than porcelain.

    Real values and typical ranges: density 2200 kg/m^3 (1900-2400); E = 40 GPa (20-70); nu = 0.2 (0.17-0.25);
    fracture toughness about 1 MPa m^0.5, G = 25 J/m^2 (10-40); bending strength 15-50 MPa (Weibull modulus 5-12).

    Animation values: E = 4 MPa (1e-4: 43 m/s wave speed, about 330 steps per frame at 24 fps and h = 1 cm);
    fracture energy 10.5 J/m^2, the critical stretch 0.006 at the 2 cm reference spacing (:data:`IMPACT_STRAIN_RATIO`:
    glass's impact strain over breaking strain at 6 m/s; the breaking stress, 24 kPa, stays below glass's 35 kPa) and
    0.0085 at 1 cm. Break pattern, tuned on the 30 cm sphere dropped at 6 m/s at the 2 cm preview spacing
    (tools/preview_final.py --seeds 5; docs/fracture.md, "Presets at preview and final spacing"): Weibull modulus 8
    (real 5-12; with the former 5, debris damping 1500 / s and cap 1.5 the scattered weak bonds crumbled: no seed of
    five met the shard figures), correlation length 5 cm, debris damping 1750 / s (3000 held the sphere together: 3-19 %
    broken out, 1-2 pieces over 5 %; 1000 shed 33-44 % of what broke out as dust) and the bonus cap 2 s_c (ceramics are
    5-10 times stronger in compression than in tension; 1.5 crushed the contact zone: 2 of 5 seeds met, with 2: 4).
    """
    return _brittle(
        "ceramic",
        2200.0,
        40.0e9,
        0.2,
        fracture_energy=25.0,
        critical_stretch=0.006,
        weibull_modulus=8.0,
        correlation_length=0.05,
        real=real,
        pattern=pattern,
        debris_damping=1750.0,
        bonus_cap=2.0,
    )


@_contact
def stone(*, real: bool = False, pattern: bool = True) -> Material:
    """Natural stone (granite, marble, sandstone; statues, blocks): brittle, strong in compression, weak in tension.

    Real values and typical ranges: density 2650 kg/m^3 (2300-2800); E = 50 GPa (10-70); nu = 0.25 (0.15-0.3);
    fracture energy 50 J/m^2 (20-150); tensile strength 5-15 MPa (Weibull modulus 5-20); compressive strength
    100-250 MPa.

    Animation values: E = 5 MPa (1e-4: 43 m/s wave speed, about 330 steps per frame at 24 fps and h = 1 cm);
    fracture energy 13.0 J/m^2, the critical stretch 0.006 at the 2 cm reference spacing (:data:`IMPACT_STRAIN_RATIO`:
    glass's impact strain over breaking strain at 6 m/s; the breaking stress, 30 kPa, stays below glass's 35 kPa, as
    the real one, 5-15 MPa, is below glass's) and 0.0085 at 1 cm. Break pattern, tuned as :func:`ceramic`'s: Weibull
    modulus 8 (real 5-20; the former 5 at the former settings met on no seed), correlation length 5 cm (grains and
    veins of a few centimetres), debris damping 1750 / s and the bonus cap 2.5 s_c (stone is about ten times
    stronger in compression than in tension; with 2 one seed of five met the shard figures, with 2.5 four).
    """
    return _brittle(
        "stone",
        2650.0,
        50.0e9,
        0.25,
        fracture_energy=50.0,
        critical_stretch=0.006,
        weibull_modulus=8.0,
        correlation_length=0.05,
        real=real,
        pattern=pattern,
        debris_damping=1750.0,
        bonus_cap=2.5,
    )


@_contact
def concrete(*, real: bool = False, pattern: bool = True) -> Material:
    """Normal-strength concrete (C30/37): brittle in tension, about ten times stronger in compression.

    Real values and typical ranges: density 2400 kg/m^3 (2200-2500); E = 30 GPa (25-40); nu = 0.2 (0.15-0.22);
    fracture energy G_F = 120 J/m^2 (70-150); tensile strength 2-4 MPa (Weibull modulus about 8-12); compressive
    strength 20-50 MPa (compressive_bonus 0.25). Its characteristic length E G_F / f_t^2 is about 0.4 m: the spacing at
    which the real G_F gives the real tensile strength is 11 cm (:func:`spacing_for_strength`), affordable for a wall
    or a slab.

    Animation values: E = 3 MPa (1e-4: 35 m/s wave speed, about 270 steps per frame at 24 fps and h = 1 cm);
    fracture energy 0.87 J/m^2, the critical stretch 0.002 at the 2 cm reference spacing (0.0028 at 1 cm):
    concrete's real breaking strain f_t / E = 1e-4 is the smallest of the presets and stays below glass's; raised 20x
    it keeps concrete the weaker, crumblier of the brittle presets at animation speeds.
    Break pattern: Weibull modulus 8 (real 8-12), correlation length 8 cm (the aggregate and its voids).
    """
    return _brittle(
        "concrete",
        2400.0,
        30.0e9,
        0.2,
        fracture_energy=120.0,
        critical_stretch=0.002,
        weibull_modulus=8.0,
        correlation_length=0.08,
        real=real,
        pattern=pattern,
        debris_damping=0.5 * DEBRIS_DAMPING,
    )


@_contact
def plaster(*, real: bool = False, pattern: bool = True) -> Material:
    """Set gypsum plaster (plaster of Paris: casts, mouldings, busts): light, brittle and weak; it breaks into chunks
    and crumbs.

    Real values and typical ranges: density 1100 kg/m^3 (1000-1400, dry); E = 12 GPa (5-15); nu = 0.2 (0.18-0.3);
    fracture energy 5 J/m^2 (2-10); tensile strength 1-3 MPa (Weibull modulus 3-8); compressive strength 5-20 MPa.

    Animation values: E = 2 MPa (:data:`PLASTER_STIFFNESS_SCALE`, 1/6000 of the real modulus where the other presets
    take 1e-4: 43 m/s wave speed, ceramic's; about 345 steps per frame at 24 fps and h = 1 cm); fracture energy 5.2
    J/m^2, the critical stretch 0.006 at the 2 cm reference spacing (:data:`IMPACT_STRAIN_RATIO`: glass's impact
    strain over breaking strain at 6 m/s; the breaking stress, 12 kPa, is the lowest of the presets, as the real 1-3
    MPa is) and 0.0085 at 1 cm. Break pattern, tuned as :func:`ceramic`'s: Weibull modulus 8 (the
    top of the real 3-8: with 3 the scattered weak bonds crumbled, no seed of five met the shard figures at any
    damping measured; with 6 none at the shipped damping and cap), correlation length 5 cm, debris damping 1000 / s
    (with m = 3: 3000 held the sphere whole, under 7 % broken out; 500 shed 42-70 % of what broke out as dust) and the
    bonus cap 2 s_c (set plaster is 5-7 times stronger in compression than in tension; 3 of 5 seeds met, 0 with 1.5;
    those figures are of the former 1.2 MPa).
    """
    return _brittle(
        "plaster",
        1100.0,
        12.0e9,
        0.2,
        fracture_energy=5.0,
        critical_stretch=0.006,
        weibull_modulus=8.0,
        correlation_length=0.05,
        real=real,
        pattern=pattern,
        debris_damping=1000.0,
        bonus_cap=2.0,
        stiffness_scale=PLASTER_STIFFNESS_SCALE,
    )


@_contact
def wood(*, real: bool = False, grain=(1.0, 0.0, 0.0), pattern: bool = True) -> Material:
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
    del pattern  # wood has no pattern settings: it splits along its grain (the module docstring)
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


@_contact
def clay(*, real: bool = False, pattern: bool = True) -> Material:
    """Plastic (modelling or pottery) clay: soft, flows at a low stress, keeps its new shape and tears only after very
    large strains.

    Real values and typical ranges: density 1800 kg/m^3 (1600-2000); E = 1 MPa (0.1-10, with the water content);
    nu = 0.45 (0.4-0.49: nearly incompressible); yield stress 20 kPa (von Mises; sqrt(3) times an undrained shear
    strength of 5-50 kPa); no hardening; a stretched clay strand tears at plastic strains of order 1
    (failure_plastic_strain 2).

    Clay is soft already (24 m/s wave speed, about 260 steps per frame at 24 fps and h = 1 cm; nu near 0.5 shortens
    the step), so the animation values equal the real ones.
    """
    del real, pattern  # the same values either way (see the docstring); no pattern settings (it tears)
    return Material(
        density=1800.0,
        youngs_modulus=1.0e6,
        poisson_ratio=0.45,
        yield_stress=20.0e3,
        hardening_modulus=0.0,
        failure_plastic_strain=2.0,
        name="clay",
    )


@_contact
def steel(*, real: bool = False, pattern: bool = True) -> Material:
    """Mild structural steel (S235-S355): ductile.

    Real values and typical ranges: density 7850 kg/m^3; E = 210 GPa (200-210); nu = 0.3; yield stress 250 MPa
    (235-355); linear hardening up to the tensile strength (400-550 MPa at 15-25 % strain), H about 1 GPa
    (0.5-2); the plastic strain in a neck reaches 0.3-1 before it tears (failure_plastic_strain 0.4).

    Animation values: E = 21 MPa (1e-4: 52 m/s wave speed, about 390 steps per frame at 24 fps and h = 1 cm); yield
    stress 210 kPa, a yield strain of 1 % instead of the real 0.12 %: a hit of a few m/s strains a body by v / c of
    several percent here, which would flatten a part with the real yield strain; 1 % keeps the spring-back invisible.
    Hardening H = 0.005 E (the real H / E); failure_plastic_strain 0.4 (real).
    """
    del pattern  # no pattern settings: steel tears by plasticity
    return _metal("steel", 7850.0, 210.0e9, 0.3, (250.0e6, 1.0e9), hardening_ratio=0.005, failure=0.4, real=real)


@_contact
def aluminium(*, real: bool = False, pattern: bool = True) -> Material:
    """Aluminium alloy 6061-T6: ductile, with less hardening and an earlier tear than mild steel.

    Real values and typical ranges: density 2700 kg/m^3; E = 69 GPa (68-71); nu = 0.33; yield stress 275 MPa
    (240-290); tensile strength 310 MPa at about 10 % strain, H about 0.5 GPa; elongation at break 8-17 %, plastic
    strain at tearing 0.2-0.5 (failure_plastic_strain 0.25).

    Animation values: E = 6.9 MPa (1e-4: 51 m/s wave speed, about 390 steps per frame at 24 fps and h = 1 cm);
    yield stress 69 kPa (1 % yield strain, for the reason given under :func:`steel`); H = 0.007 E (the real H / E);
    failure_plastic_strain 0.25 (real).
    """
    del pattern  # no pattern settings: aluminium tears by plasticity
    return _metal("aluminium", 2700.0, 69.0e9, 0.33, (275.0e6, 0.5e9), hardening_ratio=0.007, failure=0.25, real=real)


@_contact
def rubber(*, real: bool = False, pattern: bool = True) -> Material:
    """Soft natural rubber (balls, tyres' tread, props): elastic, nearly incompressible, never breaks.

    Real values and typical ranges: density 1100 kg/m^3 (920-1200); E = 1.5 MPa (1-5 at small strain); nu 0.499
    (0.49-0.5). Animation values equal the real ones (rubber is soft already) except nu = 0.45: nu -> 0.5 makes the
    bulk modulus and so the step's wave speed unbounded (nu = 0.45 gives about 360 steps per frame at 24 fps and
    h = 1 cm, nu = 0.49 five times as many). Bounces, it does not tear (no fracture settings).
    """
    del real, pattern  # the same values either way (see the docstring); rubber never breaks
    return Material(density=1100.0, youngs_modulus=1.5e6, poisson_ratio=0.45, name="rubber")


PRESETS = {
    "glass": glass,
    "porcelain": porcelain,
    "ceramic": ceramic,
    "stone": stone,
    "concrete": concrete,
    "plaster": plaster,
    "wood": wood,
    "clay": clay,
    "steel": steel,
    "aluminium": aluminium,
    "rubber": rubber,
}
BRITTLE = ("glass", "porcelain", "ceramic", "stone", "concrete", "plaster")  # the presets with a break pattern


def preset(name: str, *, real: bool = False, pattern: bool = True) -> Material:
    """The preset called ``name`` (one of :data:`PRESETS`)."""
    if name not in PRESETS:
        raise ParameterError("name", name, " or ".join(map(repr, PRESETS)))
    return PRESETS[name](real=real, pattern=pattern)


def spacing_for_strength(
    material: Material, tensile_strength: float, *, horizon_factor: float = DEFAULT_HORIZON_FACTOR
) -> float:
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
    "BRITTLE",
    "COMPRESSIVE_BONUS",
    "DEBRIS_DAMPING",
    "PLASTER_STIFFNESS_SCALE",
    "PRESETS",
    "REFERENCE_HORIZON_FACTOR",
    "REFERENCE_SPACING",
    "SAMPLING_JITTER",
    "SHARD_BONUS",
    "SHARD_BONUS_CAP",
    "STIFFNESS_SCALE",
    "TENSILE_STRENGTH",
    "aluminium",
    "ceramic",
    "clay",
    "concrete",
    "energy_for_stretch",
    "glass",
    "plaster",
    "porcelain",
    "preset",
    "rubber",
    "spacing_for_strength",
    "steel",
    "stone",
    "wood",
]
