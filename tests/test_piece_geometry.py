"""Render surfaces of broken pieces (surfaces/cut.py) against closed-form cuts of a
box, and the checks (surfaces/checks.py) on the paper's bodies and a shared mesh. The
crack fit's own tests are in test_crack_fit.py."""

import dataclasses
import functools
from pathlib import Path

import manifold3d as m3
import numpy as np
import pytest
import trimesh

from taichi_frac.fracture.cracks import CrackPlane, RingCrack, analyze_impact, tangent_frame
from taichi_frac.fracture.fragments import make_fragments, split_body
from taichi_frac.surfaces.crack_fit import FITTED_PIECE_TETS
from taichi_frac.surfaces.checks import crack_deviation, edge_counts, inside, piece_quality, signed_volume
from taichi_frac.surfaces.parts import LOST_VOLUME_SHARE
from taichi_frac.surfaces.reach import BALL_BOUND, REACH_FACTOR
from taichi_frac.surfaces.cut import cut_render_solid
from taichi_frac.surfaces.mesh import piece_mesh
from taichi_frac.surfaces.solid import render_solid_from_surface
from taichi_frac.geometry.prepare import prepare_body
from taichi_frac.options import FractureOptions, material_preset
from taichi_frac.scenes import BUILTIN_SCENE_DIR as SCENES

from support.pieces import PARTICLES, SIZE, assert_closed, split_and_cut, uv_of

REPO = Path(__file__).resolve().parents[1]
SHARED_MESHES = REPO.parent / "shared" / "meshes"


def test_edge_counts_and_inside_catch_broken_meshes():
    tetra = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    assert edge_counts(tetra) == dict(edges=6, open_edges=0, nonmanifold_edges=0, misoriented_edges=0)
    flipped = tetra.copy()
    flipped[0] = flipped[0, ::-1]
    assert edge_counts(flipped)["misoriented_edges"] == 3
    assert edge_counts(tetra[:3])["open_edges"] == 3
    fin = np.concatenate([tetra, [[0, 1, 4]]])  # a third face on edge (0, 1)
    assert edge_counts(fin)["nonmanifold_edges"] == 1
    cube = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    points = np.array([[0.0, 0.0, 0.0], [0.49, -0.49, 0.3], [0.51, 0.0, 0.0], [0.0, 0.0, -0.6]])
    np.testing.assert_array_equal(inside(points, cube.triangles), [True, True, False, False])
    # A sphere of 5,120 triangles against its radius, away from the facets' band (their
    # chords lie within 0.2 % of the radius), and no points or no triangles.
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    probes = np.random.default_rng(3).uniform(-1.5, 1.5, size=(2000, 3))
    radius = np.linalg.norm(probes, axis=1)
    clear = np.abs(radius - 1.0) > 0.01
    np.testing.assert_array_equal(inside(probes[clear], sphere.triangles), radius[clear] < 1.0)
    assert inside(np.zeros((0, 3)), sphere.triangles).shape == (0,)
    assert not inside(points, np.zeros((0, 3, 3))).any()


def test_voronoi_cells_union_is_the_region_nearest_those_points():
    """The union of some points' Voronoi cells, built from the diagram's ridges as one mesh,
    is a closed manifold holding exactly the space nearer those points than the others:
    against a nearest-neighbour count of 20,000 random samples in a box (three standard
    errors), and the probes' inside test against the winding number on the same samples."""
    import manifold3d as m3
    from scipy.spatial import cKDTree

    from taichi_frac.surfaces.parts import _inside_solid
    from taichi_frac.surfaces.tet_cells import voronoi_cells

    rng = np.random.default_rng(3)
    points = rng.uniform(-1.0, 1.0, size=(400, 3))
    chosen = np.nonzero(np.linalg.norm(points - [0.3, 0.0, 0.0], axis=1) < 0.6)[0]
    union = voronoi_cells(points, 0.2).union(chosen)
    assert union is not None and union.status() == m3.Error.NoError and union.genus() >= 0
    box = m3.Manifold.cube((1.6, 1.6, 1.6), center=True)
    samples = rng.uniform(-0.8, 0.8, size=(20000, 3))
    nearest_chosen = np.isin(cKDTree(points).query(samples)[1], chosen)
    share = float(nearest_chosen.mean())
    error = 3.0 * np.sqrt(share * (1 - share) / len(samples))
    assert (union ^ box).volume() / 1.6**3 == pytest.approx(share, abs=error)
    mesh = (union ^ box).to_mesh64()
    triangles = np.asarray(mesh.vert_properties)[:, :3][np.asarray(mesh.tri_verts, dtype=np.int64)]
    probe = samples[:300]
    np.testing.assert_array_equal(_inside_solid(probe, union ^ box, 1e-4), inside(probe, triangles))


def test_a_pieces_own_cells_asked_again_are_built_anew_from_the_kept_diagram():
    """``own_cells`` keeps the diagram for the same centroids, labels and pool (each pass of a
    split's crack fit asks again) and builds a new manifold from it each time (the boolean
    library numbers each solid it builds, and a cut's bytes follow those numbers): the same
    mesh, byte for byte, as asked with nothing kept, and a solid of its own each time."""
    from types import SimpleNamespace

    from taichi_frac.surfaces import tet_cells

    rng = np.random.default_rng(5)
    model = SimpleNamespace(particle_position=rng.uniform(-1.0, 1.0, size=(300, 3)))
    labels = (model.particle_position[:, 0] > 0.2).astype(np.int64)
    pool = np.arange(300)

    def mesh_bytes(solid):
        mesh = solid.to_mesh64()
        return np.asarray(mesh.vert_properties).tobytes(), np.asarray(mesh.tri_verts).tobytes()

    tet_cells._OWN_CELLS.clear()
    first = tet_cells.own_cells(model, labels, 1, 0.1, pool)
    again = tet_cells.own_cells(model, labels, 1, 0.1, pool)
    tet_cells._OWN_CELLS.clear()
    fresh = tet_cells.own_cells(model, labels, 1, 0.1, pool)
    assert first is not None and again is not first
    assert mesh_bytes(again) == mesh_bytes(first) == mesh_bytes(fresh)
    other = tet_cells.own_cells(model, labels, 0, 0.1, pool)  # (another piece: its own cells)
    assert other.volume() > 0.0 and mesh_bytes(other) != mesh_bytes(first)


