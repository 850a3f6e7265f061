"""Read a taichi-frac USD cache into plain numpy arrays. Needs pxr (Blender bundles it; outside
Blender, usd-core) and numpy, never bpy: tests run it in plain Python.

Everything returned is in Blender's convention: Z up, metres, quaternions (w, x, y, z);
the cache's upAxis and metersPerUnit are undone here.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field

import numpy as np

from . import schema


class CacheError(ValueError):
    """A cache that cannot be read: missing, not USD, corrupt, or from a newer writer. The
    message names the file and what to do; the add-on shows it in Blender's status bar."""


@dataclass
class MaterialData:
    """A UsdPreviewSurface's constant inputs; None where the shader does not author one (the
    importer then keeps Blender's default). Colours linear RGB."""

    name: str
    prim_path: str
    base_color: tuple | None = None          # diffuseColor
    roughness: float | None = None
    metallic: float | None = None
    opacity: float | None = None
    opacity_threshold: float | None = None   # > 0: a cut-out mask; 0: opacity is transmission
    ior: float | None = None


@dataclass
class FragmentData:
    """One Mesh prim. V vertices, F faces, L = sum of face sizes (loops), S pose samples,
    K visibility keys."""

    name: str
    prim_path: str
    vertices: np.ndarray            # (V,3) float64 [m] body frame
    face_sizes: np.ndarray          # (F,) int32
    face_vertices: np.ndarray       # (L,) int32
    face_material: np.ndarray       # (F,) int32 index into CacheData.materials
    loop_normals: np.ndarray | None  # (L,3) float32
    loop_uvs: np.ndarray | None      # (L,2) float32
    face_stress: np.ndarray | None   # (F,) float32 [Pa]
    sample_frames: np.ndarray       # (S,) float64
    positions: np.ndarray           # (S,3) float64 [m] world
    orientations: np.ndarray        # (S,4) float64 (w,x,y,z), sign-continuous over samples
    visibility_frames: np.ndarray   # (K,) float64
    visible: np.ndarray             # (K,) bool; held from each key to the next
    birth_frame: int | None = None
    death_frame: int | None = None
    parent: str | None = None       # prim path of the parent fragment
    impact_point: np.ndarray | None = None   # (3,) [m] world
    impact_force: np.ndarray | None = None   # (3,) [N] world
    peak_principal_stress: float | None = None  # [Pa]
    generation: int = 0             # parent links up to the scene's original body
    source: str = ""                # prim path of that original body (itself for a root)

    def visible_at(self, frame: float) -> bool:
        """Visibility as USD holds it: the last key at or before ``frame`` (first key before)."""
        k = np.searchsorted(self.visibility_frames, frame, side="right") - 1
        return bool(self.visible[max(k, 0)])


@dataclass
class CacheData:
    path: str
    fps: float
    start_frame: float
    end_frame: float
    up_axis: str
    meters_per_unit: float
    schema_version: int | None
    complete: bool | None
    last_frame: int | None
    generator: str | None = None
    materials: list = field(default_factory=list)
    fragments: list = field(default_factory=list)


# Y-up stage -> Z-up: (x, y, z) -> (x, -z, y), the inverse of the writer's turn.
_Y_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def quaternions_from_matrices(rotation: np.ndarray) -> np.ndarray:
    """(N,3,3) rotation matrices (column vectors: v' = R v) -> (N,4) unit (w,x,y,z), by the
    largest-diagonal branch (Shepperd 1978) for accuracy near 180 degrees."""
    r = rotation
    trace = r[:, 0, 0] + r[:, 1, 1] + r[:, 2, 2]
    branch = np.argmax(np.stack([trace, r[:, 0, 0], r[:, 1, 1], r[:, 2, 2]], axis=1), axis=1)
    q = np.empty((len(r), 4))
    for b in range(4):
        m = r[branch == b]
        if not len(m):
            continue
        if b == 0:
            s = 2.0 * np.sqrt(np.maximum(1.0 + m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2], 1e-300))
            qb = [0.25 * s, (m[:, 2, 1] - m[:, 1, 2]) / s, (m[:, 0, 2] - m[:, 2, 0]) / s, (m[:, 1, 0] - m[:, 0, 1]) / s]
        elif b == 1:
            s = 2.0 * np.sqrt(np.maximum(1.0 + m[:, 0, 0] - m[:, 1, 1] - m[:, 2, 2], 1e-300))
            qb = [(m[:, 2, 1] - m[:, 1, 2]) / s, 0.25 * s, (m[:, 0, 1] + m[:, 1, 0]) / s, (m[:, 0, 2] + m[:, 2, 0]) / s]
        elif b == 2:
            s = 2.0 * np.sqrt(np.maximum(1.0 - m[:, 0, 0] + m[:, 1, 1] - m[:, 2, 2], 1e-300))
            qb = [(m[:, 0, 2] - m[:, 2, 0]) / s, (m[:, 0, 1] + m[:, 1, 0]) / s, 0.25 * s, (m[:, 1, 2] + m[:, 2, 1]) / s]
        else:
            s = 2.0 * np.sqrt(np.maximum(1.0 - m[:, 0, 0] - m[:, 1, 1] + m[:, 2, 2], 1e-300))
            qb = [(m[:, 1, 0] - m[:, 0, 1]) / s, (m[:, 0, 2] + m[:, 2, 0]) / s, (m[:, 1, 2] + m[:, 2, 1]) / s, 0.25 * s]
        q[branch == b] = np.stack(qb, axis=1)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q


