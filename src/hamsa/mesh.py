"""Triangle meshes: the validated :class:`TriMesh` value object and its connectivity queries.

A ``TriMesh`` holds ``vertices`` (n, 3) float64 and ``faces`` (m, 3) int64, both read-only.
Construction validates them and raises :class:`~hamsa.errors.MeshError` naming the first problem:
non-finite coordinates, out-of-range or negative indices, faces with a repeated vertex,
zero-area faces, edges shared by more than two faces (unless ``manifold=False``, for the tufted
Laplacian), duplicate faces, empty meshes.
Vertex order is never changed: ground-truth correspondences are vertex indices.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from hamsa.errors import MeshError

# A face is "zero-area" when its area is below this fraction of its longest edge squared, i.e. its
# smallest angle is below ~2e-12 rad: degenerate up to floating-point noise.
_DEGENERATE_AREA_RATIO = 1e-12
# Cotangent weights square cross products (fourth powers of coordinates): beyond ~1e77 they overflow
# float64, so coordinates are bounded well below that.
_LARGEST_COORDINATE = 1e60


def format_ids(indices: np.ndarray, limit: int = 5) -> str:
    """The first ``limit`` ids of ``indices`` for an error message ("3, 8, 12, ..." when there are more)."""
    shown = ", ".join(str(int(i)) for i in indices[:limit])
    return shown + (", ..." if len(indices) > limit else "")


class TriMesh:
    """A validated triangle mesh.

    Parameters
    ----------
    vertices : array_like, shape (n, 3)
        Vertex coordinates; converted to float64.
    faces : array_like, shape (m, 3)
        Vertex indices of each triangle (0-based, integer dtype); converted to int64.
    manifold : bool
        True (the default) refuses edges shared by more than two faces. False accepts them: such a mesh
        (a CAD part, a scan with fins) gets operators only from ``laplacian="tufted"``
        (:func:`hamsa.operators.intrinsic_operators`); the cotan Laplacian refuses it.

    Raises
    ------
    MeshError
        If the arrays have the wrong shape or dtype, or the mesh is empty, has non-finite
        coordinates, out-of-range indices, faces with a repeated vertex, zero-area faces,
        duplicate faces or (with ``manifold=True``) non-manifold edges (shared by more than two faces).

    Notes
    -----
    Unreferenced vertices are allowed (some datasets ship them), but operators refuse them
    because their mass is zero; :meth:`without_unreferenced` removes them and returns the index map.
    Both arrays are read-only; derived quantities are computed once and cached.

    Examples
    --------
    >>> import hamsa
    >>> mesh = hamsa.TriMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    >>> mesh.n_vertices, mesh.n_faces, float(mesh.area)
    (3, 1, 0.5)
    """

    def __init__(self, vertices, faces, *, manifold: bool = True):
        vertices = as_coordinates(vertices)
        faces = _as_faces(faces)
        _validate(vertices, faces, manifold)
        vertices.flags.writeable = False
        faces.flags.writeable = False
        self._vertices = vertices
        self._faces = faces
        self._manifold = manifold

    @property
    def vertices(self) -> np.ndarray:
        """(n, 3) float64 vertex coordinates (read-only)."""
        return self._vertices

    @property
    def faces(self) -> np.ndarray:
        """(m, 3) int64 vertex indices of the triangles (read-only)."""
        return self._faces

    @property
    def n_vertices(self) -> int:
        return self._vertices.shape[0]

    @property
    def n_faces(self) -> int:
        return self._faces.shape[0]

    def __repr__(self) -> str:
        extra = "" if self.is_edge_manifold else f", non_manifold_edges={len(self.non_manifold_edges)}"
        return f"TriMesh(n_vertices={self.n_vertices}, n_faces={self.n_faces}{extra})"

    # ----------------------------------------------------------------------------- geometry
    @cached_property
    def face_areas(self) -> np.ndarray:
        """(m,) area of each triangle."""
        return _face_areas(self._vertices, self._faces)

    @cached_property
    def face_normals(self) -> np.ndarray:
        """(m, 3) unit normal of each triangle, following its winding (counter-clockwise seen from the side it
        points to)."""
        v, f = self._vertices, self._faces
        return np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]) / (2 * self.face_areas[:, None])

    @cached_property
    def area(self) -> float:
        """Total surface area (sum of the triangle areas)."""
        return float(self.face_areas.sum())

    @cached_property
    def vertex_normals(self) -> np.ndarray:
        """(n, 3) unit vertex normals: the area-weighted mean of the incident faces' normals, which follow the
        face winding (counter-clockwise seen from the side they point to); zero at an unreferenced vertex."""
        v, f = self._vertices, self._faces
        face_normal = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        normals = np.zeros_like(v)
        for c in range(3):
            np.add.at(normals, f[:, c], face_normal)
        return normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)

    @cached_property
    def signed_volume(self) -> float:
        """``sum_f x_0 . (x_1 x x_2) / 6``: the enclosed volume, positive when the faces wind outward (normals
        pointing out) on a closed, consistently oriented surface; on a surface with small holes, nearly so."""
        v, f = self._vertices, self._faces
        return float(np.einsum("ij,ij->", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])) / 6.0)

    @cached_property
    def edge_lengths(self) -> np.ndarray:
        """(e,) length of each unique edge, in the order of :attr:`edges`."""
        v = self._vertices
        return np.linalg.norm(v[self.edges[:, 1]] - v[self.edges[:, 0]], axis=1)

    @cached_property
    def mean_edge_length(self) -> float:
        return float(self.edge_lengths.mean())

    @cached_property
    def bounding_box_diagonal(self) -> float:
        used = self._vertices[self.referenced]
        return float(np.linalg.norm(used.max(axis=0) - used.min(axis=0)))

    def scaled_to_unit_area(self) -> TriMesh:
        """This mesh centered at its vertex mean and scaled to total area 1 (same faces).

        Eigenvalues scale as 1 / area, so spectra, heat times and potential scales become comparable
        across shapes; matching and the benchmarks work on unit-area shapes (Kim et al. normalize
        errors by sqrt(area) for the same reason)."""
        centered = self._vertices - self._vertices.mean(axis=0)
        return TriMesh(centered / np.sqrt(self.area), self._faces, manifold=self._manifold)

    # ------------------------------------------------------------------------- connectivity
    @cached_property
    def edges(self) -> np.ndarray:
        """(e, 2) unique undirected edges, each as (smaller index, larger index), sorted."""
        return self._edge_table[0]

    @cached_property
    def edge_face_counts(self) -> np.ndarray:
        """(e,) number of faces incident to each edge of :attr:`edges` (1 = boundary, 2 = interior)."""
        return self._edge_table[1]

    @cached_property
    def _edge_table(self) -> tuple[np.ndarray, np.ndarray]:
        return _unique_edges(self._faces)

    @cached_property
    def non_manifold_edges(self) -> np.ndarray:
        """(b, 2) edges shared by more than two faces (empty unless built with ``manifold=False``)."""
        return self.edges[self.edge_face_counts > 2]

    @property
    def is_edge_manifold(self) -> bool:
        """True when no edge has more than two incident faces."""
        return len(self.non_manifold_edges) == 0

    @cached_property
    def referenced(self) -> np.ndarray:
        """(n,) bool, True for vertices used by at least one face."""
        mask = np.zeros(self.n_vertices, dtype=bool)
        mask[self._faces.ravel()] = True
        return mask

    @cached_property
    def unreferenced_vertices(self) -> np.ndarray:
        """Indices of vertices that no face uses."""
        return np.flatnonzero(~self.referenced)

    @cached_property
    def boundary_edges(self) -> np.ndarray:
        """(b, 2) edges incident to exactly one face."""
        return self.edges[self.edge_face_counts == 1]

    @cached_property
    def boundary_loops(self) -> list[np.ndarray]:
        """Closed boundary curves, each an array of vertex indices in order along the loop.

        A boundary vertex touched by several loops (a "pinched" boundary) is followed greedily;
        loops are returned in order of their smallest vertex index.
        """
        return _boundary_loops(self.boundary_edges)

    @cached_property
    def vertex_components(self) -> tuple[int, np.ndarray]:
        """(count, labels): connected components of the referenced vertices.

        ``labels`` has shape (n,); unreferenced vertices get the label -1 and are not counted.
        """
        n = self.n_vertices
        e = self.edges
        graph = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
        _, labels = connected_components(graph, directed=False)
        labels = labels.astype(np.int64)
        labels[~self.referenced] = -1
        used = np.unique(labels[labels >= 0])
        relabel = np.full(labels.max() + 2, -1, dtype=np.int64)
        relabel[used] = np.arange(len(used))
        return len(used), relabel[labels]

    @property
    def n_components(self) -> int:
        return self.vertex_components[0]

    @cached_property
    def euler_characteristic(self) -> int:
        """V - E + F over the referenced vertices."""
        return int(self.referenced.sum()) - len(self.edges) + self.n_faces

    @property
    def is_closed(self) -> bool:
        """True when every edge has two incident faces (no boundary)."""
        return bool(np.all(self.edge_face_counts == 2))

    @cached_property
    def is_consistently_oriented(self) -> bool:
        """True when every interior edge is traversed in opposite directions by its two faces."""
        f = self._faces
        directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        codes = directed[:, 0] * self.n_vertices + directed[:, 1]
        return len(np.unique(codes)) == len(codes)

    @cached_property
    def non_manifold_vertices(self) -> np.ndarray:
        """Vertices whose incident faces do not form a single fan (e.g. two cones touching at a tip)."""
        return _non_manifold_vertices(self._faces, self.n_vertices)

    def without_unreferenced(self) -> tuple[TriMesh, np.ndarray]:
        """Remove unreferenced vertices, keeping the order of the others.

        Returns
        -------
        mesh : TriMesh
            The mesh on the referenced vertices only.
        kept : (n_kept,) int64
            ``kept[i]`` is the index in this mesh of vertex ``i`` of the new mesh; use it to carry
            per-vertex data and correspondences (``field_new = field_old[kept]``).
        """
        kept = np.flatnonzero(self.referenced)
        if len(kept) == self.n_vertices:
            return self, kept
        new_index = np.full(self.n_vertices, -1, dtype=np.int64)
        new_index[kept] = np.arange(len(kept))
        return TriMesh(self._vertices[kept], new_index[self._faces], manifold=self._manifold), kept

    def largest_component(self) -> tuple[TriMesh, np.ndarray]:
        """The connected component with the most vertices, as ``(mesh, kept)`` like
        :meth:`without_unreferenced` (``kept[i]``: this mesh's index of the new mesh's vertex i): e.g. a
        scanned body without the loose pieces beside it, as the Kim et al. benchmark keeps TOSCA's gorilla."""
        count, labels = self.vertex_components
        if count <= 1:
            return self.without_unreferenced()
        biggest = np.argmax(np.bincount(labels[labels >= 0]))
        faces = self._faces[labels[self._faces[:, 0]] == biggest]
        body, kept = TriMesh(self._vertices, faces, manifold=self._manifold).without_unreferenced()
        return body, kept

    def require_operator_ready(self) -> None:
        """Raise MeshError if the mesh has vertices without area (operators would be singular)."""
        if len(self.unreferenced_vertices):
            raise MeshError(
                f"mesh has {len(self.unreferenced_vertices)} unreferenced vertices "
                f"({format_ids(self.unreferenced_vertices)}); they carry no area and make the mass "
                "matrix singular: use mesh.without_unreferenced() and keep its index map"
            )


