"""Checkable statements of the paper's theory, as functions of computed spectra."""

from __future__ import annotations

import numpy as np

from hamsa.eigen import Eigenbasis
from hamsa.errors import HamsaError, PotentialError


def eigenvalue_bounds(lbo_values, potential) -> tuple[np.ndarray, np.ndarray]:
    """Theorem 1: ``lambda_i + min V <= E_i <= lambda_i + max V`` for every i.

    Parameters
    ----------
    lbo_values : (k,) array
        Eigenvalues lambda_i of the Laplace-Beltrami operator (V = 0), ascending.
    potential : (n,) array
        The potential V (any sign: the proof is Courant-Fischer in the A-inner product, exact for
        the discrete lumped-mass problem too).

    Returns
    -------
    lower, upper : (k,) arrays
    """
    values = np.asarray(lbo_values, dtype=np.float64)
    v = np.asarray(potential, dtype=np.float64)
    if v.size == 0 or not np.all(np.isfinite(v)):
        raise PotentialError("potential must be a non-empty finite array")
    return values + v.min(), values + v.max()


def mass_fraction(basis: Eigenbasis, region) -> np.ndarray:
    """Fraction of each eigenfunction's A-mass inside a vertex region: ``sum_{j in region} a_j psi_ij^2``.

    Parameters
    ----------
    basis : Eigenbasis (mass-orthonormal, so each column has total A-mass 1)
    region : (n,) bool array

    Returns
    -------
    (k,) array in [0, 1]. With a lumped (diagonal) mass this is exact; with the full mass the
    diagonal of A is used as the per-vertex weight.
    """
    region = np.asarray(region, dtype=bool)
    if region.shape != (basis.n,):
        raise HamsaError(f"region has shape {region.shape}, the basis has {basis.n} vertices")
    weights = basis.mass.diagonal()
    inside = (weights[region, None] * basis.vectors[region] ** 2).sum(axis=0)
    total = (weights[:, None] * basis.vectors**2).sum(axis=0)
    return inside / total
