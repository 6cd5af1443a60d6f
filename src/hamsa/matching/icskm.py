"""Iterative closest spectral kernel maps (ICSKM, Shtern & Kimmel 2014), built from small pieces.

The heat kernel ``K_t(x, y) = sum_i e^{-E_i t} psi_i(x) psi_i(y)`` of each shape is the Gram matrix of
the spectral embedding ``e_t(x) = (e^{-E_i t / 2} psi_i(x))_i``; for a near-isometry the two shapes'
embeddings agree up to an orthogonal C (sign flips, rotations within eigenspaces). ICSKM fits C to the
heat kernels of known landmark pairs (:func:`landmark_fits`), then runs ICP
(:func:`hamsa.matching.icp.alternate`) on the embeddings over heat scales from coarse (large t: only the
first eigenfunctions count) to fine (:class:`KernelICP`). A sign that the landmarks cannot decide
survives the whole schedule as a partial mirror map, so :func:`match_icskm` starts from two fits (with
and without a descriptor-commutativity term) and their sign-flipped copies (:func:`sign_flip_starts`),
through several schedules (:func:`heat_schedules`), and keeps the run with the lowest finest-scale ICP
energy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from hamsa.eigen import Eigenbasis
from hamsa.errors import HamsaError
from hamsa.matching.functional import COMMUTATIVITY_WEIGHT, functional_map
from hamsa.matching.icp import alternate, procrustes
from hamsa.matching.nearest import nearest_in, nearest_rows
from hamsa.matching.signs import intrinsic_symmetry_signs

# Runs whose energy on a third of the ICP sample is within this factor of the lowest are decided on the
# whole sample (a third can rank two nearby minima the wrong way round)
NEAR_TIE = 1.5
# The landmark fit and the sign-flipped starts use the first FIT_SIZE eigenpairs
FIT_SIZE = 20


def parse_heat_schedules(scales) -> list[tuple[int, int]]:
    """``scales`` (an int n, a pair (n, j), or a tuple of these) as sorted distinct (number of scales,
    index j of the eigenvalue that sets the coarsest scale) pairs; an int n means (n, 5)."""
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


def heat_schedules(scales, values: np.ndarray) -> list[np.ndarray]:
    """The heat scales of each schedule, coarse to fine, for the eigenvalues ``values`` (k,) of the source.

    A schedule (n, j) has n scales, geometric from ``4 ln10 / |E_j|`` (where about the first j
    eigenfunctions count; j is kept below k) down to ``4 ln10 / |E_{k-1}|``, where all k do. Every
    schedule ends at the same finest scale, so their ICP energies compare. The coarsest scale is never
    set by the ground state: a Hamiltonian's E_1 can be near 0, and a scale set by it keeps psi_1 alone.
    """
    spectrum = np.abs(values)
    finest = 4 * np.log(10) / spectrum[-1]
    return [
        np.geomspace(finest, 4 * np.log(10) / spectrum[min(j, len(values) - 1)], n)[::-1]
        for n, j in parse_heat_schedules(scales)
    ]


def landmark_fits(
    source: Eigenbasis, target: Eigenbasis, source_landmarks, target_landmarks, commutativity_weights
) -> list[np.ndarray]:
    """The initial (k, k) C for each weight of ``commutativity_weights``: orthogonal on the first
    :data:`FIT_SIZE` eigenpairs, the identity beyond.

    A functional map (:func:`hamsa.matching.functional_map`) fitted on the first FIT_SIZE eigenpairs to
    the heat kernels of the landmarks ``K_t(., p_l)`` and the HKS at five scales (intrinsic functions that
    correspond on both shapes; each column normalized; built once for all weights), then replaced by its
    nearest orthogonal matrix. With L landmarks these are 5 (L + 1) descriptors for FIT_SIZE^2 unknowns
    (20 for 400 with three landmarks), so the fit alone leaves C's low block loosely determined; the
    descriptor-commutativity term (its weight; 0: without it) asks C to carry each descriptor's
    multiplication operator as well as the descriptor, FIT_SIZE^2 equations per descriptor.
    """
    from hamsa.diffusion import default_hks_times, heat_kernel, heat_kernel_signature

    small = min(FIT_SIZE, source.k)
    s0, t0 = source.truncate(small), target.truncate(small)
    times = default_hks_times(s0, 5)

    def descriptors(basis, landmarks):
        F = np.hstack([heat_kernel(basis, times, landmarks).transpose(1, 0, 2).reshape(basis.n, -1),
                       heat_kernel_signature(basis, times, scaled=True)])  # fmt: skip
        return F / np.linalg.norm(F, axis=0)

    F, G = descriptors(s0, source_landmarks), descriptors(t0, target_landmarks)
    fits = []
    for weight in commutativity_weights:
        C = np.eye(source.k)
        C[:small, :small] = procrustes(functional_map(s0, t0, F, G, commutativity_weight=weight))
        fits.append(C)
    return fits


def sign_flip_starts(fits: list[np.ndarray], source: Eigenbasis, restarts: int) -> list[np.ndarray]:
    """Each C of ``fits`` and, for ``restarts`` > 0, copies of it with the sign of one row flipped:
    psi_1..psi_restarts (at most FIT_SIZE - 1), and the first eigenfunction the source's intrinsic symmetry
    reverses (:func:`hamsa.matching.intrinsic_symmetry_signs`), once each."""
    small = min(FIT_SIZE, source.k)
    flips = set()
    if restarts and source.k > 2:
        signs, _ = intrinsic_symmetry_signs(source, k=small - 1)
        flips = {*range(1, min(int(restarts), small - 1) + 1), int(np.argmax(signs < 0))}
    rows = np.arange(source.k)
    return [start for C in fits for start in (C, *(C * np.where(rows == j, -1.0, 1.0)[:, None] for j in sorted(flips)))]


@dataclass(frozen=True)
class _Scale:
    """The two shapes' embeddings at one heat scale: the source's spectral part (n_s, k), its feature part
    (n_s, f) or None, and the target's points (n_t, k + f)."""

    spectral: np.ndarray
    features: np.ndarray | None
    target: np.ndarray

    def queries(self, C: np.ndarray, rows=slice(None)) -> np.ndarray:
        """The source rows carried into the target's coordinates by C."""
        moved = self.spectral[rows] @ C
        return moved if self.features is None else np.hstack([moved, self.features[rows]])


