"""Options as plain data with SI units.

Every option class is a frozen, keyword-only dataclass validated on construction: a bad
value raises :class:`OptionError` naming the field, the value and the allowed range. Scene
files (TOML) map onto these classes one to one (see ``taichi_frac.scenes``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import ClassVar


class OptionError(ValueError):
    """A value out of range or of the wrong type. The message names the key and the range."""


#: The largest finite 32-bit float: the simulation's fields are float32, so no option may
#: exceed it (a velocity of 1e39 m/s would be inf on the device) ...
FLOAT32_MAX = 3.4028234663852886e38
#: ... and the smallest normal one: a quantity that must be above 0 (a density) would
#: become 0 or lose its precision below it.
FLOAT32_TINY = 1.1754943508222875e-38


def _short(value) -> str:
    """``repr(value)``, shortened for a 400-digit integer."""
    text = repr(value)
    return text if len(text) <= 40 else f"{text[:12]}...({len(text)} digits)"


def check_range(owner: str, name: str, value, low=None, high=None, *, low_open=False, high_open=False):
    """Raise OptionError unless ``low <= value <= high`` (open ends where asked) and the
    value is a finite number a 32-bit float can hold."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise OptionError(f"{owner}.{name} must be a number, got {_short(value)}")
    if isinstance(value, float) and not math.isfinite(value):
        raise OptionError(f"{owner}.{name} must be finite, got {value!r}")
    if abs(value) > FLOAT32_MAX:  # (compared exactly: an int of 400 digits has no float)
        raise OptionError(f"{owner}.{name} = {_short(value)} is beyond the largest 32-bit float (3.4e38) the "
                          "simulation computes with")
    if low_open and low == 0 and 0 < value < FLOAT32_TINY:
        raise OptionError(f"{owner}.{name} = {value!r} is below the smallest 32-bit float (1.2e-38) the simulation "
                          "computes with")
    bad_low = low is not None and (value <= low if low_open else value < low)
    bad_high = high is not None and (value >= high if high_open else value > high)
    if bad_low or bad_high:
        lo = "-inf" if low is None else f"{low:g}"
        hi = "inf" if high is None else f"{high:g}"
        rng = ("(" if low_open else "[") + f"{lo}, {hi}" + (")" if high_open else "]")
        raise OptionError(f"{owner}.{name} = {_short(value)} is out of range: allowed {rng}")
    return value


@dataclass(frozen=True, kw_only=True)
class SurfaceLook:
    """How one kind of face renders, as UsdPreviewSurface inputs (any USD renderer reads them).

    Attributes:
        diffuse_color: (3,) linear RGB in [0, 1]: the base colour (the tint of a transparent one).
        roughness: [0, 1]; 0 is a mirror-like polish, 1 fully matte.
        metallic: [0, 1]; 1 for metals.
        opacity: [0, 1]; below 1 the surface is transmissive (glass), written with
            ``opacityThreshold`` 0 so renderers refract through it instead of cutting it out.
        ior: index of refraction [-], in [1, 3].
    """

    diffuse_color: tuple[float, float, float] = (0.8, 0.8, 0.8)
    roughness: float = 0.5
    metallic: float = 0.0
    opacity: float = 1.0
    ior: float = 1.5

    def __post_init__(self):
        if len(self.diffuse_color) != 3:
            raise OptionError(f"look.diffuse_color must have 3 components, got {self.diffuse_color!r}")
        for c in self.diffuse_color:
            check_range("look", "diffuse_color", c, 0.0, 1.0)
        check_range("look", "roughness", self.roughness, 0.0, 1.0)
        check_range("look", "metallic", self.metallic, 0.0, 1.0)
        check_range("look", "opacity", self.opacity, 0.0, 1.0)
        check_range("look", "ior", self.ior, 1.0, 3.0)


