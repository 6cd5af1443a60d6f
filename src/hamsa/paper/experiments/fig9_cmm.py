"""Paper section 4: compressed manifold modes, Hamiltonian IRLS vs Neumann et al.'s ADMM.

Both methods minimize the same area-weighted objective and stop at the same 1e-6 relative change of
it. For meshes of several sizes (built-in capsules; with --data also the 6k and 14k hands) and K modes,
the wall time of each method (mean and std over --repeat runs, default 2) and both objectives; and a
render of the first IRLS modes, which should show compact supports. Full runs: K in {10, 20, 40} on the
capsules (mean ± std of 2 runs) and K = 20 on the hands. Discretization robustness (claim T17): the modes
of a capsule and of the same surface refined on one half agree when the L1 norm is the consistent,
area-weighted one, and not with the plain vector norm of Neumann et al.'s code. Writes fig9_cmm.png (the
modes), fig9_cmm_runtime.png, fig9_cmm_discretization.png and fig9_cmm.json.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import hamsa
from hamsa import shapes, viz
from hamsa.cmm import compressed_modes
from hamsa.noise import refine_region
from hamsa.paper.results import ModesAgreement, ModesRatio, ModesResult, ModesRun

from ._common import Timer, data_file, parse_args, save_figure, write_json


def run(args) -> ModesResult:
    timer = Timer()
    meshes = [
        ("capsule", shapes.capsule(0.5, 3.0, n).scaled_to_unit_area())
        for n in ((16, 24) if args.quick else (24, 40, 64))
    ]
    counts = {"capsule": (4,) if args.quick else (10, 20, 40)}
    for name in () if args.quick else ("hand_6k.off", "hand_14k.off"):
        path = data_file(args.data, f"classic/{name}")
        if path:
            meshes.append((name.split(".")[0], hamsa.load_mesh(path).scaled_to_unit_area()))
            counts[name.split(".")[0]] = (20,)
    mu = 100.0
    repeat = 1 if args.quick else 2
    rows = []
    for name, mesh in meshes:
        for K in counts[name]:
            for method in ("hamiltonian", "admm"):
                times, result = [], None
                for _ in range(repeat if name == "capsule" else 1):
                    start = time.perf_counter()
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        result = compressed_modes(mesh, K, mu, method=method)
                    times.append(time.perf_counter() - start)
                rows.append(
                    ModesRun(
                        mesh=name,
                        n_vertices=mesh.n_vertices,
                        K=K,
                        mu=mu,
                        method=method,
                        seconds_mean=float(np.mean(times)),
                        seconds_std=float(np.std(times)),
                        runs=len(times),
                        objective=result.objective,
                        orthogonality_error=result.orthogonality_error,
                    )
                )
                if method == "hamiltonian" and K == counts[name][0]:
                    shown_mesh, shown = mesh, result
    _plot_runtime(Path(args.output) / "fig9_cmm_runtime.png", rows, mu)
    count = min(5, shown.modes.shape[1])
    viz.render_fields(
        shown_mesh,
        [shown.modes[:, i] for i in range(count)],
        Path(args.output) / "fig9_cmm.png",
        titles=[f"mode {i + 1}" for i in range(count)],
        cmap="RdBu_r",
        symmetric=True,
        panel_size=(280, 300),
    )
    ratios = {}
    for name, mesh in meshes:
        for K in counts[name]:
            by = {r.method: r for r in rows if r.mesh == name and r.n_vertices == mesh.n_vertices and r.K == K}
            ratios[f"{name}-{mesh.n_vertices}-K{K}"] = ModesRatio(
                time_admm_over_hamiltonian=by["admm"].seconds_mean / by["hamiltonian"].seconds_mean,
                objective_hamiltonian_over_admm=by["hamiltonian"].objective / by["admm"].objective,
            )
    discretization = _discretization(args, Path(args.output) / "fig9_cmm_discretization.png")
    result = ModesResult(rows=rows, ratios=ratios, discretization=discretization, seconds=timer())
    write_json(Path(args.output) / "fig9_cmm.json", result)
    return result


def _plot_runtime(path, rows, mu):
    figure, axis = plt.subplots(figsize=(6.4, 4.2))
    groups = sorted({(r.mesh.split("_")[0], r.K) for r in rows})
    for method, color in (("hamiltonian", "tab:blue"), ("admm", "tab:orange")):
        for (family, K), marker in zip(groups, "os^Dv<>"):
            mine = [r for r in rows if r.method == method and r.mesh.split("_")[0] == family and r.K == K]
            axis.errorbar(
                [r.n_vertices for r in mine],
                [r.seconds_mean for r in mine],
                yerr=[r.seconds_std for r in mine],
                fmt=marker + ("-" if method == "hamiltonian" else "--"),
                color=color,
                capsize=3,
                label=f"{'IRLS' if method == 'hamiltonian' else 'ADMM'} {family} K={K}",
            )
    axis.set_xscale("log")
    axis.set_yscale("log")
    axis.set_xlabel("vertices")
    axis.set_ylabel(f"seconds (mu = {mu:g}, mean ± std)")
    axis.legend(fontsize=7, ncol=2)
    axis.grid(True, which="both", alpha=0.3)
    figure.tight_layout()
    save_figure(figure, path)
    plt.close(figure)


def _discretization(args, path) -> ModesAgreement:
    """Modes of a capsule and of the same surface refined on its x > 0 half (:func:`hamsa.noise.refine_region`):
    for each mode of the first, the largest |<phi, phi'>_A| with a mode of the second (on the shared
    vertices), for the consistent (area-weighted) and the plain vector L1 norm, both methods."""
    mesh = shapes.capsule(0.5, 3.0, 20 if args.quick else 28).scaled_to_unit_area()
    refined = refine_region(mesh, mesh.vertices[mesh.faces].mean(axis=1)[:, 0] > 0)
    areas = hamsa.mass_matrix(mesh).diagonal()
    K, mu = (4, 20.0) if args.quick else (6, 20.0)
    agreement = {}
    for method in ("hamiltonian", "admm"):
        for l1 in ("area", "vector"):
            strength = mu if l1 == "area" else mu * areas.mean()  # the same penalty for a typical vertex
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                first = compressed_modes(mesh, K, strength, method=method, l1=l1).modes
                second = compressed_modes(refined, K, strength, method=method, l1=l1).modes[: mesh.n_vertices]
            overlap = np.abs(first.T @ (areas[:, None] * second))
            agreement[f"{method}/{l1}"] = float(overlap.max(axis=1).mean())
    figure, axis = plt.subplots(figsize=(5.6, 3.4))
    labels = list(agreement)
    axis.bar(
        range(len(labels)), [agreement[k] for k in labels], color=["tab:blue", "tab:cyan", "tab:orange", "tab:red"]
    )
    axis.set_xticks(range(len(labels)), [k.replace("hamiltonian", "IRLS").replace("admm", "ADMM") for k in labels])
    axis.set_ylim(0, 1.05)
    axis.set_ylabel("mean best |<phi, phi'>_A|")
    axis.set_title(
        f"modes of a capsule vs the same surface refined on one half\n({mesh.n_vertices} vs "
        f"{refined.n_vertices} vertices, K = {K}; 1 = the same modes)",
        fontsize=9,
    )
    figure.tight_layout()
    save_figure(figure, path)
    plt.close(figure)
    return ModesAgreement(n_vertices=[mesh.n_vertices, refined.n_vertices], K=K, mu=mu, agreement=agreement)


if __name__ == "__main__":
    r = run(parse_args(__doc__))
    for key, value in r.ratios.items():
        print(
            f"fig9 {key}: time admm / hamiltonian {value.time_admm_over_hamiltonian:.2f}, "
            f"objective hamiltonian / admm {value.objective_hamiltonian_over_admm:.3f}"
        )
