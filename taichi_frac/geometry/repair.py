"""Opt-in repair: turn holey, flipped, overlapping, non-manifold or self-intersecting input
into one closed solid that keeps every part of it.

An artist's model is often several shells that overlap (a teapot's body, lid, spout and
handle; a head and its eyes), some of them open. The solid is the union of every shell:

1. clean-up (trimesh): merge duplicate vertices, drop degenerate and duplicate faces;
2. split into shells (faces joined by edges); each shell's winding is made consistent and
   outward (positive enclosed volume about its centroid, for an open one too);
3. each shell that is open, non-manifold or crosses itself is closed on its own by MeshFix
   (``pymeshfix``: fills holes, removes the crossings); closed clean shells are untouched;
4. the closed shells are united exactly by manifold3d (float64): outside, the artist's own
   triangles, split only where shells cross; buried triangles are removed;
5. the result is measured against the input: the fraction of the input's generalized
   winding-number solid (|w| >= 1/2, libigl's fast winding number at random points in the
   bounding box) that lies inside the repaired solid, and both bounding boxes. Below
   ``min_kept_fraction`` (95 %) repair stops with an error saying which region and which
   shells would be lost; separate solids left after the union are an error too (one
   breakable body is one connected solid): make one scene object per part.

Measured on the test cases and ../shared/meshes (docs/benchmarks/meshes.md): MeshFix alone
keeps only the largest component (it dropped the teapot's spout and handle); manifold3d
alone refuses open shells; fTetWild (``wildmeshing``) resolves everything but replaces the
artist's triangles by its own envelope surface and takes minutes on 100k faces. Each step
runs under the preparation's time bound (``bounded.StepClock``) and says which step ran out.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

from .bounded import StepClock
from .validate import MeshError, _edges, degenerate_faces, self_intersections, shell_labels
from .winding_solid import KEPT_SAMPLES, sampled_kept

#: Below this fraction of the input's winding-number volume kept, repair is an error.
MIN_KEPT_FRACTION = 0.95


@dataclass
class RepairReport:
    """What :func:`repair_surface` did, in order (human-readable steps), and what it kept.

    Attributes:
        steps: what was done, in order.
        shells: shells in the input (faces joined by edges).
        input_volume: volume of the input's generalized winding-number solid [m^3]
            (sampled; None when repair changed nothing that could lose volume).
        kept_fraction: fraction of that solid inside the repaired one [-] (sampled).
        input_extents, output_extents: bounding-box sizes (3,) [m].
        step_seconds: wall time of each step [s].
    """

    steps: list[str] = field(default_factory=list)
    shells: int = 1
    input_volume: float | None = None
    kept_fraction: float | None = None
    input_extents: list = field(default_factory=list)
    output_extents: list = field(default_factory=list)
    step_seconds: dict = field(default_factory=dict)

    def add(self, text: str):
        self.steps.append(text)


def _is_closed(mesh: trimesh.Trimesh) -> bool:
    return bool(mesh.is_watertight and mesh.is_winding_consistent)


def _orient_outward(shell: trimesh.Trimesh) -> trimesh.Trimesh:
    """Consistent winding, then outward: positive enclosed volume about the shell's centroid
    (for an open shell, the volume of the cone from the centroid)."""
    if not shell.is_winding_consistent:
        trimesh.repair.fix_winding(shell)
    tri = shell.triangles - shell.vertices.mean(axis=0)
    if np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() < 0:
        shell.invert()
    return shell


def _meshfix(vertices: np.ndarray, faces: np.ndarray):
    """MeshFix on one shell: fill holes, remove self-intersections. Returns (vertices, faces)."""
    import pymeshfix

    fixer = pymeshfix.MeshFix(np.ascontiguousarray(vertices, dtype=np.float64),
                              np.ascontiguousarray(faces, dtype=np.int32))
    fixer.repair(joincomp=False, remove_smallest_components=False)
    return np.asarray(fixer.points, dtype=np.float64), np.asarray(fixer.faces, dtype=np.int64)


def _meshfix_each(pieces: list[tuple[np.ndarray, np.ndarray]]) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`_meshfix` on each (vertices, faces) piece, in one bounded step: one forked child
    for all the pieces instead of one each (33 children for the beetle's shells, seconds on
    a loaded machine)."""
    return [_meshfix(v, f) for v, f in pieces]


