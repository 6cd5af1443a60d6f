"""Chebyshev-filtered subspace iteration: the eigensolver for GPUs (and for factorization-free runs).

With a lumped (diagonal) mass A = diag(a), ``H psi = E A psi`` is the standard symmetric problem
``M y = E y`` with ``M = A^(-1/2) H A^(-1/2)`` and ``y = A^(1/2) psi``. A block of m = k + guard
orthonormal vectors is improved by

1. a Chebyshev filter p(M) of degree d (Zhou & Saad 2007, "A Chebyshev-Davidson algorithm for large
   symmetric eigenproblems"; Zhou, Saad, Tiago & Chelikowsky 2006 for the scaled three-term recurrence):
   the Chebyshev polynomial of the interval ``[cut, upper]`` holding the unwanted spectrum stays within
   [-1, 1] there and grows like ``cosh(d acosh(1 + 2 (cut - E) / (upper - cut)))`` below it, so every
   wanted component is amplified over every unwanted one. ``upper`` is a Gershgorin bound on the largest
   eigenvalue; ``cut`` is the block's largest Ritz value;
2. orthonormalization (QR) and Rayleigh-Ritz on the block, with the true residuals
   ``||M y - E y|| = ||H psi - E A psi||_{A^-1}`` (the measure of :mod:`hamsa.eigen`).

Only sparse products and dense block operations: no factorization, so it runs on a GPU through CuPy
(cuSPARSE SpMM, cuBLAS, cuSOLVER) with the same code as on the CPU through NumPy/SciPy. On a CPU the
factorized Krylov solver of :mod:`hamsa.eigen` is faster; on a GPU this one is (see
``benchmarks/eigensolve.py --gpu``). The degree is set from the spectrum so that the lowest Ritz value
is amplified at most ~1e8 over the cut per iteration (keeping the block well conditioned in float64).
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from hamsa.errors import ConvergenceError, MissingDependencyError, SolverError
from hamsa.resources import require_memory

DEVICES = ("cpu", "cuda")
_MAX_AMPLIFICATION = 1e8


def array_modules(device: str):
    """(array module, sparse module) for a device: NumPy/SciPy on "cpu", CuPy on "cuda"."""
    if device not in DEVICES:
        raise ValueError(f"device must be one of {DEVICES}, got {device!r}")
    if device == "cpu":
        return np, sp
    try:
        import cupy
        import cupyx.scipy.sparse as cupy_sparse

        if cupy.cuda.runtime.getDeviceCount() < 1:
            raise RuntimeError("no CUDA device")
    except Exception as exc:  # ImportError, or CuPy without a usable GPU
        raise MissingDependencyError(
            f"the GPU eigensolver needs CuPy and a CUDA GPU ({type(exc).__name__}: {exc}); install the CuPy "
            "build for your CUDA: pip install 'hamsa[gpu-cuda12]' or 'hamsa[gpu-cuda13]'"
        ) from None
    return cupy, cupy_sparse


def chebyshev_eigsh(
    H: sp.spmatrix,
    mass_diagonal: np.ndarray,
    k: int,
    *,
    tol: float = 1e-10,
    device: str = "cpu",
    initial: np.ndarray | None = None,
    guard: int | None = None,
    max_iterations: int = 300,
    seed: int = 12345,
    return_block: bool = False,
    spectral_scale: float = 0.0,
):
    """The k smallest eigenpairs of ``H psi = E diag(a) psi`` by Chebyshev-filtered subspace iteration.

    Parameters
    ----------
    H : scipy sparse (n, n)
        Symmetric.
    mass_diagonal : (n,) positive
        The lumped masses a.
    k : int
    tol : float
        Relative residual target, as in :func:`hamsa.eigen.eigenbasis`.
    device : {"cpu", "cuda"}
        "cuda" runs every step on the GPU with CuPy.
    initial : (n, p), optional
        Start vectors (previous eigenvectors: a warm start), a NumPy array or, on "cuda", a CuPy one.
        Best is the whole previous Ritz block (``return_block``): with only the k eigenvectors the
        guard vectors restart random and the first filter is aimed at a far too wide interval.
    guard : int, optional
        Extra vectors in the block (default max(10, k // 4)): more converge faster near the k-th.
    spectral_scale : float
        A typical eigenvalue spacing: the floor of the residual scale (:func:`residual_floor`), needed when
        the k eigenvalues are all ~0 (k or more connected components).

    Returns
    -------
    values (k,), vectors (n, k) NumPy arrays with ``vectors.T @ diag(a) @ vectors = I``, and a dict with
    ``iterations``, ``products`` (sparse block products), ``max_residual``, ``seconds``, ``block`` (m),
    and with ``return_block`` ``ritz_block``: all m Ritz vectors (n, m), mass-orthonormal, left on the
    device (a CuPy array on "cuda") to be the next call's ``initial``.
    """
    start_time = time.perf_counter()
    xp, xsp = array_modules(device)
    n = H.shape[0]
    mass_diagonal = np.asarray(mass_diagonal, dtype=np.float64)
    if mass_diagonal.shape != (n,) or not np.all(mass_diagonal > 0):
        raise SolverError(f"the Chebyshev solver needs a positive lumped mass of shape ({n},)")
    guard = max(10, k // 4) if guard is None else guard
    m = min(k + guard, n)
    if not 1 <= k <= m:
        raise SolverError(f"k = {k} eigenpairs requested, must be between 1 and the number of vertices n = {n}")
    if device == "cpu":  # the block, its image, the filter's three-term recurrence and the Ritz rotation
        require_memory(8 * 6 * n * m, f"the Chebyshev block of {m} columns on n = {n}")
    scale = 1.0 / np.sqrt(mass_diagonal)
    M, upper = _symmetric_operator(H, scale)
    if device == "cuda":
        M = xsp.csr_matrix(M)

    X = _start_block(xp, n, m, seed, initial, mass_diagonal)
    products, iterations = 0, 0
    while True:
        X = xp.ascontiguousarray(X)  # row-major blocks: each row of X is read whole by the GPU kernel
        MX = _multiply(M, X)
        products += 1
        X, MX, theta_host, relative = _rayleigh_ritz(xp, X, MX, k, device, spectral_scale)
        if np.all(relative <= tol):
            break
        iterations += 1
        if iterations > max_iterations:
            raise ConvergenceError(
                f"Chebyshev eigensolver did not converge in {max_iterations} iterations: largest relative "
                f"residual {relative.max():.2e} > tol {tol:.1e}"
            )
        lowest, cut = float(theta_host[0]), float(theta_host[-1])
        if not cut < upper:
            raise SolverError("the block reached the top of the spectrum: ask for fewer eigenpairs (k << n)")
        degree = _filter_degree(lowest, cut, upper, theta_host[:k], relative / tol)
        X = _chebyshev_filter(M, X, MX, degree, lowest, cut, upper)
        products += degree - 1
        X = xp.linalg.qr(X)[0]
    del MX
    block = X * xp.asarray(scale)[:, None]
    vectors = xp.asnumpy(block[:, :k]) if device == "cuda" else block[:, :k].copy()
    seconds = time.perf_counter() - start_time
    info = {"iterations": iterations, "products": products, "max_residual": float(relative.max()),
            "seconds": seconds, "block": m, **({"ritz_block": block} if return_block else {})}  # fmt: skip
    return np.asarray(theta_host[:k], dtype=np.float64), np.asarray(vectors), info


def _start_block(xp, n: int, m: int, seed: int, initial, mass_diagonal: np.ndarray):
    """An orthonormal (n, m) start for the symmetric problem: seeded random columns, the first ones
    replaced by ``initial`` (mass-orthonormal vectors of the pencil, carried over by A^1/2)."""
    X = xp.random.RandomState(seed).standard_normal((n, m))  # drawn where it is used
    if initial is not None:
        initial = xp.asarray(initial, dtype=np.float64).reshape(n, -1)[:, :m]
        X[:, : initial.shape[1]] = initial * xp.asarray(np.sqrt(mass_diagonal))[:, None]
    return xp.linalg.qr(X)[0]


def _symmetric_operator(H, scale: np.ndarray):
    """``M = A^-1/2 H A^-1/2`` (a CSR copy; ``scale`` = a^-1/2) and a Gershgorin bound >= its top eigenvalue."""
    M = sp.csr_matrix(H, dtype=np.float64, copy=True)
    M.data *= scale[np.repeat(np.arange(M.shape[0]), np.diff(M.indptr))] * scale[M.indices]
    return M, float(np.add.reduceat(np.abs(M.data), M.indptr[:-1]).max())


def residual_floor(values: np.ndarray, spectral_scale: float = 0.0) -> float:
    """The smallest scale residuals are measured against, for the k wanted eigenvalues ``values`` ascending:
    an eigenpair's relative residual is ``|H x - E A x| / max(|E|, floor)`` with
    ``floor = 1e-2 max(|E_{k-1}|, spectral_scale)``. Without ``spectral_scale`` (a typical eigenvalue
    spacing, 4 pi / area on a surface) the floor vanishes when all k eigenvalues are ~0, as on a mesh of k
    or more connected components, and no residual could meet a tolerance."""
    return max(1e-2 * max(abs(float(values[-1])), float(spectral_scale)), 1e-300)


def _rayleigh_ritz(xp, X, MX, k: int, device: str, spectral_scale: float):
    """Rotate the orthonormal block X (and MX = M X) to its Ritz vectors: (X, MX, Ritz values on the host,
    relative residuals of the first k on the host)."""
    gram = X.T @ MX
    theta, Y = xp.linalg.eigh((gram + gram.T) / 2)
    X, MX = X @ Y, MX @ Y
    residual = xp.linalg.norm(MX[:, :k] - X[:, :k] * theta[:k], axis=0)
    theta_host = xp.asnumpy(theta) if device == "cuda" else theta
    residual_host = xp.asnumpy(residual) if device == "cuda" else residual
    return (
        X,
        MX,
        theta_host,
        residual_host / np.maximum(np.abs(theta_host[:k]), residual_floor(theta_host[:k], spectral_scale)),
    )


def _filter_degree(lowest: float, cut: float, upper: float, wanted: np.ndarray, excess: np.ndarray) -> int:
    """The filter degree: the smallest that shrinks every wanted Ritz pair's residual below the target
    (a wanted eigenvalue E gains ``T_d(1 + (cut - E) / half_width)`` over the unwanted spectrum; ``excess``
    is each pair's residual / target, with a margin of 10), and at most the largest degree whose
    amplification of the lowest Ritz value stays below ~1e8 (the block stays well conditioned). From a
    random start the cap decides; from a warm start (or in the last iteration) the need does, so
    converged pairs are not filtered further than the target asks."""
    half_width = (upper - cut) / 2
    x = 1 + (cut - lowest) / half_width
    cap = np.arccosh(_MAX_AMPLIFICATION) / np.arccosh(max(x, 1 + 1e-12))
    gain = np.arccosh(np.maximum(1 + (cut - wanted) / half_width, 1 + 1e-12))
    need = np.max(np.arccosh(np.maximum(10 * excess, 1.0)) / gain)
    return int(np.clip(np.ceil(min(need, cap)), 4, 600))


def _chebyshev_filter(M, X, MX, degree: int, lowest: float, cut: float, upper: float):
    """p(M) X for the degree-d Chebyshev polynomial of [cut, upper], scaled so p(lowest) = 1.

    The scaled three-term recurrence (Zhou et al. 2006, Algorithm 4.1) keeps every iterate of order
    one; ``MX = M @ X`` is passed in (it is known from the Rayleigh-Ritz step).
    """
    half_width = (upper - cut) / 2
    center = (upper + cut) / 2
    sigma = half_width / (lowest - center)
    sigma_first = sigma
    Y = (MX - center * X) * (sigma / half_width)
    for _ in range(2, degree + 1):
        sigma_next = 1.0 / (2.0 / sigma_first - sigma)
        # Y_next = (2 sigma_next / e) (M Y - c Y) - sigma sigma_next X
        X, Y = Y, _filter_step(M, Y, X, 2.0 * sigma_next / half_width, center, sigma * sigma_next)
        sigma = sigma_next
    return Y


def _multiply(M, X):
    """M @ X for the (n, n) CSR matrix and an (n, m) block."""
    return _filter_step(M, X, X, 1.0, 0.0, 0.0)


def _filter_step(M, Y, X, a: float, c: float, b: float):
    """``a (M Y - c Y) - b X``: a sparse product and two block updates, which is the whole cost of the
    filter. On a GPU one kernel does it (a warp-per-row CSR product over row-major blocks, fused with the
    updates: one pass over the arrays instead of four); on a CPU, SciPy's product and in-place NumPy."""
    if isinstance(Y, np.ndarray):
        MY = M @ Y
        if c:
            MY -= c * Y
        if a != 1.0:
            MY *= a
        if b:
            MY -= b * X
        return MY
    import cupy

    n, m = Y.shape
    out = cupy.empty_like(Y)
    threads = min(256, 32 * ((m + 31) // 32))
    _cuda_kernel()(
        (n,),
        (threads,),
        (M.indptr, M.indices, M.data, Y, X, out, np.int64(n), np.int64(m), np.float64(a), np.float64(c), np.float64(b)),
    )
    return out


_KERNEL = None
_KERNEL_SOURCE = r"""
extern "C" __global__ void hamsa_chebyshev_step(const int* indptr, const int* indices, const double* data,
        const double* Y, const double* X, double* out, long long n, long long m, double a, double c, double b) {
    long long row = blockIdx.x;
    int start = indptr[row], stop = indptr[row + 1];
    for (long long col = threadIdx.x; col < m; col += blockDim.x) {
        double sum = 0.0;
        for (int p = start; p < stop; ++p) sum += data[p] * Y[(long long)indices[p] * m + col];
        long long at = row * m + col;
        out[at] = a * (sum - c * Y[at]) - b * X[at];
    }
}
"""


def _cuda_kernel():
    global _KERNEL
    if _KERNEL is None:
        import cupy

        _KERNEL = cupy.RawKernel(_KERNEL_SOURCE, "hamsa_chebyshev_step")
    return _KERNEL
