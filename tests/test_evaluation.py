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
    exact = TruthDistances(mesh, truth, geodesics="exact")
    np.testing.assert_allclose(exact.errors(predicted), geodesic_errors(mesh, predicted, truth, geodesics="exact"),
                               rtol=1e-12)  # fmt: skip


def test_points_mapped_to_another_component_count_as_unreachable():
    scores = summary(np.array([0.0, 0.01, np.inf, 0.2]))
    assert scores["unreachable"] == 0.25 and scores["mean_error"] == pytest.approx(0.07)
    assert scores["within_0.05"] == 0.5 and 0 < scores["auc"] < 1


def test_exact_geodesics_are_euclidean_on_an_irregular_planar_mesh():
    from hamsa.geodesic import ExactGeodesicSolver

    plane = shapes.rectangle(2.0, 1.0, 24, 12)
    rng = np.random.default_rng(5)
    low, high = plane.vertices.min(axis=0), plane.vertices.max(axis=0)
    xy = plane.vertices[:, :2]
    inside = np.flatnonzero(np.all((xy > low[:2] + 0.01) & (xy < high[:2] - 0.01), axis=1))
    vertices = plane.vertices.copy()
    vertices[inside, :2] += rng.uniform(-0.02, 0.02, (len(inside), 2))  # irregular, still convex and flat
    plane = hamsa.TriMesh(vertices, plane.faces)
    sources = np.array([0, 100, plane.n_vertices - 1])
    euclidean = np.linalg.norm(plane.vertices[:, None, :] - plane.vertices[sources][None], axis=2)
    np.testing.assert_allclose(ExactGeodesicSolver(plane).distances_from(sources), euclidean, atol=1e-12)
    heat = GeodesicSolver(plane).distances_from(sources)
    assert np.abs(heat - euclidean).max() > 1e-3  # the heat method is only first-order accurate here


def test_exact_geodesics_beat_the_heat_method_on_a_sphere():
    sphere = shapes.sphere(2000)
    sources = np.array([0, 700])
    great_circle = np.arccos(np.clip(sphere.vertices @ sphere.vertices[sources].T, -1, 1))
    far = great_circle > 0.2
    errors = {
        method: np.mean(np.abs(hamsa.geodesic.geodesic_solver(sphere, method=method).distances_from(sources)
                               - great_circle)[far] / great_circle[far])
        for method in ("heat", "exact")
    }  # fmt: skip
    assert errors["exact"] < 0.002 and errors["exact"] < errors["heat"] / 5  # measured 0.0008 and 0.015


def test_exact_pair_distances_equal_whole_propagations_near_and_far_and_across_pieces():
    from hamsa.geodesic import ExactGeodesicSolver

    sphere = shapes.sphere(600)
    two = hamsa.TriMesh(np.vstack([sphere.vertices, sphere.vertices + [5.0, 0, 0]]),
                        np.vstack([sphere.faces, sphere.faces + sphere.n_vertices]))  # fmt: skip
    solver = ExactGeodesicSolver(two)
    rng = np.random.default_rng(3)
    sources = rng.integers(0, sphere.n_vertices, 60)
    table = solver.distances_from(np.unique(sources))[:, np.searchsorted(np.unique(sources), sources)]
    nearest = np.argsort(table, axis=0)[5]  # close pairs: found inside the first, small radius
    targets = np.concatenate([nearest, rng.integers(0, two.n_vertices, 60)])  # far pairs and the other piece
    sources = np.concatenate([sources, sources])
    table = np.hstack([table, table])
    expected = table[targets, np.arange(len(targets))]
    assert np.isinf(expected).any() and np.isfinite(expected).any()
    np.testing.assert_allclose(solver.between(sources, targets), expected, rtol=1e-12)
    np.testing.assert_allclose(GeodesicSolver(two).between(sources, targets)[np.isfinite(expected)],
                               expected[np.isfinite(expected)], rtol=0.1, atol=0.02)  # fmt: skip
    assert np.isinf(GeodesicSolver(two).between(sources, targets)[~np.isfinite(expected)]).all()


def test_exact_kim_scores_and_their_errors(body, monkeypatch):
    from hamsa.evaluation import map_scores

    points = sample_points(body.n_vertices, 200, seed=4)
    exact = geodesic_errors(body, mirror_map(body)[points], points, geodesics="exact")
    heat = geodesic_errors(body, mirror_map(body)[points], points)
    assert np.median(np.abs(exact - heat) / np.maximum(exact, 1e-12)) < 0.05  # the same protocol
    assert map_scores(body, np.arange(body.n_vertices), np.arange(body.n_vertices), 100, geodesics="exact")["auc"] == 1
    with pytest.raises(HamsaError, match="one of"):
        geodesic_errors(body, points, points, geodesics="dijkstra")
    with pytest.raises(HamsaError, match="point cloud"):
        hamsa.geodesic.geodesic_solver(hamsa.PointCloud(body.vertices), method="exact")
    with pytest.raises(HamsaError, match="diffusion time"):
        hamsa.geodesic.geodesic_solver(body, 0.1, method="exact")
    monkeypatch.setitem(__import__("sys").modules, "pygeodesic.geodesic", None)
    with pytest.raises(hamsa.errors.MissingDependencyError, match=r"hamsa\[geodesics\]"):
        hamsa.geodesic.geodesic_distance(body, [0], method="exact")


def test_map_distortion_tells_a_map_along_the_surface_from_a_scrambled_one_without_ground_truth():
    from hamsa.evaluation import map_distortion

    rest = shapes.humanoid("rest").scaled_to_unit_area()
    walk = shapes.humanoid("walk").scaled_to_unit_area()
    n = rest.n_vertices
    true = map_distortion(rest, walk, np.arange(n))  # the poses share vertex ids: the identity is the truth
    scrambled = map_distortion(rest, walk, np.random.default_rng(0).integers(0, n, n))
    # measured 0.012 against 0.35; a map with replacement hits about 1 - 1/e of the target
    assert true["coverage"] == 1.0 and true["distortion"] < 0.03 and true["pairs"] == 30 * 1000
    assert scrambled["distortion"] > 10 * true["distortion"] and 0.55 < scrambled["coverage"] < 0.7
    assert map_distortion(rest, rest, np.arange(n))["distortion"] == 0.0
    with pytest.raises(HamsaError, match="integer target ids"):
        map_distortion(rest, walk, np.arange(n - 1))