@dataclass(frozen=True, kw_only=True)
class MaterialLook:
    """A body's two looks: its original surface (``outer``) and its crack faces (``inner``)."""

    outer: SurfaceLook
    inner: SurfaceLook


# Looks written into the cache per body (render only: no effect on the physics). Artists
# replace them in their DCC; these make a first render read as the material it is.
LOOKS: dict[str, MaterialLook] = {
    # Clear glass: transmissive, smooth outside; crack faces slightly frosted.
    "glass": MaterialLook(
        outer=SurfaceLook(diffuse_color=(0.92, 0.97, 0.95), roughness=0.02, opacity=0.1, ior=1.5),
        inner=SurfaceLook(diffuse_color=(0.90, 0.96, 0.94), roughness=0.25, opacity=0.15, ior=1.5),
    ),
    # Glazed porcelain: glossy white glaze outside, matte unglazed biscuit in the cracks.
    "porcelain": MaterialLook(
        outer=SurfaceLook(diffuse_color=(0.90, 0.89, 0.85), roughness=0.08),
        inner=SurfaceLook(diffuse_color=(0.80, 0.76, 0.68), roughness=0.9),
    ),
    # Concrete: rough grey cast surface, slightly lighter and coarser fractured aggregate.
    "concrete": MaterialLook(
        outer=SurfaceLook(diffuse_color=(0.42, 0.41, 0.39), roughness=0.85),
        inner=SurfaceLook(diffuse_color=(0.55, 0.53, 0.49), roughness=0.95),
    ),
    # Brushed steel (projectiles, which do not break).
    "steel": MaterialLook(
        outer=SurfaceLook(diffuse_color=(0.60, 0.61, 0.62), roughness=0.3, metallic=1.0),
        inner=SurfaceLook(diffuse_color=(0.60, 0.61, 0.62), roughness=0.5, metallic=1.0),
    ),
    # Neutral plaster: light outside, warm brown cracks that stand out.
    "plaster": MaterialLook(
        outer=SurfaceLook(diffuse_color=(0.80, 0.78, 0.72), roughness=0.3),
        inner=SurfaceLook(diffuse_color=(0.62, 0.47, 0.35), roughness=0.85),
    ),
}


@dataclass(frozen=True, kw_only=True)
class Material:
    """An isotropic, linear-elastic brittle material.

    Attributes:
        name: label shown in reports.
        density: mass density [kg/m^3].
        young_modulus: Young's modulus E [Pa].
        poisson_ratio: Poisson's ratio nu [-], in [0, 0.5).
        tensile_strength: Rankine threshold on the largest principal stress [Pa].
        fracture_toughness: mode-I fracture toughness K_Ic [Pa m^0.5]: what new crack
            surface costs, as the fracture energy G_c = K_Ic^2 / E (:attr:`fracture_energy`).
            ``crack_count = "auto"`` weighs an impact's energy against it.
        look: how it renders, a name in ``LOOKS`` (glass, porcelain, concrete, steel,
            plaster); written into the cache, no effect on the physics.
    """

    name: str = "custom"
    density: float = 2400.0
    young_modulus: float = 70.0e9
    poisson_ratio: float = 0.2
    tensile_strength: float = 35.0e6
    fracture_toughness: float = 1.0e6
    look: str = "plaster"

    def __post_init__(self):
        if self.look not in LOOKS:
            raise OptionError(f"material.look = {self.look!r}: use one of {', '.join(LOOKS)}")
        check_range("material", "density", self.density, 0.0, None, low_open=True)
        check_range("material", "young_modulus", self.young_modulus, 0.0, None, low_open=True)
        check_range("material", "poisson_ratio", self.poisson_ratio, 0.0, 0.5, high_open=True)
        check_range("material", "tensile_strength", self.tensile_strength, 0.0, None, low_open=True)
        check_range("material", "fracture_toughness", self.fracture_toughness, 0.0, None, low_open=True)

    @property
    def fracture_energy(self) -> float:
        """G_c = K_Ic^2 / E [J/m^2]: the energy a unit area of new crack costs (Griffith,
        plane stress)."""
        return self.fracture_toughness**2 / self.young_modulus

    @property
    def shear_modulus(self) -> float:
        """G = E / (2 (1 + nu)) [Pa]."""
        return self.young_modulus / (2.0 * (1.0 + self.poisson_ratio))

    @property
    def lame_lambda(self) -> float:
        """lambda = E nu / ((1 + nu)(1 - 2 nu)) [Pa]."""
        nu = self.poisson_ratio
        return self.young_modulus * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


