"""Potentials V on a mesh (and, where they need no faces, a point cloud): (n,) float64 arrays.

Units are 1/length^2 once scaled; each function documents its normalization. Scale matters: the
effect of V on the eigenbasis depends on ``mu * V`` relative to the spectrum (see
:func:`hamsa.theory.critical_potential_scale`), so the shape-derived potentials here are normalized to
a fixed range and the caller picks the scale. The
landmark potential of ICSKM is the normalized geodesic distance,
``hamsa.geodesic.geodesic_distance(mesh, landmarks, normalize=True)``.
"""

from __future__ import annotations

import re

import numpy as np

from hamsa.eigen import Eigenbasis, eigenbasis
from hamsa.errors import HamsaError, PotentialError
from hamsa.geodesic import geodesic_distance
from hamsa.operators import laplacian_operators, vertex_areas
from hamsa.pointcloud import PointCloud, as_shape


def step(mesh, region, height: float, threshold: float | None = None) -> np.ndarray:
    """Finite step potential: ``V = height`` on a region of the surface, 0 elsewhere (paper 2.3).

    Parameters
    ----------
    mesh : TriMesh, (vertices, faces) or PointCloud
    region : (n,) bool array, or (n,) float array with ``threshold``
        The vertices where V = height: a mask, or the vertices whose field value is > threshold.
    height : float
        V0, in units of 1/length^2 (comparable to the eigenvalues: modes with E < V0 are
        concentrated where V = 0, paper Fig. 2).
    threshold : float, optional
        Required when ``region`` is a scalar field.

    Returns
    -------
    (n,) float64
    """
    mesh = as_shape(mesh)
    field = np.asarray(region)
    if field.shape != (mesh.n_vertices,):
        raise PotentialError(f"region has shape {field.shape}, the mesh has {mesh.n_vertices} vertices")
    if field.dtype == bool:
        if threshold is not None:
            raise PotentialError("threshold is only used with a scalar-field region, not a mask")
        mask = field
    else:
        if threshold is None:
            raise PotentialError("a scalar-field region needs a threshold (V = height where field > threshold)")
        mask = np.asarray(field, dtype=np.float64) > threshold
    if not np.isfinite(height):
        raise PotentialError(f"step height must be finite, got {height}")
    return np.where(mask, float(height), 0.0)


def eigenfunction_sum(basis: Eigenbasis, indices=(1, 2, 3, 4), signs=None) -> np.ndarray:
    """The paper's matching potential: a normalized sum of LBO eigenfunctions, shifted to be >= 0.

    ``V = s / max|s| - min(s / max|s|)`` with ``s = sum_j sign_j phi_{indices[j]}`` (0-based indices,
    so the default is phi_2..phi_5, the first four non-constant ones). V lies in [0, 2].

    Parameters
    ----------
    basis : Eigenbasis of the LBO
    indices : sequence of int
    signs : sequence of +-1, optional
        Eigenfunction signs are arbitrary; across shapes they must agree for the potentials to
        correspond (the paper assumes it). Pass signs resolved e.g. by ground truth or by moments.
    """
    indices = np.asarray(indices)
    if indices.size == 0 or indices.min() < 0 or indices.max() >= basis.k:
        raise PotentialError(f"eigenfunction indices {indices.tolist()} are outside the basis (k = {basis.k})")
    signs = np.ones(indices.size) if signs is None else np.asarray(signs, dtype=np.float64)
    if signs.shape != indices.shape or not np.all(np.abs(signs) == 1):
        raise PotentialError("signs must be one +1 or -1 per index")
    total = basis.vectors[:, indices] @ signs
    total = total / np.abs(total).max()
    return total - total.min()


