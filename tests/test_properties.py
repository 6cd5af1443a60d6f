"""Property-based checks over random small meshes and potentials (hypothesis)."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import hamsa
from hamsa import shapes
from hamsa.diffusion import default_hks_times, heat_kernel_signature
from hamsa.operators import hamiltonian, mass_matrix, stiffness_matrix
from hamsa.theory import eigenvalue_bounds

SETTINGS = settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@st.composite
def meshes(draw):
    """A jittered sphere or torus of a few hundred vertices (random obtuse triangles included)."""
    seed = draw(st.integers(0, 2**31 - 1))
    kind = draw(st.sampled_from(["sphere", "torus", "rectangle"]))
    rng = np.random.default_rng(seed)
    base = {
        "sphere": lambda: shapes.sphere(int(rng.integers(60, 300))),
        "torus": lambda: shapes.torus(n_major=int(rng.integers(10, 20)), n_minor=int(rng.integers(6, 10))),
        "rectangle": lambda: shapes.rectangle(1.0, float(rng.uniform(0.3, 2)), 10, 8),
    }[kind]()
    # at least some jitter: exact symmetries give repeated eigenvalues, whose basis (and a k that cuts
    # through them) is arbitrary
    jitter = draw(st.floats(0.05, 0.25)) * base.mean_edge_length
    return hamsa.TriMesh(base.vertices + jitter * rng.standard_normal(base.vertices.shape), base.faces), rng


@SETTINGS
@given(meshes())
def test_operator_identities(sample):
    mesh, _ = sample
    W = stiffness_matrix(mesh)
    assert abs(W - W.T).max() == 0
    assert np.abs(W @ np.ones(mesh.n_vertices)).max() <= 1e-12 * abs(W).max()
    for kind in ("voronoi", "barycentric", "full"):
        assert mass_matrix(mesh, kind).sum() == pytest.approx(mesh.area, rel=1e-12)


@SETTINGS
@given(meshes(), st.floats(-50, 50), st.floats(0.1, 100))
def test_eigenbasis_is_orthonormal_and_obeys_theorem_1(sample, offset, spread):
    mesh, rng = sample
    V = offset + spread * rng.random(mesh.n_vertices)
    k = min(12, mesh.n_vertices - 2)
    lbo = hamsa.eigenbasis(mesh, k)
    basis = hamsa.eigenbasis(mesh, k, V)
    gram = basis.vectors.T @ basis.mass @ basis.vectors
    assert np.abs(gram - np.eye(k)).max() < 1e-8
    lower, upper = eigenvalue_bounds(lbo.values, V)
    tol = 1e-8 * max(np.abs(basis.values).max(), 1.0)
    assert np.all(lower - tol <= basis.values) and np.all(basis.values <= upper + tol)


@SETTINGS
@given(meshes())
def test_hks_is_invariant_to_rigid_motion_and_vertex_permutation(sample):
    mesh, rng = sample
    k = min(15, mesh.n_vertices - 2)
    basis = hamsa.eigenbasis(mesh, k)
    times = default_hks_times(basis, 10)
    hks = heat_kernel_signature(basis, times)
    q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    moved = hamsa.TriMesh(mesh.vertices @ q.T + rng.standard_normal(3), mesh.faces)
    np.testing.assert_allclose(heat_kernel_signature(hamsa.eigenbasis(moved, k), times), hks, rtol=1e-6, atol=1e-9)
    order = rng.permutation(mesh.n_vertices)
    inverse = np.argsort(order)
    permuted = hamsa.TriMesh(mesh.vertices[order], inverse[mesh.faces])
    np.testing.assert_allclose(
        heat_kernel_signature(hamsa.eigenbasis(permuted, k), times)[inverse], hks, rtol=1e-6, atol=1e-9
    )


@SETTINGS
@given(meshes())
def test_hamiltonian_has_the_sparsity_of_the_stiffness(sample):
    mesh, rng = sample
    H, _ = hamiltonian(mesh, rng.standard_normal(mesh.n_vertices))
    assert H.nnz == stiffness_matrix(mesh).nnz