def as_trimesh(mesh_like) -> TriMesh:
    """Accept the meshes users have and return a validated :class:`TriMesh` (vertex order kept).

    Accepted: a TriMesh; a ``(vertices, faces)`` pair of arrays; a ``trimesh.Trimesh`` (its arrays as
    they are — load with ``process=False`` so trimesh does not merge or reorder vertices); a
    ``pyvista.PolyData`` (polygons cut into triangles by :func:`triangulate_polygons`).
    """
    if isinstance(mesh_like, TriMesh):
        return mesh_like
    if isinstance(mesh_like, (tuple, list)) and len(mesh_like) == 2:
        return TriMesh(*mesh_like)
    kind = f"{type(mesh_like).__module__.split('.')[0]}.{type(mesh_like).__name__}"
    if kind == "trimesh.Trimesh":
        return TriMesh(np.asarray(mesh_like.vertices), np.asarray(mesh_like.faces))
    if kind == "pyvista.PolyData":
        points = np.asarray(mesh_like.points)
        return TriMesh(points, triangulate_polygons(points, *_vtk_polygons(np.asarray(mesh_like.faces))))
    if kind == "hamsa.PointCloud":
        raise MeshError("this needs a triangle mesh (its faces), and a point cloud has none")
    raise MeshError(
        f"expected a TriMesh, a (vertices, faces) pair, a trimesh.Trimesh or a pyvista.PolyData, got {kind}"
    )


