"""The Princeton correspondence benchmark protocol (Kim, Lipman, Funkhouser 2011).

For a predicted map and the ground truth, both given as target vertex ids for the same evaluated
source points, the error of a point is the geodesic distance on the TARGET between its predicted and
true images, divided by the square root of the target's area. The cumulative curve gives the
fraction of points with error <= r for r in [0, 0.25]. "Symmetries are not allowed" (the paper): only
the true map counts; ``symmetry=`` gives the symmetry-allowed variant (the smaller of the errors to the
true image and to its left-right partner). Geodesics are the heat method's by default (:mod:`hamsa.geodesic`,
first-order accurate in the edge length; on a point cloud, the point-cloud heat method), batched over the
distinct true images; ``geodesics="exact"`` uses the exact polyhedral distances the published curves use
(the ``[geodesics]`` extra; docs/results/exact_geodesics.md measures the difference).
"""

from __future__ import annotations

import numpy as np

from hamsa.errors import HamsaError
from hamsa.geodesic import geodesic_solver
from hamsa.pointcloud import as_shape

THRESHOLDS = np.arange(0.0, 0.25 + 1e-12, 0.005)  # Kim et al.'s 0:0.005:0.25


def sample_points(n: int, count: int = 1000, seed: int = 0) -> np.ndarray:
    """``count`` distinct vertex ids in [0, n) (all of them if count >= n), sorted, reproducibly."""
    if count >= n:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, size=count, replace=False))


def geodesic_errors(
    target,
    predicted,
    ground_truth,
    *,
    symmetry=None,
    solver=None,
    geodesics: str = "heat",
) -> np.ndarray:
    """Normalized geodesic errors ``d_target(predicted_i, truth_i) / sqrt(area(target))``, shape (s,).

    Parameters
    ----------
    target : TriMesh (or pair) or PointCloud on which both maps land
    predicted, ground_truth : (s,) target vertex ids of the same s evaluated source points
    symmetry : (n_target,) optional left-right map of the target: symmetric flips then count as correct
    solver : a geodesic solver of ``target`` (:func:`hamsa.geodesic.geodesic_solver`) to reuse across calls
    geodesics : ``"heat"`` or ``"exact"``: the solver built when none is given
    """
    target = as_shape(target)
    predicted = np.asarray(predicted)
    truth = np.asarray(ground_truth)
    n = target.n_vertices
    if predicted.shape != truth.shape or predicted.ndim != 1:
        raise HamsaError(f"predicted {predicted.shape} and ground truth {truth.shape} must be equal 1-D shapes")
    for name, ids in (("predicted", predicted), ("ground truth", truth)):
        if ids.size and (not np.issubdtype(ids.dtype, np.integer) or ids.min() < 0 or ids.max() >= n):
            raise HamsaError(f"{name} ids must be integers in [0, {n}) (target vertices)")
    solver = solver or geodesic_solver(target, method=geodesics)
    errors = solver.between(truth, predicted)
    if symmetry is not None:
        partner = np.asarray(symmetry)
        if partner.shape != (n,):
            raise HamsaError(f"symmetry map has shape {partner.shape}, the target has {n} vertices")
        errors = np.minimum(errors, solver.between(partner[truth], predicted))
    return errors / np.sqrt(target.area)


class TruthDistances:
    """Geodesic distances on the target from the true images of the evaluated points, computed once.

    Comparing several predicted maps for the same points (methods, bases) costs one heat-method solve
    per true image instead of one per map: ``TruthDistances(target, truth).errors(predicted)`` equals
    ``geodesic_errors(target, predicted, truth)``. Memory: an (n_target, distinct true images) table.
    ``solver`` / ``geodesics`` as in :func:`geodesic_errors`; ``batch``: true images per solve.
    """

    def __init__(self, target, ground_truth, solver=None, batch: int = 64, geodesics: str = "heat"):
        self.target = as_shape(target)
        self.truth = np.asarray(ground_truth)
        n = self.target.n_vertices
        if self.truth.ndim != 1 or (
            self.truth.size and (not np.issubdtype(self.truth.dtype, np.integer) or self.truth.min() < 0
                                 or self.truth.max() >= n)
        ):  # fmt: skip
            raise HamsaError(f"ground truth must be a 1-D array of target vertex ids in [0, {n})")
        unique, self._column = np.unique(self.truth, return_inverse=True)
        solver = solver or geodesic_solver(self.target, method=geodesics)
        self._table = np.hstack([solver.distances_from(unique[s : s + batch]) for s in range(0, len(unique), batch)])

    def errors(self, predicted) -> np.ndarray:
        """(s,) normalized errors of a predicted map (target vertex ids of the same s points)."""
        predicted = np.asarray(predicted)
        if predicted.shape != self.truth.shape or not np.issubdtype(predicted.dtype, np.integer):
            raise HamsaError(f"predicted must be {self.truth.shape} integer target ids, got {predicted.shape}")
        if predicted.size and (predicted.min() < 0 or predicted.max() >= self.target.n_vertices):
            raise HamsaError(f"predicted ids must be in [0, {self.target.n_vertices}) (target vertices)")
        return self._table[predicted, self._column] / np.sqrt(self.target.area)


def error_curve(errors, thresholds=THRESHOLDS) -> np.ndarray:
    """Fraction of points with error <= r, for each threshold r (the Kim et al. cumulative curve)."""
    errors = np.asarray(errors, dtype=np.float64)
    if errors.size == 0:
        raise HamsaError("no errors to summarize")
    return np.mean(errors[None, :] <= np.asarray(thresholds)[:, None], axis=1)


def area_under_curve(errors, thresholds=THRESHOLDS) -> float:
    """The mean of the cumulative curve over the thresholds (1 = every point exact, 0 = all beyond 0.25)."""
    return float(np.mean(error_curve(errors, thresholds)))


