"""The Hamiltonian eigenbasis: the k smallest eigenpairs of ``H psi = E A psi``.

Algorithm (``method="krylov"``, chosen by ``"auto"`` for all but tiny problems)
-------------------------------------------------------------------------------
Shift-invert block Krylov with thick restarts and a dense Rayleigh-Ritz, in the A-inner product.

1. A shift below the whole spectrum: ``sigma = min(V) - delta`` (Theorem 1 gives
   ``E_1 >= lambda_1 + min V >= min V``), so ``K = H - sigma A = W + A (V - sigma)`` is symmetric
   positive definite for every potential, also when W is singular (V = 0, several components).
   K is factored once by sparse Cholesky (:mod:`hamsa.factorization`).
2. The operator ``S = K^{-1} A`` is self-adjoint in ``<x, y>_A`` and maps eigenvector psi_i to
   ``psi_i / (E_i - sigma)``: the wanted eigenpairs are its dominant ones. From a block of start
   vectors the basis grows block by block, ``Z <- S Z`` (one multi-right-hand-side solve per block),
   each new block A-orthogonalized against the basis (classical Gram-Schmidt: a first pass against the
   previous block only — the block Lanczos recurrence, exact but for rounding — then one pass against
   the whole basis) and orthonormalized by SVQB (Stathopoulos & Wu 2002), which also drops dependent
   directions.
3. Rayleigh-Ritz with H on the basis gives Ritz pairs; convergence is tested on the true residuals
   ``r_i = H x_i - E_i A x_i``. The basis is then shrunk to the best ``k + guard`` Ritz vectors (a thick
   restart, as in Wu & Simon 2000 and Stewart's Krylov-Schur) and the Krylov growth continues from the
   unconverged ones.

All the dense work (orthogonalization, Rayleigh-Ritz) is BLAS-3 on blocks, and all sparse solves have
many right-hand sides, which is where the speed over ARPACK's one-vector Lanczos comes from.
Warm starts (``initial=``): random combinations of the previous eigenvectors form the first block (a
start rich in the wanted eigenvectors; the block stays narrow). :class:`HamiltonianEigensolver` does this
when only the potential changes, and reuses the factorization's symbolic analysis. The gain is modest
(Krylov convergence depends on the start only logarithmically): see ``benchmarks/eigensolve.py --warm``.

Conventions: eigenvalues ascending; ``vectors.T @ A @ vectors = I``; each vector's sign is fixed so its
first entry of magnitude above 1e-3 of its largest is positive (deterministic for a given mesh).
"""

from __future__ import annotations

import hashlib
import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components

from hamsa.chebyshev import residual_floor
from hamsa.errors import ConvergenceError, HamsaError, InputWarning, ResourceError, SolverError
from hamsa.factorization import CholeskySolver
from hamsa.files import atomic_write, load_npz
from hamsa.mesh import format_ids
from hamsa.operators import (
    LAPLACIANS,
    MASS_KINDS,
    check_potential,
    default_laplacian,
    dirichlet_vertices,
    hamiltonian,
    laplacian_operators,
)
from hamsa.pointcloud import PointCloud, as_shape
from hamsa.resources import require_memory

METHODS = ("auto", "krylov", "dense", "chebyshev")
_DENSE_MAX_N = 1500  # "auto" uses the dense solver up to this many vertices
_DENSE_LIMIT_N = 20000  # beyond this a dense solve would need > 3 GB: refused
_FORMAT_VERSION = 1
# Krylov steps whose second Gram-Schmidt pass waits for the next settling step (see _extend)
_DEFERRED_BLOCKS = 3
# a step settles at once when its first pass left less than this fraction of a column's A-norm
_CANCELLATION = 1e-3


@dataclass(frozen=True)
class SolveInfo:
    """What a solve did: the method, restart cycles (Chebyshev: filter iterations), sparse solves
    (Chebyshev: sparse matrix-vector products, counted per column), the largest relative residual, time,
    and, when the requested method stalled and a slower one took over, why (``fallback``)."""

    method: str
    cycles: int = 0
    solves: int = 0
    max_residual: float = 0.0
    seconds: float = 0.0
    shift: float = 0.0
    fallback: str = ""  # why a slower method replaced the requested one ("" when none did)


