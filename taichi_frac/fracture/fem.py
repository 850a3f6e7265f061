"""Quasi-static linear elasticity on a body's own tets: the ``"fem"`` stress model.

The half-space field (``field.py``, ``halfspace.py``) knows nothing of the body's shape: a
ring struck on its rim bends, and a half-space cannot bend. Here the body answers with its
shape (as in Bao, Hong, Teran & Fedkiw, "Fracturing Rigid Materials", IEEE TVCG 13(2),
2007): linear tetrahedra (constant strain), the contact force spread over the surface nodes
as the same smooth patch the half-space model loads (normal traction profile
3 a^3 / (2 pi (r^2 + a^2)^(5/2)), ``field.py``), balanced by **inertia relief**: a free
body under a contact force F and torque tau accelerates rigidly (a = F / M, alpha =
I^-1 tau); the d'Alembert body force -rho (a + alpha x r) cancels the load's resultant and
moment exactly, so K u = f has a solution, unique up to the six rigid modes.

- **Rigid modes** are removed by pinning six degrees of freedom of three far-apart nodes
  (the "3-2-1" support, chosen so the pinned rows of the rigid modes are well conditioned):
  with a balanced load the supports carry no reaction, so the stress is the free body's;
  the rigid part is then projected out of the displacement (mass-orthogonal).
- **Cost**: the stiffness is assembled and factorised (sparse Cholesky) once per body
  and material (CHOLMOD: :func:`elastic_body`; ``cracks.elastic_body_of`` keeps it while the body
  lives); each impact is then one pair of triangular solves and a pass over the tets.
- **Stress** is constant on each tet (sigma = lambda tr(eps) I + 2 mu eps, eps = sym(grad u),
  small strain), recovered at the surface nodes by a linear least-squares fit over the
  tets around each (patch recovery, :func:`recovered_stress`; the volume-weighted mean
  inside and beside a contact), and reported at the tet's physics particle (the centroid).
  In bending, where brittle bodies crack, the most tensile particle of a free-free beam
  struck at mid-span reads 0.98 of beam theory's bottom-fibre stress
  (``tests/test_fem_bending.py``).

Units SI, arrays float64, body frame.
"""

from __future__ import annotations

import warnings
import weakref
from dataclasses import dataclass

import numpy as np

from ..model import BodyModel
from ..geometry.topology import boundary_faces, orient_tets
from .stress import lame_parameters


@dataclass(frozen=True, eq=False)
class ElasticBody:
    """A body's factorised linear-elastic model. V nodes, T tets, S surface nodes.

    Attributes:
        vertices: (V,3) [m]; tets: (T,4) int vertex indices.
        shape_gradient: (T,4,3) [1/m] gradients of the four linear shape functions.
        volume: (T,) [m^3].
        lame_lambda, shear_modulus: [Pa].
        node_mass: (V,) [kg] lumped (a quarter of each tet's mass to each corner).
        centre_of_mass: (3,) [m]; inertia: (3,3) [kg m^2] of the lumped masses about it
            (what makes the inertia relief's moment exactly zero).
        surface_node: (S,) int; surface_area: (S,) [m^2] a third of the adjacent boundary
            triangles' area; surface_normal: (S,3) unit outward (area-weighted).
        pinned: (6,) int degrees of freedom (3 node + component) held to remove rigid modes
            (a supported body: every degree of freedom of its fixed nodes).
        free: (3V-6-...) the other degrees of freedom (unused nodes' held too).
        factor: CHOLMOD factorisation of the stiffness on ``free``.
        node_recovery: (V,T) sparse, a node's value from its tets' (:func:`_recovery`: the
            patch fit at a surface node, the plain mean inside).
        node_average: (V,T) sparse, a node's value as the volume-weighted mean of its tets'.
        tet_average: (T,V) sparse, a tet's value as the mean of its four nodes'.
        node_spacing: (V,) [m] the mean length of the edges of a node's tets.
        free_body: True for a free body (its displacement has the rigid modes removed).
    """

    vertices: np.ndarray
    tets: np.ndarray
    shape_gradient: np.ndarray
    volume: np.ndarray
    lame_lambda: float
    shear_modulus: float
    node_mass: np.ndarray
    centre_of_mass: np.ndarray
    inertia: np.ndarray
    surface_node: np.ndarray
    surface_area: np.ndarray
    surface_normal: np.ndarray
    pinned: np.ndarray
    free: np.ndarray
    factor: object
    node_recovery: object
    node_average: object
    tet_average: object
    node_spacing: np.ndarray
    free_body: bool = True

    @property
    def node_count(self) -> int:
        return len(self.vertices)


