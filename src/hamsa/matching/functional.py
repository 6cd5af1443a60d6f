"""Functional maps (Ovsjanikov et al. 2012): fitting C to descriptors, point maps <-> C, ICP and ZoomOut.

Directions are explicit. A point map is ``map_source_to_target`` (for each source vertex, a target vertex).
Its functional map pulls functions on the target back to the source: in the A-orthonormal bases Psi_s,
Psi_t, ``C = Psi_s^T A_s Pi Psi_t`` (k_s, k_t), with Pi[y, map(y)] = 1, so that the coefficients of
``g o map`` are ``C`` times those of g. Any basis works: the LBO's or a Hamiltonian's.
"""

from __future__ import annotations

import numpy as np

from hamsa.eigen import Eigenbasis
from hamsa.errors import HamsaError
from hamsa.matching.icp import alternate, procrustes
from hamsa.matching.nearest import nearest_rows

# the coupled functional-map fit solves a dense system of (k_s k_t)^2 entries: 4096 unknowns = 128 MiB
MAX_COUPLED_UNKNOWNS = 4096
# the descriptor-commutativity weight of the fits that start the matchers (fmap's and sgfe's HKS map,
# ICSKM's landmark fit); chosen for fmap on half of the SCAPE pairs, docs/results/matching.md
COMMUTATIVITY_WEIGHT = 0.03


def check_term_weight(term: str, weight) -> None:
    """Raise a HamsaError unless ``weight`` is a finite number >= 0 (the weight of a fit's ``term``)."""
    if not (isinstance(weight, (int, float, np.number)) and np.isfinite(weight) and weight >= 0):
        raise HamsaError(f"the {term} weight must be finite and >= 0, got {weight}")


def functional_map(
    source: Eigenbasis,
    target: Eigenbasis,
    source_descriptors,
    target_descriptors,
    laplacian_weight: float = 1e-3,
    *,
    commutativity_weight: float = 0.0,
    orientation_weight: float = 0.0,
    meshes=None,
    orientation: str = "preserving",
) -> np.ndarray:
    """The (k_s, k_t) functional map C pulling target functions back to the source, fitted to descriptors.

    Minimizes ``||C b - a||^2 + w ||C Lambda_t - Lambda_s C||^2`` with a = Psi_s^T A_s F (k_s, d) and
    b = Psi_t^T A_t G (k_t, d), the descriptors' coefficients; row by row,
    ``(b b^T + w diag((lambda_t - lambda_s,i)^2)) c_i = b a_i``. The eigenvalues are divided by the largest
    magnitude on either shape, so w is scale-free.

    Two optional terms (Nogneng & Ovsjanikov 2017; Ren et al. 2018), each summed over the d descriptor
    pairs (f, g), both divided by max |f| on the source so that the weights are in the units of w:

    - descriptor commutativity, ``commutativity_weight * ||C M_g - M_f C||^2`` with the multiplication
      operators ``M_f = Psi_s^T A_s diag(f) Psi_s`` (:func:`multiplication_operator`);
    - orientation, ``orientation_weight * ||C O_g -+ O_f C||^2`` with ``O_f = int psi_i (N x grad f) . grad psi_j``
      (:func:`orientation_operator`, needs ``meshes``: triangle meshes or point clouds): ``-`` for
      ``orientation="preserving"`` maps between consistently oriented surfaces, ``+`` for ``"reversing"``
      ones (a left-right symmetry).

    With either term the energy couples all entries of C; its normal equations are assembled and solved
    densely, for at most :data:`MAX_COUPLED_UNKNOWNS` entries (fit on a truncated basis, then ZoomOut).

    Raises
    ------
    HamsaError
        If the descriptors are not (n, d) arrays with the same d on both shapes, a weight is negative or not
        finite, an orientation term is asked for without ``meshes`` or with an unknown ``orientation``, or
        the coupled system has more than :data:`MAX_COUPLED_UNKNOWNS` unknowns.
    """
    check_term_weight("commutativity", commutativity_weight)
    check_term_weight("orientation", orientation_weight)
    a = source.project(source_descriptors)  # (k_s, d)
    b = target.project(target_descriptors)  # (k_t, d)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1]:
        raise HamsaError("descriptors must be (n, d) arrays with the same d on both shapes")
    scale = max(np.abs(source.values).max(), np.abs(target.values).max(), 1e-300)
    ls, lt = source.values / scale, target.values / scale
    gram = b @ b.T
    ridge = 1e-12 * np.trace(gram) * np.eye(target.k)
    pairs = _operator_pairs(
        source, target, source_descriptors, target_descriptors, commutativity_weight, orientation_weight, meshes,
        orientation,
    )  # fmt: skip
    if pairs:
        return _coupled_solve(a @ b.T, gram, laplacian_weight, ls, lt, ridge, pairs)
    C = np.empty((source.k, target.k))
    for i in range(source.k):
        system = gram + laplacian_weight * np.diag((lt - ls[i]) ** 2)
        C[i] = np.linalg.solve(system + ridge, b @ a[i])
    return C


