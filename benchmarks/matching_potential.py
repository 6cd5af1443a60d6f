"""The matching potential's scale mu and its sign resolution, on SCAPE pairs (paper §5, NOTES T14).

The paper's HKS/WKS potential is V = mu x (normalized sum of phi_2..phi_5, scaled to [0, 1]) with the
eigenfunction signs made consistent across the two shapes; it gives neither mu nor how the signs are
found. For mesh000 against a few other SCAPE poses (unit area, k = 100, 1000 sampled vertices, Kim et al.
errors without symmetries) this prints the HKS nearest-neighbour AUC on [0, 0.25] for the LBO and for
the Hamiltonian at each mu (signs from the ground truth), then at mu = 1 with signs found without the
ground truth (:func:`hamsa.matching.resolve_signs_without_truth`: intrinsic moments and the surfaces'
orientation), and how often those signs agree with the true ones.

    python benchmarks/matching_potential.py [--pairs 1 5 20 30 40] [--mu 0.1 0.3 1 3 10 100]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

import hamsa
from hamsa.evaluation import TruthDistances, sample_points, summary
from hamsa.matching import resolve_signs, resolve_signs_without_truth
from hamsa.paper.benchmark import match_pair, paired_bases

SCAPE = Path(__file__).resolve().parents[2] / "shared" / "data" / "scape" / "meshes"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--pairs", type=int, nargs="+", default=[1, 5, 20, 30, 40])
    parser.add_argument("--mu", type=float, nargs="+", default=[0.1, 0.3, 1.0, 3.0, 10.0, 100.0])
    args = parser.parse_args(argv)
    if not SCAPE.is_dir():
        print(f"needs the SCAPE meshes at {SCAPE}")
        return 1
    source = hamsa.load_mesh(SCAPE / "mesh000.off.gz").scaled_to_unit_area()
    points = sample_points(source.n_vertices, 1000)
    columns = ["LBO"] + [f"mu={mu:g}" for mu in args.mu] + ["mu=1 no-truth signs", "signs agree"]
    print("HKS nearest neighbours, AUC on [0, 0.25]; mesh000 -> target")
    print(f"{'target':<8}" + "".join(f"{c:>{max(9, len(c) + 2)}}" for c in columns))
    totals = []
    with tempfile.TemporaryDirectory(prefix="hamsa-bases-") as cache:  # each LBO basis computed once
        for index in args.pairs:
            totals.append(_pair_row(source, index, points, args.mu, cache, columns))
    mean = np.mean(totals, axis=0)
    print(f"{'mean':<8}" + "".join(f"{v:>{max(9, len(c) + 2)}.3f}" for v, c in zip(mean, columns)))
    return 0


def _pair_row(source, index, points, mus, cache, columns) -> list:
    """One target: [LBO AUC, AUC per mu, AUC with signs found without truth, sign agreement]."""
    target = hamsa.load_mesh(SCAPE / f"mesh{index:03d}.off.gz").scaled_to_unit_area()
    truth = np.arange(source.n_vertices)
    distances = TruthDistances(target, points)

    def auc(bases):
        return summary(distances.errors(match_pair("hks", *bases)[points]))["auc"]

    row = []
    for mu in mus:
        bases = paired_bases(source, target, truth, 100, cache, eigensum_scale=mu, signs="truth")
        if not row:
            row.append(auc(bases["lbo"]))
        row.append(auc(bases["hamiltonian"]))
    row.append(auc(paired_bases(source, target, truth, 100, cache, signs="descriptors")["hamiltonian"]))
    lbo = bases["lbo"]
    found = resolve_signs_without_truth(*lbo, (1, 2, 3, 4), meshes=(source, target))
    agree = np.mean(resolve_signs(*lbo, truth, (1, 2, 3, 4)) == found)
    row.append(agree)
    print(f"mesh{index:03d} " + "".join(f"{v:>{max(9, len(c) + 2)}.3f}" for v, c in zip(row, columns)), flush=True)
    return row


if __name__ == "__main__":
    sys.exit(main())
