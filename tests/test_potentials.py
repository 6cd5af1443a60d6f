import numpy as np
import pytest

import hamsa
from hamsa import HamsaError, PotentialError, potentials, shapes
from hamsa.geodesic import geodesic_distance


def test_step_from_mask_and_from_field():
    mesh = shapes.icosphere(2)
    z = mesh.vertices[:, 2]
    np.testing.assert_array_equal(potentials.step(mesh, z > 0, 5.0), np.where(z > 0, 5.0, 0.0))
    np.testing.assert_array_equal(potentials.step(mesh, z, 5.0, threshold=0.0), np.where(z > 0, 5.0, 0.0))
    with pytest.raises(PotentialError, match="threshold"):
        potentials.step(mesh, z, 5.0)
    with pytest.raises(PotentialError, match="shape"):
        potentials.step(mesh, z[:-1] > 0, 5.0)


@pytest.mark.parametrize("n, mean_tol", [(2000, 0.025), (10000, 0.02)])
def test_heat_method_geodesics_on_the_sphere(n, mean_tol):
    mesh = shapes.sphere(n)
    distance = geodesic_distance(mesh, [0])
    exact = np.arccos(np.clip(mesh.vertices @ mesh.vertices[0], -1, 1))
    far = exact > 0.2
    relative = np.abs(distance - exact)[far] / exact[far]
    assert distance[0] == 0 and relative.mean() < mean_tol and relative.max() < 0.15


def test_geodesic_potential_is_normalized_and_multi_source():
    mesh = shapes.sphere(3000)
    V = geodesic_distance(mesh, [0, 1500], normalize=True, unreachable="error")
    assert V.min() == 0 and V.max() == 1 and V[0] == 0 and V[1500] == 0


def test_geodesic_of_unreached_component_is_infinite():
    a = shapes.icosphere(2)
    two = hamsa.TriMesh(np.vstack([a.vertices, a.vertices + 5]), np.vstack([a.faces, a.faces + a.n_vertices]))
    d = geodesic_distance(two, [0])
    assert np.all(np.isfinite(d[: a.n_vertices])) and np.all(np.isinf(d[a.n_vertices :]))
    with pytest.raises(HamsaError, match="no source"):
        geodesic_distance(two, [0], normalize=True, unreachable="error")
    V = geodesic_distance(two, [0], normalize=True, unreachable="farthest")  # the loose piece counts as farthest
    np.testing.assert_allclose(V[: a.n_vertices], d[: a.n_vertices] / d[: a.n_vertices].max())
    assert np.all(V[a.n_vertices :] == 1.0)
    np.testing.assert_array_equal(geodesic_distance(two, [0], normalize=True, unreachable=0.5)[a.n_vertices :], 0.5)
    with pytest.raises(HamsaError, match="NaN"):
        geodesic_distance(two, [0], unreachable=np.nan)
    with pytest.raises(HamsaError, match="farthest"):
        geodesic_distance(two, [0], unreachable="far")


def test_benchmark_on_a_mesh_with_a_loose_piece():
    """TOSCA's gorilla has small pieces not joined to the body: the landmark potential and the landmark
    distance features treat them as farthest, and the evaluation counts points sent there as unreachable."""
    from hamsa.paper.benchmark import evaluate_pair

    body = shapes.humanoid(spacing=0.05)
    bit = shapes.icosphere(1)
    mesh = hamsa.TriMesh(
        np.vstack([body.vertices, 0.02 * bit.vertices + 3]), np.vstack([body.faces, bit.faces + body.n_vertices])
    )
    scored = evaluate_pair(mesh, mesh, np.arange(mesh.n_vertices), k=30, methods=("icskm", "icskm_geo"), points=300)
    for row in scored["rows"]:
        assert np.isfinite(row["mean_error"]) and row["auc"] > 0.8, row


def test_eigenfunction_sum_range_and_signs():
    basis = hamsa.eigenbasis(shapes.capsule(), 8)
    V = potentials.eigenfunction_sum(basis)
    assert V.min() == 0 and np.isclose(V.max() - V.min(), V.max())
    s = basis.vectors[:, 1:5].sum(axis=1)
    np.testing.assert_allclose(V, s / np.abs(s).max() - (s / np.abs(s).max()).min())
    flipped = potentials.eigenfunction_sum(basis, signs=[-1, 1, 1, 1])
    assert not np.allclose(flipped, V)


def test_area_distortion_of_a_scaled_copy_is_one_and_detects_stretch():
    mesh = shapes.sphere(1000)
    scaled = hamsa.TriMesh(mesh.vertices * 3.0, mesh.faces)
    np.testing.assert_allclose(potentials.area_distortion(mesh, scaled), 1.0, rtol=1e-12)
    stretched = hamsa.TriMesh(mesh.vertices * [2.0, 1.0, 1.0], mesh.faces)
    V = potentials.area_distortion(mesh, stretched)
    assert V.min() >= 1.0 and V.max() > 1.3


