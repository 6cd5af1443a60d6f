"""Geodesic distances by the heat method (Crane, Weischedel, Wardetzky 2013), on hamsa's own operators.

1. Diffuse heat from the sources for a short time t: ``(A + t W) u = A delta``.
2. Normalize its gradient per face: ``X = -grad u / |grad u|``.
3. Recover the distance from ``W phi = -div X`` (our W is PSD, so the sign flips from the paper's L).
Accuracy: with the default ``t = h^2`` (h the mean edge length) the error is first order in h, largest
near the source's cut locus (``tests/test_potentials.py`` bounds it against great-circle distances).
Boundaries get the Neumann solution only. Vertices in connected components without a source are
infinitely far; ``unreachable=`` says what to put there instead (a value, the farthest reachable distance,
or an error). ``normalize=True`` divides by the largest finite distance, giving the [0, 1] landmark
potential of the paper's ICSKM and diffusion experiments. On a :class:`~hamsa.pointcloud.PointCloud`
the same steps run on the cloud's local tangent-plane triangulations (Sharp & Crane 2020, potpourri3d's
point-cloud heat solver, the ``[pointcloud]`` extra): :class:`PointCloudGeodesicSolver`.

``method="exact"`` gives the exact distances of the polyhedral surface instead (:class:`ExactGeodesicSolver`:
the MMP window propagation of Mitchell, Mount & Papadimitriou 1987 in Kirsanov's implementation, through
pygeodesic, the ``[geodesics]`` extra), as the published Kim et al. curves use; slower by orders of magnitude.
Every solver answers ``distance`` (from the nearest source), ``distances_from`` (one column per source) and
``between`` (the distance of each pair of vertices).
"""

from __future__ import annotations

import numpy as np

from hamsa.errors import HamsaError, MissingDependencyError, SolverError
from hamsa.factorization import CholeskySolver
from hamsa.mesh import as_trimesh
from hamsa.operators import divergence_matrix, face_gradients, mass_matrix, stiffness_matrix
from hamsa.pointcloud import PointCloud, as_shape


class GeodesicSolver:
    """Heat-method distances with both factorizations computed once, for many source sets.

    Parameters
    ----------
    mesh : TriMesh or (vertices, faces)
    t : float, optional
        Diffusion time; default the squared mean edge length.
    """

    def __init__(self, mesh, t: float | None = None):
        self.mesh = as_trimesh(mesh)
        self.mesh.require_operator_ready()
        W = stiffness_matrix(self.mesh)
        self._mass = mass_matrix(self.mesh)
        self.t = self.mesh.mean_edge_length**2 if t is None else float(t)
        self._heat = CholeskySolver((self._mass + self.t * W).tocsc())
        # W is singular (constants); a tiny mass shift makes it definite without moving the solution,
        # since the divergence sums to zero on every component.
        self._poisson = CholeskySolver(
            (W + 1e-10 * W.diagonal().mean() / self._mass.diagonal().mean() * self._mass).tocsc()
        )
        self._components = self.mesh.vertex_components[1]
        self._divergence = divergence_matrix(self.mesh)

    def distance(self, sources, *, normalize: bool = False, unreachable=np.inf) -> np.ndarray:
        """(n,) distances from the nearest of ``sources`` (vertex indices), 0 at the sources; ``normalize``
        and ``unreachable`` as in :func:`geodesic_distance`."""
        index = _check_sources(sources, self.mesh.n_vertices)
        delta = np.zeros(self.mesh.n_vertices)
        delta[index] = self._mass.diagonal()[index]
        phi = self._potential(delta)
        distance = np.full(self.mesh.n_vertices, np.inf)
        for component in np.unique(self._components[index]):
            members = self._components == component
            at_sources = index[self._components[index] == component]
            distance[members] = np.maximum(phi[members] - phi[at_sources].min(), 0.0)
        distance[index] = 0.0  # with several sources the heat method's values there differ by O(h)
        return _finish(distance, normalize, unreachable)

    def distances_from(self, sources, *, normalize: bool = False, unreachable=np.inf) -> np.ndarray:
        """(n, s) distances from each source separately (column j from ``sources[j]``), in one batch;
        ``normalize`` and ``unreachable`` apply per column, as in :func:`geodesic_distance`."""
        index = _check_sources(sources, self.mesh.n_vertices)
        n = self.mesh.n_vertices
        delta = np.zeros((n, len(index)))
        delta[index, np.arange(len(index))] = self._mass.diagonal()[index]
        phi = self._potential(delta)
        distance = np.maximum(phi - phi[index, np.arange(len(index))], 0.0)
        distance[self._components[:, None] != self._components[index][None, :]] = np.inf
        distance[index, np.arange(len(index))] = 0.0
        return _finish(distance, normalize, unreachable)

    def _potential(self, delta: np.ndarray) -> np.ndarray:
        """Steps 1-3 of the heat method for one (n,) or several (n, s) initial heat distributions."""
        u = self._heat.solve(delta)
        grad = face_gradients(self.mesh, u)  # (m, 3) or (m, 3, s)
        norm = np.linalg.norm(grad, axis=1, keepdims=True)
        X = -grad / np.where(norm > 0, norm, 1.0)
        return self._poisson.solve(-(self._divergence @ X.reshape(3 * len(X), -1)).reshape(u.shape))

    def between(self, sources, targets) -> np.ndarray:
        """(s,) distance from ``sources[i]`` to ``targets[i]`` (vertex ids), one heat solve per distinct source."""
        return _between_by_columns(self.distances_from, sources, targets, self.mesh.n_vertices)