def area_distortion(mesh_a, mesh_b, correspondence=None) -> np.ndarray:
    """Local area distortion of a map between two shapes (paper eq. stablePotential), on mesh_a's vertices.

    ``V(i) = max(a_A(i) / a_B(c(i)), a_B(c(i)) / a_A(i)) >= 1`` with a the lumped vertex areas (the mass of
    each shape's operator: mixed-Voronoi on a mesh, the point-cloud Laplacian's on a cloud) after scaling both
    shapes to unit total area, and c the correspondence (vertex i of A -> vertex c[i] of B; default the
    identity, for shapes that share vertex indexing). Either shape may be a mesh or a point cloud.
    """
    a, b = as_shape(mesh_a), as_shape(mesh_b)
    if correspondence is None and a.n_vertices != b.n_vertices:
        raise PotentialError(
            f"the meshes have {a.n_vertices} and {b.n_vertices} vertices: pass a correspondence (the identity "
            "needs equal vertex counts)"
        )
    c = np.arange(a.n_vertices) if correspondence is None else np.asarray(correspondence)
    if c.shape != (a.n_vertices,) or not np.issubdtype(c.dtype, np.integer):
        raise PotentialError(f"correspondence must be (n_a,) = ({a.n_vertices},) integer indices into mesh_b")
    if c.min() < 0 or c.max() >= b.n_vertices:
        raise PotentialError(f"correspondence indices must be in [0, {b.n_vertices})")
    area_a, area_b = laplacian_operators(a)[1].diagonal(), laplacian_operators(b)[1].diagonal()
    ratio = (area_a / area_a.sum()) / (area_b[c] / area_b.sum())
    return np.maximum(ratio, 1.0 / ratio)


def from_vertex_colors(mesh, colors) -> np.ndarray:
    """Texture potential: Rec. 709 luminance ``0.2126 R + 0.7152 G + 0.0722 B`` in [0, 1].

    ``colors`` is (n, 3) or (n, 4) (alpha ignored), floats in [0, 1] or integers in [0, 255]; ``mesh`` a
    mesh or a point cloud (a coloured scan).
    """
    mesh = as_shape(mesh)
    rgb = np.asarray(colors)
    if rgb.ndim != 2 or rgb.shape[0] != mesh.n_vertices or rgb.shape[1] not in (3, 4):
        raise PotentialError(f"colors must be (n, 3) or (n, 4) with n = {mesh.n_vertices}, got {rgb.shape}")
    rgb = rgb[:, :3].astype(np.float64)
    if np.issubdtype(np.asarray(colors).dtype, np.integer):
        rgb /= 255.0
    if not np.all(np.isfinite(rgb)) or rgb.min() < 0 or rgb.max() > 1:
        raise PotentialError("colors must be in [0, 1] (floats) or [0, 255] (integers)")
    return rgb @ np.array([0.2126, 0.7152, 0.0722])


def dalmatian_texture(mesh, spots: int = 40, radius: float = 0.05, seed: int = 0) -> np.ndarray:
    """A synthetic dalmatian coat: (n, 3) RGB colors in [0, 1], black spots on white (paper Fig. dalmatian).

    ``spots`` discs centered at seeded random vertices (chosen with probability proportional to their
    area), each of geodesic radius ``radius x sqrt(area) x u`` with u uniform in [0.6, 1.4], with a soft
    edge (smoothstep over the outer 30% of the radius). Geodesics by the heat method, so the coat follows
    the surface: on meshes that share vertex indexing (a TOSCA class) ``colors[truth]`` carries the same
    coat to another pose. On a point cloud, its mass and its heat-method geodesics.
    :func:`from_vertex_colors` turns it into a texture potential.
    """
    from hamsa.geodesic import geodesic_solver

    shape = as_shape(mesh)
    if not (isinstance(spots, (int, np.integer)) and spots >= 1) or not radius > 0:
        raise PotentialError(f"need spots >= 1 and radius > 0, got {spots} and {radius}")
    rng = np.random.default_rng(seed)
    areas = laplacian_operators(shape)[1].diagonal()
    centers = rng.choice(shape.n_vertices, size=min(spots, shape.n_vertices), replace=False, p=areas / areas.sum())
    radii = radius * np.sqrt(areas.sum()) * rng.uniform(0.6, 1.4, len(centers))
    closeness = (geodesic_solver(shape).distances_from(centers) / radii).min(axis=1)  # < 1 inside a spot
    edge = np.clip((closeness - 0.7) / 0.3, 0.0, 1.0)
    luminance = edge * edge * (3 - 2 * edge)  # 0 inside, 1 outside
    return np.repeat(luminance[:, None], 3, axis=1)


