"""The paper's figure scripts run (quick mode, built-in shapes) and their numbers say what the paper says."""

import importlib.util
import json
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from conftest import require_rendering

pytest.importorskip("matplotlib", reason="the figures need the [viz] extra: pip install 'hamsa[viz]'")


@pytest.fixture(autouse=True)
def _rendering():
    require_rendering()


EXPERIMENTS = Path(__file__).resolve().parents[1] / "experiments"


def run_experiment(name, tmp_path):
    sys.path.insert(0, str(EXPERIMENTS))
    spec = importlib.util.spec_from_file_location(name, EXPERIMENTS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    numbers = module.run(SimpleNamespace(output=str(tmp_path), data=None, quick=True))
    png = tmp_path / f"{name}.png"
    assert png.stat().st_size > 10_000
    assert json.loads((tmp_path / f"{name}.json").read_text())
    return numbers


def test_fig1_matches_analytic_spectra(tmp_path):
    numbers = run_experiment("fig1_harmonics_1d", tmp_path)
    assert max(numbers["box"]["relative_error"]) < 5e-4  # O(h^2) on the 400-point quick grid
    assert max(numbers["oscillator"]["relative_error"]) < 1e-3
    assert max(numbers["step"]["relative_error"]) < 1e-2  # the discontinuous V costs accuracy


def test_fig2_step_traps_modes(tmp_path):
    numbers = run_experiment("fig2_step_potential", tmp_path)
    assert numbers["theorem1_holds"] and numbers["trapped_mean_mass"] > 0.9


def test_fig3_hamiltonian_heat_moves_towards_low_potential(tmp_path):
    numbers = run_experiment("fig3_diffusion", tmp_path)
    last = [row for row in numbers["rows"] if row["t"] == numbers["times"][-1]]
    assert last[1]["mean_distance_to_leg"] < last[0]["mean_distance_to_leg"]
    lbo_heat = [row["total_heat"] for row in numbers["rows"] if row["operator"] == "LBO"]
    np.testing.assert_allclose(lbo_heat, 1.0, rtol=1e-8)  # the LBO conserves heat; H absorbs it


def test_fig4_courant(tmp_path):
    numbers = run_experiment("fig4_nodal", tmp_path)
    assert all(op["courant_holds"] for op in numbers["operators"].values())


def test_fig5_noise(tmp_path):
    numbers = run_experiment("fig5_noise", tmp_path)
    assert numbers["cases"]["potential noise"]["hamiltonian_mean_first5"] > 0.95
    assert numbers["cases"]["vertex noise"]["hamiltonian_mean_first5"] > 0.9


def test_fig6_optimized_potential_beats_the_lbo(tmp_path):
    numbers = run_experiment("fig6_optimize_1d", tmp_path)
    assert numbers["parametrizations"]["signed"]["ratio"] > 10
    assert numbers["parametrizations"]["square"]["ratio"] > 3


def test_fig7_hand_like_reconstruction(tmp_path):
    numbers = run_experiment("fig7_optimize_hand", tmp_path)
    assert numbers["ratio"] > 1.5  # built-in capsule in quick mode; the hand itself is in test_optimize
    assert (tmp_path / "fig7_potential.png").stat().st_size > 10_000


def test_fig8_rate_distortion_runs(tmp_path):
    numbers = run_experiment("fig8_compression", tmp_path)
    rows = numbers["rows"]
    assert {r["method"] for r in rows} == {"mhb", "hamiltonian", "hamiltonian-opt"}
    mhb = sorted((r["bpv"], r["rms_error"]) for r in rows if r["method"] == "mhb")
    assert all(b[1] < a[1] for a, b in zip(mhb, mhb[1:]))  # more bits per vertex, less error


def test_fig9_compressed_modes_runs(tmp_path):
    numbers = run_experiment("fig9_cmm", tmp_path)
    assert all(row["orthogonality_error"] < 1e-6 for row in numbers["rows"])
    assert (tmp_path / "fig9_cmm_runtime.png").stat().st_size > 10_000
    for ratio in numbers["ratios"].values():
        assert 0.8 < ratio["objective_hamiltonian_over_admm"] < 1.2  # same objective, similar optima
