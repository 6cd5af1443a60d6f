"""Repairs with one right answer: what ``load_mesh(..., repair=True)``, ``load_point_cloud(..., repair=True)``
and ``hamsa ... --repair`` do.

By default hamsa refuses defective meshes with a :class:`~hamsa.errors.MeshError` naming the defect.
Some defects have a well-defined fix that changes nothing a user could want kept:

* faces that repeat a vertex (zero area, no contribution to any operator) are dropped;
* duplicate faces (the same three vertices) are dropped, keeping the first;
* non-manifold vertices (several fans of faces meeting at one vertex, like two cones tip to tip) are
  split: each extra fan gets its own copy of the vertex;
* inconsistent orientation is fixed per connected component (faces flipped to agree with the
  component's first face), and closed components are turned outward (positive signed volume);
* unreferenced vertices are dropped;
* optionally (``keep="largest"``), only the largest connected component (by area) is kept.

What has no single right answer is still refused: non-finite or huge coordinates, indices out of
range, zero-area faces with distinct vertices, non-manifold edges, non-orientable surfaces.
Vertex indices change only by removal and appending: ``kept[i]`` is the original index of new
vertex i, so ground-truth correspondences can be carried over.

A point cloud (:func:`repair_point_cloud`) loses its points with non-finite coordinates (the empty rows of
a scan), repeated points (keeping the first) and stray points (:func:`hamsa.pointcloud.stray_points`:
isolated points and small groups far off the surface, each of which would add a spurious low eigenpair),
and optionally (``keep="largest"``) all but its largest piece (by mass) that the operator joins.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, fields

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components

from hamsa.eigen import eigenbasis, unresolved_eigenpairs
from hamsa.errors import InputWarning, MeshError
from hamsa.mesh import TriMesh, as_coordinates, as_trimesh
from hamsa.pointcloud import PointCloud


class _Counts:
    """A repair's report: one count per kind of change (all zeros: the input was already clean)."""

    @property
    def changed(self) -> bool:
        return any(getattr(self, field.name) for field in fields(self))

    def __str__(self) -> str:
        parts = [f"{getattr(self, f.name)} {f.name.replace('_', ' ')}" for f in fields(self) if getattr(self, f.name)]
        return "repaired: " + ", ".join(parts) if parts else "nothing to repair"


@dataclass(frozen=True)
class RepairReport(_Counts):
    """What :func:`repair_mesh` changed (all zeros: the mesh was already clean)."""

    degenerate_faces: int = 0
    duplicate_faces: int = 0
    split_vertices: int = 0
    flipped_faces: int = 0
    dropped_components: int = 0
    unreferenced_vertices: int = 0


@dataclass(frozen=True)
class PointCloudRepairReport(_Counts):
    """What :func:`repair_point_cloud` dropped (all zeros: the cloud was already clean)."""

    non_finite_points: int = 0
    repeated_points: int = 0
    stray_points: int = 0
    dropped_pieces: int = 0
    unresolved_points: int = 0


def repair_mesh(vertices, faces, keep: str = "all") -> tuple[TriMesh, np.ndarray, RepairReport]:
    """Apply the well-defined repairs listed in the module docstring.

    Parameters
    ----------
    vertices : (n, 3) array, faces : (m, 3) integer array (0-based)
    keep : "all" components, or "largest" (by area)

    Returns
    -------
    (mesh, kept, report): the repaired TriMesh, ``kept`` (n',) original index of each new vertex, and a
    :class:`RepairReport`. Raises MeshError for defects without a single right fix.
    """
    if keep not in ("all", "largest"):
        raise MeshError(f"keep must be 'all' or 'largest', got {keep!r}")
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        raise MeshError(f"need (n, 3) vertices and (m, 3) faces, got {vertices.shape} and {faces.shape}")
    if not np.issubdtype(faces.dtype, np.integer) or (faces.size and (faces.min() < 0 or faces.max() >= len(vertices))):
        raise MeshError(f"face indices must be integers in [0, {len(vertices)})")
    faces = faces.astype(np.int64)
    counts = {}

    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    faces, counts["degenerate_faces"] = faces[~repeated], int(repeated.sum())
    _, first = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
    counts["duplicate_faces"] = len(faces) - len(first)
    faces = faces[np.sort(first)]
    if len(faces) == 0:
        raise MeshError("no faces left after dropping degenerate and duplicate faces")

    kept = np.arange(len(vertices))
    faces, kept, counts["split_vertices"] = _split_non_manifold_vertices(faces, kept)
    vertices = vertices[kept]
    faces, counts["flipped_faces"] = _orient(vertices, faces)
    faces, counts["dropped_components"] = _keep_components(vertices, faces, keep)

    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    counts["unreferenced_vertices"] = int((~used[: len(used)]).sum())
    new_index = np.cumsum(used) - 1
    mesh = TriMesh(vertices[used], new_index[faces])
    return mesh, kept[used], RepairReport(**counts)


