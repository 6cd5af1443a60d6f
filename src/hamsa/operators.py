"""Linear finite-element operators on a triangle mesh: stiffness W, mass A and the Hamiltonian H.

Conventions (stated once, used everywhere in hamsa):

* ``W`` is the cotangent stiffness matrix, **positive semidefinite**: ``W_ij = -(cot a_ij + cot b_ij)/2``
  on edges, ``W_ii = -sum_j W_ij``, so ``W @ 1 = 0`` and ``f @ W @ f = integral |grad f|^2 >= 0``.
  The paper's eq. (cotan) prints the opposite sign (a negative semidefinite W), which contradicts
  H = W + A V, E >= 0 and Theorem 1; we use the PSD sign (the docs' conventions page).
* ``A`` is the mass matrix: by default the lumped mixed-Voronoi areas of Meyer et al. 2003
  (eq. fem6 of the paper), whose sum is exactly the surface area.
* Boundary edges have a single cotangent term: natural (Neumann) boundary conditions.
* The Hamiltonian ``H = W + A diag(V)`` (eq. fem6): a generalized eigenproblem ``H psi = E A psi``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from hamsa.errors import HamsaError, MeshError, MissingDependencyError, PotentialError
from hamsa.mesh import TriMesh, as_trimesh
from hamsa.pointcloud import PointCloud, as_shape

MASS_KINDS = ("voronoi", "barycentric", "full")


def _corner_geometry(mesh: TriMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-face cotangents of the three corner angles, squared opposite edge lengths, and areas.

    Corner c of face (i0, i1, i2) is vertex i_c; its opposite edge is e_c = v[i_{c+2}] - v[i_{c+1}].
    cot(angle at c) = -(e_{c+1} . e_{c+2}) / (2 area).
    """
    v = mesh.vertices
    f = mesh.faces
    p = [v[f[:, c]] for c in range(3)]
    e = [p[(c + 2) % 3] - p[(c + 1) % 3] for c in range(3)]
    double_area = np.linalg.norm(np.cross(e[0], e[1]), axis=1)
    cot = np.stack([-np.einsum("ij,ij->i", e[(c + 1) % 3], e[(c + 2) % 3]) for c in range(3)], axis=1)
    cot /= double_area[:, None]
    sq_len = np.stack([np.einsum("ij,ij->i", e[c], e[c]) for c in range(3)], axis=1)
    return cot, sq_len, 0.5 * double_area


def stiffness_matrix(mesh) -> sp.csr_matrix:
    """Cotangent stiffness matrix W, symmetric positive semidefinite (Pinkall-Polthier 1993).

    Parameters
    ----------
    mesh : TriMesh or (vertices, faces)

    Returns
    -------
    scipy.sparse.csr_matrix, shape (n, n), float64
        ``W_ij = -(cot alpha_ij + cot beta_ij)/2`` for each edge (one term on boundary edges),
        ``W_ii = -sum_{j != i} W_ij``; ``W @ ones = 0``. Units: dimensionless (cotangents), so
        ``f @ W @ f`` is the Dirichlet energy integral of |grad f|^2 over the surface.
        This is the negation of the paper's eq. (cotan), whose sign is a misprint,
        and equals ``-igl.cotmatrix(V, F)``.
    """
    mesh = as_trimesh(mesh)
    _require_edge_manifold(mesh, "cotan")
    cot, _, _ = _corner_geometry(mesh)
    f = mesh.faces
    n = mesh.n_vertices
    # corner c contributes 0.5 cot_c to its opposite edge (i_{c+1}, i_{c+2})
    i = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    j = np.concatenate([f[:, 2], f[:, 0], f[:, 1]])
    w = 0.5 * np.concatenate([cot[:, 0], cot[:, 1], cot[:, 2]])
    off = sp.coo_matrix((-w, (i, j)), shape=(n, n))
    off = (off + off.T).tocsr()
    diagonal = -np.asarray(off.sum(axis=1)).ravel()
    stiffness = (off + sp.diags(diagonal)).tocsr()
    stiffness.sum_duplicates()
    stiffness.sort_indices()
    return stiffness


