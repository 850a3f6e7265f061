"""The USD fracture cache: one Mesh per fragment in its body frame, posed per frame.

The stage lives in memory and is written to disk every ``checkpoint_every`` frames and on
``close()``: exported to a temporary file beside the target, flushed to disk, then moved over
it with ``os.replace`` (atomic on POSIX and Windows). A run that crashes or is killed leaves the
last checkpoint: a complete, valid cache of every frame up to ``lastFrame`` in its layer data,
with ``complete`` False. Rewriting the whole layer costs O(frames so far) per checkpoint; a
cache is a few MB at most, so that is milliseconds, and it keeps one file that any USD reader
opens (no sublayers to stitch).

Names, units and the layout are in ``schema.py``.
"""

from __future__ import annotations

import os
import time as _time
from pathlib import Path

import numpy as np

from .. import __version__
from ..interrupts import deferred
from ..kinematics.quaternion import quaternion_multiply
from ..options import LOOKS, MaterialLook, SurfaceLook
from . import schema

with deferred():  # (USD's loader prints a Ctrl-C during its import as a traceback)
    from pxr import Gf, Sdf, Tf, Usd, UsdGeom, Vt

# Body-frame data is Z-up; a Y-up stage turns the world by -90 degrees about X:
# (x, y, z) -> (x, z, -y). As a quaternion (w, x, y, z):
_Z_TO_Y_UP = np.array([np.sqrt(0.5), -np.sqrt(0.5), 0.0, 0.0])
_Z_TO_Y_UP_MATRIX = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

# The look of a body given none.
_DEFAULT_LOOK = LOOKS["plaster"]


def _corner_shading(tri: np.ndarray, inner: np.ndarray, corner_normals, corner_uvs, shade_inner: bool):
    """Per-corner normals (3F,3) and UVs (3F,2) of the triangles ``tri`` (F,3,3): those given
    (``None``: none) where they are finite, on outer faces (and inner ones with
    ``shade_inner``); elsewhere the face's flat normal and a box projection of the position."""
    face_normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    face_normal /= np.maximum(np.linalg.norm(face_normal, axis=1, keepdims=True), 1e-300)
    flat = np.repeat(face_normal, 3, axis=0)
    corner_inner = np.repeat(inner, 3) & (not shade_inner)
    if corner_normals is None:
        corner_normals = flat
    else:
        missing = corner_inner | ~np.all(np.isfinite(corner_normals), axis=1)
        corner_normals = np.where(missing[:, None], flat, corner_normals)
        corner_normals /= np.maximum(np.linalg.norm(corner_normals, axis=1, keepdims=True), 1e-300)
    projected = _box_projection(tri.reshape(-1, 3), flat)
    if corner_uvs is None:
        corner_uvs = projected
    else:
        missing = corner_inner | ~np.all(np.isfinite(corner_uvs), axis=1)
        corner_uvs = np.where(missing[:, None], projected, corner_uvs)
    return corner_normals, corner_uvs


def _per_corner(values: np.ndarray | None, faces: np.ndarray, vertex_count: int, width: int, what: str):
    """(F*3, width) per face corner from per-vertex (V, width) or per-corner (F, 3, width) data;
    None when absent. NaN rows mean 'no value for this corner'."""
    if values is None:
        return None
    values = np.asarray(values, dtype=np.float64)
    if values.shape == (vertex_count, width):
        return values[faces.reshape(-1)]
    if values.shape == (len(faces), 3, width):
        return values.reshape(-1, width)
    raise ValueError(
        f"{what} must be per vertex ({vertex_count}, {width}) or per face corner "
        f"({len(faces)}, 3, {width}), got {values.shape}"
    )