@dataclass(frozen=True, eq=False)
class Eigenbasis:
    """The k smallest eigenpairs of ``H psi = E A psi`` on one mesh.

    Attributes
    ----------
    values : (k,) float64
        Eigenvalues E_i, ascending, in units of 1/length^2.
    vectors : (n, k) float64
        Eigenvectors psi_i as columns, mass-orthonormal: ``vectors.T @ mass @ vectors = I``.
    mass : scipy.sparse.csr_matrix (n, n)
        The mass matrix A used (diagonal unless ``mass_kind == "full"``).
    potential : (n,) float64 or None
        The potential V (None for the Laplace-Beltrami operator, V = 0).
    mass_kind : str
    info : SolveInfo
    vertex_ids : (n,) int64 or None
        For a basis of a repaired or reduced mesh, the vertex of the original mesh each row belongs to (a
        split vertex's copies share one); None when row i is vertex i. Saved and loaded with the basis.
    """

    values: np.ndarray
    vectors: np.ndarray
    mass: sp.csr_matrix
    potential: np.ndarray | None = None
    mass_kind: str = "voronoi"
    info: SolveInfo = field(default_factory=lambda: SolveInfo(method="loaded"))
    vertex_ids: np.ndarray | None = None

    @property
    def k(self) -> int:
        return self.values.shape[0]

    @property
    def n(self) -> int:
        return self.vectors.shape[0]

    def __repr__(self) -> str:
        kind = "LBO" if self.potential is None else "Hamiltonian"
        return f"Eigenbasis({kind}, n={self.n}, k={self.k}, E=[{self.values[0]:.4g} .. {self.values[-1]:.4g}])"

    def project(self, f) -> np.ndarray:
        """Coefficients ``Psi^T A f`` of a function (n,) or functions (n, d): returns (k,) or (k, d)."""
        f = _real_array(f, "function")
        if f.ndim not in (1, 2) or f.shape[0] != self.n:
            raise HamsaError(f"function has shape {f.shape}, expected ({self.n},) or ({self.n}, d)")
        return self.vectors.T @ (self.mass @ f)

    def reconstruct(self, coefficients) -> np.ndarray:
        """The function ``Psi c`` from coefficients (k,) or (k, d): returns (n,) or (n, d)."""
        c = _real_array(coefficients, "coefficients")
        if c.ndim not in (1, 2) or c.shape[0] != self.k:
            raise HamsaError(f"coefficients have shape {c.shape}, expected ({self.k},) or ({self.k}, d)")
        return self.vectors @ c

    @property
    def participation(self) -> np.ndarray:
        """(k,) the participation number of each eigenvector, ``1 / sum_i w_i^2`` with ``w_i = a_i psi_i^2`` its
        share of the mass at vertex i (a_i the lumped mass): about how many vertices it lives on (n for a
        constant on a uniform sampling, 1 for a spike on one vertex)."""
        blocks = (_mass_shares(self, np.arange(j, min(j + 16, self.k))) for j in range(0, self.k, 16))
        return np.concatenate([1.0 / np.einsum("nk,nk->k", shares, shares) for shares in blocks])

    def truncate(self, k: int) -> Eigenbasis:
        """The first k eigenpairs."""
        if not 1 <= k <= self.k:
            raise HamsaError(f"cannot truncate a basis of {self.k} eigenpairs to {k}")
        return replace(self, values=self.values[:k], vectors=self.vectors[:, :k])

    def with_vertex_ids(self, vertex_ids) -> Eigenbasis:
        """The same basis, recording the original vertex of each row (see ``vertex_ids``), e.g. the ``kept``
        array of :func:`hamsa.repair.repair_mesh`. Raises HamsaError unless it is (n,) non-negative integers."""
        return replace(self, vertex_ids=_vertex_ids(vertex_ids, self.n))

    def save(self, path, extra: dict | None = None) -> None:
        """Write to an ``.npz`` file atomically (temporary file + rename); ``extra`` arrays ride along."""
        path = Path(path)
        mass = self.mass.tocsr()
        arrays = {
            "format_version": np.array(_FORMAT_VERSION),
            "values": self.values,
            "vectors": self.vectors,
            "mass_data": mass.data,
            "mass_indices": mass.indices,
            "mass_indptr": mass.indptr,
            "mass_kind": np.array(self.mass_kind),
        }
        if self.potential is not None:
            arrays["potential"] = self.potential
        if self.vertex_ids is not None:
            arrays["vertex_ids"] = self.vertex_ids
        arrays["checksum"] = np.array(_checksum(arrays))
        arrays.update(extra or {})
        with atomic_write(path, "wb") as handle:
            np.savez(handle, **arrays)

    def to_arrays(self) -> dict:
        """Plain arrays: ``values`` (k,), ``vectors`` (n, k), ``mass`` (n,) lumped masses — or the sparse
        (n, n) matrix for ``mass_kind == "full"`` — and ``potential`` (n,) or None. The convention is
        pyFM's and LaPy's too: columns are eigenvectors, orthonormal in the mass inner product."""
        lumped = self.mass_kind != "full"
        mass = self.mass.diagonal().copy() if lumped else self.mass.copy()
        return {"values": self.values.copy(), "vectors": self.vectors.copy(), "mass": mass, "potential": self.potential}

    @classmethod
    def from_arrays(cls, values, vectors, mass, potential=None, check: bool = True) -> Eigenbasis:
        """An Eigenbasis from arrays computed elsewhere (e.g. by scipy's eigsh, pyFM or LaPy).

        ``mass`` is the (n,) lumped masses or an (n, n) sparse matrix. Shapes must agree and everything be
        finite; with ``check`` the values must also be ascending and the columns mass-orthonormal to 1e-6
        (normalize them first). Raises HamsaError naming the first problem.
        """
        values = _real_array(values, "values")
        vectors = _real_array(vectors, "vectors")
        if sp.issparse(mass):
            matrix, kind = sp.csr_matrix(mass, dtype=np.float64), "full"
        else:
            lumped = _real_array(mass, "mass")
            if lumped.ndim != 1:
                raise HamsaError(
                    f"mass must be (n,) lumped masses or an (n, n) sparse matrix, got shape {lumped.shape}"
                )
            matrix, kind = sp.diags(lumped).tocsr(), "voronoi"
        if potential is not None:
            potential = _real_array(potential, "potential")
        return cls._validated(values, vectors, matrix, potential, kind, SolveInfo(method="arrays"), check)

    @classmethod
    def _validated(cls, values, vectors, matrix, potential, kind, info, check: bool = True) -> Eigenbasis:
        """The one validation of :meth:`from_arrays` and :meth:`load`: shapes, finiteness, positive lumped
        masses, then (``check``) ascending values and mass-orthonormal vectors."""
        if vectors.ndim != 2 or values.shape != (vectors.shape[1],) or values.size == 0:
            raise HamsaError(f"values {values.shape} and vectors {vectors.shape} must be (k,) and (n, k), k >= 1")
        n = vectors.shape[0]
        if matrix.shape != (n, n):
            raise HamsaError(f"mass must be ({n},) or ({n}, {n}) for {n} vertices, got {matrix.shape}")
        if potential is not None and potential.shape != (n,):
            raise HamsaError(f"potential must be ({n},), got {potential.shape}")
        for name, array in (("values", values), ("vectors", vectors), ("mass", matrix.data), ("potential", potential)):
            if array is not None and not np.all(np.isfinite(array)):
                raise HamsaError(f"{name} must be finite (found NaN or Inf)")
        if kind != "full" and not np.all(matrix.diagonal() > 0):
            raise HamsaError("lumped masses must be positive")
        if check:
            if np.any(np.diff(values) < 0):
                raise HamsaError("values must be ascending (sort the pairs first)")
            error = np.abs(vectors.T @ (matrix @ vectors) - np.eye(values.size)).max()
            if not error <= 1e-6:
                raise HamsaError(f"the vectors are not mass-orthonormal (max |Psi^T A Psi - I| = {error:.1e})")
        return cls(values, vectors, matrix, potential, kind, info)

    @classmethod
    def load(cls, path) -> Eigenbasis:
        """Read a basis written by :meth:`save`, validated like :meth:`from_arrays` before any array is used.

        Every member is checked from its header before it is read (dtype, dimensions, size), the sparse
        mass's index arrays must be in range, and the arrays must match their stored SHA-256 checksum.
        Raises HamsaError (:class:`~hamsa.errors.FileAccessError` for an unreadable or oversized file).
        """
        return cls.load_with_extra(path)[0]

    @classmethod
    def load_with_extra(cls, path) -> tuple[Eigenbasis, dict]:
        """:meth:`load`, and the ``extra`` arrays that :meth:`save` wrote beside the basis (name -> array),
        from one read of the file."""
        real = {"ndim": 1, "numeric": True}
        arrays = load_npz(path, {"values": real, "vectors": {"ndim": 2, "numeric": True}, "mass_data": real,
                                 "mass_indices": real, "mass_indptr": real, "potential": real, "vertex_ids": real,
                                 "format_version": {"ndim": 0, "numeric": True}})  # fmt: skip
        missing = [name for name in ("format_version", "values", "vectors", "mass_kind") if name not in arrays]
        missing += [name for name in ("mass_data", "mass_indices", "mass_indptr") if name not in arrays]
        if missing:
            raise HamsaError(f"'{path}' is not an eigenbasis file: it has no {', '.join(missing)}")
        version = int(arrays["format_version"])
        if version != _FORMAT_VERSION:
            raise HamsaError(f"'{path}' has eigenbasis format {version}, this hamsa reads {_FORMAT_VERSION}")
        if "checksum" in arrays and str(arrays["checksum"]) != _checksum(arrays):
            raise HamsaError(f"'{path}' is corrupt: its arrays do not match their SHA-256 checksum")
        kind = str(arrays["mass_kind"])
        if kind not in MASS_KINDS + LAPLACIANS:  # "intrinsic_delaunay": that Laplacian's lumped mass
            raise HamsaError(f"'{path}' has mass kind {kind!r}, expected one of {MASS_KINDS + LAPLACIANS[1:]}")
        vectors = np.asarray(arrays["vectors"], dtype=np.float64)
        try:
            mass = _csr_matrix(arrays["mass_data"], arrays["mass_indices"], arrays["mass_indptr"], vectors.shape[0])
            potential = arrays.get("potential")
            basis = cls._validated(
                np.asarray(arrays["values"], dtype=np.float64),
                vectors,
                mass,
                None if potential is None else np.asarray(potential, dtype=np.float64),
                kind,
                SolveInfo(method="loaded"),
            )
            if "vertex_ids" in arrays:
                basis = basis.with_vertex_ids(arrays["vertex_ids"])
        except HamsaError as exc:
            raise HamsaError(f"'{path}' is not a valid eigenbasis: {exc}") from None
        own = {*_CHECKED, "format_version", "mass_kind", "checksum"}
        return basis, {name: array for name, array in arrays.items() if name not in own}