def make_sign_continuous(q: np.ndarray) -> np.ndarray:
    """Flip signs so consecutive quaternions lie in the same hemisphere (q and -q are the same
    rotation; per-component interpolation between opposite signs would swing the long way)."""
    if len(q) < 2:
        return q
    step = np.sign(np.einsum("ij,ij->i", q[1:], q[:-1]))
    step[step == 0] = 1.0
    return q * np.concatenate([[1.0], np.cumprod(step)])[:, None]


# UsdPreviewSurface input -> MaterialData field.
_PREVIEW_INPUTS = (("diffuseColor", "base_color"), ("roughness", "roughness"), ("metallic", "metallic"),
                   ("opacity", "opacity"), ("opacityThreshold", "opacity_threshold"), ("ior", "ior"))


def _material_name(prim_path: str) -> str:
    """A Blender name for a material prim: its path below the materials scope ("outer",
    "ring_0_outer" for .../Materials/ring_0/outer), else the prim's own name."""
    scope = schema.MATERIALS_SCOPE + "/"
    if prim_path.startswith(scope):
        return prim_path[len(scope):].replace("/", "_")
    return prim_path.rsplit("/", 1)[-1]


def _read_material(material_prim, UsdShade) -> MaterialData:
    path = str(material_prim.GetPath())
    data = MaterialData(name=_material_name(path), prim_path=path)
    material = UsdShade.Material(material_prim)
    source = material.ComputeSurfaceSource()
    shader = source[0] if source and source[0] else None
    if shader is None or shader.GetIdAttr().Get() != "UsdPreviewSurface":
        return data
    for input_name, attr in _PREVIEW_INPUTS:
        shader_input = shader.GetInput(input_name)
        value = shader_input.Get() if shader_input else None  # (None too when a texture drives it)
        if value is not None:
            setattr(data, attr, tuple(float(c) for c in value) if attr == "base_color" else float(value))
    return data


def _loop_values(primvar, face_vertices: np.ndarray, loop_count: int, width: int):
    """A primvar as (L, width) per loop, for faceVarying or vertex interpolation; else None."""
    if not primvar or not primvar.HasValue():
        return None
    values = primvar.ComputeFlattened()
    if values is None:
        return None
    values = np.asarray(values, dtype=np.float32).reshape(-1, width)
    interpolation = primvar.GetInterpolation()
    if interpolation == "faceVarying" and len(values) == loop_count:
        return values
    if interpolation in ("vertex", "varying"):
        return values[face_vertices]
    return None


def _usd_message(exc) -> str:
    """The commentary of each error in a Tf.ErrorException (the text USD quotes after the
    C++ location), which is what a user can act on."""
    found = re.findall(r"^\s*Error in .*? : '(.*?)'\s*$", str(exc), flags=re.MULTILINE | re.DOTALL)
    return "; ".join(dict.fromkeys(m.strip() for m in found)) or str(exc).strip() or type(exc).__name__


def _check_path(path) -> None:
    if not os.path.exists(path):
        raise CacheError(f"{path}: no such file")
    if os.path.isdir(path):
        raise CacheError(f"{path} is a folder, not a USD file")