def test_inside_solid_answers_as_its_probes_do_near_and_far_from_the_surface():
    """The inside test of the cells' divide reads the winding number away from the surface and
    cuts its probe tetrahedra only near it: against the probes everywhere, on points at a
    tenth to three times the probe's size inside and outside a box's large faces (the
    nearest vertex far away), where a probe partly outside still meets the solid."""
    import manifold3d as m3

    from taichi_frac.surfaces.parts import _inside_solid, _probed_inside

    size = 0.05
    box = m3.Manifold.cube((1.0, 1.0, 1.0), center=True)
    rng = np.random.default_rng(11)
    offsets = np.array([-3.0, -1.2, -0.8, -0.4, -0.1, 0.1, 0.4, 0.8, 1.2, 3.0]) * size
    face = rng.uniform(-0.3, 0.3, size=(len(offsets), 2))
    points = np.column_stack([face, 0.5 + offsets])  # (by the top face: +z outside)
    probed = _probed_inside(points, box, size)
    np.testing.assert_array_equal(_inside_solid(points, box, size), probed)
    # (a probe's corners reach half its size along each axis: those within it outside still
    # meet the box)
    np.testing.assert_array_equal(probed, offsets < 0.5 * size)
    assert _inside_solid(np.zeros((0, 3)), box, size).shape == (0,)


def test_face_with_corners_of_two_origins_gets_the_crack_it_lies_on():
    """Hand-made faces whose corners carry different crack indices (as exact booleans leave
    them where a cut meets a face): a face on crack 0's plane gets 0, one on crack 1's plane
    (corners -1, 1, 0) gets 1, one on neither gets the artist's surface (-1), one with a hull
    corner and on no crack the hull's index."""
    from taichi_frac.surfaces.mesh import _face_cracks
    from taichi_frac.surfaces.layout import HULL_FACE
    from taichi_frac.surfaces.solid import CrackSurface

    spacing = 0.01
    cracks = (CrackSurface(np.zeros(3), np.array([0.0, 0.0, 1.0])), CrackSurface(np.zeros(3), np.array([1.0, 0.0, 0.0])))
    on_z = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]])
    on_x = np.array([[0.0, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.1]])
    off = on_z + np.array([0.0, 0.0, 0.5 * spacing])  # half a spacing off crack 0: not on it
    corners = np.array([[0, 0, 0], [-1, 0, -1], [-1, 1, 0], [-1, 0, 1], [HULL_FACE, 0, -1]])
    triangles = np.stack([on_z, on_z, on_x, off, off])
    np.testing.assert_array_equal(_face_cracks(corners, triangles, cracks, spacing), [0, 0, 1, -1, HULL_FACE])


def test_a_sliver_with_no_uv_takes_its_nearest_corner_s():
    """Hand-made: an outer sliver whose corners the booleans left without UVs (NaN) takes,
    corner by corner, the UV of the nearest outer corner that has one; an inner face's
    NaN corners stay (their UVs come from their crack)."""
    from taichi_frac.surfaces.mesh import _outer_uvs

    triangles = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]],
                          [[1.0, 0, 1e-9], [0, 1, 1e-9], [0.5, 0.5, 0]],
                          [[5.0, 5, 5], [6, 5, 5], [5, 6, 5]]])
    uvs = np.array([[[0.1, 0.2], [0.3, 0.4], [0.5, 0.6]],
                    [[np.nan, np.nan], [np.nan, np.nan], [0.9, 0.9]],
                    [[np.nan, np.nan], [np.nan, np.nan], [np.nan, np.nan]]])
    out = _outer_uvs(uvs, triangles, np.array([True, True, False]))
    np.testing.assert_allclose(out[1], [[0.3, 0.4], [0.5, 0.6], [0.9, 0.9]])
    np.testing.assert_allclose(out[0], uvs[0])
    assert np.isnan(out[2]).all()


def test_a_slab_runs_past_the_halfway_line_whole_or_in_stretches():
    """Hand-computed: on the plane z = 0, cut crossings along x = 0 (two stretches, y < 0
    and y > 0) and crossings it did not cut along x = 2 (spacing 1): the slab's edge lies
    on the halfway line x = 1 moved SLAB_PAST_FACTOR further, for the whole slab and for
    the union of its stretches alike."""
    from taichi_frac.surfaces.slabs import SLAB_PAST_FACTOR, plane_slab, segment_slabs
    from taichi_frac.surfaces.solid import CrackSurface

    crack = CrackSurface(np.zeros(3), np.array([0.0, 0.0, 1.0]))
    ys = np.arange(-5.0, 6.0)
    sites = np.concatenate([np.stack([np.zeros_like(ys), ys, np.zeros_like(ys)], axis=1),
                            np.stack([np.full_like(ys, 2.0), ys, np.zeros_like(ys)], axis=1)])
    cut = np.arange(len(sites)) < len(ys)
    edge = 1.0 + SLAB_PAST_FACTOR

    def covers(solid, x):
        point = x * np.array([1.0, 0.0, 0.0])  # along the body's x
        probe = m3.Manifold.cube((1e-3, 1e-3, 1e-3), True).translate(tuple(point))
        return (solid ^ probe).volume() > 0

    whole = plane_slab(crack, sites, cut, 1.0, 0.0, 1.0, 0, 0, past=SLAB_PAST_FACTOR)
    assert covers(whole, edge - 0.05) and not covers(whole, edge + 0.05)
    segment = np.where(cut, (sites[:, 1] > 0).astype(np.int64), -1)
    parts, wall = segment_slabs(crack, sites, cut, segment, np.array([1e-3, 2e-3]), 1.0)
    union = m3.Manifold.batch_boolean([slab for _, slab in parts], m3.OpType.Add)
    # (the stretches lie a hair above z = 0: probe at their heights)
    for x in (edge - 0.05, edge + 0.05):
        probe = m3.Manifold.cube((1e-3, 1e-3, 1e-2), True).translate((x, 3.0, 0.0))
        assert ((union ^ probe).volume() > 0) == (x < edge)
    assert wall is not None and len(parts) == 2


