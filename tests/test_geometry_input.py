"""Loading and checking surface meshes: every format, units, and one test per bad input
asserting the error message (file name, problem, numbers, what to do)."""

import math

import numpy as np
import pytest
import trimesh

from taichi_frac.geometry import primitives
from taichi_frac.geometry.meshio_in import load_surface, load_tet_mesh, unit_scale
from taichi_frac.geometry.repair import repair_surface
from taichi_frac.geometry.validate import MeshError, self_intersections, validate_surface
from taichi_frac.options import OptionError

RING_VOLUME = 2 * math.pi**2 * 0.1 * 0.025**2  # 2 pi^2 R r^2


def _write_obj(path, mesh, header=""):
    text = header + "".join(f"v {a!r} {b!r} {c!r}\n" for a, b, c in mesh.vertices)
    text += "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.faces)
    path.write_text(text)
    return path


# --- primitives -------------------------------------------------------------------------

@pytest.mark.parametrize("mesh,exact", [
    (primitives.torus(0.1, 0.025), RING_VOLUME),
    (primitives.torus(0.1, 0.025, edge_length=0.01), RING_VOLUME),
    (primitives.sphere(0.05), 4 / 3 * math.pi * 0.05**3),
    (primitives.cylinder(0.05, 0.3, edge_length=0.02), math.pi * 0.05**2 * 0.3),
    (primitives.box((1.0, 0.5, 0.01), edge_length=0.05), 1.0 * 0.5 * 0.01),
])
def test_primitives_closed_and_volume_matched(mesh, exact):
    validate_surface(mesh, "primitive")
    assert mesh.volume == pytest.approx(exact, rel=1e-5)


def test_volume_matching_stays_close_to_the_smooth_surface():
    # Inflation is bounded by the facet sagitta: every vertex lies within 2 % of r of the tube.
    mesh = primitives.torus(0.1, 0.025, edge_length=0.01)
    v = mesh.vertices
    tube = np.hypot(np.hypot(v[:, 0], v[:, 1]) - 0.1, v[:, 2])
    assert np.all(np.abs(tube - 0.025) < 0.02 * 0.025)


def test_primitive_spec_rejects_unknown_parameters():
    with pytest.raises(OptionError, match=r"primitive 'torus': unknown parameter 'radius=1'; allowed: major"):
        primitives.parse_primitive_spec("torus:radius=1")
    assert primitives.parse_primitive_spec("teapot.obj") is None


# --- formats and units --------------------------------------------------------------------

@pytest.mark.parametrize("suffix", ["obj", "stl", "ply", "off", "glb", "gltf"])
def test_every_surface_format_loads(tmp_path, suffix):
    ring = primitives.torus()
    path = tmp_path / f"ring.{suffix}"
    ring.export(str(path))
    mesh = load_surface(path)
    assert mesh.volume == pytest.approx(RING_VOLUME, rel=1e-6)  # float32 formats: ~1e-7


def test_obj_with_missing_texture_loads_geometry(tmp_path):
    (tmp_path / "ring.mtl").write_text("newmtl glaze\nmap_Kd textures/missing.png\n")
    ring = primitives.torus()
    path = tmp_path / "ring.obj"
    text = "mtllib ring.mtl\nmtllib absent.mtl\nusemtl glaze\n"
    text += "".join(f"v {a!r} {b!r} {c!r}\n" for a, b, c in ring.vertices) + "vt 0 0\n"
    text += "".join(f"f {a + 1}/1 {b + 1}/1 {c + 1}/1\n" for a, b, c in ring.faces)
    path.write_text(text)
    assert load_surface(path).volume == pytest.approx(RING_VOLUME, rel=1e-9)


@pytest.mark.parametrize("units,factor", [("m", 1.0), ("cm", 0.01), ("mm", 0.001)])
def test_units_and_scale(tmp_path, units, factor):
    path = _write_obj(tmp_path / "box.obj", trimesh.creation.box((10.0, 20.0, 30.0)))
    mesh = load_surface(path, units=units, scale=2.0)
    assert mesh.volume == pytest.approx(6000.0 * (2.0 * factor) ** 3, rel=1e-12)


def test_bad_units_named():
    with pytest.raises(OptionError, match=r"units = 'inch': use one of m, cm, mm"):
        unit_scale(1.0, "inch")


def test_tet_mesh_file_loads_as_is(tmp_path):
    import meshio

    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype=float)
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    for suffix in ("vtu", "msh", "mesh", "vtk"):
        path = tmp_path / f"two.{suffix}"
        meshio.write(str(path), meshio.Mesh(points, [("tetra", tets)]))
        v, t = load_tet_mesh(path, units="cm")
        assert np.allclose(v, points * 0.01) and np.array_equal(t, tets)


# --- bad inputs: one test each, asserting the message --------------------------------------

def test_missing_file(tmp_path):
    with pytest.raises(MeshError, match=r"'nothere.obj' does not exist"):
        load_surface(tmp_path / "nothere.obj")


def test_unsupported_suffix(tmp_path):
    (tmp_path / "a.xyz").write_text("0 0 0\n")
    with pytest.raises(MeshError, match=r"'a.xyz': unsupported file type '.xyz'; surfaces: .obj"):
        load_surface(tmp_path / "a.xyz")


def test_empty(tmp_path):
    path = tmp_path / "empty.obj"
    path.write_text("# nothing\n")
    with pytest.raises(MeshError, match=r"'empty.obj' is empty: 0 vertices, 0 faces; check the file exports"):
        load_surface(path)


