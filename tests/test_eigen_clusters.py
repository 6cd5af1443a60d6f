"""Eigenvalue clusters that k cuts: several connected components (a null space of dimension c), multiplets
of the sphere, a potential constant on one piece only, k = n - 1. Checked against a dense generalized
``eigh`` (eigenvalues to 1e-8 relative; subspaces by principal angles, since the vectors inside a multiple
eigenvalue are arbitrary)."""

import numpy as np
import pytest
import scipy.linalg as sla

import hamsa
from hamsa import shapes
from hamsa.operators import hamiltonian


def copies(mesh, count: int, gap: float = 3.0) -> hamsa.TriMesh:
    """``count`` disjoint translated copies of ``mesh``."""
    n = mesh.n_vertices
    vertices = np.vstack([mesh.vertices + [gap * i, 0.0, 0.0] for i in range(count)])
    faces = np.vstack([mesh.faces + n * i for i in range(count)])
    return hamsa.TriMesh(vertices, faces)


def reference(mesh, k, potential=None):
    H, A = hamiltonian(mesh, potential)
    return sla.eigh(H.toarray(), A.toarray(), subset_by_index=[0, k - 1])


def largest_angle(X, Y, mass):
    """The largest principal angle between span(X) and span(Y) in the A-inner product (radians)."""
    root = np.sqrt(mass)[:, None]
    return float(np.max(sla.subspace_angles(root * X, root * Y)))


def assert_matches_reference(mesh, k, basis, potential=None, extra: int = 8):
    """Eigenvalues to 1e-8 relative (absolute below 1e-8 x the spectrum's size); the span of the complete
    clusters among the first k equal to the reference's; the vectors of a cluster that k cuts inside that
    cluster's span; A-orthonormality."""
    values, vectors = reference(mesh, min(k + extra, mesh.n_vertices), potential)
    size = max(np.abs(values).max(), 1.0)
    np.testing.assert_allclose(basis.values, values[:k], rtol=1e-8, atol=1e-8 * size)
    ends = [int(i) + 1 for i in np.flatnonzero(np.diff(values) > 1e-6 * size)] + [len(values)]
    complete = max([end for end in ends if end <= k], default=0)
    cut_end = min(end for end in ends if end >= k)
    assert cut_end < len(values) or cut_end == mesh.n_vertices, "the reference must hold the whole cut cluster"
    mass = basis.mass.diagonal()
    if complete:
        assert largest_angle(basis.vectors[:, :complete], vectors[:, :complete], mass) < 1e-6
    if complete < k:
        cluster = vectors[:, complete:cut_end]
        rest = basis.vectors[:, complete:k]
        outside = rest - cluster @ (cluster.T @ (mass[:, None] * rest))
        assert np.sqrt(np.max(np.sum(mass[:, None] * outside**2, axis=0))) < 1e-6
    np.testing.assert_allclose(basis.vectors.T @ (mass[:, None] * basis.vectors), np.eye(k), atol=1e-8)


@pytest.mark.parametrize("method", ["krylov", "chebyshev"])
@pytest.mark.parametrize("count, k", [(1, 3), (2, 1), (2, 2), (2, 5), (4, 2), (4, 4), (4, 6)])
def test_components_with_k_below_at_and_above_their_count(method, count, k):
    mesh = copies(shapes.icosphere(3), count)
    basis = hamsa.eigenbasis(mesh, k, method=method)
    assert_matches_reference(mesh, k, basis, extra=120)  # the l = 1 cluster: 3 x 38
    assert np.sum(np.abs(basis.values) < 1e-8) == min(k, count)  # one zero mode per component


@pytest.mark.parametrize("k", [30, 38, 45])
def test_thirty_eight_components(k):
    mesh = copies(shapes.icosphere(1), 38)  # every eigenvalue 38 times: more copies than a Krylov block holds
    basis = hamsa.eigenbasis(mesh, k)
    assert_matches_reference(mesh, k, basis, extra=120)  # the l = 1 cluster: 3 x 38


@pytest.mark.parametrize("method", ["krylov", "chebyshev"])
@pytest.mark.parametrize("k", [5, 7, 12])
def test_k_inside_a_sphere_multiplet(method, k, sphere_5k):
    basis = hamsa.eigenbasis(sphere_5k, k, method=method)
    full = hamsa.eigenbasis(sphere_5k, 16, method="krylov")  # l = 0..3 complete
    np.testing.assert_allclose(basis.values, full.values[:k], rtol=1e-8, atol=1e-8)
    mass = basis.mass.diagonal()
    inside = 4 if k < 9 else 9  # the complete multiplets below the cut one
    assert largest_angle(basis.vectors[:, :inside], full.vectors[:, :inside], mass) < 1e-6
    # the vectors of the cut multiplet lie in that multiplet's span
    multiplet = full.vectors[:, inside : 9 if k < 9 else 16]
    residual = basis.vectors[:, inside:] - multiplet @ (multiplet.T @ (mass[:, None] * basis.vectors[:, inside:]))
    assert np.sqrt(np.max(np.sum(mass[:, None] * residual**2, axis=0))) < 1e-6