class PointCloudGeodesicSolver:
    """Heat-method distances on a point cloud (potpourri3d's ``PointCloudHeatSolver``), prefactored once.

    The interface of :class:`GeodesicSolver`. Points in pieces of the cloud that no source's piece joins
    (see :attr:`PointCloud.vertex_components`) are unreachable. Accuracy on a well-sampled smooth surface
    is comparable to the mesh heat method's (first order in the point spacing).

    Parameters
    ----------
    cloud : PointCloud
    t_coef : float
        Diffusion time as a multiple of the squared mean point spacing.
    """

    def __init__(self, cloud: PointCloud, t_coef: float = 1.0):
        try:
            import potpourri3d
        except ImportError:
            raise MissingDependencyError(
                "geodesic distances on point clouds need potpourri3d: pip install 'hamsa[pointcloud]'"
            ) from None
        self.cloud = cloud
        self._solver = potpourri3d.PointCloudHeatSolver(cloud.vertices, t_coef=t_coef)
        self._components = cloud.vertex_components[1]

    def distance(self, sources, *, normalize: bool = False, unreachable=np.inf) -> np.ndarray:
        """(n,) distances from the nearest of ``sources`` (point ids), as :meth:`GeodesicSolver.distance`."""
        index = _check_sources(sources, self.cloud.n_vertices)
        distance = np.maximum(self._solver.compute_distance_multisource(index.tolist()), 0.0)
        distance[~np.isin(self._components, self._components[index])] = np.inf
        distance[index] = 0.0
        return _finish(distance, normalize, unreachable)

    def distances_from(self, sources, *, normalize: bool = False, unreachable=np.inf) -> np.ndarray:
        """(n, s) distances from each source separately, as :meth:`GeodesicSolver.distances_from`."""
        index = _check_sources(sources, self.cloud.n_vertices)
        distance = np.stack([np.maximum(self._solver.compute_distance(int(i)), 0.0) for i in index], axis=1)
        distance[self._components[:, None] != self._components[index][None, :]] = np.inf
        distance[index, np.arange(len(index))] = 0.0
        return _finish(distance, normalize, unreachable)

    def between(self, sources, targets) -> np.ndarray:
        """(s,) distance from ``sources[i]`` to ``targets[i]`` (point ids), as :meth:`GeodesicSolver.between`."""
        return _between_by_columns(self.distances_from, sources, targets, self.cloud.n_vertices)


