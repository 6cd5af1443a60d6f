"""hamsa's eigensolver against the pipeline a user would otherwise run, measured in one run.

The baseline is what pyFM and LaPy do: ``scipy.sparse.linalg.eigsh(H, k, M=A, sigma=-0.01)``
(ARPACK shift-invert; SciPy factors ``H - sigma A`` with SuperLU). When scikit-sparse is installed,
a second baseline hands eigsh a CHOLMOD factorization as ``OPinv``. Every timing is the median of
``--repeat`` runs; the machine is noisy, so read the ratios.

For each mesh and k it prints hamsa's time, each baseline's time, baseline / hamsa, and the largest
relative eigenvalue difference (relative to max(|E_i|, E_2), so zero modes are compared absolutely).

    python benchmarks/eigensolve.py                      # 10k, 50k, 200k built-in + TOSCA david0, k = 50 100 200
    python benchmarks/eigensolve.py --sizes 50000 --k 100 --no-data
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as spla

import hamsa
from hamsa import shapes
from hamsa.factorization import HAVE_CHOLMOD
from hamsa.operators import hamiltonian

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def bumpy_sphere(n: int) -> hamsa.TriMesh:
    """A sphere with smooth radial bumps: no exact eigenvalue multiplicities (ARPACK misses some)."""
    sphere = shapes.sphere(n)
    x, y, z = sphere.vertices.T
    radius = 1 + 0.15 * np.sin(3 * x + 1) * np.cos(2 * y) + 0.1 * z**3
    return hamsa.TriMesh(sphere.vertices * radius[:, None], sphere.faces)


def median_time(function, repeat: int):
    times, result = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def eigsh_superlu(H, A, k):
    return np.sort(spla.eigsh(H, k, M=A, sigma=-0.01)[0])


def eigsh_cholmod(H, A, k):
    from sksparse.cholmod import cholesky

    factor = cholesky((H + 0.01 * A).tocsc())
    operator = spla.LinearOperator(H.shape, matvec=factor, dtype=np.float64)
    return np.sort(spla.eigsh(H, k, M=A, sigma=-0.01, OPinv=operator)[0])


def relative_difference(values, reference):
    scale = np.maximum(np.abs(reference), abs(reference[1]))
    return float(np.max(np.abs(values - reference) / scale))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 50_000, 200_000])
    parser.add_argument("--k", type=int, nargs="+", default=[50, 100, 200])
    parser.add_argument("--repeat", type=int, default=1, help="runs per timing (median)")
    parser.add_argument("--no-data", action="store_true", help="skip TOSCA david0 even if ../shared/data exists")
    parser.add_argument("--no-cholmod-baseline", action="store_true")
    args = parser.parse_args(argv)

    meshes = [(f"bumpy sphere {n // 1000}k", lambda n=n: bumpy_sphere(n)) for n in args.sizes]
    david = DATA / "tosca_hires" / "meshes" / "david0.off.gz"
    if not args.no_data and david.exists():
        meshes.append(("TOSCA david0", lambda: hamsa.load_mesh(david)))
    with_cholmod = HAVE_CHOLMOD and not args.no_cholmod_baseline
    print(
        f"hamsa {hamsa.__version__}; hamsa backend: {'CHOLMOD' if HAVE_CHOLMOD else 'SuperLU'}; "
        f"median of {args.repeat} run(s)"
    )
    header = f"{'mesh':<18} {'n':>8} {'k':>4} {'hamsa s':>8} {'eigsh+SuperLU s':>16} {'ratio':>6}"
    if with_cholmod:
        header += f" {'eigsh+CHOLMOD s':>16} {'ratio':>6}"
    header += f" {'max rel diff':>12}"
    print(header)
    for name, build in meshes:
        mesh = build()
        H, A = hamiltonian(mesh)
        for k in args.k:
            t_hamsa, basis = median_time(lambda: hamsa.eigenbasis(mesh, k, method="krylov"), args.repeat)
            t_superlu, reference = median_time(lambda: eigsh_superlu(H, A, k), args.repeat)
            row = (
                f"{name:<18} {mesh.n_vertices:>8} {k:>4} {t_hamsa:>8.2f} {t_superlu:>16.2f} {t_superlu / t_hamsa:>6.2f}"
            )
            if with_cholmod:
                t_cholmod, _ = median_time(lambda: eigsh_cholmod(H, A, k), args.repeat)
                row += f" {t_cholmod:>16.2f} {t_cholmod / t_hamsa:>6.2f}"
            row += f" {relative_difference(basis.values, reference):>12.1e}"
            print(row, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