class KernelEmbedding:
    """Heat-kernel spectral embeddings ``e_t`` of a source and a target basis, at any scale t.

    ``features``: optional ((n_s, f), (n_t, f)) intrinsic functions that correspond on the two shapes
    (e.g. geodesic distances from each landmark), appended to the embedding, scaled together to
    ``feature_weight`` times the target embedding's root-mean-square size at each scale.
    """

    def __init__(self, source: Eigenbasis, target: Eigenbasis, features=None, feature_weight: float = 0.2):
        self.source, self.target, self.feature_weight = source, target, float(feature_weight)
        self.features = None
        if features is not None:
            fs, ft = (np.asarray(f, dtype=np.float64).reshape(len(f), -1) for f in features)
            if fs.shape[0] != source.n or ft.shape != (target.n, fs.shape[1]):
                raise HamsaError(f"features must be (n_s, f) and (n_t, f), got {fs.shape} and {ft.shape}")
            scale = np.sqrt(np.mean(np.vstack([fs, ft]) ** 2))
            self.features = (fs / scale, ft / scale)

    def at(self, t: float) -> _Scale:
        """Both embeddings at heat scale t."""
        es = self.source.vectors * np.exp(-self.source.values * t / 2)
        et = self.target.vectors * np.exp(-self.target.values * t / 2)
        if self.features is None:
            return _Scale(es, None, et)
        size = self.feature_weight * np.sqrt(np.mean(np.sum(et**2, axis=1)))
        return _Scale(es, self.features[0] * size, np.hstack([et, self.features[1] * size]))

    def columns(self, t: float) -> np.ndarray:
        """The target coordinates that count at scale t: a coordinate damped below 1e-4 is ~0 on every
        target point (and, with C aligning damped coordinates with damped ones, on the queries), so
        dropping it changes distances by ~1e-8 relative."""
        decay = np.exp(-(self.target.values - self.target.values.min()) * t / 2)
        n_features = 0 if self.features is None else self.features[0].shape[1]
        return np.concatenate([np.flatnonzero(decay >= 1e-4), np.arange(self.target.k, self.target.k + n_features)])