def test_one_plane_cuts_the_box_exactly(box):
    model, report, surface = box
    render = render_solid_from_surface(report.surface, model.com_in_source, model.spacing)
    normal = np.array([1.0, 0.3, 0.1]) / np.linalg.norm([1.0, 0.3, 0.1])
    point = np.array([0.02, 0.0, 0.0]) - model.com_in_source  # body frame
    crack = CrackPlane(point=point, normal=normal, extent=1.0, peak_stress=1.0)
    pieces, renders, counts = split_and_cut(model, render, [crack], fit_rounds=0)
    assert len(pieces) == 2 and counts["slabs"] == 1 and counts["carved_pieces"] == 0
    # Closed form: the volume of the box [0, L] below the plane n.x = t (n > 0) is
    # sum over corners e of (-1)^|e| max(0, t - n.(e L))^3 / (6 n1 n2 n3) (inclusion-exclusion).
    plane_origin = point + model.com_in_source
    t = normal @ (plane_origin + SIZE / 2)
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    below = sum((-1.0) ** e.sum() * max(0.0, t - normal @ (e * SIZE)) ** 3 for e in corners) / (6 * np.prod(normal))
    expected = {True: np.prod(SIZE) - below, False: below}
    thickness = 2e-4 * model.spacing
    for piece, solid in zip(pieces, renders):
        mesh = piece_mesh(solid)
        assert_closed(mesh)
        world = mesh.vertices + piece.model.com_in_source + model.com_in_source  # source frame
        side = bool((piece.model.com_in_source - point) @ normal > 0)
        # Each piece loses half a slab: volume within half a slab of the closed form.
        section = np.prod(SIZE) / SIZE[0] * 1.2  # > the plane's section area
        assert abs(signed_volume(mesh.vertices, mesh.faces) - expected[side]) < 0.5 * thickness * section + 1e-12
        # Crack faces lie on the plane (half a slab off it) ...
        assert crack_deviation(mesh.vertices, mesh.faces, mesh.face_is_inner, mesh.face_crack,
                               mesh.cracks) == pytest.approx(0.5 * thickness, rel=1e-3)
        # ... with UVs projected along it, and their normals its own, outward.
        inner = mesh.face_is_inner
        corners = world[mesh.faces[inner]] - plane_origin
        e1, e2 = tangent_frame(normal)
        np.testing.assert_allclose(mesh.uvs[inner], np.stack([corners @ e1, corners @ e2], axis=2), atol=1e-9)
        np.testing.assert_allclose(mesh.normals[inner] @ normal, -1.0 if side else 1.0, atol=1e-9)
        # Outer faces: the box's surface, its UVs (linear in position) and its flat normals.
        outer = world[mesh.faces[~inner]]
        on_box = np.isclose(np.abs(outer), SIZE / 2, atol=1e-9).any(axis=2)
        assert on_box.all()
        np.testing.assert_allclose(mesh.uvs[~inner].reshape(-1, 2), uv_of(outer.reshape(-1, 3)), atol=1e-9)
        axis_normal = np.isclose(np.abs(mesh.normals[~inner]), 1.0, atol=1e-9).any(axis=2)
        assert axis_normal.all()
        quality = piece_quality(mesh, piece.model)
        assert abs(quality["volume_error"]) < 0.02 and quality["shells"] == 1


def test_finite_crack_and_ring_crack_make_closed_pieces_and_cut_again(box):
    """A crack that runs part-way (a slit, the piece stays whole) beside one that runs
    through, then a ring crack cutting a piece again: every piece closed, volumes add up."""
    model, report, _ = box
    render = render_solid_from_surface(report.surface, model.com_in_source, model.spacing)
    through = CrackPlane(point=np.zeros(3), normal=np.array([1.0, 0.0, 0.0]), extent=1.0, peak_stress=1.0)
    partial = CrackPlane(point=np.array([0.05, -0.05, 0.0]), normal=np.array([0.0, 1.0, 0.0]), extent=0.04,
                         peak_stress=1.0)
    pieces, renders, counts = split_and_cut(model, render, [through, partial])
    assert len(pieces) == 2 and all(r is not None for r in renders)
    total = 0.0
    for piece, solid in zip(pieces, renders):
        mesh = piece_mesh(solid)
        assert_closed(mesh)
        total += signed_volume(mesh.vertices, mesh.faces)
        assert abs(piece_quality(mesh, piece.model)["volume_error"]) < 0.02
    assert total == pytest.approx(np.prod(SIZE), rel=1e-3)

    # The first piece breaks again, by a ring crack about one of its corners.
    piece = pieces[0]
    corner = piece.model.vertices.min(axis=0)
    ring = RingCrack(point=corner, radius=0.04, peak_stress=1.0)
    parent_volume = renders[0].solid.volume()
    children, child_renders, _ = split_and_cut(piece.model, renders[0], [ring])
    assert len(children) >= 2
    volumes = []
    for child, solid in zip(children, child_renders):
        mesh = piece_mesh(solid)
        assert_closed(mesh)
        volumes.append(signed_volume(mesh.vertices, mesh.faces))
        deviation = crack_deviation(mesh.vertices, mesh.faces, mesh.face_is_inner, mesh.face_crack, mesh.cracks)
        assert deviation < 0.05 * model.spacing  # the sphere's polygon: within its sagitta bound
    assert sum(volumes) == pytest.approx(parent_volume, rel=1e-3)
    # Every generation's pieces are fitted to the unbroken box's render-to-tets volume ratio,
    # not to their parent's (which carries its own cut's misfit).
    root_scale = render.solid.volume() / model.volume
    assert render.volume_scale is None and root_scale != pytest.approx(parent_volume / piece.model.volume, abs=1e-9)
    for solid in (*renders, *child_renders):
        assert solid.volume_scale == pytest.approx(root_scale, rel=1e-12)


