"""Functional maps (Ovsjanikov et al. 2012): fitting C to descriptors, point maps <-> C, ICP and ZoomOut.

Directions are explicit. A point map is ``map_source_to_target`` (for each source vertex, a target vertex).
Its functional map pulls functions on the target back to the source: in the A-orthonormal bases Psi_s,
Psi_t, ``C = Psi_s^T A_s Pi Psi_t`` (k_s, k_t), with Pi[y, map(y)] = 1, so that the coefficients of
``g o map`` are ``C`` times those of g. Any basis works: the LBO's or a Hamiltonian's.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from hamsa.eigen import Eigenbasis
from hamsa.errors import HamsaError
from hamsa.matching.icp import alternate, procrustes
from hamsa.matching.nearest import nearest_in, nearest_rows


def functional_map(
    source: Eigenbasis, target: Eigenbasis, source_descriptors, target_descriptors, laplacian_weight: float = 1e-3
) -> np.ndarray:
    """The (k_s, k_t) functional map C pulling target functions back to the source, fitted to descriptors.

    Minimizes ``||C b - a||^2 + w ||C Lambda_t - Lambda_s C||^2`` with a = Psi_s^T A_s F (k_s, d) and
    b = Psi_t^T A_t G (k_t, d), the descriptors' coefficients; row by row,
    ``(b b^T + w diag((lambda_t - lambda_s,i)^2)) c_i = b a_i``. The eigenvalues are divided by the largest
    magnitude on either shape, so w is scale-free.

    Raises
    ------
    HamsaError
        If the descriptors are not (n, d) arrays with the same d on both shapes.
    """
    a = source.project(source_descriptors)  # (k_s, d)
    b = target.project(target_descriptors)  # (k_t, d)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1]:
        raise HamsaError("descriptors must be (n, d) arrays with the same d on both shapes")
    scale = max(np.abs(source.values).max(), np.abs(target.values).max(), 1e-300)
    ls, lt = source.values / scale, target.values / scale
    gram = b @ b.T
    C = np.empty((source.k, target.k))
    for i in range(source.k):
        system = gram + laplacian_weight * np.diag((lt - ls[i]) ** 2)
        C[i] = np.linalg.solve(system + 1e-12 * np.trace(gram) * np.eye(target.k), b @ a[i])
    return C


def map_from_functional(C: np.ndarray, source: Eigenbasis, target: Eigenbasis) -> np.ndarray:
    """``map_source_to_target`` (n_s,) from a functional map C (k_s, k_t): nearest neighbours of the rows of
    ``Psi_s C`` among the rows of ``Psi_t``."""
    C = np.asarray(C)
    if C.shape != (source.k, target.k):
        raise HamsaError(f"C has shape {C.shape}, expected ({source.k}, {target.k})")
    return nearest_rows(source.vectors @ C, target.vectors)


def functional_from_map(map_source_to_target, source: Eigenbasis, target: Eigenbasis) -> np.ndarray:
    """``C = Psi_s^T A_s Pi Psi_t`` (k_s, k_t) of a point map (n_s,), with the lumped source mass."""
    index = np.asarray(map_source_to_target)
    if index.shape != (source.n,):
        raise HamsaError(f"the map has shape {index.shape}, the source has {source.n} vertices")
    weights = source.mass.diagonal()
    return source.vectors.T @ (weights[:, None] * target.vectors[index])


def icp_refine(
    C: np.ndarray, source: Eigenbasis, target: Eigenbasis, iterations: int = 10
) -> tuple[np.ndarray, np.ndarray]:
    """Orthogonal refinement of a square functional map (Ovsjanikov et al. 2012): alternate the point map
    and the closest orthogonal C (:func:`hamsa.matching.icp.alternate`), at most ``iterations`` refits.

    Returns ``(C (k, k), map_source_to_target (n_s,))``, the map being the nearest neighbours under C.
    """
    C = np.asarray(C, dtype=np.float64)
    if C.shape != (source.k, target.k):
        raise HamsaError(f"C has shape {C.shape}, expected ({source.k}, {target.k})")
    tree = cKDTree(target.vectors)
    weights = source.mass.diagonal()

    def nearest(C):
        return nearest_in(tree, source.vectors @ C)

    def fit(mapping):
        return procrustes(source.vectors.T @ (weights[:, None] * target.vectors[mapping]))

    C, _, _ = alternate(C, nearest, fit, iterations)
    return C, nearest(C)


def zoomout(
    map_source_to_target, source: Eigenbasis, target: Eigenbasis, sizes=None, progress=None
) -> tuple[np.ndarray, np.ndarray]:
    """Spectral upsampling (ZoomOut, Melzi et al. 2019): refine a point map by alternating
    ``C_k = Psi_s[:, :k]^T A_s Pi Psi_t[:, :k]`` and the nearest-neighbour map of C_k, for growing k.

    Parameters
    ----------
    map_source_to_target : (n_s,) initial point map (e.g. from a small functional map)
    source, target : eigenbases with at least max(sizes) eigenpairs
    sizes : increasing basis sizes (default every integer from min(10, k) to k = min(k_s, k_t); starting
        much smaller collapses the map: a 4-dimensional embedding cannot tell most vertices apart)
    progress : optional ``progress(done, total)``, called after each size

    Returns
    -------
    (C, map_source_to_target) at the largest size.
    """
    top = min(source.k, target.k)
    sizes = list(range(min(10, top), top + 1)) if sizes is None else [int(s) for s in sizes]
    if not sizes or max(sizes) > top or min(sizes) < 1:
        raise HamsaError(f"sizes must lie in [1, {top}], got {sizes}")
    mapping = np.asarray(map_source_to_target)
    C = None
    for done, size in enumerate(sizes, 1):
        s, t = source.truncate(size), target.truncate(size)
        C = functional_from_map(mapping, s, t)
        mapping = map_from_functional(C, s, t)
        if progress is not None:
            progress(done, len(sizes))
    return C, mapping


def offdiagonal_energy(C: np.ndarray) -> float:
    """``||C - diag(C)||_F / ||C||_F``: 0 for a diagonal functional map, the measure of how far a basis
    pair is from commuting with the map."""
    C = np.asarray(C, dtype=np.float64)
    if C.ndim != 2:
        raise HamsaError(f"C must be a matrix, got shape {C.shape}")
    total = np.linalg.norm(C)
    if total == 0:
        raise HamsaError("C is zero")
    diagonal = np.zeros_like(C)
    np.fill_diagonal(diagonal, np.diagonal(C))
    return float(np.linalg.norm(C - diagonal) / total)