def _vertex_ids(vertex_ids, n: int) -> np.ndarray:
    ids = np.asarray(vertex_ids)
    if ids.shape != (n,) or ids.dtype.kind not in "iu" or (n and ids.min() < 0):
        raise HamsaError(f"vertex_ids must be ({n},) non-negative integers, got {ids.shape} {ids.dtype}")
    return ids.astype(np.int64)


def _real_array(values, name: str) -> np.ndarray:
    """``values`` as a float64 array, refusing complex, string and ragged input (HamsaError)."""
    try:
        array = np.asarray(values)
        if np.iscomplexobj(array):
            raise HamsaError(f"{name} must be real, got complex numbers")
        return array.astype(np.float64, copy=False)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, HamsaError):
            raise
        raise HamsaError(f"{name} must be an array of real numbers: {exc}") from None


def _csr_matrix(data, indices, indptr, n: int) -> sp.csr_matrix:
    """An (n, n) CSR matrix from stored arrays, every index checked before scipy sees it."""
    if indices.dtype.kind not in "iu" or indptr.dtype.kind not in "iu":
        raise HamsaError("the mass matrix's index arrays must be integers")
    if indptr.shape != (n + 1,) or data.shape != indices.shape:
        raise HamsaError(f"the mass matrix's arrays do not describe an ({n}, {n}) matrix")
    if indptr[0] != 0 or indptr[-1] != len(indices) or np.any(np.diff(indptr.astype(np.int64)) < 0):
        raise HamsaError("the mass matrix's row pointers are not increasing from 0 to its number of entries")
    if len(indices) and (indices.min() < 0 or indices.max() >= n):
        raise HamsaError(f"the mass matrix has column indices outside 0..{n - 1}")
    return sp.csr_matrix((data.astype(np.float64), indices.astype(np.int64), indptr.astype(np.int64)), shape=(n, n))


_CHECKED = ("values", "vectors", "mass_data", "mass_indices", "mass_indptr", "potential", "vertex_ids")


def _checksum(arrays) -> str:
    """SHA-256 over the basis arrays (dtype, shape and bytes), so a damaged file is detected on load."""
    digest = hashlib.sha256()
    for name in _CHECKED:
        if name in arrays:
            array = np.ascontiguousarray(arrays[name])
            digest.update(f"{name}:{array.dtype.str}:{array.shape}".encode())
            digest.update(array.tobytes())
    return digest.hexdigest()


def eigenbasis(
    mesh,
    k: int,
    potential=None,
    mass: str = "voronoi",
    *,
    method: str = "auto",
    tol: float = 1e-10,
    backend: str = "auto",
    initial: np.ndarray | None = None,
    laplacian: str | None = None,
    device: str = "cpu",
    boundary="neumann",
    progress=None,
) -> Eigenbasis:
    """The k smallest eigenpairs of the Hamiltonian ``(W + A diag(V)) psi = E A psi`` on a mesh or point cloud.

    Parameters
    ----------
    mesh : TriMesh, (vertices, faces) or PointCloud
        A mesh must have no unreferenced vertices (see :meth:`TriMesh.without_unreferenced`). Several
        connected components and boundaries are fine.
    k : int
        Number of eigenpairs, 1 <= k <= n (n minus the Dirichlet vertices).
    potential : array_like (n,), optional
        V at each vertex, any sign (None: V = 0, the Laplace-Beltrami operator).
    mass : {"voronoi", "barycentric", "full"}
        The mass matrix (see :func:`hamsa.operators.mass_matrix`); "voronoi" is the paper's.
    method : {"auto", "krylov", "dense", "chebyshev"}
        "krylov": the block shift-invert solver described in this module; "dense": LAPACK on dense
        matrices (small meshes only); "chebyshev": factorization-free Chebyshev-filtered subspace
        iteration (:mod:`hamsa.chebyshev`; lumped masses only), the GPU solver; "auto": dense for
        n <= 1500, else krylov on the CPU and chebyshev on a GPU.
    tol : float
        Relative residual target, ``||H x - E A x|| <= tol * max(|E|, E_scale) * ||A x||``, where
        E_scale = 1e-2 |E_k| keeps the test meaningful for eigenvalues near 0.
    backend : {"auto", "cholmod", "superlu"}
        Sparse Cholesky backend (see :mod:`hamsa.factorization`).
    initial : (n, p) array, optional
        Start vectors (e.g. the eigenvectors of a nearby potential): a warm start.
    laplacian : {"cotan", "intrinsic_delaunay", "tufted", "point_cloud"}, optional
        The discretization (:func:`hamsa.operators.laplacian_operators`): None is "cotan" for a mesh and
        "point_cloud" for a cloud; "intrinsic_delaunay" for meshes with needles or very obtuse triangles,
        "tufted" for meshes with non-manifold edges (both the ``[robust]`` extra).
    device : {"cpu", "cuda"}
        "cuda" solves on an NVIDIA GPU with CuPy (the ``[gpu-cuda12]`` / ``[gpu-cuda13]`` extras).
    boundary : "neumann", "dirichlet" or array of vertex ids
        "neumann" (natural, the default): no condition on the boundary. "dirichlet": psi = 0 on the
        mesh's boundary vertices. An index array: psi = 0 on those vertices (or points), e.g. the
        boundary of a point cloud or a region cut out of the surface. The problem is solved on the other
        vertices and the eigenvectors extended by zero (every method). See
        :func:`hamsa.operators.dirichlet_vertices`.
    progress : callable, optional
        ``progress(converged, k)``: called as the Krylov solver checks its Ritz pairs (every few blocks:
        how many of the k wanted pairs meet ``tol``), and with ``(k, k)`` when the solve is done (the
        only call for the dense, Chebyshev and per-piece solves). For a progress bar on long solves.

    Returns
    -------
    Eigenbasis
        ``values`` ascending, ``vectors`` mass-orthonormal with deterministic signs.

    Examples
    --------
    >>> import hamsa
    >>> basis = hamsa.eigenbasis(hamsa.shapes.icosphere(3), k=4)
    >>> basis.values[1:].round(2).tolist()  # unit sphere: l(l+1) = 0 (the constant), then 2 three times
    [2.0, 2.0, 2.0]
    """
    shape = as_shape(mesh)
    if mass not in MASS_KINDS:
        raise HamsaError(f"mass kind must be one of {MASS_KINDS}, got {mass!r}")
    if potential is not None:
        potential = check_potential(potential, shape.n_vertices)
    laplacian = default_laplacian(shape) if laplacian is None else laplacian
    H, A = hamiltonian(shape, potential, mass, laplacian)
    n = shape.n_vertices
    fixed = dirichlet_vertices(shape, boundary)
    free = np.setdiff1d(np.arange(n), fixed)
    if len(free) == 0:
        raise HamsaError("every vertex is a Dirichlet vertex: nothing is left to solve for")
    if initial is not None:
        initial = np.asarray(initial, dtype=np.float64)
        if initial.ndim not in (1, 2) or initial.shape[0] != n:
            raise SolverError(f"initial vectors must have shape ({n}, p), got {initial.shape}")
    restricted = len(fixed) > 0
    values, free_vectors, info = generalized_eigsh(
        H[free][:, free] if restricted else H,
        A[free][:, free] if restricted else A,
        k,
        lower_bound=float(potential.min()) if potential is not None else 0.0,
        method=method,
        tol=tol,
        backend=backend,
        initial=initial[free] if restricted and initial is not None else initial,
        spectral_scale=4 * np.pi / float(A.sum()),
        device=device,
        progress=progress,
    )
    vectors = free_vectors
    if restricted:
        vectors = np.zeros((n, free_vectors.shape[1]))
        vectors[free] = free_vectors
    basis = Eigenbasis(values, vectors, A, potential, mass if laplacian == "cotan" else laplacian, info)
    if isinstance(shape, PointCloud):
        _warn_unresolved(basis)
    return basis