# ----------------------------------------------------------------------------------- helpers
def as_coordinates(vertices, what: str = "vertices") -> np.ndarray:
    """A new float64 (n, 3) array of real coordinates, or a MeshError naming ``what`` is wrong with it."""
    try:
        v = np.asarray(vertices)
        complex_values = np.iscomplexobj(v)
        v = None if complex_values else np.array(v, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise MeshError(f"{what} are not a numeric (n, 3) array: {exc}") from None
    if complex_values:
        raise MeshError(f"{what} must be real numbers, got complex ones")
    if v.ndim != 2 or v.shape[1] != 3:
        raise MeshError(f"{what} must have shape (n, 3), got {v.shape}")
    return v


def _as_faces(faces) -> np.ndarray:
    try:
        f = np.asarray(faces)
    except (TypeError, ValueError) as exc:  # ragged lists
        raise MeshError(f"faces are not an (m, 3) integer array: {exc}") from None
    if f.size == 0:
        f = f.reshape(0, 3) if f.ndim < 2 else f
    if f.ndim != 2 or f.shape[1] != 3:
        if f.ndim == 2 and f.shape[1] > 3:
            raise MeshError(f"faces have {f.shape[1]} vertices each; hamsa needs triangles (m, 3)")
        raise MeshError(f"faces must have shape (m, 3), got {f.shape}")
    if f.size and not np.issubdtype(f.dtype, np.integer):
        raise MeshError(f"face indices must be integers, got dtype {f.dtype}")
    if f.size and f.dtype.kind == "u" and f.max() > np.iinfo(np.int64).max:
        raise MeshError(f"face index {f.max()} is out of range")
    return np.array(f, dtype=np.int64)


def _face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    v0, v1, v2 = (vertices[faces[:, c]] for c in range(3))
    return 0.5 * np.linalg.norm(np.cross(v1 - v0, v2 - v0), axis=1)


def _unique_rows(rows: np.ndarray, **kwargs):
    """``np.unique(rows, axis=0, ...)`` for small non-negative integer rows, through one int64 key per row.

    Much faster than the structured-array path of ``np.unique(axis=0)`` on millions of rows; falls back
    to it when the keys would overflow.
    """
    base = int(rows.max()) + 1 if rows.size else 1
    if float(base) ** rows.shape[1] >= 2**63:
        return np.unique(rows, axis=0, **kwargs)
    keys = np.zeros(len(rows), dtype=np.int64)
    for column in range(rows.shape[1]):
        keys = keys * base + rows[:, column]
    result = np.unique(keys, **kwargs)
    unique_keys = result[0] if isinstance(result, tuple) else result
    decoded = np.empty((len(unique_keys), rows.shape[1]), dtype=rows.dtype)
    rest = unique_keys.copy()
    for column in range(rows.shape[1] - 1, -1, -1):
        decoded[:, column] = rest % base
        rest //= base
    return (decoded, *result[1:]) if isinstance(result, tuple) else decoded


def _unique_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    half = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    half.sort(axis=1)
    edges, counts = _unique_rows(half, return_counts=True)
    return edges, counts


def check_coordinates(points: np.ndarray, what: str = "vertices", remedy: str = "") -> None:
    """Raise MeshError if any of the (n, 3) ``points`` is NaN / Inf (the message ends with ``remedy``, what
    removes them) or too large for the geometry in float64."""
    bad = np.flatnonzero(~np.isfinite(points).all(axis=1))
    if len(bad):
        raise MeshError(f"{len(bad)} {what} have non-finite coordinates (NaN or Inf): {format_ids(bad)}{remedy}")
    big = np.abs(points).max() if len(points) else 0.0
    if big > _LARGEST_COORDINATE:
        raise MeshError(
            f"coordinates as large as {big:.3g} overflow the geometry in float64 (the limit is "
            f"{_LARGEST_COORDINATE:.0e}); rescale the {what}"
        )


def _validate(vertices: np.ndarray, faces: np.ndarray, manifold: bool) -> None:
    n, m = len(vertices), len(faces)
    if n == 0 or m == 0:
        raise MeshError(f"mesh is empty ({n} vertices, {m} faces)")
    check_coordinates(vertices, "vertices")
    low, high = faces.min(axis=1), faces.max(axis=1)
    bad = np.flatnonzero(low < 0)
    if len(bad):
        raise MeshError(f"face {bad[0]} has a negative vertex index {faces[bad[0]].tolist()}")
    bad = np.flatnonzero(high >= n)
    if len(bad):
        raise MeshError(f"face {bad[0]} references vertex {int(high[bad[0]])}, mesh has {n} vertices")
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    bad = np.flatnonzero(repeated)
    if len(bad):
        raise MeshError(f"{len(bad)} faces repeat a vertex (first: face {bad[0]} = {faces[bad[0]].tolist()})")
    areas = _face_areas(vertices, faces)
    v = vertices
    longest = np.max(
        [np.sum((v[faces[:, a]] - v[faces[:, b]]) ** 2, axis=1) for a, b in ((0, 1), (1, 2), (2, 0))],
        axis=0,
    )
    bad = np.flatnonzero(areas <= _DEGENERATE_AREA_RATIO * longest)
    if len(bad):
        raise MeshError(
            f"{len(bad)} faces have zero area (collinear vertices), first: face {bad[0]} = "
            f"{faces[bad[0]].tolist()}: {format_ids(bad)}"
        )
    sorted_faces = np.sort(faces, axis=1)
    _, first_index, counts = _unique_rows(sorted_faces, return_index=True, return_counts=True)
    if np.any(counts > 1):
        dup = np.sort(first_index[counts > 1])
        raise MeshError(f"{int((counts - 1).sum())} duplicate faces (same three vertices), first: face {dup[0]}")
    if not manifold:
        return
    edges, counts = _unique_edges(faces)
    bad = np.flatnonzero(counts > 2)
    if len(bad):
        e = edges[bad[0]]
        raise MeshError(
            f"{len(bad)} non-manifold edges (shared by more than two faces), first: edge "
            f"({e[0]}, {e[1]}) is shared by {counts[bad[0]]} faces; the tufted Laplacian takes such meshes "
            "(TriMesh(..., manifold=False) with laplacian='tufted', or hamsa basis --laplacian tufted)"
        )


def _boundary_loops(boundary_edges: np.ndarray) -> list[np.ndarray]:
    if len(boundary_edges) == 0:
        return []
    neighbours: dict[int, list[int]] = {}
    for a, b in boundary_edges.tolist():
        neighbours.setdefault(a, []).append(b)
        neighbours.setdefault(b, []).append(a)
    unused = {tuple(e) for e in boundary_edges.tolist()}
    loops = []
    for start in sorted(neighbours):
        while any((min(start, x), max(start, x)) in unused for x in neighbours[start]):
            loop = [start]
            current = start
            while True:
                nxt = next((x for x in neighbours[current] if (min(current, x), max(current, x)) in unused), None)
                if nxt is None:
                    break
                unused.discard((min(current, nxt), max(current, nxt)))
                if nxt == start:
                    break
                loop.append(nxt)
                current = nxt
            loops.append(np.asarray(loop, dtype=np.int64))
    return loops


def _non_manifold_vertices(faces: np.ndarray, n: int) -> np.ndarray:
    """Vertices whose incident faces split into several edge-connected fans."""
    m = len(faces)
    # Corner c of face f is the pair (vertex faces[f, c], face f); two corners at the same vertex are
    # linked when their faces share an edge through that vertex.
    corner_vertex = faces.ravel()
    corner_id = np.arange(3 * m)
    links = []
    for a, b in ((0, 1), (1, 2), (2, 0)):
        # the directed-free edge (faces[:,a], faces[:,b]) touches corners a and b of each face
        key = np.sort(faces[:, [a, b]], axis=1)
        for c in (a, b):
            links.append((key[:, 0], key[:, 1], faces[:, c], 3 * np.arange(m) + c))
    # group corners by (edge, vertex): the corners of different faces sharing the edge at that vertex
    e0 = np.concatenate([x[0] for x in links])
    e1 = np.concatenate([x[1] for x in links])
    vert = np.concatenate([x[2] for x in links])
    corner = np.concatenate([x[3] for x in links])
    order = np.lexsort((vert, e1, e0))
    e0, e1, vert, corner = e0[order], e1[order], vert[order], corner[order]
    same = (e0[1:] == e0[:-1]) & (e1[1:] == e1[:-1]) & (vert[1:] == vert[:-1])
    rows, cols = corner[:-1][same], corner[1:][same]
    graph = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(3 * m, 3 * m))
    _, fan = connected_components(graph, directed=False)
    fans_per_vertex = np.unique(np.stack([corner_vertex, fan[corner_id]], axis=1), axis=0)[:, 0]
    counts = np.bincount(fans_per_vertex, minlength=n)
    return np.flatnonzero(counts > 1)