# Presets. Values are typical room-temperature figures; tensile strength of brittle solids
# scatters widely with flaws, so these are starting points an artist is expected to tune.
MATERIAL_PRESETS: dict[str, Material] = {
    # Annealed soda-lime glass: E 72 GPa, nu 0.23, 2500 kg/m^3 (Shelby, "Introduction to
    # Glass Science and Technology", 2nd ed., RSC 2005, ch. 8); practical tensile strength
    # of annealed float glass about 40-50 MPa (EN 572-1 gives 45 MPa characteristic bending).
    # K_Ic 0.75 MPa m^0.5 (Wiederhorn, J. Am. Ceram. Soc. 52(2), 1969: fracture surface
    # energy 3.9 J/m^2, so G_c = 2 gamma = 7.8 J/m^2).
    "soda_lime_glass": Material(
        name="soda_lime_glass", density=2500.0, young_modulus=72.0e9, poisson_ratio=0.23,
        tensile_strength=45.0e6, fracture_toughness=0.75e6, look="glass",
    ),
    # Porcelain (triaxial whiteware): E 60-100 GPa, nu about 0.2, 2300-2500 kg/m^3, flexural
    # strength 40-100 MPa, tensile lower, K_Ic 1.0-1.5 MPa m^0.5 (Carty & Senapati, J. Am.
    # Ceram. Soc. 81(1), 1998): 1.2 MPa m^0.5 here, G_c 21 J/m^2.
    "porcelain": Material(
        name="porcelain", density=2400.0, young_modulus=70.0e9, poisson_ratio=0.2,
        tensile_strength=35.0e6, fracture_toughness=1.2e6, look="porcelain",
    ),
    # Normal-strength concrete C30/37: Ecm 33 GPa, fctm 2.9 MPa (EN 1992-1-1, Table 3.1),
    # nu 0.2, about 2400 kg/m^3; fracture energy G_F = 73 f_cm^0.18 = 140 J/m^2 (fib Model
    # Code 2010, eq. 5.1-9, f_cm 38 MPa), i.e. K = sqrt(G_F E) = 2.15 MPa m^0.5.
    "concrete": Material(
        name="concrete", density=2400.0, young_modulus=33.0e9, poisson_ratio=0.2,
        tensile_strength=2.9e6, fracture_toughness=2.15e6, look="concrete",
    ),
}


def material_preset(name: str) -> Material:
    try:
        return MATERIAL_PRESETS[name]
    except KeyError:
        raise OptionError(
            f"unknown material preset {name!r}: use one of {', '.join(sorted(MATERIAL_PRESETS))} "
            "or give density, young_modulus, poisson_ratio and tensile_strength"
        ) from None


