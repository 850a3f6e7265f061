"""Input shading (normals, UVs) carried onto tet boundary faces and onto fragments."""

from __future__ import annotations

import numpy as np
import trimesh

from taichi_frac.geometry import primitives
from taichi_frac.geometry.prepare import prepare_body
from taichi_frac.geometry.surface_attributes import boundary_corner_attributes
from taichi_frac.surfaces.mesh import fragment_surface, surface_corner_attributes
from taichi_frac.model import build_body_model
from taichi_frac.options import ParticleOptions


def _root_corners(model):
    return model.vertices[model.surface_faces] + model.com_in_source


def test_box_keeps_sharp_edges_and_linear_uvs_exactly():
    surface = primitives.box((0.4, 0.3, 0.2))
    # UVs linear in position: barycentric interpolation must reproduce them exactly.
    uv = surface.vertices[:, :2] * np.array([2.0, 3.0]) + 0.5
    surface.visual = trimesh.visual.TextureVisuals(uv=uv)
    model, report = prepare_body(surface, particles=ParticleOptions(target_particles=800), use_cache=False)
    corners = _root_corners(model)
    normals, uvs = boundary_corner_attributes(report.surface, corners)
    # Every corner normal of a box is one of the six axis directions, however the mesher
    # split the faces: creases at 90 degrees are never smoothed.
    assert np.allclose(np.abs(normals).max(axis=2), 1.0, atol=1e-9)
    face_normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    face_normal /= np.linalg.norm(face_normal, axis=1, keepdims=True)
    assert np.all(np.einsum("fck,fk->fc", normals, face_normal) > 1 - 1e-9)
    expected_uv = corners[:, :, :2] * np.array([2.0, 3.0]) + 0.5
    assert np.allclose(uvs, expected_uv, atol=1e-9)


def test_torus_normals_follow_the_smooth_surface():
    model, report = prepare_body("torus:major=0.1,minor=0.025", particles=ParticleOptions(target_particles=3000))
    corners = _root_corners(model)
    normals, _ = boundary_corner_attributes(report.surface, corners)
    # Exact normal of a torus about Z: from the nearest point of the core circle.
    p = corners.reshape(-1, 3)
    core = np.concatenate([p[:, :2] / np.linalg.norm(p[:, :2], axis=1, keepdims=True) * 0.1,
                           np.zeros((len(p), 1))], axis=1)
    exact = (p - core) / np.linalg.norm(p - core, axis=1, keepdims=True)
    angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", normals.reshape(-1, 3), exact), -1, 1)))
    # Smoothed corner normals are far closer to the exact normal than the facets are.
    face_normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    face_normal = np.repeat(face_normal / np.linalg.norm(face_normal, axis=1, keepdims=True), 3, axis=0)
    facet_angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", face_normal, exact), -1, 1)))
    assert np.percentile(angle, 95) < 3.0
    assert np.mean(angle) < 0.5 * np.mean(facet_angle)


def test_fragment_outer_faces_inherit_and_crack_faces_do_not():
    surface = primitives.box((0.4, 0.3, 0.2))
    root, report = prepare_body(surface, particles=ParticleOptions(target_particles=800), use_cache=False)
    root_normals, _ = boundary_corner_attributes(report.surface, _root_corners(root))
    half = np.nonzero(root.particle_position[:, 0] < 0.0)[0]
    piece = build_body_model(root.vertices, root.tets[half], root.density, source_tet=root.source_tet[half])
    _, faces, inner = fragment_surface(piece, root)
    normals, uvs = surface_corner_attributes(piece, root, root_normals)
    assert uvs is None
    assert inner.any() and (~inner).any()
    assert np.all(np.isnan(normals[inner]))
    outer = normals[~inner]
    assert np.allclose(np.abs(outer).max(axis=2), 1.0, atol=1e-9)
    corners = piece.vertices[faces[~inner]]
    face_normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    face_normal /= np.linalg.norm(face_normal, axis=1, keepdims=True)
    # Corners were matched in the right order: each corner normal agrees with its face.
    assert np.all(np.einsum("fck,fk->fc", outer, face_normal) > 1 - 1e-9)