def repair_point_cloud(
    points, keep: str = "all", modes: int = 0, **cloud_options
) -> tuple[PointCloud, np.ndarray, PointCloudRepairReport]:
    """Drop the points of a cloud that have no right place in it, in this order: points with a NaN or infinite
    coordinate, points that repeat an earlier point exactly (the first is kept), the stray points that
    :func:`hamsa.pointcloud.stray_points` finds among the rest, with ``keep="largest"`` every piece of the
    cloud (:attr:`~hamsa.pointcloud.PointCloud.vertex_components`) but the one of largest mass, and with
    ``modes`` the points that the unresolved eigenpairs among the ``modes`` lowest live on
    (:func:`hamsa.eigen.unresolved_eigenpairs`: points nearer the surface than the stray rule looks, patches
    of normals with the wrong sign), solved again until none is left (at most three solves).

    Parameters
    ----------
    points : (n, 3) array
    keep : "all" pieces, or "largest" (by the operator's mass; building the operators twice when it drops any)
    modes : how many of the lowest eigenpairs (of the Laplacian) to check for unresolved ones; 0 (default): no
        eigensolve
    **cloud_options : the keywords of :class:`~hamsa.pointcloud.PointCloud` (``neighbors``, ...); given
        ``normals`` (n, 3) are those of the input points, and the cloud keeps the rows of the points it keeps

    Returns
    -------
    (cloud, kept, report): the :class:`~hamsa.pointcloud.PointCloud` of the points left, ``kept`` (n',) the
    input index of each of its points (ascending), and a :class:`PointCloudRepairReport`. Raises MeshError when
    the points are not an (n, 3) real array, or when what is left is not a valid cloud (too few points, huge
    coordinates).
    """
    if keep not in ("all", "largest"):
        raise MeshError(f"keep must be 'all' or 'largest', got {keep!r}")
    if not isinstance(modes, (int, np.integer)) or modes < 0:
        raise MeshError(f"modes must be a non-negative integer, got {modes!r}")
    points = as_coordinates(points, "points")
    normals = cloud_options.pop("normals", None)
    if normals is not None and np.shape(normals) != points.shape:
        raise MeshError(f"normals have shape {np.shape(normals)}, expected {points.shape}: one per point")

    def cloud_of(rows):
        return PointCloud(points[rows], normals=None if normals is None else np.asarray(normals)[rows], **cloud_options)

    kept = np.flatnonzero(np.isfinite(points).all(axis=1))
    counts = {"non_finite_points": len(points) - len(kept)}
    _, first = np.unique(points[kept], axis=0, return_index=True)
    counts["repeated_points"] = len(kept) - len(first)
    kept = kept[np.sort(first)]
    with warnings.catch_warnings():  # the cloud's own stray-point warning: those points are dropped here
        warnings.simplefilter("ignore", InputWarning)
        cloud = cloud_of(kept)
    stray = cloud.stray_points
    counts["stray_points"] = len(stray)
    if len(stray):
        kept = np.delete(kept, stray)
        cloud = cloud_of(kept)
    count, labels = cloud.vertex_components if keep == "largest" else (1, None)
    counts["dropped_pieces"] = count - 1
    if counts["dropped_pieces"]:
        largest = np.argmax(np.bincount(labels, weights=cloud.operators[1].diagonal()))
        kept = kept[labels == largest]
        cloud = cloud_of(kept)
    counts["unresolved_points"] = 0
    for _ in range(_UNRESOLVED_ROUNDS if modes else 0):
        with warnings.catch_warnings():  # eigenbasis's warning names the points dropped here
            warnings.simplefilter("ignore", InputWarning)
            unresolved = unresolved_eigenpairs(eigenbasis(cloud, min(modes, cloud.n_vertices - 1)))[1]
        if not len(unresolved):
            break
        counts["unresolved_points"] += len(unresolved)
        kept = np.delete(kept, unresolved)
        cloud = cloud_of(kept)
    return cloud, kept, PointCloudRepairReport(**counts)


_UNRESOLVED_ROUNDS = 3  # eigensolves of repair_point_cloud(modes=)


def orient_faces(mesh) -> TriMesh:
    """The mesh with its faces flipped so that neighbours traverse shared edges in opposite directions and
    each closed piece faces outward: the same vertices in the same order (the orientation repair of
    :func:`repair_mesh`, alone). A consistently oriented mesh is returned as it is. The Laplacian and the
    mass do not depend on the orientation; normals, the signed volume and everything built on them do.

    Raises
    ------
    MeshError
        If the surface is not orientable.
    """
    mesh = as_trimesh(mesh)
    if mesh.is_consistently_oriented:
        return mesh
    faces, _ = _orient(mesh.vertices, mesh.faces)
    return TriMesh(mesh.vertices, faces, manifold=mesh.is_edge_manifold)


