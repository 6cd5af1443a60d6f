"""Triangle meshes of implicit surfaces ``f(x) = 0`` (``f < 0`` inside), and skeleton-based implicits.

:func:`implicit_surface` samples f on a regular grid and builds the surface by *naive surface nets*
(Gibson 1998): one vertex per grid cell that the surface crosses, at the mean of the cell's edge
crossings, then one quad per crossed grid edge joining the four cells around it, split into two
triangles along the shorter diagonal. The vertices are then evened out by a few rounds of damped
umbrella smoothing, each followed by Newton steps that put them back on ``f = 0``. Unlike marching
cubes, surface nets gives well-shaped triangles of about the grid spacing, which the cotangent
Laplacian needs. Where the surface passes within a fraction of a cell of a saddle, a cell can be
ambiguous (two sheets through one cell); the grid value nearest to zero is flipped until none is,
so the result is always a closed manifold.

:class:`Skeleton` is a union of "round cones" (capsules with a radius varying along the bone),
blended with a polynomial smooth minimum — the built-in humanoid and hand of :mod:`hamsa.shapes`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hamsa.errors import MeshError
from hamsa.mesh import TriMesh


def implicit_surface(function, lower, upper, spacing: float, newton_steps: int = 3) -> TriMesh:
    """Mesh the surface ``function(points) = 0`` inside the box [lower, upper] (surface nets).

    Parameters
    ----------
    function : callable, (m, 3) points -> (m,) values, negative inside; roughly a distance (|grad| ~ 1)
    lower, upper : (3,) corners of the sampling box; the surface must lie strictly inside
    spacing : grid step (length units); triangles are about this size
    newton_steps : Newton projections of the vertices onto f = 0 per round (0: keep the raw surface-nets
        vertices, no relaxation)

    Returns
    -------
    TriMesh with outward-facing triangles. Raises MeshError if the surface touches the box or the result
    is not a closed manifold (a feature thinner than about two grid cells).
    """
    lower = np.asarray(lower, dtype=np.float64) - 2 * spacing
    upper = np.asarray(upper, dtype=np.float64) + 2 * spacing
    shape = np.ceil((upper - lower) / spacing).astype(int) + 1
    axes = [lower[d] + spacing * np.arange(shape[d]) for d in range(3)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    values = np.asarray(function(nodes), dtype=np.float64).reshape(shape)
    inside = values < 0
    border = np.ones(shape, dtype=bool)
    border[1:-1, 1:-1, 1:-1] = False
    if inside[border].any():
        raise MeshError("the implicit surface touches the sampling box: enlarge [lower, upper]")

    values[values == 0] = 1e-12 * spacing  # a node exactly on the surface counts as outside
    values = _disambiguate(values)
    inside = values < 0
    cells = shape - 1
    cell_sum = np.zeros((int(np.prod(cells)), 3))
    cell_count = np.zeros(int(np.prod(cells)))
    quads = []
    for axis in range(3):
        a, b = (axis + 1) % 3, (axis + 2) % 3
        step = np.zeros(3, dtype=int)
        step[axis] = 1
        start = np.argwhere(
            inside[: shape[0] - step[0], : shape[1] - step[1], : shape[2] - step[2]]
            != inside[step[0] :, step[1] :, step[2] :]
        )
        f0 = values[tuple(start.T)]
        f1 = values[tuple((start + step).T)]
        t = f0 / (f0 - f1)
        points = lower + spacing * (start + t[:, None] * step)
        # the four cells around the edge, in counterclockwise order seen from +axis
        ring = []
        for da, db in ((-1, -1), (0, -1), (0, 0), (-1, 0)):
            offset = np.zeros(3, dtype=int)
            offset[a], offset[b] = da, db
            ring.append(np.ravel_multi_index(tuple((start + offset).T), cells))
        ring = np.stack(ring, axis=1)
        for column in range(4):
            np.add.at(cell_sum, ring[:, column], points)
            np.add.at(cell_count, ring[:, column], 1.0)
        outward_positive = inside[tuple(start.T)]  # inside below, outside above: the normal points to +axis
        quads.append(np.where(outward_positive[:, None], ring, ring[:, ::-1]))
    quads = np.concatenate(quads)
    used = np.flatnonzero(cell_count)
    index = np.full(cell_count.size, -1, dtype=np.int64)
    index[used] = np.arange(used.size)
    vertices = cell_sum[used] / cell_count[used, None]
    quads = index[quads]
    vertices = _relax(function, vertices, quads, spacing, newton_steps)
    diagonal_02 = np.linalg.norm(vertices[quads[:, 0]] - vertices[quads[:, 2]], axis=1)
    diagonal_13 = np.linalg.norm(vertices[quads[:, 1]] - vertices[quads[:, 3]], axis=1)
    split = (diagonal_02 <= diagonal_13)[:, None]
    faces = np.concatenate(
        [
            np.where(split, quads[:, [0, 1, 2]], quads[:, [0, 1, 3]]),
            np.where(split, quads[:, [0, 2, 3]], quads[:, [1, 2, 3]]),
        ]
    )
    mesh = TriMesh(vertices, faces)
    if mesh.non_manifold_vertices.size or mesh.boundary_loops:
        raise MeshError("the implicit surface has features thinner than the grid: use a smaller spacing")
    return mesh


_CORNERS = np.array([(i, j, k) for i in (0, 1) for j in (0, 1) for k in (0, 1)])


def _ambiguous_configurations() -> np.ndarray:
    """(256,) bool: cube sign patterns whose inside or outside corners are not connected by cube edges.

    Surface nets puts one vertex per cell, so such a cell would join two sheets of surface at a point.
    """
    neighbours = [[j for j in range(8) if np.abs(_CORNERS[i] - _CORNERS[j]).sum() == 1] for i in range(8)]

    def pieces(members):
        left, count = set(members), 0
        while left:
            stack, count = [left.pop()], count + 1
            while stack:
                for j in neighbours[stack.pop()]:
                    if j in left:
                        left.remove(j)
                        stack.append(j)
        return count

    table = np.zeros(256, dtype=bool)
    for pattern in range(256):
        inside = [i for i in range(8) if pattern >> i & 1]
        outside = [i for i in range(8) if not pattern >> i & 1]
        table[pattern] = pieces(inside) > 1 or pieces(outside) > 1
    return table


_AMBIGUOUS = _ambiguous_configurations()


def _disambiguate(values: np.ndarray, rounds: int = 100) -> np.ndarray:
    """Flip the sign of grid values closest to zero until no cell or cell face is ambiguous.

    Ambiguous faces (inside corners on one diagonal, outside on the other) and ambiguous cells make
    surface nets non-manifold; they occur only where the surface is within a fraction of a cell of a
    saddle (a crease, two sheets nearly touching). Flipping the sign of the corner nearest to the surface
    changes the surface by less than a cell there and resolves the ambiguity.
    """
    values = values.copy()
    n0, n1, n2 = values.shape
    for _ in range(rounds):
        inside = values < 0
        corners = np.stack([inside[i : n0 - 1 + i, j : n1 - 1 + j, k : n2 - 1 + k] for i, j, k in _CORNERS], axis=-1)
        pattern = (corners * (1 << np.arange(8))).sum(axis=-1)
        bad = _AMBIGUOUS[pattern]
        for a, b in ((0, 1), (1, 2), (0, 2)):  # the two faces of each cell normal to the third axis
            for low in (0, 1):
                face = [c for c in range(8) if _CORNERS[c][3 - a - b] == low]
                c00, c01, c10, c11 = (corners[..., c] for c in face)
                bad |= (c00 == c11) & (c01 == c10) & (c00 != c01)
        cells = np.argwhere(bad)
        if cells.size == 0:
            return values
        nodes = cells[:, None, :] + _CORNERS[None]  # (m, 8, 3)
        magnitude = np.abs(values[tuple(nodes.transpose(2, 0, 1))])
        flip = nodes[np.arange(len(cells)), np.argmin(magnitude, axis=1)]
        flip = np.unique(flip, axis=0)
        values[tuple(flip.T)] *= -1
    raise MeshError("could not resolve the implicit surface's ambiguous cells: use a smaller spacing")


def _relax(function, vertices: np.ndarray, quads: np.ndarray, spacing: float, newton_steps: int, rounds: int = 4):
    """Even out the vertices: damped umbrella smoothing over the quad graph, each round followed by a
    projection onto f = 0. Surface nets can place two cells' vertices on the same point where the
    surface passes through a grid node; this separates them without changing the surface."""
    rows = quads.ravel()
    cols = np.roll(quads, -1, axis=1).ravel()
    n = len(vertices)
    graph = sp.coo_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n)).tocsr()
    graph = ((graph + graph.T) > 0).astype(np.float64)
    average = sp.diags(1.0 / np.asarray(graph.sum(axis=1)).ravel()) @ graph
    vertices = _project(function, vertices, spacing, newton_steps)
    for _ in range(rounds if newton_steps else 0):
        vertices = _project(function, 0.5 * vertices + 0.5 * (average @ vertices), spacing, newton_steps)
    return vertices


def _project(function, points: np.ndarray, spacing: float, steps: int) -> np.ndarray:
    """Newton steps ``x <- x - f(x) grad f / |grad f|^2`` (central differences), each limited to half a cell."""
    h = 1e-3 * spacing
    offsets = np.vstack([np.eye(3), -np.eye(3)]) * h
    for _ in range(steps):
        value = function(points)
        around = function((points[:, None, :] + offsets[None]).reshape(-1, 3)).reshape(-1, 6)
        gradient = (around[:, :3] - around[:, 3:]) / (2 * h)
        move = -(value / np.maximum((gradient**2).sum(axis=1), 1e-12))[:, None] * gradient
        length = np.linalg.norm(move, axis=1, keepdims=True)
        points = points + move * np.minimum(1.0, 0.5 * spacing / np.maximum(length, 1e-300))
    return points


def _smooth_min(a: np.ndarray, b: np.ndarray, blend: float) -> np.ndarray:
    """Polynomial smooth minimum (C1): equal to min(a, b) when |a - b| >= blend."""
    h = np.maximum(blend - np.abs(a - b), 0.0) / blend
    return np.minimum(a, b) - h * h * blend / 4


@dataclass(frozen=True)
class Skeleton:
    """Bones as round cones: bone i runs from ``heads[i]`` to ``tails[i]`` with radii ``radii[i] = (r0, r1)``.

    ``parents[i]`` is the bone the bone hangs from (-1 for the root); bone i's joint is its head.
    """

    heads: np.ndarray  # (b, 3)
    tails: np.ndarray  # (b, 3)
    radii: np.ndarray  # (b, 2)
    parents: tuple[int, ...]
    blend: float  # smooth-union width (length units)

    def bone_distances(self, points: np.ndarray) -> np.ndarray:
        """(m, b) approximate signed distances to each round cone (negative inside)."""
        axis = self.tails - self.heads
        length2 = np.maximum((axis**2).sum(axis=1), 1e-300)
        relative = points[:, None, :] - self.heads[None]
        t = np.clip((relative * axis[None]).sum(axis=2) / length2, 0.0, 1.0)
        nearest = self.heads[None] + t[..., None] * axis[None]
        radius = self.radii[:, 0] + t * (self.radii[:, 1] - self.radii[:, 0])
        return np.linalg.norm(points[:, None, :] - nearest, axis=2) - radius

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """(m,) the smooth union's value at (m, 3) points (evaluated in chunks to bound memory)."""
        values = np.empty(len(points))
        for start in range(0, len(points), 65536):
            distances = self.bone_distances(points[start : start + 65536])
            value = distances[:, 0]
            for column in range(1, distances.shape[1]):
                value = _smooth_min(value, distances[:, column], self.blend)
            values[start : start + 65536] = value
        return values

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        reach = self.radii.max() + self.blend
        ends = np.vstack([self.heads, self.tails])
        return ends.min(axis=0) - reach, ends.max(axis=0) + reach

    def children(self, bone: int) -> list[int]:
        return [i for i, p in enumerate(self.parents) if p == bone]

    def subtree(self, bone: int) -> list[int]:
        found = [bone]
        for child in self.children(bone):
            found += self.subtree(child)
        return found


