"""Eigenfunction signs across two shapes, and the sign pattern of a shape's intrinsic symmetry."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from hamsa.eigen import Eigenbasis
from hamsa.errors import HamsaError
from hamsa.matching.nearest import nearest_in
from hamsa.mesh import TriMesh


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


def resolve_signs_without_truth(
    source: Eigenbasis, target: Eigenbasis, indices, meshes=None, scales: int = 6
) -> np.ndarray:
    """Signs s_j for the target eigenfunctions j in ``indices`` from the shapes alone (no ground truth).

    Each function gets a feature vector on each shape that flips with its sign, and
    ``s_j = sign(<f_j^source, f_j^target>)``:

    - **moments** ``int h_t psi_j dA`` against the scaled heat kernel signature h_t (normalized to mean 1)
      at ``scales`` times (:func:`~hamsa.diffusion.default_hks_times` of the source). The HKS does not
      depend on signs, so these moments correspond between near-isometric shapes; they vanish for a
      function that an intrinsic left-right symmetry reverses (psi_j o T = -psi_j), because h_t is
      symmetric.
    - with ``meshes`` (the two shapes), **chirality** ``det(n_t, n_u, x_j)`` for pairs of times t < u, with
      ``n_t = int h_t N dA`` (the HKS-weighted outward normal) and ``x_j = int psi_j (X - X_mean) dA`` (the
      function's first moment in space), each vector normalized. The determinant is unchanged by
      rotations, translations and scaling and reverses under a reflection, so it tells an antisymmetric
      function from its mirror image — which no intrinsic quantity can — and it is largest exactly where
      the moments vanish. On two triangle meshes N is the unit vertex normal, the faces oriented
      consistently and outward (positive signed volume). Where either shape is a
      :class:`~hamsa.PointCloud`, N is the mean curvature normal ``kappa N = -Laplace X`` on both, so
      ``n_t = X^T W h_t`` (W the stiffness of :func:`hamsa.operators.laplacian_operators`): it needs no
      normal's sign. A cloud's estimated normals get their signs wrong at a few points, mostly at the
      extremities where h_t is largest, and the unit normals' integral, which nearly cancels over a
      closed surface, turns with them.

    Like :func:`resolve_signs` it assumes the functions correspond in order (no swap of near-equal
    eigenvalues) and shapes posed alike up to a rigid motion; a reflected scan gives the mirrored signs.

    Raises
    ------
    HamsaError
        If an index is not below min(source.k, target.k), or the meshes do not match the bases.
    """
    from hamsa.diffusion import default_hks_times, heat_kernel_signature
    from hamsa.pointcloud import as_shape

    indices = np.asarray(indices)
    k = min(source.k, target.k)
    if indices.max() >= k:
        raise HamsaError(f"indices must be below k = {k}")
    times = default_hks_times(source, int(scales))
    shapes = (None, None) if meshes is None else tuple(as_shape(shape) for shape in meshes)
    curvature = not all(isinstance(shape, TriMesh) for shape in shapes)  # the same field on both shapes
    features = []
    for basis, shape in zip((source, target), shapes):
        if shape is not None and shape.n_vertices != basis.n:
            raise HamsaError(f"a mesh has {shape.n_vertices} vertices, its basis {basis.n}")
        weights = basis.mass.diagonal()
        heat = heat_kernel_signature(basis, times, scaled=True)
        heat = heat / (weights @ heat)
        functions = basis.vectors[:, indices]
        parts = [(weights[:, None] * heat).T @ functions]  # (T, m) moments
        if shape is not None:
            field = _curvature_normals(shape) if curvature else _outward_normals(shape, weights)
            parts.append(_chirality(field, shape.vertices, weights, heat, functions))
        features.append(np.concatenate(parts))
    return np.where(np.sum(features[0] * features[1], axis=0) >= 0, 1.0, -1.0)


def matching_potentials(
    source: Eigenbasis, target: Eigenbasis, meshes=None, indices=(1, 2, 3, 4), signs=None
) -> tuple[np.ndarray, np.ndarray]:
    """``(V_source, V_target)``: the paper's matching potential on both shapes, made to correspond.

    Each is :func:`hamsa.potentials.eigenfunction_sum` of the LBO bases' functions ``indices`` divided by
    its maximum (so V lies in [0, 1]; scale it for a stronger potential), the target's eigenfunction signs
    being ``signs`` or, by default, those of :func:`resolve_signs_without_truth` (with ``meshes``, the two
    shapes, for the orientation term): no ground truth needed. Pass ``signs=resolve_signs(...)`` with a
    known map to reproduce the paper's oracle.
    """
    from hamsa.potentials import eigenfunction_sum

    if signs is None:
        signs = resolve_signs_without_truth(source, target, indices, meshes=meshes)
    V_s, V_t = eigenfunction_sum(source, indices), eigenfunction_sum(target, indices, signs=signs)
    return V_s / V_s.max(), V_t / V_t.max()


def _chirality(field, points, weights, heat, functions) -> np.ndarray:
    """(T (T - 1) / 2, m) determinants det(n_t, n_u, x_j) = (n_t x n_u) . x_j of
    :func:`resolve_signs_without_truth`, with ``n_t = heat[:, t] @ field`` for the area-weighted vector
    field (n, 3) and x_j the first moments of the ``functions`` (n, m) about the centroid of ``points``."""
    centred = points - weights @ points / weights.sum()
    normals = heat.T @ field  # (T, 3)
    moments = functions.T @ (weights[:, None] * centred)  # (m, 3)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    moments /= np.maximum(np.linalg.norm(moments, axis=1, keepdims=True), 1e-300)
    t, u = np.triu_indices(len(normals), 1)
    return np.cross(normals[t], normals[u]) @ moments.T


def _outward_normals(mesh: TriMesh, weights: np.ndarray) -> np.ndarray:
    """(n, 3) vertex unit normals times ``weights``, the faces oriented consistently and outward."""
    from hamsa.repair import orient_faces

    mesh = orient_faces(mesh)  # a few flipped faces would bend the near-cancelling mean normals
    outward = np.sign(mesh.signed_volume) or 1.0
    return outward * weights[:, None] * mesh.vertex_normals


def _curvature_normals(shape) -> np.ndarray:
    """(n, 3) ``W X``: the mean curvature normal -Laplace X times the lumped area, of a mesh or a cloud."""
    from hamsa.operators import laplacian_operators

    return laplacian_operators(shape)[0] @ shape.vertices


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
