"""Shared plumbing of the experiment scripts: arguments, data lookup, atomic JSON output."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import hamsa
from hamsa.cache import save_record
from hamsa.files import atomic_write
from hamsa.paper.results import to_json


def parse_args(description: str, argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("-o", "--output", default="report", help="folder for the PNG and JSON files")
    parser.add_argument(
        "--data", help="folder laid out like shared/data (TOSCA, SCAPE, classic); default: built-in shapes"
    )
    parser.add_argument("--quick", action="store_true", help="smaller sizes, for a fast check")
    args = parser.parse_args(argv)
    Path(args.output).mkdir(parents=True, exist_ok=True)
    return args


def data_file(data: str | None, relative: str) -> Path | None:
    """The path of a dataset file when a data folder was given and holds it, else None."""
    if not data:
        return None
    path = Path(data) / relative
    return path if path.exists() else None


def dataset_or_builtin(args, relative: str):
    """(mesh, name, from_data): the unit-area dataset mesh when --data holds it and not --quick, else
    the built-in humanoid (rest pose; coarser with --quick), also scaled to unit area."""
    path = data_file(args.data, relative)
    if path and not args.quick:
        return hamsa.load_mesh(path).scaled_to_unit_area(), f"TOSCA {Path(relative).name.split('.')[0]}", True
    return builtin_humanoid(args), "built-in humanoid", False


def builtin_humanoid(args, pose: str = "rest") -> hamsa.TriMesh:
    """The built-in humanoid at unit area: about 2 000 vertices with --quick, 6 300 without."""
    return hamsa.shapes.humanoid(pose, spacing=0.035 if args.quick else 0.02).scaled_to_unit_area()


def write_json(path: Path, numbers) -> None:
    """A result (or plain values) as indented JSON, written atomically."""
    save_record(path, to_json(numbers), indent=2)


class Timer:
    def __init__(self):
        self.start = time.perf_counter()

    def __call__(self) -> float:
        return round(time.perf_counter() - self.start, 2)


def save_figure(figure, path: Path, dpi: int = 110) -> None:
    """Save a matplotlib figure as PNG atomically (a killed run never leaves half an image)."""
    with atomic_write(path, "wb") as handle:
        figure.savefig(handle, format="png", dpi=dpi)


def kim_curve_panel(ax, curves: dict, aucs: dict, title: str, labels: dict | None = None) -> None:
    """One panel of Kim et al. curves: ``curves[basis]`` a list of per-pair curves on THRESHOLDS (averaged),
    LBO dashed and Hamiltonian solid, each labelled with its mean AUC ``aucs[basis]``."""
    from hamsa.evaluation import THRESHOLDS

    for basis, style in (("lbo", "--"), ("hamiltonian", "-")):
        label = (labels or {}).get(basis, basis)
        ax.plot(THRESHOLDS, np.mean(curves[basis], axis=0), style, label=f"{label} (AUC {aucs[basis]:.3f})")
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("geodesic error / sqrt(area)")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)


def print_method_scores(figure: str, result, hamiltonian: str = "Hamiltonian") -> None:
    """One line per matching method of a MatchingResult or TextureResult: AUC and mean error, LBO vs
    Hamiltonian."""
    for method, scores in result.methods.items():
        lbo, ham = scores.lbo, scores.hamiltonian
        print(
            f"{figure} {method} ({result.dataset}): AUC LBO {lbo.auc:.3f} vs {hamiltonian} {ham.auc:.3f}; "
            f"mean error {lbo.mean_error:.4f} vs {ham.mean_error:.4f}"
        )
