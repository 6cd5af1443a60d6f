"""Sparse Cholesky factorizations of symmetric positive definite matrices, reused across solves.

CHOLMOD (scikit-sparse, the ``[fast]`` extra) when it is installed: a simplicial LDL^T factorization
with a METIS ordering, and a symbolic analysis that is kept when only the values change (a new
potential changes only the diagonal of H). Inside the Krylov solver (blocks of 8 right-hand sides between
dense BLAS work) it is as fast as CHOLMOD's supernodal kernel with OpenBLAS at 200k vertices and faster at
50k, where the supernodal kernel's BLAS threads compete with NumPy's.
Without CHOLMOD, SciPy's SuperLU in symmetric mode (minimum degree on A + A^T, diagonal pivoting), with a
one-time notice saying how to get CHOLMOD.
"""

from __future__ import annotations

import warnings

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


def _cholmod_symbolic(matrix):
    """Simplicial LDL^T with a METIS ordering (see the module docstring for why not supernodal)."""
    try:
        return _cholmod_analyze(matrix, mode="simplicial", ordering_method="metis")
    except Exception:  # CHOLMOD built without METIS
        return _cholmod_analyze(matrix, mode="simplicial", ordering_method="amd")


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
            return self._factor(rhs)
        return self._factor.solve(rhs)
