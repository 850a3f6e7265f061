"""Small caches with closed-form motion for the add-on's feature checks (main env: CacheWriter
and pxr). Every piece moves as position = start + velocity * t and turns about z at ``spin``
rad/s, t = frame / fps [s], so the pose at any instant is known exactly.

Each ``Piece``: name, birth and death frames, parent name, box half extents [m], start [m],
velocity [m/s], spin [rad/s]. check_features.py (inside Blender) recomputes the same poses
from the JSON that ``describe`` writes.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom

import synthetic
from taichi_frac.io import CacheWriter
from taichi_frac.io import schema


@dataclass
class Piece:
    name: str
    birth: int
    death: int | None = None
    parent: str | None = None
    half: tuple = (0.2, 0.15, 0.1)
    start: tuple = (0.0, 0.0, 1.0)
    velocity: tuple = (0.0, 0.0, 0.0)
    spin: float = 0.0

    def pose(self, t: float):
        position = np.asarray(self.start) + np.asarray(self.velocity) * t
        return position, synthetic.axis_angle_quat((0, 0, 1), self.spin * t)


def write(path, pieces, fps: float, last_frame: int, complete: bool = True):
    """Write ``pieces`` over frames 0..last_frame; ``complete`` False leaves the cache as an
    interrupted run does (its last checkpoint)."""
    ids = {}
    writer = CacheWriter(path, fps=fps, checkpoint_every=10**6)
    for frame in range(last_frame + 1):
        for piece in pieces:
            if piece.birth == frame:
                vertices, faces = synthetic.box_mesh(piece.half)
                inner = np.arange(len(faces)) < (2 if piece.parent else 0)
                ids[piece.name] = writer.add_fragment(
                    piece.name, vertices, faces, inner, piece.birth,
                    parent=None if piece.parent is None else ids[piece.parent],
                    impact=None if piece.parent is None else synthetic.IMPACT,
                    peak_principal_stress=1e6, face_peak_stress=2e4 * np.arange(len(faces)))
            if piece.death == frame:
                writer.end_fragment(ids[piece.name], frame)
        live = [p for p in pieces if p.birth <= frame and (p.death is None or frame < p.death)]
        poses = [p.pose(frame / fps) for p in live]
        writer.write_frame(frame, [ids[p.name] for p in live], [x for x, _ in poses], [q for _, q in poses])
    writer.close(complete=complete)


def describe(pieces, fps: float) -> dict:
    return {"fps": fps, "pieces": [asdict(p) for p in pieces]}


def set_preview_inputs(path, material: str, **inputs) -> None:
    """Author UsdPreviewSurface inputs (float, or a 3-tuple colour) on a cache's material
    ``material`` (Materials/<body>/<outer|inner>, e.g. "slab/outer"), as a writer of glass or cut-out materials would."""
    stage = Usd.Stage.Open(str(path))
    shader = stage.GetPrimAtPath(f"{schema.MATERIALS_SCOPE}/{material}/PreviewSurface")
    from pxr import UsdShade

    shader = UsdShade.Shader(shader)
    for name, value in inputs.items():
        if isinstance(value, tuple):
            shader.CreateInput(name, Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*value))
        else:
            shader.CreateInput(name, Sdf.ValueTypeNames.Float).Set(float(value))
    stage.GetRootLayer().Save()


def clear_preview_inputs(path, material: str, *names: str) -> None:
    """Remove UsdPreviewSurface inputs from a cache's material ``material`` (as
    ``set_preview_inputs`` names it), as a writer that authors fewer inputs would leave it."""
    stage = Usd.Stage.Open(str(path))
    shader = stage.GetPrimAtPath(f"{schema.MATERIALS_SCOPE}/{material}/PreviewSurface")
    for name in names:
        shader.RemoveProperty(f"inputs:{name}")
    stage.GetRootLayer().Save()


def set_schema_version(path, version: int) -> None:
    layer = Sdf.Layer.FindOrOpen(str(path))
    data = dict(layer.customLayerData)
    data[schema.LAYER_DATA_KEY] = dict(data[schema.LAYER_DATA_KEY], **{schema.KEY_VERSION: version})
    layer.customLayerData = data
    layer.Save()


def write_foreign_usd(path) -> None:
    """A USD file another tool wrote: a cube, no taichi-frac layer data."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.Cube.Define(stage, "/World/Cube")
    stage.SetDefaultPrim(stage.GetPrimAtPath("/World"))
    stage.GetRootLayer().Save()
