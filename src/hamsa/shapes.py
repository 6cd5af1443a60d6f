"""Built-in surfaces generated in code, for tests, demos and benchmarks (no download needed).

Each function returns a :class:`~hamsa.mesh.TriMesh` with outward-facing, consistently oriented
triangles. Analytic spectra worth knowing: the unit sphere has eigenvalues l(l+1) with multiplicity
2l+1; the flat a x b rectangle with free (Neumann) boundary has pi^2 (i^2/a^2 + j^2/b^2).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.spatial import ConvexHull

from hamsa.errors import MeshError
from hamsa.implicit import Skeleton, implicit_surface, pose_vertices
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


def disk(radius: float = 1.0, rings: int = 16) -> TriMesh:
    """A flat disk of ``radius`` in the z = 0 plane: the center and ``rings`` concentric rings of 6i points.

    The points are Delaunay-triangulated (nearly equilateral triangles, spacing ``radius / rings``); the
    outer ring lies on the circle. Dirichlet eigenvalues of the unit disk are the squared Bessel zeros
    ``j_{m,k}^2`` (5.783, 14.682 twice, 26.374 twice, 30.471, ...), Neumann ones the squared zeros of ``J_m'``.
    """
    from scipy.spatial import Delaunay

    if rings < 1 or radius <= 0:
        raise ValueError("need rings >= 1 and radius > 0")
    points = [np.zeros((1, 2))]
    for ring in range(1, rings + 1):
        angle = 2 * np.pi * (np.arange(6 * ring) + 0.5 * (ring % 2)) / (6 * ring)
        points.append(radius * ring / rings * np.stack([np.cos(angle), np.sin(angle)], axis=1))
    xy = np.concatenate(points)
    faces = Delaunay(xy).simplices.astype(np.int64)
    a, b, c = (xy[faces[:, i]] for i in range(3))
    clockwise = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]) < 0
    faces[clockwise] = faces[clockwise][:, ::-1]
    return TriMesh(np.column_stack([xy, np.zeros(len(xy))]), faces)


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


# ------------------------------------------------------------------------ articulated shapes
def _mirror(bones: list[tuple], parent_offset: int) -> list[tuple]:
    """The bones mirrored to -x, with parents shifted by ``parent_offset`` (or kept when in the trunk)."""
    mirrored = []
    for head, tail, radii, parent in bones:
        flip = np.array([-1.0, 1.0, 1.0])
        mirrored.append((np.multiply(head, flip), np.multiply(tail, flip), radii, parent + parent_offset))
    return mirrored


def _skeleton(bones: list[tuple], blend: float) -> Skeleton:
    heads, tails, radii, parents = zip(*bones)
    return Skeleton(
        np.array(heads, dtype=np.float64),
        np.array(tails, dtype=np.float64),
        np.array(radii, dtype=np.float64),
        tuple(parents),
        blend,
    )


def _humanoid_skeleton() -> Skeleton:
    """A standing figure, 1.75 tall, z up, facing +y, arms lowered 30 degrees (a relaxed A pose)."""
    trunk = [
        ((0, 0, 0.90), (0, 0, 1.12), (0.13, 0.14), -1),  # 0 pelvis
        ((0, 0, 1.12), (0, 0, 1.36), (0.14, 0.15), 0),  # 1 chest
        ((0, 0, 1.36), (0, 0, 1.50), (0.05, 0.05), 1),  # 2 neck
        ((0, 0.01, 1.54), (0, 0.02, 1.66), (0.095, 0.085), 2),  # 3 head
    ]
    left_arm = [
        ((0.17, 0, 1.34), (0.42, 0, 1.20), (0.055, 0.045), 1),  # 4 upper arm
        ((0.42, 0, 1.20), (0.64, 0, 1.08), (0.045, 0.035), 4),  # 5 forearm
        ((0.64, 0, 1.08), (0.74, 0, 1.03), (0.035, 0.04), 5),  # 6 hand
    ]
    left_leg = [
        ((0.10, 0, 0.90), (0.12, 0, 0.50), (0.075, 0.055), 0),  # 10 thigh
        ((0.12, 0, 0.50), (0.13, 0, 0.09), (0.055, 0.04), 10),  # 11 shin
        ((0.13, 0, 0.06), (0.14, 0.13, 0.03), (0.04, 0.035), 11),  # 12 foot
    ]
    right_arm = [(h, t, r, p if p < 4 else p + 3) for h, t, r, p in _mirror(left_arm, 0)]
    right_leg = [(h, t, r, p if p < 10 else p + 3) for h, t, r, p in _mirror(left_leg, 0)]
    return _skeleton(trunk + left_arm + right_arm + left_leg + right_leg, blend=0.06)


_Y, _X, _Z = (0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)

HUMANOID_POSES = {
    "rest": {},
    "arms up": {4: (_Y, -0.7), 7: (_Y, 0.7), 5: (_Y, -0.3), 8: (_Y, 0.3)},
    "walk": {10: (_X, 0.45), 11: (_X, -0.5), 13: (_X, -0.35), 5: (_X, 0.5), 8: (_X, 0.3), 4: (_X, -0.3), 7: (_X, 0.3)},
    "wave": {7: (_Y, 1.0), 8: (_Y, 0.6), 3: (_Z, 0.4), 5: (_X, 0.6)},
    "crouch": {10: (_X, 0.6), 11: (_X, -0.8), 13: (_X, 0.6), 14: (_X, -0.8), 1: (_X, 0.2)},
}
"""Joint rotations of the built-in humanoid: bone -> (axis, radians) about the bone's rest head."""