@pytest.mark.parametrize("bead", [True, False], ids=["keeps-a-chip", "keeps-nothing"])
def test_a_piece_the_wall_gap_loses_is_carved_from_its_neighbour(box, bead):
    """Where the slabs leave a gap in the wall between two pieces, the part on both sides
    goes to one of them and the other keeps only a chip (here a bead of the artist's surface
    beside it, a separate shell) or nothing: the lost piece is carved out of that part along
    its tets' nearest-centroid cells, the rest stays with the other. Three pieces of the box: A (x <
    0), B (0 < x < 0.04), C (x > 0.04); the wall between A and B gets no slab. Closed form:
    A and B together fill the box up to C's crack face (x = 0.04 and half a slab; the bead
    is a crumb), C keeps its cut; A and B each lie within a cell (a spacing) of their tets'
    volume across the box's section; their faces between each other lie on no crack
    (HULL_FACE), B's against C on C's crack face."""
    from taichi_frac.surfaces.layout import HULL_FACE

    model, report, _ = box
    spacing = model.spacing
    side = 0.5 * spacing
    chip = trimesh.creation.box(extents=(side, side, side))
    chip.apply_translation([0.02, SIZE[1] / 2 + 0.3 * spacing + side / 2, 0.0])
    surface = trimesh.util.concatenate([report.surface, chip]) if bead else report.surface
    render = render_solid_from_surface(surface, model.com_in_source, model.spacing)
    x_axis = np.array([1.0, 0.0, 0.0])
    walls = [CrackPlane(point=np.array([x, 0.0, 0.0]) - model.com_in_source, normal=x_axis, extent=1.0,
                        peak_stress=1.0) for x in (0.0, 0.04)]
    split = split_body(model, walls, FractureOptions())
    pieces = make_fragments(model, split, np.zeros(3), [1.0, 0.0, 0.0, 0.0], np.zeros(3), np.zeros(3), None,
                            PARTICLES, options=FractureOptions())
    assert len(pieces) == 3
    leaky = [dataclasses.replace(walls[0], extent=1e-9), walls[1]]  # cuts no bond: no slab
    renders, counts = cut_render_solid(render, model, split.fragment_tets, leaky,
                                       [p.model.com_in_source for p in pieces])
    assert counts["fallback_pieces"] == 0 and counts["carved_pieces"] == 1
    a, b, c = (pieces[i] for i in np.argsort([p.model.com_in_source[0] for p in pieces]))
    mesh = {id(p): piece_mesh(r) for p, r in zip(pieces, renders)}
    volume = {}
    for piece in (a, b, c):
        assert_closed(mesh[id(piece)])
        volume[id(piece)] = signed_volume(mesh[id(piece)].vertices, mesh[id(piece)].faces)
    section = SIZE[1] * SIZE[2]
    half_slab = 1e-4 * spacing
    assert volume[id(c)] == pytest.approx((SIZE[0] / 2 - 0.04 - half_slab) * section, rel=1e-6)
    # (the bead, a separate shell under a tet's volume, is dropped as a crumb; so are the
    # bits under a tet's volume the cells' faces cut off the part: 1.3e-5 of it)
    assert volume[id(a)] + volume[id(b)] == pytest.approx((SIZE[0] / 2 + 0.04 + half_slab) * section, rel=1e-4)
    for piece in (a, b):
        assert abs(volume[id(piece)] - piece.model.volume) < spacing * section
        faces = mesh[id(piece)]
        assert (faces.face_crack == HULL_FACE).any()
    assert (mesh[id(b)].face_crack >= 0).any()  # its face against C is C's crack face
    # B is carved against A's tets alone: its face against C is the whole of C's crack
    # face, with no layer of the tets' staircase cut off beside it (drawn against every
    # tet, C's too, the cells cut B short of it).
    layer = m3.Manifold.cube((spacing, SIZE[1] + 1.0, SIZE[2] + 1.0)).translate(
        (0.04 - spacing, -SIZE[1] / 2 - 0.5, -SIZE[2] / 2 - 0.5))
    beside = renders[pieces.index(b)].solid.translate(tuple(b.model.com_in_source + model.com_in_source)) ^ layer
    assert beside.volume() == pytest.approx((spacing - half_slab) * section, rel=1e-6)


def test_a_large_piece_partly_held_by_its_neighbour_gets_the_rest_carved_back(box):
    """Three pieces of the box: A (x < 0), B (0 < x < 0.04, about 300 tets), C (x > 0.04).
    The cut's parts (built by hand): A's holds A and B's lower 30 % (y < -0.02: a gap in the
    wall between them), B's the rest of B, C's C. B, with 70 % of its tets' volume, has the
    rest carved out of A's part along its tets' nearest-centroid cells. Closed form: B then
    holds its tets' volume to within a cell (a spacing) over the carved face (0.03 m by the
    box's height), and the parts still fill the box (nothing is lost)."""
    from taichi_frac.surfaces.parts import PARTLY_LOST_SHARE, PARTLY_LOST_TETS, carve_lost_pieces

    model, _, _ = box
    spacing = model.spacing
    x_axis = np.array([1.0, 0.0, 0.0])
    walls = [CrackPlane(point=np.array([x, 0.0, 0.0]) - model.com_in_source, normal=x_axis, extent=1.0,
                        peak_stress=1.0) for x in (0.0, 0.04)]
    split = split_body(model, walls, FractureOptions())
    a, b, c = np.argsort([model.particle_position[np.asarray(t)].mean(axis=0)[0] for t in split.fragment_tets])
    assert len(split.fragment_tets[b]) >= PARTLY_LOST_TETS
    labels = np.full(model.tet_count, -1)
    for k, tets in enumerate(split.fragment_tets):
        labels[np.asarray(tets)] = k
    low, high = -SIZE / 2 - model.com_in_source, SIZE / 2 - model.com_in_source

    def block(x0, x1, y0, y1):  # (body frame; x, y given in the source frame)
        lo = np.array([x0, y0, -SIZE[2] / 2]) - model.com_in_source
        hi = np.array([x1, y1, SIZE[2] / 2]) - model.com_in_source
        return m3.Manifold.cube(tuple(hi - lo)).translate(tuple(lo))

    half = SIZE / 2
    parts = [block(-half[0], 0.0, -half[1], half[1]) + block(0.0, 0.04, -half[1], -0.02),
             block(0.0, 0.04, -0.02, half[1]), block(0.04, half[0], -half[1], half[1])]
    owner = [int(a), int(b), int(c)]
    share = parts[1].volume() / float(model.tet_volume[np.asarray(split.fragment_tets[b])].sum())
    assert 0.5 < share < PARTLY_LOST_SHARE  # (not lost, only partly)
    parts, owner = carve_lost_pieces(parts, owner, model, split.fragment_tets, labels, spacing)
    owner = [-(o + 2) if o < -1 else o for o in owner]
    held = sum(p.volume() for p, o in zip(parts, owner) if o == b)
    tets_volume = float(model.tet_volume[np.asarray(split.fragment_tets[b])].sum())
    assert abs(held - tets_volume) < spacing * 0.03 * SIZE[2]
    assert sum(p.volume() for p in parts) == pytest.approx(float(np.prod(high - low)), rel=1e-6)


