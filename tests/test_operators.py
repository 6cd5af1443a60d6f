import numpy as np
import pytest
import scipy.sparse as sp

import hamsa
from hamsa import HamsaError, PotentialError, shapes
from hamsa.operators import hamiltonian, mass_matrix, potential_mass_matrix, stiffness_matrix, vertex_areas

from conftest import data_mesh

igl = pytest.importorskip("igl", reason="libigl is the test oracle: pip install 'hamsa[test]'")

MESHES = {
    "perturbed sphere": lambda: _perturbed(),
    "rectangle (boundary)": lambda: shapes.rectangle(2, 1, 12, 7),
    "torus": lambda: shapes.torus(n_major=24, n_minor=10),
}


def _perturbed():
    mesh = shapes.sphere(300)
    rng = np.random.default_rng(1)
    return hamsa.TriMesh(mesh.vertices * (1 + 0.2 * rng.random((300, 1))), mesh.faces)


@pytest.mark.parametrize("name", MESHES)
def test_stiffness_is_symmetric_psd_and_annihilates_constants(name):
    mesh = MESHES[name]()
    W = stiffness_matrix(mesh)
    assert abs(W - W.T).max() == 0
    assert np.abs(W @ np.ones(mesh.n_vertices)).max() < 1e-12 * abs(W).max()
    eig = np.linalg.eigvalsh(W.toarray())
    assert eig.min() > -1e-10 * eig.max()


@pytest.mark.parametrize("name", MESHES)
@pytest.mark.parametrize("kind", ["voronoi", "barycentric", "full"])
def test_mass_sums_to_area(name, kind):
    mesh = MESHES[name]()
    A = mass_matrix(mesh, kind)
    assert A.sum() == pytest.approx(mesh.area, rel=1e-13)
    assert abs(A - A.T).max() == 0


def test_obtuse_rule_of_mixed_voronoi_area():
    # one triangle obtuse at vertex 0: it gets area/2, the others area/4
    mesh = hamsa.TriMesh([[0, 0, 0], [2, 0.2, 0], [-2, 0.2, 0]], [[0, 1, 2]])
    np.testing.assert_allclose(vertex_areas(mesh), mesh.area * np.array([0.5, 0.25, 0.25]), rtol=1e-14)
    # an equilateral triangle: a third each
    eq = hamsa.TriMesh([[0, 0, 0], [1, 0, 0], [0.5, np.sqrt(3) / 2, 0]], [[0, 1, 2]])
    np.testing.assert_allclose(vertex_areas(eq), np.full(3, eq.area / 3), rtol=1e-14)


@pytest.mark.parametrize("name", MESHES)
def test_operators_equal_libigl_on_builtin_shapes(name):
    _compare_with_libigl(MESHES[name]())


@pytest.mark.data
@pytest.mark.parametrize(
    "path", ["tosca_hires/meshes/cat0.off.gz", "scape/meshes/mesh000.off.gz", "classic/fandisk.obj"]
)
def test_operators_equal_libigl_on_real_meshes(path):
    _compare_with_libigl(data_mesh(path))


def _compare_with_libigl(mesh):
    v, f = mesh.vertices, mesh.faces
    W = stiffness_matrix(mesh)
    reference = -igl.cotmatrix(v, f)
    assert abs(W - reference).max() <= 1e-10 * abs(reference).max()
    for kind, igl_kind in [
        ("voronoi", igl.MASSMATRIX_TYPE_VORONOI),
        ("barycentric", igl.MASSMATRIX_TYPE_BARYCENTRIC),
        ("full", igl.MASSMATRIX_TYPE_FULL),
    ]:
        ours, theirs = mass_matrix(mesh, kind), igl.massmatrix(v, f, igl_kind)
        assert abs(ours - theirs).max() <= 1e-10 * abs(theirs).max(), kind


