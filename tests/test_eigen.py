import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

import hamsa
from hamsa import HamsaError, SolverError, shapes
from hamsa.eigen import Eigenbasis, generalized_eigsh
from hamsa.operators import hamiltonian
from hamsa.theory import eigenvalue_bounds


def relative_residuals(basis):
    H, A = hamiltonian(_mesh_of(basis), basis.potential, basis.mass_kind)
    HX = H @ basis.vectors
    R = HX - (A @ basis.vectors) * basis.values
    return np.linalg.norm(R, axis=0) / np.linalg.norm(HX, axis=0)


_MESHES = {}


def _mesh_of(basis):
    return _MESHES[id(basis)]


def solve(mesh, k, potential=None, **kwargs):
    basis = hamsa.eigenbasis(mesh, k, potential, **kwargs)
    _MESHES[id(basis)] = mesh
    return basis


def test_unit_sphere_spectrum_is_l_times_l_plus_one(sphere_5k):
    basis = solve(sphere_5k, 25, method="krylov")
    degree = np.arange(5)
    expected = np.repeat(degree * (degree + 1), 2 * degree + 1).astype(float)
    assert abs(basis.values[0]) < 1e-8
    np.testing.assert_allclose(basis.values[1:], expected[1:], rtol=0.01)


def test_neumann_rectangle_spectrum():
    a, b = 2.0, 1.0
    mesh = shapes.rectangle(a, b, 80, 40)
    basis = solve(mesh, 10, method="krylov")
    i, j = np.meshgrid(np.arange(6), np.arange(6))
    expected = np.sort((np.pi**2 * (i**2 / a**2 + j**2 / b**2)).ravel())[:10]
    assert abs(basis.values[0]) < 1e-8
    np.testing.assert_allclose(basis.values[1:], expected[1:], rtol=0.01)


def test_constant_potential_shifts_every_eigenvalue(sphere_5k):
    lbo = solve(sphere_5k, 20)
    shifted = solve(sphere_5k, 20, np.full(sphere_5k.n_vertices, 7.5))
    np.testing.assert_allclose(shifted.values, lbo.values + 7.5, rtol=1e-8)


@pytest.mark.parametrize("signed", [False, True])
def test_theorem_1_bounds_for_random_potentials(small_mesh, signed):
    rng = np.random.default_rng(11)
    lbo = solve(small_mesh, 30)
    for _ in range(3):
        V = rng.random(small_mesh.n_vertices) * 20 - (10 if signed else 0)
        basis = solve(small_mesh, 30, V)
        lower, upper = eigenvalue_bounds(lbo.values, V)
        tol = 1e-8 * np.abs(basis.values).max()
        assert np.all(lower - tol <= basis.values) and np.all(basis.values <= upper + tol)


def test_theorem_2_residual_bound(small_mesh):
    """T3: ||f - Psi_n Psi_n^T A f||_A^2 <= (f^T W f + f^T A V f) / E_{n+1} for every f."""
    rng = np.random.default_rng(5)
    V = rng.random(small_mesh.n_vertices) * 5
    H, A = hamiltonian(small_mesh, V)
    basis = solve(small_mesh, 21, V)
    for n in (5, 10, 20):
        part = basis.truncate(n)
        for _ in range(5):
            f = rng.standard_normal(small_mesh.n_vertices)
            error = f - part.reconstruct(part.project(f))
            assert error @ A @ error <= (f @ H @ f) / basis.values[n] * (1 + 1e-10)


@pytest.mark.parametrize("mass", ["voronoi", "barycentric", "full"])
def test_orthonormal_and_small_residuals(sphere_5k, mass):
    V = np.random.default_rng(3).random(sphere_5k.n_vertices) * 10
    basis = solve(sphere_5k, 30, V, mass=mass)
    gram = basis.vectors.T @ basis.mass @ basis.vectors
    assert np.abs(gram - np.eye(30)).max() < 1e-8
    assert relative_residuals(basis).max() < 1e-8
    assert np.all(np.diff(basis.values) >= 0)


