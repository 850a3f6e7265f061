"""Artists' meshes: every failure class built here (overlapping open shells, holes,
self-crossings, non-manifold edges, a dense surface, UV seams, time bounds), checked against
closed-form volumes and extents or a brute-force reference; then the public test meshes of
../shared/meshes when they are there."""

import os
import time

import numpy as np
import pytest
import trimesh

from benchmarks.meshes import overlapping_shells, shared_meshes_dir
from taichi_frac.geometry import prepare as prepare_module
from taichi_frac.geometry import repair as repair_module
from taichi_frac.geometry import simplify as simplify_module
from taichi_frac.geometry import tetra as tetra_module
from taichi_frac.geometry.bounded import StepClock
from taichi_frac.geometry.intersections import crossing_face_pairs
from taichi_frac.geometry.meshio_in import load_surface
from taichi_frac.geometry.prepare import prepare_body
from taichi_frac.geometry.repair import repair_surface
from taichi_frac.geometry.tetra import _next_bound
from taichi_frac.geometry.validate import MeshError, validate_surface
from taichi_frac.options import ParticleOptions

SHARED = shared_meshes_dir()


def _without(mesh, drop):
    keep = np.setdiff1d(np.arange(len(mesh.faces)), drop)
    return trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=False)


def _faces_facing(mesh, axis, sign):
    """Faces of a box whose normal points along +/- axis."""
    return np.nonzero(mesh.face_normals[:, axis] * sign > 0.99)[0]


def _teapot_like():
    """A unit box open at the top (the body) and a 1.0 x 0.2 x 0.2 tube open at both ends
    (the spout) through its +x wall: union volume 1 + 0.7 x 0.2 x 0.2, x from -0.5 to 1.2."""
    body = trimesh.creation.box((1.0, 1.0, 1.0))
    body = _without(body, _faces_facing(body, 2, +1))
    spout = trimesh.creation.box((1.0, 0.2, 0.2))
    spout.apply_translation((0.7, 0.0, 0.0))
    spout = _without(spout, np.concatenate([_faces_facing(spout, 0, +1), _faces_facing(spout, 0, -1)]))
    return trimesh.util.concatenate([body, spout])


# --- the broad phase against brute force ------------------------------------------------------

def _crosses(p0, p1, t):
    """Vectorised Moller-Trumbore: segment p0-p1 (K,3) through triangle t (K,3,3)'s interior."""
    d = p1 - p0
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    h = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, h)
    scale = np.linalg.norm(d, axis=1) * np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
    ok = np.abs(det) > 1e-9 * np.maximum(scale, 1e-300)
    det = np.where(ok, det, 1.0)
    s = p0 - t[:, 0]
    u = np.einsum("ij,ij->i", s, h) / det
    q = np.cross(s, e1)
    w = np.einsum("ij,ij->i", d, q) / det
    k = np.einsum("ij,ij->i", e2, q) / det
    eps = 1e-12
    return ok & (u > eps) & (w > eps) & (u + w < 1 - eps) & (k > eps) & (k < 1 - eps)


def _brute_force_pairs(vertices, faces):
    """Every pair i < j tested, no broad phase: an edge of one crossing the other's interior."""
    i, j = np.triu_indices(len(faces), k=1)
    share = (faces[i][:, :, None] == faces[j][:, None, :]).any(axis=(1, 2))
    i, j = i[~share], j[~share]
    a, b = vertices[faces[i]], vertices[faces[j]]
    hit = np.zeros(len(i), dtype=bool)
    for m in range(3):
        hit |= _crosses(b[:, m], b[:, (m + 1) % 3], a) | _crosses(a[:, m], a[:, (m + 1) % 3], b)
    return np.stack([i[hit], j[hit]], axis=1).astype(np.int64)


def test_crossing_pairs_match_brute_force_on_mixed_sizes():
    # Small triangles and a few up to 100x larger (several grid levels), randomly placed.
    rng = np.random.default_rng(3)
    n = 500
    centres = rng.random((n, 3))
    size = np.where(rng.random(n) < 0.05, 0.3, 0.08 * rng.random(n) + 0.003)
    vertices = (centres[:, None, :] + size[:, None, None] * rng.normal(size=(n, 3, 3))).reshape(-1, 3)
    faces = np.arange(len(vertices)).reshape(-1, 3)
    expected = _brute_force_pairs(vertices, faces)
    got = crossing_face_pairs(vertices, faces)
    assert len(expected) > 50
    np.testing.assert_array_equal(got, expected)