class ExactGeodesicSolver:
    """Exact geodesic distances of the polyhedral surface, by MMP window propagation (pygeodesic).

    The interface of :class:`GeodesicSolver`, without a diffusion time: the distances are those of the
    piecewise-flat surface itself, to rounding, on any triangulation the strict validation accepts.
    Vertices in components without a source are unreachable. Each source is one propagation, whose cost
    grows with the area it sweeps (superlinearly in n for a whole mesh); :meth:`between` stops each
    propagation at a radius that it grows only while a target is still beyond it, so close pairs (the
    errors of a good map) cost a fraction of a whole-mesh propagation.

    Parameters
    ----------
    mesh : TriMesh or (vertices, faces)

    Raises
    ------
    MissingDependencyError
        Without pygeodesic (``pip install 'hamsa[geodesics]'``).
    """

    def __init__(self, mesh):
        try:
            from pygeodesic.geodesic import PyGeodesicAlgorithmExact
        except ImportError:
            raise MissingDependencyError("exact geodesics need pygeodesic: pip install 'hamsa[geodesics]'") from None
        self.mesh = as_trimesh(mesh)
        self.mesh.require_operator_ready()
        self._algorithm = PyGeodesicAlgorithmExact(
            np.ascontiguousarray(self.mesh.vertices, dtype=np.float64),
            np.ascontiguousarray(self.mesh.faces, dtype=np.int32),
        )

    def _propagate(self, sources: np.ndarray, targets: np.ndarray | None = None, radius: float = np.inf):
        """Distances at ``targets`` (default every vertex) from the nearest of ``sources``, inf where
        unreachable; with a finite ``radius``, None when the propagation stopped before reaching them all."""
        try:
            distance, _ = self._algorithm.geodesicDistances(
                sources.astype(np.int32), None if targets is None else targets.astype(np.int32), min(radius, 1e100)
            )
        except OverflowError:  # pygeodesic reads an unset "best source" of a vertex the stopped front touched
            if np.isfinite(radius):
                return None
            raise SolverError("pygeodesic's exact propagation left vertices without a source; the mesh may be "
                              "degenerate (try method='heat')") from None  # fmt: skip
        distance = np.asarray(distance, dtype=np.float64)
        if targets is None:
            distance[sources] = 0.0
        else:
            distance[np.isin(targets, sources)] = 0.0
        if np.isfinite(radius) and not np.isfinite(distance).all():
            return None
        return distance

    def distance(self, sources, *, normalize: bool = False, unreachable=np.inf) -> np.ndarray:
        """(n,) exact distances from the nearest of ``sources``, as :meth:`GeodesicSolver.distance`."""
        index = _check_sources(sources, self.mesh.n_vertices)
        return _finish(self._propagate(index), normalize, unreachable)

    def distances_from(self, sources, *, normalize: bool = False, unreachable=np.inf) -> np.ndarray:
        """(n, s) exact distances from each source separately, as :meth:`GeodesicSolver.distances_from`."""
        index = _check_sources(sources, self.mesh.n_vertices)
        distance = np.stack([self._propagate(index[j : j + 1]) for j in range(len(index))], axis=1)
        return _finish(distance, normalize, unreachable)

    def between(self, sources, targets) -> np.ndarray:
        """(s,) exact distance from ``sources[i]`` to ``targets[i]``: one propagation per distinct source,
        first to 1/20 of sqrt(area), then to 1/4 (the range of the Kim et al. curve), then over the whole
        mesh, stopping as soon as every target of that source is reached (inf for targets in another
        component)."""
        sources, targets = _check_pairs(sources, targets, self.mesh.n_vertices)
        out = np.empty(len(sources))
        unique, inverse = np.unique(sources, return_inverse=True)
        first = np.sqrt(self.mesh.area) / 20
        for position, source in enumerate(unique):
            members = np.flatnonzero(inverse == position)
            for radius in (first, 5 * first, np.inf):
                reached = self._propagate(np.array([source]), targets[members], radius)
                if reached is not None:
                    break
            out[members] = reached
        return out


GEODESIC_METHODS = ("heat", "exact")


def geodesic_solver(
    shape, t: float | None = None, *, method: str = "heat"
) -> GeodesicSolver | PointCloudGeodesicSolver | ExactGeodesicSolver:
    """The geodesic solver of a shape. ``method="heat"``: the heat method on a mesh (:class:`GeodesicSolver`,
    diffusion time ``t``) or a point cloud (:class:`PointCloudGeodesicSolver`, ``t`` as a multiple of the
    squared point spacing, default 1). ``method="exact"``: the polyhedral distances of a mesh
    (:class:`ExactGeodesicSolver`; no ``t``, not for point clouds).

    Raises
    ------
    HamsaError
        On an unknown method, ``t`` with ``"exact"``, or ``"exact"`` on a point cloud.
    """
    shape = as_shape(shape)
    if method not in GEODESIC_METHODS:
        raise HamsaError(f"geodesic method must be one of {GEODESIC_METHODS}, got {method!r}")
    if method == "exact":
        if isinstance(shape, PointCloud):
            raise HamsaError("exact geodesics need a triangle mesh; a point cloud has the heat method only")
        if t is not None:
            raise HamsaError("exact geodesics have no diffusion time: leave t unset")
        return ExactGeodesicSolver(shape)
    if isinstance(shape, PointCloud):
        return PointCloudGeodesicSolver(shape, 1.0 if t is None else float(t))
    return GeodesicSolver(shape, t)


