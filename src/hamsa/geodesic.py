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
"""

from __future__ import annotations

import numpy as np

from hamsa.errors import HamsaError, MissingDependencyError
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


def geodesic_solver(shape, t: float | None = None) -> GeodesicSolver | PointCloudGeodesicSolver:
    """The heat-method solver for a mesh (:class:`GeodesicSolver`, diffusion time ``t``) or a point cloud
    (:class:`PointCloudGeodesicSolver`, ``t`` as a multiple of the squared point spacing, default 1)."""
    shape = as_shape(shape)
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


def geodesic_distance(mesh, sources, t: float | None = None, *, normalize: bool = False, unreachable=np.inf):
    """Heat-method geodesic distance (n,) from the nearest of ``sources`` (vertex ids), 0 at the sources.

    Parameters
    ----------
    mesh : TriMesh, (vertices, faces) or PointCloud
    sources : vertex (point) ids
    t : diffusion time of the heat method (default the squared mean edge length; see :func:`geodesic_solver`)
    normalize : divide by the largest finite distance, so the result is in [0, 1] (the landmark potential)
    unreachable : what vertices in pieces without a source get: a number (default ``inf``, the true
        distance; in the normalized units when ``normalize``), ``"farthest"`` (the largest finite
        distance: 1 when normalized), or ``"error"`` to raise

    Raises
    ------
    HamsaError
        On no sources, ids that are not vertex ids, a NaN ``unreachable``, or with ``unreachable="error"``
        a piece without a source. For repeated calls on one shape use :func:`geodesic_solver`.
    """
    return geodesic_solver(mesh, t).distance(sources, normalize=normalize, unreachable=unreachable)


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