@dataclass(frozen=True, kw_only=True)
class ParticleOptions:
    """How a breakable solid is discretised (BRIEF.md steps 1-3).

    Attributes:
        target_particles: wanted number of physics particles (= tets); the mesher gets a
            maximum tet volume of mesh_volume / target_particles and lands near it.
        boundary_group_size: n, the number of adjacent surface particles merged into one
            boundary particle (paper: 4). 1 means single-scale (every surface particle
            collides on its own).
        surface_group_size: the n of a body that collides through its true surface
            (``simulation.surface_contact``), has at least 32 x n surface particles and
            keeps facets on 90 % of its patches so grouped (its pieces choose by their
            size the same way when it breaks): there the spheres only find which surface
            patches may touch, so fewer, larger spheres cost less while rest heights and
            landings stay exact (docs/guide/contact.md). Other bodies and pieces keep
            boundary_group_size. 0: boundary_group_size for all.
        keep_leftovers: surface particles that cannot be grouped become their own boundary
            particle (True) or are dropped (False).
        min_dihedral_deg: quality bound passed to the mesher [degrees].
    """

    target_particles: int = 5000
    boundary_group_size: int = 4
    surface_group_size: int = 12
    keep_leftovers: bool = True
    min_dihedral_deg: float = 10.0

    def __post_init__(self):
        check_range("particles", "target_particles", self.target_particles, 1, 5_000_000)
        check_range("particles", "boundary_group_size", self.boundary_group_size, 1, 64)
        check_range("particles", "surface_group_size", self.surface_group_size, 0, 64)
        check_range("particles", "min_dihedral_deg", self.min_dihedral_deg, 0.0, 30.0)


def option_names(cls) -> list[str]:
    """The field names of an option dataclass (for 'unknown key' messages)."""
    return [f.name for f in fields(cls)]


SMALL_FRAGMENT_POLICIES = ("merge", "debris", "drop")
# How an impact's stress is computed (docs/guide/stress-models.md): the paper's SPH gradient
# of the half-space displacement, its exact closed-form gradient, or linear elasticity on
# the body's own tets.
STRESS_MODELS = ("auto", "sph", "halfspace", "fem")
#: ``crack_count`` may be a number or this word: the count then follows each impact's
#: energy (``fracture/energy.py``).
AUTO = "auto"