def multiplication_operator(basis: Eigenbasis, f) -> np.ndarray:
    """``M_f = Psi^T A diag(f) Psi`` (k, k): multiplication by a function f (n,) in the basis."""
    f = np.asarray(f, dtype=np.float64)
    if f.shape != (basis.n,):
        raise HamsaError(f"the function has shape {f.shape}, expected ({basis.n},)")
    return basis.vectors.T @ (basis.mass @ (f[:, None] * basis.vectors))


def orientation_operator(shape, basis: Eigenbasis, f) -> np.ndarray:
    """``O_f[i, j] = int psi_i (N x grad f) . grad psi_j dA`` (k, k) on a triangle mesh or a point cloud, for
    f (n,), or one per column, (d, k, k), for f (n, d): the derivative along the rotated gradient of f, in
    the basis. Antisymmetric on a closed surface, and its sign flips with the surface's orientation, which
    is what tells a map from its mirror image.

    On a mesh, exact for P1 functions (per face, area x the mean of psi_i x the constant
    (N x grad f) . grad psi_j), with the faces oriented consistently first
    (:func:`hamsa.repair.orient_faces`; a MeshError if the surface is not orientable). On a
    :class:`~hamsa.PointCloud`, the same integrand at each point, weighted by its lumped mass, with the
    cloud's outward normals and least-squares tangential gradients
    (:meth:`~hamsa.PointCloud.gradients`), in its skew-symmetric form ``(O - O^T) / 2``: N x grad f is
    divergence-free, so the exact operator is antisymmetric on a closed surface, and the symmetric part
    of the pointwise sum is discretization error (on a cloud with boundary it also drops half the
    boundary integral of psi_i psi_j times the derivative of f along the boundary)."""
    from hamsa.pointcloud import PointCloud, as_shape

    shape = as_shape(shape)
    f = np.asarray(f, dtype=np.float64)
    if shape.n_vertices != basis.n or f.ndim not in (1, 2) or f.shape[0] != basis.n:
        raise HamsaError(f"shape ({shape.n_vertices} vertices), basis ({basis.n}) and f {f.shape} must agree")
    normals, weighted_values, gradients = _gradient_quadrature(shape, basis.vectors)
    rotated = np.cross(normals[:, :, None], gradients(f.reshape(basis.n, -1)), axis=1)  # (m, 3, d)
    basis_gradients = gradients(basis.vectors)  # (m, 3, k)
    operators = np.stack(
        [weighted_values.T @ np.einsum("mc,mck->mk", r, basis_gradients) for r in rotated.T.swapaxes(1, 2)]
    )
    if isinstance(shape, PointCloud):  # the skew-symmetric form: N x grad f is divergence-free
        operators = (operators - operators.swapaxes(1, 2)) / 2
    return operators[0] if f.ndim == 1 else operators


def _gradient_quadrature(shape, vectors):
    """The quadrature of the orientation operator: ``(normals (m, 3), weight x psi (m, k), gradients)``
    over its m points (a mesh's faces, a cloud's points), ``gradients(columns (n, d)) -> (m, 3, d)``."""
    from hamsa.operators import face_gradients
    from hamsa.pointcloud import PointCloud
    from hamsa.repair import orient_faces

    if isinstance(shape, PointCloud):
        return shape.normals, shape.operators[1].diagonal()[:, None] * vectors, shape.gradients
    shape = orient_faces(shape)  # the rotated gradient N x grad f follows each face's orientation
    weighted_mean = shape.face_areas[:, None] * vectors[shape.faces].mean(axis=1)
    return shape.face_normals, weighted_mean, lambda columns: face_gradients(shape, columns)


def orientation_ratio(
    C,
    source: Eigenbasis,
    target: Eigenbasis,
    source_descriptors,
    target_descriptors,
    meshes,
    orientation: str = "preserving",
) -> float:
    """How far a functional map C (k_s, k_t) is from having ``orientation`` rather than the opposite one:
    ``sum ||C O_g -+ O_f C||^2 / sum ||C O_g +- O_f C||^2`` over the descriptor pairs (f, g) (the
    orientation term of :func:`functional_map` over the same term for the mirror image; its operators in
    the first k_s / k_t eigenpairs of ``source`` / ``target``). Below 1, C is closer to a map of the asked
    orientation than to its mirror image; independent of the scale of C and of the descriptors.

    Raises
    ------
    HamsaError
        As :func:`orientation_operator`, or on an unknown ``orientation``.
    """
    C = np.asarray(C, dtype=np.float64)
    bases = source.truncate(C.shape[0]), target.truncate(C.shape[1])
    return _operator_ratio(
        C, _orientation_operators(*bases, source_descriptors, target_descriptors, meshes, orientation)
    )