def triangulate_polygons(vertices, polygons, counts=None) -> np.ndarray:
    """The (t, 3) int64 triangles of polygonal faces, each polygon's triangles consecutive and in the polygons'
    order; vertex ids do not change. Triangles stay triangles; a quad is cut along the diagonal whose two
    triangles both face the quad's way (its Newell normal), the shorter one when both do; a larger polygon is
    a fan from its first corner when every fan triangle faces the polygon's way (a convex polygon), and is
    cut into ears otherwise, in the plane of its Newell normal.

    Parameters
    ----------
    vertices : (n, 3) coordinates
    polygons : (m, c) integer array of c-gons (a corner that repeats the one before it is left out, so a quad
        ``a b c c`` gives the triangle ``a b c``), a sequence of m index sequences (mixed sizes), or with
        ``counts`` the corners of all polygons concatenated
    counts : (m,) the number of corners of each polygon, when ``polygons`` is flat

    Raises
    ------
    MeshError
        For a polygon with fewer than 3 corners, an index outside 0..n-1, or a polygon that crosses itself
        (no ear can be cut).
    """
    vertices = as_coordinates(vertices)
    if counts is not None:
        counts, flat = np.asarray(counts, dtype=np.int64), np.asarray(polygons)
        if flat.ndim != 1 or counts.ndim != 1 or counts.sum() != len(flat):
            raise MeshError(f"counts sum to {counts.sum()}, but {flat.size} corners are given")
    elif isinstance(polygons, np.ndarray) and polygons.ndim == 2:
        counts, flat = np.full(len(polygons), polygons.shape[1]), polygons.ravel()
    else:
        polygons = [np.asarray(p).ravel() for p in polygons]
        counts = np.array([len(p) for p in polygons], dtype=np.int64)
        flat = np.concatenate(polygons) if polygons else np.zeros(0, dtype=np.int64)
    if len(counts) and counts.min() < 3:
        bad = int(np.argmax(counts < 3))
        raise MeshError(f"face {bad} has {counts[bad]} vertices; a face needs at least 3")
    if flat.size and (not np.issubdtype(flat.dtype, np.integer) and np.any(flat != np.round(flat))):
        raise MeshError("face indices must be integers")
    flat = flat.astype(np.int64)
    if np.all(counts == 3):
        return flat.reshape(-1, 3)
    n = len(vertices)
    if flat.size and (flat.min() < 0 or flat.max() >= n):
        corner = int(np.argmax((flat < 0) | (flat >= n)))
        face = int(np.searchsorted(np.cumsum(counts), corner, side="right"))
        raise MeshError(f"face {face} references vertex {flat[corner]}, mesh has {n} vertices")
    counts, flat = _without_repeated_corners(counts, flat)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    pieces, owners = [], []
    for size in np.unique(counts):
        chosen = np.flatnonzero(counts == size)
        corners = flat[starts[chosen, None] + np.arange(size)]  # (p, size)
        points = vertices[corners]
        normal = _newell_normals(points)
        if size == 3:
            triangles = corners[:, None, :]
        elif size == 4:
            first = corners[:, [[0, 1, 2], [0, 2, 3]]]
            second = corners[:, [[1, 2, 3], [1, 3, 0]]]
            fits_first, fits_second = (_faces_along(vertices, t, normal) for t in (first, second))
            shorter_first = np.linalg.norm(points[:, 0] - points[:, 2], axis=1) <= np.linalg.norm(
                points[:, 1] - points[:, 3], axis=1
            )
            use_first = fits_first & (~fits_second | shorter_first) | ~fits_first & ~fits_second & shorter_first
            triangles = np.where(use_first[:, None, None], first, second)
        else:
            fan = np.stack([np.repeat(corners[:, :1], size - 2, axis=1), corners[:, 1:-1], corners[:, 2:]], axis=2)
            convex = _faces_along(vertices, fan, normal)
            triangles = fan
            for row in np.flatnonzero(~convex & np.any(normal != 0, axis=1)):  # (a flat polygon keeps its fan)
                triangles[row] = _ears(points[row], normal[row], corners[row], int(chosen[row]))
        pieces.append(triangles.reshape(-1, 3))
        owners.append(np.repeat(chosen, triangles.shape[1]))
    order = np.argsort(np.concatenate(owners), kind="stable")
    return np.concatenate(pieces)[order]


