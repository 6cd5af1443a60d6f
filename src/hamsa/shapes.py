"""Built-in surfaces generated in code, for tests, demos and benchmarks (no download needed).

Each function returns a :class:`~hamsa.mesh.TriMesh` with outward-facing, consistently oriented
triangles. Analytic spectra worth knowing: the unit sphere has eigenvalues l(l+1) with multiplicity
2l+1; the flat a x b rectangle with free (Neumann) boundary has pi^2 (i^2/a^2 + j^2/b^2).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull

from hamsa.mesh import TriMesh


def icosphere(subdivisions: int = 3, radius: float = 1.0) -> TriMesh:
    """Subdivided icosahedron projected on a sphere: 10 * 4**subdivisions + 2 vertices."""
    if subdivisions < 0:
        raise ValueError("subdivisions must be >= 0")
    t = (1.0 + 5.0**0.5) / 2.0
    v = np.array(
        [
            [-1, t, 0],
            [1, t, 0],
            [-1, -t, 0],
            [1, -t, 0],
            [0, -1, t],
            [0, 1, t],
            [0, -1, -t],
            [0, 1, -t],
            [t, 0, -1],
            [t, 0, 1],
            [-t, 0, -1],
            [-t, 0, 1],
        ],
        dtype=float,
    )
    f = np.array(
        [
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ],
        dtype=np.int64,
    )
    for _ in range(subdivisions):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        mid = len(v) + inverse.reshape(3, -1).T  # midpoint index of edges (01, 12, 20)
        v = np.vstack([v, (v[unique[:, 0]] + v[unique[:, 1]]) / 2])
        a, b, c = f[:, 0], f[:, 1], f[:, 2]
        ab, bc, ca = mid[:, 0], mid[:, 1], mid[:, 2]
        f = np.concatenate([np.stack(x, axis=1) for x in ((a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca))])
    v = radius * v / np.linalg.norm(v, axis=1, keepdims=True)
    return TriMesh(v, f)


def sphere(n_vertices: int = 5000, radius: float = 1.0) -> TriMesh:
    """A sphere with exactly ``n_vertices`` near-uniform vertices (Fibonacci lattice + convex hull)."""
    if n_vertices < 4:
        raise ValueError("a sphere needs at least 4 vertices")
    i = np.arange(n_vertices) + 0.5
    z = 1.0 - 2.0 * i / n_vertices
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (1.0 + 5.0**0.5) * i
    points = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    faces = ConvexHull(points).simplices.astype(np.int64)
    return TriMesh(radius * points, _orient_outward(points, faces))


def _orient_outward(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Flip faces of a star-shaped (around the origin) closed surface so their normals point out."""
    p = points[faces]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    inward = np.einsum("ij,ij->i", normal, p.mean(axis=1)) < 0
    faces = faces.copy()
    faces[inward] = faces[inward][:, ::-1]
    return faces


def _grid_faces(rows: int, cols: int, wrap_cols: bool) -> np.ndarray:
    """Two triangles per cell of a rows x cols vertex grid (row-major), alternating diagonals."""
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(cols if wrap_cols else cols - 1), indexing="ij")
    r, c = r.ravel(), c.ravel()
    c1 = (c + 1) % cols
    a, b, d, e = r * cols + c, r * cols + c1, (r + 1) * cols + c, (r + 1) * cols + c1
    flip = (r + c) % 2 == 1
    t1 = np.where(flip[:, None], np.stack([a, b, d], 1), np.stack([a, b, e], 1))
    t2 = np.where(flip[:, None], np.stack([b, e, d], 1), np.stack([a, e, d], 1))
    return np.concatenate([t1, t2]).astype(np.int64)


def rectangle(width: float = 1.0, height: float = 1.0, nx: int = 40, ny: int = 40) -> TriMesh:
    """A flat ``width x height`` rectangle in the z = 0 plane with an (nx+1) x (ny+1) vertex grid.

    It has a boundary: the eigenproblem gets natural (Neumann) conditions, with eigenvalues
    ``pi^2 (i^2 / width^2 + j^2 / height^2)``. Diagonals alternate to avoid a directional bias.
    """
    x, y = np.meshgrid(np.linspace(0, width, nx + 1), np.linspace(0, height, ny + 1), indexing="ij")
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    faces = _grid_faces(nx + 1, ny + 1, wrap_cols=False)
    return TriMesh(vertices, faces[:, ::-1] if _normal_z(vertices, faces[0]) < 0 else faces)


def _normal_z(vertices: np.ndarray, face: np.ndarray) -> float:
    p = vertices[face]
    return float(np.cross(p[1] - p[0], p[2] - p[0])[2])


