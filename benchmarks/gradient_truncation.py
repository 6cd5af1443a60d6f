"""How the reduced potential-optimization gradient converges to the full one as m grows (paper section 3).

On a capsule of ~1500 vertices (small enough for the full, all-eigenvector gradient), X = the vertex
coordinates, k = 20, at a random positive potential and at V = 0, it prints the relative error
||grad_m - grad_full|| / ||grad_full|| of the reduced gradient in the span of m LBO eigenvectors, and
the relative error of the reduced loss. Not a speed benchmark: an accuracy measurement.
"""

from __future__ import annotations

import sys

import numpy as np

from hamsa import shapes
from hamsa.eigen import generalized_eigsh
from hamsa.operators import hamiltonian
from hamsa.optimize import ReducedRepresentationProblem


def main() -> int:
    mesh = shapes.capsule(radius=0.5, length=2.0, n_around=32)
    W, A = hamiltonian(mesh)
    n, k = mesh.n_vertices, 20
    values, vectors, _ = generalized_eigsh(W, A, n, method="dense")
    print(f"capsule, n = {n}, k = {k}; relative errors of the reduced problem against the full one (m = n)")
    for label, V in (
        ("V = 0", np.zeros(n)),
        ("random V in [0, 2 lambda_k]", np.random.default_rng(0).random(n) * 2 * values[k]),
    ):
        full = ReducedRepresentationProblem(values, vectors, A.diagonal(), mesh.vertices, k)
        loss_full, grad_full = full.loss_and_gradient(V)
        print(f"  {label}")
        print(f"  {'m':>6} {'gradient error':>15} {'loss error':>11}")
        for m in (30, 40, 60, 100, 200, 400, 800):
            reduced = ReducedRepresentationProblem(values[:m], vectors[:, :m], A.diagonal(), mesh.vertices, k)
            loss, grad = reduced.loss_and_gradient(V)
            print(
                f"  {m:>6} {np.linalg.norm(grad - grad_full) / np.linalg.norm(grad_full):>15.2e} "
                f"{abs(loss - loss_full) / loss_full:>11.2e}"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
