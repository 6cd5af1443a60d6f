import numpy as np
import pytest

import hamsa
from hamsa import shapes
from hamsa.operators import hamiltonian
from hamsa.theory import critical_potential_scale, eigenvalue_bounds, mass_fraction

from conftest import data_mesh


@pytest.fixture(scope="module")
def scape():
    mesh = data_mesh("scape/meshes/mesh000.off.gz")
    return mesh.scaled_to_unit_area()


@pytest.mark.data
def test_theorem_1_and_residual_bound_on_a_real_mesh(scape):
    rng = np.random.default_rng(0)
    lbo = hamsa.eigenbasis(scape, 30)
    V = rng.random(scape.n_vertices) * 200
    basis = hamsa.eigenbasis(scape, 31, V)
    lower, upper = eigenvalue_bounds(lbo.values, V)
    tol = 1e-8 * np.abs(basis.values).max()
    assert np.all(lower - tol <= basis.values[:30]) and np.all(basis.values[:30] <= upper + tol)
    H, A = hamiltonian(scape, V)
    for n in (5, 10, 20, 30):
        part = basis.truncate(n)
        f = rng.standard_normal(scape.n_vertices)
        error = f - part.reconstruct(part.project(f))
        assert error @ A @ error <= (f @ H @ f) / basis.values[n] * (1 + 1e-10)


def _check_mu_rule(mesh, V):
    lbo = hamsa.eigenbasis(mesh, 6)
    i = 1  # the first non-constant mode (simple on these shapes)
    expectation = lbo.vectors[:, i] @ (lbo.mass @ (V * lbo.vectors[:, i]))
    errors = []
    for mu in (0.4, 0.2, 0.1):
        E = hamsa.eigenbasis(mesh, 6, mu * V).values[i]
        errors.append(abs(E - (lbo.values[i] + mu * expectation)))
    assert 3.0 < errors[0] / errors[1] < 5.0 and 3.0 < errors[1] / errors[2] < 5.0  # quadratic
    bound = critical_potential_scale(lbo, V, i)
    mu = 0.5 * bound
    assert hamsa.eigenbasis(mesh, 6, mu * V).values[i] > mu * V.max()


def test_mu_rule_first_order():
    """T2: E_i(mu) = lambda_i + mu <phi_i, V phi_i> + O(mu^2), and mu = bound/2 keeps E_i > mu max V."""
    mesh = shapes.capsule(radius=0.5, length=2.0, n_around=32)
    _check_mu_rule(mesh, np.exp(-((mesh.vertices[:, 2] - 0.8) ** 2) / 0.1))  # a bump near one end, max 1


@pytest.mark.data
def test_mu_rule_on_a_real_mesh_with_a_random_potential(scape):
    V = np.random.default_rng(1).random(scape.n_vertices)  # random, max about 1
    _check_mu_rule(scape, V)


def test_high_step_traps_low_modes():
    """T7: with V0 >= 10 lambda_k, modes with E <= V0/2 keep >= 95% inside; the first above V0 leaks more."""
    mesh = shapes.capsule(radius=0.5, length=3.0, n_around=40)
    inside = mesh.vertices[:, 2] < 0.0
    k = 40
    lbo = hamsa.eigenbasis(mesh, 8)
    V0 = 10 * lbo.values[7]
    basis = hamsa.eigenbasis(mesh, k, np.where(inside, 0.0, V0))
    fraction = mass_fraction(basis, inside)
    low = basis.values <= V0 / 2
    assert low.sum() >= 3 and fraction[low].min() >= 0.95
    above = np.flatnonzero(basis.values > V0)
    assert above.size, "increase k: no mode above the step"
    assert 1 - fraction[above[0]] > 3 * (1 - fraction[low]).max()