def _without_repeated_corners(counts: np.ndarray, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The polygons (counts, corners) with a corner that repeats the one before it (cyclically) left out of
    every polygon of 4 or more corners that keeps at least 3: a quad ``a b c c`` is the triangle ``a b c``."""
    owner = np.repeat(np.arange(len(counts)), counts)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    position = np.arange(len(flat)) - starts[owner]
    repeated = flat == flat[starts[owner] + (position + 1) % counts[owner]]
    left = counts - np.bincount(owner, repeated, len(counts)).astype(np.int64)
    repeated &= ((counts >= 4) & (left >= 3))[owner]
    if not repeated.any():
        return counts, flat
    return counts - np.bincount(owner, repeated, len(counts)).astype(np.int64), flat[~repeated]


def _vtk_polygons(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(corners concatenated, corner counts (m,)) of a VTK face array ``[c, i_1 .. i_c, c, ...]``."""
    for size in (3, 4):  # all triangles or all quads: one reshape
        if cells.size % (size + 1) == 0 and np.all(cells[:: size + 1] == size):
            rows = cells.reshape(-1, size + 1)
            return rows[:, 1:].ravel(), np.full(len(rows), size)
    counts, starts, at = [], [], 0
    while at < cells.size:
        counts.append(int(cells[at]))
        starts.append(at + 1)
        at += 1 + counts[-1]
    if at != cells.size or min(counts, default=3) < 0:
        raise MeshError("the PolyData's face array does not parse as [count, ids ...] records")
    corners = np.concatenate([cells[s : s + c] for s, c in zip(starts, counts)]) if counts else cells[:0]
    return corners, np.array(counts, dtype=np.int64)


def _newell_normals(points: np.ndarray) -> np.ndarray:
    """(p, 3) Newell normals (twice the vector area) of p polygons given as (p, c, 3) corners."""
    following = np.roll(points, -1, axis=1)
    return np.cross(points, following).sum(axis=1)


def _faces_along(vertices: np.ndarray, triangles: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(p,) whether every triangle of (p, t, 3) has a positive area along its polygon's normal (p, 3)."""
    a, b, c = (vertices[triangles[..., i]] for i in range(3))
    return np.all(np.einsum("ptj,pj->pt", np.cross(b - a, c - a), normal) > 0, axis=1)


def _ears(points: np.ndarray, normal: np.ndarray, corners: np.ndarray, face: int) -> np.ndarray:
    """The (c - 2, 3) triangles of one non-convex polygon by ear cutting in the plane normal to ``normal``."""
    u = np.cross(normal, np.eye(3)[np.argmin(np.abs(normal))])
    u /= np.linalg.norm(u)
    v = np.cross(normal / np.linalg.norm(normal), u)
    plane = np.stack([points @ u, points @ v], axis=1)  # counter-clockwise seen along the normal
    if _crosses_itself(plane):
        raise MeshError(f"face {face} is a polygon that crosses itself: it cannot be cut into triangles")
    left = list(range(len(points)))
    triangles = []

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    while len(left) > 3:
        for position, i in enumerate(left):
            before, after = left[position - 1], left[(position + 1) % len(left)]
            o, a, b = plane[before], plane[i], plane[after]
            if cross(o, a, b) <= 0:
                continue  # a reflex corner (or a straight one): not an ear
            inside = [
                j
                for j in left
                if j not in (before, i, after)
                and cross(o, a, plane[j]) >= 0
                and cross(a, b, plane[j]) >= 0
                and cross(b, o, plane[j]) >= 0
            ]
            if not inside:
                triangles.append((corners[before], corners[i], corners[after]))
                left.pop(position)
                break
        else:
            raise MeshError(f"face {face} is a polygon that crosses itself: it cannot be cut into triangles")
    triangles.append(tuple(corners[left]))
    return np.array(triangles, dtype=np.int64)


def _crosses_itself(plane: np.ndarray) -> bool:
    """Whether two edges of a closed polygon (c, 2) that share no corner cross (properly, in the plane)."""
    a, b = plane, np.roll(plane, -1, axis=0)
    c = len(plane)

    def side(o, p, q):  # sign of (p - o) x (q - o), broadcast over edge pairs
        return np.sign(
            (p[..., 0] - o[..., 0]) * (q[..., 1] - o[..., 1]) - (p[..., 1] - o[..., 1]) * (q[..., 0] - o[..., 0])
        )

    i, j = np.triu_indices(c, k=2)
    keep = (j - i) % c != c - 1  # the last edge shares a corner with the first
    i, j = i[keep], j[keep]
    proper = (side(a[i], b[i], a[j]) * side(a[i], b[i], b[j]) < 0) & (
        side(a[j], b[j], a[i]) * side(a[j], b[j], b[i]) < 0
    )
    return bool(np.any(proper))
