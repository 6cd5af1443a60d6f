"""Shape matching: descriptor nearest neighbours and functional maps (Ovsjanikov et al. 2012), with ICP.

Directions are explicit. A point map is ``map_source_to_target`` (for each source vertex, a target vertex).
Its functional map pulls functions on the target back to the source: in the A-orthonormal bases Psi_s,
Psi_t, ``C = Psi_s^T A_s Pi Psi_t`` (k_s, k_t), with Pi[y, map(y)] = 1, so that the coefficients of
``g o map`` are ``C`` times those of g. It is estimated from descriptors F (on the source) and G (on
the target) by ``min ||C b - a||^2 + w ||C Lambda_t - Lambda_s C||^2`` (a, b their coefficients), and
turned back into a point map by nearest neighbours: ``map(y) = argmin_x ||(Psi_s C)[y] - Psi_t[x]||``.
Any basis works: the LBO's or a Hamiltonian's (the paper's point).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from hamsa.eigen import Eigenbasis
from hamsa.errors import HamsaError
from hamsa.mesh import as_trimesh

# ICSKM's restarts within this factor of the lowest energy on a third of the ICP sample are decided on the
# whole sample (see match_icskm)
NEAR_TIE = 1.5


def nearest_rows(queries: np.ndarray, points: np.ndarray) -> np.ndarray:
    """For each row of ``queries`` (q, d), the index of the nearest row of ``points`` (p, d) (Euclidean).

    An exact k-d tree search, at any d: the rows this package searches — spectral embeddings
    and kernel signatures of a surface — have intrinsic dimension about 2, and the tree stays well ahead
    of a BLAS distance scan even at d = 100 (SCAPE, 12.5k points, single thread: 1000 ICSKM queries at
    d = 100 in 38 ms vs 137 ms; 12.5k HKS queries at d = 50 in 0.17 s vs 1.7 s;
    ``benchmarks/nearest_neighbours.py``).
    """
    queries = np.ascontiguousarray(queries, dtype=np.float64)
    points = np.ascontiguousarray(points, dtype=np.float64)
    if queries.ndim != 2 or points.ndim != 2 or queries.shape[1] != points.shape[1]:
        raise HamsaError(f"need (q, d) and (p, d) arrays with the same d, got {queries.shape} and {points.shape}")
    return _nearest_in(cKDTree(points), queries)


def _nearest_in(tree: cKDTree, queries: np.ndarray) -> np.ndarray:
    """Indices (q,) of the nearest points of a built k-d tree to the rows of ``queries`` (q, d); on all
    cores from a thousand queries (below that, starting the threads costs more than they save)."""
    return tree.query(queries, workers=-1 if len(queries) >= 1000 else 1)[1].astype(np.int64)


def match_descriptors(source_descriptors, target_descriptors) -> np.ndarray:
    """``map_source_to_target``: the nearest target vertex in descriptor space, for each source vertex.

    Descriptors are (n, d) arrays (e.g. HKS/WKS columns); each column is scaled by its norm over both
    shapes so that no scale dominates.
    """
    F = np.asarray(source_descriptors, dtype=np.float64)
    G = np.asarray(target_descriptors, dtype=np.float64)
    if F.ndim != 2 or G.ndim != 2 or F.shape[1] != G.shape[1]:
        raise HamsaError(f"descriptors must be (n, d) with the same d, got {F.shape} and {G.shape}")
    scale = np.sqrt(np.mean(np.vstack([F, G]) ** 2, axis=0))
    scale[scale == 0] = 1.0
    return nearest_rows(F / scale, G / scale)


def functional_map(
    source: Eigenbasis, target: Eigenbasis, source_descriptors, target_descriptors, laplacian_weight: float = 1e-3
) -> np.ndarray:
    """The (k_s, k_t) functional map C pulling target functions back to the source, fitted to descriptors.

    Row by row, ``(b b^T + w diag((lambda_t - lambda_s,i)^2)) c_i = b a_i`` with a = Psi_s^T A_s F and
    b = Psi_t^T A_t G; the eigenvalues are scaled by the largest so that w is scale-free.
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
    """``map_source_to_target`` from a functional map C (k_s, k_t): nearest neighbours of the rows of Psi_s C."""
    C = np.asarray(C)
    if C.shape != (source.k, target.k):
        raise HamsaError(f"C has shape {C.shape}, expected ({source.k}, {target.k})")
    return nearest_rows(source.vectors @ C, target.vectors)