def _hand_skeleton() -> Skeleton:
    """A right hand, palm in the xy plane facing -z, fingers along +y, about 2.3 long."""
    bones = [((0, -0.55, 0), (0, 0.0, 0), (0.17, 0.19), -1)]  # 0 wrist
    knuckles = (-0.36, -0.12, 0.12, 0.36)
    lengths = ((0.38, 0.24, 0.2), (0.46, 0.3, 0.22), (0.44, 0.28, 0.21), (0.32, 0.2, 0.18))
    for x, phalanges in zip(knuckles, lengths):  # palm bones 1, 5, 9, 13 and three phalanges each
        bones.append(((0.6 * x, 0.0, 0), (x, 0.75, 0), (0.12, 0.1), 0))
        direction = np.array([0.25 * x, 1.0, 0.0])
        direction /= np.linalg.norm(direction)
        start, radius = np.array([x, 0.75, 0.0]), 0.078
        parent = len(bones) - 1
        for length in phalanges:
            end = start + length * direction
            bones.append((start, end, (radius, radius - 0.008), parent))
            start, radius, parent = end, radius - 0.008, len(bones) - 1
    thumb = [((-0.2, 0.05, 0), (-0.55, 0.35, 0), (0.11, 0.085), 0)]  # 17 metacarpal, 18-19 phalanges
    start = np.array([-0.55, 0.35, 0.0])
    direction = np.array([-0.45, 1.0, 0.0]) / np.linalg.norm([-0.45, 1.0, 0.0])
    for length, parent in ((0.32, 17), (0.26, 18)):
        thumb.append((start, start + length * direction, (0.085, 0.078), parent))
        start = start + length * direction
    return _skeleton(bones + thumb, blend=0.05)


_CURL = (_X, -0.55)
HAND_POSES = {
    "open": {},
    "curled": {b: _CURL for b in (2, 3, 4, 6, 7, 8, 10, 11, 12, 14, 15, 16)} | {18: (_Z, -0.3)},
    "pointing": {b: (_X, -0.9) for b in (6, 7, 8, 10, 11, 12, 14, 15, 16)} | {18: (_Z, -0.5), 19: (_X, -0.5)},
    "spread": {2: (_Z, 0.2), 14: (_Z, -0.12), 17: (_Z, 0.25), 3: _CURL, 11: _CURL},
}
"""Joint rotations of the built-in hand: bone -> (axis, radians)."""


@lru_cache(maxsize=8)
def _rest(kind: str, spacing: float) -> TriMesh:
    skeleton = _humanoid_skeleton() if kind == "humanoid" else _hand_skeleton()
    lower, upper = skeleton.bounds()
    return implicit_surface(skeleton, lower, upper, spacing)


def _posed(kind: str, pose: str, spacing: float) -> TriMesh:
    poses = HUMANOID_POSES if kind == "humanoid" else HAND_POSES
    if pose not in poses:
        raise MeshError(f"unknown {kind} pose '{pose}'; known: {', '.join(poses)}")
    rest = _rest(kind, float(spacing))
    if not poses[pose]:
        return rest
    skeleton = _humanoid_skeleton() if kind == "humanoid" else _hand_skeleton()
    blend = 1.3 * float(np.median(skeleton.radii))
    return TriMesh(pose_vertices(skeleton, rest.vertices, poses[pose], blend), rest.faces)


def humanoid(pose: str = "rest", spacing: float = 0.02) -> TriMesh:
    """An articulated human-like surface (head, arms, hands, legs, feet; genus 0), 1.75 tall, z up.

    Generated in code: a skeleton of round cones blended into one implicit surface, meshed by surface
    nets (:mod:`hamsa.implicit`) — about 7 300 vertices at the default ``spacing`` (length units per
    grid cell), 2 700 at 0.025. Every pose in :data:`HUMANOID_POSES` bends the same rest mesh at its joints, so
    all poses share the connectivity and vertex i corresponds to vertex i: a near-isometric family with
    identity ground truth, like TOSCA or SCAPE (edge lengths change by a few percent, more at bent joints).
    """
    return _posed("humanoid", pose, spacing)


def hand(pose: str = "open", spacing: float = 0.03) -> TriMesh:
    """An articulated hand-like surface: wrist, palm, four fingers of three phalanges and a thumb.

    About 2.3 long, palm in the xy plane, fingers along +y; about 6 000 vertices at the default
    ``spacing``. Poses in :data:`HAND_POSES` share the connectivity (see :func:`humanoid`).
    """
    return _posed("hand", pose, spacing)