def test_failed_pieces_get_the_solid_nearest_their_tets_less_the_others_parts(box):
    """Three pieces of the box: A (x < 0), B (0 < x < 0.04), C (x > 0.04); one part holds A
    and B (no wall between them), C has its own. With A and B failed, each gets the render
    solid nearer its own tet centroids than the other's, less C's part. Closed form: the two
    shares fill the box up to x = 0.04 without overlap, and each lies within a cell (a
    spacing) of its tets' volume across the box's section."""
    from taichi_frac.surfaces.parts import failed_piece_shells

    model, report, _ = box
    spacing = model.spacing
    render = render_solid_from_surface(report.surface, model.com_in_source, spacing)
    x_axis = np.array([1.0, 0.0, 0.0])
    walls = [CrackPlane(point=np.array([x, 0.0, 0.0]) - model.com_in_source, normal=x_axis, extent=1.0,
                        peak_stress=1.0) for x in (0.0, 0.04)]
    split = split_body(model, walls, FractureOptions())
    a, b, c = np.argsort([model.particle_position[np.asarray(t)].mean(axis=0)[0] for t in split.fragment_tets])
    labels = np.full(model.tet_count, -1)
    for k, tets in enumerate(split.fragment_tets):
        labels[np.asarray(tets)] = k
    face = 0.04 - model.com_in_source[0]
    parts = [render.solid.trim_by_plane(-x_axis, -face), render.solid.trim_by_plane(x_axis, face)]
    shares = {k: m3.Manifold.compose(failed_piece_shells(render.solid, model, labels, k, {a, b}, parts, [a, c], spacing))
              for k in (a, b)}
    section = SIZE[1] * SIZE[2]
    assert shares[a].volume() + shares[b].volume() == pytest.approx(parts[0].volume(), rel=1e-9)
    assert (shares[a] ^ shares[b]).volume() < 1e-12
    for k in (a, b):
        own = model.tet_volume[np.asarray(split.fragment_tets[k])].sum()
        assert abs(shares[k].volume() - own) < spacing * section


def test_a_crack_through_a_merged_piece_leaves_it_one_shell(box):
    """Two full cracks, x = 0 and y = 0, but the two quarters at x < 0 are one piece (as the
    small-fragment policy merges pieces): the y = 0 slab, cut for the pieces at x > 0, runs
    through it too, and the weld joins its halves again. Closed form: that piece is half the
    box less half a slab (x = 0) and the others a quarter less two half slabs each (the planes
    where they are put: no volume fit)."""
    model, report, _ = box
    render = render_solid_from_surface(report.surface, model.com_in_source, model.spacing)
    x = model.particle_position + model.com_in_source  # source frame: the box about 0
    label = np.where(x[:, 0] < 0, 0, np.where(x[:, 1] < 0, 1, 2))
    cracks = [CrackPlane(point=-model.com_in_source, normal=n, extent=1.0, peak_stress=1.0)
              for n in (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))]
    renders, counts = cut_render_solid(render, model, [np.nonzero(label == k)[0] for k in range(3)], cracks,
                                       np.zeros((3, 3)), fit_rounds=0)
    assert counts["welded_pieces"] == 1 and counts["fallback_pieces"] == 0
    half_slab = 1e-4 * model.spacing
    expected = [np.prod(SIZE) / 2 - half_slab * SIZE[1] * SIZE[2],
                *[np.prod(SIZE) / 4 - half_slab * (SIZE[0] / 2 * SIZE[2] + SIZE[1] / 2 * SIZE[2])] * 2]
    for solid, volume in zip(renders, expected):
        mesh = piece_mesh(solid)
        assert_closed(mesh)
        assert len(solid.solid.decompose()) == 1
        assert signed_volume(mesh.vertices, mesh.faces) == pytest.approx(volume, rel=1e-6)


def test_stray_shells_join_the_main_shell_they_touch():
    """Hand-placed unit boxes (spacing 1): piece 0's main box has a bit across a slab's gap
    (joined to it), a bit against piece 1's main box only (it goes to piece 1) and a bit
    touching nothing (it stays apart). Closed form: the bridge over the 1 x 1 contact fills
    the gap and no more (it lies inside the boxes elsewhere), so each joined solid is 4^3 + 1."""
    from taichi_frac.surfaces.shells import join_planned_shells, plan_stray_shells
    from taichi_frac.surfaces.solid import with_crack_index

    def cube(low, high):
        low, high = np.asarray(low, float), np.asarray(high, float)
        return with_crack_index(m3.Manifold.cube(tuple(high - low)).translate(tuple(low)), -1)

    gap = 2e-4
    own_bit = cube([4 + gap, 0, 0], [5, 1, 1])
    neighbour_bit = cube([9, 0, 0], [10 - gap, 1, 1])
    lone_bit = cube([20, 20, 20], [21, 21, 21])
    plan = plan_stray_shells({0: [cube([0, 0, 0], [4, 4, 4]), own_bit, neighbour_bit, lone_bit],
                              1: [cube([10, 0, 0], [14, 4, 4])]}, 1.0)
    joined = join_planned_shells(plan, 1.0)
    assert plan.moved == 1
    shells = sorted(joined[0].decompose(), key=lambda shell: -shell.volume())
    assert len(shells) == 2 and shells[1].volume() == pytest.approx(1.0, rel=1e-9)
    assert shells[0].volume() == pytest.approx(65.0, abs=1e-9)
    assert len(joined[1].decompose()) == 1 and joined[1].volume() == pytest.approx(65.0, abs=1e-9)


def test_a_bridge_is_the_union_of_a_prism_over_each_face():
    """``shells._bridge`` against closed forms of the union of a prism per face, from
    ``gap`` inside to twice it outside: over the top of a box cut into 4,096 triangles
    (slivers among them), the face's area times 3 gap; over two faces meeting at a
    right-angled edge, each face's prism less the g x g x edge they share."""
    from taichi_frac.surfaces.shells import _bridge

    gap = 0.01
    box = trimesh.creation.box(extents=(1.0, 0.6, 0.4))
    fine = box
    for _ in range(5):
        fine = fine.subdivide()
    top = np.nonzero(fine.face_normals[:, 2] > 0.99)[0]
    sliver = trimesh.Trimesh(fine.vertices + np.where(np.abs(fine.vertices[:, :1]) < 0.49, 1e-4, 0.0) * [1, 0, 0],
                             fine.faces, process=False)  # (inner columns moved: thin triangles beside thick)
    for mesh in (fine, sliver):
        bridge = _bridge(mesh, top, gap)
        assert len(bridge.decompose()) == 1
        assert bridge.volume() == pytest.approx(1.0 * 0.6 * 3.0 * gap, rel=1e-7)  # (the 2D union rounds to 1e-8)
    ridge = np.nonzero((fine.face_normals[:, 2] > 0.99) | (fine.face_normals[:, 0] > 0.99))[0]
    edge = 0.6
    expected = 3.0 * gap * (1.0 * 0.6 + 0.6 * 0.4) - gap * gap * edge
    assert _bridge(fine, ridge, gap).volume() == pytest.approx(expected, rel=1e-7)


