"""Numerical checks of the paper's theorems on a built-in shape (claims T1–T5, T8, T13, T15 of the report).

On a unit-area capsule with a random nonnegative potential V:
T1  Theorem 1, lambda_i + min V <= E_i <= lambda_i + max V (largest violation, relative);
T2  the mu rule: first-order error of E_i(mu) quadratic in mu, and E_i > mu max V at half the bound;
T3  Theorem 2, ||f - Psi_n Psi_n^T A f||_A^2 <= f^T H f / E_{n+1} (largest ratio over random f);
T4  the same bound fails for a random orthonormal basis (it is what makes the eigenbasis optimal);
T5  the potential does not change the sparsity, and the eigensolve costs about the same as the LBO's;
T8  the representation loss gradient by eigenvector perturbation vs central finite differences;
T13 the first-order eigenvector perturbation: its error shrinks like eps^2;
T15 Psi^T A Psi = I, E ascending, E_1 > 0 for V >= 0, V != 0.
Writes claims_checks.json.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import scipy.linalg

import hamsa
from hamsa import shapes
from hamsa.operators import hamiltonian, stiffness_matrix
from hamsa.optimize import ReducedRepresentationProblem
from hamsa.paper.results import BasisChecks, MuRule, SparsityAndCost, TheoremChecks
from hamsa.theory import critical_potential_scale, eigenvalue_bounds, first_order_eigenvector

from ._common import Timer, parse_args, write_json


def _theorem1(mesh, V, k):
    lbo = hamsa.eigenbasis(mesh, k)
    basis = hamsa.eigenbasis(mesh, k, V)
    lower, upper = eigenvalue_bounds(lbo.values, V)
    violation = np.maximum(lower - basis.values, basis.values - upper).max() / np.abs(basis.values).max()
    return lbo, basis, float(violation)


def _mu_rule(mesh, lbo, V, index=3):
    phi = lbo.vectors[:, index]
    expectation = phi @ (lbo.mass @ (V * phi))
    errors = []
    for mu in (0.4, 0.2, 0.1):
        E = hamsa.eigenbasis(mesh, index + 3, mu * V).values[index]
        errors.append(abs(E - (lbo.values[index] + mu * expectation)))
    mu = 0.5 * critical_potential_scale(lbo, V, index)
    E_half = hamsa.eigenbasis(mesh, index + 3, mu * V).values[index]
    return MuRule(
        error_ratios_halving_mu=[float(errors[0] / errors[1]), float(errors[1] / errors[2])],
        E_at_half_bound_over_mu_maxV=float(E_half / (mu * V.max())),
    )


def _residual_bound(mesh, V, basis, rng):
    H, A = hamiltonian(mesh, V)
    worst = 0.0
    for n in (5, 10, 20):
        part = basis.truncate(n)
        for _ in range(5):
            f = rng.standard_normal(mesh.n_vertices)
            error = f - part.reconstruct(part.project(f))
            worst = max(worst, (error @ A @ error) / ((f @ H @ f) / basis.values[n]))
    # a random A-orthonormal basis of the same size violates the bound for smooth f
    n = 10
    Q = scipy.linalg.qr(rng.standard_normal((mesh.n_vertices, n)), mode="economic")[0]
    Q = Q / np.sqrt(A.diagonal())[:, None]  # A-orthonormal for the lumped (diagonal) mass
    random_ratios = []
    for f in basis.vectors[:, :n].T:
        error = f - Q @ (Q.T @ (A @ f))
        random_ratios.append((error @ A @ error) / ((f @ H @ f) / basis.values[n]))
    return float(worst), float(max(random_ratios))


def _sparsity_and_cost(mesh, V, k):
    """nnz of H and W, and the eigensolve cost H / LBO: sparse solves (deterministic) and median time."""
    H, _ = hamiltonian(mesh, V)
    W = stiffness_matrix(mesh)
    times, solves = {}, {}
    for name, potential in (("lbo", None), ("hamiltonian", V)):
        samples = []
        for _ in range(3):
            start = time.perf_counter()
            basis = hamsa.eigenbasis(mesh, k, potential, method="krylov")
            samples.append(time.perf_counter() - start)
        times[name], solves[name] = float(np.median(samples)), basis.info.solves
    return SparsityAndCost(
        nnz_W=int(W.nnz),
        nnz_H=int(H.nnz),
        solves_ratio_hamiltonian_over_lbo=solves["hamiltonian"] / solves["lbo"],
        time_ratio_hamiltonian_over_lbo=times["hamiltonian"] / times["lbo"],
    )


def _gradient_check(mesh, rng, k=10, m=60):
    lbo = hamsa.eigenbasis(mesh, m)
    problem = ReducedRepresentationProblem(lbo.values, lbo.vectors, lbo.mass.diagonal(), mesh.vertices, k)
    V = rng.random(mesh.n_vertices) * lbo.values[k]
    direction = rng.standard_normal(mesh.n_vertices)
    _, gradient = problem.loss_and_gradient(V)
    step = 1e-4 * lbo.values[k] / np.abs(direction).max()
    difference = (problem.loss(V + step * direction) - problem.loss(V - step * direction)) / (2 * step)
    analytic = gradient @ direction
    return float(abs(analytic - difference) / abs(difference))


def _perturbation_order(mesh, V, rng, index=2):
    H, A = (M.toarray() for M in hamiltonian(mesh, V))
    values, vectors = scipy.linalg.eigh(H, A)
    noise = rng.standard_normal(mesh.vertices.shape) * 0.1 * np.sqrt(mesh.area / mesh.n_faces)
    errors = {}
    for eps in (1.0, 0.5, 0.25):
        moved = hamsa.TriMesh(mesh.vertices + eps * noise, mesh.faces)
        H2, A2 = (M.toarray() for M in hamiltonian(moved, V))
        exact = scipy.linalg.eigh(H2, A2)[1][:, index]
        exact *= np.sign(exact @ A @ vectors[:, index])
        predicted = first_order_eigenvector(values, vectors, H2 - H, A2 - A, index)
        difference = predicted - exact
        errors[eps] = float(np.sqrt(difference @ A2 @ difference))
    return [errors[1.0] / errors[0.5], errors[0.5] / errors[0.25]]


def run(args) -> TheoremChecks:
    timer = Timer()
    rng = np.random.default_rng(0)
    n_around = 24 if args.quick else 40
    mesh = shapes.capsule(0.5, 2.0, n_around).scaled_to_unit_area()
    k = 21
    V = rng.random(mesh.n_vertices) * 50
    lbo, basis, violation = _theorem1(mesh, V, k)
    residual_ratio, random_ratio = _residual_bound(mesh, V, basis, rng)
    small = shapes.capsule(0.5, 2.0, 12).scaled_to_unit_area()
    V_small = rng.random(small.n_vertices) * 50
    gram = basis.vectors.T @ basis.mass @ basis.vectors
    numbers = TheoremChecks(
        mesh=f"built-in capsule ({mesh.n_vertices} vertices, unit area)",
        T1_max_relative_violation=violation,
        T2=_mu_rule(mesh, lbo, np.exp(-((mesh.vertices[:, 2] - 0.3) ** 2) / 0.05)),
        T3_max_ratio_lhs_over_bound=residual_ratio,
        T4_random_basis_max_ratio=random_ratio,
        T5=_sparsity_and_cost(mesh, V, 50),
        T8_gradient_relative_error=_gradient_check(small, rng),
        T13_error_ratios_halving_eps=_perturbation_order(small, V_small, rng),
        T15=BasisChecks(
            orthonormality_error=float(np.abs(gram - np.eye(k)).max()),
            ascending=bool(np.all(np.diff(basis.values) >= 0)),
            E1=float(basis.values[0]),
        ),
        seconds=timer(),
    )
    write_json(Path(args.output) / "claims_checks.json", numbers)
    return numbers


if __name__ == "__main__":
    r = run(parse_args(__doc__))
    print(
        f"claims: T1 violation {r.T1_max_relative_violation:.1e}, T3 ratio {r.T3_max_ratio_lhs_over_bound:.3f}, "
        f"T8 gradient error {r.T8_gradient_relative_error:.1e}, T13 ratios {r.T13_error_ratios_halving_eps} "
        f"({r.seconds} s)"
    )