def summary(errors) -> dict:
    """Mean error, area under the curve on [0, 0.25], the fraction within 0.05, and the fraction unreachable.

    A point mapped to a different connected component of the target has an infinite geodesic error: it
    counts as beyond every threshold of the curve, is left out of the mean (reported as ``unreachable``
    instead), and the mean is NaN only if no point is reachable.
    """
    errors = np.asarray(errors, dtype=np.float64)
    finite = np.isfinite(errors)
    return {
        "mean_error": float(errors[finite].mean()) if finite.any() else float("nan"),
        "auc": area_under_curve(errors),
        "within_0.05": float(np.mean(errors <= 0.05)),
        "unreachable": float(np.mean(~finite)),
    }


def evaluated_points(ground_truth, count: int = 1000, seed: int = 0) -> np.ndarray:
    """The source vertices a map is scored at: ``count`` of those with a known true image (ground truth
    (n_s,) target ids, -1 where unknown), drawn reproducibly by :func:`sample_points`."""
    truth = np.asarray(ground_truth)
    if truth.ndim != 1 or not np.issubdtype(truth.dtype, np.integer):
        raise HamsaError(f"ground truth must be a 1-D array of integer target ids, got {truth.dtype} {truth.shape}")
    known = np.flatnonzero(truth >= 0)
    if not len(known):
        raise HamsaError("the ground truth has no known image (every entry is -1)")
    return known[sample_points(len(known), count, seed)]


def map_scores(
    target,
    map_source_to_target,
    ground_truth,
    points: int = 1000,
    seed: int = 0,
    geodesics: str = "heat",
    solver=None,
) -> dict:
    """The Kim et al. scores of a point map: :func:`summary` of the geodesic errors at ``points`` source
    vertices (:func:`evaluated_points`), plus ``points`` (how many) and ``curve`` (the cumulative curve on
    :data:`THRESHOLDS`). ``map_source_to_target`` and ``ground_truth``: (n_s,) target ids, -1 in the
    truth where unknown; ``geodesics``: ``"heat"`` or ``"exact"``, or a ``solver`` of the target to reuse
    (:func:`geodesic_errors`). What ``hamsa match --truth`` reports."""
    mapping, truth = np.asarray(map_source_to_target), np.asarray(ground_truth)
    if mapping.shape != truth.shape:
        raise HamsaError(
            f"the map has shape {mapping.shape}, the ground truth {truth.shape}: one entry per source vertex"
        )
    chosen = evaluated_points(truth, points, seed)
    errors = geodesic_errors(target, mapping[chosen], truth[chosen], solver=solver, geodesics=geodesics)
    return {**summary(errors), "points": len(chosen), "curve": error_curve(errors).tolist()}


def map_distortion(
    source, target, map_source_to_target, sources: int = 30, points: int = 1000, seed: int = 0, target_solver=None
) -> dict:
    """How far a point map is from an isometry onto the whole target, measured without ground truth.

    ``distortion``: the mean over ``sources`` x ``points`` seeded source vertex pairs (a, b) of
    ``|d_T(f(a), f(b)) / sqrt(area_T) - d_S(a, b) / sqrt(area_S)|``, heat-method geodesics on each shape (on a
    cloud, the point-cloud heat method); pairs in different pieces of either shape are left out. ``coverage``:
    the fraction of the target's area (its operator's lumped mass) at the vertices the map hits. A map between
    two poses that follows the surface has a small distortion and covers most of the target; a map that
    swaps or folds parts has a large one. An isometry's mirror image scores as well as the isometry itself:
    only ground truth (:func:`map_scores`) tells the two apart.

    Parameters
    ----------
    source, target : TriMesh (or pair) or PointCloud
    map_source_to_target : (n_source,) target vertex ids
    sources, points : how many seeded source vertices carry geodesics (each a heat-method solve on both
        shapes) and how many they are measured to
    target_solver : the target's heat-method solver (:func:`hamsa.geodesic.geodesic_solver`) to reuse

    Returns
    -------
    dict with ``distortion``, ``median_distortion`` (in units of sqrt(area)), ``coverage`` in [0, 1] and
    ``pairs`` (how many were measured).
    """
    from hamsa.operators import laplacian_operators

    source, target = as_shape(source), as_shape(target)
    mapping = np.asarray(map_source_to_target)
    if mapping.shape != (source.n_vertices,) or not np.issubdtype(mapping.dtype, np.integer):
        raise HamsaError(f"the map must be ({source.n_vertices},) integer target ids, got {mapping.shape}")
    if mapping.min() < 0 or mapping.max() >= target.n_vertices:
        raise HamsaError(f"the map's ids must be in [0, {target.n_vertices}) (target vertices)")
    a = sample_points(source.n_vertices, sources, seed)
    b = sample_points(source.n_vertices, points, seed + 1)
    mass_s = laplacian_operators(source)[1].diagonal()
    mass_t = laplacian_operators(target)[1].diagonal()
    on_source = geodesic_solver(source).distances_from(a)[b] / np.sqrt(mass_s.sum())
    on_target = (target_solver or geodesic_solver(target)).distances_from(mapping[a])[mapping[b]]
    on_target /= np.sqrt(mass_t.sum())
    difference = np.abs(on_target - on_source)[np.isfinite(on_source) & np.isfinite(on_target)]
    if difference.size == 0:
        raise HamsaError("no measured pair lies in one piece of both shapes")
    hit = np.zeros(target.n_vertices, dtype=bool)
    hit[mapping] = True
    return {
        "distortion": float(difference.mean()),
        "median_distortion": float(np.median(difference)),
        "coverage": float(mass_t[hit].sum() / mass_t.sum()),
        "pairs": int(difference.size),
    }