def layer_info(path) -> dict | None:
    """The taichi-frac layer data of a USD file (schemaVersion, complete, lastFrame,
    generator), or None when another tool wrote it. Reads the layer's metadata only."""
    from pxr import Sdf, Tf

    _check_path(path)
    try:
        layer = Sdf.Layer.OpenAsAnonymous(str(path), True)  # (metadataOnly)
    except Tf.ErrorException as exc:
        raise CacheError(f"{path} is not a readable USD file: {_usd_message(exc)}") from None
    if layer is None:
        raise CacheError(f"{path} is not a readable USD file")
    data = dict(layer.customLayerData).get(schema.LAYER_DATA_KEY)
    return dict(data) if data else None


def read_cache(path) -> CacheData:
    """Read every Mesh under the default prim (the whole stage if there is none). Raises
    CacheError, naming the file and USD's own reason, when it cannot."""
    from pxr import Tf

    _check_path(path)
    try:
        cache = _read_stage(path)
    except Tf.ErrorException as exc:
        raise CacheError(f"{path} is not a readable USD file: {_usd_message(exc)}") from None
    if cache.schema_version is not None and int(cache.schema_version) > schema.SCHEMA_VERSION:
        raise CacheError(f"{path} was written by a newer taichi-frac ({cache.generator}, cache schema "
                         f"{cache.schema_version}); this add-on reads schema {schema.SCHEMA_VERSION}: update it")
    _link_lineage(cache.fragments)
    return cache


def _link_lineage(fragments) -> None:
    """Each fragment's generation (0 for a body of the scene) and source (that body's prim
    path), by following parent links; a parent missing from the file ends the chain."""
    by_path = {f.prim_path: f for f in fragments}
    for fragment in fragments:
        generation, node, seen = 0, fragment, {fragment.prim_path}
        while node.parent in by_path and node.parent not in seen:
            seen.add(node.parent)
            node = by_path[node.parent]
            generation += 1
        fragment.generation, fragment.source = generation, node.prim_path