def functional_from_map(map_source_to_target, source: Eigenbasis, target: Eigenbasis) -> np.ndarray:
    """``C = Psi_s^T A_s Pi Psi_t`` of a point map (lumped source mass)."""
    index = np.asarray(map_source_to_target)
    if index.shape != (source.n,):
        raise HamsaError(f"the map has shape {index.shape}, the source has {source.n} vertices")
    weights = source.mass.diagonal()
    return source.vectors.T @ (weights[:, None] * target.vectors[index])


def icp_refine(
    C: np.ndarray, source: Eigenbasis, target: Eigenbasis, iterations: int = 10
) -> tuple[np.ndarray, np.ndarray]:
    """Orthogonal refinement (Ovsjanikov et al. 2012): alternate the point map and the closest orthogonal C.

    Returns (C, map_source_to_target). Stops early when the map no longer changes.
    """
    mapping = map_from_functional(C, source, target)
    for _ in range(iterations):
        U, _, Vt = np.linalg.svd(functional_from_map(mapping, source, target), full_matrices=False)
        C = U @ Vt
        new = map_from_functional(C, source, target)
        if np.array_equal(new, mapping):
            break
        mapping = new
    return C, mapping


def resolve_signs(source: Eigenbasis, target: Eigenbasis, map_source_to_target, indices) -> np.ndarray:
    """Signs s_j making target eigenfunction j agree with the source's through a known map.

    ``s_j = sign(<phi_j^source, phi_j^target o map>_A)``: what the paper assumes when it builds the
    same eigenfunction-sum potential on two shapes (NOTES T14). Uses ground truth: for evaluation only.
    Entries of -1 in the map (vertices without a known image) are left out of the products.
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


def resolve_signs_without_truth(source: Eigenbasis, target: Eigenbasis, indices, size: int = 20) -> np.ndarray:
    """Signs s_j for the target eigenfunctions j in ``indices`` from the shapes alone (no ground truth).

    An HKS-fitted functional map on the first ``size`` eigenpairs, refined by ICP (:func:`icp_refine`),
    estimates ``C_jj = <phi_j^source, phi_j^target o map>_A``; ``s_j = sign(C_jj)``. The HKS cannot tell a
    shape from its mirror image, so on a left-right symmetric shape the signs of antisymmetric
    eigenfunctions can come out as the mirror map's: the potential is then consistent with the mirrored
    correspondence (compare with :func:`resolve_signs`, which uses the true map).
    """
    from hamsa.diffusion import default_hks_times, heat_kernel_signature

    indices = np.asarray(indices)
    size = min(size, source.k, target.k)
    if indices.max() >= size:
        raise HamsaError(f"indices must be below size = {size}")
    small = source.truncate(size), target.truncate(size)
    times = default_hks_times(small[0], 30)
    C = functional_map(
        *small, heat_kernel_signature(small[0], times, scaled=True), heat_kernel_signature(small[1], times, scaled=True)
    )
    C, _ = icp_refine(C, *small)
    return np.where(C[indices, indices] >= 0, 1.0, -1.0)


def zoomout(map_source_to_target, source: Eigenbasis, target: Eigenbasis, sizes=None) -> tuple[np.ndarray, np.ndarray]:
    """Spectral upsampling (ZoomOut, Melzi et al. 2019): refine a point map by alternating
    ``C_k = Psi_s[:, :k]^T A_s Pi Psi_t[:, :k]`` and the nearest-neighbour map of C_k, for growing k.

    Parameters
    ----------
    map_source_to_target : (n_s,) initial point map (e.g. from a small functional map)
    source, target : eigenbases with at least max(sizes) eigenpairs
    sizes : increasing basis sizes (default every integer from min(10, k) to k = min(k_s, k_t); starting
        much smaller collapses the map: a 4-dimensional embedding cannot tell most vertices apart)

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
    for size in sizes:
        s, t = source.truncate(size), target.truncate(size)
        C = functional_from_map(mapping, s, t)
        mapping = map_from_functional(C, s, t)
    return C, mapping


