"""The one iterative-closest-point kernel of hamsa's matchers: nearest neighbours, then orthogonal Procrustes.

Every spectral matcher here (:func:`~hamsa.matching.icp_refine`, ICSKM, SGFE) alternates the same two
steps until the point map stops changing: the map that sends each query point to its nearest target
point under the current orthogonal C, and the orthogonal C closest to the map's cross-covariance
``M = sum_x w_x e_s(x)^T e_t(map(x))`` (``C = U V^T`` for ``M = U S V^T``, the orthogonal Procrustes
solution maximizing ``tr(C^T M)``). They differ only in the embeddings and weights they use.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


def procrustes(cross_covariance: np.ndarray) -> np.ndarray:
    """The orthogonal matrix ``U V^T`` nearest to ``cross_covariance = U S V^T`` (k, k): the C maximizing
    ``tr(C^T M)`` over orthogonal C."""
    U, _, Vt = np.linalg.svd(cross_covariance, full_matrices=False)
    return U @ Vt


def alternate(
    C: np.ndarray,
    nearest: Callable[[np.ndarray], np.ndarray],
    fit: Callable[[np.ndarray], np.ndarray],
    iterations: int,
    mapping: np.ndarray | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[np.ndarray, np.ndarray, int]:
    """ICP from C: up to ``iterations`` times, ``new = nearest(C)``; stop if it equals the current map,
    else adopt it and refit ``C = fit(new)``.

    ``mapping`` is the map a previous call ended with (so a call that finds it unchanged at once does
    nothing). ``progress(done, iterations)`` is called after each iteration, and with ``done = iterations``
    when the map stops changing earlier. Returns ``(C, mapping, fits)``: C is fitted to ``mapping``
    whenever ``fits > 0``.
    """
    fits = 0
    for done in range(1, iterations + 1):
        new = nearest(C)
        if mapping is not None and np.array_equal(new, mapping):
            break
        mapping = new
        C = fit(mapping)
        fits += 1
        if progress is not None and done < iterations:
            progress(done, iterations)
    if progress is not None and iterations > 0:
        progress(iterations, iterations)
    return C, mapping, fits
