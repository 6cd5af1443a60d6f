import numpy as np
import pytest

import hamsa
from hamsa import MeshError, shapes
from hamsa.mesh import as_trimesh

TRI = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])


@pytest.mark.parametrize(
    "vertices, faces, message",
    [
        (np.zeros((0, 3)), np.zeros((0, 3), int), "empty"),
        (TRI, np.zeros((0, 3), int), "empty"),
        (TRI[:, :2], [[0, 1, 2]], "shape"),
        ([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], "non-finite"),
        ([[0, 0, np.inf], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], "non-finite"),
        ([[0, 0, 1e300], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], "rescale"),
        (TRI, [[0, 1, 4]], "references vertex 4, mesh has 4 vertices"),
        (TRI, [[0, 1, -1]], "negative vertex index"),
        (TRI, [[0.0, 1.0, 2.0]], "integers"),
        (TRI, [[0, 1, 1]], "repeat a vertex"),
        ([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]], "zero area"),
        (TRI, [[0, 1, 2], [2, 1, 0]], "duplicate faces"),
        (TRI, [[0, 1, 2, 3]], "triangles"),
        (np.vstack([TRI, [[0.5, 0.5, 1]]]), [[0, 1, 2], [1, 0, 3], [0, 1, 4]], "non-manifold edges"),
    ],
)
def test_malformed_meshes_raise_mesh_error_naming_the_problem(vertices, faces, message):
    with pytest.raises(MeshError, match=message):
        hamsa.TriMesh(vertices, faces)


def test_arrays_are_read_only_and_typed():
    mesh = hamsa.TriMesh(TRI, [[0, 1, 2], [1, 3, 2]])
    assert mesh.vertices.dtype == np.float64 and mesh.faces.dtype == np.int64
    with pytest.raises(ValueError):
        mesh.vertices[0, 0] = 5.0


def test_topology_of_builtin_shapes():
    sphere = shapes.icosphere(2)
    assert sphere.n_vertices == 162 and sphere.euler_characteristic == 2 and sphere.is_closed
    torus = shapes.torus(n_major=20, n_minor=10)
    assert torus.euler_characteristic == 0 and torus.n_components == 1 and torus.is_consistently_oriented
    rect = shapes.rectangle(2, 1, 10, 5)
    assert rect.n_vertices == 66 and len(rect.boundary_loops) == 1 and len(rect.boundary_loops[0]) == 30
    assert rect.euler_characteristic == 1
    assert np.isclose(rect.area, 2.0)
    capsule = shapes.capsule()
    assert capsule.is_closed and capsule.euler_characteristic == 2 and capsule.is_consistently_oriented
    assert len(capsule.non_manifold_vertices) == 0


def test_two_components_and_unreferenced_vertices():
    a = shapes.icosphere(1)
    v = np.vstack([a.vertices, a.vertices + 3, [[9.0, 9, 9]]])
    f = np.vstack([a.faces, a.faces + a.n_vertices])
    mesh = hamsa.TriMesh(v, f)
    assert mesh.n_components == 2
    assert mesh.unreferenced_vertices.tolist() == [2 * a.n_vertices]
    with pytest.raises(MeshError, match="1 unreferenced vertices"):
        mesh.require_operator_ready()
    clean, kept = mesh.without_unreferenced()
    assert clean.n_vertices == 2 * a.n_vertices
    np.testing.assert_array_equal(clean.vertices, mesh.vertices[kept])
    np.testing.assert_array_equal(kept[clean.faces], mesh.faces)


def test_non_manifold_vertex_detected():
    # two triangle fans (tetrahedron caps) sharing only vertex 0
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1], [-1, 0, 0], [0, -1, 0], [-1, -1, -1]], float)
    f = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [0, 4, 5], [0, 5, 6], [0, 6, 4]])
    mesh = hamsa.TriMesh(v, f)
    assert mesh.non_manifold_vertices.tolist() == [0]


