"""The spectral gradient fields embedding (SGFE, Shtern & Kimmel 2015): ICP on eigenfunction values and
the pointwise inner products of their gradients."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from hamsa.eigen import Eigenbasis
from hamsa.errors import HamsaError
from hamsa.matching.icp import alternate, procrustes
from hamsa.matching.nearest import nearest_in
from hamsa.mesh import as_trimesh
from hamsa.operators import face_gradients


def spectral_gradient_fields(mesh, basis: Eigenbasis, k: int = 10) -> np.ndarray:
    """Pointwise inner products of eigenfunction gradients ``G_ij(x) = <grad psi_i, grad psi_j>(x)``, (n, k, k).

    Intrinsic, so for an isometry with functional map C they transform as ``G_t(T x) = C^T G_s(x) C``.
    Per-face gradients of the P1 functions (:func:`hamsa.operators.face_gradients`), averaged to the vertices
    with the face areas as weights, of the first k eigenfunctions; each gradient is divided by its L2 norm
    ``sqrt(psi_i^T W psi_i)`` so the entries are dimensionless (a zero-energy mode, the constant, is left
    as is: its gradient is zero).

    Raises
    ------
    HamsaError
        If the mesh and the basis have different vertex counts.
    """
    mesh = as_trimesh(mesh)
    if mesh.n_vertices != basis.n:
        raise HamsaError(f"the mesh has {mesh.n_vertices} vertices, the basis {basis.n}")
    k = min(int(k), basis.k)
    gradients = face_gradients(mesh, basis.vectors[:, :k])  # (m, 3, k)
    areas = mesh.face_areas
    energy = np.einsum("m,mdi,mdi->i", areas, gradients, gradients)
    gradients = gradients / np.sqrt(np.where(energy > 1e-12 * energy.max(), energy, 1.0))
    per_face = np.einsum("mdi,mdj->mij", gradients, gradients).reshape(len(areas), -1)
    incidence = sp.csr_matrix(
        (np.repeat(areas, 3), (mesh.faces.ravel(), np.repeat(np.arange(len(areas)), 3))),
        shape=(mesh.n_vertices, len(areas)),
    )
    weight = np.asarray(incidence.sum(axis=1)).ravel()
    return (incidence @ per_face / weight[:, None]).reshape(mesh.n_vertices, k, k)


def match_sgfe(
    source_mesh,
    target_mesh,
    source: Eigenbasis,
    target: Eigenbasis,
    initial_C: np.ndarray,
    *,
    gradient_k: int = 10,
    weight: float = 1.0,
    iterations: int = 20,
    sample: int = 3000,
    seed: int = 0,
    progress=None,
) -> tuple[np.ndarray, np.ndarray]:
    """Spectral gradient fields embedding (Shtern & Kimmel 2015): ICP on eigenfunction values and gradients.

    Each vertex is embedded by its eigenfunction values and the upper triangle of
    :func:`spectral_gradient_fields` of the first ``gradient_k`` eigenfunctions (off-diagonal entries times
    sqrt 2, so Euclidean distances are Frobenius distances). The source embedding is carried into the
    target's coordinates by an orthogonal C, ``(Psi_s C, C_g^T G_s C_g)`` with C_g the leading
    (gradient_k, gradient_k) block; ICP (:func:`hamsa.matching.icp.alternate`) alternates nearest
    neighbours in the concatenated embedding (``weight`` on the gradient part) and the Procrustes C of the
    value part, from ``initial_C`` (e.g. an HKS functional map after :func:`~hamsa.matching.icp_refine`,
    padded to k), on ``sample`` seeded source vertices. ``progress(done, iterations)``: optional, after each
    ICP iteration (:func:`~hamsa.matching.icp.alternate`).

    Returns
    -------
    (C (k, k), map_source_to_target (n_s,))
    """
    if source.k != target.k or np.shape(initial_C) != (source.k, target.k):
        raise HamsaError(f"need bases of the same size and a ({source.k}, {source.k}) initial C")
    gradient_k = min(gradient_k, source.k)
    G_s = spectral_gradient_fields(source_mesh, source, gradient_k)
    G_t = spectral_gradient_fields(target_mesh, target, gradient_k)
    upper = np.triu_indices(gradient_k)
    factor = np.where(upper[0] == upper[1], 1.0, np.sqrt(2.0)) * weight

    def gradient_part(G, C_g=None):
        G = G if C_g is None else np.einsum("ki,nkl,lj->nij", C_g, G, C_g, optimize=True)
        return G[:, upper[0], upper[1]] * factor

    def embedded(C, rows=slice(None)):
        return np.hstack([source.vectors[rows] @ C, gradient_part(G_s[rows], C[:gradient_k, :gradient_k])])

    tree = cKDTree(np.hstack([target.vectors, gradient_part(G_t)]))
    rows = np.random.default_rng(seed).choice(source.n, min(sample, source.n), replace=False)
    weights = source.mass.diagonal()[rows]

    def fit(mapping):
        return procrustes(source.vectors[rows].T @ (weights[:, None] * target.vectors[mapping]))

    def nearest(C):
        return nearest_in(tree, embedded(C, rows))

    C, _, _ = alternate(np.asarray(initial_C, dtype=np.float64), nearest, fit, iterations, progress=progress)
    return C, nearest_in(tree, embedded(C))
