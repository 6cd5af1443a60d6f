import numpy as np

from hamsa.paper.demo import step_potential_demo


def test_step_potential_traps_low_modes_and_respects_theorem_1():
    result = step_potential_demo(k=12)
    tol = 1e-9 * np.abs(result.upper_bounds).max()
    assert np.all(result.lower_bounds - tol <= result.values) and np.all(result.values <= result.upper_bounds + tol)
    below = result.values < result.height
    assert below.sum() >= 2 and (~below).sum() >= 2
    # trapped modes keep most of their mass where V = 0 (paper Fig. 2, NOTES T7); the LBO's do not
    assert result.inside[below].min() > 0.85
    assert result.inside[below].mean() > result.inside[~below].mean() + 0.2
    assert result.lbo_inside[below].mean() < 0.7