def _mass_shares(basis: Eigenbasis, columns: np.ndarray) -> np.ndarray:
    """(n, len(columns)): each listed eigenvector's share of its mass at each vertex, ``a_i psi_i^2`` with a_i the
    lumped mass (each column sums to 1)."""
    shares = np.asarray(basis.mass.sum(axis=1)).ravel()[:, None] * basis.vectors[:, columns] ** 2
    return shares / shares.sum(axis=0)


UNRESOLVED_POINTS = 50  # an eigenvector of a point cloud living on fewer points than this is not resolved


def unresolved_eigenpairs(basis: Eigenbasis) -> tuple[np.ndarray, np.ndarray]:
    """``(modes, points)``: the eigenpairs whose :attr:`Eigenbasis.participation` is below
    :data:`UNRESOLVED_POINTS` (and below n / 20, for small samplings), and the vertices holding at least 1% of
    the mass of one of them, both ascending int64.

    A surface's eigenfunction varies on the scale of its wavelength, so one that a handful of samples carry
    is not the surface's. On a point cloud such a mode is made by the operator where a few points hang on
    weak links to the rest: points off the surface, or a patch of normals with the wrong sign that cuts its
    points off their sheet; or by a potential well narrower than the sampling. :func:`eigenbasis` warns
    when a point cloud's basis has one."""
    return _unresolved(basis)[:2]


def _unresolved(basis: Eigenbasis) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(modes, points, participation (k,)): :func:`unresolved_eigenpairs` and the participation it decided by."""
    participation = basis.participation
    modes = np.flatnonzero(participation < min(UNRESOLVED_POINTS, basis.n / 20))
    points = np.flatnonzero((_mass_shares(basis, modes) >= 0.01).any(axis=1)) if len(modes) else modes
    return modes.astype(np.int64), points.astype(np.int64), participation


def _warn_unresolved(basis: Eigenbasis) -> None:
    """An InputWarning naming the :func:`unresolved_eigenpairs` of a point cloud's basis, if any."""
    modes, points, participation = _unresolved(basis)
    if not len(modes):
        return
    which = f"eigenpair {modes[0]} lives"
    if len(modes) > 1:
        which = f"{len(modes)} eigenpairs ({format_ids(modes)}) each live"
    warnings.warn(
        f"{which} on fewer than {UNRESOLVED_POINTS} points (participation number "
        f"{format_ids(np.round(participation[modes]))}; points {format_ids(points, 8)}): no mode of a surface "
        "is that small, so the point-cloud operator made it where a few points hang on weak links (points off the "
        "surface, a patch of normals with the wrong sign), or a potential well is narrower than the sampling. "
        "Drop those points (hamsa repair --modes K; repair_point_cloud(..., modes=K)), give the cloud its normals, "
        "or use separate_sheets=False",
        InputWarning,
        stacklevel=3,
    )


def generalized_eigsh(
    H: sp.spmatrix,
    A: sp.spmatrix,
    k: int,
    *,
    lower_bound: float = 0.0,
    method: str = "auto",
    tol: float = 1e-10,
    backend: str = "auto",
    initial: np.ndarray | None = None,
    spectral_scale: float | None = None,
    factor: CholeskySolver | None = None,
    max_cycles: int = 50,
    device: str = "cpu",
    progress=None,
) -> tuple[np.ndarray, np.ndarray, SolveInfo]:
    """The k smallest eigenpairs of a sparse symmetric pencil ``H x = E A x`` with A positive definite.

    Parameters
    ----------
    H, A : sparse (n, n)
        Symmetric; A positive definite.
    k : int
    lower_bound : float
        A number <= the smallest eigenvalue (``min V`` for a Hamiltonian, by Theorem 1).
    spectral_scale : float, optional
        A typical eigenvalue spacing (1/area for a surface); sets the shift's distance below the
        lower bound. Estimated from the matrices when omitted.
    factor : CholeskySolver, optional
        A reusable factorization object; it is re-factored with ``H - sigma A``.
    max_cycles : int
        Thick restarts of the Krylov solver before it counts as stalled (it usually needs 2-5). A stalled
        solve falls back to a dense solve where that fits, else to ARPACK, and ``info.fallback`` says so.
    method, tol, backend, initial, device, progress
        As in :func:`eigenbasis`.

    Returns
    -------
    values : (k,) ascending
    vectors : (n, k) with ``vectors.T @ A @ vectors = I`` and fixed signs
    info : SolveInfo

    Raises
    ------
    SolverError
        For an impossible request (k outside 1..n, mismatched shapes, a dense solve beyond n = 20000).
    ResourceError
        When the solve would not fit in memory (checked before the work starts).
    ConvergenceError
        When the Krylov solver stalls and its fallback does not converge either.
    """
    n = H.shape[0]
    if H.shape != (n, n) or A.shape != (n, n):
        raise SolverError(f"H {H.shape} and A {A.shape} must be square and of the same size")
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)):
        raise SolverError(f"k must be an integer, got {k!r}")
    if not 1 <= k <= n:
        raise SolverError(f"k = {k} eigenpairs requested, must be between 1 and the number of vertices n = {n}")
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if device == "cuda" and method not in ("auto", "chebyshev"):
        raise SolverError(f"method {method!r} runs on the CPU; on device='cuda' use method='chebyshev' (or 'auto')")
    count, labels = connected_components(abs(H) + abs(A), directed=False)
    if count > 1:
        options = dict(lower_bound=lower_bound, method=method, tol=tol, backend=backend, max_cycles=max_cycles,
                       device=device)  # fmt: skip
        values, vectors, info = _by_components(H, A, k, labels, initial, options)
        _report(progress, k, k)
        return values, vectors, info
    method = _resolve_method(method, device, n, k)
    if spectral_scale is None:
        spectral_scale = float(H.diagonal().mean() / A.diagonal().mean()) / n
    start = time.perf_counter()
    if method == "chebyshev":
        values, vectors, info, _ = _chebyshev(H, A, k, tol, device, initial, spectral_scale)
    elif method == "dense":
        values, vectors = _dense_eigh(H, A, k)
        info = SolveInfo(method="dense")
    else:
        shift = lower_bound - spectral_scale
        try:
            values, vectors, info = _block_krylov(
                H, A, k, shift=shift, tol=tol, backend=backend, initial=initial, factor=factor,
                max_cycles=max_cycles, spectral_scale=spectral_scale, progress=progress,
            )  # fmt: skip
        except ConvergenceError as stalled:
            values, vectors, info = _fallback(H, A, k, shift, tol, spectral_scale, str(stalled))
    _report(progress, k, k)
    fix_signs(vectors)
    return values, vectors, replace(info, seconds=time.perf_counter() - start)


def _report(progress, converged: int, k: int) -> None:
    if progress is not None:
        progress(int(converged), int(k))