def test_crossing_pairs_buffer_grows_instead_of_refusing():
    # 80 triangles all crossing one another: 3,160 pairs through a 10-pair buffer.
    t = np.linspace(0, 1, 80)
    vertices = np.concatenate([np.stack([np.full(80, -1.0), t, np.full(80, -1.0)], 1),
                               np.stack([np.full(80, 1.0), t + 0.01, np.full(80, 1.0)], 1),
                               np.stack([np.full(80, 0.0), t, np.full(80, 1.5)], 1)])
    faces = np.stack([np.arange(80), np.arange(80) + 80, np.arange(80) + 160], 1)
    other = trimesh.creation.box((4, 4, 0.001)).triangles.reshape(-1, 3)
    v = np.concatenate([vertices, other + [0, 0.5, 0.3]])
    f = np.concatenate([faces, np.arange(len(other)).reshape(-1, 3) + 240])
    pairs = crossing_face_pairs(v, f, capacity=10)
    assert len(pairs) == len(_brute_force_pairs(v, f)) > 10


# --- repair: every part kept ------------------------------------------------------------------

def test_overlapping_open_shells_keep_every_part():
    mesh, report = repair_surface(_teapot_like(), "teapot-like.obj")
    validate_surface(mesh, "teapot-like.obj")
    assert mesh.volume == pytest.approx(1.0 + 0.7 * 0.2 * 0.2, rel=1e-6)
    np.testing.assert_allclose(mesh.extents, [1.7, 1.0, 1.0], rtol=1e-9)
    assert report.shells == 2
    # The winding-number reference: 40,000 samples of a 1.7 m^3 box, ~0.5 % standard error.
    assert report.kept_fraction > 0.99
    assert report.input_volume == pytest.approx(1.028, rel=0.03)
    # The outer surface is the input's own triangles: every input vertex not buried inside
    # the body (the spout's inner end, x = 0.2) is on it.
    vertices = _teapot_like().vertices
    outside = vertices[~np.isclose(vertices[:, 0], 0.2)]
    assert np.abs(trimesh.proximity.signed_distance(mesh, outside)).max() < 1e-9


def test_losing_a_part_is_an_error_that_names_it(monkeypatch):
    real_union = repair_module._manifold_union
    monkeypatch.setattr(repair_module, "_manifold_union", lambda shells: real_union(shells[:1]))
    a = trimesh.creation.box((1.0, 1.0, 1.0))
    b = trimesh.creation.box((1.0, 1.0, 1.0))
    b.apply_translation((3.0, 0.0, 0.0))
    b.invert()  # a flipped shell far away: its winding number is -1 inside
    with pytest.raises(MeshError, match=r"'two.obj': repair would keep only (49|50|51)\.\d % of the input's volume "
                                        r"\(2(\.\d+)? m\^3 by winding number, 2 shells\); it would lose the region "
                                        r"x 2\.5\d*\.\.3\.5\d*, .*nearest to shell 1 \(12 faces\)"):
        repair_surface(trimesh.util.concatenate([a, b]), "two.obj")


def test_holes_are_closed_with_the_volume_kept():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.1)
    rng = np.random.default_rng(0)
    holey = _without(sphere, rng.choice(len(sphere.faces), 60, replace=False))
    with pytest.raises(MeshError, match="is not closed"):
        validate_surface(holey, "holey.obj")
    mesh, report = repair_surface(holey, "holey.obj")
    assert mesh.volume == pytest.approx(sphere.volume, rel=0.005)
    assert report.kept_fraction > 0.99


def test_crossing_closed_shells_keep_the_part_outside():
    # A thin horn through a body's wall (two closed shells whose faces cross): the union keeps
    # the horn's full length, and its faces outside are the input's.
    body = trimesh.creation.box((1.0, 1.0, 1.0))
    horn = trimesh.creation.box((1.2, 0.1, 0.1))
    horn.apply_translation((0.9, 0.0, 0.0))
    mesh = trimesh.util.concatenate([body, horn])
    assert len(crossing_face_pairs(mesh.vertices, mesh.faces)) > 0
    fixed, report = repair_surface(mesh, "horned.obj")
    validate_surface(fixed, "horned.obj")
    np.testing.assert_allclose(fixed.extents, [2.0, 1.0, 1.0], rtol=1e-9)
    assert fixed.volume == pytest.approx(1.0 + 1.0 * 0.1 * 0.1, rel=1e-9)
    assert report.steps == ["united 2 overlapping shells (manifold3d)"]