@pytest.mark.parametrize("method", ["krylov", "chebyshev"])
def test_a_potential_constant_on_one_component_only(method):
    mesh = copies(shapes.icosphere(3), 2)
    n = mesh.n_vertices // 2
    V = np.concatenate([np.full(n, 3.0), 10 * (mesh.vertices[n:, 2] > 0)])
    basis = hamsa.eigenbasis(mesh, 6, V, method=method)
    assert_matches_reference(mesh, 6, basis, V)


def test_k_is_n_minus_one_on_a_small_mesh():
    mesh = shapes.icosphere(1)
    basis = hamsa.eigenbasis(mesh, mesh.n_vertices - 1)
    assert_matches_reference(mesh, mesh.n_vertices - 1, basis)


@pytest.mark.data
@pytest.mark.parametrize("k", [10, 40])
def test_tosca_gorilla_with_its_loose_pieces(k):
    from conftest import data_mesh

    mesh, _ = data_mesh("tosca_hires/meshes/gorilla1.off.gz").without_unreferenced()
    count = mesh.n_components
    assert count > 30
    basis = hamsa.eigenbasis(mesh, k)
    H, A = hamiltonian(mesh)
    scale = 4 * np.pi / mesh.area
    zero = np.abs(basis.values) < 1e-6 * scale
    assert zero.sum() == min(k, count)  # one zero mode per piece
    assert np.all(basis.values[~zero] > 1e-3 * scale)
    residual = H @ basis.vectors - (A @ basis.vectors) * basis.values
    relative = np.linalg.norm(residual, axis=0) / np.linalg.norm(A @ basis.vectors, axis=0)
    assert relative.max() < 1e-6 * scale  # |H x - E A x| against the spectrum's scale
    assert basis.info.seconds < 60


@pytest.mark.parametrize("dense_fits", [True, False])
def test_a_stalled_krylov_solve_falls_back_and_says_so(monkeypatch, dense_fits):
    """When the Krylov solver stalls the dense solve (or, where it would not fit, ARPACK) takes over with
    the same answer, and SolveInfo records why."""
    from hamsa import eigen
    from hamsa.errors import ConvergenceError
    from hamsa.operators import mass_matrix, stiffness_matrix

    def stalls(*args, **kwargs):
        raise ConvergenceError("did not converge in 0 restarts")

    mesh = shapes.icosphere(3)  # 642 vertices
    W, A = stiffness_matrix(mesh), mass_matrix(mesh)
    monkeypatch.setattr(eigen, "_block_krylov", stalls)
    if not dense_fits:
        monkeypatch.setattr(eigen, "_DENSE_LIMIT_N", 100)
    values, vectors, info = eigen.generalized_eigsh(W, A, 12, method="krylov")
    reference = sla.eigh(W.toarray(), A.toarray(), eigvals_only=True, subset_by_index=[0, 11])
    np.testing.assert_allclose(values, reference, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(vectors.T @ (A @ vectors), np.eye(12), atol=1e-8)
    assert info.method == ("dense" if dense_fits else "arpack") and info.fallback.startswith("krylov stalled")


def test_k_close_to_n_is_a_dense_solve_when_it_fits_and_refused_before_any_work_otherwise(monkeypatch):
    from hamsa import resources
    from hamsa.errors import ResourceError

    mesh = shapes.icosphere(2)  # 162 vertices
    basis = hamsa.eigenbasis(mesh, mesh.n_vertices)  # k = n
    W, A = hamsa.stiffness_matrix(mesh).toarray(), hamsa.mass_matrix(mesh).toarray()
    np.testing.assert_allclose(basis.values, sla.eigh(W, A, eigvals_only=True), rtol=1e-8, atol=1e-10)
    assert basis.info.method == "dense"
    monkeypatch.setattr(resources, "available_memory", lambda: 10**5)  # 100 kB: dense 162 x 162 matrices do not fit
    with pytest.raises(ResourceError, match="dense eigensolve of n = 162"):
        hamsa.eigenbasis(mesh, mesh.n_vertices)
