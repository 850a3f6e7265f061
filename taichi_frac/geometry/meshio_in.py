"""Loading meshes from files: surfaces via trimesh, tet meshes via meshio.

Surfaces (OBJ, STL, PLY, OFF, glTF/GLB) are loaded as geometry and texture coordinates:
materials and textures are skipped, so an OBJ whose .mtl names a missing texture still
loads. Vertices are merged by position (a UV seam does not open the surface); the UVs are
kept per corner (``mesh.metadata["corner_uvs"]``, (F,3,2)) and per vertex. Multi-mesh
files (a glTF scene) are flattened into one mesh with their node transforms applied; each
piece must then be a closed shell, and several shells are an error unless repaired.

Up axis: the simulation is Z-up. glTF/GLB files are Y-up by the glTF specification and are
always turned Z-up (x, y, z) -> (x, -z, y), as Blender's importer does; the other formats
carry no up axis, so ``up_axis="y"`` says a file is Y-up (Blender's OBJ export default) and
``"z"`` (the default) takes it as it is.

Tet meshes (.msh, .vtk, .vtu, .mesh) are used as they are: no re-meshing.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import trimesh

from ..options import OptionError
from .validate import MeshError, validate_surface

#: Length units accepted by ``units=``: metres per unit.
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}

SURFACE_SUFFIXES = (".obj", ".stl", ".ply", ".off", ".gltf", ".glb")
TET_SUFFIXES = (".msh", ".vtk", ".vtu", ".mesh")
# Formats that are always text (and need no neighbouring files, as a glTF's buffers do):
# bytes that are not text mean a wrong or damaged file.
_TEXT_SUFFIXES = (".obj", ".off")

#: Up axes a surface file's coordinates may use (``up_axis=``).
UP_AXES = ("z", "y")
#: Formats whose up axis their specification fixes (glTF 2.0: +Y up).
_Y_UP_SUFFIXES = (".gltf", ".glb")

#: Sizes [m] a solid may have: below 0.1 mm its particles' distances are lost against the
#: float32 positions of a scene of metres; above 10 km float32 resolves only centimetres.
SIZE_RANGE = (1.0e-4, 1.0e4)


def check_size(size: float, what: str, scale: float = 1.0, units: str = "m") -> None:
    """Raise MeshError unless ``size`` [m] (a solid's largest extent, after ``units`` and
    ``scale``) lies in :data:`SIZE_RANGE`; the message says how to rescale."""
    low, high = SIZE_RANGE
    if low <= size <= high:
        return
    side = "small" if size < low else "large"
    hint = ("give the unit its coordinates really are in (units = \"m\", \"cm\" or \"mm\") or a scale that "
            "makes it its real size" if side == "small" else
            "if its coordinates are millimetres or centimetres give units = \"mm\" or \"cm\", or a scale below 1")
    raise MeshError(f"{what} is {size:.3g} m across (units {units!r}, scale {scale:g}): too {side} to simulate, "
                    f"sizes from {low:g} to {high:g} m work; {hint}")


def unit_scale(scale: float = 1.0, units: str = "m") -> float:
    """Metres per file unit: ``scale`` x the unit's size. Raises OptionError for bad input."""
    if units not in UNITS:
        raise OptionError(f"units = {units!r}: use one of {', '.join(UNITS)} (metres, centimetres, millimetres)")
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not np.isfinite(scale) or scale <= 0:
        raise OptionError(f"scale = {scale!r} is out of range: allowed (0, inf)")
    return float(scale) * UNITS[units]


def _check_file(path: Path, suffixes) -> None:
    if not path.exists():
        raise MeshError(f"{path.name!r} does not exist (looked at {str(path)!r})")
    if path.suffix.lower() not in suffixes:
        raise MeshError(f"{path.name!r}: unsupported file type {path.suffix!r}; surfaces: "
                        f"{', '.join(SURFACE_SUFFIXES)}; tet meshes: {', '.join(TET_SUFFIXES)}")


