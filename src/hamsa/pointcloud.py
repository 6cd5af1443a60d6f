"""Point clouds: the validated :class:`PointCloud` value object and its Laplacian (Sharp & Crane 2020).

A point cloud is an (n, 3) array of points sampling a surface, with no faces. Its operators are the
point-cloud Laplacian of Sharp & Crane, "A Laplacian for Nonmanifold Triangle Meshes" (SGP 2020), sec. 5:
each point's ``neighbors`` nearest points are projected on its tangent plane and Delaunay-triangulated
there; the union of these local triangulations is a non-manifold triangle set whose tufted intrinsic
Delaunay cotan Laplacian (each triangle weighted 1/3) is ``W`` and whose lumped mass is ``A``. ``W`` is
symmetric positive semidefinite with ``W @ 1 = 0`` (hamsa's sign convention) and ``A.sum()`` estimates the
sampled surface's area, so everything in hamsa that needs only (W, A) -- eigenbases of ``W + A diag(V)``,
heat kernels, HKS / WKS, functional maps, ICSKM, potential optimization, compressed manifold modes, nodal
domains over :attr:`PointCloud.edges` -- runs on a cloud unchanged. Geodesic distances on a cloud
come from potpourri3d's point-cloud heat method (:class:`hamsa.geodesic.PointCloudGeodesicSolver`). Needs
the ``[pointcloud]`` extra.

Points know no connectivity, so parts of a shape that nearly touch (fingers of a hand, an arm against the
body) closer than about the neighbourhood's radius would be joined by the local triangulations ("short
circuits"), as they are in robust_laplacian's ``point_cloud_laplacian``. hamsa's own local triangulations
(:attr:`PointCloud.local_triangles`) leave out the neighbours whose outward normal points away from the
point's: the facing sides of two nearly touching parts (the built-in ``shapes.hand("curled")`` as a cloud
then has the mesh's low spectrum, which robust_laplacian's operator misses; see docs/results/point_clouds.md),
and the triangles whose far edge joins two sheets where parts meet along a crease.
``separate_sheets=False`` gives robust_laplacian's operator. The rule never splits the cloud into pieces,
so separate objects that nearly touch stay joined, and where the normals' orientation fails (thin parts,
wide contacts) short circuits stay; ``off_sheet=0.7`` also leaves out the neighbours that lie off a point's
smooth sheet, whatever the normals say. Normals that come with the points (a scanner's: ``normals=``)
replace the estimated ones. Use the mesh when there is one.
"""

from __future__ import annotations

import warnings
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree
from scipy.spatial import cKDTree

from hamsa.errors import InputWarning, MeshError, MissingDependencyError
from hamsa.mesh import TriMesh, as_coordinates, as_trimesh, check_coordinates, format_ids

DEFAULT_NEIGHBORS = 30  # the local triangulation's neighbourhood size (Sharp & Crane's default)
# nearest points of the least-squares gradient and of the normals' orientation graph
GRADIENT_NEIGHBORS = 10
_NORMAL_ROUNDS = 2  # rounds of re-estimating the normals from the local triangulation's stars
# given normals are unoriented when more links to the nearest points than this disagree in sign (consistent
# normals: a few percent, where parts are thin; random signs: half)
_UNORIENTED_LINKS = 0.25
_REJOIN_ROUNDS = 4  # rounds of giving the neighbours back that the sheet rule left in another piece
_FIT_ROUNDS = 8  # reweighting rounds of the robust quadratic fit of a point's sheet (``off_sheet``)
STRAY_NEIGHBORS = 8  # nearest points linked in the stray-point test; larger groups are parts of the cloud
STRAY_JUMP = 15.0  # local spacings: a longer link does not join a point to the rest (:func:`stray_points`)