@dataclass(frozen=True)
class KernelICP:
    """Coarse-to-fine ICP of two kernel embeddings, with landmark pairs in every Procrustes step.

    At each heat scale, :func:`hamsa.matching.icp.alternate` with at most ``iterations`` refits: nearest
    neighbours over :meth:`KernelEmbedding.columns`, and the Procrustes C of the spectral parts, the
    landmark pairs weighing ``landmark_weight`` times an ordinary vertex pair. The energy of a run is the
    quantity ICP minimizes, at the finest scale: mass-weighted squared nearest-neighbour distances plus
    the landmark term.
    """

    embedding: KernelEmbedding
    source_landmarks: np.ndarray
    target_landmarks: np.ndarray
    landmark_weight: float = 10.0
    iterations: int = 10

    def run(self, C: np.ndarray, times: np.ndarray, rows: np.ndarray, visited: dict | None = None):
        """ICP from C over the scales ``times`` on the source vertices ``rows``: ``(C, energy)``.

        ``visited`` ({state after a scale: result}, shared by runs on the same rows): the state (schedule,
        scale, scale at which C was last fitted, map) decides the rest of a run, since C is the Procrustes
        fit of that map at that scale; a run that reaches a visited state ends there with that result.
        """
        weights = self.embedding.source.mass.diagonal()[rows]
        landmark_mass = self.landmark_weight * weights.mean()
        mapping, fitted, trail = None, None, []
        for index, t in enumerate(times):
            scale = self.embedding.at(t)
            C, mapping, fits = self._align(scale, self.embedding.columns(t), C, rows, weights, landmark_mass, mapping)
            fitted = index if fits else fitted
            if visited is not None:
                trail.append((times[0], len(times), index, fitted, mapping.tobytes()))
                if trail[-1] in visited:
                    return visited[trail[-1]]
        result = C, self._energy(scale, C, rows, weights, landmark_mass)
        if visited is not None:
            visited.update(dict.fromkeys(trail, result))
        return result

    def _align(self, scale: _Scale, columns, C, rows, weights, landmark_mass, mapping):
        p, q, k = self.source_landmarks, self.target_landmarks, self.embedding.target.k
        searched = cKDTree(scale.target[:, columns])
        et = scale.target[:, :k]

        def nearest(C):
            return nearest_in(searched, scale.queries(C, rows)[:, columns])

        def fit(mapping):
            return procrustes(
                scale.spectral[rows].T @ (weights[:, None] * et[mapping]) + landmark_mass * scale.spectral[p].T @ et[q]
            )

        return alternate(C, nearest, fit, self.iterations, mapping)

    def _energy(self, scale: _Scale, C, rows, weights, landmark_mass) -> float:
        points = scale.queries(C, rows)
        nearest = nearest_rows(points, scale.target)
        k = self.embedding.target.k
        landmark_residual = scale.spectral[self.source_landmarks] @ C - scale.target[self.target_landmarks, :k]
        energy = np.sum(weights * np.sum((points - scale.target[nearest]) ** 2, axis=1))
        return float(energy + landmark_mass * np.sum(landmark_residual**2))


