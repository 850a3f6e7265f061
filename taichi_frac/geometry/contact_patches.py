"""The contact patch behind each collision sphere: the true surface its contacts are
computed from (``collision/surface.py``), built once per body from its boundary faces."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import rows


@dataclass(frozen=True, eq=False)
class ContactPatches:
    """The true surface behind each collision sphere, which the contacts are computed
    from (``collision/surface.py``): the spheres find which parts of two bodies may touch,
    the patches say where and how deep.

    Attributes:
        offsets: (N+1,) CSR offsets of each sphere's points in ``points``.
        points: (P,3) [m] body frame: the vertices of the boundary triangles of the
            sphere's member tets, each once per sphere (a triangle's support along any
            direction is at a vertex, so these carry its triangles' whole extent).
        normals: (N,3) unit outward normal of each patch (its triangles' area-weighted
            normal), or zeros where the triangles face every way (their summed area normal
            is under ``FLAT_ENOUGH`` of their area: a one-tet chip's closed surface).
    """

    offsets: np.ndarray
    points: np.ndarray
    normals: np.ndarray


#: A patch has a normal when its triangles' summed area normal is at least this fraction of
#: their total area (a patch spanning 45 degrees of a tube: 0.97; one folded over a cube's
#: edge: 0.71; a closed tet: 0). A folded patch's mean normal is no face's: a chip landing
#: beside the edge was pushed along it into the body.
FLAT_ENOUGH = 0.9


def contact_patches(model, member_offsets: np.ndarray, members: np.ndarray) -> ContactPatches:
    """The contact patch of each group of surface particles of ``model`` (a BodyModel;
    ``member_offsets`` (N+1,) CSR into ``members``, tet indices): the vertices of its members' boundary triangles, and
    their outward normal (see ``ContactPatches``). Numpy, one pass over the faces."""
    count = len(member_offsets) - 1
    group_of_tet = np.full(model.tet_count, -1, dtype=np.int64)
    group_of_tet[members] = np.repeat(np.arange(count), np.diff(member_offsets))
    face_group = group_of_tet[model.surface_face_tet]
    on = face_group >= 0
    faces, face_group = model.surface_faces[on].astype(np.int64), face_group[on]
    v_count = len(model.vertices)
    keys = np.unique((face_group[:, None] * v_count + faces).reshape(-1))
    offsets = np.zeros(count + 1, dtype=np.int64)
    np.cumsum(np.bincount(keys // v_count, minlength=count), out=offsets[1:])
    corners = model.vertices[faces]
    area_normal = 0.5 * np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    summed = np.stack([np.bincount(face_group, weights=area_normal[:, k], minlength=count) for k in range(3)], 1)
    area = np.bincount(face_group, weights=rows.norm(area_normal), minlength=count)
    length = rows.norm(summed)
    flat = length >= FLAT_ENOUGH * np.maximum(area, 1e-300)
    normals = np.where(flat[:, None], summed / np.where(flat, length, 1.0)[:, None], 0.0)
    return ContactPatches(offsets=offsets, points=model.vertices[keys % v_count], normals=normals)