def read_surface(path: str | os.PathLike) -> trimesh.Trimesh:
    """Read a surface file into one trimesh (file units, no checks)."""
    path = Path(path)
    _check_file(path, SURFACE_SUFFIXES)
    suffix = path.suffix.lower()
    kwargs = {"skip_materials": True} if suffix == ".obj" else {}
    source = str(path)
    if path.is_dir():
        raise MeshError(f"{path.name!r} is a folder, not a mesh file")
    if suffix in _TEXT_SUFFIXES:
        # Decoded here: trimesh's guess at an unknown encoding needs a package it does not
        # require, and fails with that package's name instead of the file's problem.
        source = trimesh.util.wrap_as_stream(_text_of(path).encode("utf-8"))
        kwargs["file_type"] = suffix[1:]
    try:
        loaded = trimesh.load(source, process=False, **kwargs)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise MeshError(f"{path.name!r} could not be read as a surface mesh: {exc}") from exc
    if isinstance(loaded, trimesh.Scene):
        geometry = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh)]
        loaded = trimesh.util.concatenate(geometry) if geometry else trimesh.Trimesh()
    if not isinstance(loaded, trimesh.Trimesh):
        loaded = trimesh.Trimesh()  # a point cloud or a path: no faces
    vertices = np.asarray(loaded.vertices)
    _check_finite(vertices, path.name)
    uv = getattr(loaded.visual, "uv", None)
    corner_uvs = None
    if uv is not None and len(uv) == len(vertices) and len(loaded.faces):
        corner_uvs = np.asarray(uv, dtype=np.float64)[np.asarray(loaded.faces)]
    # Merge duplicate vertices (STL stores each triangle's corners separately). trimesh
    # merges within an absolute 1e-8, which collapses a mesh of 1e-9 units to a point: the
    # merge runs on the mesh scaled to about unit size by a power of two (exact, so a mesh
    # near unit size merges bit for bit as before).
    extent = float(np.max(np.ptp(vertices, axis=0))) if len(vertices) else 0.0
    unit = 2.0 ** -round(np.log2(extent)) if extent > 0 else 1.0
    mesh = trimesh.Trimesh(vertices * unit, loaded.faces, process=True)
    mesh.apply_scale(1.0 / unit)
    mesh.metadata["file_extent"] = extent
    if corner_uvs is not None and len(mesh.faces) == len(corner_uvs):
        attach_corner_uvs(mesh, corner_uvs)
    return mesh


def _text_of(path: Path) -> str:
    """The text of a text-format mesh file: UTF-8, or Latin-1 (old exporters); raises
    MeshError for bytes that are no text at all (a binary or damaged file)."""
    raw = path.read_bytes()
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        start = exc.start
    codes = np.frombuffer(raw, dtype=np.uint8)
    control = np.nonzero((codes < 32) & ~np.isin(codes, (9, 10, 12, 13)))[0]
    if len(control) == 0:
        return raw.decode("latin-1")
    at = int(control[0])
    line = raw[:at].count(b"\n") + 1
    raise MeshError(f"{path.name!r} is not a text {path.suffix.lower()[1:].upper()} file: byte 0x{raw[at]:02x} at "
                    f"offset {at} (line {line}) is not text (first non-UTF-8 byte at "
                    f"offset {start}); export the mesh again, or check the file is the mesh you meant")


def _check_finite(vertices: np.ndarray, name: str) -> None:
    bad = np.nonzero(~np.all(np.isfinite(vertices), axis=1))[0] if len(vertices) else []
    if len(bad):
        raise MeshError(f"{name!r}: {len(bad)} vertices with a NaN or infinite coordinate, e.g. vertex {int(bad[0])} "
                        f"= {vertices[bad[0]].tolist()}; fix them in the modelling program and export again")


def attach_corner_uvs(mesh: trimesh.Trimesh, corner_uvs: np.ndarray) -> None:
    """Give ``mesh`` its corners' UVs (F,3,2): exactly in ``metadata["corner_uvs"]``, and per
    vertex as a TextureVisuals (a vertex on a UV seam takes one side's UV)."""
    per_vertex = np.zeros((len(mesh.vertices), 2))
    per_vertex[np.asarray(mesh.faces).reshape(-1)] = corner_uvs.reshape(-1, 2)
    mesh.visual = trimesh.visual.TextureVisuals(uv=per_vertex)
    mesh.metadata["corner_uvs"] = np.asarray(corner_uvs, dtype=np.float64)


def check_or_repair(mesh: trimesh.Trimesh, name: str, *, repair: bool = False, clock=None,
                    check_self_intersection: bool = True, min_kept_fraction: float | None = None) -> trimesh.Trimesh:
    """``mesh`` checked (``validate_surface``) or, with ``repair``, repaired first
    (``repair.repair_surface``, its steps in ``metadata["repair"]`` and its report in
    ``metadata["repair_report"]``; ``min_kept_fraction``: its bound, None for its default);
    input UVs are carried onto a repaired surface."""
    steps: list[str] = []
    report = None
    if repair:
        from .repair import repair_surface
        from .surface_attributes import boundary_corner_attributes

        bound = {} if min_kept_fraction is None else {"min_kept_fraction": min_kept_fraction}
        repaired, report = repair_surface(mesh, name, clock=clock, **bound)
        if mesh.metadata.get("corner_uvs") is not None:
            # Each corner takes the UV of the input triangle it lies on.
            _, uvs = boundary_corner_attributes(mesh, repaired.triangles)
            attach_corner_uvs(repaired, uvs)
        mesh, steps = repaired, report.steps
    if clock is not None:
        clock.inline("validate", validate_surface, mesh, name, check_self_intersection=check_self_intersection)
    else:
        validate_surface(mesh, name, check_self_intersection=check_self_intersection)
    mesh.metadata["repair"] = steps
    mesh.metadata["repair_report"] = report
    return mesh


