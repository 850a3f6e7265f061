"""The piece-geometry page's distances (surfaces/checks.py) and its floor, a perfect
flat cut of a body's tets (bench/perfect_cut.py), against closed forms on a box."""

import numpy as np
import trimesh

from benchmarks.perfect_cut import perfect_cut
from taichi_frac.surfaces.checks import outside_distance, signed_volume
from taichi_frac.surfaces.solid import render_solid_from_surface
from taichi_frac.geometry.topology import boundary_faces

from support.pieces import SIZE


def test_outside_distance_is_zero_inside_and_the_gap_outside():
    cube = trimesh.creation.box(extents=[1.0, 1.0, 1.0])
    points = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.8], [0.7, 0.7, 0.0], [0.2, -0.1, 0.45]])
    expected = [0.0, 0.3, np.hypot(0.2, 0.2), 0.0]
    np.testing.assert_allclose(outside_distance(points, cube.vertices, cube.faces), expected, atol=1e-12)


def test_boundary_faces_of_a_box_s_tets_are_closed_and_hold_their_volume(box):
    model, _, _ = box
    faces = boundary_faces(model.tets)[0]
    assert len(faces) == len(model.surface_faces)
    assert np.isclose(signed_volume(model.vertices, faces), model.tet_volume.sum(), rtol=1e-12)
    assert np.isclose(signed_volume(model.vertices, faces), np.prod(SIZE), rtol=1e-9)


def test_a_perfect_cut_leaves_the_tets_reaching_past_the_plane(box):
    """Plane x = d through the box: the render half is the box beyond d (its volume a closed
    form); the tets whose centroids lie beyond d reach back across the plane by exactly
    their boundary vertices' depth below it, at most 3/4 of a tet's extent along x."""
    model, report, _ = box
    solid = render_solid_from_surface(report.surface, model.com_in_source, model.spacing).solid
    d = float(np.median(model.particle_position[:, 0])) + 0.013
    cut = perfect_cut(model, solid, [(np.array([1.0, 0.0, 0.0]), d)])
    mine = model.particle_position[:, 0] >= d
    assert cut.tets == int(mine.sum())
    render_volume = (model.vertices[:, 0].max() - d) * SIZE[1] * SIZE[2]
    assert np.isclose(cut.volume_error, render_volume / model.tet_volume[mine].sum() - 1.0, atol=1e-9)
    corners = model.vertices[np.unique(boundary_faces(model.tets[mine])[0])]
    depth = np.max(d - corners[:, 0])
    assert np.isclose(cut.from_tets, depth / model.spacing, rtol=1e-9)
    x = model.vertices[model.tets[mine]][:, :, 0]
    assert depth <= 0.75 * np.max(x.max(axis=1) - x.min(axis=1)) + 1e-12
    # The render half's face on the plane lies inside the tets' union or beside it.
    assert 0.0 <= cut.to_tets < 2.0
