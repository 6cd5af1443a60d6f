"""Eigenfunction signs across two shapes, and the sign pattern of a shape's intrinsic symmetry."""

from __future__ import annotations

import itertools

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
    source: Eigenbasis, target: Eigenbasis, indices, meshes=None, scales: int = 6, squares: int = 10
) -> np.ndarray:
    """Signs s_j for the target eigenfunctions j in ``indices`` from the shapes alone (no ground truth).

    Each decision compares features that flip with the signs on the two shapes by the cosine
    ``<f^source, f^target> / (|f^source| |f^target|)`` of each block of features, so that no block outweighs
    another by its units. The features integrate the functions, scaled to unit mean square
    (``phi~ = phi sqrt(area)``), against sign-free weights g: the scaled heat kernel signature h_t at
    ``scales`` times (:func:`~hamsa.diffusion.default_hks_times` of the source, in units of each shape's
    area, so that a scaled copy gets the same features) and the squares phi~_c^2 of the functions
    c = 1..``squares``. They correspond between near-isometric shapes whose functions correspond in order
    (no swap of near-equal eigenvalues).

    The source's intrinsic symmetry (:func:`intrinsic_symmetry_signs`) sorts the functions:

    - a function the symmetry **keeps** gets its sign from its **first moments** ``int g phi~_j dA / area``
      (a block of heat weights and a block of squares);
    - a function it **reverses** (phi_j o T = -phi_j) has first moments that vanish, since g is symmetric,
      and no intrinsic quantity tells it from its mirror image. Among the reversed functions the
      **relative** signs are intrinsic: the products ``phi~_a phi~_b`` are symmetric, and their moments
      ``int g phi~_a phi~_b dA / area`` (heat and squares blocks) and triple products
      ``int phi~_a phi~_b s_c phi~_c dA / area`` with the kept functions c give s_a s_b. The relative signs
      maximize the summed evidence over all patterns; one common **mirror** choice then flips all of them
      together, by the two **orientation** terms below with ``meshes``, or else by their first moments
      (which only an asymmetry of the shapes can set: without the surfaces a mirror image cannot be told).

    Both orientation terms reverse under a reflection. The **chirality** of a function is
    ``det(n_t, n_u, x_j)`` for pairs of times t < u, with ``n_t = int h_t N dA`` (the HKS-weighted normal)
    and ``x_j = int phi_j (X - X_mean) dA`` (its first moment in space), each vector normalized: unchanged by
    rigid motions and scaling, but it compares the two poses. The **rotated gradient moments**
    ``int h_t (N x grad h_u) . grad phi_j dA`` (t < u; the integrand of
    :func:`~hamsa.matching.functional.orientation_operator`) are intrinsic but for the side N is on, so they
    do not depend on the pose. On a triangle mesh N is the unit normal, the faces oriented consistently and
    outward (positive signed volume; a sheet with a large boundary keeps its faces' side). Where either shape
    is a :class:`~hamsa.PointCloud` the chirality's N is the mean curvature normal ``kappa N = -Laplace X`` on
    both, so ``n_t = X^T W h_t`` (W the stiffness of :func:`hamsa.operators.laplacian_operators`), which
    needs no normal's sign; the rotated moments use the cloud's outward normals and tangential gradients.

    Like :func:`resolve_signs` it assumes the shapes are not reflections of each other: a reflected scan
    gives the mirrored signs.

    Raises
    ------
    HamsaError
        If an index is not below min(source.k, target.k), or the meshes do not match the bases.
    """
    from hamsa.diffusion import default_hks_times
    from hamsa.pointcloud import as_shape

    indices = np.asarray(indices)
    k = min(source.k, target.k)
    if indices.max() >= k:
        raise HamsaError(f"indices must be below k = {k}")
    times = default_hks_times(source, int(scales))
    shapes = (None, None) if meshes is None else tuple(as_shape(shape) for shape in meshes)
    for basis, shape in zip((source, target), shapes):
        if shape is not None and shape.n_vertices != basis.n:
            raise HamsaError(f"a mesh has {shape.n_vertices} vertices, its basis {basis.n}")
    squares = np.arange(1, min(int(squares) + 1, k))
    areas = [basis.mass.diagonal().sum() for basis in (source, target)]
    features = [
        _SignFeatures(basis, times * area / areas[0], squares, indices) for basis, area in zip((source, target), areas)
    ]
    symmetry = np.ones(len(indices))
    symmetry_signs = intrinsic_symmetry_signs(source)[0] if source.k > 1 else np.ones(1)
    inside = indices < len(symmetry_signs)
    symmetry[inside] = symmetry_signs[indices[inside]]

    first = np.array([_cosines(*(f.first(j) for f in features)) for j in range(len(indices))])
    signs = np.where(first >= 0, 1.0, -1.0)
    kept, reversed_ = np.flatnonzero(symmetry > 0), np.flatnonzero(symmetry < 0)
    if len(reversed_) == 0:
        return signs
    relative = _relative_signs(features, reversed_, kept, signs[kept])
    if shapes[0] is None:
        mirror = relative @ first[reversed_]
    else:
        curvature = not all(isinstance(shape, TriMesh) for shape in shapes)  # the same field on both shapes
        orientation = []  # per shape: [chirality (T(T-1)/2, r), rotated moments (T(T-1)/2, r)]
        for shape, f in zip(shapes, features):
            outward = 1.0  # a cloud's normals point outward
            if isinstance(shape, TriMesh):  # a few flipped faces would bend the near-cancelling mean normals
                shape, outward = _oriented(shape)
            field = _curvature_normals(shape) if curvature else outward * f.element[:, None] * shape.vertex_normals
            functions = f.functions[:, reversed_]
            orientation.append(
                [
                    _chirality(field, shape.vertices, f.element, f.heat, functions),
                    outward * _rotated_moments(shape, f.heat, functions),
                ]
            )
        mirror = sum(
            r * _cosines([block[:, i] for block in orientation[0]], [block[:, i] for block in orientation[1]])
            for i, r in enumerate(relative)
        )
    signs[reversed_] = relative * (1.0 if mirror >= 0 else -1.0)
    return signs


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