def _manifold_union(shells: list[tuple[np.ndarray, np.ndarray]]):
    """Exact union (manifold3d, float64) of closed outward shells [(vertices, faces)].
    Returns (vertices, faces)."""
    import manifold3d

    solids = []
    for v, f in shells:
        m = manifold3d.Manifold(manifold3d.Mesh64(vert_properties=np.ascontiguousarray(v, dtype=np.float64),
                                                  tri_verts=np.ascontiguousarray(f, dtype=np.uint64)))
        # A shell manifold3d refuses is left out; the kept-volume measure reports the loss.
        if m.status() == manifold3d.Error.NoError and not m.is_empty():
            solids.append(m)
    if not solids:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    union = manifold3d.Manifold.batch_boolean(solids, manifold3d.OpType.Add) if len(solids) > 1 else solids[0]
    # Cuts along nearly parallel faces and vertices 1e-7 apart (float32 exports) leave
    # zero-area slivers; collapsing edges shorter than 1e-6 of the size removes them without
    # moving anything visible.
    box = np.asarray(union.bounding_box())
    union = union.simplify(1e-6 * float(np.linalg.norm(box[3:] - box[:3])))
    out = union.to_mesh64()
    return np.asarray(out.vert_properties, dtype=np.float64)[:, :3], np.asarray(out.tri_verts, dtype=np.int64)


def _box_text(points: np.ndarray) -> str:
    lo, hi = points.min(axis=0), points.max(axis=0)
    return ", ".join(f"{axis} {a:.4g}..{b:.4g}" for axis, a, b in zip("xyz", lo, hi))


def measure_kept(input_mesh: trimesh.Trimesh, output: trimesh.Trimesh, shell_of_face: np.ndarray,
                 samples: int = KEPT_SAMPLES, seed: int = 0):
    """Fraction of the input's winding-number solid inside ``output``, the input solid's
    volume [m^3] and a description of what is lost (None if nothing measurable)."""
    lo, hi = input_mesh.bounds
    size = np.maximum(hi - lo, 1e-12 * max(float(np.max(hi - lo)), 1e-300))
    points, held, volume = sampled_kept(input_mesh.vertices, input_mesh.faces, output.vertices, output.faces, lo, size,
                                        samples=samples, seed=seed)
    if not len(points):
        return 1.0, 0.0, None
    kept = float(held.mean())
    lost_points = points[~held]
    lost = None
    if len(lost_points):
        _, _, nearest = trimesh.proximity.closest_point(input_mesh, lost_points[:2000])
        shells, per = np.unique(shell_of_face[nearest], return_counts=True)
        order = np.argsort(-per)
        named = ", ".join(f"shell {int(shells[k])} ({int(np.sum(shell_of_face == shells[k]))} faces)"
                          for k in order[:5])
        lost = f"the region {_box_text(lost_points)}, nearest to {named}"
    return kept, volume, lost


def _groups(label: np.ndarray, count: int) -> list[np.ndarray]:
    """Indices of each label 0..count-1, in order."""
    order = np.argsort(label, kind="stable")
    bounds = np.searchsorted(label[order], np.arange(count + 1))
    return [order[bounds[k]:bounds[k + 1]] for k in range(count)]


#: Vertices closer than this fraction of the bounding-box diagonal are one vertex (float32
#: exports leave copies ~1e-8 apart that make zero-area faces).
WELD_FRACTION = 1e-7


def weld_close_vertices(vertices: np.ndarray, faces: np.ndarray, distance: float) -> tuple[np.ndarray, int]:
    """Faces (F,3) with vertices closer than ``distance`` [m] merged into one; and how many
    vertices were merged away."""
    import scipy.sparse as sp
    import scipy.sparse.csgraph as csgraph
    from scipy.spatial import cKDTree

    pairs = cKDTree(vertices).query_pairs(distance, output_type="ndarray")
    if len(pairs) == 0:
        return faces, 0
    n = len(vertices)
    graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    count, label = csgraph.connected_components(graph, directed=False)
    first = np.full(count, n, dtype=np.int64)
    np.minimum.at(first, label, np.arange(n))
    return first[label][faces], n - count


def _clean(mesh: trimesh.Trimesh, report: RepairReport) -> trimesh.Trimesh:
    mesh = trimesh.Trimesh(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces), process=True)
    faces, welded = weld_close_vertices(mesh.vertices, mesh.faces, WELD_FRACTION * float(np.linalg.norm(mesh.extents)))
    if welded:
        mesh = trimesh.Trimesh(mesh.vertices, faces, process=False)
        mesh.remove_unreferenced_vertices()
        report.add(f"welded {welded} vertices closer than {WELD_FRACTION:g} of the size to a neighbour")
    bad = degenerate_faces(mesh)
    if len(bad):
        mesh.update_faces(np.setdiff1d(np.arange(len(mesh.faces)), bad))
        mesh.remove_unreferenced_vertices()
        report.add(f"removed {len(bad)} degenerate faces")
    n_faces = len(mesh.faces)
    mesh.update_faces(mesh.unique_faces())
    if len(mesh.faces) < n_faces:
        report.add(f"removed {n_faces - len(mesh.faces)} duplicate faces")
    return mesh