def test_not_closed_counts_loops_and_edges(tmp_path):
    box = primitives.box((1, 1, 1), edge_length=0.25)
    # One triangle removed from the middle of the top and of the bottom: two triangular
    # holes that share no vertex -> 2 loops of 3 open edges each.
    c = box.triangles_center
    top = np.argmin(np.linalg.norm(c - [0.1, 0.1, 0.5], axis=1))
    bottom = np.argmin(np.linalg.norm(c - [0.1, 0.1, -0.5], axis=1))
    faces = np.delete(box.faces, [top, bottom], axis=0)
    path = _write_obj(tmp_path / "teapot.obj", trimesh.Trimesh(box.vertices, faces, process=False))
    with pytest.raises(MeshError, match=r"'teapot.obj' is not closed: 2 boundary loops, 6 open edges; .*repair"):
        load_surface(path)


def test_inconsistent_winding(tmp_path):
    box = trimesh.creation.box((1, 1, 1))
    faces = box.faces.copy()
    faces[0] = faces[0][::-1]
    path = _write_obj(tmp_path / "flip.obj", trimesh.Trimesh(box.vertices, faces, process=False))
    with pytest.raises(MeshError, match=r"'flip.obj' has inconsistent winding: 3 edges .* flipped"):
        load_surface(path)


def test_inverted(tmp_path):
    box = trimesh.creation.box((1, 2, 3))
    path = _write_obj(tmp_path / "inside_out.obj", trimesh.Trimesh(box.vertices, box.faces[:, ::-1], process=False))
    with pytest.raises(MeshError, match=r"'inside_out.obj' is inverted: enclosed volume -6 m\^3 is negative"):
        load_surface(path)


def test_degenerate_faces(tmp_path):
    path = tmp_path / "flat.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 4 5\n")
    with pytest.raises(MeshError, match=r"'flat.obj' has 1 degenerate faces \(zero area .*\) out of 2, e.g. face 0"):
        load_surface(path)


def test_several_shells(tmp_path):
    a = trimesh.creation.box((1, 1, 1))
    b = trimesh.creation.box((1, 1, 1))
    b.apply_translation((3, 0, 0))
    path = _write_obj(tmp_path / "pair.obj", trimesh.util.concatenate([a, b]))
    with pytest.raises(MeshError, match=r"'pair.obj' has 2 disconnected shells \(faces per shell: 12, 12\); make one"):
        load_surface(path)


def _dented_slab():
    """A closed, consistently wound slab whose top-centre vertex is pushed through the bottom."""
    slab = primitives.box((1.0, 1.0, 0.2), edge_length=0.25)
    v = slab.vertices.copy()
    top = np.nonzero(np.all(np.isclose(v, [0.0, 0.0, 0.1]), axis=1))[0]
    v[top] = [0.03, 0.07, -0.3]
    return trimesh.Trimesh(v, slab.faces, process=False)


def test_self_intersecting(tmp_path):
    path = _write_obj(tmp_path / "dent.obj", _dented_slab())
    with pytest.raises(MeshError, match=r"'dent.obj' self-intersects: \d+ crossing face pairs \(\d+ faces\)"):
        load_surface(path)


def test_self_intersection_reference_cases():
    # Two triangles crossing like an X, two far apart, two sharing an edge.
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, -1], [0.3, 0.2, 1], [0.2, 0.3, 1.0],
                  [5, 5, 5], [6, 5, 5], [5, 6, 5], [1, 1, 0]], dtype=float)
    assert len(self_intersections(v, np.array([[0, 1, 2], [3, 4, 5]]))) == 1
    assert len(self_intersections(v, np.array([[0, 1, 2], [6, 7, 8]]))) == 0
    assert len(self_intersections(v, np.array([[0, 1, 2], [1, 9, 2]]))) == 0


# --- repair ---------------------------------------------------------------------------------

def test_repair_closes_holes(tmp_path):
    ring = primitives.torus()
    holey = trimesh.Trimesh(ring.vertices, ring.faces[40:], process=False)
    path = _write_obj(tmp_path / "holey.obj", holey)
    with pytest.raises(MeshError, match="is not closed"):
        load_surface(path)
    mesh = load_surface(path, repair=True)
    assert mesh.volume == pytest.approx(RING_VOLUME, rel=0.01)
    assert any("pymeshfix" in step for step in mesh.metadata["repair"])


def test_repair_unites_overlapping_shells():
    a = trimesh.creation.box((1, 1, 1))
    b = trimesh.creation.box((1, 1, 1))
    b.apply_translation((0.5, 0.3, 0.2))
    mesh, report = repair_surface(trimesh.util.concatenate([a, b]), "two.obj")
    validate_surface(mesh, "two.obj")
    # Union volume: 2 - overlap 0.5 x 0.7 x 0.8 (manifold3d works in float32).
    assert mesh.volume == pytest.approx(2.0 - 0.28, rel=1e-5)
    assert report.steps == ["united 2 overlapping shells (manifold3d)"]


def test_repair_removes_self_intersection_and_fixes_inversion():
    mesh, _ = repair_surface(_dented_slab(), "dent.obj")
    validate_surface(mesh, "dent.obj")
    inverted = trimesh.creation.box((1, 2, 3))
    inverted.invert()
    fixed, report = repair_surface(inverted, "inv.obj")
    assert fixed.volume == pytest.approx(6.0) and report.steps
