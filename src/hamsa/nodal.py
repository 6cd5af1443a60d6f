"""Nodal domains of functions on a mesh, Courant's nodal theorem, and nodal segmentation (paper 2.7).

A vertex function is read as its piecewise-linear (P1) interpolant. Its nodal domains (the connected
components of {f > 0} and {f < 0}) are then exactly the connected components of the graph of mesh
edges joining two vertices of the same strict sign: inside a triangle, two vertices of one sign share
an edge, and the zero crossing on an edge with endpoints of opposite signs separates them. Vertices
with |f| <= zero_tol * max|f| lie on the nodal set and belong to no domain (label -1). On a point cloud the
graph is that of its operator (:attr:`hamsa.pointcloud.PointCloud.edges`, the local triangulations' edges).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from hamsa.eigen import Eigenbasis
from hamsa.errors import HamsaError
from hamsa.pointcloud import as_shape


def nodal_domains(mesh, f, zero_tol: float = 1e-9) -> tuple[int, np.ndarray]:
    """Nodal domains of a vertex function.

    Parameters
    ----------
    mesh : TriMesh, (vertices, faces) or PointCloud (its graph: :attr:`~hamsa.pointcloud.PointCloud.edges`)
    f : (n,) array
    zero_tol : float
        Values with |f| <= zero_tol * max|f| count as zero (on the nodal set).

    Returns
    -------
    count : int
    labels : (n,) int64, domain index 0..count-1 per vertex, -1 on the nodal set; domains are numbered
        in order of their smallest vertex index.
    """
    mesh = as_shape(mesh)
    f = np.asarray(f, dtype=np.float64)
    if f.shape != (mesh.n_vertices,):
        raise HamsaError(f"function has shape {f.shape}, the mesh has {mesh.n_vertices} vertices")
    if not np.all(np.isfinite(f)):
        raise HamsaError("function has non-finite values")
    scale = np.abs(f).max()
    sign = np.where(np.abs(f) <= zero_tol * scale, 0, np.sign(f)).astype(np.int8)
    e = mesh.edges
    same = (sign[e[:, 0]] == sign[e[:, 1]]) & (sign[e[:, 0]] != 0)
    n = mesh.n_vertices
    graph = sp.coo_matrix((np.ones(same.sum()), (e[same, 0], e[same, 1])), shape=(n, n))
    _, components = connected_components(graph, directed=False)
    labels = np.full(n, -1, dtype=np.int64)
    signed = sign != 0
    # renumber the components of signed vertices 0..count-1 by first appearance
    _, first, inverse = np.unique(components[signed], return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    labels[signed] = rank[inverse.ravel()]
    return len(first), labels


def eigenvalue_clusters(values, rtol: float = 1e-6) -> np.ndarray:
    """Cluster index of each eigenvalue: consecutive values within rtol (relative to the spectrum's scale)."""
    values = np.asarray(values, dtype=np.float64)
    scale = max(np.abs(values).max(), 1e-300)
    breaks = np.diff(values) > rtol * scale
    return np.concatenate([[0], np.cumsum(breaks)])


def courant_check(mesh, basis: Eigenbasis, count: int | None = None, zero_tol: float = 1e-9) -> list[dict]:
    """Check Courant's nodal theorem on the first ``count`` eigenfunctions (paper Prop. 1).

    The discrete version (Davies, Gladwell, Leydold, Stadler 2001) bounds the number of (strong) nodal
    domains of the i-th eigenfunction (1-based) by ``i + r - 1`` where r is the multiplicity of its
    eigenvalue and i the first index of that eigenvalue, i.e. by the last index of its cluster.

    Returns one dict per eigenfunction: index (1-based), value, domains, bound, holds.
    """
    count = basis.k if count is None else count
    clusters = eigenvalue_clusters(basis.values)
    last_index = {c: int(np.flatnonzero(clusters == c).max()) + 1 for c in np.unique(clusters)}
    rows = []
    for i in range(count):
        domains, _ = nodal_domains(mesh, basis.vectors[:, i], zero_tol)
        bound = last_index[clusters[i]]
        rows.append(
            {
                "index": i + 1,
                "value": float(basis.values[i]),
                "domains": domains,
                "bound": bound,
                "holds": domains <= bound,
            }
        )
    return rows


def segment(mesh, basis: Eigenbasis, index: int, min_vertices: int = 1) -> np.ndarray:
    """Segment a mesh by the nodal domains of eigenfunction ``index`` (0-based): (n,) labels >= 0.

    Nodal-set vertices and domains smaller than ``min_vertices`` join the neighbouring domain they
    share most edges with, so every vertex gets a segment.
    """
    mesh = as_shape(mesh)
    if not 0 <= index < basis.k:
        raise HamsaError(f"eigenfunction index {index} is outside the basis (k = {basis.k})")
    _, labels = nodal_domains(mesh, basis.vectors[:, index])
    sizes = np.bincount(labels[labels >= 0])
    labels = np.where((labels >= 0) & (sizes[np.maximum(labels, 0)] >= min_vertices), labels, -1)
    e = mesh.edges
    while np.any(labels < 0):
        a, b = labels[e[:, 0]], labels[e[:, 1]]
        # an unlabelled endpoint takes the label of its labelled neighbour (majority by edge count)
        pairs = np.concatenate(
            [
                np.stack([e[(a < 0) & (b >= 0), 0], b[(a < 0) & (b >= 0)]], 1),
                np.stack([e[(b < 0) & (a >= 0), 1], a[(b < 0) & (a >= 0)]], 1),
            ]
        )
        if len(pairs) == 0:  # a component without any labelled vertex
            labels[labels < 0] = labels.max() + 1
            break
        uniq, counts = np.unique(pairs, axis=0, return_counts=True)
        best = np.lexsort((-counts, uniq[:, 0]))
        chosen = uniq[best]
        first = np.concatenate([[True], chosen[1:, 0] != chosen[:-1, 0]])
        labels[chosen[first, 0]] = chosen[first, 1]
    _, relabel = np.unique(labels, return_inverse=True)
    return relabel.ravel().astype(np.int64)