def _face_graph(faces: np.ndarray):
    """Interior edges as (face a, face b, same_direction) triples, for edges shared by exactly two faces."""
    m = len(faces)
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    owner = np.tile(np.arange(m), 3)
    key = np.sort(directed, axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    key, directed, owner = key[order], directed[order], owner[order]
    same_as_next = np.all(key[1:] == key[:-1], axis=1)
    start = np.flatnonzero(same_as_next)
    if np.any(same_as_next[1:] & same_as_next[:-1]):
        raise MeshError("an edge is shared by more than two faces (non-manifold edge): no well-defined repair")
    same_direction = directed[start, 0] == directed[start + 1, 0]
    return owner[start], owner[start + 1], same_direction


def _split_non_manifold_vertices(faces: np.ndarray, kept: np.ndarray):
    """Give each extra fan of faces around a vertex its own copy of the vertex."""
    m = len(faces)
    # corners (face, vertex); two corners of one vertex are joined when their faces share an edge at it
    corner_vertex = faces.ravel()
    a, b, _ = _face_graph(faces)
    links_a, links_b = [], []
    for i in range(3):
        for j in range(3):
            shared = faces[a, i] == faces[b, j]
            links_a.append(3 * a[shared] + i)
            links_b.append(3 * b[shared] + j)
    links_a, links_b = np.concatenate(links_a), np.concatenate(links_b)
    graph = sp.coo_matrix((np.ones(len(links_a)), (links_a, links_b)), shape=(3 * m, 3 * m))
    _, fan = connected_components(graph, directed=False)
    # the first fan of each vertex keeps it; every other fan gets a new vertex
    pairs = np.unique(np.stack([corner_vertex, fan], axis=1), axis=0)
    first_fan = np.r_[True, pairs[1:, 0] != pairs[:-1, 0]]
    extra = pairs[~first_fan]
    if len(extra) == 0:
        return faces, kept, 0
    new_ids = len(kept) + np.arange(len(extra))
    lookup = {(int(v), int(f)): int(new) for (v, f), new in zip(extra, new_ids)}
    flat = faces.ravel().copy()
    for c in np.flatnonzero(np.isin(fan, extra[:, 1])):
        flat[c] = lookup.get((int(corner_vertex[c]), int(fan[c])), flat[c])
    return flat.reshape(-1, 3), np.concatenate([kept, extra[:, 0]]), len(extra)


def _orient(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, int]:
    """Flip faces so that neighbours traverse shared edges in opposite directions; closed pieces outward."""
    m = len(faces)
    a, b, same = _face_graph(faces)
    graph = sp.coo_matrix((same.astype(np.float64) + 1.0, (a, b)), shape=(m, m)).tocsr()
    graph = graph + graph.T  # weight 2: same direction (flip needed), 1: consistent
    count, component = connected_components(graph, directed=False)
    flip = np.zeros(m, dtype=bool)
    for piece in range(count):
        root = int(np.flatnonzero(component == piece)[0])
        order, parent = breadth_first_order(graph, root, directed=False, return_predecessors=True)
        children = order[1:]
        if children.size == 0:
            continue
        needs_flip = (np.asarray(graph[parent[children], children]).ravel() == 2).tolist()
        state = flip.tolist()
        for face, up, change in zip(children.tolist(), parent[children].tolist(), needs_flip):
            state[face] = state[up] ^ change
        flip = np.array(state, dtype=bool)
    oriented = np.where(flip[:, None], faces[:, ::-1], faces)
    _, _, same_after = _face_graph(oriented)
    if np.any(same_after):
        raise MeshError("the surface is not orientable (like a Moebius strip): no consistent orientation exists")
    closed = _closed_components(oriented, component, count)
    for piece in closed:
        members = component == piece
        v0, v1, v2 = (vertices[oriented[members, i]] for i in range(3))
        if np.einsum("ij,ij->i", v0, np.cross(v1, v2)).sum() < 0:  # signed volume, outward positive
            oriented[members] = oriented[members, ::-1]
            flip[members] = ~flip[members]
    return oriented, int(flip.sum())


def _closed_components(faces: np.ndarray, component: np.ndarray, count: int) -> list[int]:
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, inverse, uses = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
    boundary_face = np.zeros(len(faces), dtype=bool)
    boundary_face[np.tile(np.arange(len(faces)), 3)[uses[inverse.ravel()] == 1]] = True
    return [piece for piece in range(count) if not boundary_face[component == piece].any()]


def _keep_components(vertices: np.ndarray, faces: np.ndarray, keep: str) -> tuple[np.ndarray, int]:
    if keep == "all":
        return faces, 0
    m = len(faces)
    a, b, _ = _face_graph(faces)
    count, component = connected_components(sp.coo_matrix((np.ones(len(a)), (a, b)), shape=(m, m)), directed=False)
    if count == 1:
        return faces, 0
    v0, v1, v2 = (vertices[faces[:, i]] for i in range(3))
    areas = np.bincount(component, weights=np.linalg.norm(np.cross(v1 - v0, v2 - v0), axis=1), minlength=count)
    return faces[component == np.argmax(areas)], count - 1