@dataclass(frozen=True, kw_only=True)
class FractureOptions:
    """The artist's controls over how a breakable body cracks (BRIEF.md steps 5-10).

    Attributes:
        crack_count: n, the number of neighbour groups at an analysis point; each group's
            stress gives one crack direction. n = 1 is the single crack of the stress field
            alone. "auto" (the default): n follows each impact's energy against the fracture
            energy of a crack through the body (Griffith; ``fracture/energy.py``), so a
            harder hit makes more cracks.
        crack_scale: multiplies the automatic count (``crack_count = "auto"`` only) [-]:
            the artist's control over a physical count; the result is rounded, 1 to 64.
        seed: seed of every random choice (grouping start angle), so runs repeat exactly.
        impact_force_threshold: contacts whose force |impulse| / dt is below this are not
            analysed at all [N].
        crack_length: how far a crack runs from its analysis point [m]; None means as far as
            the stress along the crack plane exceeds the tensile strength.
        ring_crack_count: concentric cracks around each cracking analysis point, besides
            the n planar ones: spheres about the point whose radii split the crack length
            (or, with crack_length None, the contact's longest crack) into equal steps,
            cutting the wedges into rings, as a pane hit by a ball breaks. 0 (the default,
            and the paper's model) makes none.
        min_fragment_particles: a piece with fewer physics particles is "small".
        small_fragment_policy: what happens to small pieces: "merge" into the neighbouring
            fragment they share most faces with, kept as unbreakable "debris", or "drop".
        smoothing_length_factor: SPH smoothing length h = factor x mean particle spacing [-].
        corrected_gradient: use the Bonet-Lok corrected kernel gradient (recommended; the
            plain sum is biased near free surfaces).
        contact_radius: radius of the regularised load patch [m]; None = the contact
            particle's radius (a minimum distance of about one particle radius).
        refracture: fragments may break again on later impacts.
        stress_model: how an impact's stress is computed: "halfspace" (the exact stress of
            the regularised Boussinesq-Cerruti load, closed form: the paper's model), "sph"
            (the paper's SPH gradient of that displacement), "fem" (linear elasticity on the
            body's tets, the body's shape and so its bending included; a stiffness
            factorisation per body) or "auto" (the default): "fem" for slender bodies (plates,
            rods, rings, shells), which break by bending, where a half-space sees none,
            and "halfspace" for compact ones (``fracture/energy.py``).
        max_generations: how many times a piece of a piece may break again (>= 0).
        crack_roughness: amplitude [m] of the noise that roughens the rendered crack faces
            (the physics is untouched); 0, the default, leaves them flat, as glass breaks.
            Porcelain and stone look right at about a tenth of the particle spacing to one
            spacing (``taichi-frac info`` prints the spacing).
        crack_roughness_scale: wavelength [m] of that noise's coarsest octave; None = four
            particle spacings.
        crack_fit_rounds: how many times the rendered cracks are moved (planes shifted by at
            most half a particle spacing and, where shifts cannot do it, tilted by at most
            half a spacing more at their far end; ring cracks' spheres resized by at most half
            a spacing: within the tets' staircase along the crack) so that each piece's
            render surface holds its tets' volume; 0 leaves them where the analysis put them. Each round cuts the split's render solid again
            once or twice, and only when a piece of 100 tets or more is off by over 1 %. Where
            the whole planes cannot do it, up to as many rounds more shift the stretch of a
            plane between each pair of pieces on its own (at most half a spacing more; not
            for rough cracks).
        crack_fit_min_tets: the smallest piece (in tets) whose volume those stretches are
            fitted to. The default, 100, holds the larger pieces within 2 % of their tets'
            volume; lower it (to about 30) for close-ups where mid-sized pieces show, at
            several times the cache writing's cost per split
            (docs/guide/fragment-geometry.md). The whole planes are always fitted to pieces
            of 100 tets or more: a few small pieces where cracks meet must not pull a plane
            that many larger pieces lie on.
    """

    crack_count: int | str = AUTO
    crack_scale: float = 1.0
    seed: int = 0
    impact_force_threshold: float = 0.0
    crack_length: float | None = None
    ring_crack_count: int = 0
    min_fragment_particles: int = 8
    small_fragment_policy: str = "merge"
    smoothing_length_factor: float = 2.0
    corrected_gradient: bool = True
    contact_radius: float | None = None
    refracture: bool = True
    max_generations: int = 3
    crack_roughness: float = 0.0
    crack_roughness_scale: float | None = None
    crack_fit_rounds: int = 3
    crack_fit_min_tets: int = 100
    stress_model: str = AUTO

    def __post_init__(self):
        if self.crack_count != AUTO:
            if isinstance(self.crack_count, str):
                raise OptionError(f"fracture.crack_count = {self.crack_count!r}: use a number of cracks (1-64) or "
                                  f"{AUTO!r}")
            check_range("fracture", "crack_count", self.crack_count, 1, 64)
        check_range("fracture", "crack_scale", self.crack_scale, 0.0, 64.0, low_open=True)
        check_range("fracture", "seed", self.seed, 0, 2**31 - 1)
        check_range("fracture", "impact_force_threshold", self.impact_force_threshold, 0.0, None)
        if self.crack_length is not None:
            check_range("fracture", "crack_length", self.crack_length, 0.0, None, low_open=True)
        check_range("fracture", "ring_crack_count", self.ring_crack_count, 0, 64)
        check_range("fracture", "min_fragment_particles", self.min_fragment_particles, 1, 1_000_000)
        if self.small_fragment_policy not in SMALL_FRAGMENT_POLICIES:
            raise OptionError(
                f"fracture.small_fragment_policy = {self.small_fragment_policy!r}: use one of "
                + ", ".join(SMALL_FRAGMENT_POLICIES)
            )
        check_range("fracture", "smoothing_length_factor", self.smoothing_length_factor, 1.0, 5.0)
        if self.contact_radius is not None:
            check_range("fracture", "contact_radius", self.contact_radius, 0.0, None, low_open=True)
        check_range("fracture", "max_generations", self.max_generations, 0, 100)
        check_range("fracture", "crack_roughness", self.crack_roughness, 0.0, None)
        if self.crack_roughness_scale is not None:
            check_range("fracture", "crack_roughness_scale", self.crack_roughness_scale, 0.0, None, low_open=True)
        check_range("fracture", "crack_fit_rounds", self.crack_fit_rounds, 0, 10)
        check_range("fracture", "crack_fit_min_tets", self.crack_fit_min_tets, 1, 1_000_000)
        if self.stress_model not in STRESS_MODELS:
            raise OptionError(f"fracture.stress_model = {self.stress_model!r}: use one of " + ", ".join(STRESS_MODELS))