def _impact_fields(impact):
    """(point (3,), force (3,)) from a mapping with 'point'/'force', an object with those
    attributes, or a (point, force) pair."""
    if isinstance(impact, dict):
        point, force = impact["point"], impact["force"]
    elif hasattr(impact, "point") and hasattr(impact, "force"):
        point, force = impact.point, impact.force
    else:
        point, force = impact
    point, force = np.asarray(point, dtype=np.float64), np.asarray(force, dtype=np.float64)
    if point.shape != (3,) or force.shape != (3,):
        raise ValueError(f"impact point and force must be 3-vectors, got {point.shape} and {force.shape}")
    return point, force


class _Fragment:
    __slots__ = ("prim_path", "translate", "orient", "visibility", "death", "birth", "pose", "held")

    def __init__(self, prim_path, translate, orient, visibility, birth):
        self.prim_path = prim_path
        self.translate = translate  # Sdf.Path of the translate op's attribute
        self.orient = orient  # Sdf.Path of the orient op's attribute
        self.visibility = visibility  # Sdf.Path of its visibility attribute
        self.birth = birth
        self.death = None
        self.pose = None  # (position, quaternion) of the last pose written, stage frame
        self.held = None  # the last frame that repeated it without a sample


def _prim_spec(layer, path, type_name: str):
    """A ``def`` prim spec of ``type_name`` at ``path`` (its parent already defined)."""
    return Sdf.PrimSpec(layer.GetPrimAtPath(path.GetParentPath()), path.name, Sdf.SpecifierDef, type_name)


def _attribute(prim_spec, name: str, type_name, value, *, uniform: bool = False, custom: bool = False,
               interpolation: str | None = None):
    """An attribute spec with its default ``value`` (None: none), as the schema API writes it."""
    variability = Sdf.VariabilityUniform if uniform else Sdf.VariabilityVarying
    spec = Sdf.AttributeSpec(prim_spec, name, type_name, variability, custom)
    if value is not None:
        spec.default = value
    if interpolation is not None:
        spec.SetInfo("interpolation", interpolation)
    return spec


def _apply_binding_api(prim_spec) -> None:
    """``prepend apiSchemas = ["MaterialBindingAPI"]``, what MaterialBindingAPI.Apply adds."""
    prim_spec.SetInfo("apiSchemas", Sdf.TokenListOp.Create(prependedItems=["MaterialBindingAPI"]))


