"""A scene as plain data: breakable and rigid objects, static colliders, simulation and
output settings. The same structure comes from a TOML file (``load_scene``) or is written
directly in Python:

    from taichi_frac.scenes import Scene, SceneObject, Collider
    scene = Scene(
        name="drop",
        objects=[SceneObject(name="ring", primitive="torus", material="porcelain",
                             position=(0, 0, 1.0), euler_deg=(90, 0, 0))],
        colliders=[Collider.ground()],
    )

Every field maps one to one onto a TOML key of the same name (docs/reference/scene-file.md).
World frame: Z up, metres, seconds; quaternions (w, x, y, z).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..geometry.meshio_in import SIZE_RANGE, UNITS
from ..geometry.primitives import parse_primitive_spec
from ..kinematics.quaternion import quaternion_multiply
from ..options import (
    FractureOptions,
    Material,
    OptionError,
    ParticleOptions,
    SimulationOptions,
    check_range,
    material_preset,
)


def euler_deg_to_quaternion(euler_deg) -> tuple[float, float, float, float]:
    """Extrinsic X, then Y, then Z rotations [degrees] (Blender's "XYZ Euler") -> (w,x,y,z).

    R = Rz(c) Ry(b) Rx(a), i.e. q = qz * qy * qx.
    """
    a, b, c = (math.radians(float(x)) / 2.0 for x in euler_deg)
    qx = np.array([math.cos(a), math.sin(a), 0.0, 0.0])
    qy = np.array([math.cos(b), 0.0, math.sin(b), 0.0])
    qz = np.array([math.cos(c), 0.0, 0.0, math.sin(c)])
    return tuple(float(v) for v in quaternion_multiply(qz, quaternion_multiply(qy, qx)))


#: Largest coordinate [m] of a position, ground height or box: float32 positions are
#: spaced 8 mm apart there, already coarser than the particles of a small object.
MAX_COORDINATE = 1.0e5
#: Largest initial speed [m/s] and spin [rad/s]: far beyond any projectile; beyond them a
#: substep moves a body kilometres and the contact stage cannot follow.
MAX_SPEED = 1.0e4
MAX_SPIN = 1.0e5


def _vec3(owner, name, value, limit: float | None = None, unit: str = "") -> tuple[float, float, float]:
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 3:
        raise OptionError(f"{owner}.{name} must be a list of 3 numbers, got {value!r}")
    for v in value:
        check_range(owner, name, v)
    vec = tuple(float(v) for v in value)
    if limit is not None and float(np.linalg.norm(vec)) > limit:
        raise OptionError(f"{owner}.{name} = {list(vec)!r} is {float(np.linalg.norm(vec)):.3g} {unit} long: beyond "
                          f"the {limit:g} {unit} the simulation represents well")
    return vec


def _unit_quaternion(owner, value) -> tuple[float, float, float, float]:
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 4:
        raise OptionError(f"{owner}.orientation must be a quaternion [w, x, y, z] (4 numbers), got {value!r}")
    for v in value:
        check_range(owner, "orientation", v)
    q = np.asarray(value, dtype=np.float64)
    largest = float(np.abs(q).max())
    if largest < 1e-30:
        raise OptionError(f"{owner}.orientation = {list(value)!r} has zero length: use [1, 0, 0, 0] for no rotation")
    q = q / largest  # (first: the norm of [1e200, 1e200, 0, 0] overflows)
    return tuple(float(v) for v in q / np.linalg.norm(q))


def check_primitive_size(spec: str, factor: float, owner: str | None = None) -> None:
    """Raise OptionError unless each length of primitive ``spec`` [m], times ``factor``
    (the object's scale and units), is a size a solid may have (``meshio_in.SIZE_RANGE``)."""
    name, params = parse_primitive_spec(spec)
    low, high = SIZE_RANGE
    for key, value in params.items():
        size = value * factor
        if not (math.isfinite(size) and low <= size <= high):
            where = f"{owner}.primitive = {spec!r}" if owner else f"primitive {spec!r}"
            raise OptionError(f"{where}: {key} = {value:g} m (x scale {factor:g}) is outside the sizes a solid may "
                              f"have, {low:g} to {high:g} m")


@dataclass(frozen=True, kw_only=True)
class SceneObject:
    """One solid in the scene.

    Attributes:
        name: unique label (USD prim name of its fragments).
        mesh: surface or tet-mesh file (relative paths are relative to the scene file).
        primitive: or a primitive spec, e.g. "torus" or "box:x=1,y=1,z=0.01" (metres).
        scale: multiplies the mesh's coordinates [-].
        units: unit of the mesh file's coordinates: "m", "cm" or "mm".
        repair: repair the mesh before meshing (holes, flips, self-intersections): a mesh
            that is not a clean solid becomes the solid of its generalized winding number.
        thickness: [m] an open sheet (a pane, a sign, a leaf) becomes a closed shell this
            thick about its surface; None: a mesh with no volume is an error.
        up_axis: "z" (the file as it is) or "y" (a Y-up OBJ/PLY/STL/OFF file, turned Z up);
            glTF/GLB files are always Y-up by their specification and turned Z up.
        material: a preset name ("porcelain", "soda_lime_glass", "concrete") or a Material.
        breakable: False for rigid props (a projectile); they never fracture.
        position: (3,) [m] world position of the body-frame origin = the centre of mass.
        orientation: (w,x,y,z) unit quaternion, body -> world. Normalised on construction.
        euler_deg: alternative to orientation: (3,) extrinsic XYZ angles [degrees].
        linear_velocity: (3,) [m/s] initial velocity of the centre of mass.
        angular_velocity: (3,) [rad/s] initial angular velocity, world frame.
        friction: Coulomb friction coefficient [-], >= 0.
        restitution: coefficient of restitution [-], in [0, 1].
        particles: discretisation (ParticleOptions).
        fracture: crack controls (FractureOptions).

    Note on position: the source mesh's origin is generally not its centre of mass; the
    body is placed so its centre of mass is at ``position`` (the body frame is COM-centred).
    """

    name: str
    mesh: str | None = None
    primitive: str | None = None
    scale: float = 1.0
    units: str = "m"
    repair: bool = False
    thickness: float | None = None
    up_axis: str = "z"
    material: Material | str = "porcelain"
    breakable: bool = True
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation: tuple[float, float, float, float] | None = None
    euler_deg: tuple[float, float, float] | None = None
    linear_velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    angular_velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    friction: float = 0.5
    restitution: float = 0.2
    particles: ParticleOptions = field(default_factory=ParticleOptions)
    fracture: FractureOptions = field(default_factory=FractureOptions)

    def __post_init__(self):
        owner = f"objects[{self.name!r}]"
        if not isinstance(self.name, str) or not self.name:
            raise OptionError(f"every object needs a non-empty name, got {self.name!r}")
        if (self.mesh is None) == (self.primitive is None):
            raise OptionError(f"{owner}: give exactly one of mesh = \"file\" or primitive = \"torus\"")
        if self.primitive is not None and parse_primitive_spec(self.primitive) is None:
            raise OptionError(f"{owner}.primitive = {self.primitive!r}: use torus, ring, box, sphere or cylinder, "
                              "optionally with parameters, e.g. \"torus:major=0.1,minor=0.025\"")
        check_range(owner, "scale", self.scale, 0.0, None, low_open=True)
        if self.units not in UNITS:
            raise OptionError(f"{owner}.units = {self.units!r}: use one of {', '.join(UNITS)}")
        if self.thickness is not None:
            check_range(owner, "thickness", self.thickness, 0.0, None, low_open=True)
            if self.primitive is not None:
                raise OptionError(f"{owner}.thickness applies to a mesh (a sheet); a primitive is a solid already")
        if self.up_axis not in ("z", "y"):
            raise OptionError(f"{owner}.up_axis = {self.up_axis!r}: use \"z\" (the file as it is) or \"y\" "
                              "(a Y-up file, turned Z up)")
        if self.primitive is not None:
            check_primitive_size(self.primitive, float(self.scale) * UNITS[self.units], owner)
        if isinstance(self.material, str):
            object.__setattr__(self, "material", material_preset(self.material))
        elif not isinstance(self.material, Material):
            raise OptionError(f"{owner}.material must be a preset name or a Material, got {self.material!r}")
        object.__setattr__(self, "position", _vec3(owner, "position", self.position, MAX_COORDINATE, "m"))
        object.__setattr__(self, "linear_velocity",
                           _vec3(owner, "linear_velocity", self.linear_velocity, MAX_SPEED, "m/s"))
        object.__setattr__(self, "angular_velocity",
                           _vec3(owner, "angular_velocity", self.angular_velocity, MAX_SPIN, "rad/s"))
        if self.orientation is not None and self.euler_deg is not None:
            # dataclasses.replace() passes both back: accept them when they agree.
            from_euler = np.array(euler_deg_to_quaternion(_vec3(owner, "euler_deg", self.euler_deg)))
            given = np.array(_unit_quaternion(owner, self.orientation))
            if min(np.abs(from_euler - given).max(), np.abs(from_euler + given).max()) > 1e-9:
                raise OptionError(f"{owner}: give orientation (quaternion w,x,y,z) or euler_deg, not both")
        if self.euler_deg is not None:
            euler = _vec3(owner, "euler_deg", self.euler_deg)
            object.__setattr__(self, "euler_deg", euler)
            object.__setattr__(self, "orientation", euler_deg_to_quaternion(euler))
        else:
            object.__setattr__(self, "orientation", _unit_quaternion(owner, self.orientation or (1.0, 0.0, 0.0, 0.0)))
        check_range(owner, "friction", self.friction, 0.0, 10.0)
        check_range(owner, "restitution", self.restitution, 0.0, 1.0)
        for key, cls in (("particles", ParticleOptions), ("fracture", FractureOptions)):
            if not isinstance(getattr(self, key), cls):
                raise OptionError(f"{owner}.{key} must be a {cls.__name__}")

    @property
    def source(self) -> str:
        """What ``geometry.prepare.prepare_body`` takes: the mesh path or the primitive spec."""
        return self.mesh if self.mesh is not None else self.primitive

    def prepare(self, *, use_cache: bool = True, backend: str = "tetgen", surface_contact: bool = False):
        """Mesh and model this object: ``(BodyModel, PrepareReport)`` (see prepare_body;
        ``surface_contact``: the scene's ``simulation.surface_contact``)."""
        from ..geometry.prepare import prepare_body

        return prepare_body(self.source, scale=self.scale, units=self.units, material=self.material,
                            particles=self.particles, repair=self.repair, backend=backend, use_cache=use_cache,
                            surface_contact=surface_contact, thickness=self.thickness, up_axis=self.up_axis)


COLLIDER_TYPES = ("ground", "box")


@dataclass(frozen=True, kw_only=True)
class Collider:
    """A static collider: an infinite ground plane z = height, or an oriented box.

    Attributes:
        type: "ground" or "box".
        height: ground plane height [m] (ground only).
        center: (3,) [m] box centre (box only).
        half_extents: (3,) [m] box half side lengths, > 0 (box only).
        orientation: (w,x,y,z) unit quaternion, the box's rotation (box only).
        euler_deg: alternative to orientation: (3,) extrinsic XYZ angles [degrees].
        friction: Coulomb friction coefficient [-] of contacts with it.
        restitution: coefficient of restitution [-] of contacts with it.
    """

    type: str = "ground"
    height: float = 0.0
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    half_extents: tuple[float, float, float] = (0.5, 0.5, 0.5)
    orientation: tuple[float, float, float, float] | None = None
    euler_deg: tuple[float, float, float] | None = None
    friction: float = 0.5
    restitution: float = 0.2

    def __post_init__(self):
        owner = f"colliders[{self.type!r}]"
        if self.type not in COLLIDER_TYPES:
            raise OptionError(f"collider type = {self.type!r}: use one of {', '.join(COLLIDER_TYPES)}")
        check_range(owner, "height", self.height, -MAX_COORDINATE, MAX_COORDINATE)
        object.__setattr__(self, "center", _vec3(owner, "center", self.center, MAX_COORDINATE, "m"))
        half = _vec3(owner, "half_extents", self.half_extents, MAX_COORDINATE, "m")
        for h in half:
            check_range(owner, "half_extents", h, 0.0, None, low_open=True)
        object.__setattr__(self, "half_extents", half)
        if self.orientation is not None and self.euler_deg is not None:
            raise OptionError(f"{owner}: give orientation or euler_deg, not both")
        if self.euler_deg is not None:
            object.__setattr__(self, "orientation", euler_deg_to_quaternion(_vec3(owner, "euler_deg", self.euler_deg)))
        else:
            object.__setattr__(self, "orientation", _unit_quaternion(owner, self.orientation or (1.0, 0.0, 0.0, 0.0)))
        check_range(owner, "friction", self.friction, 0.0, 10.0)
        check_range(owner, "restitution", self.restitution, 0.0, 1.0)

    @classmethod
    def ground(cls, height: float = 0.0, **kwargs) -> "Collider":
        return cls(type="ground", height=height, **kwargs)

    @classmethod
    def box(cls, center, half_extents, **kwargs) -> "Collider":
        return cls(type="box", center=center, half_extents=half_extents, **kwargs)


@dataclass(frozen=True, kw_only=True)
class OutputSettings:
    """Where and how the cache is written.

    Attributes:
        path: the .usdc (or .usda) file; relative paths are relative to the scene file.
        checkpoint_every: 0 writes the file only at the end (and on Ctrl-C); otherwise it is
            also written while the run goes on, so a crash or a kill loses little:
        checkpoint_seconds: right after the first frame, then whenever this many seconds of
            wall time have passed since the last write, however slow the frames [s]. A
            checkpoint rewrites the whole file (~30 ms for the glass walls), which a fast run
            would otherwise pay every few frames. 0: every ``checkpoint_every`` frames.
    """

    path: str = "out.usdc"
    checkpoint_every: int = 25
    checkpoint_seconds: float = 10.0

    def __post_init__(self):
        if not isinstance(self.path, str) or not self.path.lower().endswith((".usdc", ".usda", ".usd")):
            raise OptionError(f"output.path = {self.path!r}: must be a .usdc, .usda or .usd file name")
        check_range("output", "checkpoint_every", self.checkpoint_every, 0, 1_000_000)
        check_range("output", "checkpoint_seconds", self.checkpoint_seconds, 0.0, None)


@dataclass(frozen=True, kw_only=True)
class Scene:
    """A whole scene. ``source_path`` is the TOML file it came from (None from Python)."""

    name: str = "scene"
    objects: list[SceneObject] = field(default_factory=list)
    colliders: list[Collider] = field(default_factory=list)
    simulation: SimulationOptions = field(default_factory=SimulationOptions)
    output: OutputSettings = field(default_factory=OutputSettings)
    source_path: Path | None = None

    def __post_init__(self):
        object.__setattr__(self, "objects", list(self.objects))
        object.__setattr__(self, "colliders", list(self.colliders))
        if not self.objects:
            raise OptionError(f"scene {self.name!r} has no objects: add at least one [[objects]] table")
        names = [o.name for o in self.objects]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise OptionError(f"scene {self.name!r}: object names must be unique, repeated: {', '.join(dupes)}")
        grounds = [(i, c.height) for i, c in enumerate(self.colliders) if c.type == "ground"]
        for obj in self.objects:
            for i, height in grounds:
                if obj.position[2] < height:
                    raise OptionError(f"objects[{obj.name!r}].position z = {obj.position[2]:g} m is below the ground "
                                      f"colliders[{i}] at height {height:g} m, which would throw it out: raise the "
                                      "object or lower the ground")

    @property
    def output_path(self) -> Path:
        """The output file, resolved against the scene file's folder."""
        p = Path(self.output.path)
        if not p.is_absolute() and self.source_path is not None:
            p = Path(self.source_path).parent / p
        return p

    @property
    def breakable_objects(self) -> list[SceneObject]:
        return [o for o in self.objects if o.breakable]
