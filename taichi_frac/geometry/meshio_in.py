"""Loading meshes from files: surfaces via trimesh, tet meshes via meshio.

Surfaces (OBJ, STL, PLY, OFF, glTF/GLB) are loaded as geometry only: materials and
textures are skipped, so an OBJ whose .mtl names a missing texture still loads. Multi-mesh
files (a glTF scene) are flattened into one mesh with their node transforms applied; each
piece must then be a closed shell, and several shells are an error unless repaired.

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
    kwargs = {"skip_materials": True} if path.suffix.lower() == ".obj" else {}
    try:
        loaded = trimesh.load(str(path), process=False, **kwargs)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise MeshError(f"{path.name!r} could not be read as a surface mesh: {exc}") from exc
    if isinstance(loaded, trimesh.Scene):
        geometry = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh)]
        loaded = trimesh.util.concatenate(geometry) if geometry else trimesh.Trimesh()
    if not isinstance(loaded, trimesh.Trimesh):
        loaded = trimesh.Trimesh()  # a point cloud or a path: no faces
    # Merge duplicate vertices (STL stores each triangle's corners separately).
    return trimesh.Trimesh(loaded.vertices, loaded.faces, process=True)


def load_surface(path: str | os.PathLike, *, scale: float = 1.0, units: str = "m", repair: bool = False,
                 check_self_intersection: bool = True) -> trimesh.Trimesh:
    """Load a closed surface mesh in metres and check it (see ``validate_surface``).

    Args:
        path: OBJ, STL, PLY, OFF, glTF or GLB file.
        scale: multiplies the coordinates after the unit conversion [-].
        units: length unit of the file's coordinates: "m", "cm" or "mm".
        repair: fix holes, flipped faces, overlapping shells and self-intersections first
            (``repair.repair_surface``); the steps taken are in ``mesh.metadata["repair"]``.

    Raises:
        MeshError: the file is missing, unreadable, or fails a check (message says which).
    """
    path = Path(path)
    factor = unit_scale(scale, units)
    mesh = read_surface(path)
    mesh.apply_scale(factor)
    steps: list[str] = []
    if repair:
        from .repair import repair_surface

        mesh, report = repair_surface(mesh, path.name)
        steps = report.steps
    validate_surface(mesh, path.name, check_self_intersection=check_self_intersection)
    mesh.metadata["repair"] = steps
    mesh.metadata["source"] = str(path)
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
    if tets.min() < 0 or tets.max() >= len(vertices):
        raise MeshError(f"{path.name!r}: tet vertex indices out of range 0..{len(vertices) - 1}")
    return vertices, tets


def is_tet_file(path: str | os.PathLike) -> bool:
    return Path(path).suffix.lower() in TET_SUFFIXES
