"""Tetrahedralization: tets fill the solid exactly (volume), nowhere outside it or in a
hole, counts land near the target, quality is reported, the cache is used."""

import math

import numpy as np
import pytest
import trimesh

from taichi_frac.geometry import primitives
from taichi_frac.geometry.prepare import prepare_body
from taichi_frac.geometry.tetra import tetrahedralize
from taichi_frac.geometry.topology import dihedral_angles_deg, signed_volumes
from taichi_frac.options import ParticleOptions


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("TAICHI_FRAC_CACHE", str(tmp_path / "cache"))


def _centroids(tm):
    return tm.vertices[tm.tets].mean(axis=1)


def test_ring_tets_fill_the_torus_and_not_the_hole():
    R, r = 0.1, 0.025
    surface = primitives.torus(R, r, edge_length=0.008)
    tm = tetrahedralize(surface, target_tets=5000)
    # Sum of tet volumes = enclosed surface volume (0.1 %), and the smooth torus's (0.1 %).
    assert abs(tm.volume_error) < 1e-3
    assert signed_volumes(tm.vertices, tm.tets).sum() == pytest.approx(2 * math.pi**2 * R * r**2, rel=1e-3)
    assert np.all(signed_volumes(tm.vertices, tm.tets) > 0)
    c = _centroids(tm)
    # Nothing in the hole (radius R - r about the Z axis), nothing outside the tube
    # (the volume-matched facets bulge at most ~1 % of r beyond the smooth tube).
    assert np.hypot(c[:, 0], c[:, 1]).min() > R - r
    tube = np.hypot(np.hypot(c[:, 0], c[:, 1]) - R, c[:, 2])
    assert tube.max() < r * 1.01
    assert surface.contains(c).all()


def test_genus_one_block_with_sharp_edges():
    import manifold3d

    block = manifold3d.Manifold.cube((0.2, 0.2, 0.1), center=True)
    hole = manifold3d.Manifold.cylinder(0.3, 0.05, 0.05, 64, center=True)
    out = (block - hole).to_mesh()
    surface = trimesh.Trimesh(np.asarray(out.vert_properties)[:, :3], np.asarray(out.tri_verts))
    assert surface.euler_number == 0  # genus 1
    tm = tetrahedralize(surface, target_tets=3000)
    assert abs(tm.volume_error) < 1e-3
    c = _centroids(tm)
    # Inscribed 64-gon of radius 0.05: its apothem is 0.05 cos(pi/64).
    assert np.hypot(c[:, 0], c[:, 1]).min() > 0.05 * math.cos(math.pi / 64)
    assert surface.contains(c).all()
    # Sharp features kept: every box corner is a tet vertex.
    corners = np.array([[x, y, z] for x in (-0.1, 0.1) for y in (-0.1, 0.1) for z in (-0.05, 0.05)])
    d = np.linalg.norm(tm.vertices[None, :, :] - corners[:, None, :], axis=2).min(axis=1)
    assert d.max() < 1e-6


@pytest.mark.parametrize("target", [2000, 5000, 20000])
def test_count_lands_near_target(target):
    _, report = prepare_body("torus", particles=ParticleOptions(target_particles=target), use_cache=False)
    assert abs(report.tets / target - 1.0) < 0.15, report.tets


def test_quality_is_reported_truthfully():
    tm = tetrahedralize(primitives.sphere(0.05, edge_length=0.01), target_tets=3000)
    angles = dihedral_angles_deg(tm.vertices, tm.tets)
    assert tm.min_dihedral_deg == pytest.approx(angles.min())
    assert tm.sliver_count == int(np.sum(angles.min(axis=1) < 5.0))
    # Few slivers: under 0.5 % of the tets, and no flat (zero-volume) tet.
    assert tm.sliver_count < 0.005 * tm.tet_count
    assert tm.min_dihedral_deg > 1.0


def test_max_volume_bound_is_respected():
    surface = primitives.box((0.1, 0.1, 0.1))
    tm = tetrahedralize(surface, max_volume=1e-6)
    vol = signed_volumes(tm.vertices, tm.tets)
    # tetgen's final flips/smoothing may push a few tets slightly over the bound.
    assert vol.max() <= 1.25e-6 and np.mean(vol > 1e-6) < 0.01
    assert abs(tm.volume_error) < 1e-9


def test_prepare_caches_by_content(tmp_path):
    particles = ParticleOptions(target_particles=1500)
    m1, r1 = prepare_body("sphere:radius=0.05", particles=particles)
    m2, r2 = prepare_body("sphere:radius=0.05", particles=particles)
    assert not r1.cache_hit and r2.cache_hit
    assert np.array_equal(m1.tets, m2.tets) and np.allclose(m1.vertices, m2.vertices)
    _, r3 = prepare_body("sphere:radius=0.051", particles=particles)
    assert not r3.cache_hit  # different content, different key
    assert len(list((tmp_path / "cache" / "tets").glob("*.npz"))) == 2


def test_prepare_from_file_with_units(tmp_path):
    box = trimesh.creation.box((10.0, 20.0, 5.0))  # centimetres
    path = tmp_path / "brick.stl"
    box.export(str(path))
    model, report = prepare_body(path, units="cm", material="concrete",
                                 particles=ParticleOptions(target_particles=800))
    assert report.source == "brick.stl"
    assert model.mass == pytest.approx(2400.0 * 0.1 * 0.2 * 0.05, rel=1e-9)


def test_prepare_tet_file_used_as_is(tmp_path):
    import meshio

    tm = tetrahedralize(primitives.box((0.1, 0.1, 0.1)), target_tets=500)
    path = tmp_path / "cube.vtu"
    meshio.write(str(path), meshio.Mesh(tm.vertices, [("tetra", tm.tets)]))
    model, report = prepare_body(path)
    assert report.tets == tm.tet_count and report.backend == "file"
    assert model.volume == pytest.approx(1e-3, rel=1e-12)