def test_inconsistent_orientation_detected():
    mesh = hamsa.TriMesh(TRI, [[0, 1, 2], [1, 2, 3]])
    assert not mesh.is_consistently_oriented
    assert hamsa.TriMesh(TRI, [[0, 1, 2], [1, 3, 2]]).is_consistently_oriented


def test_as_trimesh_accepts_pairs_and_rejects_others():
    assert as_trimesh((TRI, [[0, 1, 2]])).n_faces == 1
    with pytest.raises(MeshError, match="expected a TriMesh"):
        as_trimesh("mesh.off")


def test_largest_component_keeps_the_body_and_its_vertex_ids():
    body, bit = shapes.icosphere(2), shapes.icosphere(0)
    faces = np.vstack([bit.faces, bit.faces + bit.n_vertices])  # two loose bits first
    vertices = np.vstack([bit.vertices + 5, bit.vertices - 5])
    mesh = hamsa.TriMesh(np.vstack([vertices, body.vertices]), np.vstack([faces, body.faces + len(vertices)]))
    kept_mesh, kept = mesh.largest_component()
    np.testing.assert_array_equal(kept, np.arange(len(vertices), mesh.n_vertices))
    np.testing.assert_array_equal(kept_mesh.faces, body.faces)
    assert kept_mesh.n_components == 1 and body.largest_component()[0] is body


def test_scaled_to_unit_area_centers_and_scales_the_spectrum_by_the_area():
    capsule = shapes.capsule(0.5, 2.0, 16)
    mesh = hamsa.TriMesh(capsule.vertices * 3.0 + [1.0, -2.0, 4.0], capsule.faces)
    unit = mesh.scaled_to_unit_area()
    assert unit.area == pytest.approx(1.0, rel=1e-12)
    np.testing.assert_allclose(unit.vertices.mean(axis=0), 0.0, atol=1e-12)
    np.testing.assert_array_equal(unit.faces, mesh.faces)
    # Laplacian eigenvalues scale as 1 / length^2 = 1 / area: E(unit) = area * E(mesh)
    original, scaled = hamsa.eigenbasis(mesh, 8).values, hamsa.eigenbasis(unit, 8).values
    np.testing.assert_allclose(scaled[1:], mesh.area * original[1:], rtol=1e-8)


def test_triangulate_polygons_cuts_quads_along_the_right_diagonal_and_accepts_three_layouts():
    from hamsa.mesh import triangulate_polygons

    # a non-planar quad: 0-2 is the shorter diagonal; a dart (non-convex) quad: only 1-3 lies inside it
    vertices = np.array([[0, 0, 0], [1, 0, 0.5], [0.8, 0.8, 0], [0, 1, 0.5], [3, 0, 0], [5, 0, 0], [3.6, 0.6, 0],
                         [3, 2, 0]], dtype=float)  # fmt: skip
    quads = np.array([[0, 1, 2, 3], [5, 6, 7, 4]])
    faces = triangulate_polygons(vertices, quads)
    assert faces.tolist() == [[0, 1, 2], [0, 2, 3], [6, 7, 4], [6, 4, 5]]
    assert faces.tolist() == triangulate_polygons(vertices, [list(q) for q in quads]).tolist()
    assert faces.tolist() == triangulate_polygons(vertices, quads.ravel(), counts=[4, 4]).tolist()
    with pytest.raises(MeshError, match="counts sum to 7, but 8 corners"):
        triangulate_polygons(vertices, quads.ravel(), counts=[4, 3])
    # triangles pass through unchanged; a quad with a repeated corner is the triangle it stands for
    assert triangulate_polygons(vertices, np.array([[0, 1, 2]])).tolist() == [[0, 1, 2]]
    assert triangulate_polygons(vertices, [[0, 1, 2, 2], [3, 3, 0, 1], [4, 5, 6, 7]]).tolist()[:2] == [
        [0, 1, 2],
        [3, 0, 1],
    ]
