"""Eigenfunction signs across two shapes, and the sign pattern of a shape's intrinsic symmetry."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from hamsa.eigen import Eigenbasis
from hamsa.errors import HamsaError
from hamsa.matching.functional import functional_map, icp_refine
from hamsa.matching.nearest import nearest_in


def resolve_signs(source: Eigenbasis, target: Eigenbasis, map_source_to_target, indices) -> np.ndarray:
    """Signs s_j (len(indices),) making target eigenfunction j agree with the source's through a known map.

    ``s_j = sign(<phi_j^source, phi_j^target o map>_A)``: what the paper assumes when it builds the same
    eigenfunction-sum potential on two shapes. Uses ground truth, so it is for evaluation only. Entries of
    -1 in the map (vertices without a known image) are left out of the products.
    """
    index = np.asarray(map_source_to_target)
    if index.shape != (source.n,):
        raise HamsaError(f"the map has shape {index.shape}, the source has {source.n} vertices")
    known = index >= 0
    weights = source.mass.diagonal()[known]
    indices = np.asarray(indices)
    a, b = source.vectors[known][:, indices], target.vectors[index[known]][:, indices]
    products = np.sum(weights[:, None] * a * b, axis=0)
    return np.where(products >= 0, 1.0, -1.0)


def resolve_signs_without_truth(source: Eigenbasis, target: Eigenbasis, indices, k: int = 20) -> np.ndarray:
    """Signs s_j for the target eigenfunctions j in ``indices`` from the shapes alone (no ground truth).

    An HKS-fitted functional map on the first ``k`` eigenpairs, refined by ICP (:func:`icp_refine`),
    estimates ``C_jj = <phi_j^source, phi_j^target o map>_A``; ``s_j = sign(C_jj)``. The HKS cannot tell a
    shape from its mirror image, so on a left-right symmetric shape the signs of antisymmetric
    eigenfunctions can come out as the mirror map's: the potential is then consistent with the mirrored
    correspondence (compare :func:`resolve_signs`, which uses the true map).
    """
    from hamsa.diffusion import default_hks_times, heat_kernel_signature

    indices = np.asarray(indices)
    k = min(k, source.k, target.k)
    if indices.max() >= k:
        raise HamsaError(f"indices must be below k = {k}")
    small = source.truncate(k), target.truncate(k)
    times = default_hks_times(small[0], 30)
    C = functional_map(
        *small, heat_kernel_signature(small[0], times, scaled=True), heat_kernel_signature(small[1], times, scaled=True)
    )
    C, _ = icp_refine(C, *small)
    return np.where(C[indices, indices] >= 0, 1.0, -1.0)


def intrinsic_symmetry_signs(
    basis: Eigenbasis, k: int = 20, sample: int = 500, database: int = 10000, seed: int = 0
) -> tuple[np.ndarray, float]:
    """The sign pattern of a shape's best non-identity intrinsic self-symmetry (Ovsjanikov et al. 2008).

    An intrinsic symmetry T (an isometry of the shape onto itself) maps every eigenfunction of a simple
    eigenvalue to plus or minus itself, ``psi_i o T = s_i psi_i``, so it acts on the spectral embedding
    ``g(x) = (psi_i(x) / sqrt|E_i|)_{i=1..k}`` as a sign flip. The signs are found greedily: for each
    candidate first flipped function j (the identity is excluded), the later signs are chosen one at a
    time by the nearest-neighbour residual ``mean_x min_y |g(x) s - g(y)|^2 / mean |g|^2`` on seeded
    samples (``sample`` queries, ``database`` candidates). The pattern that wins has the lowest residual
    *per displacement* ``mean_x |g(x) s - g(x)|^2 / mean |g|^2``: flipping only a high, lightly weighted
    function leaves a small residual because it hardly moves the embedding, while a mirror moves it far
    even on a shape that is only nearly symmetric. The ground state (index 0: the constant, or a
    Hamiltonian's positive ground state) is kept.

    Returns
    -------
    (signs (k + 1,) of +-1 for psi_0..psi_k, residual): a residual well below 0.01 means the shape has that
    symmetry; a larger one, that the pattern is only the least bad (no symmetry found)
    """
    k = min(int(k), basis.k - 1)
    if k < 1:
        raise HamsaError(f"need at least two eigenpairs to look for a symmetry, got k = {basis.k}")
    rng = np.random.default_rng(seed)
    queries = rng.choice(basis.n, min(sample, basis.n), replace=False)
    candidates = rng.choice(basis.n, min(database, basis.n), replace=False)
    spectrum = np.abs(basis.values[1 : k + 1])
    embedding = basis.vectors[:, 1 : k + 1] / np.sqrt(np.maximum(spectrum, 1e-9 * spectrum.max()))
    size = np.mean(np.sum(embedding[queries] ** 2, axis=1))
    trees = {}  # m -> k-d tree of the candidates' first m coordinates

    def residual(signs, m):
        flipped = embedding[queries, :m] * signs[:m]
        if m not in trees:
            trees[m] = cKDTree(embedding[candidates, :m])
        nearest = candidates[nearest_in(trees[m], flipped)]
        return float(np.mean(np.sum((flipped - embedding[nearest, :m]) ** 2, axis=1)) / size)

    best = (np.inf, np.inf, None)  # (residual per displacement, residual, signs)
    for first in range(k):
        signs = np.ones(k)
        signs[first] = -1.0
        for i in range(first + 1, k):
            keep = residual(signs, i + 1)
            signs[i] = -1.0
            if keep <= residual(signs, i + 1):
                signs[i] = 1.0
        moved = np.mean(np.sum((embedding[queries] * (signs - 1.0)) ** 2, axis=1)) / size
        found = residual(signs, k)
        best = min(best, (found / moved, found, signs), key=lambda run: run[0])
    return np.concatenate([[1.0], best[2]]), best[1]
