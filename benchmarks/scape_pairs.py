"""What the SCAPE pair benchmarks share: the data folder, their common options, and scoring every pair.

Not a benchmark itself: ``exact_geodesics.py`` and ``fmap_commutativity.py`` import it (run them from the
repository root as ``python benchmarks/NAME.py``).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from hamsa.datasets import load_scape
from hamsa.files import atomic_write
from hamsa.paper.benchmark import dataset_pairs, load_pair

SCAPE = Path(__file__).resolve().parents[2] / "shared" / "data" / "scape" / "meshes"


def options(doc: str, k: int) -> argparse.ArgumentParser:
    """The shared options: ``-k`` (default ``k``), ``--points`` (1000), ``--jobs`` (1), ``-o`` (JSON records)."""
    parser = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-k", type=int, default=k, help=f"eigenpairs per basis (default {k})")
    parser.add_argument("--points", type=int, default=1000, help="scored vertices per pair (default 1000)")
    parser.add_argument("--jobs", type=int, default=1, help="worker processes, one pair each (default 1)")
    parser.add_argument("-o", "--output", help="also write the per-pair records as JSON")
    return parser


def score_pairs(score, jobs: int, limit: int | None = None, output=None, prepare=None) -> tuple[list, float]:
    """``[score(source, target, truth) for each SCAPE pair]`` (mesh000 against the others, at most ``limit``,
    loaded by :func:`hamsa.paper.benchmark.load_pair`) in ``jobs`` processes, and the wall seconds. Each
    record gets the target's name; with ``output`` the records are also written there as JSON.
    ``prepare(source)`` runs once first (e.g. to cache the shared source's bases). Raises
    FileNotFoundError without the SCAPE meshes."""
    import joblib

    if not SCAPE.is_dir():
        raise FileNotFoundError(f"needs the SCAPE meshes at {SCAPE}")
    dataset = load_scape(SCAPE)
    pairs = dataset_pairs(dataset)[:limit]
    start = time.perf_counter()
    if prepare is not None:
        prepare(load_pair(dataset, *pairs[0])[0])
    records = joblib.Parallel(n_jobs=jobs)(joblib.delayed(_score)(score, dataset, s, t) for s, t in pairs)
    if output is not None:
        with atomic_write(output, "w") as handle:
            json.dump(records, handle, indent=1)
    return records, time.perf_counter() - start


def _score(score, dataset, source_name: str, target_name: str) -> dict:
    return {"target": target_name, **score(*load_pair(dataset, source_name, target_name))}