def _fallback(H, A, k: int, shift: float, tol: float, spectral_scale: float, stalled: str):
    """When the block Krylov solver stalls: a dense solve where it fits, else ARPACK (scipy's eigsh) in
    shift-invert mode about the same shift. ``SolveInfo.fallback`` says why; ConvergenceError if both fail."""
    n = H.shape[0]
    if n <= _DENSE_LIMIT_N:
        try:
            values, vectors = _dense_eigh(H, A, k)
            return values, vectors, SolveInfo("dense", fallback=f"krylov stalled ({stalled})")
        except ResourceError:
            pass
    try:
        start = np.random.default_rng(12345).standard_normal(n)  # deterministic; a wide basis for multiplets
        values, vectors = spla.eigsh(H, k, M=A, sigma=shift, which="LM", tol=tol, maxiter=max(300, 10 * k),
                                     ncv=min(n, 3 * k + 20), v0=start)  # fmt: skip
    except spla.ArpackNoConvergence:
        raise ConvergenceError(f"{stalled}; ARPACK (scipy eigsh) did not converge either") from None
    order = np.argsort(values)
    values, vectors = values[order], vectors[:, order]
    residual = np.linalg.norm(H @ vectors - (A @ vectors) * values, axis=0) / np.linalg.norm(A @ vectors, axis=0)
    largest = float(np.max(residual / np.maximum(np.abs(values), residual_floor(values, spectral_scale))))
    return (
        values,
        vectors,
        SolveInfo("arpack", max_residual=largest, shift=shift, fallback=f"krylov stalled ({stalled})"),
    )


def _by_components(H, A, k: int, labels: np.ndarray, initial, options: dict):
    """The k smallest eigenpairs of a pencil that decouples into the pieces ``labels`` (n,): each piece
    solved on its own for min(k, its size) pairs, and the k smallest of all of them kept.

    A pencil of c pieces has c copies of every eigenvalue the pieces share (c zero modes for the LBO), and a
    Krylov space grown from a block of b vectors holds at most b copies of an eigenvalue: with c > b it
    would miss some, and no residual test notices. Solved per piece, every eigenvalue is simple or a
    multiplet of the piece itself.
    """
    n = H.shape[0]
    H, A = sp.csr_matrix(H), sp.csr_matrix(A)
    start = time.perf_counter()
    found = []  # (values, vectors, rows, info) per piece
    for piece in range(labels.max() + 1):
        rows = np.flatnonzero(labels == piece)
        wanted = min(k, len(rows))
        method = options["method"] if 3 * wanted < len(rows) and len(rows) > _DENSE_MAX_N else "dense"
        local = None if initial is None else np.asarray(initial).reshape(n, -1)[rows]
        part = dict(options, method=method, device=options["device"] if method != "dense" else "cpu")
        values, vectors, info = generalized_eigsh(H[rows][:, rows], A[rows][:, rows], wanted, initial=local, **part)
        found.append((values, vectors, rows, info))
    values = np.concatenate([f[0] for f in found])
    order = np.argsort(values, kind="stable")[:k]
    piece_of = np.concatenate([np.full(len(f[0]), i) for i, f in enumerate(found)])[order]
    column_of = np.concatenate([np.arange(len(f[0])) for f in found])[order]
    X = np.zeros((n, k))
    for j, (piece, column) in enumerate(zip(piece_of, column_of)):
        X[found[piece][2], j] = found[piece][1][:, column]
    largest = max(found, key=lambda f: len(f[2]))[3]
    info = SolveInfo(
        largest.method,
        max(f[3].cycles for f in found),
        sum(f[3].solves for f in found),
        max(f[3].max_residual for f in found),
        time.perf_counter() - start,
        largest.shift,
        "; ".join(sorted({f[3].fallback for f in found if f[3].fallback})),
    )
    return values[order], X, info


def _resolve_method(method: str, device: str, n: int, k: int) -> str:
    """What ``method="auto"`` means for n vertices and k pairs: Chebyshev on a GPU, the dense solver for small
    problems or k >= n/3, the shift-invert Krylov solver otherwise; other methods are returned as given."""
    if method != "auto":
        return method
    return "chebyshev" if device == "cuda" else "dense" if (n <= _DENSE_MAX_N or 3 * k >= n) else "krylov"