def test_non_manifold_edge_is_resolved():
    # A closed box and a fin: a triangle hanging on one of the box's edges (3 faces there).
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    edge = box.edges_unique[0]
    apex = box.vertices[edge].mean(axis=0) * 3.0
    vertices = np.vstack([box.vertices, apex])
    faces = np.vstack([box.faces, [edge[0], edge[1], len(box.vertices)]])
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    with pytest.raises(MeshError, match="not closed|not manifold"):
        validate_surface(mesh, "fin.obj")
    fixed, report = repair_surface(mesh, "fin.obj")
    validate_surface(fixed, "fin.obj")
    assert fixed.volume == pytest.approx(1.0, rel=0.01)


def test_a_step_that_runs_out_of_time_is_named():
    clock = StepClock(name="slow.obj", seconds=0.5)
    with pytest.raises(MeshError, match=r"'slow.obj': step 'nap' ran out of time: the preparation's bound of "
                                        r"0 s was used up"):
        clock.run("nap", time.sleep, 5.0)
    assert clock.remaining() > -1.0  # the child was killed at the bound, not waited for
    with pytest.raises(MeshError, match=r"step 'clean-up' ran out of time"):
        repair_surface(_teapot_like(), "late.obj", clock=StepClock(name="late.obj", seconds=1e-9))


def _hanging_tetgen(*args, **kwargs):
    time.sleep(600.0)  # TetGen looping on a union of many shells (the beetle)


def _crashing_tetgen(*args, **kwargs):
    os._exit(134)  # TetGen dying in native code (as an abort does)


@pytest.mark.parametrize("mesher,why", [(_hanging_tetgen, "ran past its share"), (_crashing_tetgen, "crashed")])
def test_tetgen_hang_or_crash_falls_back_to_ftetwild(monkeypatch, mesher, why):
    pytest.importorskip("wildmeshing")
    monkeypatch.setitem(tetra_module.BACKENDS, "tetgen", mesher)
    monkeypatch.setattr(tetra_module, "_tetgen", mesher)  # the relaxed-quality re-runs too
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    # The bound leaves fTetWild 54 s after TetGen's share (a tenth here: 6 s): its two runs on
    # this box take 9 s on a quiet machine, up to 38 s on a loaded one.
    monkeypatch.setattr(prepare_module, "TETGEN_TIME_SHARE", 0.1)
    start = time.perf_counter()
    model, report = prepare_body(box, particles=ParticleOptions(target_particles=300), use_cache=False,
                                 time_limit=60.0)
    assert time.perf_counter() - start < 60.0  # the hanging TetGen was stopped, not waited for
    assert report.backend == "wildmeshing"
    assert any("fTetWild" in step and why.split()[0] in step for step in report.repair_steps), report.repair_steps
    assert abs(model.volume / box.volume - 1) <= 0.01


# --- resolution set by the target -------------------------------------------------------------

def test_surface_deviation_matches_hand_computed_distances():
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    points = np.array([[2.0, 0.0, 0.0], [0.0, 0.0, 0.5], [0.5, 0.5, 1.5]])  # 1.5, 0, sqrt(1^2) = 1
    assert simplify_module.surface_deviation(points, box.vertices, box.faces) == pytest.approx(1.5, abs=1e-12)
    assert simplify_module.surface_deviation(points[1:], box.vertices, box.faces) == pytest.approx(1.0, abs=1e-12)


def _sphere_with_tail():
    """A 0.05 m sphere (5,120 faces) with a 3 mm thick tail reaching to x = 0.1 m: one closed
    solid whose tail is thinner than the particle spacing of 1,000 particles (8 mm)."""
    body = trimesh.creation.icosphere(subdivisions=4, radius=0.05)
    tail = trimesh.creation.cylinder(radius=0.0015, height=0.06, sections=8)
    tail.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    tail.apply_translation((0.07, 0.0, 0.0))
    v, f = repair_module._manifold_union([(body.vertices, body.faces), (tail.vertices, tail.faces)])
    return trimesh.Trimesh(v, f, process=True)