def test_the_faces_touching_a_shell_are_those_a_plain_loop_finds():
    """``piece_shells._touching`` against every face centre measured to every triangle whose
    grown box holds it, one by one: random small triangles, some a hair off the centres, and
    one triangle as large as the whole set (the k-d tree's reach is each box's own)."""
    from trimesh.triangles import closest_point

    from taichi_frac.surfaces.shells import _touching

    rng = np.random.default_rng(3)
    mesh = trimesh.creation.icosphere(subdivisions=3)
    gap = 0.01
    near = mesh.triangles[::7] + rng.normal(scale=0.006, size=(1, 3)) * mesh.face_normals[::7, None, :]
    small = rng.uniform(-1.2, 1.2, (200, 1, 3)) + rng.uniform(-0.05, 0.05, (200, 3, 3))
    large = np.array([[[-3.0, -3.0, 0.0], [3.0, -3.0, 0.0], [0.0, 3.0, 0.0]]])
    triangles = np.concatenate([near, small, large])
    expected = []
    for k, centre in enumerate(mesh.triangles_center):
        holding = np.all((triangles.min(axis=1) - gap <= centre) & (centre <= triangles.max(axis=1) + gap), axis=1)
        if holding.any():
            nearest = closest_point(triangles[holding], np.repeat(centre[None], holding.sum(), axis=0))
            if np.min(np.linalg.norm(nearest - centre, axis=1)) <= gap:
                expected.append(k)
    found = _touching(mesh, triangles, gap)
    assert len(expected) > 40 and found.tolist() == expected  # (the plane z = 0 cuts the sphere's equator too)


def test_a_piece_reaching_far_past_its_tets_gets_its_tets_boundary(box):
    """A part that holds the whole box given to the piece of the tets at x < -0.05 reaches
    half a box past them: that piece and the one whose tets it covers fall back; the parts
    of a plane cut at x = -0.05 do not."""
    from taichi_frac.surfaces.parts import overreaching_pieces

    model, report, _ = box
    render = render_solid_from_surface(report.surface, model.com_in_source, model.spacing)
    x = model.particle_position + model.com_in_source
    label = (x[:, 0] >= -0.05).astype(np.int64)
    assert overreaching_pieces([render.solid], [0], model, label, model.spacing, {}) == {0, 1}
    plane = -0.05 - model.com_in_source[0]
    halves = [render.solid.trim_by_plane((-1.0, 0.0, 0.0), -plane), render.solid.trim_by_plane((1.0, 0.0, 0.0), plane)]
    assert overreaching_pieces(halves, [0, 1], model, label, model.spacing, {}) == set()


def test_a_part_joining_two_pieces_is_divided_by_their_tets(box):
    """The whole box given to the piece of the tets at x < -0.05, as where the artist's
    surface joins two pieces across a gap their tets leave open: it reaches half a box past
    them, so it is divided by the tets' owners. The part has no crack face, so the other
    piece gets all the material nearer its tet centroids: the box beyond a face within a
    cell (1.5 spacings) of x = -0.05; the two shares are closed, fill the box and reach no
    farther than the check allows."""
    from taichi_frac.surfaces.parts import divide_joined_parts, overreaching_pieces

    model, report, _ = box
    spacing = model.spacing
    render = render_solid_from_surface(report.surface, model.com_in_source, spacing)
    x = model.particle_position + model.com_in_source
    label = (x[:, 0] >= -0.05).astype(np.int64)
    parts, owner, received = divide_joined_parts([render.solid], [0], model, label, spacing, {})
    assert received == {1} and sorted(set(owner)) == [0, 1]
    assert all(part.status() == part.status().NoError and part.genus() == 0 for part in parts)
    volume = [sum(part.volume() for part, o in zip(parts, owner) if o == k) for k in (0, 1)]
    assert sum(volume) == pytest.approx(np.prod(SIZE), rel=1e-9)
    face = -SIZE[0] / 2 + volume[0] / (SIZE[1] * SIZE[2])  # where piece 0's share ends, box frame
    assert abs(face + 0.05) < 1.5 * spacing
    assert overreaching_pieces(parts, owner, model, label, spacing, {}) == set()


def test_a_piece_holding_more_than_its_tets_gets_its_tets_boundary(box):
    """The part up to x = -0.03 given to the piece of the tets at x < -0.05 holds 40 % more
    than its tets (0.02 m of the box's length, 146 spacings cubed, two spacings past them:
    the reach check lets it be): it and the piece whose tets it holds fall back. A plane cut
    at x = -0.05 gives neither."""
    from taichi_frac.surfaces.parts import overfull_pieces, overreaching_pieces

    model, report, _ = box
    render = render_solid_from_surface(report.surface, model.com_in_source, model.spacing)
    x = model.particle_position + model.com_in_source
    label = (x[:, 0] >= -0.05).astype(np.int64)

    def halves(at):
        plane = at - model.com_in_source[0]
        return [render.solid.trim_by_plane((-1.0, 0.0, 0.0), -plane), render.solid.trim_by_plane((1.0, 0.0, 0.0), plane)]

    assert overfull_pieces(halves(-0.03), [0, 1], model, label, model.spacing) == {0, 1}
    assert overreaching_pieces(halves(-0.03), [0, 1], model, label, model.spacing, {}) == set()
    assert overfull_pieces(halves(-0.05), [0, 1], model, label, model.spacing) == set()