def _dense_eigh(H, A, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The k smallest pairs by a dense LAPACK solve: the policy for small meshes and for k close to n.

    The memory check counts what the solve allocates — the two dense matrices, LAPACK's copies of them and
    the eigenvectors — and refuses, before anything is allocated, a solve that does not fit or n > 20000.
    """
    n = H.shape[0]
    need = 8 * (4 * n * n + 2 * n * k)
    if n > _DENSE_LIMIT_N:
        raise SolverError(
            f"k = {k} of n = {n} needs a dense eigensolve ({need / 1e9:.0f} GB): ask for fewer than n/3 eigenpairs "
            "to use the sparse solver"
        )
    require_memory(need, f"a dense eigensolve of n = {n} (k = {k})")
    return sla.eigh(H.toarray(), A.toarray(), subset_by_index=[0, k - 1])


def _chebyshev(H, A, k, tol, device, initial, spectral_scale, return_block=False):
    """:func:`hamsa.chebyshev.chebyshev_eigsh` on a lumped mass: (values, vectors, SolveInfo, the whole Ritz
    block or None)."""
    from hamsa.chebyshev import chebyshev_eigsh

    mass = _MassOperator(A)
    if not mass.is_diagonal:
        raise SolverError("method 'chebyshev' needs a lumped (diagonal) mass matrix; use 'krylov' for mass='full'")
    values, vectors, details = chebyshev_eigsh(
        H, mass.diagonal, k, tol=tol, device=device, initial=initial, return_block=return_block,
        spectral_scale=spectral_scale,
    )  # fmt: skip
    info = SolveInfo(
        "chebyshev", details["iterations"], details["products"] * details["block"], details["max_residual"]
    )
    return values, vectors, info, details.get("ritz_block")


def fix_signs(vectors: np.ndarray) -> np.ndarray:
    """Flip columns in place so that each one's first entry above 1e-3 of its largest magnitude is positive."""
    magnitude = np.abs(vectors)
    first = np.argmax(magnitude >= 1e-3 * magnitude.max(axis=0), axis=0)
    signs = np.sign(vectors[first, np.arange(vectors.shape[1])])
    signs[signs == 0] = 1.0
    vectors *= signs
    return vectors


def _orthonormalize(Z: np.ndarray, mass, floor: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A-orthonormal Qn with ``Z = Qn @ R``, dropping directions of A-norm below ``floor``.

    SVQB (Stathopoulos & Wu 2002) applied twice: all BLAS-3, and the second pass restores the
    orthogonality the first loses on ill-conditioned blocks, so the relation Z = Qn R stays exact.
    """
    Qn, R = Z, np.eye(Z.shape[1])
    for _ in range(2):
        AQn = mass(Qn)
        gram = Qn.T @ AQn
        s, U = np.linalg.eigh((gram + gram.T) / 2)
        keep = s > max(floor**2, 1e-24 * s.max(initial=0.0))
        Qn = Qn @ (U[:, keep] / np.sqrt(s[keep]))
        R = (U[:, keep] * np.sqrt(s[keep])).T @ R
    return np.asfortranarray(Qn), mass(Qn), R


class _MassOperator:
    """The mass matrix A as the solvers use it: products (a diagonal fast path), A-norms, the diagonal
    A^-1 weights of residual norms, and Gram-Schmidt passes in the A inner product.

    The passes write their (n, m) temporaries into two buffers kept for the whole solve: fresh arrays of
    that size cost page faults on every pass, a third of a pass's time at 200k vertices.
    """

    def __init__(self, A: sp.spmatrix):
        self.matrix = A.tocsr()
        diagonal = A.diagonal()
        self.is_diagonal = A.nnz == np.count_nonzero(diagonal)
        self.diagonal = diagonal
        self.inverse_diagonal = 1.0 / diagonal
        self._buffers = [np.empty((A.shape[0], 0), order="F") for _ in range(2)]

    def __call__(self, X: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        if self.is_diagonal:
            return np.multiply(X, self.diagonal[:, None] if X.ndim == 2 else self.diagonal, out=out)
        return self.matrix @ X

    def norms(self, X: np.ndarray) -> np.ndarray:
        """The A-norms of the columns of X (n, m)."""
        if self.is_diagonal:
            return np.sqrt(np.einsum("ij,ij,i->j", X, X, self.diagonal))
        return np.sqrt(np.maximum(np.einsum("ij,ij->j", X, self.matrix @ X), 0.0))

    def buffer(self, slot: int, columns: int) -> np.ndarray:
        """Scratch (n, columns), F-ordered: slot 0 or 1, overwritten by the next pass."""
        if self._buffers[slot].shape[1] < columns:
            self._buffers[slot] = np.empty((self.matrix.shape[0], columns), order="F")
        return self._buffers[slot][:, :columns]

    def project_out(self, X: np.ndarray, basis: np.ndarray, a_basis=None) -> np.ndarray:
        """One classical Gram-Schmidt pass, in place: ``X -= basis @ C`` with ``C = basis.T A X`` (basis
        A-orthonormal; ``a_basis`` = A basis, or None to apply A to X); returns C."""
        if a_basis is None:
            C = basis.T @ self(X, out=self.buffer(0, X.shape[1]) if self.is_diagonal else None)
        else:
            C = a_basis.T @ X
        X -= np.matmul(basis, C, out=self.buffer(1, X.shape[1]))
        return C

    def orthogonalize(self, Z: np.ndarray, Q: np.ndarray, AQ=None) -> np.ndarray:
        """Remove from Z, in place, its A-projection on span(Q) (Q A-orthonormal; AQ = A Q, or None to
        apply A on the fly): classical Gram-Schmidt, BLAS-3, a further pass only where the one before
        removed most of a column (the DGKS test; "twice is enough", Kahan-Parlett). Returns C with
        ``Z_in = Q @ C + Z_out``; an F-ordered Z is fastest."""
        coefficients = np.zeros((Q.shape[1], Z.shape[1]))
        for _ in range(3):
            before = self.norms(Z)
            coefficients += self.project_out(Z, Q, AQ)
            if not np.any(self.norms(Z) < 0.5 * before):
                break
        return coefficients


def _block_krylov(H, A, k, *, shift, tol, backend, initial, factor, max_cycles, spectral_scale, progress=None):
    """Block Krylov-Schur for the dominant eigenpairs of S = (H - shift A)^-1 A in <.,.>_A.

    Invariant: Q = [closed | frontier] holds ``S Q_closed = Q T[:, closed]`` exactly up to rounding, and
    T (the projection of S) is known on every column but the frontier's. Q[:, :settled] is A-orthonormal;
    the later columns are so only up to a second Gram-Schmidt pass, deferred to the next settling step
    (see :func:`_extend`), and the solver checks, restarts and stops only after a settling step. The Ritz
    pairs (theta, y) of T_closed then have the residual ``S x - theta x = Q_f (T[f, closed] y)``, and in
    the original pencil ``H x - E A x = -(H - shift A) Q_f T[f, closed] y / theta`` with E = shift + 1/theta:
    exact residual norms at the cost of one sparse product with the frontier block.
    """
    n = H.shape[0]
    mass = _MassOperator(A)
    K = (H - shift * A).tocsc()
    if factor is None:
        factor = CholeskySolver(K, backend)
    else:
        factor.refactor(K)
    guard = max(8, k // 5)
    wanted = min(k + guard, n)
    # Small blocks keep the Krylov polynomial degree high per solve (fewest solves); the basis holds
    # three times the wanted pairs before a thick restart (on a 50k sphere, k = 100: block 8 -> 424 solves,
    # 16 -> 592, 32 -> 1056).
    block = min(max(8, k // 12), 32, n)
    rng = np.random.default_rng(12345)
    first = _start_block(n, block, initial, rng, mass)
    width = first.shape[1]
    # room for the kept Ritz vectors, the frontier and its expansion (blocks never shrink the relation)
    capacity = min(n, max(wanted + 5 * width, 3 * wanted))
    if capacity < n and wanted + 2 * width > capacity:
        raise SolverError(f"k = {k} is too large for the sparse solver on n = {n}: use method='dense'")
    # A Q is kept only for a full mass matrix; a diagonal one is applied on the fly (half the memory)
    copies = 1 if mass.is_diagonal else 2
    # the basis (and its A-image), the projected matrix and its eigenvectors, the Ritz vectors with
    # residuals, and a settling step's pending blocks with the buffers of its pass
    settling = 3 * n * (_DEFERRED_BLOCKS + 1) * block
    need = 8 * (copies * n * capacity + 3 * capacity * capacity + 3 * n * wanted + settling)
    require_memory(need, f"the Krylov basis for k = {k} eigenpairs of n = {n} ({copies} x {capacity} columns)")
    Q = np.empty((n, capacity), order="F")  # column blocks are contiguous
    AQ = None if mass.is_diagonal else np.empty((n, capacity), order="F")
    T = np.zeros((capacity, capacity))
    Q[:, :width] = first[:, :width]
    if AQ is not None:
        AQ[:, :width] = mass(Q[:, :width])
    f0, f1 = 0, width  # frontier columns
    local = 0  # S Q_frontier is A-orthogonal to the columns before this one (exactly: up to rounding)
    settled = f1  # Q[:, :settled] is A-orthonormal to rounding; later columns wait for their second pass
    # light steps (second pass deferred) between settling ones; none when the basis may fill the space
    defer = _DEFERRED_BLOCKS if capacity < n else 0
    light = 0
    solves, cycles = 0, 1
    since_check, check_every = 0, max(1, wanted // (4 * block))
    while True:
        check_due = f1 >= wanted and since_check + 1 >= check_every
        settle = light >= defer or check_due or f1 + 2 * (f1 - f0) > capacity
        Qn, AQn, settled_now = _extend(factor, Q, AQ, T, f0, f1, settled, settle, capacity, block, mass, local, rng)
        solves += f1 - f0
        bn = Qn.shape[1]
        since_check += 1
        light = 0 if settled_now else light + 1
        restart = f1 + 2 * bn > capacity or bn == 0  # only after a settling step
        # Rayleigh-Ritz on the closed part, every few blocks (an eigh of T per block would cost more
        # than the solves) and before every restart, on a settled basis
        if restart or (settled_now and f1 >= wanted and since_check >= check_every):
            since_check = 0
            theta, Y, W, E, residual = _ritz(H, T, f1, bn, min(wanted, f1), k, Qn, AQn, shift, mass, spectral_scale)
            _report(progress, np.sum(residual[:k] <= tol), k)
            if len(E) >= k and np.all(residual[:k] <= tol):
                X = Q[:, :f1] @ Y[:, :k]
                return E[:k], X, SolveInfo("krylov", cycles, solves, float(residual[:k].max()), shift=shift)
        if restart:  # thick restart: keep the best `wanted` Ritz vectors
            cycles += 1
            if cycles > max_cycles:
                raise ConvergenceError(
                    f"eigensolver did not converge in {max_cycles} restarts: largest relative residual "
                    f"{residual[:k].max():.2e} > tol {tol:.1e}"
                )
            f0, f1 = _thick_restart(Q, AQ, T, f1, bn, theta, Y, W)
            local = 0  # the new frontier's image has components on every kept Ritz vector
        else:
            local = f0
            f0, f1 = f1, f1 + bn
        if settled_now:
            settled = f1
        Q[:, f0:f1] = Qn
        if AQ is not None:
            AQ[:, f0:f1] = AQn


def _start_block(n: int, block: int, initial, rng, mass) -> np.ndarray:
    """The A-orthonormal first Krylov block: random, or random combinations of ``initial`` (n, p).

    A wide start block would make every Krylov block as wide (4x slower than cold at 50k vertices,
    k = 100); random combinations of the start vectors keep the block narrow and the start rich in the
    wanted eigenvectors and poor in the others.
    """
    start = rng.standard_normal((n, block))
    if initial is not None:
        initial = np.asarray(initial, dtype=np.float64).reshape(n, -1)
        if initial.shape[1] > block:
            initial = initial @ rng.standard_normal((initial.shape[1], block))
        start = np.hstack([initial, start[:, : max(0, block - initial.shape[1])]])
    first, _, _ = _orthonormalize(start, mass, 1e-8 * np.linalg.norm(start, axis=0).max())
    return first


def _cholesky_qr(X: np.ndarray, mass) -> np.ndarray:
    """Replaces X, in place, by the A-orthonormal P with ``X = P R``, R upper triangular; returns R. For
    nearly A-orthonormal X (Cholesky QR loses orthogonality as cond(X)^2, about 1 here). Triangular, so
    span(P[:, :j]) = span(X[:, :j]) for every j: a block Krylov basis stays one."""
    gram = X.T @ mass(X, out=mass.buffer(0, X.shape[1]) if mass.is_diagonal else None)
    R = np.linalg.cholesky((gram + gram.T) / 2).T
    X[:] = np.matmul(X, np.linalg.inv(R), out=mass.buffer(1, X.shape[1]))
    return R


def _columns(matrix, start, stop):
    return None if matrix is None else matrix[:, start:stop]


def _extend(factor, Q, AQ, T, f0, f1, settled, settle, capacity, block, mass, local, rng):
    """One block Krylov step ``Z = S Q[:, f0:f1]`` (S Q_frontier), orthogonalized and A-orthonormalized into
    the new block (Qn, A Qn); its coefficients go into T's frontier columns and rows, its coupling B below
    them. Returns (Qn, AQn, whether the step settled the basis).

    In exact arithmetic Z is A-orthogonal to every column before ``local`` (the previous block's first),
    so one Gram-Schmidt pass over Q[:, local:f1] leaves only rounding there, and a second pass over all of
    Q removes it. That pass reads the whole (n, f1) basis and is what a step costs (it is memory-bound),
    so it is deferred: a step that does not ``settle`` keeps its new block after the local pass alone
    (pending; the columns Q[:, settled:f1] are pending), and a settling step takes all pending columns and
    Z through one joint pass over Q[:, :settled] (:func:`_settle`). A step settles anyway when its local
    pass removed most of a column (the rounding left behind would be amplified) or its block loses rank.
    An invariant subspace continues from fresh random directions.
    """
    n, width = Q.shape[0], f1 - f0
    Z = np.asfortranarray(factor.solve(mass(Q[:, f0:f1])))
    norms = mass.norms(Z)
    floor = 1e-13 * norms.max()
    coefficients = np.zeros((f1, width))
    coefficients[local:] = mass.project_out(Z, Q[:, local:f1], _columns(AQ, local, f1))
    settle = settle or bool(np.any(mass.norms(Z) < _CANCELLATION * norms))
    if not settle:
        Qn, AQn, B = _orthonormalize(Z, mass, floor)
        settle = Qn.shape[1] < width
    if not settle:
        T[:f1, f0:f1] = coefficients
        T[f0:f1, :f1] = coefficients.T
        T[f0:f1, f0:f1] = (coefficients[f0:f1] + coefficients[f0:f1].T) / 2
    else:
        Z, frontier_scale = _settle(Q, AQ, T, Z, coefficients, f0, f1, settled, mass)
        room = capacity - f1
        Qn, AQn, B = _orthonormalize(Z, mass, floor)
        B = B @ frontier_scale
        if Qn.shape[1] > room:  # only when the basis is the whole space (capacity == n): S Q is in span(Q)
            Qn, AQn, B = Qn[:, :0], AQn[:, :0], B[:0]
        if Qn.shape[1] == 0 and room > 0:  # an invariant subspace: continue from fresh random directions
            Z = np.asfortranarray(rng.standard_normal((n, min(block, room))))
            mass.orthogonalize(Z, Q[:, :f1], _columns(AQ, 0, f1))
            Qn, AQn, _ = _orthonormalize(Z, mass, 1e-8)
            B = np.zeros((Qn.shape[1], width))
    bn = Qn.shape[1]
    T[f1 : f1 + bn, f0:f1] = B
    T[f0:f1, f1 : f1 + bn] = B.T
    return Qn, AQn, settle


def _settle(Q, AQ, T, Z, coefficients, f0, f1, settled, mass):
    """The deferred pass of :func:`_extend`: the pending columns Q[:, settled:f1] and Z (after its local
    pass, with ``coefficients`` (f1, b) on the columns as they were) jointly orthogonalized against
    Q[:, :settled]; the pending columns A-orthonormalized in place by a triangular R, and Z against them.

    T follows the change of basis exactly: ``Q_old[:, settled:f1] = Q[:, :settled] C + Q_new[:, settled:f1] R``
    means ``Q_old = Q_new G^-1`` with ``G^-1 = [[I, C], [0, R]]``, so ``S Q_new = Q_new (G^-1 T G)``. Writes
    T[:f1, :f1] (symmetrized) and returns Z, A-orthogonal to all of Q[:, :f1], and the frontier's block of
    R^-1, by which the frontier's coupling to the next block scales.
    """
    pending, width = f1 - settled, f1 - f0
    if pending:  # the joint block in place, Z in the columns the next block will take (always free)
        Q[:, f1 : f1 + width] = Z
        Z = Q[:, f1 : f1 + width]
    G = mass.orthogonalize(Q[:, settled : f1 + width] if pending else Z, Q[:, :settled], _columns(AQ, 0, settled))
    T[:f1, f0:f1] = coefficients  # S Q_old[:, f] in the old basis
    view = T[:f1, :f1]
    frontier_scale = np.eye(width)
    if pending:
        C = G[:, :pending]
        P = Q[:, settled:f1]
        R = _cholesky_qr(P, mass)
        if AQ is not None:
            AQ[:, settled:f1] = mass(P)
        view[:settled] += C @ view[settled:]  # rows: T <- G^-1 T
        view[settled:] = R @ view[settled:]
        view[settled:, f0:] += mass.orthogonalize(Z, P, _columns(AQ, settled, f1))
        R_inverse = np.linalg.inv(R)
        view[:settled, f0:] += G[:, pending:]
        view[:, settled:] = (view[:, settled:] - view[:, :settled] @ C) @ R_inverse  # columns: T <- T G
        frontier_scale = R_inverse[-width:, -width:]
    else:
        view[:, f0:] += G
    view[:] = (view + view.T) / 2
    return Z, frontier_scale


def _ritz(H, T, f1, bn, m, k, Qn, AQn, shift, mass, spectral_scale):
    """Rayleigh-Ritz on the closed part T[:f1, :f1]: (theta, Y) dominant first, W (bn, m) with
    ``S x_i - theta_i x_i = Qn W[:, i]``, the pencil's eigenvalues E (m,) and their relative residuals."""
    theta, Y = np.linalg.eigh(T[:f1, :f1])
    theta, Y = theta[::-1], Y[:, ::-1]  # dominant first = smallest E first
    W = T[f1 : f1 + bn, :f1] @ Y[:, :m]
    if bn:
        KQn = H @ Qn - shift * AQn
        gram = KQn.T @ (KQn * mass.inverse_diagonal[:, None])
        residual_norm = np.sqrt(np.maximum(np.einsum("ij,ij->j", W, gram @ W), 0.0)) / np.abs(theta[:m])
    else:
        residual_norm = np.zeros(m)
    E = shift + 1.0 / theta[:m]
    scale = np.maximum(np.abs(E), residual_floor(E[: min(k, m)], spectral_scale))
    return theta, Y, W, E, residual_norm / scale


def _thick_restart(Q, AQ, T, f1, bn, theta, Y, W) -> tuple[int, int]:
    """Keep the p = W.shape[1] best Ritz vectors as the new closed part (T diagonal there, coupled to the
    pending block by W); returns the new frontier columns (p, p + bn)."""
    p = W.shape[1]
    Q[:, :p] = Q[:, :f1] @ Y[:, :p]
    if AQ is not None:
        AQ[:, :p] = AQ[:, :f1] @ Y[:, :p]
    T[:] = 0.0
    T[np.arange(p), np.arange(p)] = theta[:p]
    T[p : p + bn, :p] = W
    T[:p, p : p + bn] = W.T
    return p, p + bn


class HamiltonianEigensolver:
    """The k smallest eigenpairs of ``(W + A diag(V)) psi = E A psi`` for a sequence of potentials.

    For loops that change only the potential (potential optimization, continuation, robustness
    sweeps). Each :meth:`solve` reuses what the last one left: the operators W and A, the symbolic
    analysis of the sparse Cholesky factorization (a new V changes only the diagonal), and the last
    eigenvectors as the Krylov start (a warm start). It also keeps eigenpairs recognizable across
    calls: each new eigenvector's sign is chosen to agree with the previous eigenvector it overlaps
    most, and :attr:`continues` says which previous eigenpair each new one continues (eigenvalues stay
    ascending, so two pairs that cross swap places and ``continues`` shows it).

    Parameters
    ----------
    stiffness, mass : sparse (n, n)
        W and A (see :func:`hamsa.operators.stiffness_matrix`, :func:`hamsa.operators.mass_matrix`).
    k : int
    tol, method, backend, device
        As in :func:`eigenbasis`. With ``method="chebyshev"`` (the choice on ``device="cuda"``) the warm
        start is the previous call's whole Ritz block, kept on the device: after a 5% change of V,
        1.5-1.7x fewer sparse products than a cold solve (10k vertices, k = 50; only the k vectors:
        1.03-1.13x).
    mass_kind : str
        Recorded in the returned bases.

    Examples
    --------
    >>> import numpy as np, hamsa
    >>> mesh = hamsa.shapes.capsule()  # a capsule along x
    >>> solver = HamiltonianEigensolver.for_mesh(mesh, k=3)
    >>> first = solver.solve()  # the LBO
    >>> second = solver.solve(0.5 * mesh.vertices[:, 0] ** 2)  # warm-started
    >>> solver.continues.tolist()  # each eigenpair continues the one at the same place
    [0, 1, 2]
    >>> bool(np.all(np.diag(solver.overlap) > 0.99))  # with the same signs
    True
    """

    def __init__(
        self,
        stiffness,
        mass,
        k: int,
        *,
        tol: float = 1e-10,
        method: str = "auto",
        backend: str = "auto",
        mass_kind: str = "voronoi",
        spectral_scale: float | None = None,
        device: str = "cpu",
    ):
        self.stiffness = sp.csr_matrix(stiffness)
        self.mass = sp.csr_matrix(mass)
        self.k, self.tol, self.method, self.backend, self.device = k, tol, method, backend, device
        self.mass_kind = mass_kind
        self.spectral_scale = spectral_scale
        self.factor: CholeskySolver | None = None
        self._block = None  # the Chebyshev solver's last Ritz block (on its device)
        self._pieces = connected_components(abs(self.stiffness) + abs(self.mass), directed=False)[0]
        self.basis: Eigenbasis | None = None
        self.continues: np.ndarray | None = None
        self.overlap: np.ndarray | None = None

    @classmethod
    def for_mesh(
        cls, mesh, k: int, mass: str = "voronoi", laplacian: str | None = None, **options
    ) -> HamiltonianEigensolver:
        """A solver on a mesh's (or point cloud's) stiffness and lumped mass (``mass`` "voronoi" or
        "barycentric"; ``laplacian`` as in :func:`eigenbasis`)."""
        if mass not in ("voronoi", "barycentric"):
            raise HamsaError(f"HamiltonianEigensolver needs a lumped mass ('voronoi' or 'barycentric'), got {mass!r}")
        shape = as_shape(mesh)
        laplacian = default_laplacian(shape) if laplacian is None else laplacian
        stiffness, lumped = laplacian_operators(shape, mass, laplacian)
        return cls(
            stiffness,
            lumped,
            k,
            mass_kind=mass if laplacian == "cotan" else laplacian,
            spectral_scale=4 * np.pi / float(lumped.sum()),
            **options,
        )

    def solve(self, potential=None) -> Eigenbasis:
        """The eigenbasis for potential V (n,) (None: V = 0), warm-started from the previous call."""
        n = self.stiffness.shape[0]
        V = np.zeros(n) if potential is None else check_potential(potential, n)
        H = self.stiffness + self.mass @ sp.diags(V)
        method = _resolve_method(self.method, self.device, n, self.k)
        if method == "krylov" and self.factor is None:  # factored (once per solve) inside generalized_eigsh
            self.factor = CholeskySolver.unfactored(H.shape, self.backend)
        previous = self.basis
        if method == "chebyshev" and self._pieces == 1:  # the whole Ritz block (guard vectors too) is the next start
            start = time.perf_counter()
            values, vectors, info, self._block = _chebyshev(
                H, self.mass, self.k, self.tol, self.device, self._block, self.spectral_scale or 0.0, return_block=True
            )
            fix_signs(vectors)
            info = replace(info, seconds=time.perf_counter() - start)
        else:
            values, vectors, info = generalized_eigsh(
                H,
                self.mass,
                self.k,
                lower_bound=float(V.min()),
                method=method,
                tol=self.tol,
                backend=self.backend,
                initial=None if previous is None else previous.vectors,
                spectral_scale=self.spectral_scale,
                factor=self.factor if method == "krylov" else None,
                device=self.device,
            )
        if previous is None:
            self.continues, self.overlap = np.arange(self.k), None
        else:
            self.overlap = vectors.T @ (self.mass @ previous.vectors)  # (k, k) A-inner products
            self.continues = np.argmax(np.abs(self.overlap), axis=1)
            signs = np.sign(self.overlap[np.arange(self.k), self.continues])
            signs[signs == 0] = 1.0
            vectors *= signs
            self.overlap *= signs[:, None]
        self.basis = Eigenbasis(values, vectors, self.mass, V if potential is not None else None, self.mass_kind, info)
        return self.basis