def test_a_copy_that_loses_a_thin_part_is_refused(monkeypatch):
    """The cow's tail: decimated into its leg, then cut away with the crossing, 7 % of its length
    and 0.01 % of its volume. A decimator that drops the tail below 1,000 faces stands in:
    the distance bound refuses those copies and keeps the finer one, whose box is the input's."""
    mesh = _sphere_with_tail()
    assert mesh.is_watertight and mesh.bounds[1][0] == pytest.approx(0.1)
    real = simplify_module._decimate
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.05)

    def tail_lost_when_coarse(vertices, faces, count):
        return real(sphere.vertices, sphere.faces, count) if count < 1000 else real(vertices, faces, count)

    monkeypatch.setattr(simplify_module, "_decimate", tail_lost_when_coarse)
    spacing = simplify_module.tet_edge(mesh.volume, 1000)
    unbounded, _ = simplify_module.simplify_to_faces(mesh, 700, max_deviation=None)
    assert unbounded.bounds[1][0] == pytest.approx(0.05, abs=0.002)  # the tail is gone: the test can fail
    copy, _ = simplify_module.simplify_to_faces(mesh, 700, max_deviation=0.5 * spacing)
    assert len(copy.faces) >= 1000
    np.testing.assert_allclose(copy.bounds, mesh.bounds, atol=0.5 * spacing)
    points = simplify_module.deviation_points(mesh)
    assert simplify_module.surface_deviation(points, copy.vertices, copy.faces) <= 0.5 * spacing



def test_a_staged_copy_that_fails_is_made_again_from_the_full_surface(monkeypatch):
    """A large input is first decimated to a staged copy; where decimating that copy further
    fails at the wanted count (the overlapping shells: open or crossing at every count up to
    2.3x), the full surface is decimated to the same count before the count grows."""
    full = trimesh.creation.icosphere(subdivisions=5, radius=0.05)  # 20,480 faces
    staged = trimesh.creation.icosphere(subdivisions=4, radius=0.05)  # 5,120 faces
    real = simplify_module._decimate

    def staged_copies_open(vertices, faces, count):
        v, f = real(vertices, faces, count)
        return (v, f[1:]) if len(faces) == len(staged.faces) else (v, f)  # one face missing: open

    monkeypatch.setattr(simplify_module, "_decimate", staged_copies_open)
    copy, _ = simplify_module.simplify_to_faces(staged, 600, reference_volume=full.volume, finer=full)
    assert len(copy.faces) <= 620  # the wanted count, not 1.15^k of it
    assert copy.is_watertight and abs(copy.volume / full.volume - 1) <= simplify_module.VOLUME_TOLERANCE
    assert simplify_module.simplify_to_faces(staged, 600, reference_volume=full.volume) is None


def test_dense_surface_meshes_at_the_target():
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=0.05)  # 20,480 faces
    model, report = prepare_body(sphere, particles=ParticleOptions(target_particles=1500), use_cache=False)
    assert report.surface_triangles == 20480 and report.surface is not None
    assert len(report.surface.faces) == 20480  # the artist's surface stays full resolution
    assert report.tet_surface_triangles < 2000
    assert abs(report.physics_particles / 1500 - 1) <= 0.15
    assert abs(model.volume / sphere.volume - 1) <= 0.01
    np.testing.assert_allclose(report.tet_extents, report.input_extents, rtol=0.02)


def test_relaxed_quality_recalibrates_the_count():
    """The generated overlapping shells: their coarse copy's count is mostly set by the surface
    once TetGen's quality is relaxed, and the volume bound fitted under the strict quality
    undershot (3,967 for 5,000) until it was re-fitted under the relaxed one."""
    shells = overlapping_shells()
    shells.apply_scale(0.3 / float(np.linalg.norm(shells.extents)))
    # A generous time bound, so that the outcome does not depend on the machine's load: the
    # count is under test here, the bound's fallback elsewhere.
    model, report = prepare_body(shells, repair=True, particles=ParticleOptions(target_particles=5000),
                                 use_cache=False, time_limit=300)
    assert abs(report.physics_particles / 5000 - 1) <= 0.15, report.physics_particles
    assert abs(model.volume / report.surface_volume - 1) <= 0.01