def check_up_axis(up_axis: str) -> str:
    """``up_axis`` if it is one of :data:`UP_AXES`, else OptionError."""
    if up_axis not in UP_AXES:
        raise OptionError(f"up_axis = {up_axis!r}: use \"z\" (the file is Z-up, taken as it is) or \"y\" "
                          "(the file is Y-up, e.g. Blender's OBJ export default; turned Z-up)")
    return up_axis


def file_up_axis(path: str | os.PathLike, up_axis: str = "z") -> str:
    """The up axis of ``path``'s coordinates: "y" for glTF/GLB (their specification), else
    ``up_axis``."""
    check_up_axis(up_axis)
    return "y" if Path(path).suffix.lower() in _Y_UP_SUFFIXES else up_axis


def to_z_up(mesh: trimesh.Trimesh, up_axis: str) -> trimesh.Trimesh:
    """``mesh`` turned in place from ``up_axis`` up to Z up: Y up is (x, y, z) -> (x, -z, y),
    a quarter turn about x (orientation and winding kept)."""
    if check_up_axis(up_axis) == "y":
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
        mesh.vertices = np.column_stack([vertices[:, 0], -vertices[:, 2], vertices[:, 1]])
    return mesh


def load_raw_surface(path: str | os.PathLike, *, scale: float = 1.0, units: str = "m", up_axis: str = "z",
                     clock=None) -> trimesh.Trimesh:
    """A surface file in metres, Z up (see the module docstring), its size checked and
    nothing else: open, crossing or degenerate surfaces are returned as they are."""
    path = Path(path)
    factor = unit_scale(scale, units)
    axis = file_up_axis(path, up_axis)
    mesh = clock.inline("load", read_surface, path) if clock is not None else read_surface(path)
    to_z_up(mesh, axis)
    mesh.apply_scale(factor)
    if len(mesh.faces):
        check_size(mesh.metadata["file_extent"] * factor, repr(path.name), scale, units)
    mesh.metadata["source"] = str(path)
    mesh.metadata["up_axis"] = axis
    return mesh


def load_surface(path: str | os.PathLike, *, scale: float = 1.0, units: str = "m", repair: bool = False,
                 check_self_intersection: bool = True, clock=None, up_axis: str = "z") -> trimesh.Trimesh:
    """Load a closed surface mesh in metres and check it (see ``validate_surface``).

    Args:
        path: OBJ, STL, PLY, OFF, glTF or GLB file.
        scale: multiplies the coordinates after the unit conversion [-].
        units: length unit of the file's coordinates: "m", "cm" or "mm".
        repair: fix holes, flipped faces, overlapping shells and self-intersections first
            (``repair.repair_surface``); the steps taken are in ``mesh.metadata["repair"]``.
        clock: a ``bounded.StepClock`` whose time bound the steps run under (None: unbounded).
        up_axis: "z" or "y", the up axis of an OBJ/STL/PLY/OFF file's coordinates (glTF/GLB
            are Y-up by their specification whatever this says).

    Raises:
        MeshError: the file is missing, unreadable, or fails a check (message says which).
    """
    path = Path(path)
    mesh = load_raw_surface(path, scale=scale, units=units, up_axis=up_axis, clock=clock)
    axis = mesh.metadata["up_axis"]
    mesh = check_or_repair(mesh, path.name, repair=repair, clock=clock, check_self_intersection=check_self_intersection)
    mesh.metadata["source"] = str(path)
    mesh.metadata["up_axis"] = axis
    return mesh


def load_tet_mesh(path: str | os.PathLike, *, scale: float = 1.0, units: str = "m"):
    """Read a tetrahedral mesh with meshio. Returns (vertices (V,3) float64 [m], tets (T,4) int64).

    Raises MeshError if the file has no tetra cells (a surface-only .vtk, say)."""
    import meshio

    path = Path(path)
    _check_file(path, TET_SUFFIXES)
    factor = unit_scale(scale, units)
    try:
        data = meshio.read(str(path))
    except Exception as exc:
        raise MeshError(f"{path.name!r} could not be read as a tet mesh: {exc}") from exc
    blocks = [c.data for c in data.cells if c.type == "tetra"]
    if not blocks:
        kinds = ", ".join(sorted({c.type for c in data.cells})) or "none"
        raise MeshError(f"{path.name!r} has no tetrahedra (cell types: {kinds}); give a surface mesh "
                        "(OBJ/STL/PLY/OFF/glTF) to be tetrahedralised, or a tet mesh")
    tets = np.concatenate(blocks).astype(np.int64)
    vertices = np.asarray(data.points, dtype=np.float64)[:, :3] * factor
    _check_finite(vertices, path.name)
    if len(vertices):
        check_size(float(np.max(np.ptp(vertices, axis=0))), repr(path.name), scale, units)
    if tets.min() < 0 or tets.max() >= len(vertices):
        raise MeshError(f"{path.name!r}: tet vertex indices out of range 0..{len(vertices) - 1}")
    return vertices, tets


def is_tet_file(path: str | os.PathLike) -> bool:
    return Path(path).suffix.lower() in TET_SUFFIXES