class _SignFeatures:
    """One shape's side of :func:`resolve_signs_without_truth`: the functions ``indices`` scaled to unit mean
    square (n, m) and the sign-free weights (n, T + C) — the heat kernel signature at T times, scaled to mean 1,
    and the squares of C functions — times the area element divided by the area, so that a weight's product
    with a function summed over the vertices is its mean over the surface."""

    def __init__(self, basis: Eigenbasis, times, squares, indices):
        from hamsa.diffusion import heat_kernel_signature

        element = basis.mass.diagonal()
        area = element.sum()
        heat = heat_kernel_signature(basis, times, scaled=True)
        self.heat = heat * (area / (element @ heat))
        self.functions = basis.vectors[:, indices] * np.sqrt(area)
        squared = area * basis.vectors[:, squares] ** 2
        self.element = element / area
        self.weights = np.hstack([self.heat, squared]) * self.element[:, None]
        self.split = len(times)

    def _blocks(self, values) -> list[np.ndarray]:
        moments = self.weights.T @ values
        return [moments[: self.split], moments[self.split :]]

    def first(self, j) -> list[np.ndarray]:
        """[heat block (T,), squares block (C,)]: the means of g phi~_j."""
        return self._blocks(self.functions[:, j])

    def second(self, a, b, kept, kept_signs) -> list[np.ndarray]:
        """The means of g phi~_a phi~_b (heat, squares) and of s_c phi~_a phi~_b phi~_c for the kept c."""
        product = self.functions[:, a] * self.functions[:, b]
        triple = (self.element * product) @ self.functions[:, kept] * kept_signs
        return self._blocks(product) + ([triple] if len(kept) else [])


def _cosines(blocks_source, blocks_target) -> float:
    """The sum over blocks of the cosine between the source's and the target's features."""
    total = 0.0
    for x, y in zip(blocks_source, blocks_target):
        total += float(x @ y) / max(float(np.linalg.norm(x) * np.linalg.norm(y)), 1e-300)
    return total


def _relative_signs(features, reversed_, kept, kept_signs) -> np.ndarray:
    """(len(reversed_),) signs, the first +1, maximizing the summed evidence s_a s_b of the second-order
    features over the pairs of reversed functions."""
    evidence = {
        (a, b): _cosines(*(f.second(reversed_[a], reversed_[b], kept, kept_signs) for f in features))
        for a in range(len(reversed_))
        for b in range(a + 1, len(reversed_))
    }
    best, chosen = -np.inf, np.ones(len(reversed_))
    for pattern in itertools.product((1.0, -1.0), repeat=len(reversed_) - 1):
        signs = np.array((1.0,) + pattern)
        score = sum(signs[a] * signs[b] * e for (a, b), e in evidence.items())
        if score > best:
            best, chosen = score, signs
    return chosen


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


