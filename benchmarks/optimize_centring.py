"""Optimizing the potential on raw or on centred coordinates (``optimize_potential(..., center=)``).

A Hamiltonian basis has no constant function, so on raw vertex coordinates the optimizer must spend part of
the basis on the shape's translation; ``center=True`` removes the area-weighted mean first (and adds it back
when X is represented). This prints, per shape (unit area, largest component, X = vertex coordinates, k = 30,
the default m and iterations), the error ratio optimized / LBO of both variants. The LBO error is the same
for both (its constant eigenfunction carries the mean exactly), so the ratios compare reconstruction errors
of X directly. Shapes: the built-in humanoid, and cow, homer and hand_6k from ../shared/data when present.

    OMP_NUM_THREADS=1 python benchmarks/optimize_centring.py [-k 30]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import hamsa
from hamsa import shapes
from hamsa.optimize import optimize_potential

CLASSIC = Path(__file__).resolve().parents[2] / "shared" / "data" / "classic"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-k", type=int, default=30)
    args = parser.parse_args(argv)
    meshes = {"humanoid (built-in)": shapes.humanoid()}
    for name in ("cow.obj", "homer.obj", "hand_6k.off"):
        if (CLASSIC / name).exists():
            meshes[name] = hamsa.load_mesh(CLASSIC / name)
    print(f"k = {args.k}, default m and iterations, hamsa {hamsa.__version__}\n")
    print("| shape | n | raw: optimized / LBO error | centred | seconds raw / centred |")
    print("|---|---|---|---|---|")
    for name, mesh in meshes.items():
        mesh = mesh.largest_component()[0].scaled_to_unit_area()
        ratios, seconds = [], []
        for center in (False, True):
            start = time.perf_counter()
            result = optimize_potential(mesh, mesh.vertices, args.k, center=center)
            seconds.append(time.perf_counter() - start)
            ratios.append(result.loss / result.lbo_loss)
        print(
            f"| {name} | {mesh.n_vertices} | {ratios[0]:.3f} | {ratios[1]:.3f} | {seconds[0]:.0f} / {seconds[1]:.0f} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