def offdiagonal_energy(C: np.ndarray) -> float:
    """``||C - diag(C)||_F / ||C||_F``: 0 for a diagonal functional map (NOTES T14's "more diagonal")."""
    C = np.asarray(C, dtype=np.float64)
    if C.ndim != 2:
        raise HamsaError(f"C must be a matrix, got shape {C.shape}")
    total = np.linalg.norm(C)
    if total == 0:
        raise HamsaError("C is zero")
    diagonal = np.zeros_like(C)
    np.fill_diagonal(diagonal, np.diagonal(C))
    return float(np.linalg.norm(C - diagonal) / total)


def intrinsic_symmetry_signs(
    basis: Eigenbasis, count: int = 20, sample: int = 500, database: int = 10000, seed: int = 0
) -> tuple[np.ndarray, float]:
    """The sign pattern of a shape's best non-identity intrinsic self-symmetry (Ovsjanikov et al. 2008).

    An intrinsic symmetry T (an isometry of the shape onto itself) maps every eigenfunction of a simple
    eigenvalue to plus or minus itself, ``psi_i o T = s_i psi_i``, so it acts on the spectral embedding
    ``g(x) = (psi_i(x) / sqrt|E_i|)_{i=1..count}`` as a sign flip. The signs are found greedily: for each
    candidate first flipped function j (the identity is excluded), the later signs are chosen one at a
    time by the nearest-neighbour residual ``mean_x min_y |g(x) s - g(y)|^2 / mean |g|^2`` on seeded
    samples (``sample`` queries, ``database`` candidates). The pattern that wins has the lowest residual
    *per displacement* ``mean_x |g(x) s - g(x)|^2 / mean |g|^2``: flipping only a high, lightly weighted
    function leaves a small residual because it hardly moves the embedding, while a mirror moves it far
    (on TOSCA's gorilla, not exactly symmetric, the lowest plain residual was psi_19 flipped alone, 0.015;
    per displacement, the left-right mirror wins, residual 0.046). An exact symmetry wins either way.
    The ground state (index 0: the constant, or a Hamiltonian's positive ground state) is kept.

    Returns
    -------
    (signs (count + 1,) of +-1 for psi_0..psi_count, residual): a residual well below 0.01 means the shape
    has that symmetry; a larger one, that the pattern is only the least bad (no symmetry found)
    """
    count = min(int(count), basis.k - 1)
    if count < 1:
        raise HamsaError(f"need at least two eigenpairs to look for a symmetry, got k = {basis.k}")
    rng = np.random.default_rng(seed)
    queries = rng.choice(basis.n, min(sample, basis.n), replace=False)
    candidates = rng.choice(basis.n, min(database, basis.n), replace=False)
    spectrum = np.abs(basis.values[1 : count + 1])
    embedding = basis.vectors[:, 1 : count + 1] / np.sqrt(np.maximum(spectrum, 1e-9 * spectrum.max()))
    size = np.mean(np.sum(embedding[queries] ** 2, axis=1))

    trees = {}  # m -> k-d tree of the candidates' first m coordinates

    def residual(signs, m):
        flipped = embedding[queries, :m] * signs[:m]
        if m not in trees:
            trees[m] = cKDTree(embedding[candidates, :m])
        nearest = candidates[_nearest_in(trees[m], flipped)]
        return float(np.mean(np.sum((flipped - embedding[nearest, :m]) ** 2, axis=1)) / size)

    best = (np.inf, np.inf, None)  # (residual per displacement, residual, signs)
    for first in range(count):
        signs = np.ones(count)
        signs[first] = -1.0
        for i in range(first + 1, count):
            keep = residual(signs, i + 1)
            signs[i] = -1.0
            if keep <= residual(signs, i + 1):
                signs[i] = 1.0
        moved = np.mean(np.sum((embedding[queries] * (signs - 1.0)) ** 2, axis=1)) / size
        found = residual(signs, count)
        best = min(best, (found / moved, found, signs), key=lambda run: run[0])
    return np.concatenate([[1.0], best[2]]), best[1]