def test_hamiltonian_adds_the_potential_on_the_diagonal_only():
    mesh = _perturbed()
    V = np.random.default_rng(0).standard_normal(mesh.n_vertices)
    H, A = hamiltonian(mesh, V)
    W = stiffness_matrix(mesh)
    assert abs(H - W - sp.diags(A.diagonal() * V)).max() <= 1e-14 * abs(W).max()
    assert H.nnz == W.nnz  # same sparsity (NOTES T5)


def test_full_potential_mass_matrix_integrates_exactly():
    mesh = _perturbed()
    ones = np.ones(mesh.n_vertices)
    full = mass_matrix(mesh, "full")
    assert abs(potential_mass_matrix(mesh, 3.0 * ones, "full") - 3.0 * full).max() < 1e-14
    # integral of V * f * g with V, f, g linear per triangle: compare with a 6-point degree-4 quadrature
    rng = np.random.default_rng(2)
    V, f, g = rng.standard_normal((3, mesh.n_vertices))
    M = potential_mass_matrix(mesh, V, "full")
    assert abs(M - M.T).max() < 1e-15
    bary = np.array(
        [
            [0.816847572980459, 0.091576213509771, 0.091576213509771],
            [0.091576213509771, 0.816847572980459, 0.091576213509771],
            [0.091576213509771, 0.091576213509771, 0.816847572980459],
            [0.108103018168070, 0.445948490915965, 0.445948490915965],
            [0.445948490915965, 0.108103018168070, 0.445948490915965],
            [0.445948490915965, 0.445948490915965, 0.108103018168070],
        ]
    )
    weights = np.array([0.109951743655322] * 3 + [0.223381589678011] * 3)
    values = [(x[mesh.faces] @ bary.T) for x in (V, f, g)]  # (m, 6) each
    integral = np.sum(mesh.face_areas[:, None] * weights * values[0] * values[1] * values[2])
    assert f @ M @ g == pytest.approx(integral, rel=1e-12)


@pytest.mark.parametrize(
    "bad, message", [(np.ones(5), "shape"), (np.full(300, np.nan), "non-finite"), ("x", "numeric")]
)
def test_potential_errors(bad, message):
    with pytest.raises(PotentialError, match=message):
        hamiltonian(_perturbed(), bad)


def test_absurd_potential_magnitudes_are_refused_not_silently_rounded():
    mesh = shapes.icosphere(2)
    with pytest.raises(PotentialError, match="round-off"):
        hamiltonian(mesh, np.full(mesh.n_vertices, 1e300))
    hamiltonian(mesh, np.full(mesh.n_vertices, 1e6))  # an 'infinite wall' far above the spectrum is fine


def test_divergence_of_the_gradient_is_minus_the_stiffness():
    """The weak divergence is minus the area-weighted transpose of the P1 gradient: div(grad f) = -W f for
    every f, and the divergence of a constant field integrates to zero on a closed surface."""
    from hamsa.operators import divergence, divergence_matrix, face_gradients

    mesh = shapes.humanoid(spacing=0.05)
    f = np.random.default_rng(3).standard_normal((mesh.n_vertices, 2))
    W = stiffness_matrix(mesh)
    gradients = face_gradients(mesh, f)  # (m, 3, 2)
    for j in range(2):
        np.testing.assert_allclose(divergence(mesh, gradients[:, :, j]), -W @ f[:, j], atol=1e-12 * np.abs(W @ f).max())
    G = face_gradients(mesh, np.eye(mesh.n_vertices)[:, :50])  # columns of the gradient matrix
    D = divergence_matrix(mesh)[:50].toarray().reshape(50, mesh.n_faces, 3)
    np.testing.assert_allclose(D, -np.einsum("m,mdi->imd", mesh.face_areas, G), atol=1e-12)
    assert abs(divergence(mesh, np.tile([0.3, -1.0, 2.0], (mesh.n_faces, 1))).sum()) < 1e-10
    with pytest.raises(HamsaError, match="per-face vector field"):
        divergence(mesh, np.zeros((mesh.n_vertices, 3)))