def _operator_ratio(C, operators) -> float:
    """:func:`orientation_ratio` of C with its operators [(+-O_f, O_g)] already built."""
    asked = sum(np.linalg.norm(C @ Ot - Os @ C) ** 2 for Os, Ot in operators)
    mirror = sum(np.linalg.norm(C @ Ot + Os @ C) ** 2 for Os, Ot in operators)
    return float(asked / max(mirror, 1e-300))


def _check_orientation(orientation) -> None:
    if orientation not in ("preserving", "reversing"):
        raise HamsaError(f"orientation must be 'preserving' or 'reversing', got {orientation!r}")


def _scaled_descriptors(F, G) -> tuple[np.ndarray, np.ndarray]:
    """F, G (n, d) with each column divided by max |f| on the source: the weights' units."""
    F, G = np.asarray(F, dtype=np.float64), np.asarray(G, dtype=np.float64)
    scales = np.maximum(np.abs(F).max(axis=0), 1e-300)
    return F / scales, G / scales


def _orientation_operators(source, target, F, G, meshes, orientation) -> list[tuple[np.ndarray, np.ndarray]]:
    """[(+-O_f, O_g)] per descriptor pair, the source's sign flipped for a ``"reversing"`` orientation."""
    _check_orientation(orientation)
    F, G = _scaled_descriptors(F, G)
    sign = -1.0 if orientation == "reversing" else 1.0
    return [
        (sign * Os, Ot)
        for Os, Ot in zip(orientation_operator(meshes[0], source, F), orientation_operator(meshes[1], target, G))
    ]


def _operator_pairs(source, target, F, G, commutativity_weight, orientation_weight, meshes, orientation):
    """[(weight, X_t, X_s)] of the terms ``weight ||C X_t - X_s C||^2`` beyond the Laplacian's."""
    _check_orientation(orientation)
    if orientation_weight and meshes is None:
        raise HamsaError("the orientation term needs the two meshes (meshes=(source, target))")
    pairs = []
    if commutativity_weight:
        pairs += [
            (commutativity_weight, multiplication_operator(target, g), multiplication_operator(source, f))
            for f, g in zip(*(columns.T for columns in _scaled_descriptors(F, G)))
        ]
    if orientation_weight:
        pairs += [
            (orientation_weight, Ot, Os) for Os, Ot in _orientation_operators(source, target, F, G, meshes, orientation)
        ]
    return pairs


def _coupled_solve(rhs, gram, laplacian_weight, ls, lt, ridge, pairs) -> np.ndarray:
    """Minimize the full energy: its normal equations on the row-major vec(C), assembled from Kronecker
    products (``vec(C X) = (I kron X^T) vec(C)``, ``vec(X C) = (X kron I) vec(C)``) and solved densely."""
    ks, kt = rhs.shape
    if ks * kt > MAX_COUPLED_UNKNOWNS:
        raise HamsaError(
            f"the commutativity and orientation terms couple all {ks} x {kt} entries of C; fit C on at most "
            f"{MAX_COUPLED_UNKNOWNS} entries (e.g. 64 x 64 eigenpairs, via truncate) and refine it with zoomout"
        )
    identity_s, identity_t = np.eye(ks), np.eye(kt)
    normal = np.kron(identity_s, gram + ridge)
    normal[np.diag_indices(ks * kt)] += laplacian_weight * ((lt[None, :] - ls[:, None]) ** 2).reshape(-1)
    for weight, Xt, Xs in pairs:
        normal += weight * (
            np.kron(identity_s, Xt @ Xt.T) - np.kron(Xs, Xt) - np.kron(Xs.T, Xt.T) + np.kron(Xs.T @ Xs, identity_t)
        )
    return np.linalg.solve(normal, rhs.reshape(-1)).reshape(ks, kt)


def map_from_functional(C: np.ndarray, source: Eigenbasis, target: Eigenbasis) -> np.ndarray:
    """``map_source_to_target`` (n_s,) from a functional map C (k_s, k_t): nearest neighbours of the rows of
    ``Psi_s C`` among the rows of ``Psi_t`` (exact). Those images lie off the target's embedding, where a
    k-d tree's pruning fails in many dimensions: the search is ``nearest_rows(..., method="auto")``, a tree
    or a distance scan, whichever is faster on a sample."""
    C = np.asarray(C)
    if C.shape != (source.k, target.k):
        raise HamsaError(f"C has shape {C.shape}, expected ({source.k}, {target.k})")
    return nearest_rows(source.vectors @ C, target.vectors, method="auto")


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
    weights = source.mass.diagonal()

    def nearest(C):
        return nearest_rows(source.vectors @ C, target.vectors, method="auto")

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