def _heat_schedules(scales) -> list[tuple[int, int]]:
    """``match_icskm``'s ``scales`` (an int n, a pair (n, j), or a tuple of these) as sorted distinct
    (number of scales, index j of the eigenvalue that sets the coarsest scale) pairs; int n means (n, 5)."""
    items = [scales] if isinstance(scales, (int, np.integer)) else list(scales)
    plans = set()
    for item in items:
        if isinstance(item, (int, np.integer)):
            n, j = int(item), 5
        elif np.ndim(item) == 1 and len(item) == 2:
            n, j = (int(value) for value in item)
        else:
            raise HamsaError(f"a heat schedule is an int n or a pair (n, j), got {item!r}")
        if n < 1 or j < 1:
            raise HamsaError(f"a heat schedule needs at least one scale from E_j with j >= 1, got {item!r}")
        plans.add((n, j))
    if not plans:
        raise HamsaError("need at least one heat schedule, got none")
    return sorted(plans)


def match_icskm(
    source: Eigenbasis,
    target: Eigenbasis,
    source_landmarks,
    target_landmarks,
    *,
    scales: int | tuple = (6, 10, (6, 20)),
    iterations: int = 10,
    landmark_weight: float = 10.0,
    sample: int = 3000,
    seed: int = 0,
    features: tuple[np.ndarray, np.ndarray] | None = None,
    feature_weight: float = 0.2,
    restarts: int = 5,
) -> tuple[np.ndarray, np.ndarray]:
    """Iterative closest spectral kernel maps (Shtern & Kimmel 2014), started from landmark pairs.

    The heat kernel ``K_t(x, y) = sum_i e^{-E_i t} psi_i(x) psi_i(y)`` of each shape is the Gram matrix of
    the spectral embedding ``e_t(x) = (e^{-E_i t / 2} psi_i(x))_i``; for a near-isometry the two shapes'
    embeddings agree up to an orthogonal C (sign flips, rotations within eigenspaces). Starting from C
    fitted to the heat kernels of the landmarks (plus the HKS, with the Laplacian-commutativity term of
    :func:`functional_map`), ICP alternates nearest neighbours in the embedding and the orthogonal
    Procrustes C, over heat scales from coarse (large t: only the first eigenfunctions count) to fine
    (NOTES §4.2). The landmark pairs enter every Procrustes step with ``landmark_weight`` times the
    weight of an ordinary vertex pair. Works with any basis: the LBO's or a Hamiltonian's (the paper uses
    V = geodesic distance from the landmarks, :func:`hamsa.potentials.geodesic_distance`).

    A sign of the initial C that the landmarks cannot decide (on a symmetric shape, the first antisymmetric
    eigenfunction's when a landmark lies near the symmetry plane; with a Hamiltonian basis, whichever low eigenfunction
    the potential leaves nearly symmetric) stays through the whole schedule as a partial left-right flip: the coarse
    scales cannot tell the map from its mirror image. So ICSKM is started ``restarts`` more times, each time from the
    initial C with one of psi_1..psi_restarts's signs flipped (and the sign of the first eigenfunction that the source's
    intrinsic symmetry reverses, :func:`intrinsic_symmetry_signs`, when it is later), and the start whose ICP ends with
    the lowest energy at the finest scale (nearest-neighbour distances plus the landmark term, the quantity ICP
    minimizes) is run again in full. Each start runs through every schedule of ``scales`` (where ICP starts and how far
    it steps from coarse to fine decide which minimum it follows, see ``scales``). The runs are compared on a third of
    the ICP sample, and a run that reaches a state an earlier one passed through (same schedule, same scale, same map)
    stops there with that run's result; the runs whose energy on the third is within :data:`NEAR_TIE` of the lowest are
    all run on the whole sample, where the lowest energy wins. No ground truth is used. On TOSCA with one landmark the
    flip that wins was psi_2, psi_4 or psi_5 depending on the shape and the landmark, and the lowest energy picked the
    right start where we checked (centaur: 0.017 vs 0.033 for the partial mirror, michael: 0.0012 vs 0.0066); on
    david0 -> 1 with three landmarks the third alone picked a worse map (the psi_2 flip, 0.0037 vs 0.0047 on the
    third, 0.0152 vs 0.0140 on the whole sample: AUC 0.68 against 0.78).

    Parameters
    ----------
    source, target : eigenbases with the same k
    source_landmarks, target_landmarks : (L,) vertex ids, L >= 1, matched in order
    scales : coarse-to-fine schedules of heat scales. An int n: n scales, geometric from 4 ln10 / E_5 down to 4 ln10 /
        E_{k-1} (eigenvalues E_0 <= E_1 <= ... of the source basis, counted from 0); a pair (n, j) in a tuple: n scales
        from 4 ln10 / E_j, where about the first j eigenfunctions count, down to the same finest scale (a tuple of ints
        is several schedules from E_5); a tuple of these: several schedules, each run from every start, the lowest
        finest-scale energy deciding among all of them (the schedules share the finest scale, so their energies
        compare). Which minimum ICP follows depends on where it starts and on the step. On SCAPE mesh000 -> 013 from one
        landmark (Hamiltonian basis) the right map has the lower finest-scale energy (0.0208 against 0.0251) yet six
        scales (t shrinking ~2.2x per step at k = 100) end in a limb swap from every start, even from the right C, while
        ten do not; on mesh000 -> 004 it is the other way round (ten: 0.030, a swap; six: 0.024, right). On mesh000 ->
        006, 008, 019, 025, 027, 029, 039, 041 (LBO basis) both end in a limb swap (on mesh039 even when started from
        the ground truth's C: at 4 ln10 / E_5 the five functions that count cannot hold the limbs apart), while six
        scales from 4 ln10 / E_20 (the size of the landmark fit) find the right map, at lower energy (mesh006: 0.0228
        against 0.0302, AUC 0.92 against 0.66; not on 021, 024, 032). Where the other schedules were right it ties them
        in energy and costs up to 0.01 AUC (mesh001, 004, 013). The energy picked a right map wherever one was among
        the runs, so the default runs all three, (6, 10, (6, 20))
    iterations : ICP iterations per scale at most (stops when the sampled map no longer changes)
    sample : source vertices used in the ICP steps (seeded); the final map covers every vertex
    features : optional ((n_s, f), (n_t, f)) intrinsic functions that correspond on the two shapes (e.g. the
        geodesic distances from each landmark, :meth:`hamsa.geodesic.GeodesicSolver.distances_from`),
        appended to the embedding in every nearest-neighbour step, scaled to ``feature_weight`` times the
        embedding's size: they keep the map from swapping parts that the kernels alone cannot tell apart
        (left and right limbs); kept small, the spectral embedding still decides the fine alignment
    restarts : sign-flipped starts tried (0 with a single schedule, e.g. ``scales=6``: the paper's single
        ICSKM run from the landmark fit)

    Returns
    -------
    (C (k, k), map_source_to_target (n_s,))
    """
    from hamsa.diffusion import default_hks_times, heat_kernel, heat_kernel_signature

    if source.k != target.k:
        raise HamsaError(f"ICSKM needs bases of the same size, got k = {source.k} and {target.k}")
    p = np.atleast_1d(np.asarray(source_landmarks, dtype=np.int64))
    q = np.atleast_1d(np.asarray(target_landmarks, dtype=np.int64))
    if p.shape != q.shape or p.ndim != 1 or p.size == 0:
        raise HamsaError(f"need matched, non-empty landmark lists, got {p.shape} and {q.shape}")
    if p.min() < 0 or p.max() >= source.n or q.min() < 0 or q.max() >= target.n:
        raise HamsaError("a landmark is not a vertex id of its shape")
    if int(restarts) < 0:
        raise HamsaError(f"restarts must be >= 0, got {restarts}")
    plans = _heat_schedules(scales)
    if int(iterations) < 1:
        raise HamsaError(f"need at least one ICP iteration, got {iterations}")
    # coarse to fine: from the scale where about the first j eigenfunctions count (j = 5 or more, not the ground
    # state's: a Hamiltonian's E_1 can be near 0 and a scale set by it keeps psi_1 alone, collapsing the map)
    # to the one where all k do; every schedule ends at the same finest scale, so their energies compare
    spectrum = np.abs(source.values)
    finest = 4 * np.log(10) / spectrum[-1]
    schedules = [np.geomspace(finest, 4 * np.log(10) / spectrum[min(j, source.k - 1)], n)[::-1] for n, j in plans]
    # initial C on a small basis from landmark heat kernels and the HKS (intrinsic: no sign ambiguity)
    small = min(20, source.k)
    s0, t0 = source.truncate(small), target.truncate(small)
    kernel_times = default_hks_times(s0, 5)
    F = np.hstack([heat_kernel(s0, kernel_times, p).transpose(1, 0, 2).reshape(source.n, -1),
                   heat_kernel_signature(s0, kernel_times, scaled=True)])  # fmt: skip
    G = np.hstack([heat_kernel(t0, kernel_times, q).transpose(1, 0, 2).reshape(target.n, -1),
                   heat_kernel_signature(t0, kernel_times, scaled=True)])  # fmt: skip
    C = np.eye(source.k)
    C[:small, :small] = functional_map(s0, t0, F / np.linalg.norm(F, axis=0), G / np.linalg.norm(G, axis=0))
    U, _, Vt = np.linalg.svd(C[:small, :small])
    C[:small, :small] = U @ Vt
    rng = np.random.default_rng(seed)
    sampled = rng.choice(source.n, min(sample, source.n), replace=False)
    if features is not None:
        fs, ft = (np.asarray(f, dtype=np.float64).reshape(len(f), -1) for f in features)
        if fs.shape[0] != source.n or ft.shape != (target.n, fs.shape[1]):
            raise HamsaError(f"features must be (n_s, f) and (n_t, f), got {fs.shape} and {ft.shape}")
        scale = np.sqrt(np.mean(np.vstack([fs, ft]) ** 2))
        fs, ft = fs / scale, ft / scale
    n_features = 0 if features is None else fs.shape[1]

    def embeddings(t):  # (source embedding, target points) at heat scale t; with features: ((es, fs), [et ft])
        es = source.vectors * np.exp(-source.values * t / 2)
        et = target.vectors * np.exp(-target.values * t / 2)
        if features is None:
            return es, et
        size = feature_weight * np.sqrt(np.mean(np.sum(et**2, axis=1)))  # features weigh like the embedding
        return (es, fs * size), np.hstack([et, ft * size])

    def significant(t):  # the nearest-neighbour coordinates that count at scale t (coarse scales: few)
        decay = np.exp(-(target.values - target.values.min()) * t / 2)
        # a target coordinate damped below 1e-4 is ~0 on every target point and so, with C aligning damped
        # coordinates with damped ones, on the queries: dropping it changes distances by ~1e-8 relative
        return np.concatenate([np.flatnonzero(decay >= 1e-4), np.arange(target.k, target.k + n_features)])

    def query(es, C, ids=slice(None)):
        return es[ids] @ C if features is None else np.hstack([es[0][ids] @ C, es[1][ids]])

    def icp(C, times, rows, visited=None):  # coarse-to-fine ICP from C over the heat scales times on the source
        # vertices rows -> (C, energy at the finest scale). visited: {state after a scale: result} of earlier
        # runs on the same rows; the state (schedule, scale, scale at which C was last fitted, map) decides the
        # rest of the run (C is the Procrustes fit of that map at that scale), so a run that reaches a visited
        # state ends there
        weights = source.mass.diagonal()[rows]
        landmark_mass = landmark_weight * weights.mean()
        mapping, fitted, trail = None, None, []
        for scale, t in enumerate(times):
            es, target_points = embeddings(t)
            spectral = es if features is None else es[0]
            columns = significant(t)
            searched = cKDTree(target_points[:, columns])  # one tree for the scale's iterations
            for _ in range(iterations):
                new = _nearest_in(searched, query(es, C, rows)[:, columns])
                if mapping is not None and np.array_equal(new, mapping):
                    break
                mapping, fitted = new, scale
                et = target_points[:, : target.k]
                cross = spectral[rows].T @ (weights[:, None] * et[mapping]) + landmark_mass * spectral[p].T @ et[q]
                U, _, Vt = np.linalg.svd(cross)
                C = U @ Vt
            if visited is not None:
                trail.append((times[0], len(times), scale, fitted, mapping.tobytes()))
                if trail[-1] in visited:
                    return visited[trail[-1]]
        points = query(es, C, rows)
        nearest = nearest_rows(points, target_points)
        landmark_residual = spectral[p] @ C - target_points[q, : target.k]
        energy = np.sum(weights * np.sum((points - target_points[nearest]) ** 2, axis=1))
        result = C, float(energy + landmark_mass * np.sum(landmark_residual**2))
        if visited is not None:
            visited.update(dict.fromkeys(trail, result))
        return result

    starts = [C]
    if restarts and source.k > 2:
        signs, _ = intrinsic_symmetry_signs(source, count=small - 1)
        flips = {*range(1, min(int(restarts), small - 1) + 1), int(np.argmax(signs < 0))}
        starts += [C * np.where(np.arange(source.k) == j, -1.0, 1.0)[:, None] for j in sorted(flips)]
    runs = [(start, times) for times in schedules for start in starts]
    if len(runs) > 1:
        explored, visited = sampled[: max(len(sampled) // 3, 1)], {}
        ranked = {}  # energy on the explored third -> the first run that ended there
        for run in runs:
            ranked.setdefault(icp(*run, explored, visited)[1], run)
        runs = [run for energy, run in ranked.items() if energy <= NEAR_TIE * min(ranked)]
    finished = {}
    C, _ = min((icp(*run, sampled, finished) for run in runs), key=lambda result: result[1])
    es, target_points = embeddings(finest)
    return C, nearest_rows(query(es, C), target_points)


def spectral_gradient_fields(mesh, basis: Eigenbasis, count: int = 10) -> np.ndarray:
    """Pointwise inner products of eigenfunction gradients ``G_ij(x) = <grad psi_i, grad psi_j>(x)``, (n, c, c).

    Shtern & Kimmel 2015 (NOTES §4.3): intrinsic, so for an isometry with functional map C they transform
    as ``G_t(T x) = C^T G_s(x) C``. Per-face gradients of the P1 functions, averaged to the vertices with
    the face areas as weights; each gradient is divided by its L2 norm ``sqrt(psi_i^T W psi_i)`` so the
    entries are dimensionless (the constant, zero-energy mode is left as is: its gradient is zero).
    """
    from hamsa.geodesic import face_gradients

    mesh = as_trimesh(mesh)
    if mesh.n_vertices != basis.n:
        raise HamsaError(f"the mesh has {mesh.n_vertices} vertices, the basis {basis.n}")
    count = min(int(count), basis.k)
    gradients = face_gradients(mesh, basis.vectors[:, :count])  # (m, 3, c)
    areas = mesh.face_areas
    energy = np.einsum("m,mdi,mdi->i", areas, gradients, gradients)
    gradients = gradients / np.sqrt(np.where(energy > 1e-12 * energy.max(), energy, 1.0))
    per_face = np.einsum("mdi,mdj->mij", gradients, gradients).reshape(len(areas), -1)
    incidence = sp.csr_matrix(
        (np.repeat(areas, 3), (mesh.faces.ravel(), np.repeat(np.arange(len(areas)), 3))),
        shape=(mesh.n_vertices, len(areas)),
    )
    weight = np.asarray(incidence.sum(axis=1)).ravel()
    return (incidence @ per_face / weight[:, None]).reshape(mesh.n_vertices, count, count)


def match_sgfe(
    source_mesh,
    target_mesh,
    source: Eigenbasis,
    target: Eigenbasis,
    initial_C: np.ndarray,
    *,
    count: int = 10,
    weight: float = 1.0,
    iterations: int = 20,
    sample: int = 3000,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Spectral gradient fields embedding (Shtern & Kimmel 2015): ICP on eigenfunction values and gradients.

    Each vertex is embedded by its eigenfunction values and the upper triangle of
    :func:`spectral_gradient_fields` (off-diagonal entries times sqrt 2, so Euclidean distances are Frobenius
    distances). The source embedding is carried into the target's coordinates by an orthogonal C,
    ``(Psi_s C, C_g^T G_s C_g)`` with C_g the leading (count, count) block; ICP alternates nearest
    neighbours in the concatenated embedding (``weight`` on the gradient part) and the Procrustes C of the
    value part, from ``initial_C`` (e.g. an HKS functional map after :func:`icp_refine`, padded to k).

    Returns (C (k, k), map_source_to_target (n_s,)).
    """
    if source.k != target.k or np.shape(initial_C) != (source.k, target.k):
        raise HamsaError(f"need bases of the same size and a ({source.k}, {source.k}) initial C")
    count = min(count, source.k)
    G_s = spectral_gradient_fields(source_mesh, source, count)
    G_t = spectral_gradient_fields(target_mesh, target, count)
    upper = np.triu_indices(count)
    factor = np.where(upper[0] == upper[1], 1.0, np.sqrt(2.0)) * weight

    def gradient_part(G, C_g=None):
        G = G if C_g is None else np.einsum("ki,nkl,lj->nij", C_g, G, C_g, optimize=True)
        return G[:, upper[0], upper[1]] * factor

    target_embedding = np.hstack([target.vectors, gradient_part(G_t)])
    rows = np.random.default_rng(seed).choice(source.n, min(sample, source.n), replace=False)
    weights = source.mass.diagonal()[rows]
    C, mapping = np.asarray(initial_C, dtype=np.float64), None
    for _ in range(iterations):
        embedding = np.hstack([source.vectors[rows] @ C, gradient_part(G_s[rows], C[:count, :count])])
        new = nearest_rows(embedding, target_embedding)
        if mapping is not None and np.array_equal(new, mapping):
            break
        mapping = new
        U, _, Vt = np.linalg.svd(source.vectors[rows].T @ (weights[:, None] * target.vectors[mapping]))
        C = U @ Vt
    embedding = np.hstack([source.vectors @ C, gradient_part(G_s, C[:count, :count])])
    return C, nearest_rows(embedding, target_embedding)