def torus(major_radius: float = 1.0, minor_radius: float = 0.35, n_major: int = 64, n_minor: int = 24) -> TriMesh:
    """A torus around the z axis with n_major x n_minor vertices."""
    u, w = np.meshgrid(
        np.linspace(0, 2 * np.pi, n_major, endpoint=False),
        np.linspace(0, 2 * np.pi, n_minor, endpoint=False),
        indexing="ij",
    )
    ring = major_radius + minor_radius * np.cos(w)
    vertices = np.stack([(ring * np.cos(u)).ravel(), (ring * np.sin(u)).ravel(), (minor_radius * np.sin(w)).ravel()], 1)
    faces = _grid_faces(n_major + 1, n_minor, wrap_cols=True)
    faces = np.where(faces >= n_major * n_minor, faces - n_major * n_minor, faces)  # wrap the major direction
    return TriMesh(vertices, faces)


def surface_of_revolution(profile_r: np.ndarray, profile_z: np.ndarray, n_around: int) -> TriMesh:
    """Revolve a profile curve (r(s), z(s)) about the z axis; r = 0 at both ends closes it with poles.

    ``profile_r`` and ``profile_z`` have shape (p,); the first and last r must be 0 (the poles).
    """
    r = np.asarray(profile_r, dtype=float)
    z = np.asarray(profile_z, dtype=float)
    if r[0] != 0 or r[-1] != 0:
        raise ValueError("the profile must start and end on the axis (r = 0)")
    angle = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    rings = len(r) - 2
    ring_v = np.stack(
        [
            np.outer(r[1:-1], np.cos(angle)).ravel(),
            np.outer(r[1:-1], np.sin(angle)).ravel(),
            np.repeat(z[1:-1], n_around),
        ],
        axis=1,
    )
    vertices = np.vstack([[0, 0, z[0]], ring_v, [0, 0, z[-1]]])
    body = _grid_faces(rings, n_around, wrap_cols=True) + 1
    j = np.arange(n_around)
    bottom = np.stack([np.zeros(n_around, dtype=np.int64), 1 + (j + 1) % n_around, 1 + j], axis=1)
    last = 1 + (rings - 1) * n_around
    top = np.stack([np.full(n_around, len(vertices) - 1), last + j, last + (j + 1) % n_around], axis=1)
    faces = np.concatenate([bottom, body, top])
    faces = _orient_about_axis(vertices, faces)
    return TriMesh(vertices, faces)


def _orient_about_axis(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Orient a surface of revolution outward: normals point away from the z axis / the poles' side."""
    p = vertices[faces]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    centroid = p.mean(axis=1)
    outward = centroid.copy()
    outward[:, 2] = 0.0
    polar = np.linalg.norm(outward, axis=1) < 1e-12 * (1 + np.abs(centroid[:, 2]))
    outward[polar, 2] = centroid[polar, 2]
    majority_inward = np.sum(np.einsum("ij,ij->i", normal, outward) < 0) > len(faces) / 2
    return faces[:, ::-1].copy() if majority_inward else faces


def uv_sphere(n_latitude: int = 32, n_longitude: int = 64, radius: float = 1.0) -> TriMesh:
    """Latitude-longitude sphere (poles are high-valence vertices; use :func:`sphere` for uniform sampling)."""
    theta = np.linspace(0, np.pi, n_latitude + 1)
    return surface_of_revolution(
        radius * np.sin(theta) * (np.arange(n_latitude + 1) % n_latitude != 0), -radius * np.cos(theta), n_longitude
    )


def capsule(radius: float = 0.5, length: float = 2.0, n_around: int = 48, n_along: int | None = None) -> TriMesh:
    """A cylinder of the given radius and length capped by two hemispheres, along the z axis.

    The profile is sampled at near-uniform arc length (about the spacing of ``n_around`` around).
    """
    spacing = 2 * np.pi * radius / n_around
    arc = np.pi * radius + length
    count = n_along or max(4, int(round(arc / spacing)))
    s = np.linspace(0, arc, count + 1)
    cap = np.pi * radius / 2
    r = np.where(
        s < cap, radius * np.sin(s / radius), np.where(s > cap + length, radius * np.sin((arc - s) / radius), radius)
    )
    z = np.where(
        s < cap,
        -length / 2 - radius * np.cos(s / radius),
        np.where(s > cap + length, length / 2 + radius * np.cos((arc - s) / radius), s - cap - length / 2),
    )
    r[0] = r[-1] = 0.0
    return surface_of_revolution(r, z, n_around)
