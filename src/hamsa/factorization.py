"""Sparse Cholesky factorizations of symmetric positive definite matrices, reused across solves.

CHOLMOD (scikit-sparse, the ``[fast]`` extra) when it is installed, with a METIS ordering and a symbolic
analysis that is kept when only the values change (a new potential changes only the diagonal of H). The
kernel depends on the size: below :data:`SUPERNODAL_FROM` rows a simplicial LDL^T (no BLAS; inside the
Krylov solver, blocks of 8 right-hand sides between dense BLAS work, it is as fast as the supernodal
kernel there); from it, when CHOLMOD's BLAS is an optimized one, the supernodal LL^T, whose numeric
factorization runs on dense BLAS blocks (several times faster on meshes of a million vertices). Its solves
run with CHOLMOD's BLAS and OpenMP held to one thread (threadpoolctl): NumPy's BLAS threads stay busy on
the other cores between the solver's dense products, and two thread pools competing for the cores make
the solves slower, not faster. Without an optimized BLAS behind CHOLMOD (the reference BLAS) or without
threadpoolctl, the simplicial kernel at every size.
Without CHOLMOD, SciPy's SuperLU in symmetric mode (minimum degree on A + A^T, diagonal pivoting), with a
one-time notice saying how to get CHOLMOD.
"""

from __future__ import annotations

import os
import warnings
from functools import cache

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from hamsa.errors import PerformanceNotice, SolverError

try:  # pragma: no cover - depends on the environment
    from sksparse.cholmod import CholmodNotPositiveDefiniteError
    from sksparse.cholmod import analyze as _cholmod_analyze

    HAVE_CHOLMOD = True
except ImportError:  # pragma: no cover - depends on the environment
    HAVE_CHOLMOD = False

BACKENDS = ("auto", "cholmod", "superlu")
SUPERNODAL_FROM = 100_000  # rows from which CHOLMOD's supernodal kernel is used (with an optimized BLAS)
# NumPy's and SciPy's own BLAS in their wheels: not the one CHOLMOD calls
_BUNDLED = (f"{os.sep}numpy.libs{os.sep}", f"{os.sep}scipy.libs{os.sep}", f"{os.sep}scipy_openblas")


@cache
def cholmod_thread_pools():
    """The threadpoolctl selection of the optimized BLAS and OpenMP libraries CHOLMOD runs on (those not
    bundled in NumPy's or SciPy's wheels), or None: no threadpoolctl, or no optimized BLAS among them (the
    reference BLAS, which threadpoolctl does not list, is too slow for the supernodal kernel)."""
    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:
        return None
    controller = ThreadpoolController()
    pools = [
        pool
        for pool in controller.info()
        if pool["user_api"] in ("blas", "openmp") and not any(mark in pool["filepath"] for mark in _BUNDLED)
    ]
    if not any(pool["user_api"] == "blas" for pool in pools):
        return None
    return controller.select(filepath=[pool["filepath"] for pool in pools])


def supernodal(n: int) -> bool:
    """Whether an n-row factorization uses CHOLMOD's supernodal kernel (see the module docstring)."""
    return HAVE_CHOLMOD and n >= SUPERNODAL_FROM and cholmod_thread_pools() is not None


def _cholmod_symbolic(matrix):
    """The symbolic analysis with a METIS ordering (AMD when CHOLMOD lacks METIS), simplicial or supernodal
    by :func:`supernodal`."""
    mode = "supernodal" if supernodal(matrix.shape[0]) else "simplicial"
    try:
        return _cholmod_analyze(matrix, mode=mode, ordering_method="metis")
    except Exception:  # CHOLMOD built without METIS
        return _cholmod_analyze(matrix, mode=mode, ordering_method="amd")


_notified = False


def _notify_fallback() -> None:
    global _notified
    if not _notified:
        _notified = True
        warnings.warn(
            "CHOLMOD (scikit-sparse) is not installed; using SciPy's SuperLU, which is slower. "
            "Install it with: pip install 'hamsa[fast]' (needs Debian's libsuitesparse-dev).",
            PerformanceNotice,
            stacklevel=3,
        )


def resolve_backend(backend: str) -> str:
    if backend not in BACKENDS:
        raise ValueError(f"factorization backend must be one of {BACKENDS}, got {backend!r}")
    if backend == "cholmod" and not HAVE_CHOLMOD:
        from hamsa.errors import MissingDependencyError

        raise MissingDependencyError("backend 'cholmod' needs scikit-sparse: pip install 'hamsa[fast]'")
    if backend == "auto":
        if HAVE_CHOLMOD:
            return "cholmod"
        _notify_fallback()
        return "superlu"
    return backend


class CholeskySolver:
    """Factor a sparse symmetric positive definite matrix once; solve for many right-hand sides.

    Parameters
    ----------
    matrix : sparse (n, n)
        Symmetric positive definite.
    backend : {"auto", "cholmod", "superlu"}

    Examples
    --------
    >>> import scipy.sparse as sp, numpy as np
    >>> solver = CholeskySolver(sp.diags([2.0, 4.0]).tocsc())
    >>> solver.solve(np.array([2.0, 4.0]))
    array([1., 1.])
    """

    def __init__(self, matrix: sp.spmatrix, backend: str = "auto"):
        self.backend = resolve_backend(backend)
        self.shape = matrix.shape
        self._symbolic = None
        self._factor = None
        self.refactor(matrix)

    @classmethod
    def unfactored(cls, shape: tuple[int, int], backend: str = "auto") -> CholeskySolver:
        """A solver with nothing factored yet: its first :meth:`refactor` does the (symbolic and numeric)
        work, so a caller that owns the solver does not factor a matrix it will replace at once."""
        solver = cls.__new__(cls)
        solver.backend = resolve_backend(backend)
        solver.shape = tuple(shape)
        solver._symbolic = None
        solver._factor = None
        return solver

    def refactor(self, matrix: sp.spmatrix) -> None:
        """Factor a new matrix with the same sparsity pattern (CHOLMOD keeps its symbolic analysis)."""
        matrix = sp.csc_matrix(matrix)
        if matrix.shape != self.shape:
            raise ValueError(f"matrix shape {matrix.shape} differs from the factored {self.shape}")
        if self.backend == "cholmod":
            try:
                if self._symbolic is None:
                    self._symbolic = _cholmod_symbolic(matrix)
                self._factor = self._symbolic.cholesky(matrix)
            except CholmodNotPositiveDefiniteError:
                raise SolverError("matrix is not positive definite (Cholesky failed)") from None
        else:
            try:
                self._factor = spla.splu(
                    matrix,
                    permc_spec="MMD_AT_PLUS_A",
                    diag_pivot_thresh=0.0,
                    options={"SymmetricMode": True},
                )
            except RuntimeError as exc:
                raise SolverError(f"sparse factorization failed: {exc}") from None

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve ``matrix @ x = rhs`` for ``rhs`` of shape (n,) or (n, p)."""
        if self._factor is None:
            raise SolverError("nothing is factored yet: call refactor(matrix) first")
        rhs = np.asarray(rhs, dtype=np.float64)
        if self.backend == "cholmod":
            rhs = np.asfortranarray(rhs)
            if not supernodal(self.shape[0]):
                return self._factor(rhs)
            with cholmod_thread_pools().limit(limits=1):
                return self._factor(rhs)
        return self._factor.solve(rhs)
