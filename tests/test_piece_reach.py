"""A piece's render solid kept within reach of its tets (surfaces/reach.py), checked on a
grid of tets whose union is a box: the distance to it has a closed form."""

from types import SimpleNamespace

import manifold3d as m3
import numpy as np

from taichi_frac.surfaces.reach import REACH_FACTOR, _ball, distance_to_tets, trim_overreach

#: The grid: unit cubes over [0, 8] x [0, 4] x [0, 4] [m], six tets each.
CELLS = (8, 4, 4)
#: The grown tets' hull lies within this factor of the reach (an icosahedron's circumradius
#: over its inradius).
BALL_BOUND = 1.26


def _grid():
    """(model, labels): the cubes' tets (Kuhn's six per cube, sharing the diagonal), piece 0
    the cubes with x < 3 and piece 1 the rest."""
    nx, ny, nz = CELLS
    index = np.arange((nx + 1) * (ny + 1) * (nz + 1)).reshape(nx + 1, ny + 1, nz + 1)
    vertices = np.stack(np.meshgrid(*(np.arange(n + 1.0) for n in CELLS), indexing="ij"), axis=-1).reshape(-1, 3)
    paths = [(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)]
    tets = []
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                for path in paths:
                    corner, tet = np.array([i, j, k]), [index[i, j, k]]
                    for axis in path:
                        corner = corner.copy()
                        corner[axis] += 1
                        tet.append(index[tuple(corner)])
                    tets.append(tet)
    tets = np.array(tets)
    centroids = vertices[tets].mean(axis=1)
    model = SimpleNamespace(vertices=vertices, tets=tets, particle_position=centroids)
    return model, (centroids[:, 0] > 3.0).astype(np.int64)


def _box_distance(points, low, high):
    """Closed form: each point's distance to the box [low, high]."""
    return np.linalg.norm(np.maximum(0.0, np.maximum(low - points, points - high)), axis=1)


def _box(low, high):
    low = np.asarray(low, dtype=np.float64)
    return m3.Manifold.cube(tuple(np.asarray(high, dtype=np.float64) - low)).translate(tuple(low))


def test_distance_to_tets_is_the_distance_to_their_union():
    model, _ = _grid()
    rng = np.random.default_rng(3)
    points = rng.uniform([-2.0, -2.0, -2.0], [10.0, 6.0, 6.0], size=(400, 3))
    corners = model.vertices[model.tets]
    measured = distance_to_tets(points, corners, model.particle_position)
    exact = _box_distance(points, np.zeros(3), np.array(CELLS, dtype=np.float64))
    assert np.allclose(measured, exact, atol=1e-9)


def test_a_flat_tet_holds_no_point():
    """A tet of no volume (four corners in a plane) is measured by its faces alone: a point
    a metre off its plane is a metre from it."""
    corners = np.array([[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [1.0, 1.0, 0.0]]])
    points = np.array([[0.2, 0.2, 0.5], [0.5, 0.5, -1.0]])
    measured = distance_to_tets(points, corners, corners.mean(axis=1))
    assert np.allclose(measured, [0.5, 1.0], atol=1e-12)


def test_ball_directions_span_the_unit_ball_within_the_bound():
    directions = _ball()
    hull = m3.Manifold.hull_points(np.ascontiguousarray(directions))
    # Every unit direction's support is at least 1 (the ball inside) and the corners reach
    # at most the bound.
    rng = np.random.default_rng(0)
    probe = rng.normal(size=(2000, 3))
    probe /= np.linalg.norm(probe, axis=1, keepdims=True)
    assert np.all((probe @ directions.T).max(axis=1) >= 1.0 - 1e-12)
    assert np.linalg.norm(directions, axis=1).max() <= BALL_BOUND
    assert hull.volume() > 4.0 / 3.0 * np.pi


