import numpy as np
import pytest
import scipy.sparse as sp

import hamsa
from hamsa import HamsaError, shapes
from hamsa.eigen import generalized_eigsh
from hamsa.interval import interval_operators
from hamsa.operators import hamiltonian
from hamsa.optimize import ReducedRepresentationProblem, optimize_potential, representation_loss

from conftest import data_mesh


def _problem(W, A, X, k, m=None):
    n = W.shape[0]
    values, vectors, _ = generalized_eigsh(W, A, m or n, method="dense")
    return ReducedRepresentationProblem(values, vectors, A.diagonal(), X, k)


def _directional_fd(function, V, direction, h):
    """Richardson-extrapolated central difference: O(h^4)."""
    d1 = (function(V + h * direction) - function(V - h * direction)) / (2 * h)
    d2 = (function(V + h / 2 * direction) - function(V - h / 2 * direction)) / h
    return (4 * d2 - d1) / 3


def _cases():
    mesh = shapes.sphere(200)
    X = mesh.vertices * (1 + 0.3 * mesh.vertices[:, [0]] ** 2)
    W, A = hamiltonian(mesh)
    W1, A1, x = interval_operators(120)
    return {
        "mesh, mass-weighted": (W, A, X),
        "mesh, Euclidean": (W, sp.identity(200, format="csr"), X),
        "1-D grid, mass-weighted": (W1, A1, x),
        "1-D grid, Euclidean": (W1, sp.identity(120, format="csr"), x),
    }


@pytest.mark.parametrize("case", list(_cases()))
@pytest.mark.parametrize("square", [False, True])
@pytest.mark.parametrize("smoothed", [False, True])
def test_gradient_equals_finite_differences(case, square, smoothed):
    W, A, X = _cases()[case]
    problem = _problem(W, A, X, k=10)
    rng = np.random.default_rng(1)
    n = W.shape[0]
    scale = np.diag(problem.stiffness)[10]  # the 11th LBO eigenvalue
    problem.width = 0.1 * scale if smoothed else 0.0
    v = rng.random(n) * np.sqrt(scale) if square else (rng.random(n) - 0.3) * scale
    to_V = (lambda v: v**2) if square else (lambda v: v)
    loss, gradient = problem.loss_and_gradient(to_V(v))
    if square:
        gradient = 2 * v * gradient
    for _ in range(3):
        direction = rng.standard_normal(n)
        fd = _directional_fd(lambda y: problem.loss(to_V(y)), v, direction, 1e-4 * np.abs(v).max())
        assert gradient @ direction == pytest.approx(fd, rel=1e-5)


def test_the_soft_top_k_keeps_a_budget_of_k_and_becomes_the_papers_loss_as_the_width_shrinks():
    W, A, X = _cases()["mesh, mass-weighted"]
    problem = _problem(W, A, X, k=10)
    V = np.random.default_rng(4).random(W.shape[0]) * 30
    E, U = problem.eigen(V)
    hard = problem.loss(V)
    gaps = []
    for width in (10.0, 1.0, 0.1, 0.01):
        problem.width = width
        weights, slope = problem._soft_weights(E)
        assert weights.sum() == pytest.approx(10, rel=1e-10)
        assert np.all(slope <= 0)
        gaps.append(abs(problem.loss(V) - hard))
    assert all(later < earlier for earlier, later in zip(gaps, gaps[1:]))
    assert gaps[-1] < 1e-6 * hard


def test_the_papers_closed_form_has_the_opposite_sign():
    W, A, X = _cases()["mesh, Euclidean"]
    n, k = W.shape[0], 10
    V = np.random.default_rng(2).random(n) * 5
    problem = _problem(W, A, X, k)
    _, ours = problem.loss_and_gradient(V)
    E, Psi = np.linalg.eigh((W + sp.diags(V)).toarray())
    B = np.zeros((n, n))
    off = ~np.eye(n, dtype=bool)
    B[off] = 1.0 / (E[None, :] - E[:, None])[off]  # B_ij = 1/(lambda_j - lambda_i)
    Z = np.zeros((n, n))
    Z[:k] = Psi[:, :k].T @ X @ X.T @ Psi  # Z Psi_k^T X X^T Psi_n, zero below row k
    paper = np.diag(-2 * Psi @ (Z * B) @ Psi.T)
    # equal up to our stabilization epsilon of the eigenvalue gaps; the sign is the point
    np.testing.assert_allclose(paper, -ours, rtol=1e-3, atol=1e-6 * np.abs(ours).max())


def test_reduced_gradient_converges_to_the_full_one():
    mesh = shapes.capsule(radius=0.5, length=2.0, n_around=20)
    W, A = hamiltonian(mesh)
    X = mesh.vertices
    n, k = mesh.n_vertices, 10
    V = np.random.default_rng(3).random(n) * 20
    full = _problem(W, A, X, k).loss_and_gradient(V)[1]
    errors = []
    for m in (20, 40, 80, 160, 320):
        reduced = _problem(W, A, X, k, m).loss_and_gradient(V)[1]
        errors.append(np.linalg.norm(reduced - full) / np.linalg.norm(full))
    assert all(later <= earlier * 1.05 for earlier, later in zip(errors, errors[1:]))
    assert errors[-1] < 0.2 * errors[0]


