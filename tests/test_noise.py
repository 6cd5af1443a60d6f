import numpy as np
import pytest

import hamsa
from hamsa import shapes
from hamsa.noise import basis_stability, potential_noise, topological_noise, vertex_noise


@pytest.fixture(scope="module")
def mesh():
    return shapes.capsule(radius=0.5, length=2.0, n_around=48)


def test_generators_are_seeded_and_reproducible(mesh):
    assert np.array_equal(vertex_noise(mesh, 0.2, seed=1).vertices, vertex_noise(mesh, 0.2, seed=1).vertices)
    assert not np.array_equal(vertex_noise(mesh, 0.2, seed=1).vertices, vertex_noise(mesh, 0.2, seed=2).vertices)
    V = mesh.vertices[:, 2] ** 2
    assert np.array_equal(potential_noise(V, 0.2, seed=3), potential_noise(V, 0.2, seed=3))
    a, ka = topological_noise(mesh, 0.3, seed=4)
    b, kb = topological_noise(mesh, 0.3, seed=4)
    assert np.array_equal(a.faces, b.faces) and np.array_equal(ka, kb)


def test_noise_magnitudes(mesh):
    moved = vertex_noise(mesh, 0.2, seed=0).vertices - mesh.vertices
    assert moved.std() == pytest.approx(0.2 * mesh.mean_edge_length, rel=0.05)
    V = mesh.vertices[:, 2] ** 2
    assert (potential_noise(V, 0.2, seed=0) - V).var() == pytest.approx(0.2 * V.var(), rel=0.1)


@pytest.mark.parametrize("fraction", [0.1, 0.3])
def test_topological_noise_removes_the_requested_area(mesh, fraction):
    holed, kept = topological_noise(mesh, fraction, seed=0)
    assert holed.n_components == 1
    np.testing.assert_array_equal(holed.vertices, mesh.vertices[kept])
    removed = 1 - holed.area / mesh.area
    # the largest piece is kept, so tiny islands may add to the removed area
    assert abs(removed - fraction) < 0.01
    assert len(holed.boundary_loops) > 5  # many small holes


def test_basis_stability_is_one_without_noise_and_drops_with_it(mesh):
    clean = hamsa.eigenbasis(mesh, 10)
    assert np.allclose(basis_stability(clean, clean), 1.0)
    noisy = hamsa.eigenbasis(vertex_noise(mesh, 0.2, seed=0), 10)
    stability = basis_stability(clean, noisy)
    assert np.all(stability[:5] > 0.9) and np.all(stability <= 1.0)
    holed, kept = topological_noise(mesh, 0.3, seed=0)
    holey = hamsa.eigenbasis(holed, 10)
    assert basis_stability(clean, holey, kept).shape == (10,)


def test_refine_region_keeps_the_surface_and_is_conforming():
    from hamsa.noise import refine_region

    mesh = shapes.capsule(0.5, 3.0, 24)
    refined = refine_region(mesh, mesh.vertices[mesh.faces].mean(axis=1)[:, 0] > 0)
    assert refined.n_vertices > 2 * mesh.n_vertices
    np.testing.assert_array_equal(refined.vertices[: mesh.n_vertices], mesh.vertices)  # ids kept
    assert np.isclose(refined.area, mesh.area, rtol=1e-12)  # midpoints lie on the faces
    assert refined.n_components == 1 and len(refined.boundary_loops) == 0  # closed: no hanging vertices
    assert refined.euler_characteristic == mesh.euler_characteristic
    # the same surface: the low spectrum moves only by the discretization error
    np.testing.assert_allclose(hamsa.eigenbasis(refined, 6).values[1:], hamsa.eigenbasis(mesh, 6).values[1:], rtol=0.01)