def shape_gradients(vertices, tets):
    """(T,4,3) [1/m] gradients of the linear shape functions and (T,) [m^3] signed volumes."""
    x = vertices[tets]  # (T,4,3)
    edges = (x[:, 1:] - x[:, :1]).transpose(0, 2, 1)  # (T,3,3) columns x_k - x_0
    det = np.linalg.det(edges)
    if np.any(np.abs(det) <= 1e-30 * np.max(np.abs(det), initial=1.0)):
        raise ValueError("degenerate (zero-volume) tet in the mesh: clean the tet mesh first")
    inv = np.linalg.inv(edges)  # rows: gradients of N_1, N_2, N_3
    grads = np.empty((len(tets), 4, 3))
    grads[:, 1:] = inv
    grads[:, 0] = -inv.sum(axis=1)
    return grads, det / 6.0


def _stiffness(grads, volume, lam, mu):
    """(T,4,3,4,3) element stiffnesses [N/m]: K_e[i a, j b] = V (lam g_ia g_jb + mu (g_ib g_ja +
    delta_ab g_i . g_j)), g_i the shape-function gradients (linear tet, Zienkiewicz & Taylor,
    "The Finite Element Method", vol. 1, ch. 6)."""
    g = grads * np.sqrt(np.abs(volume))[:, None, None]
    gi = g[:, :, :, None, None]  # (T,4,3,1,1): g_ia
    gj = g[:, None, None, :, :]  # (T,1,1,4,3): g_jb
    ke = lam * gi * gj + mu * g[:, :, None, None, :] * g.transpose(0, 2, 1)[:, None, :, :, None]
    dots = np.einsum("tik,tjk->tij", g, g)
    for k in range(3):
        ke[:, :, k, :, k] += mu * dots
    return ke


