import numpy as np
import pytest

import hamsa
from hamsa import shapes
from hamsa.nodal import courant_check, eigenvalue_clusters, nodal_domains, segment


@pytest.fixture(scope="module")
def sphere():
    # a latitude-longitude sphere: nodal lines that cross (at the poles, on the equator) pass through
    # vertices there, where a P1 function's domains are unambiguous
    return shapes.uv_sphere(32, 64)


@pytest.mark.parametrize(
    "function, expected",
    [
        (lambda x, y, z: z, 2),  # Y_1^0
        (lambda x, y, z: 3 * z**2 - 1, 3),  # Y_2^0: two caps and a band
        (lambda x, y, z: x**2 - y**2, 4),  # sectoral Y_2^2: cos(2 phi)
        (lambda x, y, z: np.real((x + 1j * y) ** 3), 6),  # sectoral Y_3^3: cos(3 phi)
        (lambda x, y, z: x * z, 4),  # tesseral Y_2^1
        (lambda x, y, z: 5 * z**3 - 3 * z, 4),  # Y_3^0
    ],
)
def test_domain_counts_of_spherical_harmonics(sphere, function, expected):
    count, labels = nodal_domains(sphere, function(*sphere.vertices.T))
    assert count == expected
    assert labels.max() == expected - 1


@pytest.mark.parametrize("i, j", [(0, 1), (1, 1), (2, 1), (3, 2)])
def test_domain_counts_of_rectangle_modes(i, j):
    mesh = shapes.rectangle(2.0, 1.0, 60, 60)  # nodal lines on grid lines: crossings at vertices
    x, y, _ = mesh.vertices.T
    count, _ = nodal_domains(mesh, np.cos(i * np.pi * x / 2.0) * np.cos(j * np.pi * y))
    assert count == (i + 1) * (j + 1)


def test_courant_holds_for_computed_eigenfunctions():
    mesh = shapes.rectangle(2.0, 1.3, 50, 32)
    basis = hamsa.eigenbasis(mesh, 20)
    rows = courant_check(mesh, basis)
    assert all(row["holds"] for row in rows)
    assert rows[0]["domains"] == 1 and rows[1]["domains"] == 2  # constant, then the first cosine


def test_clusters_and_segmentation():
    sphere = shapes.sphere(4000)
    basis = hamsa.eigenbasis(sphere, 9)
    clusters = eigenvalue_clusters(basis.values, rtol=1e-3)
    assert clusters.tolist() == [0, 1, 1, 1, 2, 2, 2, 2, 2]
    labels = segment(sphere, basis, 1)
    assert labels.min() == 0 and labels.max() == 1 and labels.shape == (sphere.n_vertices,)
    # the two hemispheres have about equal area
    areas = np.bincount(labels, weights=basis.mass.diagonal())
    assert abs(areas[0] - areas[1]) < 0.05 * areas.sum()
