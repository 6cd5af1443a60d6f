"""Cost of optimizing the potential, in units of one eigensolve, measured in one run.

The whole hand optimization of paper section 3 (hand_6k, X = vertex coordinates, k = 50, m = 300 LBO
eigenvectors, 60 L-BFGS iterations: the settings of hamsa.paper.experiments.fig7_optimize_hand) divided by the
time of one k = 50 eigensolve of the same mesh (median of 5). Without ../shared/data, a built-in
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
    start = time.perf_counter()
    result = optimize_potential(mesh, mesh.vertices, 50, m=300, max_iterations=60)
    whole = time.perf_counter() - start
    print(f"{name}: n = {mesh.n_vertices}, k = 50, m = 300, {len(result.history) - 1} L-BFGS iterations")
    print(f"one k = 50 eigensolve (median of 5): {one:.3f} s")
    print(f"whole optimization:                  {whole:.2f} s")
    print(f"ratio whole / one eigensolve:        {whole / one:.1f}   (bar: <= 30)")
    print(f"error LBO {result.lbo_loss:.3g} -> optimized Hamiltonian {result.loss:.3g} ({result.ratio:.2f}x smaller)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