def test_wildmeshing_backend_fills_the_solid():
    pytest.importorskip("wildmeshing")
    surface = primitives.box((0.1, 0.1, 0.05))
    tm = tetrahedralize(surface, target_tets=300, backend="wildmeshing")
    # fTetWild approximates the surface within an envelope of 1e-3 of the bbox diagonal.
    assert abs(tm.volume_error) < 5e-3
    assert surface.contains(_centroids(tm)).all()


def test_backends_are_swappable():
    from taichi_frac.geometry import tetra

    calls = []

    def recording(vertices, faces, max_volume, min_dihedral_deg):
        calls.append(max_volume)
        return tetra.BACKENDS["tetgen"](vertices, faces, max_volume, min_dihedral_deg)

    tetra.register_backend("recording", recording)
    try:
        tm = tetrahedralize(primitives.box((0.1, 0.1, 0.1)), max_volume=2e-5, backend="recording")
    finally:
        del tetra.BACKENDS["recording"]
    assert calls == [2e-5] and tm.backend == "recording" and abs(tm.volume_error) < 1e-9
    from taichi_frac.geometry.validate import MeshError

    with pytest.raises(MeshError, match="unknown mesher backend 'nope': use one of tetgen, wildmeshing"):
        tetrahedralize(primitives.box((0.1, 0.1, 0.1)), backend="nope")


def test_row_operations_match_numpy():
    """geometry.rows: the fast row-wise forms against numpy's own (cross and the corner
    means must be identical, bit for bit, so swapping them in changes no model)."""
    from taichi_frac.geometry import rows

    rng = np.random.default_rng(7)
    a, b = rng.normal(size=(500, 3)), rng.normal(size=(500, 3))
    tets, faces = rng.normal(size=(200, 4, 3)), rng.normal(size=(200, 3, 3))
    assert np.array_equal(rows.cross(a, b), np.cross(a, b))
    assert np.array_equal(rows.corner_mean(tets), tets.mean(axis=1))
    assert np.array_equal(rows.corner_mean(faces), faces.mean(axis=1))
    assert np.array_equal(rows.corner_sum(tets), tets.sum(axis=1))
    np.testing.assert_allclose(rows.dot(a, b), (a * b).sum(axis=1), rtol=0, atol=1e-14)
    np.testing.assert_allclose(rows.norm(a), np.linalg.norm(a, axis=1), rtol=1e-15, atol=0)


@pytest.mark.parametrize("path", ["kernel", "numpy"])
def test_first_hits_against_a_box_and_brute_force(path, monkeypatch):
    """geometry.rays.first_hits: rays from inside a closed box mesh outward along the
    axes hit the walls at the hand-computed distances; random short rays agree with a
    brute-force Moller-Trumbore loop over every face (inf where none is within reach).
    Both the kernel and the all-pairs numpy path (small inputs) are checked."""
    from taichi_frac.geometry import rays
    from taichi_frac.geometry.rays import first_hits

    monkeypatch.setattr(rays, "SMALL_PAIRS", 0 if path == "kernel" else 10**9)

    box = trimesh.creation.box(extents=(2.0, 1.0, 0.5))
    verts, faces = np.asarray(box.vertices, dtype=np.float64), np.asarray(box.faces)
    origin = np.array([[0.2, 0.1, 0.05]] * 3)
    direction = np.eye(3)
    hits = first_hits(verts, faces, origin, direction, np.full(3, 5.0))
    np.testing.assert_allclose(hits, [1.0 - 0.2, 0.5 - 0.1, 0.25 - 0.05], atol=1e-12)
    assert np.all(np.isinf(first_hits(verts, faces, origin, direction, np.full(3, 0.1))))  # out of reach

    rng = np.random.default_rng(3)
    origin = rng.uniform(-0.9, 0.9, size=(200, 3)) * [1.0, 0.5, 0.25]
    direction = rng.normal(size=(200, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    reach = rng.uniform(0.05, 1.0, size=200)
    expected = np.full(200, np.inf)
    for p in range(200):
        for tri in verts[faces]:
            e1, e2 = tri[1] - tri[0], tri[2] - tri[0]
            q = np.cross(direction[p], e2)
            det = e1 @ q
            if abs(det) <= 1e-18:
                continue
            s = origin[p] - tri[0]
            u, r = s @ q / det, np.cross(s, e1)
            v, t = direction[p] @ r / det, e2 @ r / det
            if u >= 0 and v >= 0 and u + v <= 1 and 0 < t <= reach[p]:
                expected[p] = min(expected[p], t)
    got = first_hits(verts, faces, origin, direction, reach)
    assert np.array_equal(np.isinf(got), np.isinf(expected)) and np.isfinite(expected).sum() > 20
    np.testing.assert_allclose(got[np.isfinite(got)], expected[np.isfinite(expected)], rtol=1e-12)



def test_a_refused_surface_leaves_no_files_in_the_working_directory(tmp_path, monkeypatch):
    """TetGen writes the facets it skips ("_skipped.node", "_skipped.face") where it runs: a
    self-intersecting pair of boxes must be refused without a file in the user's folder."""
    from taichi_frac.geometry.validate import MeshError

    a, b = trimesh.creation.box((1.0, 1.0, 1.0)), trimesh.creation.box((1.0, 1.0, 1.0))
    b.apply_translation((0.5, 0.5, 0.5))
    pair = trimesh.util.concatenate([a, b])
    monkeypatch.chdir(tmp_path)
    with pytest.raises(MeshError):
        tetrahedralize(pair, max_volume=0.01)
    assert list(tmp_path.iterdir()) == []
