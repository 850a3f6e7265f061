"""The contact patch behind each collision sphere: the true surface its contacts are
computed from (``collision/surface.py``), built once per body from its boundary faces."""

from __future__ import annotations

import weakref
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
        facets: (N, MAX_FACETS, 3) unit outward normals of the planes a patch's triangles
            lie in: its normal alone where it has one; for a patch folded round a block's
            edge or corner, the area-weighted normal of each group of its triangles within
            ``FACET_ANGLE`` of each other (two or three: the faces it spans); zeros where
            its triangles need more planes than ``MAX_FACETS`` (a chip's closed surface, a
            curved piece) and in the unused rows.
    """

    offsets: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    facets: np.ndarray


#: A patch has a normal when its triangles' summed area normal is at least this fraction of
#: their total area (a patch spanning 45 degrees of a tube: 0.97; one folded over a cube's
#: edge: 0.71; a closed tet: 0). A folded patch's mean normal is no face's: a chip landing
#: beside the edge was pushed along it into the body.
FLAT_ENOUGH = 0.9

#: Planes a folded patch may span and keep its facets (``ContactPatches.facets``): a block's
#: edge (two faces) or corner (three). A one-tet chip's four faces are more: it faces every
#: way, and meets a body on the body's patch (``collision.surface.pair``).
MAX_FACETS = 3

#: Triangles whose normals are within this angle [rad] of a facet's first (largest)
#: triangle's lie in that facet (``ContactPatches.facets``): a tet mesh's faces of one flat
#: side are coplanar to rounding.
FACET_ANGLE = 0.1


def contact_patches(model, member_offsets: np.ndarray, members: np.ndarray) -> ContactPatches:
    """The contact patch of each group of surface particles of ``model`` (a BodyModel;
    ``member_offsets`` (N+1,) CSR into ``members``, tet indices): the vertices of its members' boundary triangles, and
    their outward normal (see ``ContactPatches``). Numpy, one pass over the faces."""
    return contact_patches_many([(model, member_offsets, members)])[0]


def contact_patches_many(groups) -> list[ContactPatches]:
    """``contact_patches`` of each (model, member_offsets, members) of ``groups`` in one
    numpy pass over all their faces: the same arrays as one call each (every sum runs over
    one patch's faces in the same order), at a fraction of the calls' numpy overhead
    (a fracture adds several small fragments at once)."""
    counts = [len(offsets) - 1 for _, offsets, _ in groups]
    group_start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    tet_start = np.concatenate([[0], np.cumsum([m.tet_count for m, _, _ in groups])]).astype(np.int64)
    vertex_start = np.concatenate([[0], np.cumsum([len(m.vertices) for m, _, _ in groups])]).astype(np.int64)
    count, v_count = int(group_start[-1]), int(vertex_start[-1])
    group_of_tet = np.full(int(tet_start[-1]), -1, dtype=np.int64)
    for k, (_, member_offsets, members) in enumerate(groups):
        group_of_tet[tet_start[k] + members] = group_start[k] + np.repeat(np.arange(counts[k]), np.diff(member_offsets))
    face_group = group_of_tet[np.concatenate([tet_start[k] + m.surface_face_tet for k, (m, _, _) in enumerate(groups)])]
    all_faces = np.concatenate([vertex_start[k] + m.surface_faces.astype(np.int64) for k, (m, _, _) in enumerate(groups)])
    vertices = np.concatenate([m.vertices for m, _, _ in groups])
    on = face_group >= 0
    faces, face_group = all_faces[on], face_group[on]
    keys = np.unique((face_group[:, None] * v_count + faces).reshape(-1))
    offsets = np.zeros(count + 1, dtype=np.int64)
    np.cumsum(np.bincount(keys // v_count, minlength=count), out=offsets[1:])
    corners = vertices[faces]
    area_normal = 0.5 * np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    summed = np.stack([np.bincount(face_group, weights=area_normal[:, k], minlength=count) for k in range(3)], 1)
    area = np.bincount(face_group, weights=rows.norm(area_normal), minlength=count)
    length = rows.norm(summed)
    flat = length >= FLAT_ENOUGH * np.maximum(area, 1e-300)
    normals = np.where(flat[:, None], summed / np.where(flat, length, 1.0)[:, None], 0.0)
    facets = np.zeros((count, MAX_FACETS, 3))
    facets[:, 0] = normals
    folded = ~flat & (area > 0.0)
    on_folded = folded[face_group]
    if on_folded.any():
        facets[folded] = _facets(face_group[on_folded], area_normal[on_folded])[np.flatnonzero(folded)]
    points = vertices[keys % v_count]
    out = []
    for k in range(len(groups)):
        g0, g1 = group_start[k], group_start[k + 1]
        out.append(ContactPatches(offsets=offsets[g0:g1 + 1] - offsets[g0], points=points[offsets[g0]:offsets[g1]],
                                  normals=normals[g0:g1], facets=facets[g0:g1]))
    return out


def _facets(group: np.ndarray, area_normal: np.ndarray) -> np.ndarray:
    """(G, MAX_FACETS, 3) the facets of folded patches from their triangles' groups (T,)
    (G: one more than the largest) and area normals (T,3): in each patch, the largest
    triangle not yet in a facet and every such triangle within ``FACET_ANGLE`` of it make
    the next facet, its summed area normal normalised; all zeros where triangles remain
    after ``MAX_FACETS`` facets. Every patch at once, a pass a facet."""
    size = rows.norm(area_normal)
    order = np.lexsort((-size, group))
    group, area_normal, size = group[order], area_normal[order], size[order]
    unit = area_normal / np.maximum(size, 1e-300)[:, None]
    count = int(group.max()) + 1
    starts = np.searchsorted(group, np.arange(count))
    ends = np.searchsorted(group, np.arange(count), side="right")
    present = ends > starts
    index = np.arange(len(group))
    left = np.ones(len(group), dtype=bool)
    out = np.zeros((count, MAX_FACETS + 1, 3))
    for k in range(MAX_FACETS + 1):
        # The first (largest) triangle left in each patch, or none (past its end).
        first = np.minimum.reduceat(np.where(left, index, len(group)), np.minimum(starts, len(group) - 1))
        has = present & (first < ends)
        leader = np.zeros((count, 3))
        leader[has] = unit[first[has]]
        member = left & has[group] & (np.einsum("ij,ij->i", unit, leader[group]) >= np.cos(FACET_ANGLE))
        for d in range(3):
            out[:, k, d] = np.bincount(group[member], weights=area_normal[member, d], minlength=count)
        left &= ~member
    out[np.any(out[:, MAX_FACETS] != 0.0, axis=1)] = 0.0
    length = rows.norm(out.reshape(-1, 3)).reshape(count, MAX_FACETS + 1)
    out /= np.maximum(length, 1e-300)[:, :, None]
    return out[:, :MAX_FACETS]


# (model, single) -> ContactPatches: each live model's patches, dropped with the model, so
# a model stays as built and bodies made from one model share its patches.
_PATCHES: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def patch_groups(model, single: bool):
    """(model, member offsets, members) of the single-scale layer's patches (``single``: one
    per surface particle) or the boundary spheres': what ``contact_patches`` takes."""
    if single:
        return model, np.arange(len(model.surface_particles) + 1), model.surface_particles
    return model, model.boundary_member_offsets, model.boundary_members


def patches_of(models, single: bool) -> list:
    """Each ``model.BodyModel``'s patches: its surface particles' (``single``) or its boundary
    spheres'. Those not computed yet are computed in one ``contact_patches_many`` pass (the
    same arrays as one call each) and kept while their models live."""
    missing = list({id(m): m for m in models if single not in _PATCHES.get(m, ())}.values())
    if missing:
        for model, patches in zip(missing, contact_patches_many([patch_groups(m, single) for m in missing])):
            _PATCHES.setdefault(model, {})[single] = patches
    return [_PATCHES[m][single] for m in models]