def elastic_body(vertices, tets, density, young_modulus, poisson_ratio, *, surface_faces=None,
                 fixed_nodes=None) -> ElasticBody:
    """Assemble and factorise the linear-elastic model of a tet mesh (once per body).

    Args:
        vertices: (V,3) [m]; tets: (T,4) vertex indices (any orientation).
        density: [kg/m^3] > 0; young_modulus: E [Pa]; poisson_ratio: nu in [0, 0.5).
        surface_faces: (F,3) boundary triangles, outward winding; None = found from the tets.
        fixed_nodes: node indices held at zero displacement (a supported structure, e.g. a
            clamped cantilever); None = a free body (rigid modes removed, loads must be
            balanced: :func:`inertia_relief`).
    """
    verts = np.ascontiguousarray(vertices, dtype=np.float64)
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    if verts.ndim != 2 or verts.shape[1] != 3 or tets.ndim != 2 or tets.shape[1] != 4 or len(tets) == 0:
        raise ValueError(f"vertices {verts.shape} and tets {tets.shape} must be (V,3) and (T,4), T > 0")
    if tets.min() < 0 or tets.max() >= len(verts):
        raise ValueError("tet vertex index out of range")
    if not (np.isfinite(density) and density > 0.0):
        raise ValueError(f"density must be > 0, got {density!r}")
    lam, mu = lame_parameters(young_modulus, poisson_ratio)
    tets = orient_tets(verts, tets).astype(np.int64)  # so the boundary faces wind outward
    grads, volume = shape_gradients(verts, tets)
    used = np.unique(tets)
    n = len(verts)


    node_mass = np.zeros(n)
    np.add.at(node_mass, tets.reshape(-1), np.repeat(density * volume / 4.0, 4))
    com = node_mass @ verts / node_mass.sum()
    r = verts - com
    inertia = np.einsum("v,vk,vk->", node_mass, r, r) * np.eye(3) - np.einsum("v,va,vb->ab", node_mass, r, r)

    faces = boundary_faces(tets)[0] if surface_faces is None else np.asarray(surface_faces, dtype=np.int64)
    tri = verts[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # 2 x area x outward normal
    area = np.zeros(n)
    normal = np.zeros((n, 3))
    np.add.at(area, faces.reshape(-1), np.repeat(np.linalg.norm(cross, axis=1) / 6.0, 3))
    np.add.at(normal, faces.reshape(-1), np.repeat(cross, 3, axis=0))
    surface_node = np.nonzero(area > 0.0)[0]
    surface_normal = normal[surface_node]
    surface_normal /= np.maximum(np.linalg.norm(surface_normal, axis=1, keepdims=True), 1e-300)

    if fixed_nodes is None:
        pinned = _pinned_dofs(verts[used], com)
        pinned = 3 * used[pinned // 3] + pinned % 3
    else:
        pinned = (3 * np.asarray(fixed_nodes, dtype=np.int64)[:, None] + np.arange(3)).reshape(-1)
    # Nodes no tet uses have no stiffness: hold them too (they carry no load).
    unused = np.setdiff1d(np.arange(n), used)
    held = np.union1d(pinned, (3 * unused[:, None] + np.arange(3)).reshape(-1))
    free = np.setdiff1d(np.arange(3 * n), held)
    factor = _factorise(_stiffness(grads, volume, lam, mu), tets, free, n)
    return ElasticBody(vertices=verts, tets=tets, shape_gradient=grads, volume=np.abs(volume), lame_lambda=lam,
                       shear_modulus=mu, node_mass=node_mass, centre_of_mass=com, inertia=inertia,
                       surface_node=surface_node, surface_area=area[surface_node], surface_normal=surface_normal,
                       pinned=pinned, free=free, factor=factor, free_body=fixed_nodes is None,
                       **_recovery(verts, tets, np.abs(volume), n, surface_node))


# The largest noise gain of a surface node's recovered stress: the sum of the absolute
# weights that map the tets' stresses to it. A mean has 1; the fit extrapolated to a node on
# a flat face of a structured mesh has 2, at its edges and corners 4-6, on tetgen surfaces
# 2-4. Measured on the beam of :func:`recovered_stress` (8 elements through the depth) and
# the ring's landing impact: at 2 the most tensile particle reads 0.93 of the beam's fibre
# stress (1.01 of beam theory at the particle) and the ring's bending peak 265 MPa on 4,894
# tets; at 3, 0.98 (1.06) and 302 MPa (339 on 116,536 tets, near converged); at 4, 1.04
# (1.13).
RECOVERY_GAIN = 3.0
# Surface nodes facing a contact within this many edge lengths of it take the plain mean
# (:func:`contact_nodes`). At 2 the benchmark cube's largest principal stress near its
# contact (2h to L/3 from it, mostly the loaded face) read 74 % off at 4,822 tets, at 3
# 40 %, as the plain mean.
CONTACT_REACH = 3.0


def _recovery(vertices, tets, volume, node_count, surface_node):
    """The sparse maps of :func:`recovered_stress`: tets -> nodes, the patch recovery
    ``node_recovery`` and the plain mean ``node_average`` (V,T); nodes -> tets, the mean of a
    tet's four corners ``tet_average`` (T,V); and ``node_spacing`` (V,) [m], the mean length
    of the edges of a node's tets.

    A node's patch is the tets around it; its plain mean is their volume-weighted mean. At a
    surface node a linear field a + b . (x - x_node) is fitted to their constant stresses,
    sampled at their centroids (least squares, weighted by volume; Zienkiewicz & Zhu, "The
    superconvergent patch recovery and a posteriori error estimates", IJNME 33, 1992), and
    the node takes a: a = sum_t g_t sigma_t with sum_t g_t = 1 and
    sum_t g_t (c_t - x_node) = 0, so a uniform or linear field is kept exactly. The
    centroids all lie on one side of the node, so a is extrapolated: some weights are
    negative and amplify the tets' scatter. The weights are blended toward the plain mean,
    g = theta g_fit + (1 - theta) g_mean, with the largest theta in [0, 1] whose gain
    sum_t |g_t| is at most ``RECOVERY_GAIN`` (the gain is convex in theta and 1 at
    theta = 0: bisection). A patch of fewer than 4 tets, or whose centroids are (nearly)
    coplanar, takes the mean.

    An interior node takes the plain mean: around it the fit's value differs from the mean
    only where the patch is lopsided, as on a graded mesh, and there a field far from linear
    (1/r^2 near a load) made it worse: the graded block of ``test_stress_models`` read its
    quadrants' mean stress 10-55 % off with fits at every node, 10-13 % with the mean
    inside. Every map's rows sum to 1, so a uniform stress stays exact everywhere."""
    import scipy.sparse as sp

    count = len(tets)
    node = tets.reshape(-1)
    owner = np.repeat(np.arange(count), 4)
    offset = vertices[tets].mean(axis=1)[owner] - vertices[node]  # (4T,3) node -> centroid
    total = np.bincount(node, volume[owner], node_count)
    mean = volume[owner] / np.where(total > 0.0, total, 1.0)[node]  # the plain mean's weights
    size = np.sqrt(np.maximum(np.bincount(node, mean * np.einsum("ij,ij->i", offset, offset), node_count), 1e-300))
    basis = np.concatenate([np.ones((len(node), 1)), offset / size[node, None]], axis=1)  # (4T,4), unitless
    normal = np.zeros((node_count, 4, 4))
    np.add.at(normal, node, mean[:, None, None] * basis[:, :, None] * basis[:, None, :])
    spread = normal[:, 1:, 1:] - normal[:, 0, 1:, None] * normal[:, 0, None, 1:]  # covariance of the centroids
    fitted = np.zeros(node_count, dtype=bool)
    fitted[surface_node] = True
    fitted &= (np.bincount(node, minlength=node_count) >= 4) & (np.linalg.eigvalsh(spread)[:, 0] > 1e-6)
    first_row = np.zeros((node_count, 4))
    first_row[fitted] = np.linalg.inv(normal[fitted])[:, 0]
    fit = np.where(fitted[node], mean * np.einsum("ik,ik->i", first_row[node], basis), mean)

    def gain(theta):
        return np.bincount(node, np.abs(mean + theta[node] * (fit - mean)), node_count)

    low = np.where(gain(np.ones(node_count)) <= RECOVERY_GAIN * (1.0 + 1e-9), 1.0, 0.0)
    high = np.ones(node_count)
    for _ in range(30):
        mid = 0.5 * (low + high)
        within = gain(mid) <= RECOVERY_GAIN
        low, high = np.where(within, mid, low), np.where(within, high, mid)

    pairs = [(i, j) for i in range(4) for j in range(i + 1, 4)]
    edge = np.linalg.norm(vertices[tets[:, [i for i, _ in pairs]]] - vertices[tets[:, [j for _, j in pairs]]], axis=2)
    spacing = np.bincount(node, np.repeat(edge.mean(axis=1), 4), node_count)
    spacing /= np.maximum(np.bincount(node, minlength=node_count), 1)
    return {"node_recovery": sp.csr_matrix((mean + low[node] * (fit - mean), (node, owner)), shape=(node_count, count)),
            "node_average": sp.csr_matrix((mean, (node, owner)), shape=(node_count, count)),
            "tet_average": sp.csr_matrix((np.full(4 * count, 0.25), (owner, node)), shape=(count, node_count)),
            "node_spacing": spacing}


def _factorise(element_stiffness, tets, free, node_count):
    """Sparse Cholesky (CHOLMOD, supernodal, AMD ordering, through cvxopt) of the stiffness
    restricted to the ``free`` degrees of freedom, assembled straight from the element
    matrices (T,4,3,4,3) (lower triangle; duplicates summed). SuperLU (scipy) took ~9x as
    long on a 20,000-tet body, a solve ~3x."""
    from cvxopt import cholmod, matrix, spmatrix

    reduced = np.full(3 * node_count, -1, dtype=np.int64)
    reduced[free] = np.arange(len(free))
    dof = reduced[(3 * tets[:, :, None] + np.arange(3)).reshape(len(tets), 12)]
    rows = np.broadcast_to(dof[:, :, None], (len(tets), 12, 12)).reshape(-1)
    cols = np.broadcast_to(dof[:, None, :], (len(tets), 12, 12)).reshape(-1)
    keep = (rows >= cols) & (cols >= 0)
    size = len(free)
    stiffness = spmatrix(matrix(element_stiffness.reshape(-1)[keep]), matrix(rows[keep]), matrix(cols[keep]),
                         (size, size))
    options = {"supernodal": 2, "postorder": True}
    factor = cholmod.symbolic(stiffness, uplo="L")
    saved = dict(cholmod.options)
    try:
        cholmod.options.update(options)
        cholmod.numeric(stiffness, factor)
    except ArithmeticError as error:
        raise ValueError("the stiffness is not positive definite: the tet mesh has a piece attached to the "
                         "rest by an edge or a vertex only, or inverted tets") from error
    finally:
        cholmod.options.clear()
        cholmod.options.update(saved)
    return factor


_BODIES: "weakref.WeakKeyDictionary[BodyModel, dict]" = weakref.WeakKeyDictionary()


def elastic_body_of(model: BodyModel, material) -> ElasticBody:
    """The factorised elastic model of a body model and ``material`` (Material: E, nu),
    built on first use and kept while the model lives: a body is factorised once and every
    impact on it reuses it (a fragment when it is first analysed). None (with a warning)
    where the stiffness is singular; the crack analysis then uses the half-space model."""
    per_model = _BODIES.setdefault(model, {})
    key = (float(material.young_modulus), float(material.poisson_ratio))
    if key not in per_model:
        try:
            per_model[key] = elastic_body(model.vertices, model.tets, model.density, *key,
                                          surface_faces=model.surface_faces)
        except ValueError as error:  # a piece held to the rest by an edge or a vertex only
            warnings.warn(f"fem stress model: {error}; this body ({model.tet_count} tets) uses the half-space "
                          "model instead", RuntimeWarning, stacklevel=2)
            per_model[key] = None
    return per_model[key]


def rigid_modes(points, centre):
    """(3P,6) the rigid modes of points (P,3) [m]: three translations, three rotations about
    ``centre``."""
    r = points - centre
    modes = np.zeros((len(points), 3, 6))
    modes[:, :, :3] = np.eye(3)
    for k in range(3):
        modes[:, :, 3 + k] = np.cross(np.eye(3)[k], r)
    return modes.reshape(-1, 6)


def _pinned_dofs(points, centre):
    """Six degrees of freedom (node x 3 + component) of three far-apart nodes whose rows of
    the rigid modes form the best-conditioned 6x6 block: holding them removes every rigid
    mode and nothing else."""
    first = int(np.argmax(np.linalg.norm(points - centre, axis=1)))
    second = int(np.argmax(np.linalg.norm(points - points[first], axis=1)))
    axis = points[second] - points[first]
    axis /= np.linalg.norm(axis)
    off = points - points[first]
    off -= np.outer(off @ axis, axis)
    third = int(np.argmax(np.linalg.norm(off, axis=1)))
    nodes = np.array([first, second, third])
    candidates = (3 * nodes[:, None] + np.arange(3)).reshape(-1)
    modes = rigid_modes(points[nodes], centre)
    scale = np.linalg.norm(modes, axis=0)
    best, best_det = None, -1.0
    from itertools import combinations

    for pick in combinations(range(9), 6):
        d = abs(np.linalg.det(modes[list(pick)] / scale))
        if d > best_det:
            best, best_det = pick, d
    if best_det < 1e-9:
        raise ValueError("the body's nodes are (nearly) collinear: no support removes its rigid modes")
    return candidates[list(best)]


def contact_loads(body: ElasticBody, contact_points, normals_in, forces, contact_radii) -> np.ndarray:
    """(V,3) [N] nodal forces of K contact forces, each spread over the surface nodes that
    face it (outward normal against the inward contact normal) with the regularised
    half-space load's traction profile 3 a^3 / (2 pi (r^2 + a^2)^(5/2)) x nodal area,
    normalised so each contact's nodal forces sum to its force exactly."""
    points = np.asarray(contact_points, dtype=np.float64).reshape(-1, 3)
    normals = np.asarray(normals_in, dtype=np.float64).reshape(len(points), 3)
    forces = np.asarray(forces, dtype=np.float64).reshape(len(points), 3)
    radii = np.asarray(contact_radii, dtype=np.float64).reshape(len(points))
    loads = np.zeros((body.node_count, 3))
    nodes = body.vertices[body.surface_node]
    for k in range(len(points)):
        d2 = np.einsum("sx,sx->s", nodes - points[k], nodes - points[k])
        a = max(float(radii[k]), 1e-12)
        facing = body.surface_normal @ normals[k] < 0.0
        weight = np.where(facing, body.surface_area * a**3 / (d2 + a * a) ** 2.5, 0.0)
        total = weight.sum()
        if not total > 0.0:  # no facing node: the nearest surface node takes it all
            weight = np.zeros(len(nodes))
            weight[int(np.argmin(d2))] = 1.0
            total = 1.0
        np.add.at(loads, body.surface_node, np.outer(weight / total, forces[k]))
    return loads


def inertia_relief(body: ElasticBody, loads) -> np.ndarray:
    """(V,3) [N] the d'Alembert forces -m_i (a + alpha x r_i) of the rigid acceleration that
    the nodal ``loads`` (V,3) [N] give the free body: loads + relief has zero resultant and
    zero moment (with the lumped masses and their own inertia, exactly)."""
    r = body.vertices - body.centre_of_mass
    force = loads.sum(axis=0)
    torque = np.cross(r, loads).sum(axis=0)
    accel = force / body.node_mass.sum()
    alpha = np.linalg.solve(body.inertia, torque)
    return -body.node_mass[:, None] * (accel + np.cross(alpha, r))


def solve_displacement(body: ElasticBody, loads) -> np.ndarray:
    """(V,3) [m] displacement under nodal ``loads`` (V,3) [N]: for a free body the loads
    must be balanced, and the rigid part is removed (mass-orthogonal to the six rigid
    modes); a supported body's is returned as solved."""
    f = np.asarray(loads, dtype=np.float64).reshape(-1)
    u = np.zeros(3 * body.node_count)
    from cvxopt import cholmod, matrix

    rhs = matrix(np.ascontiguousarray(f[body.free]))
    cholmod.solve(body.factor, rhs)
    u[body.free] = np.asarray(rhs).reshape(-1)
    if not body.free_body:
        return u.reshape(-1, 3)
    modes = rigid_modes(body.vertices, body.centre_of_mass)
    mass = np.repeat(body.node_mass, 3)
    coeff = np.linalg.solve(modes.T @ (mass[:, None] * modes), modes.T @ (mass * u))
    return (u - modes @ coeff).reshape(-1, 3)


def tet_stress(body: ElasticBody, displacement) -> np.ndarray:
    """(T,3,3) [Pa] the constant stress of each linear tet under nodal ``displacement`` (V,3)."""
    grad = np.einsum("tia,tib->tab", displacement[body.tets], body.shape_gradient)  # d u_a / d x_b
    strain = 0.5 * (grad + grad.transpose(0, 2, 1))
    trace = np.trace(strain, axis1=1, axis2=2)
    return 2.0 * body.shear_modulus * strain + body.lame_lambda * trace[:, None, None] * np.eye(3)


def contact_nodes(body: ElasticBody, contact_points, normals_in) -> np.ndarray:
    """(V,) bool: the surface nodes facing a contact (outward normal against its inward
    normal) within ``CONTACT_REACH`` edge lengths (``node_spacing`` of the surface node
    nearest the contact) of its point. The contact's own stress is singular as its patch
    shrinks (the tets' peak beside the ring's landing contact, 180 kN on a 1.5 mm patch:
    337 MPa at 4,894 tets, 3,912 MPa at 116,536); a fit extrapolated there passed it into
    the surface (808 MPa at 39,402 tets, over the ring's bending peak of 337 MPa), so these
    nodes keep the plain mean (47 MPa)."""
    points = np.asarray(contact_points, dtype=np.float64).reshape(-1, 3)
    normals = np.asarray(normals_in, dtype=np.float64).reshape(len(points), 3)
    near = np.zeros(body.node_count, dtype=bool)
    nodes = body.vertices[body.surface_node]
    for point, normal in zip(points, normals):
        distance = np.linalg.norm(nodes - point, axis=1)
        reach = CONTACT_REACH * body.node_spacing[body.surface_node[int(np.argmin(distance))]]
        near[body.surface_node[(distance < reach) & (body.surface_normal @ normal < 0.0)]] = True
    return near


def recovered_stress(body: ElasticBody, stress, plain=None) -> np.ndarray:
    """(T,3,3) [Pa] the tets' constant stresses (T,3,3) recovered at their centroids: each
    surface node takes the value at the node of a linear field fitted to the stresses of its
    tets (superconvergent patch recovery, capped where it extrapolates), each interior node
    and each node of ``plain`` ((V,) bool, e.g. :func:`contact_nodes`) their volume-weighted
    mean (:func:`_recovery`); each tet the mean of its four nodes'. Sparse products with
    maps built once per body: the cost of a plain nodal mean. A uniform stress is kept
    exactly.

    Linear tets' own stress jumps from tet to tet around the true field, and the plain
    nodal mean flattens a bending stress's peak, which lies on the surface. Measured
    (``tests/test_fem_bending.py``): on a free-free 0.4 x 0.04 x 0.04 m beam struck at
    mid-span (8 elements through the depth, 19,200 tets) the most tensile particle, 1/32 of
    the depth above the bottom fibre, reads 0.98 of beam theory's fibre stress (1.06 of
    beam theory at the particle: the fit at the beam's edges, capped at a gain of 3,
    overshoots by up to 16 %, 1 % on average over the bottom face); the plain nodal mean
    reads 0.78 (0.95 against 0.72 with 6 elements, 0.92 against 0.64 with 4). On a clamped
    circular plate (a / h = 10, 3 layers of tets) under a central load the far face's
    tangential stress reads 7 % under thin-plate theory (nodal mean 40 %). On the ring's
    landing impact (benchmarks/stress_models.py: 180 kN) the bending peak reads 302 MPa on
    4,894 tets, 325 on 19,864, 339 on 116,536 (nodal mean 188, 261, 302), the tension beside
    the contact 34-48 MPa with either. On the benchmark's cube, near its contact, the
    largest principal stress's L1 error is 40 % at 4,822 tets and 43 % at 19,137 (nodal
    mean 40 % and 34 %, the tets' own 142 % and 106 %)."""
    flat = np.asarray(stress, dtype=np.float64).reshape(len(stress), 9)
    nodal = np.asarray(body.node_recovery @ flat)
    if plain is not None and np.any(plain):
        nodal[plain] = body.node_average[np.nonzero(plain)[0]] @ flat
    return np.asarray(body.tet_average @ nodal).reshape(-1, 3, 3)


def fem_response(body: ElasticBody, contact_points, normals_in, forces, contact_radii):
    """One impact: (nodal displacement (V,3) [m], tet stress (T,3,3) [Pa], recovered:
    :func:`recovered_stress`, the contacts' :func:`contact_nodes` on the plain mean) of the
    contacts' patch loads, balanced by inertia relief on a free body (a supported body's
    fixed nodes carry them)."""
    loads = contact_loads(body, contact_points, normals_in, forces, contact_radii)
    if body.free_body:
        loads = loads + inertia_relief(body, loads)
    displacement = solve_displacement(body, loads)
    return displacement, recovered_stress(body, tet_stress(body, displacement),
                                          plain=contact_nodes(body, contact_points, normals_in))