def lowest_energy_run(icp: KernelICP, runs: list, sampled: np.ndarray, progress=None) -> np.ndarray:
    """The C of the (start, schedule) run that ends with the lowest energy on the ICP sample ``sampled``.

    A single run goes through its schedule on the whole sample. Several runs first go through their
    schedules on a third of the sample (runs that reach a state an earlier one passed through stop there,
    :meth:`KernelICP.run`); each of those within :data:`NEAR_TIE` of the lowest energy there is decided on
    the whole sample twice: run again from its start through its schedule, and continued from the C it
    reached, with ICP at the finest scale. From the same start the third and the whole sample can follow a
    schedule into different minima, so both the start and the minimum the third found compete; the lowest
    energy wins. ``progress(done, total)`` is called after each run (the total grows once the runs kept for
    the whole sample are known).
    """
    done, total = 0, len(runs)

    def report():
        if progress is not None:
            progress(done, total)

    if len(runs) == 1:
        C = icp.run(*runs[0], sampled)[0]
        done += 1
        report()
        return C
    explored, visited = sampled[: max(len(sampled) // 3, 1)], {}
    ranked = {}  # energy on the explored third -> the first run that ended there, and the C it reached
    for start, times in runs:
        reached, energy = icp.run(start, times, explored, visited)
        ranked.setdefault(energy, (start, times, reached))
        done += 1
        report()
    kept = [run for energy, run in ranked.items() if energy <= NEAR_TIE * min(ranked)]
    total += 2 * len(kept)
    finished, results = {}, []
    for start, times, reached in kept:
        for C, schedule in ((start, times), (reached, times[-1:])):
            results.append(icp.run(C, schedule, sampled, finished))
            done += 1
            report()
    return min(results, key=lambda result: result[1])[0]


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
    restarts: int = 10,
    commutativity_weight: float = COMMUTATIVITY_WEIGHT,
    progress=None,
) -> tuple[np.ndarray, np.ndarray]:
    """Iterative closest spectral kernel maps (Shtern & Kimmel 2014), started from landmark pairs.

    Fits C to the landmarks (:func:`landmark_fits`) twice, with the descriptor-commutativity term and
    without it, then runs coarse-to-fine ICP (:class:`KernelICP`) from both fits and from their
    sign-flipped copies (:func:`sign_flip_starts`), each through every heat schedule of ``scales``
    (:func:`heat_schedules`); the run with the lowest finest-scale energy wins (:func:`lowest_energy_run`).
    The term brings the fit closer to the true map on most pairs, but which start ICP turns into the right
    map varies from pair to pair, so both compete. No ground truth is used. Where ICP starts and how far
    it steps from coarse to fine decide which minimum it follows, and on near-isometric humans the right
    map has the lower energy where it is among the runs, hence several starts and schedules
    (``docs/results/matching.md`` shows what each changes). Works with any basis: the LBO's or a
    Hamiltonian's (the paper uses V = geodesic distance from the landmarks,
    :func:`hamsa.geodesic.geodesic_distance`).

    Parameters
    ----------
    source, target : eigenbases with the same k
    source_landmarks, target_landmarks : (L,) vertex ids, L >= 1, matched in order
    scales : heat schedules: an int n (n scales from 4 ln10 / E_5), a pair (n, j) inside a tuple (n scales
        from 4 ln10 / E_j), or a tuple of these; all end at 4 ln10 / E_{k-1}
    iterations : ICP refits per scale at most (fewer when the sampled map stops changing)
    landmark_weight : weight of a landmark pair in the Procrustes steps, relative to a vertex pair
    sample : source vertices used in the ICP steps (seeded by ``seed``); the final map covers every vertex
    features : optional ((n_s, f), (n_t, f)) corresponding intrinsic functions appended to the embedding
        (:class:`KernelEmbedding`), e.g. geodesic distances from each landmark: they keep the map from
        swapping parts that the kernels alone cannot tell apart (left and right limbs)
    feature_weight : the features' size relative to the embedding's
    restarts : sign-flipped starts of each fit (0 with a single schedule, e.g. ``scales=6``, and
        ``commutativity_weight=0``: the paper's single run)
    commutativity_weight : the descriptor-commutativity weight of the landmark fit that starts beside the
        plain fit (0: the plain fit alone)
    progress : optional ``progress(done, total)``, called after each ICP run (:func:`lowest_energy_run`)

    Returns
    -------
    (C (k, k), map_source_to_target (n_s,))

    Raises
    ------
    HamsaError
        On bases of different k, landmark lists that are empty, unmatched or not vertex ids, a bad
        schedule, ``restarts < 0``, ``iterations < 1`` or a negative or non-finite ``commutativity_weight``.
    """
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
    schedules = heat_schedules(scales, source.values)
    if int(iterations) < 1:
        raise HamsaError(f"need at least one ICP iteration, got {iterations}")
    weights = dict.fromkeys((float(commutativity_weight), 0.0))  # with the term, then the plain fit
    fits = landmark_fits(source, target, p, q, weights)
    sampled = np.random.default_rng(seed).choice(source.n, min(sample, source.n), replace=False)
    embedding = KernelEmbedding(source, target, features, feature_weight)
    icp = KernelICP(embedding, p, q, landmark_weight, int(iterations))
    starts = sign_flip_starts(fits, source, restarts)  # once: each start runs through every schedule
    runs = [(start, times) for times in schedules for start in starts]
    C = lowest_energy_run(icp, runs, sampled, progress)
    finest = embedding.at(schedules[0][-1])  # every schedule ends at the same finest scale
    return C, nearest_rows(finest.queries(C), finest.target)