def test_texture_potential_luminance():
    mesh = shapes.icosphere(1)
    colors = np.zeros((mesh.n_vertices, 3), dtype=np.uint8)
    colors[0] = [255, 255, 255]
    colors[1] = [0, 255, 0]
    V = potentials.from_vertex_colors(mesh, colors)
    assert V[0] == pytest.approx(1.0) and V[1] == pytest.approx(0.7152) and V[2] == 0
    with pytest.raises(PotentialError, match=r"\[0, 1\]"):
        potentials.from_vertex_colors(mesh, np.full((mesh.n_vertices, 3), 2.0))


def test_curvature_of_spheres_and_plane():
    sphere = shapes.sphere(5000, radius=2.0)
    for kind, exact in (("mean", 0.5), ("gaussian", 0.25)):
        error = np.abs(potentials.curvature(sphere, kind) / exact - 1)
        assert np.median(error) < 0.005 and error.max() < 0.05  # the lattice's two end vertices are irregular
    plane = shapes.rectangle(1, 1, 10, 10)
    gaussian = potentials.curvature(plane, "gaussian")
    corners = np.isin(np.arange(plane.n_vertices), [0, 10, 110, 120])
    assert np.abs(gaussian[~corners]).max() < 1e-9  # corners carry the boundary's turning angle
    assert np.abs(potentials.curvature(plane, "mean")).max() < 1e-9


def test_dalmatian_texture_is_seeded_geodesic_spots():
    mesh = shapes.icosphere(4)
    colors = potentials.dalmatian_texture(mesh, spots=12, radius=0.05, seed=3)
    assert colors.shape == (mesh.n_vertices, 3) and colors.min() >= 0 and colors.max() <= 1
    np.testing.assert_array_equal(colors, potentials.dalmatian_texture(mesh, spots=12, radius=0.05, seed=3))
    assert not np.array_equal(colors, potentials.dalmatian_texture(mesh, spots=12, radius=0.05, seed=4))
    dark = colors[:, 0] < 0.5
    # 12 discs of geodesic radius ~0.05 sqrt(4 pi) = 0.18 (x 0.7 up to the soft edge) on the unit sphere:
    # each covers ~pi r^2 ~ 0.05 of the 4 pi area, overlaps aside
    assert 0.02 < dark.mean() < 0.3
    luminance = potentials.from_vertex_colors(mesh, colors)
    np.testing.assert_allclose(luminance, colors[:, 0])  # grey: luminance = any channel
    with pytest.raises(PotentialError):
        potentials.dalmatian_texture(mesh, spots=0)


def test_potential_specifications_equal_the_functions_they_name():
    from hamsa.potentials import eigenfunction_sum, from_spec, is_spec

    mesh = shapes.humanoid(spacing=0.05)
    np.testing.assert_array_equal(
        from_spec(mesh, "100*geodesic:3,40"), 100 * geodesic_distance(mesh, [3, 40], normalize=True)
    )
    np.testing.assert_array_equal(from_spec(mesh, "step:z>0.9"), potentials.step(mesh, mesh.vertices[:, 2] > 0.9, 1.0))
    np.testing.assert_array_equal(from_spec(mesh, "2.5*step:x<0"), potentials.step(mesh, mesh.vertices[:, 0] < 0, 2.5))
    lbo = hamsa.eigenbasis(mesh, 5)
    np.testing.assert_allclose(from_spec(mesh, "eigsum:1-4"), eigenfunction_sum(lbo), atol=1e-10)
    np.testing.assert_allclose(from_spec(mesh, "eigsum:1,3"), eigenfunction_sum(lbo, (1, 3)), atol=1e-10)
    np.testing.assert_array_equal(from_spec(mesh, "curvature:mean"), potentials.curvature(mesh, "mean"))
    assert is_spec("geodesic:1") and is_spec(" 3*step:y>0 ") and not is_spec("V.npy") and not is_spec("C:/V.npy")


def test_a_geodesic_specification_on_a_repaired_mesh_takes_input_ids():
    from hamsa.potentials import from_spec

    mesh = shapes.humanoid(spacing=0.05)
    vertex_ids = np.arange(mesh.n_vertices) + 7  # as if 7 vertices before these were dropped
    np.testing.assert_array_equal(
        from_spec(mesh, "geodesic:17", vertex_ids), geodesic_distance(mesh, [10], normalize=True)
    )
    with pytest.raises(PotentialError, match="input vertex 3 is not in the repaired mesh"):
        from_spec(mesh, "geodesic:3", vertex_ids)


@pytest.mark.parametrize(
    "spec, message",
    [
        ("geodesic:a", "not a comma-separated list of integers"),
        ("geodesic:99999", "vertex 99999 is not in 0..1005"),
        ("step:w>1", "AXIS>VALUE or AXIS<VALUE"),
        ("step:z>100", r"no vertex has z > 100 \(z is in"),
        ("step:z>-100", "every vertex has z > -100"),
        ("eigsum:1-2-3", "FIRST-LAST"),
        ("curvature:foo", "mean, absolute_mean or gaussian"),
        ("inf*step:z>0", "'inf' is not a finite number"),
        ("foo:1", "KIND one of geodesic, step, eigsum, curvature"),
    ],
)
def test_malformed_potential_specifications_are_refused_by_name(spec, message):
    from hamsa.potentials import from_spec

    mesh = shapes.humanoid(spacing=0.05)
    assert mesh.n_vertices == 1006
    with pytest.raises(PotentialError, match=message):
        from_spec(mesh, spec)
