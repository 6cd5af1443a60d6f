"""Paper section 4: compressed manifold modes, Hamiltonian IRLS vs Neumann et al.'s ADMM.

Both methods minimize the same area-weighted objective and stop at the same 1e-6 relative change of
it. For meshes of several sizes (built-in capsules; with --data also the 6k and 14k hands) and K modes,
the wall time of each method (mean and std over --repeat runs, default 2) and both objectives; and a
render of the first IRLS modes, which should show compact supports. Writes fig9_cmm.png (the modes),
fig9_cmm_runtime.png and fig9_cmm.json.
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

from ._common import Timer, data_file, parse_args, save_figure, unit_area, write_json


def run(args) -> dict:
    timer = Timer()
    meshes = [("capsule", unit_area(shapes.capsule(0.5, 3.0, n))) for n in ((16, 24) if args.quick else (24, 40, 64))]
    for name in () if args.quick else ("hand_6k.off", "hand_14k.off"):
        path = data_file(args.data, f"classic/{name}")
        if path:
            meshes.append((name.split(".")[0], unit_area(hamsa.load_mesh(path))))
    K, mu = (4, 100.0) if args.quick else (10, 100.0)
    repeat = 1 if args.quick else 2
    rows = []
    for name, mesh in meshes:
        for method in ("hamiltonian", "admm"):
            times, result = [], None
            for _ in range(repeat):
                start = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    result = compressed_modes(mesh, K, mu, method=method)
                times.append(time.perf_counter() - start)
            rows.append(
                {
                    "mesh": name,
                    "n_vertices": mesh.n_vertices,
                    "K": K,
                    "mu": mu,
                    "method": method,
                    "seconds_mean": float(np.mean(times)),
                    "seconds_std": float(np.std(times)),
                    "objective": result.objective,
                    "orthogonality_error": result.orthogonality_error,
                }
            )
            if method == "hamiltonian":
                shown_mesh, shown = mesh, result
    figure, axis = plt.subplots(figsize=(6, 4))
    families = sorted({r["mesh"].split("_")[0] for r in rows})  # capsules of several sizes; the hands
    for method, color in (("hamiltonian", "tab:blue"), ("admm", "tab:orange")):
        for family, marker in zip(families, "os^"):
            mine = [r for r in rows if r["method"] == method and r["mesh"].split("_")[0] == family]
            axis.errorbar(
                [r["n_vertices"] for r in mine],
                [r["seconds_mean"] for r in mine],
                yerr=[r["seconds_std"] for r in mine],
                fmt=marker + "-",
                color=color,
                capsize=3,
                label=f"{method} ({family})",
            )
    axis.set_xscale("log")
    axis.set_yscale("log")
    axis.set_xlabel("vertices")
    axis.set_ylabel(f"seconds (K = {K}, mu = {mu:g})")
    axis.legend()
    axis.grid(True, which="both", alpha=0.3)
    figure.tight_layout()
    save_figure(figure, Path(args.output) / "fig9_cmm_runtime.png")
    plt.close(figure)
    count = min(5, K)
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
        by = {r["method"]: r for r in rows if r["mesh"] == name and r["n_vertices"] == mesh.n_vertices}
        ratios[f"{name}-{mesh.n_vertices}"] = {
            "time_admm_over_hamiltonian": by["admm"]["seconds_mean"] / by["hamiltonian"]["seconds_mean"],
            "objective_hamiltonian_over_admm": by["hamiltonian"]["objective"] / by["admm"]["objective"],
        }
    numbers = {"rows": rows, "ratios": ratios, "seconds": timer()}
    write_json(Path(args.output) / "fig9_cmm.json", numbers)
    return numbers


if __name__ == "__main__":
    r = run(parse_args(__doc__))
    for key, value in r["ratios"].items():
        print(
            f"fig9 {key}: time admm / hamiltonian {value['time_admm_over_hamiltonian']:.2f}, "
            f"objective hamiltonian / admm {value['objective_hamiltonian_over_admm']:.3f}"
        )