def curvature(mesh, kind: str = "mean") -> np.ndarray:
    """Discrete curvature per vertex (Meyer et al. 2003), in 1/length (mean) or 1/length^2 (gaussian).

    ``"mean"``: H = |W X|_i / (2 a_i), signed positive where the surface is convex (the mean-curvature
    normal W X / a points inward; sign from the outward vertex normal). On a point cloud W and a are its
    operator's and the sign comes from its estimated outward normals. ``"gaussian"`` (meshes only):
    K = (2 pi - sum of angles) / a_i at interior vertices, (pi - sum) / a_i on the boundary (there it
    also counts the boundary's turning angle, e.g. (pi/2) / a_i at a rectangle's corner).
    ``"absolute_mean"``: |H|.
    """
    shape = as_shape(mesh)
    if kind in ("mean", "absolute_mean"):
        W, A = laplacian_operators(shape)
        laplacian = W @ shape.vertices  # = -(Laplacian) X = 2 a H n (inward-pointing for convex)
        value = np.linalg.norm(laplacian, axis=1) / (2 * A.diagonal())
        if kind == "absolute_mean":
            return value
        normals = shape.normals if isinstance(shape, PointCloud) else shape.vertex_normals
        return value * np.sign(np.einsum("ij,ij->i", laplacian, normals) + 0.0)
    if kind == "gaussian":
        if isinstance(shape, PointCloud):
            raise HamsaError("gaussian curvature needs a mesh's angles; a point cloud has the mean curvature only")
        mesh = shape
        areas = vertex_areas(mesh)
        v, f = mesh.vertices, mesh.faces
        angles = np.zeros(mesh.n_vertices)
        for c in range(3):
            a = v[f[:, (c + 1) % 3]] - v[f[:, c]]
            b = v[f[:, (c + 2) % 3]] - v[f[:, c]]
            angle = np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.einsum("ij,ij->i", a, b))
            angles += np.bincount(f[:, c], weights=angle, minlength=mesh.n_vertices)
        full = np.full(mesh.n_vertices, 2 * np.pi)
        boundary = np.unique(mesh.boundary_edges)
        full[boundary] = np.pi
        return (full - angles) / areas
    raise HamsaError(f"curvature kind must be 'mean', 'absolute_mean' or 'gaussian', got {kind!r}")


SPEC_KINDS = ("geodesic", "step", "eigsum", "curvature", "texture")
_SPEC = re.compile(r"^(?:(?P<scale>[^*:]+)\*)?(?P<kind>[a-z]+):(?P<arguments>.*)$")


def is_spec(text: str) -> bool:
    """Whether ``text`` reads as a potential specification (``[SCALE*]KIND:ARGUMENTS``) rather than a file."""
    match = _SPEC.match(text.strip())
    return match is not None and match["kind"] in SPEC_KINDS


def from_spec(shape, spec: str, vertex_ids=None) -> np.ndarray:
    """A potential (n,) from a one-line specification, ``[SCALE*]KIND:ARGUMENTS`` (the CLI's ``--potential``):

    - ``geodesic:I[,J,...]``: geodesic distance from the vertices I, J, ... normalized to [0, 1] (the
      paper's landmark potential; pieces without a source get 1);
    - ``step:AXIS>VALUE`` or ``step:AXIS<VALUE``: 1 where the x, y or z coordinate (in the shape's own
      units) is above (below) VALUE, 0 elsewhere (the paper's step potential, Fig. 2);
    - ``eigsum:I-J`` or ``eigsum:I,J,...``: :func:`eigenfunction_sum` of the shape's LBO eigenfunctions
      with those 0-based indices (``eigsum:1-4`` is the paper's phi_2..phi_5), in [0, 2];
    - ``curvature:mean|absolute_mean|gaussian``: :func:`curvature`;
    - ``texture:FILE``: :func:`from_vertex_colors` of the vertex colours of FILE
      (:func:`hamsa.io.read_vertex_colors`; e.g. the coloured scan the shape was read from), in [0, 1];

    times SCALE (default 1), e.g. ``100*geodesic:12,40``. ``vertex_ids`` (n,): when ``shape`` is a
    repaired copy of an input, the input vertex of each of its vertices (``Eigenbasis.vertex_ids``); the
    ids in a ``geodesic`` spec and the rows of a ``texture`` file are then the input's.

    Raises
    ------
    PotentialError
        On a malformed specification, an unknown kind or axis, a vertex id outside the shape (or removed by
        a repair), or a scale that is not a finite number.
    """
    shape = as_shape(shape)
    match = _SPEC.match(spec.strip())
    if match is None or match["kind"] not in SPEC_KINDS:
        raise PotentialError(
            f"potential {spec!r} is not [SCALE*]KIND:ARGUMENTS with KIND one of {', '.join(SPEC_KINDS)} "
            "(e.g. 100*geodesic:12,40 or step:z>0.5)"
        )
    scale = _spec_scale(match["scale"], spec)
    kind, arguments = match["kind"], match["arguments"].strip()
    if kind == "geodesic":
        ids = _spec_vertices(_spec_integers(arguments, spec), shape.n_vertices, vertex_ids, spec)
        values = geodesic_distance(shape, ids, normalize=True, unreachable="farthest")
    elif kind == "step":
        values = _spec_step(shape, arguments, spec)
    elif kind == "eigsum":
        bounds = _spec_integers(arguments.replace("-", ","), spec) if "-" in arguments else None
        if bounds is not None and len(bounds) != 2:
            raise PotentialError(f"potential {spec!r}: a range of eigenfunctions is FIRST-LAST, e.g. eigsum:1-4")
        indices = list(range(bounds[0], bounds[1] + 1)) if bounds else _spec_integers(arguments, spec)
        if not indices or min(indices) < 0:
            raise PotentialError(f"potential {spec!r}: eigsum needs 0-based indices, e.g. eigsum:1-4")
        values = eigenfunction_sum(eigenbasis(shape, max(indices) + 1), indices)
    elif kind == "texture":
        values = from_vertex_colors(shape, _spec_colours(arguments, shape.n_vertices, vertex_ids, spec))
    else:
        if arguments not in ("mean", "absolute_mean", "gaussian"):
            raise PotentialError(f"potential {spec!r}: curvature is mean, absolute_mean or gaussian")
        values = curvature(shape, arguments)
    return scale * values


