"""Linear finite elements on a 1-D interval: the paper's one-dimensional examples (Fig. 1, the toy of 3).

The same discretization as on surfaces, one dimension down: on a uniform grid of n points with
spacing h, the stiffness W is tridiagonal (1/h on the diagonal ends, 2/h inside, -1/h off it) and
the lumped mass is h (h/2 at the two ends), so ``(W + A diag(V)) psi = E A psi`` discretizes
``-psi'' + V psi = E psi``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from hamsa.errors import HamsaError

BOUNDARIES = ("neumann", "dirichlet")


def interval_operators(n: int, length: float = 1.0, boundary: str = "neumann"):
    """Stiffness W (n', n'), lumped mass A (n', n') and grid points x (n',) on [0, length].

    ``boundary="neumann"``: free ends (natural conditions), n' = n. ``"dirichlet"``: psi = 0 at both
    ends (the particle in a box); the two end points are removed, n' = n - 2.
    """
    if n < 3:
        raise HamsaError(f"an interval grid needs at least 3 points, got {n}")
    if boundary not in BOUNDARIES:
        raise HamsaError(f"boundary must be one of {BOUNDARIES}, got {boundary!r}")
    h = length / (n - 1)
    x = np.linspace(0.0, length, n)
    main = np.full(n, 2.0 / h)
    main[[0, -1]] = 1.0 / h
    W = sp.diags([main, np.full(n - 1, -1.0 / h), np.full(n - 1, -1.0 / h)], [0, -1, 1]).tocsr()
    mass = np.full(n, h)
    mass[[0, -1]] = h / 2
    A = sp.diags(mass).tocsr()
    if boundary == "dirichlet":
        inner = slice(1, n - 1)
        return W[inner, inner].tocsr(), A[inner, inner].tocsr(), x[inner]
    return W, A, x