@pytest.mark.parametrize("method", ["krylov", "chebyshev"])
@pytest.mark.parametrize("potential", ["zero", "positive", "signed"])
def test_sparse_solvers_match_dense_generalized_eigh(small_mesh, potential, method):
    rng = np.random.default_rng(4)
    V = {"zero": None, "positive": rng.random(400) * 30, "signed": rng.standard_normal(400) * 30}[potential]
    H, A = hamiltonian(small_mesh, V)
    reference = sla.eigh(H.toarray(), A.toarray(), eigvals_only=True)[:40]
    basis = solve(small_mesh, 40, V, method=method)
    scale = np.abs(reference).max()
    np.testing.assert_allclose(basis.values, reference, rtol=1e-9, atol=1e-9 * scale)
    dense = solve(small_mesh, 40, V, method="dense")
    np.testing.assert_allclose(dense.values, reference, rtol=1e-9, atol=1e-9 * scale)


@pytest.mark.parametrize("method", ["krylov", "chebyshev"])
def test_sparse_solvers_match_dense_with_several_components_boundary_and_multiplicities(method):
    # (scipy's eigsh with sigma=-0.01 misses one of the nine-fold sphere eigenvalues near 19.5 here)
    sphere = shapes.icosphere(3)
    plate = shapes.rectangle(1.5, 1.0, 30, 20)
    v = np.vstack([sphere.vertices, plate.vertices + [3.0, 0, 0]])
    f = np.vstack([sphere.faces, plate.faces + sphere.n_vertices])
    mesh = hamsa.TriMesh(v, f)
    assert mesh.n_components == 2
    basis = solve(mesh, 30, method=method)
    H, A = hamiltonian(mesh)
    reference = sla.eigh(H.toarray(), A.toarray(), eigvals_only=True)[:30]
    assert np.sum(np.abs(basis.values) < 1e-8) == 2  # one zero mode per component
    np.testing.assert_allclose(basis.values, reference, rtol=1e-8, atol=1e-9)
    assert relative_residuals(basis)[2:].max() < 1e-8


def test_signs_are_deterministic_and_basis_reconstructs(small_mesh):
    a = solve(small_mesh, 15, method="krylov")
    b = solve(small_mesh, 15, method="dense")
    # same sign convention from two different solvers (simple eigenvalues only)
    simple = np.flatnonzero(np.minimum(np.diff(a.values, prepend=-1), np.diff(a.values, append=1e9)) > 1e-6)
    np.testing.assert_allclose(a.vectors[:, simple], b.vectors[:, simple], atol=1e-6)
    f = a.vectors @ np.arange(15.0)
    np.testing.assert_allclose(a.project(f), np.arange(15.0), atol=1e-9)
    np.testing.assert_allclose(a.reconstruct(a.project(f)), f, atol=1e-9)


def test_warm_start_equals_cold_start(sphere_5k):
    rng = np.random.default_rng(9)
    V = rng.random(sphere_5k.n_vertices) * 5
    cold = solve(sphere_5k, 20, V)
    V2 = V * (1 + 0.05 * rng.standard_normal(V.size))
    warm = solve(sphere_5k, 20, V2, initial=cold.vectors)
    fresh = solve(sphere_5k, 20, V2)
    np.testing.assert_allclose(warm.values, fresh.values, rtol=1e-9)
    overlap = np.abs(warm.vectors.T @ warm.mass @ fresh.vectors)
    assert np.all(np.abs(np.linalg.svd(overlap[:15, :15], compute_uv=False)) > 1 - 1e-8)


