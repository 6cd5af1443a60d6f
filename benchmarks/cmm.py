"""Compressed manifold modes: Neumann et al.'s ADMM vs the Hamiltonian IRLS, measured in one run.

Both minimize the same area-weighted objective tr(Phi^T W Phi) + mu sum a |Phi| with Phi^T A Phi = I
and stop on the same relative change of the objective (1e-6). Mesh: the 14k-vertex hand of
../shared/data/classic (or the 6k one, or a built-in capsule of ~10k vertices without the data), scaled
to unit area; k = 20, mu = 100. Prints both times (median of --repeat), the ratio admm / hamiltonian,
both objectives and their ratio. Bar (issue 5): ratio >= 3 with the Hamiltonian objective at most 5% above.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import hamsa
from hamsa import shapes
from hamsa.cmm import compressed_modes

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "classic"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-k", type=int, default=20)
    parser.add_argument("--mu", type=float, default=100.0)
    parser.add_argument("--repeat", type=int, default=1)
    args = parser.parse_args(argv)
    path = next((p for p in (DATA / "hand_14k.off", DATA / "hand_6k.off") if p.exists()), None)
    mesh = hamsa.load_mesh(path) if path else shapes.capsule(0.5, 3.0, 100)
    mesh = hamsa.TriMesh((mesh.vertices - mesh.vertices.mean(axis=0)) / np.sqrt(mesh.area), mesh.faces)
    print(
        f"{path.name if path else 'built-in capsule'}: n = {mesh.n_vertices}, k = {args.k}, mu = {args.mu:g}, "
        "area-weighted L1, stop at 1e-6 relative change of the objective"
    )
    results = {}
    for method in ("hamiltonian", "admm"):
        times = []
        for _ in range(args.repeat):
            start = time.perf_counter()
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                result = compressed_modes(mesh, args.k, args.mu, method=method)
            times.append(time.perf_counter() - start)
        results[method] = (statistics.median(times), result, len(caught))
        print(
            f"{method:<12} {statistics.median(times):8.2f} s   objective {result.objective:.6g}   "
            f"max|Phi^T A Phi - I| {result.orthogonality_error:.1e}   iterations {sum(result.iterations)}"
            + (f"   ({len(caught)} iteration-cap warnings)" if caught else "")
        )
    (t_h, r_h, _), (t_a, r_a, _) = results["hamiltonian"], results["admm"]
    print(f"time admm / hamiltonian: {t_a / t_h:.2f}   (bar >= 3)")
    print(f"objective hamiltonian / admm: {r_h.objective / r_a.objective:.4f}   (bar <= 1.05)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