@dataclass(frozen=True, kw_only=True)
class RigidBodyOptions:
    """The rigid-body solver settings a scene's ``[simulation]`` table and the World's
    ``DynamicsOptions`` share (each class adds its own; each field is defined and checked
    here once). Error messages name the subclass's table (``simulation.`` / ``dynamics.``).

    Attributes:
        solver_iterations: sequential-impulse sweeps over the contacts per substep.
        gravity: (3,) [m/s^2], world Z up.
        max_substeps: cap on substeps per frame after the substep refinement
            (``substep_motion_fraction``); when hit, the World's
            ``stats.substep_limit_hits`` counts it.
        substep_motion_fraction: a substep is shortened until no body that may touch
            something this frame moves further than this fraction of its mean collision
            particle radius in one substep [-]. Tunnelling is prevented by speculative
            contacts whatever the substep; this bounds how far a contact is extrapolated.
        single_scale: collide with every surface particle instead of the boundary layer
            (the paper's "single-scale" column; for measurement). For the World: the
            default of ``add_body(single_scale=None)``.
        surface_contact: bodies added while this is on (the default) collide through
            their true surface: the collision spheres only find the pairs of surface
            patches that may touch, and each contact's point, normal and depth come from
            the patches' triangles (``collision/surface.py``), so a body rests on its
            surface within 0.5 mm, not on its spheres (docs/guide/contact.md). It costs
            about 1.1-1.25 times the sphere contacts' time a frame in the shipped scenes,
            and a process's first frame about 0.7 s more (it loads the larger collision
            kernel). False (``surface_contact = false`` in a scene, ``--set
            simulation.surface_contact=false``): sphere contacts, the paper's (the spheres
            stand proud of a flat or gently curved surface by up to R - sqrt(R^2 - rho^2),
            a few millimetres for a ring). Read when a body is added.
        sleep_linear_speed: a body whose every point (|v| + |w| x bounding radius) is slower
            than this ... [m/s]
        sleep_angular_speed: ... and that turns slower than this [rad/s] ...
        sleep_time: ... for this long goes to sleep [s] (velocity zeroed, no integration)
            until woken, together with the bodies it touches (when they have all been
            slow that long). A substep under three times those speeds takes four substeps
            off that time, a faster one all of it, unless every point of the body is still
            within a tenth of its mean collision-sphere radius of where it was (a body
            jittering in place counts as slow); a sleeping body is woken by the touch of
            a body moving faster than three times sleep_linear_speed.
        rolling_resistance: lever arm of the rolling resistance, as a fraction of the
            contact's (smaller) collision-sphere radius [-]: a contact carrying normal
            impulse j resists the bodies' relative turning with an angular impulse of at
            most rolling_resistance x radius x j. It stands for the flat faces a body's
            spheres round off: without it a chip of two spheres rolls on the floor like a
            dumbbell for seconds, and each touch wakes the pile it rolls into. A body much
            larger than its spheres (a whole ring, rolling resistance coefficient
            ~rolling_resistance x sphere radius / body radius) is barely slowed. 0: off.
    """

    #: The table its error messages name.
    OWNER: ClassVar[str] = "solver"

    solver_iterations: int = 10
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    max_substeps: int = 200
    substep_motion_fraction: float = 1.0
    single_scale: bool = False
    surface_contact: bool = True
    sleep_linear_speed: float = 0.01
    sleep_angular_speed: float = 1.0
    sleep_time: float = 0.5
    rolling_resistance: float = 0.1

    def __post_init__(self):
        owner = self.OWNER
        check_range(owner, "solver_iterations", self.solver_iterations, 1, 1000)
        if isinstance(self.gravity, (str, bytes)) or not hasattr(self.gravity, "__len__") or len(self.gravity) != 3:
            raise OptionError(f"{owner}.gravity must have 3 components, got {self.gravity!r}")
        for g in self.gravity:
            check_range(owner, "gravity", g, -1000.0, 1000.0)
        check_range(owner, "max_substeps", self.max_substeps, 1, 1_000_000)
        check_range(owner, "substep_motion_fraction", self.substep_motion_fraction, 0.0, 10.0, low_open=True)
        check_range(owner, "sleep_linear_speed", self.sleep_linear_speed, 0.0, None)
        check_range(owner, "sleep_angular_speed", self.sleep_angular_speed, 0.0, None)
        check_range(owner, "sleep_time", self.sleep_time, 0.0, None)
        check_range(owner, "rolling_resistance", self.rolling_resistance, 0.0, 10.0)


