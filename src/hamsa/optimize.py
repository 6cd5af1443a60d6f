"""Optimizing the potential for a task by eigenvector perturbation (paper section 3).

Task: represent data X (n, d) in the first k eigenvectors of ``H(V) = W + A diag(V)``:

    L(V) = || Psi_k Psi_k^T A X - X ||_A^2 = ||X||_A^2 - || Psi_k^T A X ||_F^2        (paper eq. PCA_H)

(``mass_weighted=False`` is the paper's Euclidean setting: A = I in the operator and the norm.)

Gradient. With ``dH = A diag(dV)`` and first-order eigenvector perturbation ``dpsi_b = sum_{a != b} psi_a
(psi_a^T dH psi_b) / (E_b - E_a)``, the pairs a, b <= k cancel and

    dL/dV_j = -2 a_j sum_{b <= k} sum_{a > k} G_ab psi_a(j) psi_b(j) / (E_b - E_a),   G = Psi^T A X X^T A Psi.

The paper's closed form ``diag(-2 Psi((Z Psi_k^T X X^T Psi) o B) Psi^T)`` has the wrong sign: the trace
identity it uses needs B^T, and B is antisymmetric (``tests/test_optimize.py`` checks ours against
finite differences). ``1 / (E_b - E_a)`` is stabilized as the paper suggests,
``1 / ((|E_b - E_a| + eps) sgn(E_b - E_a))`` with sgn(0) = +1.

Cost. The sum over a > k needs all eigenvectors (O(n^3)). As the paper hints, we work in the span of
the first m LBO eigenvectors Phi_m (k < m << n): ``H_m = Lambda_m + Phi_m^T A diag(V) Phi_m`` is an
(m, m) matrix whose eigenvectors U give ``Psi ~ Phi_m U``, and L and its gradient are those of this
reduced problem, exactly (a Rayleigh-Ritz projection of H). One iteration costs O(n m^2) with no
sparse solve; m = n reproduces the full problem. The truncation error of the gradient shrinks as m
grows (``tests/test_optimize.py`` measures it).
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.optimize as sopt
import scipy.sparse as sp

from hamsa.eigen import Eigenbasis, HamiltonianEigensolver, generalized_eigsh
from hamsa.errors import HamsaError
from hamsa.mesh import as_trimesh
from hamsa.operators import hamiltonian

PARAMETRIZATIONS = ("signed", "square")


@dataclass(frozen=True)
class OptimizationResult:
    """The optimized potential and what it took.

    Attributes
    ----------
    potential : (n,) the optimized V
    loss : float, the representation loss with V (full operator, not the reduced one)
    lbo_loss : float, the same loss with V = 0 (the Laplace-Beltrami basis)
    basis : Eigenbasis of the optimized Hamiltonian (k eigenpairs), or None for raw operators
    history : list of dicts (iteration, loss, gradient_norm, seconds), for the reduced problem
    mean : (d,) or scalar column means removed from X first (``center=True``), else None; both losses
        are then those of ``X - mean``, and X is represented as ``mean + Psi Psi^T A (X - mean)``
    """

    potential: np.ndarray
    loss: float
    lbo_loss: float
    basis: Eigenbasis | None
    history: list = field(default_factory=list)
    mean: np.ndarray | None = None

    @property
    def ratio(self) -> float:
        """lbo_loss / loss: how many times smaller the error got."""
        return self.lbo_loss / self.loss if self.loss > 0 else float("inf")


class ReducedRepresentationProblem:
    """Loss and gradient of the representation task in the span of m LBO eigenvectors.

    Parameters
    ----------
    lbo_values : (m,) LBO eigenvalues, or the (m, m) projected stiffness ``Phi^T W Phi`` when the
        columns of lbo_vectors are only approximate eigenvectors (any A-orthonormal basis works)
    lbo_vectors : (n, m) A-orthonormal basis, normally LBO eigenvectors (orthonormal when ``mass`` is all ones)
    mass : (n,) lumped vertex masses a_j (ones for the Euclidean setting)
    X : (n,) or (n, d) data
    k : number of eigenvectors representing X
    epsilon : stabilization of 1/(E_b - E_a), relative to the largest |E|
    """

    def __init__(self, lbo_values, lbo_vectors, mass, X, k: int, epsilon: float = 1e-8):
        values = np.asarray(lbo_values, dtype=np.float64)
        self.stiffness = np.diag(values) if values.ndim == 1 else (values + values.T) / 2
        self.phi = np.asarray(lbo_vectors, dtype=np.float64)
        self.mass = np.asarray(mass, dtype=np.float64)
        X = np.asarray(X, dtype=np.float64)
        self.X = X[:, None] if X.ndim == 1 else X
        n, m = self.phi.shape
        if self.X.shape[0] != n:
            raise HamsaError(f"X has {self.X.shape[0]} rows, the mesh has {n} vertices")
        if not 1 <= k < m:
            raise HamsaError(f"k = {k} must be between 1 and m - 1 = {m - 1} (m = number of LBO eigenvectors)")
        self.k = k
        self.epsilon = epsilon
        self.total = float(np.sum(self.mass[:, None] * self.X**2))  # ||X||_A^2
        self.coefficients = self.phi.T @ (self.mass[:, None] * self.X)  # (m, d) = Phi^T A X

    def reduced_operator(self, V: np.ndarray) -> np.ndarray:
        """``Lambda_m + Phi_m^T A diag(V) Phi_m`` (m, m)."""
        H = self.phi.T @ (self.phi * (self.mass * V)[:, None])
        return (H + H.T) / 2 + self.stiffness

    def eigen(self, V: np.ndarray):
        """(E (m,), U (m, m)) of the reduced operator."""
        return np.linalg.eigh(self.reduced_operator(V))  # divide and conquer: faster than MRRR here

    def loss(self, V: np.ndarray) -> float:
        _, U = self.eigen(V)
        return self._loss(U)

    def _loss(self, U: np.ndarray) -> float:
        projected = U[:, : self.k].T @ self.coefficients
        return self.total - float(np.sum(projected**2))

    def loss_and_gradient(self, V: np.ndarray) -> tuple[float, np.ndarray]:
        E, U = self.eigen(V)
        k = self.k
        c = U.T @ self.coefficients  # (m, d): Psi^T A X in the eigenbasis
        G = c[k:] @ c[:k].T  # (m-k, k): G_ab, a > k, b <= k
        difference = E[None, :k] - E[k:, None]  # E_b - E_a
        scale = self.epsilon * max(np.abs(E).max(), 1.0)
        B = 1.0 / ((np.abs(difference) + scale) * np.where(difference >= 0, 1.0, -1.0))
        M = G * B  # (m-k, k)
        # sum_ab psi_a(j) M_ab psi_b(j) with psi = Phi U, grouped as (Phi (U_>k M)) . (Phi U_<=k): O(n m k)
        left = self.phi @ (U[:, k:] @ M)
        right = self.phi @ U[:, :k]
        gradient = -2.0 * self.mass * np.einsum("jb,jb->j", left, right)
        return self.total - float(np.sum(c[:k] ** 2)), gradient


def representation_loss(basis_vectors: np.ndarray, mass: np.ndarray, X: np.ndarray) -> float:
    """``||Psi Psi^T A X - X||_A^2`` for A-orthonormal columns Psi (n, k) and lumped masses (n,)."""
    X = np.asarray(X, dtype=np.float64)
    X = X[:, None] if X.ndim == 1 else X
    weighted = mass[:, None] * X
    projected = basis_vectors.T @ weighted
    return float(np.sum(weighted * X) - np.sum(projected**2))


def _operators(mesh, operators, mass_weighted: bool):
    """(W, A, lumped masses a) from a mesh, or from explicit ``operators=(W, A)``."""
    if (mesh is None) == (operators is None):
        raise HamsaError("give a mesh (a TriMesh or (vertices, faces)) or operators=(W, A), not both or neither")
    if mesh is not None:
        W, A = hamiltonian(as_trimesh(mesh))
    else:
        try:
            W, A = operators
        except (TypeError, ValueError):
            raise HamsaError("operators must be a (W, A) pair of sparse matrices") from None
        W, A = sp.csr_matrix(W), sp.csr_matrix(A)
        if W.shape != A.shape or W.shape[0] != W.shape[1]:
            raise HamsaError(f"operators must be square and of one size, got W {W.shape} and A {A.shape}")
    if not mass_weighted:
        A = sp.identity(W.shape[0], format="csr")
    a = A.diagonal()
    if abs(A - sp.diags(a)).max() > 0:
        raise HamsaError("potential optimization needs a lumped (diagonal) mass matrix")
    return W, A, a


class _Progress:
    def __init__(self, total: int, enabled: bool):
        self.total, self.enabled, self.start = total, enabled, time.perf_counter()
        self.bar = None
        if enabled:
            try:
                from tqdm import tqdm

                self.bar = tqdm(total=total, desc="optimizing V", unit="it", leave=False)
            except ImportError:
                self.bar = None

    def update(self, iteration: int, loss: float, gradient_norm: float) -> None:
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.update(1)
            self.bar.set_postfix(loss=f"{loss:.3e}", grad=f"{gradient_norm:.1e}")
        else:
            print(
                f"\r  iteration {iteration}/{self.total}  loss {loss:.4e}  |grad| {gradient_norm:.2e}",
                end="",
                file=sys.stderr,
                flush=True,
            )

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
        elif self.enabled:
            print(file=sys.stderr)


def optimize_potential(
    mesh,
    X,
    k: int,
    *,
    operators=None,
    m: int | None = None,
    parametrization: str = "signed",
    mass_weighted: bool = True,
    max_iterations: int = 200,
    rounds: int = 1,
    epsilon: float = 1e-8,
    progress: bool = False,
    center: bool = False,
) -> OptimizationResult:
    """The potential V minimizing ``||Psi_k Psi_k^T A X - X||_A^2`` (paper section 3), by L-BFGS from V = 0.

    Parameters
    ----------
    mesh : TriMesh or (vertices, faces); None with ``operators``
    X : (n,) or (n, d) data; for a mesh, typically its vertex coordinates
    k : number of eigenvectors representing X
    operators : a (W, A) pair of sparse matrices instead of a mesh (e.g. from
        :func:`hamsa.interval.interval_operators`)
    m : LBO eigenvectors spanning the reduced problem (default min(n - 1, max(4 k, k + 100)));
        m >= n - 1 on small problems uses them all (the exact, full problem)
    parametrization : "signed" (V free, the paper's default "for performance") or "square" (V = v^2 >= 0)
    mass_weighted : the geometric (A-weighted) setting; False is the Euclidean one (A = I)
    max_iterations : L-BFGS iterations in all
    rounds : the reduced subspace is recomputed around the current V this many times (each costs one
        sparse eigensolve of m eigenpairs); a round's step is kept only if the loss decreased. One round
        suffices when V stays moderate (the hand); large potentials (e.g. on a combinatorial Laplacian)
        leave the LBO subspace and need several
    epsilon : stabilization of the eigenvalue differences (relative)
    progress : show a progress bar (tqdm when installed) on stderr
    center : first subtract each column's mean (mass-weighted in the geometric setting), kept in
        ``result.mean``. A Hamiltonian basis has no constant function, so raw coordinates make it spend
        eigenvectors on their translation; with ``center`` the result does not depend on where the shape
        sits. Whether the centred optimum represents X better depends on the shape (both ways at the
        defaults, docs/results/optimize.md): off by default, as in the paper

    Returns
    -------
    OptimizationResult with the loss of the full operator at V_opt and at V = 0.

    Raises
    ------
    HamsaError
        On a bad mesh or operators, X with the wrong number of rows or non-finite entries, k >= m, an
        unknown parametrization, or a non-lumped mass.
    """
    if parametrization not in PARAMETRIZATIONS:
        raise HamsaError(f"parametrization must be one of {PARAMETRIZATIONS}, got {parametrization!r}")
    W, A, a = _operators(mesh, operators, mass_weighted)
    n = W.shape[0]
    X = np.asarray(X, dtype=np.float64)
    if X.shape[0] != n or not np.all(np.isfinite(X)):
        raise HamsaError(f"X must be a finite array with {n} rows, got shape {X.shape}")
    mean = (a @ X) / a.sum() if center else None
    if center:
        X = X - mean
    m = min(n, max(4 * k, k + 100)) if m is None else min(int(m), n)
    if not k < m:
        raise HamsaError(f"k = {k} must be smaller than m = {m}")
    # m eigenvectors of H(V) at every re-centering, warm-started from the last ones. A loose tolerance
    # suffices (the stiffness is projected exactly onto whatever basis we get).
    solver = HamiltonianEigensolver(W, A, m, tol=1e-5, method="dense" if m >= n - 1 or n <= 1500 else "auto")

    def subspace(V):
        """The reduced problem around V: accurate near V."""
        vectors = solver.solve(V).vectors
        return ReducedRepresentationProblem(vectors.T @ (W @ vectors), vectors, a, X, k, epsilon)

    square = parametrization == "square"
    x, history, lbo_loss = _minimize(subspace, n, square, max_iterations, rounds, progress)
    V = x**2 if square else x
    if lbo_loss is None:
        lbo_loss = subspace(np.zeros(n)).loss(np.zeros(n))
    values, vectors, _ = generalized_eigsh(W + A @ sp.diags(V), A, k, lower_bound=float(V.min()))
    basis = Eigenbasis(values, vectors, A, V) if mesh is not None and mass_weighted else None
    return OptimizationResult(V, representation_loss(vectors, a, X), lbo_loss, basis, history, mean)


def _minimize(subspace, n: int, square: bool, max_iterations: int, rounds: int, progress: bool):
    """L-BFGS on the reduced problems ``subspace(V)``, re-centred ``rounds`` times, from V = 0 (or v = 1e-3
    when ``square``: V = v^2). Returns (x, history, the loss at V = 0 or None when ``square``)."""
    history: list[dict] = []
    bar = _Progress(max_iterations, progress)
    start = time.perf_counter()
    last = {}
    to_V = (lambda y: y**2) if square else (lambda y: y)

    def objective(x):
        loss, gradient = problem.loss_and_gradient(to_V(x))
        if square:
            gradient = 2 * x * gradient
        last.update(x=x.copy(), loss=loss, gradient=gradient)
        return loss, gradient

    def record(x):
        # L-BFGS calls back with the iterate it last evaluated: reuse that evaluation
        loss, gradient = (last["loss"], last["gradient"]) if np.array_equal(last.get("x"), x) else objective(x)
        history.append(
            {"iteration": len(history), "loss": loss, "gradient_norm": float(np.linalg.norm(gradient)),
             "seconds": time.perf_counter() - start}
        )  # fmt: skip
        bar.update(len(history), loss, history[-1]["gradient_norm"])

    x = np.full(n, 1e-3) if square else np.zeros(n)
    problem = subspace(to_V(x))
    lbo_loss = None if square else problem.loss(np.zeros(n))
    current = problem.loss(to_V(x))
    history.append(
        {"iteration": 0, "loss": current, "gradient_norm": float(np.linalg.norm(objective(x)[1])), "seconds": 0.0}
    )
    per_round = max(1, max_iterations // rounds)
    try:
        for _ in range(rounds):
            result = sopt.minimize(
                objective,
                x,
                jac=True,
                method="L-BFGS-B",
                callback=record,
                options={"maxiter": per_round, "ftol": 1e-14, "gtol": 1e-14, "maxcor": 20},
            )
            # Trust the reduced model only where it is accurate: re-center the subspace at the new V and
            # accept the step only if the loss there (the true one, up to the loose basis) decreased;
            # otherwise halve the step, up to four times.
            step = result.x - x
            for _ in range(5):
                candidate = subspace(to_V(x + step))
                value = candidate.loss(to_V(x + step))
                if value < current:
                    x, problem, current = x + step, candidate, value
                    break
                step = step / 2
            else:
                break
    finally:
        bar.close()
    return x, history, lbo_loss
