"""Fig. 1: harmonics on an interval under three potentials, against their analytic solutions.

(a) the box (V = 0, psi = 0 at the walls): E_n = (n pi / L)^2, psi_n ~ sin(n pi x / L);
(b) a finite step well inside the box (V = V0 outside |x - L/2| < a): E_n from the even/odd matching
    conditions, solved by bracketing (pole-free forms, continuous through E = V0);
(c) the harmonic oscillator V = w^2 (x - L/2)^2: E_n = (2n + 1) w, psi_n = Hermite functions.
Writes fig1_harmonics_1d.png and fig1_harmonics_1d.json (numeric vs analytic eigenvalues).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import scipy.sparse as sp
from scipy.optimize import brentq
from scipy.special import eval_hermite, factorial

from hamsa.eigen import generalized_eigsh
from hamsa.interval import interval_operators
from hamsa.paper.results import HarmonicsResult, Spectrum1D

from ._common import Timer, parse_args, save_figure, write_json

LENGTH = 1.0


def finite_well_levels(depth: float, half_width: float, count: int) -> np.ndarray:
    """Eigenvalues of -psi'' + V psi in a box [0, 1] with V = depth outside |x - 1/2| < half_width."""
    wall = 0.5 - half_width

    def parts(E):
        k = np.sqrt(E)
        kappa = np.sqrt(np.abs(depth - E))
        safe = np.where(kappa > 0, kappa, 1.0)
        below = np.asarray(E) < depth
        S = np.where(kappa > 0, np.where(below, np.sinh(kappa * wall), np.sin(kappa * wall)) / safe, wall)
        C = np.where(below, np.cosh(kappa * wall), np.cos(kappa * wall))
        return k, S, C

    def even(E):
        k, S, C = parts(E)
        return k * np.sin(k * half_width) * S - np.cos(k * half_width) * C

    def odd(E):
        k, S, C = parts(E)
        return k * np.cos(k * half_width) * S + np.sin(k * half_width) * C

    grid = np.linspace(1e-6, 60 * (count + 2) ** 2, 200000)
    roots = []
    for function in (even, odd):
        values = function(grid)
        for i in np.flatnonzero(np.sign(values[:-1]) != np.sign(values[1:])):
            roots.append(brentq(lambda E: float(function(E)), grid[i], grid[i + 1], xtol=1e-13))
    return np.sort(roots)[:count]


def oscillator_function(n: int, y: np.ndarray, omega: float) -> np.ndarray:
    s = np.sqrt(omega) * y
    return eval_hermite(n, s) * np.exp(-(s**2) / 2) / np.sqrt(2.0**n * factorial(n) * np.sqrt(np.pi / omega))


def solve(V: np.ndarray, W, A, count: int):
    """The first ``count`` eigenpairs of (W + A diag(V)) psi = E A psi on the interval."""
    values, vectors, _ = generalized_eigsh(W + sp.diags(A.diagonal() * V), A, count, lower_bound=float(V.min()))
    return values, vectors


def run(args) -> HarmonicsResult:
    timer = Timer()
    n = 400 if args.quick else 2000
    count = 6
    W, A, x = interval_operators(n, LENGTH, "dirichlet")
    cases = {}
    # (a) box
    values, vectors = solve(np.zeros_like(x), W, A, count)
    exact = (np.arange(1, count + 1) * np.pi / LENGTH) ** 2
    cases["box"] = dict(
        V=np.zeros_like(x),
        values=values,
        vectors=vectors,
        exact=exact,
        exact_vectors=[np.sqrt(2 / LENGTH) * np.sin((i + 1) * np.pi * x / LENGTH) for i in range(count)],
    )
    # (b) finite step well
    depth, half_width = 400.0, 0.2
    V = np.where(np.abs(x - 0.5) < half_width, 0.0, depth)
    values, vectors = solve(V, W, A, count)
    cases["step"] = dict(V=V, values=values, vectors=vectors, exact=finite_well_levels(depth, half_width, count))
    # (c) harmonic oscillator
    omega = 150.0
    V = omega**2 * (x - 0.5) ** 2
    values, vectors = solve(V, W, A, count)
    cases["oscillator"] = dict(
        V=V,
        values=values,
        vectors=vectors,
        exact=(2 * np.arange(count) + 1) * omega,
        exact_vectors=[oscillator_function(i, x - 0.5, omega) for i in range(count)],
    )

    figure, axes = plt.subplots(1, 3, figsize=(13, 4.2))
    titles = {
        "box": "box (V = 0, walls)",
        "step": f"finite step (V0 = {depth:g})",
        "oscillator": f"oscillator (w = {omega:g})",
    }
    spectra = {}
    for axis, (name, case) in zip(axes, cases.items()):
        scale = 0.35 * (case["values"][1] - case["values"][0])
        axis.plot(x, np.minimum(case["V"], case["values"][-1] * 1.3), color="0.6", lw=2, label="V")
        for i in range(count):
            psi = case["vectors"][:, i]
            psi = psi * np.sign(psi[np.argmax(np.abs(psi) > 1e-3 * np.abs(psi).max())])
            axis.plot(x, case["values"][i] + scale * psi / np.abs(psi).max(), lw=1.5)
            if "exact_vectors" in case:
                ref = case["exact_vectors"][i]
                ref = ref * np.sign(ref[np.argmax(np.abs(ref) > 1e-3 * np.abs(ref).max())])
                axis.plot(
                    x[:: max(1, n // 40)],
                    (case["exact"][i] + scale * ref / np.abs(ref).max())[:: max(1, n // 40)],
                    "k.",
                    ms=3,
                )
            axis.axhline(case["exact"][i], color="k", lw=0.5, ls=":")
        axis.set_title(titles[name])
        axis.set_xlabel("x")
        axis.set_ylabel("E  (psi offset by its eigenvalue)")
        errors = np.abs(case["values"] - case["exact"]) / case["exact"]
        spectra[name] = Spectrum1D(numeric=case["values"], analytic=case["exact"], relative_error=errors)
    figure.suptitle("Fig. 1 - 1-D harmonics: FEM (lines) vs analytic (dots; dotted lines = analytic E_n)")
    figure.tight_layout()
    png = Path(args.output) / "fig1_harmonics_1d.png"
    save_figure(figure, png)
    plt.close(figure)
    result = HarmonicsResult(
        grid_points=n,
        **spectra,
        max_relative_error=max(float(np.max(s.relative_error)) for s in spectra.values()),
        seconds=timer(),
    )
    write_json(Path(args.output) / "fig1_harmonics_1d.json", result)
    return result


if __name__ == "__main__":
    result = run(parse_args(__doc__))
    print(f"fig1: max relative eigenvalue error vs analytic {result.max_relative_error:.2e} ({result.seconds} s)")