def test_next_bound_fits_the_surface_floor():
    # count = 3000 + 0.01 / bound: the fitted bound lands on the target where a
    # proportional step from (1e-5, 4000) would ask for 8e-6 (count 4,250).
    seen = [(2e-5, 3500), (1e-5, 4000)]
    assert _next_bound(seen, 5000) == pytest.approx(5e-6)
    assert _next_bound([(1e-5, 6000), (2e-5, 5900)], 5000) is None  # the floor is above it
    assert _next_bound([(1e-5, 4000)], 5000) == pytest.approx(8e-6)


def test_primitives_are_never_simplified():
    _, with_simplify = prepare_body("torus", use_cache=False)
    _, without = prepare_body("torus", use_cache=False, simplify=False)
    assert with_simplify.tet_surface is None and with_simplify.tets == without.tets


# --- UVs ---------------------------------------------------------------------------------------

def test_uv_seams_do_not_open_the_surface(tmp_path):
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    # Each face's corners get their own UVs (a seam everywhere), as an OBJ with v/vt writes.
    lines = [f"v {a} {b} {c}" for a, b, c in box.vertices]
    corner_uv = np.array([[0, 0], [1, 0], [0, 1]], dtype=float) * 0.5 + (np.arange(len(box.faces)) * 0.01)[:, None, None]
    lines += [f"vt {u} {v}" for u, v in corner_uv.reshape(-1, 2)]
    lines += [f"f {a + 1}/{3 * k + 1} {b + 1}/{3 * k + 2} {c + 1}/{3 * k + 3}" for k, (a, b, c) in enumerate(box.faces)]
    path = tmp_path / "seams.obj"
    path.write_text("\n".join(lines) + "\n")
    mesh = load_surface(path)
    assert mesh.is_watertight and len(mesh.vertices) == 8
    np.testing.assert_allclose(mesh.metadata["corner_uvs"], corner_uv)
    assert len(mesh.visual.uv) == 8


# --- the public test meshes --------------------------------------------------------------------

@pytest.mark.parametrize("name,shells", [("teapot", 4), ("suzanne", 3), ("cow", 1), ("beetle", 2)])
def test_shared_meshes_keep_their_whole_shape(name, shells):
    """``shells``: at least this many (non-manifold edges split shells further)."""
    path = SHARED / f"{name}.obj"
    if not path.exists():
        pytest.skip(f"{path} is not there (the public test meshes live beside the checkout)")
    mesh = load_surface(path, repair=True)
    report = mesh.metadata["repair_report"]
    assert report.shells >= shells
    assert report.kept_fraction >= 0.99
    np.testing.assert_allclose(report.output_extents, report.input_extents, rtol=0.01)
    # Closing an open shell can add volume the winding number counts as half outside (the
    # beetle's open underside), never lose it.
    assert mesh.volume >= 0.95 * report.input_volume


def test_cow_keeps_its_tail():
    """The cow's tail is thinner than the particle spacing of 5,000 particles; its simplified
    copies either cross themselves there or lose it. The simulated solid's box is held to the
    source file's own box (read without repair) within half a tet edge on every side, at the
    target count, and no point of the cow lies more than 0.75 tet edges from the simulated
    solid (a lost tail lies 2.4 tet edges away; the winding-number solid's lattice tets,
    which mesh the self-crossing cow, blunt thin tips by up to 0.6)."""
    path = SHARED / "cow.obj"
    if not path.exists():
        pytest.skip(f"{path} is not there (the public test meshes live beside the checkout)")
    from benchmarks.meshes import _scale_for
    from taichi_frac.geometry.meshio_in import read_surface

    scale = _scale_for(str(path))
    model, report = prepare_body(str(path), scale=scale, repair=True, particles=ParticleOptions(target_particles=5000),
                                 use_cache=False, time_limit=300)
    source_bounds = read_surface(path).bounds * scale
    spacing = simplify_module.tet_edge(report.surface_volume, 5000)
    tets = report.tet_surface if report.tet_surface is not None else report.surface
    assert tets is not None
    lo, hi = np.asarray(report.tet_extents), np.asarray(source_bounds[1] - source_bounds[0])
    assert np.all(np.abs(lo - hi) <= spacing), (lo, hi, spacing)
    np.testing.assert_allclose(tets.bounds, source_bounds, atol=0.5 * spacing)
    assert report.surface_deviation <= 0.75 * spacing
    assert abs(report.physics_particles / 5000 - 1) <= 0.15, report.physics_particles