@dataclass(frozen=True, kw_only=True)
class FrameTiming:
    """The output frames and the substeps of each (checked by :class:`SimulationOptions`,
    which holds them first, so a scene's ``[simulation]`` table lists them first).

    Attributes:
        fps: output frames per second [1/s].
        duration: simulated time [s].
        substeps: solver substeps per frame while any body may touch something (a frame of
            free flight takes one exact step); ``max_substeps`` must be at least this, and
            at most 100,000.
    """

    fps: float = 50.0
    duration: float = 3.0
    substeps: int = 10

    @property
    def frame_dt(self) -> float:
        return 1.0 / self.fps

    @property
    def frame_count(self) -> int:
        return int(round(self.duration * self.fps))


@dataclass(frozen=True, kw_only=True)
class SimulationOptions(RigidBodyOptions, FrameTiming):
    """Time stepping and the rigid-body solver: a scene's ``[simulation]`` table
    (:class:`FrameTiming`'s and :class:`RigidBodyOptions`' fields, then these).

    Attributes:
        resimulate_fractures: fracture inside the frame: each substep's impacts are
            analysed as they happen, and a substep in which a body breaks is simulated
            again with the pieces in the body's place, so the impact that broke it meets
            the pieces (a projectile goes on through what it breaks) instead of the whole
            body, which the rigid solver has already bounced. Costs a device checkpoint per substep
            and a second run of each such substep. Off: the frame's impacts are analysed
            after it.
        arch: Taichi backend: cpu, cuda, vulkan, metal or gpu.
    """

    OWNER: ClassVar[str] = "simulation"

    resimulate_fractures: bool = False
    arch: str = "cpu"

    def __post_init__(self):
        check_range("simulation", "fps", self.fps, 1.0, 10_000.0)
        check_range("simulation", "duration", self.duration, 0.0, 3600.0, low_open=True)
        check_range("simulation", "substeps", self.substeps, 1, 10_000)
        super().__post_init__()
        check_range("simulation", "max_substeps", self.max_substeps, self.substeps, 100_000)
        if self.arch not in ("cpu", "cuda", "vulkan", "metal", "gpu"):
            raise OptionError(f"simulation.arch = {self.arch!r}: use cpu, cuda, vulkan, metal or gpu")
        if self.frame_count < 1:
            raise OptionError(f"simulation.duration = {self.duration!r} s at fps = {self.fps!r} is "
                              f"{self.duration * self.fps:.3g} frames, which rounds to none: make the duration at "
                              f"least one frame ({1.0 / self.fps:.3g} s)")