def test_one_dimensional_toy_drops_the_error_tenfold():
    W, A, x = interval_operators(200)
    plain = {"max_iterations": 200, "rounds": 1, "smoothing": ()}  # a simple spectrum: nothing to smooth
    result = optimize_potential(None, x, 15, operators=(W, A), mass_weighted=False, **plain)
    assert result.loss <= 0.1 * result.lbo_loss
    assert result.history[-1]["loss"] < result.history[0]["loss"]
    # the smoothed default keeps a stage only if the paper's loss fell: never worse than the LBO
    default = optimize_potential(None, x, 15, operators=(W, A), mass_weighted=False)
    assert default.loss < default.lbo_loss
    assert {entry["width"] for entry in default.history} >= {0.0}


def test_bad_requests():
    W, A, x = interval_operators(50)
    with pytest.raises(HamsaError, match="rows"):
        optimize_potential(None, x[:-1], 5, operators=(W, A))
    with pytest.raises(HamsaError, match="parametrization"):
        optimize_potential(None, x, 5, operators=(W, A), parametrization="cubic")
    with pytest.raises(HamsaError, match="smaller than m"):
        optimize_potential(None, x, 50, operators=(W, A))
    with pytest.raises(HamsaError, match="not both"):
        optimize_potential(shapes.icosphere(1), x, 5, operators=(W, A))
    with pytest.raises(HamsaError, match="one size"):
        optimize_potential(None, x, 5, operators=(W, A[:-1, :-1]))
    with pytest.raises(HamsaError, match="smoothing widths"):
        optimize_potential(None, x, 5, operators=(W, A), smoothing=(1.0, -2.0))
    with pytest.raises(HamsaError, match="rounds"):
        optimize_potential(None, x, 5, operators=(W, A), rounds=0)


def test_a_pair_is_vertices_and_faces_as_everywhere():
    mesh = shapes.icosphere(2)
    pair = optimize_potential((mesh.vertices, mesh.faces), mesh.vertices, 5, m=40, max_iterations=5)
    same = optimize_potential(mesh, mesh.vertices, 5, m=40, max_iterations=5)
    np.testing.assert_array_equal(pair.potential, same.potential)
    assert pair.basis is not None and pair.loss <= pair.lbo_loss


@pytest.mark.data
def test_hand_reconstruction_error_halves():
    mesh = data_mesh("classic/hand_6k.off").scaled_to_unit_area()
    result = optimize_potential(mesh, mesh.vertices, 50, m=300, max_iterations=60)
    assert result.loss <= 0.5 * result.lbo_loss
    assert result.basis is not None and result.basis.k == 50


def test_centring_removes_the_weighted_mean_and_makes_the_result_translation_invariant():
    from hamsa.operators import mass_matrix

    mesh = shapes.capsule(0.5, 2.0, 16)
    a = mass_matrix(mesh).diagonal()
    shifted = hamsa.TriMesh(mesh.vertices + [3.0, -1.0, 2.0], mesh.faces)
    results = [optimize_potential(m, m.vertices, 8, m=40, max_iterations=15, center=True) for m in (mesh, shifted)]
    np.testing.assert_allclose(results[0].mean, a @ mesh.vertices / a.sum(), rtol=1e-12)
    np.testing.assert_allclose(results[1].mean - results[0].mean, [3.0, -1.0, 2.0], rtol=1e-12)
    scale = np.abs(results[0].potential).max()
    assert np.abs(results[1].potential - results[0].potential).max() < 1e-3 * scale  # (iterative solves: 2e-5)
    assert results[0].loss == pytest.approx(
        representation_loss(results[0].basis.vectors, a, mesh.vertices - results[0].mean), rel=1e-10
    )
    raw = [optimize_potential(m, m.vertices, 8, m=40, max_iterations=15) for m in (mesh, shifted)]
    assert raw[0].mean is None and np.abs(raw[1].potential - raw[0].potential).max() > 0.1 * scale  # it matters


@pytest.mark.parametrize("center, plain", [(False, False), (True, False), (False, True)])
def test_cli_optimize_writes_the_python_apis_potential(tmp_path, capsys, center, plain):
    from hamsa.cli import main

    mesh = shapes.capsule(0.5, 2.0, 16)
    hamsa.save_mesh(mesh, tmp_path / "capsule.off")
    out = tmp_path / "V.npy"
    command = ["optimize", str(tmp_path / "capsule.off"), "-k", "8", "-m", "40", "--iterations", "15", "-o", str(out)]
    assert main(command + (["--center"] if center else []) + (["--plain"] if plain else [])) == 0
    assert ("of the centred data" in capsys.readouterr().out) == center
    loaded = hamsa.load_mesh(tmp_path / "capsule.off")
    optimizer = {"smoothing": (), "rounds": 1} if plain else {}
    expected = optimize_potential(loaded, loaded.vertices, 8, m=40, max_iterations=15, center=center, **optimizer)
    np.testing.assert_allclose(np.load(out), expected.potential, rtol=1e-10, atol=1e-12)