def test_a_plane_through_large_inner_tets_cuts_a_graded_body_in_two():
    """A box with a finely tessellated ball buried in one end, one surface of two overlapping
    closed shells (repair unites them, the ball's inside half left out): the mesher grades
    from tets a few millimetres across at the ball to ones four times the mean spacing in the
    middle, where bond crossings of a plane lie further apart than a few spacings. The slab
    must still reach across the whole section: each piece's render volume within 2 % of its
    tets', none falling back to its tets' boundary."""
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.03)
    ball.apply_translation((-0.1, 0.0, 0.0))
    surface = trimesh.util.concatenate([trimesh.creation.box(extents=SIZE), ball])
    model, report = prepare_body(surface, repair=True, max_volume=np.prod(SIZE) / 200, simplify=False,
                                 use_cache=False)
    assert report.surface.is_watertight and report.surface.volume < np.prod(SIZE) + ball.volume
    render = render_solid_from_surface(report.surface, model.com_in_source, model.spacing)
    normal = np.array([1.0, 0.2, 0.1]) / np.linalg.norm([1.0, 0.2, 0.1])
    crack = CrackPlane(point=np.array([0.05, 0.0, 0.0]) - model.com_in_source, normal=normal, extent=1.0,
                       peak_stress=1.0)
    pieces, renders, counts = split_and_cut(model, render, [crack])
    assert len(pieces) == 2 and counts["fallback_pieces"] == 0 and counts["parts"] == 2
    total = 0.0
    for piece, solid in zip(pieces, renders):
        mesh = piece_mesh(solid)
        assert_closed(mesh)
        quality = piece_quality(mesh, piece.model)
        assert abs(quality["volume_error"]) < 0.02 and quality["shells"] == 1
        total += signed_volume(mesh.vertices, mesh.faces)
    assert total == pytest.approx(render.solid.volume(), rel=1e-4)


def test_rough_cracks_fit_together_and_keep_the_outside(box):
    model, report, _ = box
    render = render_solid_from_surface(report.surface, model.com_in_source, model.spacing)
    crack = CrackPlane(point=np.zeros(3), normal=np.array([1.0, 0.2, 0.0]) / np.hypot(1.0, 0.2), extent=1.0,
                       peak_stress=1.0)
    amplitude = 0.3 * model.spacing
    pieces, renders, _ = split_and_cut(model, render, [crack], roughness=amplitude, seed=5)
    flat_pieces, flat_renders, _ = split_and_cut(model, render, [crack])
    rough_volume = 0.0
    for piece, solid, flat in zip(pieces, renders, flat_renders):
        mesh = piece_mesh(solid)
        assert_closed(mesh)
        rough_volume += signed_volume(mesh.vertices, mesh.faces)
        rms = crack_deviation(mesh.vertices, mesh.faces, mesh.face_is_inner, mesh.face_crack, mesh.cracks)
        assert 0.1 * amplitude < rms < amplitude  # value noise in [-1, 1], RMS well inside
        # The outside is still the box.
        world = mesh.vertices[mesh.faces[~mesh.face_is_inner]] + piece.model.com_in_source + model.com_in_source
        assert np.isclose(np.abs(world), SIZE / 2, atol=1e-9).any(axis=2).all()
    # Both sides share one rough surface: together they still fill the box.
    assert rough_volume == pytest.approx(np.prod(SIZE), rel=1e-4)


def test_crack_face_options_are_checked():
    from taichi_frac.options import OptionError
    from taichi_frac.scenes import load_scene

    assert FractureOptions().crack_roughness == 0.0 and FractureOptions().crack_fit_rounds == 3
    with pytest.raises(OptionError, match="crack_roughness"):
        FractureOptions(crack_roughness=-1e-3)
    with pytest.raises(OptionError, match="crack_roughness_scale"):
        FractureOptions(crack_roughness_scale=0.0)
    with pytest.raises(OptionError, match="crack_fit_rounds"):
        FractureOptions(crack_fit_rounds=-1)
    scene = load_scene(SCENES / "single_ring.toml", ["ring.fracture.crack_fit_rounds=0"])
    assert scene.breakable_objects[0].fracture.crack_fit_rounds == 0
    with pytest.raises(Exception, match="crack_fit_rounds"):
        load_scene(SCENES / "single_ring.toml", ["ring.fracture.crack_fit_rounds=1.5"])


def _struck(model, report, material, options, point, direction, force_scale=400.0, **cut):
    analysis = analyze_impact(model, point, direction, np.asarray(direction) * force_scale * model.mass * 9.81,
                              material, options)
    split = split_body(model, analysis, options)
    pieces = make_fragments(model, split, np.zeros(3), [1.0, 0.0, 0.0, 0.0], np.zeros(3), np.zeros(3), material,
                            PARTICLES, options=options)
    render = render_solid_from_surface(report.surface, model.com_in_source, model.spacing)
    renders, counts = cut_render_solid(render, model, split.fragment_tets, analysis.cracks,
                                       [p.model.com_in_source for p in pieces], **cut)
    return pieces, renders, counts


def _check_struck(pieces, renders, counts, mean_volume_error=0.02, fallback_share=0.1, large_volume_error=0.02,
                  multi_shell=0):
    """At most ``fallback_share`` of the pieces (and at least one) fall back to their tets'
    boundary; every other piece
    closed, manifold, outward; crack faces on their cracks (a ring crack's
    sphere polygon within its sagitta bound); volumes: the pieces of FITTED_PIECE_TETS (100)
    tets or more within ``large_volume_error`` of their tets' (the fit aims at 1 %), all
    pieces' errors (volume-weighted mean) within
    ``mean_volume_error``; at most ``multi_shell`` pieces of two or more shells (with stray
    shells left apart: 7 of the glass wall's 60 pieces, 6 of spot.obj's 11)."""
    assert len(pieces) >= 2, "the impact must break the body"
    assert counts["empty_pieces"] == 0
    errors, volumes, shells = [], [], []
    assert counts["fallback_pieces"] <= max(1, int(fallback_share * len(pieces)))
    for piece, solid in zip(pieces, renders):
        if solid is None:  # the cut failed it: the cache writes its tets' boundary
            continue
        quality = piece_quality(piece_mesh(solid), piece.model)
        assert quality["watertight"] and quality["outward"], quality
        assert quality["crack_rms_spacings"] < 0.02, quality
        # A wedge past the piece's tets is cut at the reach (the grown tets' hull: at most
        # BALL_BOUND times it).
        assert quality["distance_to_tets_spacings"] <= BALL_BOUND * REACH_FACTOR + 1e-6, quality
        if piece.model.tet_count >= FITTED_PIECE_TETS:
            assert abs(quality["volume_error"]) < large_volume_error, quality
        # (a piece the vote left with chips is carved from its neighbour, never left a sliver)
        assert quality["volume_error"] > -LOST_VOLUME_SHARE, quality
        errors.append(abs(quality["volume_error"]))
        volumes.append(piece.model.volume)
        shells.append(quality["shells"])
    assert np.average(errors, weights=volumes) < mean_volume_error
    assert sum(count > 1 for count in shells) <= multi_shell, shells