def vertex_areas(mesh, kind: str = "voronoi") -> np.ndarray:
    """Lumped area of each vertex, shape (n,); ``sum(vertex_areas(mesh)) == mesh.area``.

    ``kind="voronoi"``: mixed Voronoi cells (Meyer, Desbrun, Schroeder, Barr 2003). In a
    non-obtuse triangle PQR, P gets ``(|PR|^2 cot Q + |PQ|^2 cot R) / 8``; in an obtuse triangle the
    obtuse vertex gets area/2 and the two others area/4 each.
    ``kind="barycentric"``: each vertex gets a third of the area of each incident triangle.
    """
    mesh = as_trimesh(mesh)
    mesh.require_operator_ready()
    cot, sq_len, area = _corner_geometry(mesh)
    if kind == "barycentric":
        corner_area = np.repeat(area[:, None] / 3.0, 3, axis=1)
    elif kind == "voronoi":
        voronoi = np.stack(
            [
                (sq_len[:, (c + 1) % 3] * cot[:, (c + 1) % 3] + sq_len[:, (c + 2) % 3] * cot[:, (c + 2) % 3]) / 8.0
                for c in range(3)
            ],
            axis=1,
        )
        obtuse_corner = cot < 0
        obtuse_face = obtuse_corner.any(axis=1)
        corner_area = np.where(
            obtuse_face[:, None],
            np.where(obtuse_corner, area[:, None] / 2.0, area[:, None] / 4.0),
            voronoi,
        )
    else:
        raise HamsaError(f"lumped mass kind must be 'voronoi' or 'barycentric', got {kind!r}")
    return np.bincount(mesh.faces.ravel(), weights=corner_area.ravel(), minlength=mesh.n_vertices)


def mass_matrix(mesh, kind: str = "voronoi") -> sp.csr_matrix:
    """Mass matrix A, shape (n, n), symmetric positive definite, units of area.

    Parameters
    ----------
    mesh : TriMesh or (vertices, faces)
    kind : {"voronoi", "barycentric", "full"}
        ``"voronoi"`` (default, the paper's choice): diagonal mixed-Voronoi areas, see
        :func:`vertex_areas`. ``"barycentric"``: diagonal, a third of each incident triangle.
        ``"full"``: the consistent P1 mass ``M_ij = integral phi_i phi_j`` (area/6 on the diagonal and
        area/12 off it, per triangle); not diagonal.

    Returns
    -------
    scipy.sparse.csr_matrix
        For every kind, ``ones @ A @ ones`` equals the surface area.
    """
    if kind not in MASS_KINDS:
        raise HamsaError(f"mass kind must be one of {MASS_KINDS}, got {kind!r}")
    mesh = as_trimesh(mesh)
    if kind == "full":
        return potential_mass_matrix(mesh, np.ones(mesh.n_vertices), kind="full")
    return sp.diags(vertex_areas(mesh, kind)).tocsr()


def potential_mass_matrix(mesh, potential: np.ndarray, kind: str = "voronoi") -> sp.csr_matrix:
    """The discrete potential term ``integral V phi_i phi_j``, shape (n, n).

    For the lumped kinds it is ``A diag(V)`` (the paper's eq. fem6), diagonal. For ``kind="full"``
    it is the exact integral with V linearly interpolated: per triangle of area |T|,
    ``|T| (V_i/10 + (V_j + V_k)/30)`` on the diagonal and ``|T| (V_i/30 + V_j/30 + V_k/60)`` off it;
    it is symmetric and has the sparsity of W. With V = 1 both reduce to the mass matrix.
    """
    mesh = as_trimesh(mesh)
    potential = check_potential(potential, mesh.n_vertices)
    if kind != "full":
        return sp.diags(vertex_areas(mesh, kind) * potential).tocsr()
    mesh.require_operator_ready()
    f = mesh.faces
    area = mesh.face_areas
    vf = potential[f]
    total = vf.sum(axis=1)
    n = mesh.n_vertices
    rows, cols = [f[:, c] for c in range(3)], [f[:, c] for c in range(3)]
    vals = [area * (vf[:, c] / 10.0 + (total - vf[:, c]) / 30.0) for c in range(3)]
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        entry = area * ((vf[:, a] + vf[:, b]) / 30.0 + vf[:, c] / 60.0)
        rows += [f[:, a], f[:, b]]
        cols += [f[:, b], f[:, a]]
        vals += [entry, entry]
    matrix = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    matrix = matrix.tocsr()
    matrix.sum_duplicates()
    matrix.sort_indices()
    return matrix


MAX_POTENTIAL_RATIO = 1e12
"""Largest |V| accepted, relative to the mesh's largest Laplacian eigenvalue (float64 keeps ~16 digits)."""


