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

Smoothing. L jumps wherever E_k and E_{k+1} cross (the projector onto the first k eigenvectors changes
which vectors it holds), and near such a crossing the gradient's ``1 / (E_b - E_a)`` is huge: L-BFGS stalls
there, in whichever local minimum the rounding led it to. ``optimize_potential`` therefore first minimizes
a smoothed loss, the soft top-k

    L_w(V) = ||X||_A^2 - sum_b s_w(E_b) || psi_b^T A X ||^2,   s_w(E) = 1 / (1 + exp((E - mu) / w)),

with mu chosen so that sum_b s_w(E_b) = k (the weights stay a budget of k vectors however the spectrum
clusters), for decreasing widths w, and ends on the paper's loss itself (w = 0). Its gradient is the
Daleckii-Krein formula: ``dL_w/dV_j = -a_j sum_ab psi_a(j) psi_b(j) (c_a . c_b) D_ab - (dL_w/dmu)(dmu/dV_j)``
with ``c_b = psi_b^T A X``, ``D_ab = (s_a - s_b) / (E_a - E_b)`` (``s'(E_a)`` on the diagonal), bounded
through every crossing; for w -> 0 it becomes the hard gradient above.
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
    history : list of dicts (iteration, loss, gradient_norm, width, seconds) for the reduced problem;
        ``loss`` is that of the stage's smoothing width (0: the paper's loss)
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
    width : 0 for the paper's loss; > 0 for the soft top-k loss of that width (eigenvalue units, module
        docstring), which ``loss`` and ``loss_and_gradient`` then return
    """

    def __init__(self, lbo_values, lbo_vectors, mass, X, k: int, epsilon: float = 1e-8, width: float = 0.0):
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
        self.width = float(width)
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
        E, U = self.eigen(V)
        strength = (U.T @ self.coefficients) ** 2
        if self.width > 0:
            return self.total - float(self._soft_weights(E)[0] @ strength.sum(axis=1))
        return self.total - float(np.sum(strength[: self.k]))

    def loss_and_gradient(self, V: np.ndarray) -> tuple[float, np.ndarray]:
        E, U = self.eigen(V)
        if self.width > 0:
            return self._soft_loss_and_gradient(E, U)
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

    def _soft_weights(self, E: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(s_w(E) (m,), s_w'(E) (m,)) with mu such that the weights sum to k."""
        w, k = self.width, self.k

        def weights(mu):
            return 0.5 * (1.0 - np.tanh((E - mu) / (2 * w)))  # the logistic 1 / (1 + exp((E - mu) / w))

        mu = sopt.brentq(lambda mu: weights(mu).sum() - k, E[0] - 60 * w, E[-1] + 60 * w, xtol=1e-12 * w)
        s = weights(mu)
        return s, -s * (1.0 - s) / w

    def _soft_loss_and_gradient(self, E: np.ndarray, U: np.ndarray) -> tuple[float, np.ndarray]:
        s, slope = self._soft_weights(E)
        c = U.T @ self.coefficients
        strength = np.sum(c**2, axis=1)
        difference = E[:, None] - E[None, :]
        close = np.abs(difference) < 1e-8 * self.width
        D = np.where(
            close, (slope[:, None] + slope[None, :]) / 2, (s[:, None] - s[None, :]) / np.where(close, 1.0, difference)
        )
        psi = self.phi @ U  # (n, m): O(n m^2), the order of reduced_operator
        at_fixed_mu = self.mass * np.einsum("ja,ja->j", psi @ ((c @ c.T) * D), psi)
        # mu keeps sum_b s_b = k: dmu = sum_b s'_b dE_b / sum_b s'_b, dE_b/dV_j = a_j psi_b(j)^2
        dmu = self.mass * ((psi**2) @ slope) / slope.sum()
        gradient = -(at_fixed_mu - float(slope @ strength) * dmu)
        return self.total - float(s @ strength), gradient


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
        W, A = hamiltonian(mesh)
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
    max_iterations: int = 150,
    rounds: int = 3,
    smoothing: tuple[float, ...] = (3.0, 1.0),
    epsilon: float = 1e-8,
    progress: bool = False,
    center: bool = False,
) -> OptimizationResult:
    """The potential V minimizing ``||Psi_k Psi_k^T A X - X||_A^2`` (paper section 3), by L-BFGS from V = 0.

    The minimization runs in stages: the soft top-k loss for each width in ``smoothing`` (module
    docstring), then the paper's loss, starting each stage where the last ended. The smoothed stages carry
    L-BFGS past the eigenvalue crossings where it otherwise stalls; the result is always judged by the
    paper's loss. ``smoothing=(), rounds=1, max_iterations=200`` is plain L-BFGS on the paper's loss, as
    in the paper: about 2.5x faster, and it stops higher on surfaces (docs/results/optimize.md compares both).

    Parameters
    ----------
    mesh : TriMesh, (vertices, faces) or PointCloud; None with ``operators``
    X : (n,) or (n, d) data; for a mesh, typically its vertex coordinates
    k : number of eigenvectors representing X
    operators : a (W, A) pair of sparse matrices instead of a mesh (e.g. from
        :func:`hamsa.interval.interval_operators`)
    m : LBO eigenvectors spanning the reduced problem (default min(n - 1, max(4 k, k + 100)));
        m >= n - 1 on small problems uses them all (the exact, full problem)
    parametrization : "signed" (V free, the paper's default "for performance") or "square" (V = v^2 >= 0)
    mass_weighted : the geometric (A-weighted) setting; False is the Euclidean one (A = I)
    max_iterations : L-BFGS iterations in all, shared equally by the rounds of every stage
    rounds : per stage, the reduced subspace is recomputed around the current V this many times (each
        costs one sparse eigensolve of m eigenpairs); a round's step is kept only if the stage's loss
        decreased there, and a stage ends at its first round without progress. Large potentials (e.g. on
        a combinatorial Laplacian) leave the LBO subspace and need several
    smoothing : widths of the smoothed stages, in units of the mean eigenvalue spacing around E_k at the
        start, largest first; () minimizes the paper's loss only
    epsilon : stabilization of the eigenvalue differences (relative)
    progress : show a progress bar (tqdm when installed) on stderr
    center : first subtract each column's mean (mass-weighted in the geometric setting), kept in
        ``result.mean``. A Hamiltonian basis has no constant function, so raw coordinates make it spend
        eigenvectors on their translation; with ``center`` the result does not depend on where the shape
        sits. With the default optimizer raw and centred coordinates end close to each other
        (docs/results/optimize.md): off by default, as in the paper

    Returns
    -------
    OptimizationResult with the loss of the full operator at V_opt and at V = 0.

    Raises
    ------
    HamsaError
        On a bad mesh or operators, X with the wrong number of rows or non-finite entries, k >= m, an
        unknown parametrization, a non-lumped mass, rounds or max_iterations below 1, or a smoothing
        width that is not a finite positive number.
    """
    if parametrization not in PARAMETRIZATIONS:
        raise HamsaError(f"parametrization must be one of {PARAMETRIZATIONS}, got {parametrization!r}")
    smoothing = tuple(float(width) for width in smoothing)
    if not all(np.isfinite(width) and width > 0 for width in smoothing):
        raise HamsaError(f"smoothing widths must be finite and positive, got {smoothing}")
    if rounds < 1 or max_iterations < 1:
        raise HamsaError(f"rounds and max_iterations must be at least 1, got {rounds} and {max_iterations}")
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
    x, history, lbo_loss = _minimize(subspace, n, square, max_iterations, rounds, smoothing, progress)
    V = x**2 if square else x
    if lbo_loss is None:
        lbo_loss = subspace(np.zeros(n)).loss(np.zeros(n))
    values, vectors, _ = generalized_eigsh(W + A @ sp.diags(V), A, k, lower_bound=float(V.min()))
    basis = Eigenbasis(values, vectors, A, V) if mesh is not None and mass_weighted else None
    return OptimizationResult(V, representation_loss(vectors, a, X), lbo_loss, basis, history, mean)