def test_a_wedge_past_the_pieces_tets_is_cut_at_the_reach():
    """Piece 0's tets fill [0, 3] x [0, 4]^2 (spacing 1 here); its solid also has a spike of
    cross-section 0.5 x 0.5 running on to x = 7 through piece 1's tets. What lies past the
    reach (1.5 to 1.89 from x = 3) goes; the box and the spike's first 1.5 stay."""
    model, labels = _grid()
    spacing = 1.0
    reach = REACH_FACTOR * spacing
    spike = _box([2.0, 1.75, 1.75], [7.0, 2.25, 2.25])
    solid = _box([0.0, 0.0, 0.0], [3.0, 4.0, 4.0]) + spike
    trimmed, volume = trim_overreach(solid, model, labels, 0, spacing)
    mesh = trimmed.to_mesh()
    vertices = np.asarray(mesh.vert_properties)[:, :3]
    distance = _box_distance(vertices, np.zeros(3), np.array([3.0, 4.0, 4.0]))
    assert distance.max() <= BALL_BOUND * reach + 1e-9
    area = 0.25
    assert area * (4.0 - BALL_BOUND * reach) - 1e-9 <= volume <= area * (4.0 - reach) + 1e-9
    assert np.isclose(trimmed.volume(), solid.volume() - volume)
    # What lies within the reach is all kept.
    assert np.isclose((trimmed ^ _box([0.0, 0.0, 0.0], [3.0 + reach, 4.0, 4.0])).volume(),
                      (solid ^ _box([0.0, 0.0, 0.0], [3.0 + reach, 4.0, 4.0])).volume())
    assert len(trimmed.decompose()) == 1


def test_a_solid_within_reach_and_detail_past_every_tet_stay():
    model, labels = _grid()
    near = _box([0.0, 0.0, 0.0], [4.2, 4.0, 4.0])  # 1.2 past piece 0's tets: within reach
    same, volume = trim_overreach(near, model, labels, 0, 1.0)
    assert same is near and volume == 0.0
    # A horn out of the tets' union where no other piece's tets are (the artist's detail
    # the mesher left out) is not another piece's material: it stays.
    horn = _box([0.0, 0.0, 0.0], [3.0, 4.0, 4.0]) + _box([-4.0, 1.75, 1.75], [0.5, 2.25, 2.25])
    same, volume = trim_overreach(horn, model, labels, 0, 1.0)
    assert same is horn and volume == 0.0


def test_a_piece_mostly_past_its_tets_is_left_to_the_cuts_checks():
    """A solid lying wholly in the other piece's tets is not a wedge: the trim would take all
    of it, so the piece keeps it (the cut's own checks judge such a piece)."""
    from taichi_frac.surfaces.cut import _trimmed
    from taichi_frac.surfaces.solid import RenderSolid

    model, labels = _grid()
    astray = RenderSolid(_box([5.0, 1.0, 1.0], [7.0, 3.0, 3.0]), (), 1.0)
    wedged = RenderSolid(_box([0.0, 0.0, 0.0], [3.0, 4.0, 4.0]) + _box([2.0, 1.75, 1.75], [7.0, 2.25, 2.25]), (), 1.0)
    _, volume = trim_overreach(astray.solid, model, labels, 0, 1.0)
    assert volume > 0.5 * astray.solid.volume()
    pieces, stats = _trimmed([astray], {}, model, labels, np.zeros((1, 3)))
    assert pieces[0] is astray and stats["trimmed_pieces"] == 0
    pieces, stats = _trimmed([wedged], {}, model, labels, np.zeros((1, 3)))
    assert stats["trimmed_pieces"] == 1 and np.isclose(pieces[0].solid.volume(),
                                                       wedged.solid.volume() - stats["trimmed_volume"])


def test_centroid_trees_are_kept_per_set_and_answer_as_a_new_tree():
    """``surfaces.trees.centroid_tree``: the tree of a body's centroids, a piece's, or the
    rest's, each the same object when asked again with the same arrays, and answering as a
    KD-tree built afresh on that set (scipy's own, the reference); another labels array (a
    later split) gets trees of its own."""
    from types import SimpleNamespace

    from scipy.spatial import cKDTree

    from taichi_frac.surfaces.trees import centroid_tree

    rng = np.random.default_rng(3)
    model = SimpleNamespace(particle_position=rng.random((300, 3)))
    labels = rng.integers(0, 3, 300)
    probes = rng.random((50, 3))
    for args, kwargs, chosen in (((), {}, np.ones(300, bool)), ((labels, 1), {}, labels == 1),
                                 ((labels, 1), {"others": True}, labels != 1)):
        tree = centroid_tree(model, *args, **kwargs)
        assert centroid_tree(model, *args, **kwargs) is tree
        got, expected = tree.query(probes, k=3), cKDTree(model.particle_position[chosen]).query(probes, k=3)
        assert np.array_equal(got[1], expected[1]) and np.array_equal(got[0], expected[0])
    relabelled = (labels + 1) % 3
    tree = centroid_tree(model, relabelled, 1)
    assert tree is not centroid_tree(model, labels, 1)
    assert np.array_equal(tree.data, model.particle_position[relabelled == 1])