class PointCloud:
    """A validated point cloud with the point-cloud Laplacian and mass.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        The sample points; converted to float64, order kept (point i is "vertex" i everywhere in hamsa).
    neighbors : int
        Nearest neighbours of each point in its local tangent-plane triangulation; n must exceed it.
    mollify : float
        Intrinsic mollification of near-degenerate local triangles, as a fraction of the mean edge length.
    separate_sheets : bool
        Leave the neighbours on another sheet (outward normals pointing apart) out of each point's local
        triangulation (:attr:`local_triangles`); False: robust_laplacian's ``point_cloud_laplacian`` over
        all ``neighbors`` nearest points.
    off_sheet : float, optional
        With ``separate_sheets``, also leave out the neighbours farther than this many local spacings from
        the point's smooth sheet (:attr:`sheet_offsets`), whatever the normals' signs: it separates parts
        that touch over a wide area, where the normals' orientation fails. None (default): the normals
        alone decide. 0.7 is the measured choice (docs/results/point_clouds.md).
    normals : array_like, shape (n, 3), optional
        Normals that come with the points (a scanner's, a mesh's), used as :attr:`normals` instead of
        estimated ones (rescaled to unit length). Their signs are kept when they are consistent (at most a
        quarter of the links to each point's nearest points join normals of opposite orientation), all
        flipped if they point inward, and their directions oriented as estimated ones are otherwise
        (unoriented normals); :attr:`normals_origin` says which. A patch of wrong signs in consistent normals
        is kept and cuts the surface there. A zero or non-finite row (a point the scanner gave no normal) is
        estimated at that point and oriented like its neighbours' given normals, with an
        :class:`~hamsa.errors.InputWarning`. None (default): estimated.

    Raises
    ------
    MeshError
        If the array is not real (n, 3), has non-finite or huge coordinates, has no more than ``neighbors``
        points or repeats a point (two samples at one place have no tangent-plane triangulation between
        them; remove duplicates first), if ``off_sheet`` is not a positive number or comes with
        ``separate_sheets=False``, or if ``normals`` is not (n, 3).

    Warns
    -----
    InputWarning
        If the cloud has :attr:`stray_points` (each adds a spurious low eigenpair), or if some given normals
        are zero or not finite (estimated there).

    Examples
    --------
    >>> import hamsa
    >>> cloud = hamsa.PointCloud(hamsa.shapes.icosphere(3).vertices)
    >>> basis = hamsa.eigenbasis(cloud, k=4)
    >>> basis.values[1:].round(1).tolist()  # close to the unit sphere's l(l+1) = 2
    [2.0, 2.0, 2.0]
    """

    def __init__(
        self,
        points,
        *,
        neighbors: int = DEFAULT_NEIGHBORS,
        mollify: float = 1e-5,
        separate_sheets: bool = True,
        off_sheet: float | None = None,
        normals=None,
    ):
        points = as_coordinates(points, "points")
        check_coordinates(points, "points", "; repair_point_cloud (--repair on the command line) drops them")
        self._given_normals = None if normals is None else _unit_normals(normals, len(points))
        missing = np.flatnonzero(np.isnan(self._given_normals[:, 0])) if normals is not None else []
        if len(missing):
            warnings.warn(
                f"{len(missing)} of the {len(points)} given normals are zero or not finite ({format_ids(missing)}): "
                + ("estimated at those points" if len(missing) < len(points) else "all estimated"),
                InputWarning,
                stacklevel=2,
            )
        if len(missing) == len(points):
            self._given_normals = None
        if not isinstance(neighbors, (int, np.integer)) or neighbors < 3:
            raise MeshError(f"neighbors must be an integer >= 3, got {neighbors!r}")
        if off_sheet is not None and not (isinstance(off_sheet, (int, float, np.number)) and 0 < off_sheet < np.inf):
            raise MeshError(f"off_sheet must be a positive number of spacings or None, got {off_sheet!r}")
        if off_sheet is not None and not separate_sheets:
            raise MeshError("off_sheet leaves neighbours out, separate_sheets=False keeps them all: choose one")
        if len(points) <= neighbors:
            raise MeshError(
                f"a point cloud needs more than neighbors = {neighbors} points for its local triangulations, "
                f"got {len(points)}"
            )
        distance, nearest = cKDTree(points).query(points, k=min(STRAY_NEIGHBORS + 1, len(points)))
        repeated = np.flatnonzero(distance[:, 1] == 0)
        if len(repeated):
            i = int(repeated[0])
            raise MeshError(
                f"{len(repeated)} points repeat another point exactly ({format_ids(repeated)}; point {i} equals point "
                f"{int(nearest[i, 1]) if nearest[i, 1] != i else int(nearest[i, 0])}): remove the duplicates "
                "(hamsa.repair.repair_point_cloud; --repair on the command line)"
            )
        points.flags.writeable = False
        self._points = points
        self._spacing = distance[:, 1]
        self._stray = stray_points(points, (distance, nearest))
        self._stray.flags.writeable = False
        if len(self._stray):
            warnings.warn(
                f"{len(self._stray)} stray points ({format_ids(self._stray)}) lie more than {STRAY_JUMP:g} local "
                "spacings from the rest of the cloud: each adds a spurious low eigenpair localized on it; "
                "hamsa.repair.repair_point_cloud (--repair on the command line) drops them",
                InputWarning,
                stacklevel=2,
            )
        self.neighbors = int(neighbors)
        self.mollify = float(mollify)
        self.separate_sheets = bool(separate_sheets)
        self.off_sheet = None if off_sheet is None else float(off_sheet)

    @property
    def vertices(self) -> np.ndarray:
        """(n, 3) float64 point coordinates (read-only); named as a mesh's so vertex-wise code serves both."""
        return self._points

    @property
    def points(self) -> np.ndarray:
        """The same array as :attr:`vertices`."""
        return self._points

    @property
    def n_vertices(self) -> int:
        return self._points.shape[0]

    @property
    def normals_origin(self) -> str:
        """Where :attr:`normals` come from: ``"estimated"``, ``"given"`` (the constructor's, their signs kept or
        all flipped outward) or ``"given, re-oriented"`` (their directions, signs made consistent by hamsa),
        followed by ``", estimated at m points"`` when m given rows were zero or not finite."""
        return "estimated" if self._given_normals is None else self._given_oriented[1]

    @cached_property
    def _given_oriented(self) -> tuple[np.ndarray, str]:
        """(the given normals as :attr:`normals` uses them, :attr:`normals_origin`).

        The links from each point to its :data:`GRADIENT_NEIGHBORS` nearest points that join two given normals
        decide: more than :data:`_UNORIENTED_LINKS` of them disagreeing in sign (:func:`_transported_agreement`)
        makes the normals unoriented, and their directions are oriented by :func:`_oriented`; otherwise their
        signs are kept, all flipped if they point inward. A missing row (NaN, :func:`_unit_normals`) takes the
        direction of the plane fitted to the point's nearest points, oriented to agree with the given normals
        of its neighbours (with the orientation :func:`_oriented` gives the whole cloud where it has none)."""
        distances, indices = self._neighbourhoods
        given, n = self._given_normals, self.n_vertices
        missing = np.isnan(given[:, 0])
        rows = np.repeat(np.arange(n), GRADIENT_NEIGHBORS)
        columns = indices[:, 1 : GRADIENT_NEIGHBORS + 1].reshape(-1)
        directions = given.copy()
        directions[missing] = _plane_normals(self._points, indices[missing, : self._fitted])
        known = ~missing[rows] & ~missing[columns]
        agreement = _transported_agreement(self._points, directions, rows, columns)
        estimated = f", estimated at {missing.sum()} points" if missing.any() else ""
        if np.mean(agreement[known] < 0) > _UNORIENTED_LINKS:
            oriented = _oriented(self._points, directions, distances, indices)
            oriented.flags.writeable = False
            return oriented, "given, re-oriented" + estimated
        if np.einsum("ij,ij->", given[~missing], self._points[~missing] - self._points.mean(axis=0)) < 0:
            directions[~missing] *= -1
            agreement *= np.where(missing[rows] == missing[columns], 1.0, -1.0)
        if missing.any():
            votes = np.bincount(rows, np.where(missing[rows] & ~missing[columns], agreement, 0.0), n)[missing]
            overall = _oriented(self._points, directions, distances, indices)
            if np.einsum("ij,ij->", overall[~missing], directions[~missing]) < 0:
                overall *= -1
            directions[missing] *= np.where(votes != 0, np.sign(votes), 0.0)[:, None]
            directions[missing] += np.where(votes == 0, 1.0, 0.0)[:, None] * overall[missing]
        directions.flags.writeable = False
        return directions, "given" + estimated

    def __repr__(self) -> str:
        return (
            f"PointCloud(n_points={self.n_vertices}, neighbors={self.neighbors}, "
            f"separate_sheets={self.separate_sheets}, off_sheet={self.off_sheet}"
            + (")" if self._given_normals is None else f", normals {self.normals_origin})")
        )

    @cached_property
    def operators(self) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        """``(W, A)``: the point-cloud stiffness (PSD, ``W @ 1 = 0``) and lumped mass, both (n, n) csr.

        With ``separate_sheets`` the local triangulations are hamsa's own (:attr:`local_triangles`: each
        point's Delaunay star among the neighbours on its own sheet) and robust_laplacian builds the tufted
        intrinsic Delaunay operators of their union, each triangle weighted 1/3 as in Sharp & Crane;
        without, it is robust_laplacian's ``point_cloud_laplacian`` (all ``neighbors`` nearest points)."""
        try:
            import robust_laplacian
        except ImportError:
            raise MissingDependencyError(
                "the point-cloud Laplacian needs robust_laplacian: pip install 'hamsa[pointcloud]'"
            ) from None
        if not self.separate_sheets:
            W, A = robust_laplacian.point_cloud_laplacian(
                self._points, mollify_factor=self.mollify, n_neighbors=self.neighbors
            )
            return sp.csr_matrix(W), sp.csr_matrix(A)
        W, A = robust_laplacian.mesh_laplacian(self._points, self.local_triangles, mollify_factor=self.mollify)
        return sp.csr_matrix(W) / 3.0, sp.csr_matrix(A) / 3.0

    @cached_property
    def local_triangles(self) -> np.ndarray:
        """(f, 3) point ids: every point's Delaunay star among its ``neighbors`` nearest points on the same
        sheet, projected on its tangent plane (Sharp & Crane 2020, sec. 5); a triangle appears once per
        point whose star holds it (up to three times).

        A neighbour q of p is on another sheet when their outward normals (:attr:`normals`) point apart,
        ``n_p . n_q <= 0``: where two parts of a surface nearly touch (an arm against the body) their
        facing sides have opposite outward normals, and so do the two sides of a part thinner than the
        neighbourhood; joining them would short-circuit the Laplacian. A star triangle (p, a, b) whose
        corners a and b both pass that test can still join two sheets through its edge a b, where two parts
        meet along a crease and p's normal lies between theirs; it is left out when n_a and n_b point apart
        and still do with n_a carried to b along the circle through both (:func:`_transported_agreement`:
        the surface does not turn from a to b, as it does round a sharp fold or a thin part). A wrongly
        oriented normal must not cut the surface itself, hence two safeguards: a point with fewer than two
        neighbours on its sheet keeps all of them and all its triangles, and a neighbour that the rule leaves
        in another piece of the triangulation (a patch of flipped normals, cut off along its rim) is given
        back, the star of a point that the triangle test left in another piece keeps all its triangles, and
        the stars are rebuilt, for up to :data:`_REJOIN_ROUNDS` rounds; if pieces that the neighbourhoods join
        are still apart after them, every point keeps all its neighbours and triangles. With ``off_sheet``, a
        neighbour off the point's smooth sheet (:attr:`sheet_offsets`) is on another sheet too, and the rounds
        give back the neighbours on the smooth sheet first (they are the rim of a flipped patch; the others,
        the gap of a contact). Read-only."""
        return self._sheet_triangulation[0]

    @property
    def separated_neighbours(self) -> int:
        """How many (point, neighbour) pairs of the ``neighbors`` nearest the sheet rule of
        :attr:`local_triangles` leaves out of the point's star (0 without ``separate_sheets``): a measure of
        how much of the cloud lies across a nearly touching or thin part."""
        if not self.separate_sheets:
            return 0
        return int(np.count_nonzero(~self._sheet_triangulation[1]))

    @cached_property
    def _sheet_triangulation(self) -> tuple[np.ndarray, np.ndarray]:
        """(faces (f, 3), same_sheet (n, neighbors) bool): :attr:`local_triangles` and which neighbours its
        stars were built from."""
        smooth = None if self.off_sheet is None else self.sheet_offsets <= self.off_sheet
        faces, same_sheet = self._triangulate(self.normals, smooth)
        faces.flags.writeable = False
        same_sheet.flags.writeable = False
        return faces, same_sheet

    def _triangulate(self, normals: np.ndarray, smooth: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """(faces (f, 3), same_sheet (n, neighbors) bool): the sheet rule of :attr:`local_triangles` with the
        unit normals ``normals`` (n, 3), and with ``smooth`` (n, neighbors) bool, which neighbours lie on the
        point's smooth sheet (``off_sheet``), or None."""
        n, neighbours = self.n_vertices, self._neighbourhoods[1][:, 1:]
        same_sheet = np.einsum("nc,nkc->nk", normals, normals[neighbours]) > 0
        if smooth is not None:
            same_sheet &= smooth
        far_edges = same_sheet.sum(axis=1) >= 2  # the points whose stars drop triangles joining two sheets
        same_sheet[~far_edges] = True
        faces = self._stars(normals, np.arange(n), neighbours, same_sheet, far_edges)
        for attempt in range(_REJOIN_ROUNDS + 1):
            edges = np.vstack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [0, 2]]])
            graph = sp.csr_matrix((np.ones(len(edges)), edges.T), shape=(n, n))
            pieces = connected_components(graph, directed=False)[1]
            apart = pieces[:, None] != pieces[neighbours]
            if not apart.any():
                break
            bridges = apart & ~same_sheet  # neighbours the rule left in another piece
            if smooth is not None and (bridges & smooth).any():
                bridges &= smooth  # first those on the point's smooth sheet (a flipped patch's rim)
            torn = far_edges & (apart & same_sheet).any(axis=1)  # stars whose far-edge test may have cut a piece off
            if attempt == _REJOIN_ROUNDS or not (bridges.any() or torn.any()):  # no sheets are separated anywhere
                same_sheet[:] = True
                faces = self._stars(normals, np.arange(n), neighbours, same_sheet, np.zeros(n, dtype=bool))
                break
            same_sheet |= bridges
            far_edges &= ~(torn | bridges.any(axis=1))  # stars joined back keep all their triangles
            centers = np.flatnonzero(bridges.any(axis=1) | torn)
            rebuilt = self._stars(normals, centers, neighbours, same_sheet, far_edges)
            faces = np.vstack([faces[~np.isin(faces[:, 0], centers)], rebuilt])
        return faces, same_sheet

    @cached_property
    def sheet_offsets(self) -> np.ndarray:
        """(n, neighbors) read-only: how far each of the point's ``neighbors`` nearest points q (in order of
        distance) lies from the point p's smooth sheet, in local spacings
        (the mean distance from p to its six nearest points): ``|w_q - w(u_q)|``, with (u_q, w_q) the
        tangent-plane coordinates and height of q - p, and w(u) = g . u + u^T H u / 2 the quadratic height
        function through p fitted to all neighbours by least squares reweighted with Cauchy weights
        (:data:`_FIT_ROUNDS` rounds, residual scale 1.4826 x the median absolute residual, at least 0.02
        spacings). The points of p's own sheet fit it to the order of the sampling's roughness; the facing
        side of a part that nearly touches, a minority of the neighbourhood, stays off it by the gap."""
        distances, indices = self._neighbourhoods
        neighbours = indices[:, 1:]
        spacing = distances[:, 1:7].mean(axis=1)
        offsets = np.empty(neighbours.shape)
        for rows in _chunks(len(neighbours), 16 * neighbours.shape[1]):  # the fit's (chunk, K, 5) arrays
            design, height, _ = _quadratic_design(self._points, self.normals, rows, neighbours[rows])
            unit = spacing[rows, None, None]  # lengths in local spacings: a well-conditioned fit at any scale
            design[..., :2] /= unit
            design[..., 2:] /= unit**2
            height /= unit[..., 0]
            weights = np.ones_like(height)
            for _ in range(_FIT_ROUNDS):
                normal_matrix = np.einsum("nk,nki,nkj->nij", weights, design, design) + 1e-6 * np.eye(5)
                moments = np.einsum("nk,nki,nk->ni", weights, design, height)
                residual = height - np.einsum(
                    "nki,ni->nk", design, np.linalg.solve(normal_matrix, moments[..., None])[..., 0]
                )
                scale = np.maximum(1.4826 * np.median(np.abs(residual), axis=1, keepdims=True), 0.02)
                weights = 1.0 / (1.0 + (residual / (2.0 * scale)) ** 2)
            offsets[rows] = np.abs(residual)
        offsets.flags.writeable = False
        return offsets

    def _stars(self, normals, ids, neighbours, kept, far_edges) -> np.ndarray:
        """The :func:`_delaunay_stars` of the points ``ids`` with the unit normals ``normals`` (n, 3), in
        memory-bounded chunks, less the triangles (p, a, b) of the points p with ``far_edges[p]`` whose edge
        a b runs between two sheets (:attr:`local_triangles`)."""
        faces = np.vstack([
            _delaunay_stars(self._points, normals, ids[rows], neighbours[ids[rows]], kept[ids[rows]])
            for rows in _chunks(len(ids), 8 * neighbours.shape[1])
        ])  # fmt: skip
        a, b = faces[:, 1], faces[:, 2]
        apart = np.einsum("fc,fc->f", normals[a], normals[b]) <= 0
        apart &= _transported_agreement(self._points, normals, a, b) <= 0
        return faces[~(far_edges[faces[:, 0]] & apart)]

    @cached_property
    def area(self) -> float:
        """The sampled surface's area as the Laplacian's mass estimates it (sum of the lumped mass)."""
        return float(self.operators[1].diagonal().sum())

    @cached_property
    def mean_spacing(self) -> float:
        """Mean distance from a point to its nearest other point (the cloud's "edge length")."""
        return float(self._spacing.mean())

    @cached_property
    def bounding_box_diagonal(self) -> float:
        return float(np.linalg.norm(self._points.max(axis=0) - self._points.min(axis=0)))

    @cached_property
    def edges(self) -> np.ndarray:
        """(e, 2) unique pairs (i < j, sorted) that the stiffness W joins: the edges of the local triangulations
        (of robust_laplacian's, with ``separate_sheets=False``), the cloud's graph for nodal domains (read-only)."""
        upper = sp.triu(self.operators[0], k=1).tocoo()
        edges = np.unique(np.stack([upper.row, upper.col], axis=1).astype(np.int64), axis=0)
        edges.flags.writeable = False
        return edges

    @property
    def stray_points(self) -> np.ndarray:
        """Indices (ascending) of the points :func:`stray_points` finds: isolated points and small groups off
        the sampled surface, such as scanner outliers (read-only; empty for a clean cloud)."""
        return self._stray

    @cached_property
    def vertex_components(self) -> tuple[int, np.ndarray]:
        """(count, labels (n,)): pieces of the cloud that the Laplacian's neighbourhoods do not join."""
        count, labels = connected_components(self.operators[0], directed=False)
        return int(count), labels.astype(np.int64)

    @property
    def n_components(self) -> int:
        return self.vertex_components[0]

    @cached_property
    def _neighbourhoods(self) -> tuple[np.ndarray, np.ndarray]:
        """(distances, indices), both (n, neighbors + 1): each point's nearest points, itself first."""
        return cKDTree(self._points).query(self._points, k=self.neighbors + 1)

    @property
    def _fitted(self) -> int:
        """How many of each point's nearest points (itself first) the plane of its first normal is fitted to."""
        return 1 + max(GRADIENT_NEIGHBORS, self.neighbors // 2)

    @cached_property
    def normals(self) -> np.ndarray:
        """(n, 3) unit normals, consistently oriented and pointing outward (read-only).

        First each is the direction of least variance of the point and its ``neighbors // 2`` nearest
        points (at least :data:`GRADIENT_NEIGHBORS`; PCA), oriented by :func:`_oriented`. Where two parts
        nearly touch or meet at an angle, or a part is thinner than that neighbourhood, the PCA plane
        averages over both sides and tilts; so, :data:`_NORMAL_ROUNDS` times, each normal is replaced by the
        area-weighted mean normal of the point's star in the local triangulation these normals give
        (:attr:`local_triangles`, without ``off_sheet``: only the neighbours on the point's own sheet, as a
        mesh's vertex normal averages its faces) and the signs are oriented again, which the better
        directions make clearer. Where parts are thinner than the point spacing or touch over a wide area
        some points can still get the wrong sign, mostly in patches on legs, tails, ears and at the
        contacts, and where a star still joins two sheets its normal tilts toward the other one.
        Normals given to the constructor are used instead, oriented as the constructor says."""
        if self._given_normals is not None:
            return self._given_oriented[0]
        distances, indices = self._neighbourhoods
        normals = _oriented(self._points, _plane_normals(self._points, indices[:, : self._fitted]), distances, indices)
        for _ in range(_NORMAL_ROUNDS):
            stars = self._triangulate(normals, None)[0]
            normals = _oriented(self._points, _star_normals(self._points, stars, normals), distances, indices)
        normals.flags.writeable = False
        return normals

    @cached_property
    def gradient_matrix(self) -> sp.csr_matrix:
        """(3n, n) csr: ``(G @ f).reshape(n, 3)`` is the tangential gradient of f (n,) at each point, in units
        of f per length: the linear part g of the least-squares quadratic ``f(q) - f(p) = g . u + u^T H u / 2``
        over the point's :data:`GRADIENT_NEIGHBORS` nearest points q, with u the projection of q - p on
        the plane normal to :attr:`normals` (the quadratic part keeps curvature out of g)."""
        _, indices = self._neighbourhoods
        neighbours = indices[:, 1 : GRADIENT_NEIGHBORS + 1]
        n, normals = self.n_vertices, self.normals
        weights = np.empty((n, 3, GRADIENT_NEIGHBORS))  # gradient at p = sum_k w_k (f_k - f_p)
        for chunk in _chunks(n, 16 * GRADIENT_NEIGHBORS):  # the fit's (chunk, K, 5) arrays: bounded memory
            design, _, frames = _quadratic_design(self._points, normals, chunk, neighbours[chunk])
            fit = np.linalg.pinv(design)[:, :2]  # (chunk, 2, K): the linear part in tangent coordinates
            weights[chunk] = np.einsum("nak,nac->nck", fit, frames)
        rows = np.repeat(np.arange(3 * n), GRADIENT_NEIGHBORS)
        columns = np.repeat(neighbours[:, None, :], 3, axis=1).reshape(-1)
        G = sp.csr_matrix((weights.reshape(-1), (rows, columns)), shape=(3 * n, n))
        return (G - sp.diags(np.asarray(G.sum(axis=1)).ravel()) @ sp.kron(sp.eye(n), np.ones((3, 1)))).tocsr()

    def gradients(self, f) -> np.ndarray:
        """The tangential gradient of f (n,) or (n, d) at each point (:attr:`gradient_matrix`): (n, 3) or
        (n, 3, d)."""
        f = np.asarray(f, dtype=np.float64)
        if f.ndim not in (1, 2) or f.shape[0] != self.n_vertices:
            raise MeshError(f"f has shape {f.shape}, expected ({self.n_vertices},) or ({self.n_vertices}, d)")
        return (self.gradient_matrix @ f).reshape(self.n_vertices, 3, *f.shape[1:])

    def scaled_to_unit_area(self) -> PointCloud:
        """This cloud centered at its mean and scaled so that :attr:`area` is 1 (same neighbourhoods)."""
        centered = (self._points - self._points.mean(axis=0)) / np.sqrt(self.area)
        return self._with_points(centered, self._given_normals)

    def subset(self, indices) -> PointCloud:
        """The cloud of the points ``indices`` (in that order): e.g. a random subsample."""
        indices = np.asarray(indices)
        if indices.ndim != 1 or not np.issubdtype(indices.dtype, np.integer):
            raise MeshError(f"indices must be a 1-D integer array, got shape {indices.shape} {indices.dtype}")
        if indices.size and (indices.min() < 0 or indices.max() >= self.n_vertices):
            raise MeshError(f"indices must be in [0, {self.n_vertices})")
        return self._with_points(
            self._points[indices], None if self._given_normals is None else self._given_normals[indices]
        )

    def _with_points(self, points, normals) -> PointCloud:
        return PointCloud(
            points,
            neighbors=self.neighbors,
            mollify=self.mollify,
            separate_sheets=self.separate_sheets,
            off_sheet=self.off_sheet,
            normals=normals,
        )


def _unit_normals(normals, n: int) -> np.ndarray:
    """Given normals as a read-only (n, 3) float64 array of unit rows, NaN rows where they are zero or not
    finite (missing); MeshError if the shape is not (n, 3)."""
    normals = np.array(normals, dtype=np.float64)
    if normals.shape != (n, 3):
        raise MeshError(f"normals have shape {normals.shape}, expected ({n}, 3): one per point")
    length = np.linalg.norm(normals, axis=1)
    usable = np.isfinite(length) & (length > 0)
    normals = np.where(usable[:, None], normals / np.where(usable, length, 1.0)[:, None], np.nan)
    normals.flags.writeable = False
    return normals


def _plane_normals(points: np.ndarray, neighbourhoods: np.ndarray) -> np.ndarray:
    """(m, 3) unit normals of the least-squares planes through the points ``neighbourhoods`` (m, k) (PCA: the
    direction of least variance), unoriented."""
    directions = np.empty((len(neighbourhoods), 3))
    for rows in _chunks(len(neighbourhoods), neighbourhoods.shape[1] * 3):  # bounded memory
        neighbourhood = points[neighbourhoods[rows]]
        spread = neighbourhood - neighbourhood.mean(axis=1, keepdims=True)
        directions[rows] = np.linalg.eigh(np.einsum("nki,nkj->nij", spread, spread))[1][:, :, 0]
    return directions


def stray_points(points, nearest: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Indices (ascending) of the stray points of a cloud: groups of at most :data:`STRAY_NEIGHBORS` points that
    reach the rest only by links longer than :data:`STRAY_JUMP` local spacings.

    Each point is linked to its :data:`STRAY_NEIGHBORS` nearest points; a link of length L between p and q
    holds when ``L <= STRAY_JUMP * max(s_p, s_q)``, where a point's local spacing s is the median, over its
    linked neighbours, of their distances to their own nearest points (so the test follows the sampling
    density, and a point off the surface takes the spacing of the surface beneath it). The pieces the links
    that hold make with at most :data:`STRAY_NEIGHBORS` points are stray; larger pieces are parts of the
    cloud. A stray point has no surface around it: the point-cloud Laplacian gives it a large mass and
    weak links, so the spectrum gets a spurious low eigenpair localized on it for each. Points nearer the
    surface than the jump are not found (they act like noise on the operator, or do harm undetected).

    Parameters
    ----------
    points : (n, 3) array
    nearest : optional ``(distances, indices)`` of each point's nearest points, itself first, at least
        ``STRAY_NEIGHBORS + 1`` columns (a cloud's own neighbourhoods, to avoid a second query).

    Returns
    -------
    (s,) int64 array; empty when the cloud has no more than ``2 * STRAY_NEIGHBORS`` points (too few to tell).
    """
    points = as_coordinates(points, "points")
    n = len(points)
    if n <= 2 * STRAY_NEIGHBORS:
        return np.zeros(0, dtype=np.int64)
    if nearest is None:
        nearest = cKDTree(points).query(points, k=STRAY_NEIGHBORS + 1)
    distances, indices = nearest[0][:, 1 : STRAY_NEIGHBORS + 1], nearest[1][:, 1 : STRAY_NEIGHBORS + 1]
    spacing = np.median(nearest[0][:, 1][indices], axis=1)
    rows = np.repeat(np.arange(n), STRAY_NEIGHBORS)
    columns = indices.ravel()
    holds = distances.ravel() <= STRAY_JUMP * np.maximum(spacing[rows], spacing[columns])
    links = sp.csr_matrix((np.ones(int(holds.sum())), (rows[holds], columns[holds])), shape=(n, n))
    _, labels = connected_components(links, directed=False)
    return np.flatnonzero(np.bincount(labels)[labels] <= STRAY_NEIGHBORS).astype(np.int64)


def _tangent_frames(normals: np.ndarray) -> np.ndarray:
    """(r, 2, 3): two orthonormal tangent axes perpendicular to each unit normal (r, 3)."""
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    first = np.cross(normals, helper)
    first /= np.linalg.norm(first, axis=1, keepdims=True)
    return np.stack([first, np.cross(normals, first)], axis=1)


def _quadratic_design(points, normals, rows, neighbours) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(design (r, K, 5), height (r, K), frames (r, 2, 3)) of the points ``rows`` and their neighbours (r, K):
    with (u, v) the coordinates of q - p on the plane normal to p's normal (the axes ``frames`` of
    :func:`_tangent_frames`) and w its height along the normal, the monomials [u, v, u^2, uv, v^2] of a
    quadratic through p, and w."""
    offsets = points[neighbours] - points[rows, None, :]  # (r, K, 3)
    frames = _tangent_frames(normals[rows])
    u, v = np.einsum("nkc,nac->ank", offsets, frames)
    return np.stack([u, v, u * u, u * v, v * v], axis=2), np.einsum("nkc,nc->nk", offsets, normals[rows]), frames


def _transported_agreement(points, normals, rows, columns) -> np.ndarray:
    """``n_q . (I - 2 e e^T) n_p`` for the point pairs (p, q) = (rows, columns), e = (q - p) / |q - p|: the
    normal at p carried to q along the circle through p and q that it is normal to (König & Gumhold 2009),
    against q's own. Positive when the two are oriented alike: for two points of one sheet (e nearly
    tangent) it is ``n_q . n_p``, and for two facing points of parts that nearly touch, or the two sides of
    a thin part (e along the normals), it is ``-n_q . n_p``, so a sign never travels across such a gap
    reversed."""
    e = points[columns] - points[rows]
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    p, q = normals[rows], normals[columns]
    return np.einsum("ij,ij->i", q, p) - 2 * np.einsum("ij,ij->i", p, e) * np.einsum("ij,ij->i", q, e)


def _oriented(points: np.ndarray, directions: np.ndarray, distances: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """(n, 3): the unit normal directions (n, 3) with their signs made consistent and outward.

    Signs travel along a minimum spanning tree of the graph of each point's :data:`GRADIENT_NEIGHBORS`
    nearest points (``indices`` and ``distances`` (n, k + 1), the point itself first; Hoppe et al. 1992),
    weighted by ``(1 - |t_ij| + 1e-3) x distance`` where t_ij compares n_j with n_i carried to point j
    along the circle through both points (König & Gumhold 2009; :func:`_transported_agreement`): the sign
    travels where that comparison is clearest first, and it crosses the gap between two nearly touching
    parts, or a thin part, reversed (facing sides point apart) instead of copied. Then each piece of that
    graph is flipped so that ``sum n . (p - centroid) > 0`` (3 x the enclosed volume, by the divergence
    theorem: outward on a closed piece)."""
    n = len(points)
    normals = directions.copy()
    rows = np.repeat(np.arange(n), GRADIENT_NEIGHBORS)
    columns = indices[:, 1 : GRADIENT_NEIGHBORS + 1].reshape(-1)
    alignment = np.abs(_transported_agreement(points, normals, rows, columns))
    weights = (1.0 - alignment + 1e-3) * distances[:, 1 : GRADIENT_NEIGHBORS + 1].reshape(-1)
    graph = sp.csr_matrix((weights, (rows, columns)), shape=(n, n))
    tree = minimum_spanning_tree(graph.maximum(graph.T))
    count, labels = connected_components(tree, directed=False)
    normals[_flips_along_forest(tree, points, normals, labels, count)] *= -1
    pieces = np.bincount(labels, minlength=count)[:, None]
    centroids = np.stack([np.bincount(labels, points[:, d], count) for d in range(3)], axis=1) / pieces
    volumes = np.bincount(labels, np.einsum("ij,ij->i", normals, points - centroids[labels]), count)
    normals[volumes[labels] < 0] *= -1
    return normals


def _star_normals(points: np.ndarray, stars: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(n, 3) unit normals: at each point p the sum of the normals of the triangles (p, a, b) of its star
    (``stars`` (f, 3), the star's point first), each of length twice the triangle's area and turned to the
    side of ``normals[p]``; a point without triangles keeps ``normals[p]``."""
    first, second, third = (points[stars[:, i]] for i in range(3))
    faces = np.cross(second - first, third - first)
    faces *= np.where(np.einsum("fc,fc->f", faces, normals[stars[:, 0]]) < 0, -1.0, 1.0)[:, None]
    summed = np.stack([np.bincount(stars[:, 0], faces[:, d], len(points)) for d in range(3)], axis=1)
    length = np.linalg.norm(summed, axis=1, keepdims=True)
    return np.where(length > 0, summed / np.where(length > 0, length, 1.0), normals)


def _flips_along_forest(
    tree: sp.spmatrix, points: np.ndarray, normals: np.ndarray, labels: np.ndarray, count: int
) -> np.ndarray:
    """(n,) bool: which normals to flip so that each agrees in sign with its parent in the spanning forest
    ``tree`` (pieces ``labels``, each rooted at its first point). A point is flipped when an odd number of
    the tree edges on its path to the root join normals of opposite sign: one breadth-first search from a
    virtual root joined to every piece's root, then the parities summed up the paths by pointer jumping
    (log2 of the depth vectorized steps, not a Python loop over the points)."""
    n = len(normals)
    roots = np.unique(labels, return_index=True)[1]
    virtual = sp.csr_matrix((np.ones(count), (np.full(count, n), roots)), shape=(n + 1, n + 1))
    forest = sp.block_diag([tree, sp.csr_matrix((1, 1))]).tocsr() + virtual
    _, parent = breadth_first_order(forest, n, directed=False, return_predecessors=True)
    parent[n] = n
    odd = np.zeros(n + 1, dtype=bool)
    odd[:n] = _transported_agreement(points, normals, np.minimum(parent[:n], n - 1), np.arange(n)) < 0
    odd[roots] = False  # a root's parent is the virtual root
    while np.any(parent != n):
        odd ^= odd[parent]
        parent = parent[parent]
    return odd[:n]


def _delaunay_stars(points, normals, rows, neighbours, kept) -> np.ndarray:
    """(f, 3) triangles (p, a, b): the Delaunay star of each point p of ``rows`` among its ``kept``
    neighbours (both (r, m)), projected on its tangent plane (normal ``normals[p]``), a and b in
    counterclockwise order about the normal.

    Under the inversion w = u / |u|^2 of the tangent coordinates u about p, the circles through p become
    lines and their insides the half-planes away from p, so (p, a, b) is a Delaunay triangle (its
    circumcircle empty) exactly when w_a w_b is an edge of the convex hull of the w with p on its inner
    side. The inversion keeps the angles about p, so the w sorted by angle form a polygon star-shaped from
    p, whose hull a Graham scan from a hull vertex finds (Sklansky's scan, correct on star-shaped
    polygons): pop the top of the stack while it and the next vertex make no left turn. With p inside the
    hull the scan starts at the largest |w| and closes the loop; with p outside it or on it (an angular gap
    of at least pi between neighbours: p on the border of its neighbourhood) it runs from one side of the
    gap to the other, leaving out the edge across it. A point behind a nearer one on the same ray from p
    lies inside the hull and is dropped first (on a regular grid many do). Vectorized over the points: m
    steps, each popping only where a pop is due."""
    r, m = neighbours.shape
    u = (points[neighbours] - points[rows, None, :]) @ _tangent_frames(normals[rows]).transpose(0, 2, 1)
    squared = np.einsum("nka,nka->nk", u, u)
    angle = np.arctan2(u[..., 1], u[..., 0])
    angle = np.where(kept & (squared > 0), np.where(angle >= np.pi, -np.pi, angle), np.inf)  # one per ray
    order = np.lexsort((squared, angle), axis=1)  # by angle, the nearest first on a ray
    angle = np.take_along_axis(angle, order, axis=1)
    hidden = ~np.isfinite(angle)
    hidden[:, 1:] |= angle[:, 1:] == angle[:, :-1]  # behind a nearer point on its ray
    compact = np.argsort(hidden, axis=1, kind="stable")  # the visible ones first, still by angle
    order, angle = np.take_along_axis(order, compact, axis=1), np.take_along_axis(angle, compact, axis=1)
    count = m - hidden.sum(axis=1)
    size, local, position = np.maximum(count, 1), np.arange(r), np.arange(m)
    visible = position < count[:, None]
    angle = np.where(visible, angle, 0.0)
    gap = np.mod(np.take_along_axis(angle, (position + 1) % size[:, None], axis=1) - angle, 2 * np.pi)
    widest = np.argmax(np.where(visible, gap, -1.0), axis=1)
    chain = gap[local, widest] >= np.pi  # p outside the hull or on it: an open chain across the gap
    squared = np.take_along_axis(squared, order, axis=1)
    first = np.where(chain, (widest + 1) % size, np.argmax(np.where(visible, -squared, -np.inf), axis=1))
    steps = np.where(chain, count - 1, count) * (count >= 2)  # a closed hull returns to its first vertex
    w = np.take_along_axis(u, order[..., None], axis=1) / np.where(squared > 0, squared, 1.0)[..., None]
    x, y = w[..., 0].ravel(), w[..., 1].ravel()
    base = local * m
    stack = np.zeros((r, m + 1), dtype=np.int64)  # per point, the hull so far: positions in the angular order
    stack[:, 0] = first
    top = np.zeros(r, dtype=np.int64)
    flat = stack.ravel()
    below_x, below_y = np.zeros(r), np.zeros(r)  # the w of the stack's second entry
    top_x, top_y = x[base + first], y[base + first]  # and of its top
    for step in range(1, m + 1):
        live = step <= steps
        if not live.any():
            break
        following = (first + step) % size
        next_x, next_y = x[base + following], y[base + following]
        popping = np.flatnonzero(live & (top >= 1))
        while popping.size:
            i = popping
            turn = (top_x[i] - below_x[i]) * (next_y[i] - top_y[i]) - (top_y[i] - below_y[i]) * (next_x[i] - top_x[i])
            i = i[turn <= 0]
            top[i] -= 1
            top_x[i], top_y[i] = below_x[i], below_y[i]
            popping = i = i[top[i] >= 1]
            under = base[i] + flat[i * (m + 1) + top[i] - 1]
            below_x[i], below_y[i] = x[under], y[under]
        top += live
        flat[(local * (m + 1) + top)[live]] = following[live]
        below_x, below_y = np.where(live, top_x, below_x), np.where(live, top_y, below_y)
        top_x, top_y = np.where(live, next_x, top_x), np.where(live, next_y, top_y)
    star, at = np.nonzero(position < top[:, None])
    ids = np.take_along_axis(neighbours, order, axis=1)
    return np.stack([rows[star], ids[star, stack[star, at]], ids[star, stack[star, at + 1]]], axis=1)


def _chunks(n: int, values_per_row: int, budget: int = 2**23):
    """Slices covering range(n) in order, each of at most ``budget`` / ``values_per_row`` rows (at least
    one): per-point work on (rows, values_per_row) float arrays stays near 8 x budget bytes (64 MB) each."""
    step = max(1, budget // max(1, values_per_row))
    return (slice(start, min(start + step, n)) for start in range(0, n, step))


def as_shape(shape_like) -> TriMesh | PointCloud:
    """A :class:`PointCloud` as it is, anything else through :func:`hamsa.mesh.as_trimesh`."""
    if isinstance(shape_like, PointCloud):
        return shape_like
    return as_trimesh(shape_like)