def _minimize(subspace, n: int, square: bool, max_iterations: int, rounds: int, smoothing, progress: bool):
    """L-BFGS on the reduced problems ``subspace(V)`` from V = 0 (or v = 1e-3 when ``square``: V = v^2):
    one stage per smoothing width (in mean eigenvalue spacings at the k-th eigenvalue of the start), then
    the paper's loss, each stage re-centred ``rounds`` times. Returns (x, history, the loss at V = 0 or
    None when ``square``)."""
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
             "width": problem.width, "seconds": time.perf_counter() - start}
        )  # fmt: skip
        bar.update(len(history), loss, history[-1]["gradient_norm"])

    x = np.full(n, 1e-3) if square else np.zeros(n)
    problem = subspace(to_V(x))
    lbo_loss = None if square else problem.loss(np.zeros(n))
    history.append(
        {"iteration": 0, "loss": problem.loss(to_V(x)), "gradient_norm": float(np.linalg.norm(objective(x)[1])),
         "width": 0.0, "seconds": 0.0}
    )  # fmt: skip
    widths = [factor * _spacing_at_k(problem, to_V(x)) for factor in smoothing] + [0.0]
    # max_iterations shared by the rounds of all stages, the remainder going to the last ones (the paper's
    # loss); with fewer iterations than rounds the first rounds get none
    count = rounds * len(widths)
    shares = np.full(count, max_iterations // count)
    shares[count - max_iterations % count :] += 1
    budgets = iter(shares.tolist())
    try:
        for width in widths:
            stage = [next(budgets) for _ in range(rounds)]
            if not any(stage):
                continue
            before = (x, problem, problem.loss(to_V(x)))  # the paper's loss: problem.width is 0 here
            problem.width = width
            current = problem.loss(to_V(x))
            for budget in filter(None, stage):
                result = sopt.minimize(
                    objective,
                    x,
                    jac=True,
                    method="L-BFGS-B",
                    callback=record,
                    options={"maxiter": budget, "ftol": 1e-14, "gtol": 1e-14, "maxcor": 20},
                )
                # Trust the reduced model only where it is accurate: re-center the subspace at the new V and
                # accept the step only if this stage's loss there (the true one, up to the loose basis)
                # decreased; otherwise halve the step, up to four times, and else end the stage.
                step = result.x - x
                for _ in range(5):
                    candidate = subspace(to_V(x + step))
                    candidate.width = width
                    value = candidate.loss(to_V(x + step))
                    if value < current:
                        x, problem, current = x + step, candidate, value
                        break
                    step = step / 2
                else:
                    break
            problem.width = 0.0
            if problem.loss(to_V(x)) >= before[2]:  # a smoothed stage is kept only if the paper's loss fell
                x, problem, _ = before
                problem.width = 0.0
    finally:
        bar.close()
    return x, history, lbo_loss


def _spacing_at_k(problem: ReducedRepresentationProblem, V: np.ndarray) -> float:
    """Mean gap of the reduced eigenvalues from the (k - 5)-th to the (k + 5)-th: the smoothing unit."""
    E = problem.eigen(V)[0]
    low, high = max(0, problem.k - 6), min(len(E) - 1, problem.k + 4)
    spacing = (E[high] - E[low]) / (high - low)
    return float(spacing) if spacing > 0 else 1e-3 * max(float(np.abs(E).max()), 1.0)
