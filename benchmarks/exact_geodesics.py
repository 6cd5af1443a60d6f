"""Kim et al. scores with heat-method geodesics (hamsa's default) against exact polyhedral geodesics (MMP).

Published correspondence curves measure errors with exact geodesics; hamsa scores with the heat method
unless asked (``geodesics="exact"``, ``hamsa match --geodesics exact``). This measures what that changes.
Each SCAPE pair (mesh000 against every other pose, unit area) is matched with the LBO basis (k = 50) by
two methods of different quality, ``hks`` (nearest neighbours of scaled HKS) and ``fmap`` (HKS functional
map + ICP + ZoomOut), and each map is scored at the same 1000 seeded vertices with both kinds of geodesics.
Printed: per method, the pair-averaged AUC on [0, 0.25], fraction within 0.05 and mean error under each
kind, the mean and the largest per-pair difference (heat - exact), the heat method's relative distance
error at the scored pairs (exact distance > 0.01), and the scoring time of each kind (CPU and wall, one
process per pair).

    OMP_NUM_THREADS=1 python benchmarks/exact_geodesics.py [--pairs 66] [--jobs 2] [-o exact_geodesics.json]
"""

from __future__ import annotations

import functools
import sys
import tempfile
import time

import numpy as np
from scape_pairs import options, score_pairs

import hamsa
from hamsa.datasets import cached_eigenbasis
from hamsa.evaluation import evaluated_points, summary
from hamsa.geodesic import geodesic_solver
from hamsa.matching.functional import COMMUTATIVITY_WEIGHT
from hamsa.paper.benchmark import match_pair

METHODS = ("hks", "fmap")
SCORES = ("auc", "within_0.05", "mean_error")


def score_pair(source, target, truth, k: int, points: int, cache: str, commutativity: float) -> dict:
    """Both methods' scores under both geodesics, the distance error, and the scoring times, for one pair."""
    chosen = evaluated_points(truth, points)
    bases = (cached_eigenbasis(source, k, cache), cached_eigenbasis(target, k, cache))
    maps = {method: match_pair(method, *bases, commutativity_weight=commutativity)[chosen] for method in METHODS}
    record, distances, seconds = {}, {}, []
    for kind in ("heat", "exact"):
        wall, cpu = time.perf_counter(), time.process_time()
        solver = geodesic_solver(target, method=kind)
        both = solver.between(np.tile(truth[chosen], len(METHODS)), np.concatenate(list(maps.values())))
        distances[kind] = dict(zip(METHODS, np.split(both, len(METHODS))))  # one propagation per true image
        seconds.append((time.perf_counter() - wall, time.process_time() - cpu))
    record["seconds"] = seconds
    for method in METHODS:
        heat, exact = distances["heat"][method], distances["exact"][method]
        far = exact > 0.01
        record[method] = {
            "heat": summary(heat / np.sqrt(target.area)),
            "exact": summary(exact / np.sqrt(target.area)),
            "relative_distance_error": float(np.median(np.abs(heat[far] - exact[far]) / exact[far])),
        }
    return record


def main(argv=None) -> int:
    parser = options(__doc__, k=50)
    parser.add_argument("--pairs", type=int, default=66, help="SCAPE pairs (mesh000 against the next ones)")
    parser.add_argument(
        "--commutativity", type=float, default=COMMUTATIVITY_WEIGHT, help="fmap's start-map commutativity weight"
    )
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="hamsa-bases-") as cache:
        records, seconds = score_pairs(
            functools.partial(score_pair, k=args.k, points=args.points, cache=cache, commutativity=args.commutativity),
            args.jobs,
            args.pairs,
            args.output,
            prepare=lambda source: cached_eigenbasis(source, args.k, cache),  # the shared source, once
        )
    print(f"SCAPE, {len(records)} pairs, LBO k = {args.k}, {args.points} scored vertices, hamsa {hamsa.__version__}")
    print(f"({seconds:.0f} s with {args.jobs} job(s))\n")
    print("| method | geodesics | AUC | within 0.05 | mean error |")
    print("|---|---|---|---|---|")
    for method in METHODS:
        for kind in ("heat", "exact"):
            means = [np.mean([r[method][kind][s] for r in records]) for s in SCORES]
            print(f"| {method} | {kind} | " + " | ".join(f"{v:.4f}" for v in means) + " |")
    print("\n| method | score | mean heat - exact | largest per-pair abs difference |")
    print("|---|---|---|---|")
    for method in METHODS:
        for score in SCORES:
            diff = np.array([r[method]["heat"][score] - r[method]["exact"][score] for r in records])
            print(f"| {method} | {score} | {diff.mean():+.4f} | {np.abs(diff).max():.4f} |")
    for method in METHODS:
        error = [r[method]["relative_distance_error"] for r in records]
        print(f"\n{method}: heat-method distance error at the scored pairs, median over pairs {np.median(error):.4f}"
              f" (largest {np.max(error):.4f})")  # fmt: skip
    times = np.array([r["seconds"] for r in records])  # (pairs, heat/exact, wall/cpu)
    heat, exact = np.median(times[:, 0], axis=0), np.median(times[:, 1], axis=0)
    print(f"\nscoring both maps of a pair, median: heat {heat[0]:.2f} s wall / {heat[1]:.2f} s CPU, exact "
          f"{exact[0]:.2f} s wall / {exact[1]:.2f} s CPU (exact / heat: {exact[0] / heat[0]:.1f}x wall)")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
