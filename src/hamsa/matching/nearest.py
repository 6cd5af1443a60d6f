"""Exact nearest neighbours in spectral embeddings and descriptor spaces (k-d trees, and a distance scan)."""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial import cKDTree

from hamsa.errors import HamsaError

_SCAN_BLOCK_BYTES = 2**25  # distances held at once by the scan
_PROBE = 256  # queries timed by method="auto"


def nearest_rows(queries: np.ndarray, points: np.ndarray, method: str = "tree") -> np.ndarray:
    """For each row of ``queries`` (q, d), the index (q,) of the nearest row of ``points`` (p, d) (Euclidean).

    Every method is exact. ``"tree"``, a k-d tree, suits queries that lie on or near the point set:
    spectral embeddings and kernel signatures of a surface have intrinsic dimension about 2, so there it
    stays ahead of a distance scan even at d = 100. ``"scan"`` (:func:`scan_nearest_rows`, cost q p d)
    suits queries far from the points in many dimensions, where a tree's pruning fails: the images of an
    imperfect functional map. ``"auto"`` (from 2048 queries; a tree below) times both on 256 evenly
    spaced queries and runs the faster on all of them (``benchmarks/nearest_neighbours.py`` measures both
    kinds); the answer does not depend on the choice (up to exact ties, which the scan gives to the
    lowest index).

    Raises
    ------
    HamsaError
        If the arrays are not 2-D with the same number of columns, hold NaN or infinite values, there
        are no points, or the method is unknown.
    """
    queries = np.ascontiguousarray(queries, dtype=np.float64)
    points = np.ascontiguousarray(points, dtype=np.float64)
    if queries.ndim != 2 or points.ndim != 2 or queries.shape[1] != points.shape[1]:
        raise HamsaError(f"need (q, d) and (p, d) arrays with the same d, got {queries.shape} and {points.shape}")
    if len(points) == 0:
        raise HamsaError("there are no points to search")
    for name, array in (("queries", queries), ("points", points)):
        if not np.all(np.isfinite(array)):
            raise HamsaError(f"the {name} contain NaN or infinite values")
    if method not in ("tree", "scan", "auto"):
        raise HamsaError(f"method must be 'tree', 'scan' or 'auto', got {method!r}")
    if method == "scan":
        return scan_nearest_rows(queries, points)
    tree = cKDTree(points)
    if method == "auto" and len(queries) >= 8 * _PROBE:
        sample = queries[:: len(queries) // _PROBE][:_PROBE]
        start = time.perf_counter()
        tree.query(sample, workers=-1)
        tree_seconds = time.perf_counter() - start
        start = time.perf_counter()
        scan_nearest_rows(sample, points)
        if time.perf_counter() - start < tree_seconds:
            return scan_nearest_rows(queries, points)
    return nearest_in(tree, queries)


def scan_nearest_rows(queries: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Exact nearest rows (q,) of ``points`` (p, d) to ``queries`` (q, d) by a blocked distance scan.

    Each block ranks the points by ``|y|^2 - 2 x.y`` (one matrix product, on every BLAS thread). That
    expansion cancels digits when x and y are close to each other and far from 0, so every point within
    its rounding bound, ``4 (d + 2) eps (|x|^2 + max |y|^2)``, of the best one is ranked again by the
    directly computed ``|x - y|^2`` (ties: the lowest index).
    """
    queries = np.ascontiguousarray(queries, dtype=np.float64)
    points = np.ascontiguousarray(points, dtype=np.float64)
    squared = np.einsum("ij,ij->i", points, points)
    bound = 4 * (points.shape[1] + 2) * np.finfo(np.float64).eps
    block = max(1, _SCAN_BLOCK_BYTES // (8 * max(1, len(points))))
    nearest = np.empty(len(queries), dtype=np.int64)
    for start in range(0, len(queries), block):
        x = queries[start : start + block]
        ranks = x @ points.T
        ranks *= -2.0
        ranks += squared
        best = np.argmin(ranks, axis=1)
        rows = np.arange(len(x))
        threshold = ranks[rows, best] + bound * (np.einsum("ij,ij->i", x, x) + squared.max())
        ranks[rows, best] = np.inf
        contested = np.flatnonzero(ranks.min(axis=1) <= threshold)  # a second point within the bound
        if len(contested):
            ranks[contested, best[contested]] = -np.inf
            near_rows, near_points = np.nonzero(ranks[contested] <= threshold[contested, None])
            difference = x[contested[near_rows]] - points[near_points]
            exact = np.einsum("ij,ij->i", difference, difference)
            order = np.lexsort((near_points, exact, near_rows))  # per row: nearest, then lowest index
            first = order[np.r_[True, near_rows[order][1:] != near_rows[order][:-1]]]
            best[contested[near_rows[first]]] = near_points[first]
        nearest[start : start + block] = best
    return nearest


def nearest_in(tree: cKDTree, queries: np.ndarray) -> np.ndarray:
    """Indices (q,) of the nearest points of a built k-d tree to the rows of ``queries`` (q, d); on all
    cores from a thousand queries (below that, starting the threads costs more than they save)."""
    return tree.query(queries, workers=-1 if len(queries) >= 1000 else 1)[1].astype(np.int64)


def match_descriptors(source_descriptors, target_descriptors) -> np.ndarray:
    """``map_source_to_target`` (n_s,): the nearest target vertex in descriptor space, for each source vertex.

    Descriptors are (n, d) arrays (e.g. HKS/WKS columns); each column is scaled by its root mean square
    over both shapes so that no scale dominates.

    Raises
    ------
    HamsaError
        If the descriptors are not (n, d) arrays with the same d.
    """
    F = np.asarray(source_descriptors, dtype=np.float64)
    G = np.asarray(target_descriptors, dtype=np.float64)
    if F.ndim != 2 or G.ndim != 2 or F.shape[1] != G.shape[1]:
        raise HamsaError(f"descriptors must be (n, d) with the same d, got {F.shape} and {G.shape}")
    scale = np.sqrt(np.mean(np.vstack([F, G]) ** 2, axis=0))
    scale[scale == 0] = 1.0
    return nearest_rows(F / scale, G / scale)
