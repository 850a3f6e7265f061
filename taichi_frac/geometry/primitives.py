"""Closed triangle-mesh primitives in metres (trimesh), centred on the origin, Z up.

Faceting loses volume (a polygon inscribed in a circle is smaller than the circle), and the
mass-property tests compare against the smooth solid's closed form. So by default the
curved primitives are *volume-matched*: the faceted mesh is inflated about its section
centres until its enclosed volume equals the smooth solid's (to ~1e-6 relative). The shape
stays within one facet's sagitta of the smooth surface either way.

Resolution follows ``edge_length`` [m] (the wanted mean surface edge length); ``prepare``
passes the edge length of a regular tet of the target particle volume so the surface is
neither far finer (the mesher would then exceed the particle target) nor far coarser.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh

from ..options import OptionError, check_range

#: The paper's porcelain ring (BRIEF.md Table 1): torus major radius and minor radius [m].
RING_MAJOR_RADIUS = 0.1
RING_MINOR_RADIUS = 0.025


def _sections(length: float, edge_length: float | None, default: int, minimum: int) -> int:
    """Number of segments along a curve of ``length`` [m]."""
    if edge_length is None:
        return default
    return max(minimum, int(math.ceil(length / edge_length)))


def _match_volume(mesh: trimesh.Trimesh, exact_volume: float, inflate) -> trimesh.Trimesh:
    """Apply ``inflate(mesh, s)`` (a scale factor s of the faceted cross-section) until the
    mesh volume equals ``exact_volume``. Volume ~ s^2 for a section scale, so two fixed-point
    steps on s <- s sqrt(V*/V) converge to ~1e-6."""
    s = 1.0
    base = mesh.copy()
    for _ in range(3):
        s *= math.sqrt(exact_volume / inflate(base, s).volume)
    return inflate(base, s)


def torus(
    major_radius: float = RING_MAJOR_RADIUS,
    minor_radius: float = RING_MINOR_RADIUS,
    *,
    edge_length: float | None = None,
    major_sections: int | None = None,
    minor_sections: int | None = None,
    volume_matched: bool = True,
) -> trimesh.Trimesh:
    """A torus around the Z axis (the paper's ring by default), radii in metres.

    Volume of the smooth solid: 2 pi^2 R r^2.
    """
    check_range("torus", "major_radius", major_radius, 0.0, None, low_open=True)
    check_range("torus", "minor_radius", minor_radius, 0.0, major_radius, low_open=True, high_open=True)
    m_sec = major_sections or _sections(2 * math.pi * major_radius, edge_length, 64, 12)
    n_sec = minor_sections or _sections(2 * math.pi * minor_radius, edge_length, 24, 8)
    mesh = trimesh.creation.torus(major_radius, minor_radius, major_sections=m_sec, minor_sections=n_sec)
    if not volume_matched:
        return mesh

    def inflate(base, s):
        # Scale each vertex's offset from the tube's centre circle (radius R in the XY plane).
        v = base.vertices.copy()
        rho = np.linalg.norm(v[:, :2], axis=1)
        centre = np.zeros_like(v)
        centre[:, :2] = v[:, :2] * (major_radius / rho)[:, None]
        return trimesh.Trimesh(centre + s * (v - centre), base.faces, process=False)

    return _match_volume(mesh, 2 * math.pi**2 * major_radius * minor_radius**2, inflate)


def box(extents=(1.0, 1.0, 1.0), *, edge_length: float | None = None) -> trimesh.Trimesh:
    """An axis-aligned box of full side lengths ``extents`` (3,) [m], centred on the origin.

    With ``edge_length`` the faces are subdivided so the surface edges are about that long
    (a glass wall 1 m x 1 m x 1 cm needs small faces or the mesher makes needle tets).
    """
    extents = tuple(float(e) for e in np.broadcast_to(np.asarray(extents, dtype=float), (3,)))
    for name, e in zip("xyz", extents):
        check_range("box", f"extents.{name}", e, 0.0, None, low_open=True)
    if edge_length is None:
        return trimesh.creation.box(extents=extents)
    # A structured grid on each face: conforming along the box edges because both faces
    # sharing an edge use the same count along it.
    counts = [max(1, int(math.ceil(e / edge_length))) for e in extents]
    half = np.array(extents) / 2.0
    verts, faces = [], []
    offset = 0
    for axis in range(3):
        u, w = [a for a in range(3) if a != axis]
        for sign in (-1.0, 1.0):
            nu, nw = counts[u], counts[w]
            gu, gw = np.meshgrid(np.linspace(-half[u], half[u], nu + 1), np.linspace(-half[w], half[w], nw + 1), indexing="ij")
            p = np.zeros((nu + 1, nw + 1, 3))
            p[..., axis] = sign * half[axis]
            p[..., u] = gu
            p[..., w] = gw
            idx = np.arange((nu + 1) * (nw + 1)).reshape(nu + 1, nw + 1) + offset
            a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
            quad = np.stack([a, b, c, d], axis=-1).reshape(-1, 4)
            tri = np.concatenate([quad[:, [0, 1, 2]], quad[:, [0, 2, 3]]])
            verts.append(p.reshape(-1, 3))
            faces.append(tri)
            offset += len(p.reshape(-1, 3))
    mesh = trimesh.Trimesh(np.concatenate(verts), np.concatenate(faces), process=True)  # merges seams
    trimesh.repair.fix_normals(mesh)
    return mesh


def sphere(radius: float = 0.05, *, edge_length: float | None = None, volume_matched: bool = True) -> trimesh.Trimesh:
    """An icosphere of ``radius`` [m]; subdivisions follow ``edge_length`` (default 3)."""
    check_range("sphere", "radius", radius, 0.0, None, low_open=True)
    subdivisions = 3
    if edge_length is not None:
        # Icosahedron edge = 1.05 R; each subdivision halves it.
        subdivisions = int(np.clip(math.ceil(math.log2(max(1.0515 * radius / edge_length, 1.0))), 1, 7))
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    if not volume_matched:
        return mesh
    return _match_volume(
        mesh, 4.0 / 3.0 * math.pi * radius**3,
        lambda base, s: trimesh.Trimesh(base.vertices * s ** (2.0 / 3.0), base.faces, process=False),
    )


def cylinder(radius: float = 0.05, height: float = 0.1, *, edge_length: float | None = None,
             sections: int | None = None, volume_matched: bool = True) -> trimesh.Trimesh:
    """A cylinder of ``radius`` and ``height`` [m] along Z, centred on the origin."""
    check_range("cylinder", "radius", radius, 0.0, None, low_open=True)
    check_range("cylinder", "height", height, 0.0, None, low_open=True)
    n_sec = sections or _sections(2 * math.pi * radius, edge_length, 48, 12)
    mesh = trimesh.creation.cylinder(radius=radius, height=height, sections=n_sec)
    if edge_length is not None and height > 2 * edge_length:
        # Long side faces become needles; split the sides into rings of about edge_length.
        rings = int(math.ceil(height / edge_length))
        mesh = _cylinder_rings(radius, height, n_sec, rings)
    if not volume_matched:
        return mesh

    def inflate(base, s):
        v = base.vertices.copy()
        v[:, :2] *= s
        return trimesh.Trimesh(v, base.faces, process=False)

    return _match_volume(mesh, math.pi * radius**2 * height, inflate)


def _cylinder_rings(radius, height, sections, rings) -> trimesh.Trimesh:
    """Cylinder with the side split into ``rings`` bands and fan caps."""
    theta = np.linspace(0, 2 * math.pi, sections, endpoint=False)
    z = np.linspace(-height / 2, height / 2, rings + 1)
    ring_v = np.stack(np.broadcast_arrays(radius * np.cos(theta)[None, :], radius * np.sin(theta)[None, :], z[:, None]), -1)
    verts = np.concatenate([ring_v.reshape(-1, 3), [[0, 0, -height / 2], [0, 0, height / 2]]])
    idx = np.arange((rings + 1) * sections).reshape(rings + 1, sections)
    nxt = np.roll(idx, -1, axis=1)
    a, b, c, d = idx[:-1], nxt[:-1], nxt[1:], idx[1:]
    side = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    bottom_c, top_c = len(verts) - 2, len(verts) - 1
    bottom = np.stack([np.full(sections, bottom_c), nxt[0], idx[0]], -1)
    top = np.stack([np.full(sections, top_c), idx[-1], nxt[-1]], -1)
    mesh = trimesh.Trimesh(verts, np.concatenate([side, bottom, top]), process=True)
    trimesh.repair.fix_normals(mesh)
    return mesh


#: name -> (factory, {parameter: default}) for specs like "torus:major=0.1,minor=0.025".
PRIMITIVES = {
    "torus": (torus, {"major": RING_MAJOR_RADIUS, "minor": RING_MINOR_RADIUS}),
    "ring": (torus, {"major": RING_MAJOR_RADIUS, "minor": RING_MINOR_RADIUS}),
    "box": (box, {"x": 1.0, "y": 1.0, "z": 0.01}),
    "sphere": (sphere, {"radius": 0.05}),
    "cylinder": (cylinder, {"radius": 0.05, "height": 0.1}),
}


def parse_primitive_spec(spec: str) -> tuple[str, dict[str, float]] | None:
    """Parse ``name`` or ``name:key=value,...`` into (name, parameters), or None if ``spec``
    names no primitive. Unknown parameters raise OptionError listing the allowed ones."""
    name, _, rest = spec.partition(":")
    name = name.strip().lower()
    if name not in PRIMITIVES:
        return None
    params = dict(PRIMITIVES[name][1])
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, eq, value = item.partition("=")
        key = key.strip()
        if not eq or key not in params:
            raise OptionError(
                f"primitive {name!r}: unknown parameter {item!r}; allowed: "
                + ", ".join(f"{k}=<metres> (default {v:g})" for k, v in PRIMITIVES[name][1].items())
            )
        try:
            params[key] = float(value)
        except ValueError:
            raise OptionError(f"primitive {name!r}: {key}={value!r} is not a number") from None
    return name, params


def make_primitive(name: str, params: dict[str, float], *, edge_length: float | None = None) -> trimesh.Trimesh:
    """Build primitive ``name`` from spec parameters (metres); see :data:`PRIMITIVES`."""
    if name in ("torus", "ring"):
        return torus(params["major"], params["minor"], edge_length=edge_length)
    if name == "box":
        return box((params["x"], params["y"], params["z"]), edge_length=edge_length)
    if name == "sphere":
        return sphere(params["radius"], edge_length=edge_length)
    if name == "cylinder":
        return cylinder(params["radius"], params["height"], edge_length=edge_length)
    raise OptionError(f"unknown primitive {name!r}: use one of {', '.join(PRIMITIVES)}")