def _rotated_moments(shape, heat, functions) -> np.ndarray:
    """(T (T - 1) / 2, m) ``int h_t (N x grad h_u) . grad phi_j dA`` for the columns h_t of ``heat`` (n, T),
    t < u, and the ``functions`` (n, m), N on the side the faces (or a cloud's normals) give: the quadrature
    of :func:`~hamsa.matching.functional.orientation_operator`."""
    from hamsa.matching.functional import _gradient_quadrature

    normals, weighted_heat, gradients = _gradient_quadrature(shape, heat)
    rotated = np.cross(normals[:, :, None], gradients(heat), axis=1)  # (q, 3, T) at the q quadrature points
    along = np.einsum("qcu,qcj->quj", rotated, gradients(functions))
    t, u = np.triu_indices(heat.shape[1], 1)
    return np.einsum("qt,quj->tuj", weighted_heat, along)[t, u]


def _oriented(mesh: TriMesh) -> tuple[TriMesh, float]:
    """(mesh with its faces oriented consistently, +-1 making them face outward). The outward side is where the
    signed volume is positive on a surface that encloses one: closed, or with holes whose caps are small (the
    faces' vector area, which a closed surface has zero, under a tenth of their area). An open sheet keeps its
    faces' own side: its signed volume depends on the origin."""
    from hamsa.repair import orient_faces

    mesh = orient_faces(mesh)
    vector_area = mesh.face_areas @ mesh.face_normals
    encloses = np.linalg.norm(vector_area) < 0.1 * mesh.face_areas.sum()
    return mesh, (np.sign(mesh.signed_volume) or 1.0) if encloses else 1.0


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
    ``g(x) = (psi_i(x) / sqrt|E_i|)_{i=1..k}`` as a sign flip. A pattern s is scored by its
    nearest-neighbour residual ``mean_x min_y |g(x) s - g(y)|^2 / mean |g|^2`` on seeded samples
    (``sample`` queries, ``database`` candidates) *per displacement* ``mean_x |g(x) s - g(x)|^2 / mean
    |g|^2``: flipping only a high, lightly weighted function leaves a small residual because it hardly
    moves the embedding, while a mirror moves it far even on a shape that is only nearly symmetric. The
    signs are found greedily: for each candidate first flipped function j (the identity is excluded), the
    later signs are chosen one at a time by that score in the coordinates decided so far, and the pattern
    with the lowest score over all k coordinates wins; where both signs of a function match equally well
    in the coordinates so far, the score flips it (its displacement is larger), and the later coordinates
    decide whether that pattern holds. The ground state (index 0: the constant, or a Hamiltonian's
    positive ground state) is kept.

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

    def residuals(patterns):
        """(residual, displacement), each (r,), of the sign patterns (r, m) in the embedding's first m
        coordinates."""
        r, m = patterns.shape
        points = embedding[queries, :m][None, :, :]
        flipped = (points * patterns[:, None, :]).reshape(-1, m)
        nearest = candidates[nearest_in(cKDTree(embedding[candidates, :m]), flipped)]
        found = np.mean(np.sum((flipped - embedding[nearest, :m]) ** 2, axis=1).reshape(r, -1), axis=1)
        moved = np.mean(np.sum((points * (patterns[:, None, :] - 1.0)) ** 2, axis=2), axis=1)
        return found / size, moved / size

    # the greedy searches of all first flipped functions j (row j) side by side, one coordinate at a time
    patterns = np.ones((k, k))
    patterns[np.arange(k), np.arange(k)] = -1.0
    for i in range(1, k):
        trial = np.repeat(patterns[:i, None, : i + 1], 2, axis=1)  # (searches, keep / flip, i + 1)
        trial[:, 1, i] = -1.0
        found, moved = residuals(trial.reshape(2 * i, i + 1))
        keep, flip = (found / moved).reshape(i, 2).T
        patterns[:i, i] = np.where(keep <= flip, 1.0, -1.0)
    found, moved = residuals(patterns)
    best = int(np.argmin(found / moved))
    return np.concatenate([[1.0], patterns[best]]), float(found[best])
