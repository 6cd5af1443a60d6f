import numpy as np
import pytest
from scipy.spatial import cKDTree

import hamsa
from hamsa import HamsaError, shapes
from hamsa.evaluation import THRESHOLDS, area_under_curve, error_curve, geodesic_errors, sample_points, summary
from hamsa.geodesic import GeodesicSolver


@pytest.fixture(scope="module")
def body():
    """An asymmetric-looking but left-right symmetric surface: a bent capsule, mirror plane x = 0."""
    capsule = shapes.capsule(0.4, 2.0, 32)
    x, y, z = capsule.vertices.T
    vertices = np.stack([z, y, 0.3 * z**2 + x], axis=1)  # long axis along x, bent up: symmetric in x -> -x
    return hamsa.TriMesh(vertices, capsule.faces)


def mirror_map(mesh):
    reflected = mesh.vertices * [-1.0, 1.0, 1.0]
    return cKDTree(mesh.vertices).query(reflected)[1]


def test_identity_map_scores_perfectly(body):
    points = sample_points(body.n_vertices, 300, seed=1)
    errors = geodesic_errors(body, points, points)
    assert np.all(errors == 0)
    assert np.all(error_curve(errors) == 1) and area_under_curve(errors) == 1
    assert summary(errors)["within_0.05"] == 1


def test_a_symmetric_flip_fails_without_symmetries_and_passes_with_them(body):
    mirror = mirror_map(body)
    np.testing.assert_array_equal(mirror[mirror], np.arange(body.n_vertices))  # an exact involution
    points = sample_points(body.n_vertices, 400, seed=2)
    flipped = geodesic_errors(body, mirror[points], points)
    allowed = geodesic_errors(body, mirror[points], points, symmetry=mirror)
    far = np.abs(body.vertices[points, 0]) > 0.3  # points off the mirror plane
    assert np.median(flipped[far]) > 0.2 and area_under_curve(flipped) < 0.6
    assert np.all(allowed == 0)


@pytest.mark.parametrize("n", [2000, 6000])
def test_geodesics_within_two_percent_of_exact_on_a_sphere(n):
    sphere = shapes.sphere(n)
    sources = np.array([0, n // 3, n // 2])
    table = GeodesicSolver(sphere).distances_from(sources)
    exact = np.arccos(np.clip(sphere.vertices @ sphere.vertices[sources].T, -1, 1))
    far = exact > 0.2
    assert np.mean(np.abs(table - exact)[far] / exact[far]) < 0.02


def test_curve_thresholds_and_bad_inputs(body):
    assert THRESHOLDS[0] == 0 and THRESHOLDS[-1] == pytest.approx(0.25) and len(THRESHOLDS) == 51
    curve = error_curve([0.0, 0.1, 0.3])
    assert curve[0] == pytest.approx(1 / 3) and curve[-1] == pytest.approx(2 / 3)
    with pytest.raises(HamsaError, match="equal"):
        geodesic_errors(body, [0, 1], [0])
    with pytest.raises(HamsaError, match="integers"):
        geodesic_errors(body, [0, body.n_vertices], [0, 1])
    assert sample_points(10, 50).tolist() == list(range(10))


def test_truth_distances_equal_geodesic_errors_for_every_map():
    from hamsa.evaluation import TruthDistances

    mesh = shapes.sphere(800)
    rng = np.random.default_rng(2)
    truth = rng.integers(0, mesh.n_vertices, 100)
    table = TruthDistances(mesh, truth, batch=16)
    for _ in range(3):
        predicted = rng.integers(0, mesh.n_vertices, 100)
        np.testing.assert_allclose(table.errors(predicted), geodesic_errors(mesh, predicted, truth), rtol=1e-12)
    with pytest.raises(HamsaError, match="predicted"):
        table.errors(predicted[:5])


def test_points_mapped_to_another_component_count_as_unreachable():
    scores = summary(np.array([0.0, 0.01, np.inf, 0.2]))
    assert scores["unreachable"] == 0.25 and scores["mean_error"] == pytest.approx(0.07)
    assert scores["within_0.05"] == 0.5 and 0 < scores["auc"] < 1