#: Separate solids left after the union whose volumes together are under this fraction of
#: the whole (slivers between touching parts) are dropped, and the drop is reported.
CRUMB_FRACTION = 0.001


def _drop_crumbs(result: trimesh.Trimesh, report: RepairReport) -> trimesh.Trimesh:
    parts = result.split(only_watertight=False)
    volumes = np.array([abs(p.volume) for p in parts])
    order = np.argsort(-volumes)
    small = np.cumsum(volumes[order[::-1]])[::-1] <= CRUMB_FRACTION * volumes.sum()
    keep = [parts[k] for k, tiny in zip(order, small) if not tiny]
    dropped = int(np.sum(small))
    if dropped:
        report.add(f"dropped {dropped} separate sliver solid{'s' if dropped > 1 else ''} of "
                   f"{volumes[order][small].sum():.3g} m^3 in all ({100 * volumes[order][small].sum() / volumes.sum():.2g} "
                   "% of the volume)")
        return trimesh.util.concatenate(keep) if len(keep) > 1 else keep[0]
    return result


def repair_surface(mesh: trimesh.Trimesh, name: str = "mesh", *, clock: StepClock | None = None,
                   min_kept_fraction: float = MIN_KEPT_FRACTION) -> tuple[trimesh.Trimesh, RepairReport]:
    """Return a repaired copy of ``mesh`` (closed, manifold, outward, one solid) and what was
    done (see the module docstring).

    Raises :class:`MeshError` when the result would keep under ``min_kept_fraction`` of the
    input's winding-number volume (the message says which region and shells), when it is
    several separate solids, when it is still not closed, or when a step runs out of the
    ``clock``'s time bound (the message names the step).
    """
    clock = clock or StepClock(name=name)
    report = RepairReport()
    if len(mesh.faces) == 0:
        raise MeshError(f"{name!r} is empty: nothing to repair")
    mesh = clock.inline("clean-up", _clean, mesh, report)
    report.input_extents = mesh.extents.tolist()
    count, label = clock.inline("split into shells", shell_labels, mesh.faces)
    report.shells = count
    pairs = clock.inline("self-intersection check", self_intersections, mesh.vertices, mesh.faces)
    crossing_within = np.zeros(count, dtype=bool)
    crossing_between = False
    if len(pairs):
        same = label[pairs[:, 0]] == label[pairs[:, 1]]
        crossing_within[np.unique(label[pairs[same, 0]])] = True
        crossing_between = bool(np.any(~same))
    # A non-manifold edge joins faces of one shell: MeshFix resolves it.
    edges, uses = _edges(mesh.faces)
    nonmanifold_vertices = np.unique(edges[uses > 2])
    crossing_faces = np.zeros(len(mesh.faces), dtype=bool)
    if len(pairs):
        within = pairs[label[pairs[:, 0]] == label[pairs[:, 1]]]
        crossing_faces[within.reshape(-1)] = True
    shells, oriented, to_close = [], [], []
    closed_count = fixed_count = flipped = 0
    for index, faces_of in enumerate(_groups(label, count)):
        part = mesh.submesh([faces_of], append=True, repair=False)
        was_consistent = part.is_winding_consistent
        before = part.volume if part.is_watertight and was_consistent else None
        part = clock.inline("orient shells", _orient_outward, part)
        oriented.append(part)
        nonmanifold = bool(len(nonmanifold_vertices)) and bool(
            np.isin(mesh.faces[faces_of], nonmanifold_vertices).any())
        if _is_closed(part) and not crossing_within[index] and not nonmanifold:
            flipped += int(before is not None and before < 0) + int(not was_consistent)
            shells.append((np.asarray(part.vertices), np.asarray(part.faces)))
            closed_count += 1
            continue
        # A shell that crosses itself (a horn through a head): MeshFix would cut away the
        # region around the crossing and keep the largest piece, losing the horn. Removing
        # only the crossing faces leaves pieces with holes, each closed on its own and united.
        pieces = [part]
        if crossing_within[index]:
            cut = mesh.submesh([faces_of[~crossing_faces[faces_of]]], append=True, repair=False)
            piece_count, piece_label = shell_labels(cut.faces)
            pieces = [cut.submesh([g], append=True, repair=False) for g in _groups(piece_label, piece_count)]
        to_close.extend((np.asarray(piece.vertices), np.asarray(piece.faces)) for piece in pieces)
        fixed_count += 1
    for v, f in (clock.run("close shells (pymeshfix)", _meshfix_each, to_close) if to_close else []):
        closed = trimesh.Trimesh(v, f, process=True)
        if len(closed.faces) and closed.is_watertight and closed.volume < 0:
            closed.invert()
        # A sheet with no inside (a fin, a single face) closes to nothing: the kept-volume
        # measure below says whether anything with an inside went missing.
        if len(closed.faces) and _is_closed(closed) and closed.volume > 0:
            shells.append((np.asarray(closed.vertices), np.asarray(closed.faces)))
    if flipped:
        report.add(f"made the winding consistent and outward in {flipped} shells")
    if fixed_count:
        report.add(f"closed holes and removed self-intersections (pymeshfix) in {fixed_count} of {count} shells")
    if len(shells) > 1:
        v, f = clock.run("union of shells (manifold3d)", _manifold_union, shells)
        result = trimesh.Trimesh(v, f, process=True)
        report.add(f"united {len(shells)} {'overlapping ' if crossing_between else ''}shells (manifold3d)")
    elif shells:
        result = trimesh.Trimesh(*shells[0], process=True)
    else:
        result = trimesh.Trimesh()
    if len(result.faces) and result.is_watertight and result.volume < 0:
        result.invert()
    if len(result.faces) and len(degenerate_faces(result)):
        # Zero-area slivers where the union cut a face next to a vertex: weld the vertices
        # that close together (collapsing the slivers), MeshFix if that leaves it open.
        slivers = len(degenerate_faces(result))
        faces, _ = weld_close_vertices(result.vertices, result.faces,
                                       WELD_FRACTION * float(np.linalg.norm(result.extents)))
        welded = trimesh.Trimesh(result.vertices, faces, process=False)
        welded.update_faces(np.setdiff1d(np.arange(len(welded.faces)), degenerate_faces(welded)))
        welded.update_faces(welded.unique_faces())
        welded.remove_unreferenced_vertices()
        if not _is_closed(welded) or len(degenerate_faces(welded)):
            v, f = clock.run("remove slivers (pymeshfix)", _meshfix, welded.vertices, welded.faces)
            welded = trimesh.Trimesh(v, f, process=True)
        result = welded
        report.add(f"removed {slivers} zero-area slivers of the union")
    if len(result.faces) and result.body_count > 1:
        result = _drop_crumbs(result, report)
    if fixed_count or len(shells) > 1:
        # Closing and uniting can lose parts: measure against the input's winding-number solid.
        oriented_input = trimesh.util.concatenate(oriented) if len(oriented) > 1 else oriented[0]
        shell_of_face = np.repeat(np.arange(len(oriented)), [len(p.faces) for p in oriented])
        kept, volume, lost = clock.inline("measure kept volume", measure_kept, oriented_input, result, shell_of_face)
        report.kept_fraction, report.input_volume = kept, volume
        if kept < min_kept_fraction:
            raise MeshError(f"{name!r}: repair would keep only {100 * kept:.1f} % of the input's volume "
                            f"({volume:.4g} m^3 by winding number, {count} shells); it would lose {lost}. "
                            "Close or reconnect that part in a modelling tool, or use backend='wildmeshing' "
                            "on the unrepaired mesh")
    if len(result.faces) == 0 or not _is_closed(result):
        raise MeshError(f"{name!r} could not be repaired into a closed solid ({len(result.faces)} faces left, "
                        f"watertight={result.is_watertight}); fix it in a modelling tool")
    if result.body_count > 1:
        parts = result.split(only_watertight=False)
        volumes = sorted((abs(p.volume) for p in parts), reverse=True)
        raise MeshError(f"{name!r} is {len(parts)} separate solids after uniting its shells (volumes "
                        f"{', '.join(f'{x:.3g}' for x in volumes[:6])}{', ...' if len(volumes) > 6 else ''} m^3): "
                        "one breakable body is one connected solid; make one scene object per part, or join "
                        "the parts in a modelling tool")
    report.output_extents = result.extents.tolist()
    report.step_seconds = dict(clock.step_seconds)
    return result, report
