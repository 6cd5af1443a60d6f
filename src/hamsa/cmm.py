"""Compressed manifold modes as Hamiltonian eigenproblems (paper section 4; Bronstein et al. 2016).

Compressed modes are localized functions minimizing ``tr(Phi^T W Phi) + mu ||Phi||_1`` subject to
``Phi^T A Phi = I`` (paper eq. CMM-discrete). We use the consistent, area-weighted L1 norm
``sum_j a_j |phi_j|`` (a discretization of the integral of |phi|; the plain vector norm depends on
the sampling). Mode by mode, iteratively reweighted least squares turns the L1 term into a potential:

    |phi_j| <= phi_j^2 / (2 |phi_j_old|) + |phi_j_old| / 2     (a majorizer, equal at phi_old)

so ``mu sum_j a_j |phi_j|`` is majorized by ``mu phi^T A diag(V) phi`` with ``V = 1 / (2 max(|phi_old|, eps))``
(eq. CMM-ls), and the update is the smallest eigenvector of the Hamiltonian ``H = W + mu A diag(V)``
(eq. eigendec-irls). The modes found before are pushed away by the low-rank term
``Z = beta A Phi_prev Phi_prev^T A``; inverse iteration with ``(H + Z)^-1`` costs one sparse solve plus a
small dense correction by the Woodbury identity (:class:`WoodburyInverse`) — "a cascade of sparse and
low-rank systems". A final A-orthogonalization against the previous modes removes what beta leaves.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from functools import partial

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from hamsa.eigen import eigenbasis
from hamsa.errors import ConvergenceWarning, HamsaError
from hamsa.factorization import CholeskySolver
from hamsa.operators import hamiltonian
from hamsa.pointcloud import as_shape


class WoodburyInverse:
    """``x -> (H + U U^T)^-1 x`` from a factorization of H and a dense (p, p) system (Woodbury identity).

    ``(H + U U^T)^-1 = H^-1 - H^-1 U (I + U^T H^-1 U)^-1 U^T H^-1``: p sparse solves once, then one
    sparse solve and O(n p) work per application.

    Parameters
    ----------
    factor : CholeskySolver of the sparse SPD matrix H (n, n)
    U : (n, p) dense
    """

    def __init__(self, factor: CholeskySolver, U: np.ndarray):
        self.factor = factor
        self.U = np.asarray(U, dtype=np.float64)
        if self.U.shape[1]:
            self.HU = factor.solve(self.U)
            self.small = sla.cho_factor(np.eye(self.U.shape[1]) + self.U.T @ self.HU)

    def solve(self, x: np.ndarray) -> np.ndarray:
        y = self.factor.solve(x)
        if self.U.shape[1] == 0:
            return y
        return y - self.HU @ sla.cho_solve(self.small, self.U.T @ y)


@dataclass(frozen=True)
class CompressedModes:
    """k compressed modes and how they were obtained.

    Attributes
    ----------
    modes : (n, k), A-orthonormal columns (up to ``orthogonality_error``), ordered as computed
    objective : float, ``tr(Phi^T W Phi) + mu sum_j a_j |Phi_jk|`` summed over the modes
    orthogonality_error : float, ``max |Phi^T A Phi - I|``
    iterations : list of int, IRLS iterations per mode
    seconds : float
    history : per mode, {"objective": values over the IRLS iterations, "majorized": (before, after) pairs
        of the majorizer phi^T (W + mu A V) phi at each step, for its monotonicity}
    """

    modes: np.ndarray
    objective: float
    orthogonality_error: float
    iterations: list
    seconds: float
    mu: float
    history: list = field(default_factory=list)


def mode_objective(W, weights: np.ndarray, phi: np.ndarray, mu: float) -> float:
    """``phi^T W phi + mu sum_j w_j |phi_j|`` (one mode) or the sum over the columns of phi; w are the L1
    weights (the vertex areas for the consistent norm)."""
    phi = phi[:, None] if phi.ndim == 1 else phi
    return float(np.sum(phi * (W @ phi)) + mu * np.sum(weights[:, None] * np.abs(phi)))


def compressed_modes(
    mesh,
    k: int,
    mu: float,
    *,
    method: str = "hamiltonian",
    tol: float = 1e-6,
    max_iterations: int = 200,
    epsilon: float = 1e-6,
    beta: float | None = None,
    inverse_steps: int = 2,
    refine: bool = True,
    l1: str = "area",
    seed: int = 0,
    callback=None,
) -> CompressedModes:
    """k compressed manifold modes minimizing ``tr(Phi^T W Phi) + mu sum a |Phi|`` with ``Phi^T A Phi = I``.

    Parameters
    ----------
    mesh : TriMesh, (vertices, faces) or PointCloud
    k : number of modes
    mu : L1 weight (scale-dependent: with a unit-area mesh, mu ~ 1-50 gives compact supports)
    method : "hamiltonian" (IRLS + Woodbury, this paper) or "admm" (the baseline of Neumann et al. 2014,
        see :func:`_admm_modes`), both on the same area-weighted objective and stopping rule
    tol : stop a mode's IRLS when its objective changes by less than tol (relative) in an iteration,
        once the reweighting floor has reached epsilon
    max_iterations : IRLS iterations per mode at most
    epsilon : the reweighting floor, relative to max |phi| (``V = 1 / (2 max(|phi|, epsilon max|phi|))``)
    beta : weight of the low-rank term pushing away previous modes (default 1e8 x the largest LBO
        eigenvalue among the first k)
    inverse_steps : inverse-iteration steps on ``H + Z`` per IRLS update (each never increases the
        majorized objective's Rayleigh quotient)
    refine : after the greedy mode-by-mode pass ("hamiltonian"), improve the modes jointly: Jacobi
        rotations of mode pairs that lower the L1 term (``tr(Phi^T W Phi)`` and ``Phi^T A Phi = I`` do not
        change under rotations), then one more IRLS pass in which each mode is re-solved, warm-started,
        A-orthogonal to all the others. The greedy pass alone ends in a worse local minimum
        (``docs/results/cmm.md`` compares the two with ADMM)
    l1 : "area" (default): the consistent norm ``sum_j a_j |phi_j|``, a discretization of the integral of
        |phi|; "vector": the plain ``sum_j |phi_j|`` of Neumann et al.'s code, which depends on the sampling
        (denser regions weigh more) — for comparisons only
    seed : the start vectors are the LBO eigenvectors plus 10% seeded noise
    callback : optional ``callback(stage, mode_index, iterations, objective)`` for progress: stage
        "greedy" after each mode of the first pass, "refinement" after each mode of the joint refinement
        (iterations: that pass's), "admm" after each ADMM iteration (mode_index -1: all modes at once;
        objective: of all k modes)
    """
    if method not in ("hamiltonian", "admm"):
        raise HamsaError(f"method must be 'hamiltonian' or 'admm', got {method!r}")
    if l1 not in ("area", "vector"):
        raise HamsaError(f"l1 must be 'area' or 'vector', got {l1!r}")
    mesh = as_shape(mesh)
    n = mesh.n_vertices
    if not 1 <= k < n:
        raise HamsaError(f"k = {k} must be between 1 and n - 1 = {n - 1}")
    if not mu >= 0 or not np.isfinite(mu):
        raise HamsaError(f"mu must be a finite number >= 0, got {mu}")
    start = time.perf_counter()
    W, A = hamiltonian(mesh)
    areas = A.diagonal()
    weights = areas if l1 == "area" else np.ones(n)
    lbo = eigenbasis(mesh, k)
    if method == "admm":
        modes, iterations, history = _admm_modes(
            W, A, weights, lbo.vectors, float(lbo.values[-1]), mu, tol, max_iterations * 50, callback
        )
        return _result(W, areas, weights, modes, mu, iterations, history, start)
    beta = 1e8 * max(float(lbo.values[-1]), 1.0) if beta is None else float(beta)
    irls = partial(_irls_mode, W, areas, weights, mu, tol=tol, max_iterations=max_iterations, epsilon=epsilon,
                   inverse_steps=inverse_steps)  # fmt: skip
    modes, iterations, history, factor = _greedy_modes(irls, lbo.vectors, areas, beta, seed, callback)
    if refine and k > 1 and mu > 0:  # (with mu = 0 the greedy modes are eigenvectors: nothing to gain)
        _rotate_to_lower_l1(modes, weights)
        _refine_modes(irls, modes, areas, beta, factor, iterations, history, callback)
    return _result(W, areas, weights, modes, mu, iterations, history, start)


def _result(W, areas, weights, modes, mu, iterations, history, start) -> CompressedModes:
    gram = modes.T @ (areas[:, None] * modes)
    return CompressedModes(
        modes=modes,
        objective=mode_objective(W, weights, modes, mu),
        orthogonality_error=float(np.abs(gram - np.eye(modes.shape[1])).max()),
        iterations=iterations,
        seconds=time.perf_counter() - start,
        mu=mu,
        history=history,
    )


def _greedy_modes(irls, lbo_vectors, areas, beta, seed, callback):
    """The modes one by one, each A-orthogonal to the earlier ones (pushed away by the low-rank term
    ``beta (A Phi)(A Phi)^T``): (modes (n, k), IRLS iterations, histories, the reusable factorization)."""
    n, k = lbo_vectors.shape
    modes = np.zeros((n, k))
    rng = np.random.default_rng(seed)
    factor = None
    iterations, history = [], []
    for i in range(k):
        previous = modes[:, :i]
        # the LBO eigenvector, slightly perturbed: the constant mode is a fixed point of the reweighting
        # (|phi| constant gives a constant V) though not a minimizer, so start off it
        start_vector = lbo_vectors[:, i] + 0.1 * rng.standard_normal(n)
        phi = _a_normalize(_a_orthogonalize(start_vector, previous, areas), areas)
        U = np.sqrt(beta) * (areas[:, None] * previous)
        phi, iteration, trace, majorized, factor = irls(phi, previous, U, factor, label=f"mode {i + 1}")
        modes[:, i] = phi
        iterations.append(iteration)
        history.append({"objective": trace, "majorized": majorized})
        if callback is not None:
            callback("greedy", i, iteration, trace[-1])
    return modes, iterations, history, factor


def _refine_modes(irls, modes, areas, beta, factor, iterations, history, callback) -> None:
    """One more warm-started IRLS pass, in place, each mode A-orthogonal to all the others."""
    for i in range(modes.shape[1]):
        others = np.delete(modes, i, axis=1)
        U = np.sqrt(beta) * (areas[:, None] * others)
        phi, iteration, trace, majorized, factor = irls(
            modes[:, i], others, U, factor, label=f"mode {i + 1} (refinement)", floor_start=1e-3
        )
        modes[:, i] = phi
        iterations[i] += iteration
        history[i]["objective"] += trace[1:]
        history[i]["majorized"] += majorized
        if callback is not None:
            callback("refinement", i, iteration, trace[-1])


def _irls_mode(
    W, areas, weights, mu, phi, others, U, factor, tol, max_iterations, epsilon, inverse_steps, label, floor_start=0.1
):
    """IRLS for one mode, A-orthogonal to ``others``: returns (phi, iterations, objective trace,
    majorizer pairs, the factorization object for reuse). The reweighting floor starts at ``floor_start``
    (relative to max|phi|) and halves every iteration down to epsilon."""
    trace = [mode_objective(W, weights, phi, mu)]
    majorized = []
    for iteration in range(1, max_iterations + 1):
        # the reweighting floor starts large and shrinks to epsilon (continuation, as in Daubechies,
        # DeVore, Fornasier, Guentuerk 2010): early iterations stay smooth, later ones sharpen
        relative = max(epsilon, floor_start * 0.5 ** (iteration - 1))
        floor = relative * np.abs(phi).max()
        V = 1.0 / (2.0 * np.maximum(np.abs(phi), floor))
        H = (W + sp.diags(mu * weights * V)).tocsc()
        if factor is None:
            factor = CholeskySolver(H)
        else:
            factor.refactor(H)
        inverse = WoodburyInverse(factor, U)
        new = phi
        for _ in range(inverse_steps):
            new = _a_normalize(inverse.solve(areas * new), areas)
        new = _a_normalize(_a_orthogonalize(new, others, areas), areas)
        if np.sum(areas * new) < 0:  # a deterministic sign: positive mean
            new = -new
        majorized.append((_majorized(W, weights, phi, V, mu), _majorized(W, weights, new, V, mu)))
        phi = new
        trace.append(mode_objective(W, weights, phi, mu))
        if abs(trace[-1] - trace[-2]) <= tol * abs(trace[-2]) and relative <= epsilon * 1.0001:
            break
    else:
        warnings.warn(
            f"IRLS for {label} stopped after {max_iterations} iterations; the last relative change of its "
            f"objective was {abs(trace[-1] - trace[-2]) / abs(trace[-2]):.1e} > tol {tol:.0e}",
            ConvergenceWarning,
            stacklevel=3,
        )
    return phi, iteration, trace, majorized, factor


def _admm_modes(
    W, A, weights, initial, lbo_top: float, mu: float, tol: float, max_iterations: int, callback,
    adaptive_rho: bool = False,
):  # fmt: skip
    """Neumann, Varanasi, Wenger, Wacker, Magnor, Theobalt 2014, written from their update rules, with the
    area-weighted objective: in scaled variables Psi = A^(1/2) Phi (so Psi^T Psi = I),
    ``tr(Psi^T A^-1/2 W A^-1/2 Psi) + mu sum_j sqrt(a_j) |Psi_jk|``, split as Psi = S (L1) = E (quadratic):

    * Psi-step: Stiefel projection of ``Y = S - U_S + E - U_E``: ``Y (Y^T Y)^(-1/2)``;
    * S-step: shrinkage with per-vertex thresholds ``mu sqrt(a_j) / rho``;
    * E-step: ``(2 W + rho A) E' = rho A^(1/2) (Psi + U_E)``, ``E = A^(1/2) E'`` (sparse Cholesky, re-factored
      when rho changes);
    * scaled duals ``U += Psi - S``, ``U += Psi - E``.

    rho is fixed at ``100 max(mu, lambda_K)`` (lambda_K the largest of the k LBO eigenvalues): in the
    scaled variables the entries are ~ n^(-1/2), so the shrinkage threshold needs rho >> mu, and the
    E-step needs rho comparable to the spectrum. Neumann et al.'s residual balancing (double or halve rho
    every 10 iterations when one residual exceeds 5x the other) drove rho down to ~10 and diverged on our
    test shapes with this objective; it is available as ``adaptive_rho=True`` for comparison.

    It stops when the objective of the feasible iterate Phi = A^(-1/2) Psi changes by less than tol
    (relative) between two checks, 10 iterations apart. Starts from the LBO eigenvectors.
    """
    areas = A.diagonal()
    root = np.sqrt(areas)[:, None]
    psi = initial * root
    S, E = psi.copy(), psi.copy()
    U_S, U_E = np.zeros_like(psi), np.zeros_like(psi)
    rho = 100.0 * max(mu, lbo_top)
    factor = CholeskySolver((2 * W + rho * A).tocsc())
    threshold = mu * (weights / np.sqrt(areas))[:, None]  # sum_j w_j |Phi_jk| = sum_j w_j / sqrt(a_j) |Psi_jk|
    objective = mode_objective(W, weights, psi / root, mu)
    history = [objective]
    for iteration in range(1, max_iterations + 1):
        Y = S - U_S + E - U_E
        s_values, vectors = np.linalg.eigh(Y.T @ Y)
        psi = Y @ (vectors / np.sqrt(np.maximum(s_values, 1e-300))) @ vectors.T
        S_old, E_old = S, E
        shifted = psi + U_S
        S = np.sign(shifted) * np.maximum(np.abs(shifted) - threshold / rho, 0.0)
        E = root * factor.solve(rho * root * (psi + U_E))
        U_S += psi - S
        U_E += psi - E
        if iteration % 10 == 0:
            primal = np.sqrt(np.sum((psi - S) ** 2) + np.sum((psi - E) ** 2))
            dual = rho * np.sqrt(np.sum((S - S_old) ** 2) + np.sum((E - E_old) ** 2))
            if adaptive_rho and primal > 5 * dual:
                rho, U_S, U_E = 2 * rho, U_S / 2, U_E / 2
                factor.refactor((2 * W + rho * A).tocsc())
            elif adaptive_rho and dual > 5 * primal:
                rho, U_S, U_E = rho / 2, U_S * 2, U_E * 2
                factor.refactor((2 * W + rho * A).tocsc())
            value = mode_objective(W, weights, psi / root, mu)
            history.append(value)
            if callback is not None:
                callback("admm", -1, iteration, value)
            if abs(value - objective) <= tol * abs(objective):
                break
            objective = value
    else:
        warnings.warn(
            f"ADMM stopped after {max_iterations} iterations before its tolerance {tol:.0e}",
            ConvergenceWarning,
            stacklevel=3,
        )
    return psi / root, [iteration], [{"objective": history, "majorized": []}]


def _rotate_to_lower_l1(modes: np.ndarray, weights: np.ndarray, sweeps: int = 4, tol: float = 1e-3) -> None:
    """Jacobi sweeps over mode pairs (in place): each pair (i, j) is rotated by the angle in [-pi/4, pi/4]
    that minimizes ``sum_v a_v (|phi_i| + |phi_j|)`` (a grid of 33 angles, then 17 finer ones around the
    best). Rotations keep ``Phi^T A Phi`` and ``tr(Phi^T W Phi)``; stops when a sweep gains less than
    ``tol`` of the L1 term."""
    k = modes.shape[1]

    def cost(x, y, angles):
        c, s = np.cos(angles), np.sin(angles)
        rotated = np.abs(np.outer(x, c) - np.outer(y, s)) + np.abs(np.outer(x, s) + np.outer(y, c))
        return weights @ rotated

    coarse = np.linspace(-np.pi / 4, np.pi / 4, 33)
    step = coarse[1] - coarse[0]
    for _ in range(sweeps):
        before = float(weights @ np.abs(modes).sum(axis=1))
        for i in range(k):
            for j in range(i + 1, k):
                x, y = modes[:, i].copy(), modes[:, j].copy()
                best = coarse[np.argmin(cost(x, y, coarse))]
                fine = np.linspace(best - step, best + step, 17)
                values = cost(x, y, fine)
                angle = fine[np.argmin(values)]
                if values.min() < cost(x, y, np.zeros(1))[0]:
                    modes[:, i] = np.cos(angle) * x - np.sin(angle) * y
                    modes[:, j] = np.sin(angle) * x + np.cos(angle) * y
        if before - float(weights @ np.abs(modes).sum(axis=1)) < tol * before:
            break


def _majorized(W, weights, phi, V, mu) -> float:
    """The IRLS majorizer without its constant: ``phi^T W phi + mu phi^T diag(w V) phi``."""
    return float(phi @ (W @ phi) + mu * np.sum(weights * V * phi**2))


def _a_orthogonalize(phi: np.ndarray, previous: np.ndarray, areas: np.ndarray) -> np.ndarray:
    for _ in range(2):
        phi = phi - previous @ (previous.T @ (areas * phi))
    return phi


def _a_normalize(phi: np.ndarray, areas: np.ndarray) -> np.ndarray:
    return phi / np.sqrt(np.sum(areas * phi**2))