def _spec_colours(path: str, n: int, vertex_ids, spec: str) -> np.ndarray:
    """The vertex colours of ``path``, one row per vertex of the shape (picked through ``vertex_ids`` when the
    file is the input of a repaired shape)."""
    from hamsa.io import read_vertex_colors

    if not path:
        raise PotentialError(f"potential {spec!r}: name the file with the vertex colours, e.g. texture:scan.ply")
    colours = read_vertex_colors(path)
    if vertex_ids is not None and len(colours) != n and len(colours) > np.max(vertex_ids):
        colours = colours[np.asarray(vertex_ids)]  # the repaired shape's input: its kept vertices' colours
    if len(colours) != n:
        raise PotentialError(f"potential {spec!r}: '{path}' has {len(colours)} vertex colours, the shape {n} vertices")
    return colours


def _spec_scale(text: str | None, spec: str) -> float:
    if text is None:
        return 1.0
    try:
        scale = float(text)
    except ValueError:
        scale = float("nan")
    if not np.isfinite(scale):
        raise PotentialError(f"potential {spec!r}: the scale {text!r} is not a finite number")
    return scale


def _spec_integers(text: str, spec: str) -> list[int]:
    try:
        return [int(part) for part in text.split(",")]
    except ValueError:
        raise PotentialError(f"potential {spec!r}: {text!r} is not a comma-separated list of integers") from None


def _spec_vertices(ids: list[int], n: int, vertex_ids, spec: str) -> np.ndarray:
    """Vertex ids of the spec as ids of the shape (input ids through ``vertex_ids`` after a repair)."""
    if vertex_ids is None:
        bad = [i for i in ids if not 0 <= i < n]
        if bad:
            raise PotentialError(f"potential {spec!r}: vertex {bad[0]} is not in 0..{n - 1}")
        return np.asarray(ids, dtype=np.int64)
    vertex_ids = np.asarray(vertex_ids)
    found = []
    for i in ids:
        hits = np.flatnonzero(vertex_ids == i)
        if not len(hits):
            raise PotentialError(f"potential {spec!r}: input vertex {i} is not in the repaired mesh")
        found.append(int(hits[0]))
    return np.asarray(found, dtype=np.int64)


def _spec_step(shape, arguments: str, spec: str) -> np.ndarray:
    step_form = re.fullmatch(r"\s*([xyz])\s*([<>])\s*(\S+)\s*", arguments)
    if step_form is None:
        raise PotentialError(f"potential {spec!r}: a step is AXIS>VALUE or AXIS<VALUE with AXIS x, y or z")
    axis, sign, text = step_form.groups()
    try:
        threshold = float(text)
    except ValueError:
        raise PotentialError(f"potential {spec!r}: {text!r} is not a number") from None
    coordinate = shape.vertices[:, "xyz".index(axis)]
    region = coordinate > threshold if sign == ">" else coordinate < threshold
    if not region.any() or region.all():
        raise PotentialError(
            f"potential {spec!r}: {'every' if region.all() else 'no'} vertex has {axis} {sign} {threshold:g} "
            f"({axis} is in [{coordinate.min():.4g}, {coordinate.max():.4g}]): the step would be constant"
        )
    return step(shape, region, 1.0)
