"""Dirichlet boundary conditions: analytic spectra with their FEM convergence rate, and the particle in a box."""

import numpy as np
import pytest
from scipy.special import jn_zeros

import hamsa
from hamsa.errors import HamsaError
from hamsa.operators import dirichlet_vertices

SQUARE = np.pi**2 * np.array([2, 5, 5, 8, 10, 10])  # pi^2 (i^2 + j^2), i, j >= 1
DISK = np.sort(np.concatenate([jn_zeros(0, 2), *[jn_zeros(1, 2)] * 2, *[jn_zeros(2, 1)] * 2]) ** 2)[:6]


def _errors(meshes, exact):
    values = [hamsa.eigenbasis(m, len(exact), boundary="dirichlet").values for m in meshes]
    return [np.max(np.abs(v - exact) / exact) for v in values]


@pytest.mark.parametrize(
    "name, meshes, exact",
    [
        ("square", [hamsa.shapes.rectangle(1, 1, n, n) for n in (10, 20, 40)], SQUARE),
        ("disk", [hamsa.shapes.disk(rings=r) for r in (8, 16, 32)], DISK),
    ],
)
def test_dirichlet_eigenvalues_converge_to_the_analytic_ones_at_second_order(name, meshes, exact):
    errors = _errors(meshes, exact)
    assert errors[-1] < 5e-3, errors
    rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))  # halving h: error / 4 for P1 eigenvalues
    assert np.all(rates > 1.8), (name, errors, rates)


def test_dirichlet_eigenvectors_vanish_on_the_boundary_and_are_mass_orthonormal():
    mesh = hamsa.shapes.disk(rings=10)
    basis = hamsa.eigenbasis(mesh, 5, boundary="dirichlet", method="krylov")
    fixed = np.unique(mesh.boundary_edges)
    assert len(fixed) == 60 and np.all(basis.vectors[fixed] == 0)
    np.testing.assert_allclose(basis.vectors.T @ basis.mass @ basis.vectors, np.eye(5), atol=1e-8)
    H, A = hamsa.hamiltonian(mesh)
    residual = H @ basis.vectors - A @ basis.vectors * basis.values
    free = np.setdiff1d(np.arange(mesh.n_vertices), fixed)
    assert np.abs(residual[free]).max() < 1e-7  # the equations hold at every free vertex


@pytest.mark.parametrize("method", ["dense", "krylov", "chebyshev"])
def test_every_solver_path_gives_the_same_dirichlet_spectrum(method):
    mesh = hamsa.shapes.rectangle(1, 1, 24, 24)
    reference = hamsa.eigenbasis(mesh, 6, boundary="dirichlet", method="dense").values
    values = hamsa.eigenbasis(mesh, 6, boundary="dirichlet", method=method).values
    np.testing.assert_allclose(values, reference, rtol=1e-7)


def test_a_wall_of_growing_height_turns_into_a_dirichlet_condition():
    """The particle in a box (paper Fig. 2): V0 on a region makes the low eigenvalues converge, from below and
    monotonically, to the Dirichlet eigenvalues of the rest of the surface (restriction = the limit V0 -> inf)."""
    mesh = hamsa.shapes.humanoid().scaled_to_unit_area()
    height = mesh.vertices[:, 2]
    region = height > np.quantile(height, 0.7)  # the head and shoulders
    dirichlet = hamsa.eigenbasis(mesh, 8, boundary=np.flatnonzero(region)).values
    gaps = []
    for V0 in (1e2, 1e3, 1e4, 1e5):
        values = hamsa.eigenbasis(mesh, 8, hamsa.potentials.step(mesh, region, V0)).values
        assert np.all(values <= dirichlet + 1e-8 * dirichlet)  # min-max: the wall only adds energy
        gaps.append(np.max(dirichlet - values))
    assert np.all(np.diff(gaps) < 0), gaps
    assert gaps[-1] < 0.02 * dirichlet[-1] and gaps[0] > 10 * gaps[-1], gaps


def test_boundary_arguments_are_checked():
    mesh = hamsa.shapes.rectangle(1, 1, 4, 4)
    assert dirichlet_vertices(mesh, "neumann").size == 0
    assert dirichlet_vertices(mesh, [3, 3, 1]).tolist() == [1, 3]
    assert dirichlet_vertices(hamsa.shapes.icosphere(1), "dirichlet").size == 0  # closed: no boundary
    with pytest.raises(HamsaError, match="boundary must be"):
        dirichlet_vertices(mesh, "robin")
    with pytest.raises(HamsaError, match=r"in \[0, 25\)"):
        dirichlet_vertices(mesh, [0, 25])
    with pytest.raises(HamsaError, match="integer ids"):
        dirichlet_vertices(mesh, [0.5])
    with pytest.raises(HamsaError, match="every vertex"):
        hamsa.eigenbasis(mesh, 1, boundary=np.arange(25))
    with pytest.raises(hamsa.SolverError, match="between 1 and"):
        hamsa.eigenbasis(mesh, 10, boundary="dirichlet")  # 9 interior vertices