@pytest.mark.parametrize("method", ["krylov", "chebyshev"])
def test_solver_object_warm_starts_match_cold_solves_and_keep_signs(sphere_5k, method):
    """HamiltonianEigensolver over a sequence of potentials: each warm-started result equals a cold
    solve (values 1e-9, eigenvectors up to sign), signs follow the previous call; Krylov reuses the
    factorization's symbolic analysis, Chebyshev restarts from its whole previous block (fewer products)."""
    from hamsa.eigen import HamiltonianEigensolver

    rng = np.random.default_rng(3)
    mesh = hamsa.TriMesh(sphere_5k.vertices * (1 + 0.1 * sphere_5k.vertices[:, :1] ** 2), sphere_5k.faces)
    solver = HamiltonianEigensolver.for_mesh(mesh, 12, method=method)
    V = 4 * rng.random(mesh.n_vertices)
    first = solver.solve(V)
    symbolic = solver.factor._symbolic if method == "krylov" else None
    V2 = V * (1 + 0.05 * rng.standard_normal(V.size))
    second = solver.solve(V2)
    fresh = solve(mesh, 12, V2, method=method)
    if method == "chebyshev":
        assert second.info.solves < 0.75 * fresh.info.solves, (second.info, fresh.info)
    np.testing.assert_allclose(second.values, fresh.values, rtol=1e-9)
    np.testing.assert_allclose(np.abs(second.vectors.T @ second.mass @ fresh.vectors), np.eye(12), atol=1e-6)
    assert solver.continues.tolist() == list(range(12))
    assert np.all(np.diag(second.vectors.T @ second.mass @ first.vectors) > 0.9)  # signs kept
    if symbolic is not None:
        assert solver.factor._symbolic is symbolic


def test_solver_object_reports_a_swap_of_crossing_eigenpairs():
    """Two components, a constant potential c on the first: its constant mode (E = c) climbs past the
    second component's first three modes; ``continues`` says which previous pair each new one is."""
    from hamsa.eigen import HamiltonianEigensolver

    sphere = shapes.icosphere(2)
    ellipsoid = sphere.vertices * np.array([1.0, 1.1, 1.2])
    n = sphere.n_vertices
    mesh = hamsa.TriMesh(
        np.vstack([sphere.vertices + [5.0, 0, 0], ellipsoid]), np.vstack([sphere.faces, sphere.faces + n])
    )
    on_first = np.r_[np.ones(n), np.zeros(n)]
    solver = HamiltonianEigensolver.for_mesh(mesh, 5, method="dense")
    low = solver.solve(1.0 * on_first)
    assert np.isclose(low.values[1], 1.0) and low.values[2] > 1.0
    high = solver.solve(3.0 * on_first)
    assert np.isclose(high.values[4], 3.0) and high.values[3] < 3.0
    assert solver.continues.tolist() == [0, 2, 3, 4, 1]
    assert np.all(solver.overlap[np.arange(5), solver.continues] > 0.99)  # and with the same signs


