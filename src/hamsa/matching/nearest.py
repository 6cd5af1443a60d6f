"""Exact nearest neighbours in spectral embeddings and descriptor spaces (k-d trees)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from hamsa.errors import HamsaError


def nearest_rows(queries: np.ndarray, points: np.ndarray) -> np.ndarray:
    """For each row of ``queries`` (q, d), the index (q,) of the nearest row of ``points`` (p, d) (Euclidean).

    An exact k-d tree search at any d: spectral embeddings and kernel signatures of a surface have
    intrinsic dimension about 2, so a tree stays ahead of a dense distance scan even at d = 100
    (``benchmarks/nearest_neighbours.py`` measures both).

    Raises
    ------
    HamsaError
        If the arrays are not 2-D with the same number of columns.
    """
    queries = np.ascontiguousarray(queries, dtype=np.float64)
    points = np.ascontiguousarray(points, dtype=np.float64)
    if queries.ndim != 2 or points.ndim != 2 or queries.shape[1] != points.shape[1]:
        raise HamsaError(f"need (q, d) and (p, d) arrays with the same d, got {queries.shape} and {points.shape}")
    return nearest_in(cKDTree(points), queries)


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
