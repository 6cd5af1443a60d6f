"""Built-in articulated shapes and the implicit-surface mesher behind them."""

import numpy as np
import pytest

import hamsa
from hamsa import shapes
from hamsa.errors import MeshError
from hamsa.implicit import _AMBIGUOUS, implicit_surface


def _sphere_function(radius):
    return lambda p: np.linalg.norm(p, axis=1) - radius


def test_surface_nets_sphere_is_on_the_surface_with_the_right_area_and_spectrum():
    mesh = implicit_surface(_sphere_function(1.0), [-1, -1, -1], [1, 1, 1], spacing=0.08)
    assert mesh.euler_characteristic == 2 and not mesh.boundary_loops
    np.testing.assert_allclose(np.linalg.norm(mesh.vertices, axis=1), 1.0, atol=1e-6)
    assert abs(mesh.area / (4 * np.pi) - 1) < 0.01
    values = hamsa.eigenbasis(mesh, 16).values
    expected = np.repeat([0, 2, 6, 12], [1, 3, 5, 7])
    np.testing.assert_allclose(values[1:], expected[1:], rtol=0.02)
    assert hamsa.eigenbasis(mesh, 2).values[0] == pytest.approx(0, abs=1e-8)


def test_ambiguous_table_knows_the_classic_cases():
    assert not _AMBIGUOUS[0] and not _AMBIGUOUS[255] and not _AMBIGUOUS[1]  # empty, full, one corner
    assert _AMBIGUOUS[1 | 128]  # corners (0,0,0) and (1,1,1): two sheets through one cell
    assert not _AMBIGUOUS[1 | 2]  # two corners on an edge


@pytest.mark.parametrize("gap", [0.2, 0.5, 1.0, 1.7])
def test_nearly_touching_spheres_stay_manifold(gap):
    """Two spheres a fraction of a cell apart produce saddles that would make surface nets non-manifold."""
    spacing = 0.1

    def two_spheres(p):
        offset = np.array([1.0 + gap * spacing / 2, 0.0, 0.0])
        return np.minimum(np.linalg.norm(p - offset, axis=1), np.linalg.norm(p + offset, axis=1)) - 1.0

    mesh = implicit_surface(two_spheres, [-2.2, -1.1, -1.1], [2.2, 1.1, 1.1], spacing)
    assert not mesh.boundary_loops and mesh.non_manifold_vertices.size == 0
    assert mesh.euler_characteristic in (2, 4)  # joined through a small neck (genus 0) or separate


def test_surface_touching_the_box_is_an_error():
    with pytest.raises(MeshError, match="touches the sampling box"):
        implicit_surface(_sphere_function(1.0), [-0.5, -0.5, -0.5], [0.5, 0.5, 0.5], 0.1)


@pytest.mark.parametrize(
    "make, poses, p90",
    [(shapes.humanoid, shapes.HUMANOID_POSES, 0.15), (shapes.hand, shapes.HAND_POSES, 0.15)],
)
def test_pose_family_shares_connectivity_and_is_near_isometric(make, poses, p90):
    """Stated tolerance: median edge-length change < 1%, 90% of edges within 15%, total area within 1%."""
    names = list(poses)
    rest = make(names[0], spacing=0.04)
    assert rest.euler_characteristic == 2 and not rest.boundary_loops
    assert rest.vertex_components[0] == 1
    edges = rest.edges
    rest_lengths = np.linalg.norm(np.subtract(*rest.vertices[edges.T]), axis=1)
    for name in names[1:]:
        posed = make(name, spacing=0.04)
        np.testing.assert_array_equal(posed.faces, rest.faces)
        assert np.abs(posed.vertices - rest.vertices).max() > 0.05  # it did move
        change = np.abs(np.linalg.norm(np.subtract(*posed.vertices[edges.T]), axis=1) / rest_lengths - 1)
        assert np.median(change) < 0.01 and np.percentile(change, 90) < p90, name
        assert abs(posed.area / rest.area - 1) < 0.01


def test_unknown_pose_names_the_known_ones():
    with pytest.raises(MeshError, match="known: rest"):
        shapes.humanoid("dance")