def _check_sources(sources, n: int) -> np.ndarray:
    index = np.atleast_1d(np.asarray(sources))
    if index.size == 0:
        raise HamsaError("no source vertices given")
    if not np.issubdtype(index.dtype, np.integer) or index.min() < 0 or index.max() >= n:
        raise HamsaError(f"source vertices must be integers in [0, {n}), got {sources!r}")
    return index


def _check_pairs(sources, targets, n: int) -> tuple[np.ndarray, np.ndarray]:
    sources, targets = np.asarray(sources), np.asarray(targets)
    if sources.shape != targets.shape or sources.ndim != 1:
        raise HamsaError(f"sources {sources.shape} and targets {targets.shape} must be equal 1-D shapes")
    for name, ids in (("sources", sources), ("targets", targets)):
        if ids.size and (not np.issubdtype(ids.dtype, np.integer) or ids.min() < 0 or ids.max() >= n):
            raise HamsaError(f"{name} must be integer vertex ids in [0, {n})")
    return sources, targets


def _between_by_columns(distances_from, sources, targets, n: int) -> np.ndarray:
    """(s,) distances of vertex pairs from batched (n, b) columns of ``distances_from``, b distinct sources
    at a time (b bounded so the batch's per-face work stays near 2^24 numbers)."""
    sources, targets = _check_pairs(sources, targets, n)
    out = np.empty(len(sources))
    unique, inverse = np.unique(sources, return_inverse=True)
    batch = int(np.clip(2**24 // (6 * n), 1, 256))
    for start in range(0, len(unique), batch):
        table = distances_from(unique[start : start + batch])  # (n, b)
        members = np.flatnonzero((inverse >= start) & (inverse < start + batch))
        out[members] = table[targets[members], inverse[members] - start]
    return out


def geodesic_distance(
    mesh, sources, t: float | None = None, *, method: str = "heat", normalize: bool = False, unreachable=np.inf
):
    """Geodesic distance (n,) from the nearest of ``sources`` (vertex ids), 0 at the sources.

    Parameters
    ----------
    mesh : TriMesh, (vertices, faces) or PointCloud
    sources : vertex (point) ids
    t : diffusion time of the heat method (default the squared mean edge length; see :func:`geodesic_solver`)
    method : ``"heat"`` (default) or ``"exact"`` (polyhedral distances of a mesh, the ``[geodesics]`` extra)
    normalize : divide by the largest finite distance, so the result is in [0, 1] (the landmark potential)
    unreachable : what vertices in pieces without a source get: a number (default ``inf``, the true
        distance; in the normalized units when ``normalize``), ``"farthest"`` (the largest finite
        distance: 1 when normalized), or ``"error"`` to raise

    Raises
    ------
    HamsaError
        On no sources, ids that are not vertex ids, a NaN ``unreachable``, with ``unreachable="error"``
        a piece without a source, or a method :func:`geodesic_solver` refuses. For repeated calls on one
        shape use :func:`geodesic_solver`.
    """
    return geodesic_solver(mesh, t, method=method).distance(sources, normalize=normalize, unreachable=unreachable)


def _finish(distance: np.ndarray, normalize: bool, unreachable) -> np.ndarray:
    """Distances (n,) or (n, s) normalized per column and with the unreachable entries filled."""
    finite = np.isfinite(distance)
    if isinstance(unreachable, str):
        if unreachable not in ("farthest", "error"):
            raise HamsaError(f"unreachable must be a number, 'farthest' or 'error', got {unreachable!r}")
        if unreachable == "error" and not finite.all():
            raise HamsaError(
                "some connected components contain no source, so their distance is infinite (pass unreachable= "
                "a value or 'farthest')"
            )
    elif np.isnan(unreachable):
        raise HamsaError("unreachable must not be NaN")
    farthest = np.where(finite, distance, -np.inf).max(axis=0)
    if normalize:
        distance = distance / farthest
        farthest = farthest / farthest
    fill = farthest if isinstance(unreachable, str) else float(unreachable)
    return np.where(finite, distance, fill)
