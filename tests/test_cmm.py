import numpy as np
import pytest
import scipy.sparse as sp

import hamsa
from hamsa import HamsaError, shapes
from hamsa.cmm import WoodburyInverse, compressed_modes
from hamsa.factorization import CholeskySolver
from hamsa.operators import hamiltonian


@pytest.fixture(scope="module")
def capsule():
    mesh = shapes.capsule(0.5, 3.0, 32)
    return mesh.scaled_to_unit_area()


def test_woodbury_equals_a_dense_inverse(capsule):
    W, A = hamiltonian(capsule)
    rng = np.random.default_rng(0)
    H = (W + sp.diags(A.diagonal() * (1 + rng.random(capsule.n_vertices)))).tocsc()
    U = rng.standard_normal((capsule.n_vertices, 5)) * 3
    operator = WoodburyInverse(CholeskySolver(H), U)
    x = rng.standard_normal((capsule.n_vertices, 3))
    dense = np.linalg.solve(H.toarray() + U @ U.T, x)
    assert np.abs(operator.solve(x) - dense).max() <= 1e-10 * np.abs(dense).max()


@pytest.fixture(scope="module")
def modes(capsule):
    return compressed_modes(capsule, 5, 100.0)


def _support90(areas, phi):
    """The smallest area holding 90% of a function's A-mass."""
    weight = areas * phi**2
    order = np.argsort(-weight)
    return areas[order][: np.searchsorted(np.cumsum(weight[order]) / weight.sum(), 0.9) + 1].sum()


def test_modes_are_orthonormal_and_localized(capsule, modes):
    assert modes.orthogonality_error < 1e-6
    areas = hamsa.mass_matrix(capsule).diagonal()
    compressed = [_support90(areas, modes.modes[:, i]) for i in range(5)]
    lbo = hamsa.eigenbasis(capsule, 5)
    harmonics = [_support90(areas, lbo.vectors[:, i]) for i in range(5)]
    assert max(compressed) < 0.45 < min(harmonics)  # the capsule has unit area


def test_each_irls_step_never_increases_the_majorized_objective(modes):
    for mode in modes.history:
        for before, after in mode["majorized"]:
            assert after <= before * (1 + 1e-9) + 1e-12


def test_mu_zero_recovers_the_lbo_subspace(capsule):
    k = 6  # the capsule's spectrum has a pair at 5/6: take whole clusters
    result = compressed_modes(capsule, k, 0.0)
    lbo = hamsa.eigenbasis(capsule, k)
    areas = lbo.mass.diagonal()
    cosines = np.linalg.svd(lbo.vectors.T @ (areas[:, None] * result.modes), compute_uv=False)
    assert cosines.min() > 1 - 1e-6
    np.testing.assert_allclose(result.objective, lbo.values.sum(), rtol=1e-6)


def test_bad_requests(capsule):
    with pytest.raises(HamsaError, match="k = 0"):
        compressed_modes(capsule, 0, 1.0)
    with pytest.raises(HamsaError, match="mu"):
        compressed_modes(capsule, 3, -1.0)
    with pytest.raises(HamsaError, match="method"):
        compressed_modes(capsule, 3, 1.0, method="simulated-annealing")


def test_admm_and_hamiltonian_reach_similar_objectives(capsule):
    greedy = compressed_modes(capsule, 4, 20.0, method="hamiltonian", refine=False)
    hamiltonian_modes = compressed_modes(capsule, 4, 20.0, method="hamiltonian")
    admm_modes = compressed_modes(capsule, 4, 20.0, method="admm")
    assert admm_modes.orthogonality_error < 1e-6 and hamiltonian_modes.orthogonality_error < 1e-6
    # the joint refinement (pair rotations + one more IRLS pass) only lowers the objective
    assert hamiltonian_modes.objective <= greedy.objective * (1 + 1e-9)
    # issue 5's bar: at most 5% above ADMM's objective (measured here: 10% below it, 149.1 vs 166.2;
    # greedy alone 157.7), and both solve the same problem (within 15% of each other)
    assert hamiltonian_modes.objective <= 1.05 * admm_modes.objective
    assert abs(hamiltonian_modes.objective - admm_modes.objective) <= 0.15 * admm_modes.objective


def test_cli_modes(tmp_path, capsule, capsys):
    from hamsa.cli import main

    path = tmp_path / "capsule.off"
    hamsa.save_mesh(capsule, path)
    assert main(["modes", str(path), "-k", "3", "--mu", "50", "-o", str(tmp_path / "modes.npz")]) == 0
    saved = np.load(tmp_path / "modes.npz")
    assert saved["modes"].shape == (capsule.n_vertices, 3)
    progress = capsys.readouterr().err  # one line per mode in each pass
    assert progress.count("  mode ") == 3 and progress.count("refining mode") == 3
    admm = ["modes", str(path), "-k", "2", "--mu", "50", "--method", "admm", "-o", str(tmp_path / "admm.npz")]
    assert main(admm) == 0
    progress = capsys.readouterr().err  # every 100th ADMM iteration, not one line per iteration
    assert "mode 0/" not in progress and 0 < len(progress.splitlines()) <= 101
    assert main(["modes", str(path), "-k", "3", "--mu", "-5", "-o", str(tmp_path / "bad.npz")]) == 2
    assert not (tmp_path / "bad.npz").exists()
