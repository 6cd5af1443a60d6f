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


def critical_potential_scale(lbo_basis: Eigenbasis, potential, index: int) -> float:
    """The paper's bound on the potential scale mu (eq. mu_potential), for eigenpair ``index`` (0-based).

    To first order ``E_i(mu) ~ lambda_i + mu <phi_i, V phi_i>_A``; requiring ``E_i > mu max V`` gives
    ``mu < lambda_i / (max V - <phi_i, V phi_i>_A)``. The paper writes psi_i in the denominator, but
    psi_i depends on mu; the first-order derivation uses the LBO eigenfunction phi_i.

    Returns +inf when the denominator is <= 0 (phi_i already sits where V is maximal).
    """
    if not 0 <= index < lbo_basis.k:
        raise HamsaError(f"index {index} is outside the basis (k = {lbo_basis.k})")
    v = np.asarray(potential, dtype=np.float64)
    if v.shape != (lbo_basis.n,) or not np.all(np.isfinite(v)):
        raise PotentialError(f"potential must be a finite ({lbo_basis.n},) array")
    phi = lbo_basis.vectors[:, index]
    expectation = phi @ (lbo_basis.mass @ (v * phi))
    denominator = v.max() - expectation
    if denominator <= 0:
        return float("inf")
    return float(lbo_basis.values[index] / denominator)


def first_order_eigenvector(values, vectors, stiffness_change, mass_change, index: int) -> np.ndarray:
    """The paper's first-order eigenvector perturbation (eq. perturbation).

    For ``H psi = E A psi`` perturbed to ``(H + dH) psi~ = E~ (A + dA) psi~``::

        psi~_i ~ psi_i (1 - psi_i^T dA psi_i / 2) + sum_{k != i} psi_k^T (dH - E_i dA) psi_i / (E_i - E_k) psi_k

    with signed changes (the paper writes |.|, which is not a perturbation expansion) and ``dH`` including
    the change of ``A diag(V)``. The sum runs over the columns given: pass the complete basis (small
    meshes) for the exact first-order term, or a truncated one for an approximation.

    Parameters
    ----------
    values : (m,) eigenvalues E, vectors : (n, m) A-orthonormal eigenvectors
    stiffness_change, mass_change : (n, n) sparse or dense, dH and dA
    index : the eigenpair to perturb (0-based, a simple eigenvalue)

    Returns
    -------
    (n,) the predicted perturbed eigenvector, normalized like psi_i (to first order).
    """
    values = np.asarray(values, dtype=np.float64)
    vectors = np.asarray(vectors, dtype=np.float64)
    if not 0 <= index < values.size:
        raise HamsaError(f"index {index} is outside the basis (m = {values.size})")
    psi = vectors[:, index]
    coupling = vectors.T @ (stiffness_change @ psi - values[index] * (mass_change @ psi))
    gaps = values[index] - values
    gaps[index] = np.inf
    if np.any(np.abs(gaps) < 1e-12 * max(np.abs(values).max(), 1.0)):
        raise HamsaError(f"eigenvalue {index} is repeated: the first-order formula needs a simple eigenvalue")
    return psi * (1 - psi @ (mass_change @ psi) / 2) + vectors @ (coupling / gaps)