def _scene_body(path, name):
    from taichi_frac.scenes import load_scene

    scene = load_scene(path)
    obj = next(o for o in scene.objects if o.name == name)
    model, report = obj.prepare()
    return model, report, obj.material, obj.fracture


def test_single_ring_struck_from_below():
    model, report, material, fracture = _scene_body(SCENES / "single_ring.toml", "ring")
    # One fixed crack set: the SPH stress's at 6 MPa (pieces of a few hundred tets). The
    # halfspace stress's five cracks cut pieces of a few tens of tets, whose flat faces miss
    # their tets' staircase by 3.25 % of volume.
    material = dataclasses.replace(material, tensile_strength=6e6)
    options = FractureOptions(crack_count=5, crack_length=0.25, seed=1, stress_model="sph")
    low = int(np.argmin(model.particle_position[:, 2]))
    _check_struck(*_struck(model, report, material, options, model.particle_position[low], [0.0, 0.0, 1.0]))


@functools.lru_cache(maxsize=1)
def _glass_wall():
    """(model, ``_struck`` of the glass walls scene's breakable wall hit at its centre along
    x, taking the cut's keywords)."""
    from taichi_frac.scenes import load_scene

    scene = load_scene(SCENES / "glass_walls.toml")
    obj = next(o for o in scene.objects if o.breakable)
    model, report = obj.prepare()
    centre = np.argmin(np.linalg.norm(model.particle_position, axis=1))
    # The SPH stress's crack set; under the halfspace stress one piece of over 300 tets misses
    # its tets' volume by 4.1 %.
    fracture = dataclasses.replace(obj.fracture, stress_model="sph")
    return model, functools.partial(_struck, model, report, obj.material, fracture, model.particle_position[centre],
                                    [1.0, 0.0, 0.0], force_scale=4000.0)


def test_glass_wall_struck_by_the_ball():
    # The wall is three particle spacings thick: a crack plane's staircase of tets is then
    # a large share of a piece, measured 3.0 % (volume-weighted) against the planes.
    _, struck = _glass_wall()
    fitted = struck()
    _check_struck(*fitted, mean_volume_error=0.04, multi_shell=1)
    # Moving the cracks fails no piece the cut on the cracks as placed did not (a move that
    # opens a gap at a crack's end is refused: unguarded, this fit failed 4 of 60 pieces).
    unmoved = struck(fit_rounds=0)
    assert set(fitted[2]["fallback_ids"]) <= set(unmoved[2]["fallback_ids"])
    assert fitted[2]["moved_segments"] > 0  # (a radial crack's stretches fitted on their own)


def test_rough_glass_wall_keeps_its_pieces_volumes():
    """The struck glass wall with rough crack faces (0.3 particle spacings of noise): every
    piece closed and outward, and, with the stretches fitted in the warped surface, every
    piece of 100 tets or more within 2 % of its tets' volume (measured 0.15 %; with whole
    planes alone 3.4 %, 7 pieces over 2 %)."""
    model, struck = _glass_wall()
    pieces, renders, counts = struck(roughness=0.3 * model.spacing, seed=1)
    assert counts["moved_segments"] > 0
    for piece, solid in zip(pieces, renders):
        if solid is None:
            continue
        quality = piece_quality(piece_mesh(solid), piece.model)
        assert quality["watertight"] and quality["outward"], quality
        if piece.model.tet_count >= FITTED_PIECE_TETS:
            assert abs(quality["volume_error"]) < 0.02, quality


@functools.lru_cache(maxsize=1)
def _spot_struck():
    """spot.obj struck on its top: (report, pieces, renders, counts)."""
    material = material_preset("porcelain")
    model, report = prepare_body(str(SHARED_MESHES / "spot.obj"), material=material, particles=PARTICLES)
    # Cracks as long as the cow: the stress field's own length stops them inside it.
    options = FractureOptions(crack_count=4, crack_length=float(np.ptp(model.vertices, axis=0).max()), seed=0,
                              stress_model="halfspace")
    top = int(np.argmax(model.particle_position[:, 2]))
    return (report, *_struck(model, report, material, options, model.particle_position[top], [0.0, 0.0, -1.0],
                             force_scale=800.0))


NO_SPOT = pytest.mark.skipif(not (SHARED_MESHES / "spot.obj").exists(), reason="../shared/meshes/spot.obj is not here")


@NO_SPOT
def test_shared_mesh_breaks_into_closed_pieces():
    """Every piece the cut gives a surface is closed, manifold, outward, on its cracks and
    near its tets' volume (a piece the cut fails keeps its tets' boundary, which is all of
    that by construction); outer corners keep the input's UVs. The cow's tets fill a
    simplified copy of its surface and grade from about one spacing at the surface to three
    or four inside, so the flat crack faces miss the tets' staircase by more than in the
    primitives: with the planes fitted to the pieces' volumes the pieces of 100 tets or more
    are held to 2 % (measured 0.94 %; 5.6 % on the planes as placed), the volume-weighted
    mean over all to 4 % (measured 2.1 %, 4.1 % unmoved: pieces of a few tens of tets are off
    by tens of per cent)."""
    report, pieces, renders, counts = _spot_struck()
    _check_struck(pieces, renders, counts, fallback_share=1.0, large_volume_error=0.02, mean_volume_error=0.04)
    # Outer UVs are the input's (where the loader kept them): every outer corner's UV lies
    # in the input's UV range.
    uv = getattr(report.surface.visual, "uv", None)
    if uv is None or len(uv) != len(report.surface.vertices):
        return
    uv = np.asarray(uv)
    for solid in renders:
        if solid is None:
            continue
        mesh = piece_mesh(solid)
        outer = mesh.uvs[~mesh.face_is_inner].reshape(-1, 2)
        assert np.all(outer >= uv.min(axis=0) - 1e-9) and np.all(outer <= uv.max(axis=0) + 1e-9)


@NO_SPOT
def test_shared_mesh_pieces_get_cut_surfaces():
    report, pieces, renders, counts = _spot_struck()
    assert counts["fallback_pieces"] <= max(1, len(pieces) // 10)