class CacheWriter:
    """Writes a taichi-frac USD cache (``.usdc``, ``.usda`` or ``.usd``).

    Args:
        path: target file; replaced atomically at every checkpoint.
        fps: frames per second (``timeCodesPerSecond``); time code = frame number.
        start_frame: first frame of the animation (``startTimeCode``).
        up_axis: "Z" (the simulation's world) or "Y" (the stage is turned; poses converted).
        meters_per_unit: stage unit [m]; lengths are divided by it on output.
        checkpoint_every: write the file every this many ``write_frame`` calls ...
        checkpoint_seconds: ... once at least this many seconds of wall time have passed
            since the last write (0: every ``checkpoint_every`` frames). A checkpoint
            rewrites the whole file (~30 ms for the glass walls' 2.7 MB): a fast run need
            not pay it every few frames to lose at most a few seconds to a crash.
        lock: an ``output.OutputLock`` held on ``path``, checked before every write: a run
            whose output another run took over stops instead of overwriting it.

    No NaN or infinite value is ever written: a pose, vertex or stress that is not finite
    raises ``NonFiniteError`` and leaves the file as the last checkpoint wrote it.

    Positions, vertices and impact points given to the writer are always in the simulation's
    units and frame: metres, Z up, quaternions (w, x, y, z) body -> world.
    """

    def __init__(
        self,
        path,
        fps: float,
        start_frame: int = 0,
        up_axis: str = "Z",
        meters_per_unit: float = 1.0,
        checkpoint_every: int = 10,
        checkpoint_seconds: float = 0.0,
        lock=None,
    ):
        self.path = Path(path)
        if self.path.suffix not in (".usd", ".usdc", ".usda"):
            raise ValueError(f"cache path must end in .usd, .usdc or .usda: {self.path}")
        if not fps > 0:
            raise ValueError(f"fps must be > 0, got {fps}")
        if up_axis not in ("Z", "Y"):
            raise ValueError(f"up_axis must be 'Z' or 'Y', got {up_axis!r}")
        if not meters_per_unit > 0:
            raise ValueError(f"meters_per_unit must be > 0, got {meters_per_unit}")
        if int(checkpoint_every) < 1:
            raise ValueError(f"checkpoint_every must be >= 1, got {checkpoint_every}")
        if not checkpoint_seconds >= 0:
            raise ValueError(f"checkpoint_seconds must be >= 0, got {checkpoint_seconds}")
        self.fps = float(fps)
        self.start_frame = int(start_frame)
        self.up_axis = up_axis
        self.meters_per_unit = float(meters_per_unit)
        self.checkpoint_every = int(checkpoint_every)
        self.checkpoint_seconds = float(checkpoint_seconds)
        self.lock = lock
        self._last_write_time = _time.monotonic()
        self._fragments: list[_Fragment] = []
        self._names: set[str] = set()
        self._last_frame: int | None = None
        self._frames_since_checkpoint = 0
        self._closed = False

        layer = Sdf.Layer.CreateAnonymous("taichi_frac_cache" + self.path.suffix)  # (a strong reference)
        stage = Usd.Stage.Open(layer)
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if up_axis == "Z" else UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(stage, self.meters_per_unit)
        stage.SetTimeCodesPerSecond(self.fps)
        stage.SetFramesPerSecond(self.fps)
        stage.SetStartTimeCode(self.start_frame)
        stage.SetEndTimeCode(self.start_frame)
        root = UsdGeom.Xform.Define(stage, schema.ROOT_PRIM)
        stage.SetDefaultPrim(root.GetPrim())
        UsdGeom.Scope.Define(stage, schema.MATERIALS_SCOPE)
        UsdGeom.Scope.Define(stage, schema.FRAGMENTS_SCOPE)
        self._material_paths: list[dict[str, Sdf.Path]] = []  # per fragment: subset name -> material
        # From here on the writer edits the layer's specs directly, with no stage open on it:
        # a stage recomposes every prim added under it, for no reader. ``stage`` opens one
        # on demand.
        self._layer = layer
        del stage
        self._set_layer_data(complete=False)

    # ----------------------------------------------------------------- set-up
    def _define_materials(self, body: str, look: MaterialLook) -> dict[str, Sdf.Path]:
        """A body's two UsdPreviewSurface materials, ``Materials/<body>/outer`` and ``inner``:
        the specs UsdShade.Material / Shader author (tests/test_usd_cache.py compares them),
        written on the layer with no stage recomposing it."""
        scope = Sdf.Path(schema.MATERIALS_SCOPE).AppendChild(body)
        paths = {}
        with Sdf.ChangeBlock():
            _prim_spec(self._layer, scope, "Scope")
            for subset_name, surface in ((schema.OUTER_SUBSET, look.outer), (schema.INNER_SUBSET, look.inner)):
                material_path = scope.AppendChild(subset_name)
                material = _prim_spec(self._layer, material_path, "Material")
                shader = _prim_spec(self._layer, material_path.AppendChild("PreviewSurface"), "Shader")
                _attribute(shader, "info:id", Sdf.ValueTypeNames.Token, "UsdPreviewSurface", uniform=True)
                for name, type_name, value in _preview_inputs(surface):
                    _attribute(shader, f"inputs:{name}", type_name, value)
                shader_output = _attribute(shader, "outputs:surface", Sdf.ValueTypeNames.Token, None)
                output = _attribute(material, "outputs:surface", Sdf.ValueTypeNames.Token, None)
                output.connectionPathList.explicitItems = [shader_output.path]
                paths[subset_name] = material_path
        return paths

    def _unique_prim_name(self, name: str) -> str:
        base = Tf.MakeValidIdentifier(str(name) or "fragment")
        candidate, k = base, 1
        while candidate in self._names:
            candidate = f"{base}_{k}"
            k += 1
        self._names.add(candidate)
        return candidate

    def _set_layer_data(self, complete: bool):
        layer = self._layer
        data = dict(layer.customLayerData)
        data[schema.LAYER_DATA_KEY] = {
            schema.KEY_VERSION: schema.SCHEMA_VERSION,
            schema.KEY_COMPLETE: bool(complete),
            schema.KEY_LAST_FRAME: int(self._last_frame if self._last_frame is not None else self.start_frame - 1),
            schema.KEY_GENERATOR: f"taichi-frac {__version__}",
        }
        layer.customLayerData = data

    # ------------------------------------------------------------- fragments
    def add_fragment(
        self,
        name: str,
        vertices,
        faces,
        face_is_inner,
        birth_frame: int,
        parent: int | None = None,
        impact=None,
        peak_principal_stress: float = 0.0,
        face_peak_stress=None,
        normals=None,
        uvs=None,
        shade_inner: bool = False,
        look: MaterialLook | None = None,
    ) -> int:
        """Add a fragment (or a whole unbroken body) and return its id for ``write_frame``.

        vertices (V,3) [m] body frame; faces (F,3) vertex indices, outward winding;
        face_is_inner (F,) bool, True for crack faces; birth_frame: first visible frame;
        parent: id of the fragment it broke from; impact: (point (3,) world [m], force (3,) [N])
        of the impact that made it (mapping, object with .point/.force, or pair);
        peak_principal_stress [Pa]; face_peak_stress (F,) [Pa]; normals (V,3) or (F,3,3) and
        uvs (V,2) or (F,3,2) of the input mesh, used on outer faces only (NaN = none there).
        Crack faces, and outer faces without input normals, get their flat face normal; faces
        without input UVs get a box projection of the body-frame position [m].
        shade_inner: the normals and UVs given are the crack faces' too (a cut render solid's,
        surfaces/cut.py, which projects UVs along each crack).
        look: the body's two materials (``options.LOOKS``); a fragment with a parent and no
        look shares its parent's materials, one without either gets the plaster look.
        """
        self._check_open()
        vertices, faces, inner, face_stress = self._checked_surface(name, vertices, faces, face_is_inner, parent,
                                                                    face_peak_stress, peak_principal_stress)
        corner_normals = _per_corner(normals, faces, len(vertices), 3, "normals")
        corner_uvs = _per_corner(uvs, faces, len(vertices), 2, "uvs")
        # Keep only the vertices the surface uses (a tet mesh's interior ones are not drawn).
        used, faces = np.unique(faces.reshape(-1), return_inverse=True)
        faces = faces.reshape(-1, 3)
        points = vertices[used]
        corner_normals, corner_uvs = _corner_shading(points[faces], inner, corner_normals, corner_uvs, shade_inner)

        prim_path = Sdf.Path(f"{schema.FRAGMENTS_SCOPE}/{self._unique_prim_name(name)}")
        impact_fields = None
        if impact is not None:
            point, force = _impact_fields(impact)
            _check_finite(f"fragment {name!r}: impact", np.concatenate([point, force]))
            point, force = self._to_stage_vectors(point[None], force[None])
            impact_fields = (Gf.Vec3d(*point[0]), Gf.Vec3d(*force[0]))
        parent_path = None if parent is None else self._fragments[int(parent)].prim_path
        if look is None and parent is not None:
            materials = self._material_paths[int(parent)]
        else:
            materials = self._define_materials(prim_path.name, look or _DEFAULT_LOOK)
        birth_frame = int(birth_frame)
        # The layer's specs written directly: what UsdGeom.Mesh, PrimvarsAPI and
        # MaterialBindingAPI author (tests/test_usd_cache.py compares the two), with no
        # stage recomposing each edit.
        with Sdf.ChangeBlock():
            mesh = self._mesh_spec(prim_path, points, faces, inner, corner_normals, corner_uvs, face_stress,
                                   materials)
            _attribute(mesh, schema.ATTR_BIRTH_FRAME, Sdf.ValueTypeNames.Int, birth_frame, custom=True)
            _attribute(mesh, schema.ATTR_DEATH_FRAME, Sdf.ValueTypeNames.Int, -1, custom=True)
            _attribute(mesh, schema.ATTR_PEAK_STRESS, Sdf.ValueTypeNames.Double, float(peak_principal_stress),
                       custom=True)
            if parent_path is not None:
                relationship = Sdf.RelationshipSpec(mesh, schema.ATTR_PARENT, custom=True)
                relationship.targetPathList.explicitItems = [Sdf.Path(parent_path)]
            if impact_fields is not None:
                _attribute(mesh, schema.ATTR_IMPACT_POINT, Sdf.ValueTypeNames.Point3d, impact_fields[0], custom=True)
                _attribute(mesh, schema.ATTR_IMPACT_FORCE, Sdf.ValueTypeNames.Vector3d, impact_fields[1], custom=True)
            translate = _attribute(mesh, "xformOp:translate", Sdf.ValueTypeNames.Double3, None)
            orient = _attribute(mesh, "xformOp:orient", Sdf.ValueTypeNames.Quatd, None)
            _attribute(mesh, "xformOpOrder", Sdf.ValueTypeNames.TokenArray,
                       Vt.TokenArray(["xformOp:translate", "xformOp:orient"]), uniform=True)
            visibility = _attribute(mesh, "visibility", Sdf.ValueTypeNames.Token, None)
            layer = self._layer
            # Visibility is held between samples: invisible up to birth, then inherited.
            if birth_frame > self.start_frame:
                layer.SetTimeSample(visibility.path, self.start_frame, UsdGeom.Tokens.invisible)
            layer.SetTimeSample(visibility.path, birth_frame, UsdGeom.Tokens.inherited)
        self._fragments.append(_Fragment(str(prim_path), translate.path, orient.path, visibility.path, birth_frame))
        self._material_paths.append(materials)
        return len(self._fragments) - 1

    def _checked_surface(self, name, vertices, faces, face_is_inner, parent, face_peak_stress, peak):
        """``add_fragment``'s arrays as arrays of their dtypes, each checked: (vertices (V,3)
        float64, faces (F,3) int64, inner (F,) bool, face stress (F,) float64 [Pa])."""
        vertices = np.asarray(vertices, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64)
        inner = np.asarray(face_is_inner, dtype=bool)
        if vertices.ndim != 2 or vertices.shape[1] != 3:
            raise ValueError(f"vertices must be (V, 3), got {vertices.shape}")
        if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
            raise ValueError(f"faces must be a non-empty (F, 3) array, got {faces.shape}")
        if faces.min() < 0 or faces.max() >= len(vertices):
            raise ValueError("faces index vertices out of range")
        if inner.shape != (len(faces),):
            raise ValueError(f"face_is_inner must be ({len(faces)},), got {inner.shape}")
        _check_finite(f"fragment {name!r}: vertices", vertices / self.meters_per_unit, float32=True)
        if parent is not None and not 0 <= int(parent) < len(self._fragments):
            raise ValueError(f"unknown parent fragment id {parent}")
        face_stress = np.zeros(len(faces)) if face_peak_stress is None else np.asarray(face_peak_stress, np.float64)
        if face_stress.shape != (len(faces),):
            raise ValueError(f"face_peak_stress must be ({len(faces)},), got {face_stress.shape}")
        _check_finite(f"fragment {name!r}: peak stress", face_stress, float32=True)
        _check_finite(f"fragment {name!r}: peak stress", float(peak))
        return vertices, faces, inner, face_stress

    def _mesh_spec(self, prim_path, points, faces, inner, corner_normals, corner_uvs, face_stress, materials):
        """The fragment's Mesh prim spec with its geometry, shading, stress and the two face
        subsets bound to ``materials``; returns the spec."""
        scale = 1.0 / self.meters_per_unit
        mesh = _prim_spec(self._layer, prim_path, "Mesh")
        _attribute(mesh, "points", Sdf.ValueTypeNames.Point3fArray,
                   Vt.Vec3fArray.FromNumpy((points * scale).astype(np.float32)))
        _attribute(mesh, "faceVertexCounts", Sdf.ValueTypeNames.IntArray,
                   Vt.IntArray.FromNumpy(np.full(len(faces), 3, dtype=np.int32)))
        _attribute(mesh, "faceVertexIndices", Sdf.ValueTypeNames.IntArray,
                   Vt.IntArray.FromNumpy(faces.reshape(-1).astype(np.int32)))
        _attribute(mesh, "extent", Sdf.ValueTypeNames.Float3Array,
                   Vt.Vec3fArray.FromNumpy((np.stack([points.min(0), points.max(0)]) * scale).astype(np.float32)))
        _attribute(mesh, "subdivisionScheme", Sdf.ValueTypeNames.Token, UsdGeom.Tokens.none, uniform=True)
        _attribute(mesh, "normals", Sdf.ValueTypeNames.Normal3fArray,
                   Vt.Vec3fArray.FromNumpy(corner_normals.astype(np.float32)), interpolation="faceVarying")
        _attribute(mesh, f"primvars:{schema.PRIMVAR_UV}", Sdf.ValueTypeNames.TexCoord2fArray,
                   Vt.Vec2fArray.FromNumpy(corner_uvs.astype(np.float32)), interpolation="faceVarying")
        _attribute(mesh, f"primvars:{schema.PRIMVAR_FACE_STRESS}", Sdf.ValueTypeNames.FloatArray,
                   Vt.FloatArray.FromNumpy(face_stress.astype(np.float32)), interpolation="uniform")
        _apply_binding_api(mesh)
        for subset_name, faces_in in ((schema.OUTER_SUBSET, ~inner), (schema.INNER_SUBSET, inner)):
            subset = _prim_spec(self._layer, prim_path.AppendChild(subset_name), "GeomSubset")
            _attribute(subset, "indices", Sdf.ValueTypeNames.IntArray,
                       Vt.IntArray.FromNumpy(np.nonzero(faces_in)[0].astype(np.int32)))
            _attribute(subset, "elementType", Sdf.ValueTypeNames.Token, UsdGeom.Tokens.face, uniform=True)
            _attribute(subset, "familyName", Sdf.ValueTypeNames.Token, "materialBind", uniform=True)
            _apply_binding_api(subset)
            binding = Sdf.RelationshipSpec(subset, "material:binding", custom=False)
            binding.targetPathList.explicitItems = [materials[subset_name]]
        _attribute(mesh, "subsetFamily:materialBind:familyType", Sdf.ValueTypeNames.Token,
                   UsdGeom.Tokens.partition, uniform=True)
        return mesh

    def _to_stage_vectors(self, points: np.ndarray, vectors: np.ndarray | None = None):
        """World points [m] (K,3) -> stage frame and units; free vectors only turned."""
        if self.up_axis == "Y":
            points = points @ _Z_TO_Y_UP_MATRIX.T
            vectors = None if vectors is None else vectors @ _Z_TO_Y_UP_MATRIX.T
        return points / self.meters_per_unit, vectors

    # ------------------------------------------------------------------ frames
    def write_frame(self, frame: int, fragment_ids, positions, orientations_wxyz) -> None:
        """World pose of each live body at ``frame``: positions (K,3) [m] of the body-frame
        origin (centre of mass), orientations (K,4) unit quaternions (w,x,y,z) body -> world.

        A pose equal to the body's last one (a sleeping body) gets no sample: USD, and the
        add-on's linear keys, hold a value after its last sample and between two equal
        ones, so when the body moves again the held pose is written at the last frame that
        repeated it, and the cache reads the same at every frame with fewer samples
        (the 13 rings: most bodies sleep for the last quarter of the run)."""
        self._check_open()
        ids = np.asarray(fragment_ids, dtype=np.int64).reshape(-1)
        positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        quats = np.asarray(orientations_wxyz, dtype=np.float64).reshape(-1, 4)
        if not len(ids) == len(positions) == len(quats):
            raise ValueError(f"{len(ids)} ids, {len(positions)} positions, {len(quats)} orientations")
        if len(ids) and (ids.min() < 0 or ids.max() >= len(self._fragments)):
            raise ValueError("unknown fragment id in write_frame")
        bad = ~(np.all(np.isfinite(positions), axis=1) & np.all(np.isfinite(quats), axis=1))
        if np.any(bad):
            k = int(np.argmax(bad))
            raise NonFiniteError(f"frame {int(frame)}: fragment {self._fragments[int(ids[k])].prim_path} has a non-finite "
                                 f"pose (position {positions[k].tolist()}, orientation {quats[k].tolist()})")
        norms = np.linalg.norm(quats, axis=1)
        if np.any(np.abs(norms - 1.0) > 1e-3):
            raise ValueError("orientations must be unit quaternions (w, x, y, z)")
        quats = quats / norms[:, None]
        positions, _ = self._to_stage_vectors(positions)
        if self.up_axis == "Y":
            quats = quaternion_multiply(_Z_TO_Y_UP, quats)
        frame = int(frame)
        layer = self._layer
        with Sdf.ChangeBlock():  # (the layer's own time samples: ~2x faster than UsdAttribute.Set)
            for fid, p, q in zip(ids.tolist(), positions.tolist(), quats.tolist()):
                fragment = self._fragments[fid]
                pose = (p, q)
                if pose == fragment.pose:
                    fragment.held = frame
                    continue
                if fragment.held is not None:
                    self._set_pose(layer, fragment, fragment.held, *fragment.pose)
                    fragment.held = None
                self._set_pose(layer, fragment, frame, p, q)
                fragment.pose = pose
        self._last_frame = frame if self._last_frame is None else max(self._last_frame, frame)
        self._frames_since_checkpoint += 1
        if (self._frames_since_checkpoint >= self.checkpoint_every
                and _time.monotonic() - self._last_write_time >= self.checkpoint_seconds):
            self.checkpoint()

    @staticmethod
    def _set_pose(layer, fragment, frame: int, p, q) -> None:
        layer.SetTimeSample(fragment.translate, frame, Gf.Vec3d(*p))
        layer.SetTimeSample(fragment.orient, frame, Gf.Quatd(q[0], q[1], q[2], q[3]))

    def end_fragment(self, fragment_id: int, frame: int) -> None:
        """The fragment is gone (broke into children) from ``frame`` on: invisible from then."""
        self._check_open()
        fragment = self._fragments[int(fragment_id)]
        frame = int(frame)
        if frame < fragment.birth:
            raise ValueError(f"fragment {fragment_id} ends at frame {frame}, before its birth {fragment.birth}")
        fragment.death = frame
        layer = self._layer
        layer.SetTimeSample(fragment.visibility, frame, UsdGeom.Tokens.invisible)
        layer.GetAttributeAtPath(Sdf.Path(fragment.prim_path).AppendProperty(schema.ATTR_DEATH_FRAME)).default = frame

    # ---------------------------------------------------------------- output
    def checkpoint(self) -> None:
        """Write everything so far to ``path`` atomically (temporary file, fsync, os.replace)."""
        self._check_open()
        self._write(complete=False)

    @property
    def frames_since_write(self) -> int:
        """Frames given to ``write_frame`` since the file was last written."""
        return self._frames_since_checkpoint

    @property
    def seconds_since_write(self) -> float:
        """Wall time since the file was last written (or the writer made) [s]."""
        return _time.monotonic() - self._last_write_time

    def _write(self, complete: bool) -> None:
        if self.lock is not None:
            self.lock.check()
        last = self._last_frame if self._last_frame is not None else self.start_frame
        deaths = [f.death for f in self._fragments if f.death is not None]
        self._layer.endTimeCode = max([last, self.start_frame] + deaths)
        self._set_layer_data(complete)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(f".{self.path.stem}.tmp{os.getpid()}{self.path.suffix}")
        try:
            if not self._layer.Export(str(tmp)):
                raise OSError(f"USD could not write {tmp}")
            with open(tmp, "rb") as fh:
                os.fsync(fh.fileno())
            os.replace(tmp, self.path)
        finally:
            if tmp.exists():
                tmp.unlink()
        self._frames_since_checkpoint = 0
        self._last_write_time = _time.monotonic()

    def close(self, complete: bool = True) -> None:
        """Write the final file (``complete`` True in its layer data). Idempotent."""
        if self._closed:
            return
        self._write(complete=complete)
        self._closed = True

    def _check_open(self):
        if self._closed:
            raise RuntimeError(f"cache {self.path} is closed")

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        # On an exception the frames done so far are still written (marked incomplete).
        self.close(complete=exc_type is None)
        return False

    @property
    def stage(self) -> Usd.Stage:
        """A stage on the in-memory layer (read-only use: inspection in tests)."""
        return Usd.Stage.Open(self._layer)