def _rotation(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(m, 3, 3) rotations by ``angle`` (m,) radians about the unit ``axis`` (3,) (Rodrigues)."""
    x, y, z = axis / np.linalg.norm(axis)
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    c, s = np.cos(angle)[:, None, None], np.sin(angle)[:, None, None]
    return np.eye(3)[None] + s * K[None] + (1 - c) * (K @ K)[None]


def pose_vertices(skeleton: Skeleton, vertices: np.ndarray, rotations: dict, blend_width: float) -> np.ndarray:
    """Bend a rest-pose surface at the skeleton's joints, keeping its connectivity.

    A joint rotation ``rotations[bone] = (axis (3,), angle)`` turns the bone's subtree about the bone's
    head. A vertex turns by the fraction ``w`` of the angle, a smooth partition of the surface: with
    ``d_in`` / ``d_out`` its distance to the nearest bone inside / outside the subtree,
    ``w = smoothstep(1/2 + (d_out - d_in) / (2 blend_width))`` — 1 on the limb, 0 on the rest, and a
    gradual bend (not a crease) where they meet, so the surface stays close to isometric away from the
    joints. Joints are applied from the leaves up (forward kinematics in rest coordinates).

    Returns
    -------
    (n, 3) posed vertex positions.
    """
    distances = skeleton.bone_distances(vertices)
    posed = np.array(vertices, dtype=np.float64)
    depth = {}
    for bone in range(len(skeleton.parents)):
        d, b = 0, bone
        while skeleton.parents[b] >= 0:
            d, b = d + 1, skeleton.parents[b]
        depth[bone] = d
    for bone in sorted(rotations, key=lambda b: -depth[b]):
        axis, angle = rotations[bone]
        inside = skeleton.subtree(bone)
        outside = [b for b in range(len(skeleton.parents)) if b not in inside]
        d_in = distances[:, inside].min(axis=1)
        d_out = distances[:, outside].min(axis=1) if outside else np.full(len(vertices), np.inf)
        weight = np.clip(0.5 + (d_out - d_in) / (2 * blend_width), 0.0, 1.0)
        weight = weight * weight * (3 - 2 * weight)
        moving = weight > 0
        joint = skeleton.heads[bone]
        R = _rotation(np.asarray(axis, dtype=np.float64), angle * weight[moving])
        posed[moving] = joint + np.einsum("mij,mj->mi", R, posed[moving] - joint)
    return posed