def test_save_and_load_round_trip(tmp_path, small_mesh):
    V = np.linspace(0, 1, small_mesh.n_vertices)
    basis = solve(small_mesh, 8, V, mass="full")
    basis.save(tmp_path / "b.npz")
    back = Eigenbasis.load(tmp_path / "b.npz")
    np.testing.assert_array_equal(back.values, basis.values)
    np.testing.assert_array_equal(back.vectors, basis.vectors)
    np.testing.assert_array_equal(back.potential, V)
    assert abs(back.mass - basis.mass).max() == 0 and back.mass_kind == "full"
    (tmp_path / "bad.npz").write_bytes(b"garbage")
    with pytest.raises(HamsaError, match="not an .npz archive"):
        Eigenbasis.load(tmp_path / "bad.npz")
    # damage that keeps a valid zip: one eigenvector entry changed by 1e-9 -> the SHA-256 checksum catches it
    with np.load(tmp_path / "b.npz") as data:
        arrays = dict(data)
    arrays["vectors"][3, 2] += 1e-9
    np.savez(tmp_path / "tampered.npz", **arrays)
    with pytest.raises(HamsaError, match="corrupt"):
        Eigenbasis.load(tmp_path / "tampered.npz")
    raw = bytearray((tmp_path / "b.npz").read_bytes())  # a flipped byte inside the zip: bad CRC
    raw[len(raw) // 2] ^= 0xFF
    (tmp_path / "flipped.npz").write_bytes(bytes(raw))
    with pytest.raises(HamsaError):
        Eigenbasis.load(tmp_path / "flipped.npz")


@pytest.mark.parametrize("k", [0, -3, 401, 2.5, True])
def test_impossible_k_is_a_clear_error(small_mesh, k):
    with pytest.raises(SolverError, match="k"):
        hamsa.eigenbasis(small_mesh, k)


def test_unreferenced_vertices_are_refused_with_the_fix():
    mesh = shapes.icosphere(2)
    dirty = hamsa.TriMesh(np.vstack([mesh.vertices, [[5.0, 5, 5]]]), mesh.faces)
    with pytest.raises(hamsa.MeshError, match="without_unreferenced"):
        hamsa.eigenbasis(dirty, 5)


def test_generalized_eigsh_accepts_raw_matrices(small_mesh):
    H, A = hamiltonian(small_mesh)
    values, vectors, info = generalized_eigsh(H, A, 12, method="krylov")
    assert info.method == "krylov" and info.max_residual < 1e-9
    np.testing.assert_allclose(vectors.T @ A @ vectors, np.eye(12), atol=1e-10)


def test_superlu_and_cholmod_backends_agree(sphere_5k):
    from hamsa.factorization import HAVE_CHOLMOD

    superlu = solve(sphere_5k, 16, np.linspace(0, 4, sphere_5k.n_vertices), backend="superlu")
    assert relative_residuals(superlu)[1:].max() < 1e-8
    if HAVE_CHOLMOD:
        cholmod = solve(sphere_5k, 16, np.linspace(0, 4, sphere_5k.n_vertices), backend="cholmod")
        np.testing.assert_allclose(superlu.values, cholmod.values, rtol=1e-10)


def test_the_supernodal_kernel_agrees_with_the_simplicial_one_and_restores_the_blas_threads(sphere_5k, monkeypatch):
    import hamsa.factorization as factorization
    from hamsa.factorization import CholeskySolver, cholmod_thread_pools

    if not (factorization.HAVE_CHOLMOD and cholmod_thread_pools() is not None):
        pytest.skip("needs CHOLMOD with an optimized BLAS and threadpoolctl (the supernodal kernel is not used)")
    V = np.linspace(0, 4, sphere_5k.n_vertices)
    simplicial = solve(sphere_5k, 16, V, backend="cholmod")
    before = [pool["num_threads"] for pool in cholmod_thread_pools().info()]
    monkeypatch.setattr(factorization, "SUPERNODAL_FROM", 0)
    assert factorization.supernodal(sphere_5k.n_vertices)
    super_ = solve(sphere_5k, 16, V, backend="cholmod")
    np.testing.assert_allclose(super_.values, simplicial.values, rtol=1e-10)
    assert relative_residuals(super_)[1:].max() < 1e-9
    modes, analyze = [], factorization._cholmod_analyze
    monkeypatch.setattr(
        factorization, "_cholmod_analyze", lambda m, **kw: (modes.append(kw["mode"]), analyze(m, **kw))[1]
    )
    H, A = hamiltonian(sphere_5k)
    K = (H + A).tocsc()
    solver = CholeskySolver(K, "cholmod")
    assert modes == ["supernodal"]
    rhs = np.random.default_rng(3).standard_normal((K.shape[0], 3))
    np.testing.assert_allclose(K @ solver.solve(rhs), rhs, atol=1e-10 * np.abs(rhs).max())
    solver.refactor((H + 2 * A).tocsc())  # new values, the analysis kept
    np.testing.assert_allclose((H + 2 * A) @ solver.solve(rhs), rhs, atol=1e-10 * np.abs(rhs).max())
    assert [pool["num_threads"] for pool in cholmod_thread_pools().info()] == before


def test_chebyshev_refuses_a_full_mass_and_cpu_methods_on_the_gpu(small_mesh):
    with pytest.raises(SolverError, match="lumped"):
        hamsa.eigenbasis(small_mesh, 5, mass="full", method="chebyshev")
    with pytest.raises(SolverError, match="chebyshev"):
        hamsa.eigenbasis(small_mesh, 5, method="krylov", device="cuda")


def _has_cuda():
    try:
        from hamsa.chebyshev import array_modules

        array_modules("cuda")
        return True
    except Exception:
        return False


@pytest.mark.skipif(_has_cuda(), reason="CuPy and a GPU are present: the missing-dependency error cannot occur")
def test_gpu_without_cupy_says_which_extra_to_install(small_mesh):
    with pytest.raises(hamsa.MissingDependencyError, match="gpu-cuda"):
        hamsa.eigenbasis(small_mesh, 5, device="cuda")


@pytest.mark.skipif(not _has_cuda(), reason="needs CuPy and a CUDA GPU (the GPU path is optional)")
@pytest.mark.parametrize("potential", ["zero", "signed"])
def test_gpu_solver_matches_the_cpu_solver(sphere_5k, potential):
    rng = np.random.default_rng(6)
    V = None if potential == "zero" else 20 * rng.standard_normal(sphere_5k.n_vertices)
    gpu = solve(sphere_5k, 40, V, device="cuda")
    cpu = solve(sphere_5k, 40, V, method="krylov")
    assert gpu.info.method == "chebyshev"
    np.testing.assert_allclose(gpu.values, cpu.values, rtol=1e-8, atol=1e-8 * np.abs(cpu.values).max())
    assert relative_residuals(gpu)[1:].max() < 1e-8  # (the first is the zero mode when V = 0)
    # same subspace (the sphere has multiplicities: compare spans, not vectors)
    inner = gpu.vectors[:, :35].T @ (gpu.mass @ cpu.vectors)
    assert np.linalg.svd(inner, compute_uv=False).min() > 1 - 1e-6


def test_solver_object_factors_once_per_solve(sphere_5k, monkeypatch):
    from hamsa.eigen import HamiltonianEigensolver
    from hamsa.factorization import CholeskySolver

    calls = []
    original = CholeskySolver.refactor
    monkeypatch.setattr(CholeskySolver, "refactor", lambda self, m: (calls.append(1), original(self, m))[1])
    solver = HamiltonianEigensolver.for_mesh(sphere_5k, 8, method="krylov")
    solver.solve(np.ones(sphere_5k.n_vertices))
    solver.solve(2 * np.ones(sphere_5k.n_vertices))
    assert len(calls) == 2
    with pytest.raises(SolverError, match="nothing is factored"):
        CholeskySolver.unfactored((3, 3)).solve(np.ones(3))


class _DenseInverse:
    """Stands in for the sparse factorization: solve(X) = K^-1 X."""

    def __init__(self, K):
        self.K = K

    def solve(self, X):
        return np.linalg.solve(self.K, X)


@pytest.mark.parametrize("full_mass", [False, True])
def test_settling_step_carries_the_krylov_relation_to_the_orthonormal_basis(full_mass):
    """A settling step must turn any exact relation S Q_old = Q_old T_old on a basis whose pending columns
    are far from orthogonal (Q_old = Q_true G^-1, G^-1 = [[I, C], [0, R]]) into the A-projection of S on
    the A-orthonormal basis, with the next block's coupling; errors in the bookkeeping of C or R show."""
    from hamsa import eigen

    rng = np.random.default_rng(7)
    n, b, blocks, settled_blocks = 90, 4, 5, 2
    f1, f0, settled = b * blocks, b * (blocks - 1), b * settled_blocks
    if full_mass:
        M = sp.random(n, n, density=0.05, random_state=3)
        A = (M @ M.T + sp.eye(n)).tocsr()
    else:
        A = sp.diags(rng.uniform(0.5, 2.0, n)).tocsr()
    B = rng.standard_normal((n, n))
    K = B @ B.T + n * np.eye(n)
    S = np.linalg.solve(K, A.toarray())  # self-adjoint in the A inner product
    # the exact block Krylov basis: A-orthonormal, nested spans
    krylov = [rng.standard_normal((n, b))]
    for _ in range(blocks - 1):
        krylov.append(S @ krylov[-1])
    V = np.hstack(krylov)
    Q_true = V @ np.linalg.inv(np.linalg.cholesky(V.T @ A @ V).T)
    T_true = Q_true.T @ A @ S @ Q_true
    # the pending columns as a deferred pass leaves them (here grossly), and T in that basis
    G_inverse = np.eye(f1)
    G_inverse[:settled, settled:] = 0.05 * rng.standard_normal((settled, f1 - settled))
    G_inverse[settled:, settled:] += np.triu(0.05 * rng.standard_normal((f1 - settled,) * 2))
    Q_old = Q_true @ G_inverse
    capacity = f1 + 2 * b
    Q, T = np.zeros((n, capacity), order="F"), np.zeros((capacity, capacity))
    Q[:, :f1] = Q_old
    T[:f1, :f0] = (np.linalg.solve(G_inverse, T_true @ G_inverse))[:, :f0]
    mass = eigen._MassOperator(A)
    AQ = None if mass.is_diagonal else np.asfortranarray(A @ Q)
    Qn, AQn, settled_now = eigen._extend(
        _DenseInverse(K), Q, AQ, T, f0, f1, settled, True, capacity, b, mass, f0 - b, rng
    )
    assert settled_now and Qn.shape[1] == b
    basis = np.hstack([Q[:, :f1], Qn])
    np.testing.assert_allclose(basis.T @ A @ basis, np.eye(f1 + b), atol=1e-12)
    # the pending columns are the true ones (the triangular R keeps every leading span)
    np.testing.assert_allclose(Q[:, :f1], Q_true, atol=1e-10)
    np.testing.assert_allclose(T[:f1, :f1], Q_true.T @ A @ S @ Q_true, atol=1e-10)
    relation = S @ Q[:, :f1] - Q[:, :f1] @ T[:f1, :f1]
    relation[:, f0:] -= Qn @ T[f1 : f1 + b, f0:f1]
    assert np.abs(relation).max() < 1e-10
    if AQ is not None:
        np.testing.assert_allclose(AQ[:, :f1], A @ Q[:, :f1], atol=1e-12)


def test_deferred_second_passes_give_the_settled_solvers_eigenpairs(sphere_5k, monkeypatch):
    """The solver with its second Gram-Schmidt passes deferred agrees with the one that settles every
    step, and it does defer (light steps happen) on a mesh larger than the Krylov basis."""
    from hamsa import eigen

    light = []
    original = eigen._extend

    def counting(*args):
        Qn, AQn, settled = original(*args)
        light.append(not settled)
        return Qn, AQn, settled

    monkeypatch.setattr(eigen, "_extend", counting)
    deferred = solve(sphere_5k, 40, method="krylov")
    assert sum(light) >= 3
    cancellation = eigen._CANCELLATION
    monkeypatch.setattr(eigen, "_CANCELLATION", 1.0)  # every first pass "cancels": every step settles
    light.clear()
    cancelled = solve(sphere_5k, 40, method="krylov")
    assert not any(light)
    monkeypatch.setattr(eigen, "_CANCELLATION", cancellation)
    monkeypatch.setattr(eigen, "_DEFERRED_BLOCKS", 0)
    light.clear()
    settled = solve(sphere_5k, 40, method="krylov")
    assert not any(light)
    np.testing.assert_allclose(deferred.values, settled.values, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(cancelled.values, settled.values, rtol=1e-12, atol=1e-12)
    assert relative_residuals(deferred)[1:].max() < 1e-9
    gram = deferred.vectors.T @ (deferred.mass @ deferred.vectors)
    assert np.abs(gram - np.eye(40)).max() < 1e-12
