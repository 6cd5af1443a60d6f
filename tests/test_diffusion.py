import numpy as np
import pytest

import hamsa
from hamsa import HamsaError, shapes
from hamsa.diffusion import (
    default_hks_times,
    default_wks_energies,
    diffuse,
    diffuse_time_stepping,
    heat_kernel,
    heat_kernel_signature,
    total_heat,
    wave_kernel_signature,
)

from conftest import data_mesh


@pytest.fixture(scope="module")
def capsule():
    return shapes.capsule(radius=0.5, length=1.5, n_around=32)


def test_spectral_diffusion_matches_time_stepping(capsule):
    rng = np.random.default_rng(0)
    V = 3.0 * (capsule.vertices[:, 2] > 0) + rng.random(capsule.n_vertices)
    center = capsule.vertices[np.argmax(capsule.vertices[:, 0])]
    u0 = np.exp(-np.sum((capsule.vertices - center) ** 2, axis=1) / 0.05)  # a smooth bump
    t = 0.05
    basis = hamsa.eigenbasis(capsule, 300, V)
    spectral = diffuse(basis, u0, t)
    stepped = diffuse_time_stepping(capsule, u0, t, V, steps=400)
    A = basis.mass
    error = np.sqrt((spectral - stepped) @ A @ (spectral - stepped) / (stepped @ A @ stepped))
    assert error < 1e-3


def test_constant_potential_decays_total_heat_exponentially(capsule):
    c = 2.5
    basis = hamsa.eigenbasis(capsule, 20, np.full(capsule.n_vertices, c))
    u0 = np.zeros(capsule.n_vertices)
    u0[5] = 1.0 / basis.mass.diagonal()[5]  # unit heat at one vertex
    times = np.array([0.01, 0.1, 0.5, 2.0])
    np.testing.assert_allclose(total_heat(basis, diffuse(basis, u0, times)), np.exp(-c * times), rtol=1e-9)


def test_lbo_heat_kernel_is_symmetric_and_conserves_heat(capsule):
    basis = hamsa.eigenbasis(capsule, 60)
    sources = [0, 17, 400, 900]
    K = heat_kernel(basis, 0.2, sources)  # (n, 4)
    np.testing.assert_allclose(K[sources, :], K[sources, :].T, rtol=1e-12)
    np.testing.assert_allclose(total_heat(basis, K.T), np.ones(4), rtol=1e-10)
    # a unit delta diffused spectrally equals the kernel column
    u0 = np.zeros(capsule.n_vertices)
    u0[17] = 1.0 / basis.mass.diagonal()[17]
    np.testing.assert_allclose(diffuse(basis, u0, 0.2), K[:, 1], atol=1e-12)


def test_hks_wks_are_constant_on_a_sphere():
    sphere = shapes.icosphere(4)
    basis = hamsa.eigenbasis(sphere, 36)  # l <= 5 complete
    hks = heat_kernel_signature(basis)
    wks = wave_kernel_signature(basis)
    assert hks.shape == (sphere.n_vertices, 100) and wks.shape == (sphere.n_vertices, 100)
    # complete eigenspaces give rotation-invariant sums (addition theorem), up to the discretization
    assert (hks.std(axis=0) / hks.mean(axis=0)).max() < 0.02
    assert (wks.std(axis=0) / wks.mean(axis=0)).max() < 0.03


def test_automatic_scales_follow_the_formulas():
    basis = hamsa.eigenbasis(shapes.icosphere(3), 30)
    values = basis.values
    times = default_hks_times(basis)
    assert times[0] == pytest.approx(4 * np.log(10) / values.max())
    assert times[-1] == pytest.approx(4 * np.log(10) / values[1])  # lambda_2: the zero mode is skipped
    assert np.allclose(np.diff(np.log(times)), np.log(times[1] / times[0]))
    energies, sigma = default_wks_energies(basis)
    e_min, e_max = np.log(values[1]), np.log(values.max())
    assert sigma == pytest.approx(7 * (e_max - e_min) / 100)
    assert energies[0] == pytest.approx(e_min + 2 * sigma) and energies[-1] == pytest.approx(e_max - 2 * sigma)
    # a Hamiltonian with V > 0 has no zero mode: E_1 sets the longest time
    ham = hamsa.eigenbasis(shapes.icosphere(3), 30, np.full(642, 0.5))
    assert default_hks_times(ham)[-1] == pytest.approx(4 * np.log(10) / ham.values[0])


def _roll(mesh, radius):
    """Roll a flat rectangle onto a cylinder: an isometry of the surface."""
    x, y, _ = mesh.vertices.T
    return hamsa.TriMesh(np.stack([radius * np.sin(x / radius), y, radius * (1 - np.cos(x / radius))], 1), mesh.faces)


def test_signatures_are_invariant_under_isometric_bending():
    flat = shapes.rectangle(2.0, 1.0, 60, 30)
    bent = _roll(flat, 0.8)
    a, b = hamsa.eigenbasis(flat, 40), hamsa.eigenbasis(bent, 40)
    times = default_hks_times(a)
    hks_a, hks_b = heat_kernel_signature(a, times), heat_kernel_signature(b, times)
    assert np.abs(hks_a - hks_b).max() / np.abs(hks_a).max() < 0.02
    energies, sigma = default_wks_energies(a)
    wks_a, wks_b = wave_kernel_signature(a, energies, sigma), wave_kernel_signature(b, energies, sigma)
    assert np.abs(wks_a - wks_b).max() / np.abs(wks_a).max() < 0.05


@pytest.mark.data
def test_hks_nearly_invariant_between_scape_poses():
    meshes = [data_mesh(f"scape/meshes/mesh00{i}.off.gz").scaled_to_unit_area() for i in (0, 1)]
    bases = [hamsa.eigenbasis(m, 50) for m in meshes]
    times = default_hks_times(bases[0], 20)[5:]
    h0, h1 = (heat_kernel_signature(b, times, scaled=True) for b in bases)
    relative = np.abs(h0 - h1) / np.abs(h0)
    # poses differ by a near-isometry; the same-vertex signatures agree to a few percent
    assert np.median(relative) < 0.05
    # and far better than a random pairing of vertices
    shuffled = np.random.default_rng(0).permutation(h1.shape[0])
    assert np.median(np.abs(h0 - h1[shuffled]) / np.abs(h0)) > 4 * np.median(relative)


@pytest.mark.parametrize("t", [0.0, -1.0, np.nan, []])
def test_bad_times_are_refused(t):
    basis = hamsa.eigenbasis(shapes.icosphere(2), 5)
    with pytest.raises(HamsaError, match="times"):
        heat_kernel(basis, t, [0])