class NonFiniteError(ValueError):
    """A NaN or infinite value was given to the writer (and not written)."""


def _check_finite(what: str, values, float32: bool = False) -> None:
    """``float32``: the values are written as 32-bit floats, where beyond 3.4e38 is inf."""
    values = np.asarray(values, dtype=np.float64)
    if not np.all(np.isfinite(values)):
        raise NonFiniteError(f"{what} has NaN or infinite values; nothing of it was written")
    if float32 and values.size and np.abs(values).max() > np.finfo(np.float32).max:
        raise NonFiniteError(f"{what} has values beyond a 32-bit float (3.4e38); nothing of it was written")


def _preview_inputs(surface: SurfaceLook):
    """(name, type, value) of the UsdPreviewSurface inputs of one look. opacityThreshold 0
    makes opacity < 1 mean transmission (glass), not a cut-out mask."""
    float_type = Sdf.ValueTypeNames.Float
    return [
        ("diffuseColor", Sdf.ValueTypeNames.Color3f, Gf.Vec3f(*surface.diffuse_color)),
        ("roughness", float_type, float(surface.roughness)),
        ("metallic", float_type, float(surface.metallic)),
        ("opacity", float_type, float(surface.opacity)),
        ("opacityThreshold", float_type, 0.0),
        ("ior", float_type, float(surface.ior)),
    ]


