"""Geometric, potential and topological noise, and how much an eigenbasis moves under it (paper 2.8).

All generators take a ``seed`` and are reproducible. Conventions (where the paper leaves them open):

* vertex noise: i.i.d. Gaussian displacement of each coordinate with standard deviation
  ``sigma = fraction * mean edge length`` (the paper's "sigma_x^2 = 20% of the mean edge length" is
  dimensionally odd; we read it as sigma = 0.2 h);
* potential noise: additive Gaussian with variance ``fraction * Var(V)``;
* topological noise: many small holes (faces within a radius of random seed vertices) until the
  requested fraction of the area is gone; the last hole is trimmed face by face so the removed area
  matches the request, and only the largest connected piece is kept, with its vertex index map.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from hamsa.eigen import Eigenbasis
from hamsa.errors import HamsaError
from hamsa.mesh import TriMesh, as_trimesh
from hamsa.nodal import eigenvalue_clusters


def vertex_noise(mesh, fraction: float = 0.2, seed: int = 0) -> TriMesh:
    """Move every vertex by Gaussian noise of per-coordinate std ``fraction * mean edge length``."""
    mesh = as_trimesh(mesh)
    if fraction < 0:
        raise HamsaError("noise fraction must be >= 0")
    rng = np.random.default_rng(seed)
    sigma = fraction * mesh.mean_edge_length
    return TriMesh(mesh.vertices + sigma * rng.standard_normal(mesh.vertices.shape), mesh.faces)


def potential_noise(potential, fraction: float = 0.2, seed: int = 0) -> np.ndarray:
    """``V + N(0, fraction * Var(V))`` per vertex."""
    v = np.asarray(potential, dtype=np.float64)
    if fraction < 0:
        raise HamsaError("noise fraction must be >= 0")
    rng = np.random.default_rng(seed)
    return v + np.sqrt(fraction * v.var()) * rng.standard_normal(v.shape)


def topological_noise(
    mesh, area_fraction: float = 0.3, hole_radius: float = 3.0, seed: int = 0
) -> tuple[TriMesh, np.ndarray]:
    """Cut small holes until ``area_fraction`` of the surface area is removed.

    Parameters
    ----------
    mesh : TriMesh
    area_fraction : float in [0, 1)
    hole_radius : float
        Radius of each hole in mean edge lengths (faces whose centroid is within it are removed).
    seed : int

    Returns
    -------
    holed : TriMesh
        The largest connected piece left.
    kept : (n_kept,) int64
        ``kept[i]`` is the original index of vertex i of ``holed``.
    """
    mesh = as_trimesh(mesh)
    if not 0 <= area_fraction < 1:
        raise HamsaError(f"area_fraction must be in [0, 1), got {area_fraction}")
    rng = np.random.default_rng(seed)
    centroids = mesh.vertices[mesh.faces].mean(axis=1)
    tree = cKDTree(centroids)
    radius = hole_radius * mesh.mean_edge_length
    removed = np.zeros(mesh.n_faces, dtype=bool)
    target = area_fraction * mesh.area
    removed_area = 0.0
    for center in rng.permutation(mesh.n_faces):
        if removed_area >= target:
            break
        if removed[center]:
            continue
        near = np.asarray(tree.query_ball_point(centroids[center], radius), dtype=np.int64)
        near = near[~removed[near]]
        order = np.argsort(np.linalg.norm(centroids[near] - centroids[center], axis=1))
        near = near[order]
        areas = mesh.face_areas[near]
        take = np.searchsorted(np.cumsum(areas), target - removed_area) + 1  # trims the last hole
        chosen = near[:take]
        removed[chosen] = True
        removed_area += mesh.face_areas[chosen].sum()
    faces = mesh.faces[~removed]
    holed, kept = TriMesh(mesh.vertices, faces).without_unreferenced()
    count, labels = holed.vertex_components
    if count > 1:
        largest = np.argmax(np.bincount(labels[labels >= 0]))
        face_keep = labels[holed.faces[:, 0]] == largest
        holed, kept_inner = TriMesh(holed.vertices, holed.faces[face_keep]).without_unreferenced()
        kept = kept[kept_inner]
    return holed, kept


def refine_region(mesh, faces) -> TriMesh:
    """The same surface with a denser triangulation on some faces: a remeshing for discretization tests.

    The chosen faces are split 1-to-4 at their edge midpoints ("red"); a face with two split edges is
    split 1-to-4 too (repeated until none is left), and a face with one split edge is bisected ("green"),
    so the result is conforming — no hanging vertices. Midpoints lie on the flat faces: the piecewise-linear
    surface is unchanged, only its sampling. The original vertices keep their indices (0..n-1); the
    midpoints follow.

    Parameters
    ----------
    mesh : TriMesh or (vertices, faces)
    faces : (m,) bool mask or face indices to refine
    """
    mesh = as_trimesh(mesh)
    F = mesh.faces
    red = np.zeros(len(F), dtype=bool)
    red[np.asarray(faces)] = True
    corner_edges = np.sort(np.stack([F, np.roll(F, -1, axis=1)], axis=2), axis=2)  # edge c: v_c -> v_{c+1}
    unique, edge_ids = np.unique(corner_edges.reshape(-1, 2), axis=0, return_inverse=True)
    edge_ids = edge_ids.reshape(-1, 3)
    while True:
        split = np.zeros(len(unique), dtype=bool)
        split[edge_ids[red]] = True
        promote = ~red & (split[edge_ids].sum(axis=1) >= 2)
        if not promote.any():
            break
        red |= promote
    new_id = np.full(len(unique), -1, dtype=np.int64)
    new_id[split] = mesh.n_vertices + np.arange(split.sum())
    vertices = np.vstack([mesh.vertices, mesh.vertices[unique[split]].mean(axis=1)])
    m = new_id[edge_ids]  # (faces, 3) midpoint of edge c, or -1
    v0, v1, v2 = F.T
    out = [F[~red & (m < 0).all(axis=1)]]
    r = red
    out += [np.stack(t, axis=1) for t in (
        (v0[r], m[r, 0], m[r, 2]), (v1[r], m[r, 1], m[r, 0]), (v2[r], m[r, 2], m[r, 1]), (m[r, 0], m[r, 1], m[r, 2])
    )]  # fmt: skip
    for c in range(3):  # green: only edge c split
        g = ~red & (m[:, c] >= 0)
        a, b, opposite = F[g, c], F[g, (c + 1) % 3], F[g, (c + 2) % 3]
        out += [np.stack([a, m[g, c], opposite], axis=1), np.stack([m[g, c], b, opposite], axis=1)]
    return TriMesh(vertices, np.vstack(out))


def basis_stability(
    clean: Eigenbasis, perturbed: Eigenbasis, kept=None, count: int | None = None, cluster_rtol: float = 0.03
) -> np.ndarray:
    """How well each clean eigenfunction survives a perturbation: (count,) values in [0, 1].

    Eigenfunctions are compared in the clean basis's A-inner product on the vertices both share
    (``kept``: original indices of the perturbed mesh's vertices, from :func:`topological_noise`).
    Within a cluster of (near-)repeated eigenvalues the basis is arbitrary, and a perturbation mixes
    eigenvectors whose eigenvalues are closer than its size (Davis-Kahan), so each clean mode gets the
    norm of its projection onto the perturbed modes of its cluster's index range (the cosine of its
    principal angle to that eigenspace). Clusters join consecutive clean eigenvalues closer than
    ``cluster_rtol`` times the largest one; isolated eigenvalues reduce to ``|<psi_i, psi~_i>_A|``.
    """
    count = min(clean.k, perturbed.k) if count is None else count
    kept = np.arange(clean.n) if kept is None else np.asarray(kept)
    if perturbed.n != len(kept):
        raise HamsaError(f"perturbed basis has {perturbed.n} vertices, kept map has {len(kept)}")
    weights = clean.mass.diagonal()[kept]
    a = clean.vectors[kept, :count]
    b = perturbed.vectors[:, :count]
    a = a / np.sqrt((weights[:, None] * a**2).sum(axis=0))
    b = b / np.sqrt((weights[:, None] * b**2).sum(axis=0))
    overlap = a.T @ (weights[:, None] * b)  # (count, count)
    clusters = eigenvalue_clusters(clean.values[:count], rtol=cluster_rtol)
    result = np.empty(count)
    for c in np.unique(clusters):
        members = np.flatnonzero(clusters == c)
        result[members] = np.linalg.norm(overlap[np.ix_(members, members)], axis=1)
    return np.minimum(result, 1.0)
