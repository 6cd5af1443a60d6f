"""Meshes and bases from other libraries: trimesh, pyvista, plain arrays, scipy's eigsh (pyFM / LaPy style)."""

import numpy as np
import pytest
import scipy.sparse.linalg as sla

import hamsa
from hamsa import shapes
from hamsa.errors import HamsaError, MeshError
from hamsa.mesh import as_trimesh
from hamsa.operators import mass_matrix, stiffness_matrix


@pytest.fixture(scope="module")
def mesh():
    return shapes.torus(1.0, 0.4, 32, 12)


def _same_spectrum(other, mesh):
    np.testing.assert_allclose(hamsa.eigenbasis(other, 8).values, hamsa.eigenbasis(mesh, 8).values, rtol=1e-10)


def test_trimesh_objects_are_accepted_without_reordering(mesh):
    trimesh = pytest.importorskip("trimesh")
    other = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    converted = as_trimesh(other)
    np.testing.assert_array_equal(converted.faces, mesh.faces)
    _same_spectrum(other, mesh)


def test_pyvista_polydata_is_accepted_and_its_polygons_cut_into_triangles(mesh):
    pv = pytest.importorskip("pyvista")
    cells = np.hstack([np.full((mesh.n_faces, 1), 3), mesh.faces]).ravel()
    _same_spectrum(pv.PolyData(mesh.vertices, cells), mesh)
    plane = pv.Plane(i_resolution=4, j_resolution=3)  # 12 quads
    converted = as_trimesh(plane)
    np.testing.assert_array_equal(converted.vertices, plane.points)
    assert converted.n_faces == 24 and np.isclose(converted.area, plane.area)
    # a hexagon (two corners on straight edges) beside a quad: a 3 x 1 strip of unit cells
    points = np.array([[i, j, 0.0] for j in (0, 1) for i in range(4)])
    strip = pv.PolyData(points, np.array([6, 0, 1, 2, 6, 5, 4, 4, 2, 3, 7, 6]))
    converted = as_trimesh(strip)
    assert converted.n_faces == 4 + 2 and np.isclose(converted.area, 3.0)
    with pytest.raises(MeshError, match="trimesh.Trimesh"):
        as_trimesh(np.zeros((3, 3)))


def test_pairs_of_arrays_are_accepted(mesh):
    _same_spectrum((mesh.vertices.tolist(), mesh.faces), mesh)


def test_eigenbasis_round_trips_through_arrays_and_accepts_an_eigsh_basis(mesh):
    basis = hamsa.eigenbasis(mesh, 10)
    arrays = basis.to_arrays()
    assert arrays["mass"].shape == (mesh.n_vertices,) and arrays["vectors"].shape == (mesh.n_vertices, 10)
    again = hamsa.Eigenbasis.from_arrays(**arrays)
    f = np.sin(mesh.vertices[:, 0])
    np.testing.assert_allclose(again.project(f), basis.project(f), atol=1e-12)
    # what a pyFM / LaPy user has: scipy eigsh on (W, A), columns normalized in the A inner product
    W, A = stiffness_matrix(mesh), mass_matrix(mesh)
    values, vectors = sla.eigsh(W, 10, M=A, sigma=-0.01)
    external = hamsa.Eigenbasis.from_arrays(values, vectors, A.diagonal())
    np.testing.assert_allclose(external.values, basis.values, rtol=1e-8, atol=1e-10)
    with pytest.raises(HamsaError, match="mass-orthonormal"):
        hamsa.Eigenbasis.from_arrays(values, 2 * vectors, A.diagonal())
    with pytest.raises(HamsaError, match="ascending"):
        hamsa.Eigenbasis.from_arrays(values[::-1], vectors[:, ::-1], A.diagonal())
    with pytest.raises(HamsaError, match="mass must be"):
        hamsa.Eigenbasis.from_arrays(values, vectors, np.ones(3))