def _box_projection(corners: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """UVs [m] of face corners by projecting along each face normal's dominant axis."""
    axis = np.argmax(np.abs(normals), axis=1)
    drop = np.array([[1, 2], [0, 2], [0, 1]])[axis]
    return np.take_along_axis(corners, drop, axis=1)


def cache_digest(path) -> str:
    """A SHA-256 of what a cache holds: every prim's path, and each attribute's name and value
    at every time sample, in the stage's order. Two runs that wrote the same fragments,
    surfaces and poses give the same digest whatever the file's byte layout."""
    import hashlib

    stage = Usd.Stage.Open(str(path))
    digest = hashlib.sha256()
    for prim in stage.Traverse():
        digest.update(str(prim.GetPath()).encode())
        for attr in prim.GetAttributes():
            digest.update(attr.GetName().encode())
            for t in attr.GetTimeSamples() or [None]:
                digest.update(repr(attr.Get() if t is None else attr.Get(t)).encode())
    return digest.hexdigest()


def check_cache(path) -> list[str]:
    """Run every validator USD registers (what ``usdchecker`` runs: UsdValidation, which
    replaced UsdUtils.ComplianceChecker) on a cache; returns their errors and warnings as text,
    empty when the file is compliant."""
    from pxr import UsdValidation

    stage = Usd.Stage.Open(str(path))
    if stage is None:
        return [f"USD cannot open {path}"]
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    return [f"{e.GetType()}: {e.GetName()}: {e.GetMessage()}" for e in context.Validate(stage)]