def _read_stage(path) -> CacheData:
    from pxr import Usd, UsdGeom, UsdShade

    stage = Usd.Stage.Open(str(path))
    if stage is None:
        raise CacheError(f"USD cannot open {path}")
    up_axis = UsdGeom.GetStageUpAxis(stage)
    meters_per_unit = UsdGeom.GetStageMetersPerUnit(stage)
    axis_turn = _Y_TO_Z_UP if up_axis == "Y" else np.eye(3)
    layer_data = dict(stage.GetRootLayer().customLayerData).get(schema.LAYER_DATA_KEY, {})
    fps = stage.GetTimeCodesPerSecond()
    cache = CacheData(
        path=str(path),
        fps=float(fps),
        start_frame=float(stage.GetStartTimeCode()),
        end_frame=float(stage.GetEndTimeCode()),
        up_axis=str(up_axis),
        meters_per_unit=float(meters_per_unit),
        schema_version=layer_data.get(schema.KEY_VERSION),
        complete=layer_data.get(schema.KEY_COMPLETE),
        last_frame=layer_data.get(schema.KEY_LAST_FRAME),
        generator=layer_data.get(schema.KEY_GENERATOR),
    )
    material_index: dict[str, int] = {}

    def material_of(prim) -> int | None:
        bound = UsdShade.MaterialBindingAPI(prim).GetDirectBinding().GetMaterial()
        if not bound:
            return None
        key = str(bound.GetPath())
        if key not in material_index:
            material_index[key] = len(cache.materials)
            cache.materials.append(_read_material(bound.GetPrim(), UsdShade))
        return material_index[key]

    root = stage.GetDefaultPrim() or stage.GetPseudoRoot()
    xform_cache = UsdGeom.XformCache(Usd.TimeCode.EarliestTime())
    for prim in Usd.PrimRange(root):
        if not prim.IsA(UsdGeom.Mesh):
            continue
        mesh = UsdGeom.Mesh(prim)
        points = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64).reshape(-1, 3) * meters_per_unit
        face_sizes = np.asarray(mesh.GetFaceVertexCountsAttr().Get(), dtype=np.int32)
        face_vertices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(), dtype=np.int32)
        if mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded:
            starts = np.concatenate([[0], np.cumsum(face_sizes)[:-1]])
            order = np.concatenate([s + np.arange(n)[::-1] for s, n in zip(starts, face_sizes)])
            face_vertices = face_vertices[order]
        loop_count = len(face_vertices)

        face_material = np.full(len(face_sizes), material_of(prim) or 0, dtype=np.int32)
        for subset in UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets():
            index = material_of(subset.GetPrim())
            if index is not None:
                face_material[np.asarray(subset.GetIndicesAttr().Get(), dtype=np.int64)] = index

        primvars = UsdGeom.PrimvarsAPI(prim)
        normals_primvar = primvars.GetPrimvar("normals")
        if normals_primvar and normals_primvar.HasValue():
            loop_normals = _loop_values(normals_primvar, face_vertices, loop_count, 3)
        else:
            normals = mesh.GetNormalsAttr().Get()
            loop_normals = None
            if normals is not None:
                normals = np.asarray(normals, dtype=np.float32).reshape(-1, 3)
                interpolation = mesh.GetNormalsInterpolation()
                if interpolation == "faceVarying" and len(normals) == loop_count:
                    loop_normals = normals
                elif interpolation in ("vertex", "varying") and len(normals) == len(points):
                    loop_normals = normals[face_vertices]
        loop_uvs = _loop_values(primvars.GetPrimvar(schema.PRIMVAR_UV), face_vertices, loop_count, 2)
        stress_primvar = primvars.GetPrimvar(schema.PRIMVAR_FACE_STRESS)
        face_stress = None
        if stress_primvar and stress_primvar.HasValue():
            face_stress = np.asarray(stress_primvar.ComputeFlattened(), dtype=np.float32)
            if face_stress.shape != face_sizes.shape:
                face_stress = None

        # World transform at each pose sample. USD matrices act on row vectors (p' = p M):
        # the rotation block is R transposed, the translation the last row.
        xformable = UsdGeom.Xformable(prim)
        parent_world = np.asarray(xform_cache.GetParentToWorldTransform(prim), dtype=np.float64)
        times = list(xformable.GetTimeSamples()) or [Usd.TimeCode.EarliestTime().GetValue()]
        local = np.array([np.asarray(xformable.GetLocalTransformation(Usd.TimeCode(t)), dtype=np.float64)
                          for t in times]).reshape(-1, 4, 4)
        world = local @ parent_world
        rotation = axis_turn @ np.transpose(world[:, :3, :3], (0, 2, 1))
        positions = (world[:, 3, :3] @ axis_turn.T) * meters_per_unit
        orientations = make_sign_continuous(quaternions_from_matrices(rotation))

        visibility = UsdGeom.Imageable(prim).GetVisibilityAttr()
        vis_times = list(visibility.GetTimeSamples())
        if vis_times:
            vis_values = [visibility.Get(Usd.TimeCode(t)) for t in vis_times]
        else:
            vis_times, vis_values = [cache.start_frame], [visibility.Get() or UsdGeom.Tokens.inherited]

        def custom(name):
            attr = prim.GetAttribute(name)
            return attr.Get() if attr and attr.HasAuthoredValue() else None

        parent_rel = prim.GetRelationship(schema.ATTR_PARENT)
        parent_targets = parent_rel.GetTargets() if parent_rel else []
        impact_point, impact_force = custom(schema.ATTR_IMPACT_POINT), custom(schema.ATTR_IMPACT_FORCE)
        death = custom(schema.ATTR_DEATH_FRAME)
        cache.fragments.append(FragmentData(
            name=prim.GetName(),
            prim_path=str(prim.GetPath()),
            vertices=points,
            face_sizes=face_sizes,
            face_vertices=face_vertices,
            face_material=face_material,
            loop_normals=loop_normals,
            loop_uvs=loop_uvs,
            face_stress=face_stress,
            sample_frames=np.asarray(times, dtype=np.float64),
            positions=positions,
            orientations=orientations,
            visibility_frames=np.asarray(vis_times, dtype=np.float64),
            visible=np.array([v != UsdGeom.Tokens.invisible for v in vis_values]),
            birth_frame=custom(schema.ATTR_BIRTH_FRAME),
            death_frame=None if death is None or death < 0 else int(death),
            parent=str(parent_targets[0]) if parent_targets else None,
            impact_point=None if impact_point is None else axis_turn @ np.asarray(impact_point) * meters_per_unit,
            impact_force=None if impact_force is None else axis_turn @ np.asarray(impact_force),
            peak_principal_stress=custom(schema.ATTR_PEAK_STRESS),
        ))
    return cache
