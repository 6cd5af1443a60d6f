"""hamsa's eigensolver against the pipeline a user would otherwise run, measured in one run.

The baseline is what pyFM and LaPy do: ``scipy.sparse.linalg.eigsh(H, k, M=A, sigma=-0.01)``
(ARPACK shift-invert; SciPy factors ``H - sigma A`` with SuperLU). When scikit-sparse is installed,
a second baseline hands eigsh a CHOLMOD factorization as ``OPinv``. Each baseline runs twice: with its
BLAS pinned to one thread (threadpoolctl) and with the libraries' default threads. Every timing is the
median of ``--repeat`` runs of wall time, with the CPU time (all threads) of the same runs beside it;
the machine is noisy, so read the ratios, measured in one run.

For each mesh and k it prints hamsa's wall and CPU seconds (default threads), each baseline's wall and
CPU seconds at 1 thread and at the default threads, baseline / hamsa in wall time (against the default
threads: the bar of the eigensolver issue), and the largest relative eigenvalue difference (relative to
max(|E_i|, E_2), so zero modes are compared absolutely).

``--warm`` adds the warm-start case: a potential V, then V changed by 5% (multiplicative noise);
cold = a fresh solve of the changed problem, warm = :class:`hamsa.eigen.HamiltonianEigensolver`'s second
solve (previous eigenvectors as the start, symbolic factorization reused); prints cold / warm.
``--gpu`` times the CuPy Chebyshev solver (``device="cuda"``) instead of the CPU one, with its warm start
(the whole previous Ritz block); ``--method chebyshev`` runs that solver on the CPU (slower than Krylov
there, but it shows the same warm-start ratio without a GPU).
``--no-baselines`` skips eigsh (for the 1M-vertex run); peak memory is printed at the end.

    python benchmarks/eigensolve.py                      # 10k, 50k, 200k built-in + TOSCA david0, k = 50 100 200
    python benchmarks/eigensolve.py --sizes 50000 --k 100 --no-data --warm
    python benchmarks/eigensolve.py --sizes 50000 200000 --k 100 --gpu --warm   # on a machine with CUDA
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as spla
from threadpoolctl import threadpool_limits

import hamsa
from hamsa import shapes
from hamsa.eigen import HamiltonianEigensolver
from hamsa.factorization import HAVE_CHOLMOD
from hamsa.operators import hamiltonian

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def bumpy_sphere(n: int) -> hamsa.TriMesh:
    """A sphere with smooth radial bumps: no exact eigenvalue multiplicities (ARPACK misses some)."""
    sphere = shapes.sphere(n)
    x, y, z = sphere.vertices.T
    radius = 1 + 0.15 * np.sin(3 * x + 1) * np.cos(2 * y) + 0.1 * z**3
    return hamsa.TriMesh(sphere.vertices * radius[:, None], sphere.faces)


def median_time(function, repeat: int, threads: int | None = None):
    """(median wall s, CPU s of that run, the last result); ``threads`` pins every BLAS pool (None: defaults)."""
    runs, result = [], None
    for _ in range(repeat):
        with threadpool_limits(limits=threads):
            wall, cpu = time.perf_counter(), time.process_time()
            result = function()
            runs.append((time.perf_counter() - wall, time.process_time() - cpu))
    runs.sort()
    wall, cpu = runs[len(runs) // 2]
    return wall, cpu, result


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
    parser.add_argument("--no-baselines", action="store_true", help="time hamsa only (e.g. at 1M vertices)")
    parser.add_argument("--warm", action="store_true", help="add the warm start after a 5%% change of V")
    parser.add_argument("--gpu", action="store_true", help="time hamsa on the GPU (device='cuda', Chebyshev)")
    parser.add_argument(
        "--method", choices=("krylov", "chebyshev"), default="krylov", help="hamsa's solver on the CPU (default krylov)"
    )
    parser.add_argument("--tol", type=float, default=1e-10, help="hamsa's relative residual target")
    args = parser.parse_args(argv)
    device = "cuda" if args.gpu else "cpu"
    method = "chebyshev" if args.gpu else args.method

    meshes = [(f"bumpy sphere {n // 1000}k", lambda n=n: bumpy_sphere(n)) for n in args.sizes]
    david = DATA / "tosca_hires" / "meshes" / "david0.off.gz"
    if not args.no_data and david.exists():
        meshes.append(("TOSCA david0", lambda: hamsa.load_mesh(david)))
    with_cholmod = HAVE_CHOLMOD and not args.no_cholmod_baseline and not args.no_baselines
    solver = (
        "CuPy Chebyshev on the GPU"
        if args.gpu
        else "Chebyshev on the CPU"
        if method == "chebyshev"
        else f"Krylov, {'CHOLMOD' if HAVE_CHOLMOD else 'SuperLU'}"
    )
    print(f"hamsa {hamsa.__version__}; hamsa solver: {solver}; tol {args.tol:g}; median of {args.repeat} run(s)")
    baselines = [] if args.no_baselines else [("eigsh+SuperLU", eigsh_superlu)]
    if with_cholmod:
        baselines.append(("eigsh+CHOLMOD", eigsh_cholmod))
    header = f"{'mesh':<18} {'n':>8} {'k':>4} {'hamsa wall/cpu s':>16}"
    for label, _ in baselines:
        header += f" {label + ' 1 thread':>22} {label + ' default':>21} {'ratio':>6}"
    if baselines:
        header += f" {'max rel diff':>12}"
    if args.warm:
        header += f" {'cold s':>7} {'warm s':>7} {'cold/warm':>9}"
    if args.gpu:  # CUDA context, cuSPARSE/cuSOLVER handles and CuPy's kernels are made once, not timed
        hamsa.eigenbasis(bumpy_sphere(5000), 20, device="cuda")
    print(f"{os.cpu_count()} CPUs; ratio = baseline wall time at its default threads / hamsa's wall time")
    print(header)
    for name, build in meshes:
        mesh = build()
        H, A = hamiltonian(mesh)
        for k in args.k:
            wall, cpu, basis = median_time(
                lambda: hamsa.eigenbasis(mesh, k, method=method, tol=args.tol, device=device), args.repeat
            )
            row = f"{name:<18} {mesh.n_vertices:>8} {k:>4} {f'{wall:.2f} / {cpu:.2f}':>16}"
            reference = None
            for _, baseline in baselines:
                single = median_time(lambda: baseline(H, A, k), args.repeat, threads=1)
                default = median_time(lambda: baseline(H, A, k), args.repeat)
                reference = single[2] if reference is None else reference
                row += f" {f'{single[0]:.2f} / {single[1]:.2f}':>22} {f'{default[0]:.2f} / {default[1]:.2f}':>21}"
                row += f" {default[0] / wall:>6.2f}"
            if reference is not None:
                row += f" {relative_difference(basis.values, reference):>12.1e}"
            if args.warm:
                t_cold, t_warm = warm_start_times(mesh, k, args, method, device)
                row += f" {t_cold:>7.2f} {t_warm:>7.2f} {t_cold / t_warm:>9.2f}"
            print(row, flush=True)
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    print(f"peak resident memory of this process: {peak_gb:.2f} GB")
    if args.gpu:
        import cupy

        print(f"peak GPU memory (CuPy pool): {cupy.get_default_memory_pool().total_bytes() / 1e9:.2f} GB")
    return 0


def warm_start_times(mesh, k, args, method, device):
    """Median (cold, warm) seconds for the problem after a 5% change of a smooth potential."""
    x = mesh.vertices[:, 0]
    V = 50 * (x - x.min()) / (np.ptp(x) or 1.0) * (4 * np.pi / mesh.area)  # up to about E_20
    changed = V * (1 + 0.05 * np.random.default_rng(1).standard_normal(V.size))
    cold = median_time(lambda: hamsa.eigenbasis(mesh, k, changed, method=method, tol=args.tol, device=device), 1)[0]
    warm_runs = []
    for _ in range(args.repeat):
        solver = HamiltonianEigensolver.for_mesh(mesh, k, tol=args.tol, method=method, device=device)
        solver.solve(V)
        warm_runs.append(median_time(lambda: solver.solve(changed), 1)[0])
    return cold, statistics.median(warm_runs)


if __name__ == "__main__":
    sys.exit(main())