def test_teapot_meets_the_particle_target():
    """Its spout and handle are thinner than the particle spacing: the count was +27 % until
    the volume bound was re-fitted under TetGen's relaxed quality."""
    path = SHARED / "teapot.obj"
    if not path.exists():
        pytest.skip(f"{path} is not there (the public test meshes live beside the checkout)")
    from benchmarks.meshes import _scale_for

    _, report = prepare_body(str(path), scale=_scale_for(str(path)), repair=True,
                             particles=ParticleOptions(target_particles=5000), use_cache=False, time_limit=120)
    assert abs(report.physics_particles / 5000 - 1) <= 0.15, report.physics_particles


def test_edge_checks_take_one_sort_and_agree_with_a_reference(monkeypatch):
    """The edge, winding and shell checks of ``validate_surface`` group the half-edges with
    one 1-D sort (a 1.3M-face sphere's checks took 14 s with three ``np.unique`` passes and
    trimesh's area and volume; 3.1 s now, crossings included): no ``np.unique`` on the way,
    and the same verdicts and shells as a per-edge reference."""
    from taichi_frac.geometry import validate as validate_module

    def no_unique(*args, **kwargs):
        raise AssertionError("np.unique called")

    sphere = trimesh.creation.icosphere(subdivisions=3)
    flipped = sphere.faces.copy()
    flipped[[0, 7]] = flipped[[0, 7], ::-1]
    two = trimesh.util.concatenate([sphere, trimesh.creation.box(bounds=[[3, 3, 3], [4, 4, 4]])])
    reference_edges = {}
    for face_index, face in enumerate(flipped):
        for a, b in zip(face, np.roll(face, -1)):
            reference_edges.setdefault((min(a, b), max(a, b)), []).append((a < b, face_index))
    same_way = sum(1 for uses in reference_edges.values() if uses[0][0] == uses[1][0])
    validate_surface(sphere, "sphere")  # the crossing kernel's broad phase may use np.unique
    with pytest.raises(MeshError, match=r"not closed: 1 boundary loop, 3 open edges"):
        validate_surface(_without(sphere, [5]), "holed")  # counting loops (error path) may too
    monkeypatch.setattr(validate_module.np, "unique", no_unique)
    validate_surface(sphere, "sphere", check_self_intersection=False)
    with pytest.raises(MeshError, match=rf"inconsistent winding: {same_way} edges"):
        validate_surface(trimesh.Trimesh(sphere.vertices, flipped, process=False), "flipped")
    with pytest.raises(MeshError, match=r"2 disconnected shells"):
        validate_surface(two, "two", check_self_intersection=False)
    count, label = validate_module.shell_labels(two.faces)
    assert count == 2 and np.array_equal(label, (np.arange(len(two.faces)) >= len(sphere.faces)).astype(label.dtype))


def test_cache_read_back_sees_the_whole_shape_then_every_piece(tmp_path):
    """The bench's render check on a hand-built cache: a 0.2 x 0.1 x 0.05 m box (Y-up stage in
    centimetres) breaks at frame 3 into two halves; the box at the first frame and the halves'
    volume at the last are the box's, a piece that ends (is hidden) no longer counts."""
    from benchmarks.meshes import _read_back
    from taichi_frac.io import CacheWriter

    whole = trimesh.creation.box((0.2, 0.1, 0.05))
    half = trimesh.creation.box((0.1, 0.1, 0.05))
    unit = np.array([[1.0, 0.0, 0.0, 0.0]])
    path = tmp_path / "drop.usdc"
    with CacheWriter(path, fps=24, up_axis="Y", meters_per_unit=0.01) as writer:
        body = writer.add_fragment("body", whole.vertices, whole.faces, np.zeros(12, bool), 0)
        pieces = [writer.add_fragment(f"half{k}", half.vertices, half.faces, np.zeros(12, bool), 3, parent=body)
                  for k in range(2)]
        for frame in range(6):
            if frame < 3:
                writer.write_frame(frame, [body], np.zeros((1, 3)), unit)
            else:
                writer.write_frame(frame, pieces, np.array([[-0.05, 0, 0], [0.05, 0, 0]]), np.repeat(unit, 2, axis=0))
            if frame == 3:
                writer.end_fragment(body, frame)
    seen = _read_back(path)
    assert seen["meshes"] == 3 and seen["issues"] == 0
    np.testing.assert_allclose(seen["extents"], [0.05, 0.1, 0.2], rtol=1e-6)
    assert seen["volume"] == pytest.approx(whole.volume, rel=1e-6)