def face_gradients(mesh, f: np.ndarray) -> np.ndarray:
    """Per-face gradient of a P1 function: ``sum_v f_v (N x e_v) / (2 area)``, shape (m, 3) (or (m, 3, d)
    for an (n, d) f), in units of f per length.

    e_v is the edge opposite vertex v, oriented along the face, N the unit face normal.
    """
    mesh = as_trimesh(mesh)
    v, faces = mesh.vertices, mesh.faces
    p = [v[faces[:, c]] for c in range(3)]
    normal, double_area = mesh.face_normals, 2 * mesh.face_areas
    f = np.asarray(f, dtype=np.float64)
    grad = 0.0
    for c in range(3):
        edge = p[(c + 2) % 3] - p[(c + 1) % 3]
        rotated = np.cross(normal, edge) / double_area[:, None]
        values = f[faces[:, c]]
        grad = grad + (rotated * values[:, None] if values.ndim == 1 else rotated[:, :, None] * values[:, None, :])
    return grad


def divergence_matrix(mesh) -> sp.csr_matrix:
    """The integrated divergence (n, 3m) of a per-face vector field X (m, 3), flattened face by face
    (``X.reshape(-1)``): at a corner i of a face, ``1/2 (cot_k (e1 . X) + cot_j (e2 . X))`` with e1, e2
    the edges from i and k, j the corners opposite them. It is minus the transpose of the gradient
    weighted by the face areas, so ``divergence(mesh, face_gradients(mesh, f)) = -W f`` (the cotan
    Laplacian of f, integrated over each vertex's cell)."""
    mesh = as_trimesh(mesh)
    faces = mesh.faces
    p = [mesh.vertices[faces[:, c]] for c in range(3)]
    n, m = mesh.n_vertices, mesh.n_faces
    rows, columns, weights = [], [], []
    for c in range(3):
        i, j, k = c, (c + 1) % 3, (c + 2) % 3
        e1, e2 = p[j] - p[i], p[k] - p[i]
        cot_k = _cot(p[i] - p[k], p[j] - p[k])  # the angle opposite e1
        cot_j = _cot(p[i] - p[j], p[k] - p[j])  # the angle opposite e2
        weight = 0.5 * (cot_k[:, None] * e1 + cot_j[:, None] * e2)  # (m, 3)
        rows.append(np.repeat(faces[:, i], 3))
        columns.append(3 * np.repeat(np.arange(m), 3) + np.tile(np.arange(3), m))
        weights.append(weight.ravel())
    return sp.csr_matrix((np.concatenate(weights), (np.concatenate(rows), np.concatenate(columns))), shape=(n, 3 * m))


def divergence(mesh, field: np.ndarray) -> np.ndarray:
    """Integrated divergence (n,) of a per-face vector field (m, 3) (:func:`divergence_matrix`)."""
    mesh = as_trimesh(mesh)
    field = np.asarray(field, dtype=np.float64)
    if field.shape != (mesh.n_faces, 3):
        raise HamsaError(f"a per-face vector field must be ({mesh.n_faces}, 3), got {field.shape}")
    return divergence_matrix(mesh) @ field.reshape(-1)


def _cot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b) / np.linalg.norm(np.cross(a, b), axis=1)


def check_potential(potential, n: int) -> np.ndarray:
    """Return ``potential`` as a finite float64 array of length n, or raise PotentialError."""
    try:
        v = np.asarray(potential)
        complex_values = np.iscomplexobj(v)
        v = None if complex_values else v.astype(np.float64, copy=False)
    except (TypeError, ValueError) as exc:
        raise PotentialError(f"potential is not numeric: {exc}") from None
    if complex_values:
        raise PotentialError("potential must be real, got complex values")
    if v.ndim == 2 and 1 in v.shape:
        v = v.ravel()
    if v.shape != (n,):
        raise PotentialError(f"potential has shape {v.shape}, the mesh has {n} vertices: expected ({n},)")
    bad = np.flatnonzero(~np.isfinite(v))
    if len(bad):
        raise PotentialError(f"potential has {len(bad)} non-finite values (NaN or Inf), first at vertex {bad[0]}")
    return v


LAPLACIANS = ("cotan", "intrinsic_delaunay", "tufted", "point_cloud")


