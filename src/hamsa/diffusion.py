"""Hamiltonian heat diffusion and the heat and wave kernel signatures (paper section 2.6).

The Hamiltonian heat equation is ``du/dt = Laplacian u - V u = -H u`` (the paper's eq. heatKernelH
prints ``du/dt = H u``, a typo, and its Feynman-Kac formula carries the matching wrong sign; see the
docs' conventions page).
Its solution decays: ``u(t) = Psi diag(exp(-E t)) Psi^T A u0``. Every function here takes an
:class:`~hamsa.eigen.Eigenbasis` of either the LBO (V = 0) or a Hamiltonian, so HKS and WKS come for
free for any potential (the paper's "Hamiltonian signatures").
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from hamsa.eigen import Eigenbasis
from hamsa.errors import HamsaError
from hamsa.factorization import CholeskySolver
from hamsa.operators import check_potential, hamiltonian
from hamsa.pointcloud import as_shape

LN10 = np.log(10.0)


def _times(t) -> np.ndarray:
    times = np.atleast_1d(np.asarray(t, dtype=np.float64))
    if times.ndim != 1 or times.size == 0 or not np.all(np.isfinite(times)) or np.any(times <= 0):
        raise HamsaError(f"diffusion times must be positive and finite, got {t!r}")
    return times


def _sources(basis: Eigenbasis, sources) -> np.ndarray:
    index = np.atleast_1d(np.asarray(sources))
    if index.size == 0:
        raise HamsaError("no source vertices given")
    if not np.issubdtype(index.dtype, np.integer) or index.min() < 0 or index.max() >= basis.n:
        raise HamsaError(f"source vertices must be integers in [0, {basis.n}), got {sources!r}")
    return index


def diffuse(basis: Eigenbasis, u0, t) -> np.ndarray:
    """Spectral solution of ``A du/dt = -(W + A V) u`` from ``u(0) = u0``.

    Parameters
    ----------
    basis : Eigenbasis of H (the more eigenpairs, the smaller t can be: modes beyond k are dropped)
    u0 : (n,) or (n, d) initial temperatures
    t : float or (T,) times, > 0

    Returns
    -------
    (n,) / (n, d) for a scalar t, else (T, n) / (T, n, d): ``Psi exp(-E t) Psi^T A u0``.
    """
    times = _times(t)
    coefficients = basis.project(u0)  # (k,) or (k, d)
    decay = np.exp(-np.outer(times, basis.values))  # (T, k)
    if coefficients.ndim == 1:
        out = (decay * coefficients) @ basis.vectors.T
    else:
        out = np.einsum("tk,kd,nk->tnd", decay, coefficients, basis.vectors)
    return out[0] if np.ndim(t) == 0 else out


def heat_kernel(basis: Eigenbasis, t, sources) -> np.ndarray:
    """Heat kernel ``K_t(x, y) = sum_i exp(-E_i t) psi_i(x) psi_i(y)`` for y in ``sources``.

    ``K_t(., j)`` is the temperature at time t from a unit amount of heat put at vertex j
    (``u0 = e_j / a_j``). Returns (n, s) for a scalar t, else (T, n, s).
    """
    times = _times(t)
    index = _sources(basis, sources)
    decay = np.exp(-np.outer(times, basis.values))  # (T, k)
    out = np.einsum("tk,nk,sk->tns", decay, basis.vectors, basis.vectors[index])
    return out[0] if np.ndim(t) == 0 else out


def landmark_descriptors(basis: Eigenbasis, landmarks, times=None) -> np.ndarray:
    """Heat kernel maps from landmark vertices, ``K_t(x, l) / K_t(l, l)`` for each landmark l and time t:
    (n, s T) columns ordered landmark-major, each 1 at its landmark. Given the two shapes' landmarks in
    corresponding order, they are corresponding descriptors: what turns known pairs into constraints of a
    functional map (:func:`hamsa.matching.functional_map`). ``times`` default: 5 of :func:`default_hks_times`.
    """
    index = _sources(basis, landmarks)
    times = default_hks_times(basis, 5) if times is None else _times(times)
    kernel = heat_kernel(basis, times, index)  # (T, n, s)
    kernel = kernel / kernel[:, index, np.arange(index.size)][:, None, :]
    return kernel.transpose(1, 2, 0).reshape(basis.n, -1)


def diffuse_time_stepping(mesh, u0, t: float, potential=None, steps: int = 200, mass: str = "voronoi") -> np.ndarray:
    """Reference solution of ``A du/dt = -(W + A V) u`` by implicit time stepping (no eigenbasis).

    Crank-Nicolson (second order) with one sparse factorization of ``A + dt/2 H``, started by two
    implicit-Euler half steps (Rannacher start-up) so that rough data such as a delta do not leave
    undamped high-frequency oscillations. Used to cross-check :func:`diffuse`.

    ``mesh`` may be a point cloud (its Laplacian, see :mod:`hamsa.pointcloud`). Returns (n,) or (n, d) at t.
    """
    mesh = as_shape(mesh)
    if potential is not None:
        potential = check_potential(potential, mesh.n_vertices)
    (t,) = _times(t)
    if steps < 2:
        raise HamsaError("need at least 2 time steps")
    H, A = hamiltonian(mesh, potential, mass)
    dt = t / steps
    u = np.asarray(u0, dtype=np.float64).copy()
    euler = CholeskySolver((A + (dt / 2) * H).tocsc())
    for _ in range(2):  # two implicit Euler steps of dt/2 = one step of dt
        u = euler.solve(A @ u)
    explicit = (A - (dt / 2) * H).tocsr()
    for _ in range(steps - 1):  # the same matrix A + dt/2 H serves Crank-Nicolson
        u = euler.solve(explicit @ u)
    return u


def total_heat(basis_or_mass, u) -> np.ndarray:
    """``integral u = 1^T A u`` for u (n,) or (T, n)."""
    mass = basis_or_mass.mass if isinstance(basis_or_mass, Eigenbasis) else sp.csr_matrix(basis_or_mass)
    u = np.asarray(u, dtype=np.float64)
    weights = np.asarray(mass.sum(axis=0)).ravel()
    return u @ weights


def _positive_spectrum(basis: Eigenbasis) -> np.ndarray:
    values = basis.values
    top = np.abs(values).max()
    positive = values[values > 1e-8 * top]
    if positive.size < 2:
        raise HamsaError("signatures need at least two eigenvalues above zero; compute a larger basis")
    return positive


def default_hks_times(basis: Eigenbasis, count: int = 100) -> np.ndarray:
    """Sun et al. 2009 scales: ``count`` times geometrically spaced in [4 ln10 / E_max, 4 ln10 / E_low].

    E_low is the smallest eigenvalue above zero (lambda_2 for the LBO of a connected surface; E_1 for a
    Hamiltonian with V >= 0, V != 0, which has no zero mode).
    """
    positive = _positive_spectrum(basis)
    return np.geomspace(4 * LN10 / positive.max(), 4 * LN10 / positive.min(), count)


def heat_kernel_signature(basis: Eigenbasis, times=None, scaled: bool = False) -> np.ndarray:
    """HKS(x, t) = K_t(x, x) = sum_i exp(-E_i t) psi_i(x)^2 (Sun, Ovsjanikov, Guibas 2009), shape (n, T).

    Parameters
    ----------
    basis : Eigenbasis (LBO or Hamiltonian)
    times : (T,) array, optional
        Default :func:`default_hks_times` (100 scales).
    scaled : bool
        Divide each column by the heat trace ``sum_i exp(-E_i t)`` (comparable across shapes).
    """
    times = default_hks_times(basis) if times is None else _times(times)
    decay = np.exp(-np.outer(basis.values, times))  # (k, T)
    signature = (basis.vectors**2) @ decay
    if scaled:
        signature /= decay.sum(axis=0)
    return signature


def default_wks_energies(basis: Eigenbasis, count: int = 100, sigma_factor: float = 7.0) -> tuple[np.ndarray, float]:
    """Aubry et al. 2011 log-energy grid: (energies (count,), sigma).

    ``e_min = log E_low, e_max = log E_max, sigma = sigma_factor (e_max - e_min) / count``, then the grid
    ``linspace(e_min + 2 sigma, e_max - 2 sigma, count)`` (the convention of Aubry et al.'s paper, also pyFM's).
    """
    positive = _positive_spectrum(basis)
    e_min, e_max = np.log(positive.min()), np.log(positive.max())
    sigma = sigma_factor * (e_max - e_min) / count
    return np.linspace(e_min + 2 * sigma, e_max - 2 * sigma, count), float(sigma)


def wave_kernel_signature(basis: Eigenbasis, energies=None, sigma: float | None = None) -> np.ndarray:
    """WKS(x, e) = sum_i psi_i(x)^2 exp(-(e - log E_i)^2 / 2 sigma^2) / sum_i exp(...) (Aubry et al. 2011).

    Eigenpairs with E_i <= 0 (the LBO's constant mode; negative energies of a signed potential) have
    no log-energy and are left out. Returns (n, M).
    """
    if energies is None:
        energies, default_sigma = default_wks_energies(basis)
        sigma = default_sigma if sigma is None else sigma
    elif sigma is None:
        raise HamsaError("give sigma together with explicit energies")
    energies = np.atleast_1d(np.asarray(energies, dtype=np.float64))
    if not sigma > 0:
        raise HamsaError(f"sigma must be positive, got {sigma}")
    top = np.abs(basis.values).max()
    keep = basis.values > 1e-8 * top
    log_e = np.log(basis.values[keep])
    weights = np.exp(-((energies[None, :] - log_e[:, None]) ** 2) / (2 * sigma**2))  # (k', M)
    return (basis.vectors[:, keep] ** 2) @ weights / weights.sum(axis=0)
