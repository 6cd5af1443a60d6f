"""Cost of optimizing the potential, in units of one eigensolve, measured in one run.

The whole hand optimization of paper section 3 (hand_6k, X = vertex coordinates, k = 50, m = 300 LBO
eigenvectors, 60 L-BFGS iterations: the settings of hamsa.paper.experiments.fig7_optimize_hand) divided by the
time of one k = 50 eigensolve of the same mesh (median of 5), for the plain L-BFGS of the paper and for the
smoothed default (hamsa.optimize). Without ../shared/data, a built-in
capsule of similar size stands in.

    python benchmarks/optimize.py
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

import hamsa
from hamsa import shapes
from hamsa.optimize import optimize_potential

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def main() -> int:
    path = DATA / "classic" / "hand_6k.off"
    mesh = hamsa.load_mesh(path) if path.exists() else shapes.capsule(0.5, 2.0, 64)
    mesh = hamsa.TriMesh((mesh.vertices - mesh.vertices.mean(axis=0)) / np.sqrt(mesh.area), mesh.faces)
    name = "hand_6k" if path.exists() else "built-in capsule"
    solves = []
    for _ in range(5):
        start = time.perf_counter()
        hamsa.eigenbasis(mesh, 50)
        solves.append(time.perf_counter() - start)
    one = statistics.median(solves)
    print(f"{name}: n = {mesh.n_vertices}, k = 50, m = 300, 60 L-BFGS iterations")
    print(f"one k = 50 eigensolve (median of 5): {one:.3f} s")
    for label, optimizer in (("plain", {"smoothing": (), "rounds": 1}), ("smoothed (default)", {})):
        start = time.perf_counter()
        result = optimize_potential(mesh, mesh.vertices, 50, m=300, max_iterations=60, **optimizer)
        whole = time.perf_counter() - start
        print(
            f"{label:>18}: whole optimization {whole:.2f} s = {whole / one:.1f} eigensolves (bar: <= 30), "
            f"error LBO {result.lbo_loss:.3g} -> {result.loss:.3g} ({result.ratio:.2f}x smaller)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