def intrinsic_delaunay_operators(mesh, mollify: float = 1e-5) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Stiffness and lumped mass of the tufted intrinsic Delaunay triangulation (Sharp & Crane 2020), ``(W, A)``.

    The same piecewise-flat surface, retriangulated by intrinsic edge flips until every edge is
    Delaunay: all cotangent weights become nonnegative (W is an M-matrix, so diffusion obeys the maximum
    principle) and needles or very obtuse triangles no longer spoil accuracy. The flips run on the
    mesh's tufted cover (each face doubled, faces around a non-manifold edge glued in a cycle), so the
    operator is defined, symmetric and PSD for any triangle set: non-manifold edges and vertices and
    inconsistent orientation included, vertex ids unchanged. On an edge-manifold mesh it is the intrinsic
    Delaunay Laplacian, and on a mesh that is already Delaunay W equals :func:`stiffness_matrix`. The mass
    is the intrinsic triangulation's lumped (barycentric) mass; ``mollify`` (a fraction of the mean edge
    length) lengthens near-degenerate edges first (0: none). Needs the ``[robust]`` extra (robust_laplacian).
    """
    try:
        import robust_laplacian
    except ImportError:
        raise MissingDependencyError(
            "the intrinsic Delaunay / tufted Laplacian needs robust_laplacian: pip install 'hamsa[robust]'"
        ) from None
    mesh = as_trimesh(mesh)
    mesh.require_operator_ready()
    W, A = robust_laplacian.mesh_laplacian(mesh.vertices, mesh.faces, mollify_factor=mollify)
    return sp.csr_matrix(W), sp.csr_matrix(A)


def default_laplacian(shape) -> str:
    """ "point_cloud" for a :class:`~hamsa.pointcloud.PointCloud`, "cotan" (the paper's) for a mesh."""
    return "point_cloud" if isinstance(shape, PointCloud) else "cotan"


def laplacian_operators(
    shape, mass: str = "voronoi", laplacian: str | None = None
) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """The stiffness W and mass A of a mesh or point cloud for one choice of discretization, ``(W, A)``.

    Parameters
    ----------
    shape : TriMesh, (vertices, faces) or PointCloud
    mass : {"voronoi", "barycentric", "full"}
        For "cotan" only; the other Laplacians come with their own lumped mass (pass a lumped kind).
    laplacian : {"cotan", "intrinsic_delaunay", "tufted", "point_cloud"}, optional
        "cotan": :func:`stiffness_matrix` and :func:`mass_matrix` of the mesh as given (the paper's);
        "intrinsic_delaunay": :func:`intrinsic_delaunay_operators` of an edge-manifold mesh; "tufted": the
        same operator for any triangle set, non-manifold edges included; "point_cloud": the operators of
        a :class:`~hamsa.pointcloud.PointCloud` (Sharp & Crane 2020, sec. 5). None: the shape's default
        (:func:`default_laplacian`).

    Raises
    ------
    HamsaError
        On an unknown or mismatched choice (a mesh Laplacian for a cloud or the reverse, cotan or
        intrinsic_delaunay on a mesh with non-manifold edges, a full mass with a non-cotan Laplacian).
    """
    shape = as_shape(shape)
    if mass not in MASS_KINDS:
        raise HamsaError(f"mass kind must be one of {MASS_KINDS}, got {mass!r}")
    laplacian = default_laplacian(shape) if laplacian is None else laplacian
    if laplacian not in LAPLACIANS:
        raise HamsaError(f"laplacian must be one of {LAPLACIANS}, got {laplacian!r}")
    if laplacian != "cotan" and mass == "full":
        raise HamsaError(f"the {laplacian} Laplacian comes with a lumped mass: use mass='voronoi'")
    if isinstance(shape, PointCloud):
        if laplacian != "point_cloud":
            raise HamsaError(f"a point cloud has no faces for the {laplacian} Laplacian: use laplacian='point_cloud'")
        return shape.operators
    if laplacian == "point_cloud":
        raise HamsaError("laplacian='point_cloud' is for a PointCloud: use hamsa.PointCloud(mesh.vertices)")
    shape.require_operator_ready()
    if laplacian == "tufted":
        return intrinsic_delaunay_operators(shape)
    if laplacian == "intrinsic_delaunay":
        _require_edge_manifold(shape, laplacian)
        return intrinsic_delaunay_operators(shape)
    return stiffness_matrix(shape), mass_matrix(shape, mass)


BOUNDARY_CONDITIONS = ("neumann", "dirichlet")


def dirichlet_vertices(shape, boundary="neumann") -> np.ndarray:
    """The vertices held at psi = 0 by a boundary condition, sorted unique int64 ids (empty for Neumann).

    Parameters
    ----------
    shape : TriMesh, (vertices, faces) or PointCloud
    boundary : "neumann", "dirichlet" or array_like of vertex ids
        "neumann": none (the natural condition of W, no constraint). "dirichlet": every vertex on a
        boundary edge of the mesh (none on a closed mesh, where both conditions coincide). An array: those
        vertices (or points), in any order, repeats allowed.

    Dirichlet conditions are imposed by restriction: the eigenproblem of ``H`` and ``A`` on the other
    vertices (rows and columns of the fixed ones removed) is the P1 finite-element problem on the
    functions that vanish at the fixed vertices, and its eigenvectors extend by zero.

    Raises
    ------
    HamsaError
        On an unknown string, "dirichlet" for a point cloud (it has no boundary edges: pass the ids of its
        boundary points), or ids that are not integers in [0, n).
    """
    shape = as_shape(shape)
    n = shape.n_vertices
    if isinstance(boundary, str):
        if boundary not in BOUNDARY_CONDITIONS:
            raise HamsaError(f"boundary must be {BOUNDARY_CONDITIONS} or an array of vertex ids, got {boundary!r}")
        if boundary == "neumann":
            return np.zeros(0, dtype=np.int64)
        if isinstance(shape, PointCloud):
            raise HamsaError(
                "a point cloud has no boundary edges for boundary='dirichlet': pass boundary= the ids of the "
                "points to hold at zero"
            )
        return np.unique(shape.boundary_edges).astype(np.int64)
    ids = np.asarray(boundary)
    if ids.ndim != 1 or (ids.size and not np.issubdtype(ids.dtype, np.integer)):
        raise HamsaError(f"Dirichlet vertices must be a 1-D array of integer ids, got shape {ids.shape} {ids.dtype}")
    if ids.size and (ids.min() < 0 or ids.max() >= n):
        raise HamsaError(f"Dirichlet vertex ids must be in [0, {n}), got {int(ids.min())} .. {int(ids.max())}")
    return np.unique(ids).astype(np.int64)


def _require_edge_manifold(mesh: TriMesh, laplacian: str) -> None:
    if not mesh.is_edge_manifold:
        raise MeshError(
            f"the mesh has {len(mesh.non_manifold_edges)} edges shared by more than two faces (first: "
            f"{mesh.non_manifold_edges[0].tolist()}): the {laplacian} Laplacian is undefined there; use "
            "laplacian='tufted'"
        )


def hamiltonian(
    shape, potential=None, mass: str = "voronoi", laplacian: str | None = None
) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """The discrete Hamiltonian ``H = W + A diag(V)`` and the mass ``A`` (paper eq. fem6).

    Parameters
    ----------
    shape : TriMesh, (vertices, faces) or PointCloud
    potential : array_like, shape (n,), optional
        V at each vertex (point), any sign, in units of 1/length^2 (the units of the eigenvalues).
        None means V = 0 (the Laplace-Beltrami operator).
    mass : {"voronoi", "barycentric", "full"}
        Mass kind, see :func:`mass_matrix`; with "full" the potential term is the consistent
        ``integral V phi_i phi_j`` (see :func:`potential_mass_matrix`).
    laplacian : {"cotan", "intrinsic_delaunay", "tufted", "point_cloud"}, optional
        The discretization of W and A, see :func:`laplacian_operators` (None: "cotan" for a mesh,
        "point_cloud" for a cloud).

    Returns
    -------
    H : scipy.sparse.csr_matrix, shape (n, n)
        Symmetric, with the sparsity pattern of W (the potential only changes the diagonal for the
        lumped kinds). Generalized eigenproblem: ``H psi = E A psi``.
    A : scipy.sparse.csr_matrix, shape (n, n)
    """
    shape = as_shape(shape)
    stiffness, mass_mat = laplacian_operators(shape, mass, laplacian)
    if potential is None:
        return stiffness, mass_mat
    potential = check_potential(potential, shape.n_vertices)
    spectrum_scale = float(np.max(stiffness.diagonal() / mass_mat.diagonal()))  # about the largest eigenvalue
    if np.abs(potential).max() > MAX_POTENTIAL_RATIO * spectrum_scale:
        raise PotentialError(
            f"potential reaches {np.abs(potential).max():.3g}, more than {MAX_POTENTIAL_RATIO:.0e} times the "
            f"mesh's largest Laplacian eigenvalue (about {spectrum_scale:.3g}): in float64 the Laplacian would "
            "vanish in round-off; rescale V (an 'infinite wall' works as well at 1e6 times the eigenvalues of interest)"
        )
    if mass == "full":
        term = potential_mass_matrix(shape, potential, "full")
    else:
        term = sp.diags(mass_mat.diagonal() * potential)
    return (stiffness + term).tocsr(), mass_mat
