"""Nearest-neighbour search in spectral embeddings: hamsa's k-d tree against a BLAS distance scan.

Matching spends most of its time finding, for each source point, the nearest target point in an embedding:
ICSKM's heat-kernel embedding ``(e^{-E_i t / 2} psi_i)_i`` at each heat scale, and the HKS / WKS columns in
descriptor matching. The usual fast baseline is the scan ``argmin_y |y|^2 - 2 x.y`` by matrix products (what
hamsa did above 24 coordinates up to 0.1.4, and what a NumPy user writes). The rows of these embeddings
have intrinsic dimension about 2 (they are functions on a surface), so the k-d tree
(:func:`hamsa.matching.nearest_rows`) keeps winning at d = 100. ZoomOut's queries are different: the
images ``Psi C`` of an imperfect functional map lie off the embedding, where the tree's pruning fails in
many dimensions. hamsa's exact scan (``nearest_rows(..., method="scan")``: near ties of the expansion
re-ranked by direct distances) is timed too, and ``method="auto"`` (what ICP and ZoomOut use: both timed on
a sample of queries, the faster one run).
Every timing is the median of ``--repeat`` runs with the tree built inside the timing. "same" is the
fraction of queries given the same index as the tree; where the plain scan differs, "scan farther" is the
fraction where its answer is truly farther (its ``|y|^2 - 2 x.y`` cancels digits when the embedding is
small, at coarse heat scales), the rest being ties (on a symmetric shape, mirror points).

    python benchmarks/nearest_neighbours.py                   # built-in humanoid, k = 100
    python benchmarks/nearest_neighbours.py --data ../shared/data/scape/meshes/mesh000.off.gz
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import hamsa
from hamsa.diffusion import default_hks_times, heat_kernel_signature
from hamsa.matching import functional_from_map, nearest_rows


def distance_scan(queries: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The baseline: nearest rows by ``|y|^2 - 2 x.y`` in blocks of about 16 MB (BLAS-3)."""
    squared = np.einsum("ij,ij->i", points, points)
    block = max(1, 2**21 // len(points))
    nearest = np.empty(len(queries), dtype=np.int64)
    for start in range(0, len(queries), block):
        nearest[start : start + block] = np.argmin(squared - 2.0 * (queries[start : start + block] @ points.T), axis=1)
    return nearest


def median_seconds(function, repeat: int) -> tuple[float, np.ndarray]:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", help="a mesh file (default: the built-in humanoid)")
    parser.add_argument("-k", type=int, default=100)
    parser.add_argument("--queries", type=int, default=1000, help="sampled source points per search")
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)
    mesh = hamsa.load_mesh(args.data) if args.data else hamsa.shapes.humanoid()
    basis = hamsa.eigenbasis(mesh, args.k)
    rng = np.random.default_rng(0)
    rows = rng.choice(basis.n, min(args.queries, basis.n), replace=False)
    spectrum = np.abs(basis.values)
    scales = np.geomspace(4 * np.log(10) / spectrum[-1], 4 * np.log(10) / spectrum[min(5, basis.k - 1)], 3)
    cases = {}
    for t in scales[::-1]:
        embedding = basis.vectors * np.exp(-basis.values * t / 2)
        kept = np.exp(-(basis.values - basis.values.min()) * t / 2) >= 1e-4  # as ICSKM: coordinates not damped away
        cases[f"heat embedding t={t:.2g} (d={kept.sum()})"] = (embedding[rows][:, kept], embedding[:, kept])
    hks = heat_kernel_signature(basis, default_hks_times(basis, 50), scaled=True)
    hks /= np.sqrt(np.mean(hks**2, axis=0))
    cases["HKS, all vertices (d=50)"] = (hks, hks[::-1].copy())
    # what ZoomOut searches: the images Psi C of a functional map, here of the shape onto itself with a
    # fifth of the vertices sent to random places (an imperfect map, as in the middle of a refinement)
    noisy = np.arange(basis.n)
    moved = rng.random(basis.n) < 0.2
    noisy[moved] = rng.integers(0, basis.n, moved.sum())
    for d in (32, 64, min(100, basis.k)):
        truncated = basis.truncate(d)
        images = truncated.vectors @ functional_from_map(noisy, truncated, truncated)
        cases[f"functional-map images (d={d})"] = (images[rows], truncated.vectors)
    print(f"{mesh.n_vertices} vertices, k = {basis.k}, {len(rows)} queries per embedding search")
    print(
        f"{'search':<40} {'k-d tree':>10} {'scan':>10} {'scan / tree':>12} {'same':>7} {'scan farther':>13}"
        f" {'exact scan':>11} {'/ tree':>7} {'same':>7} {'auto':>8} {'/ tree':>7}"
    )
    for name, (queries, points) in cases.items():
        queries, points = np.ascontiguousarray(queries), np.ascontiguousarray(points)
        tree_time, tree = median_seconds(lambda: nearest_rows(queries, points), args.repeat)
        scan_time, scan = median_seconds(lambda: distance_scan(queries, points), args.repeat)
        exact_time, exact = median_seconds(lambda: nearest_rows(queries, points, method="scan"), args.repeat)
        auto_time, auto = median_seconds(lambda: nearest_rows(queries, points, method="auto"), args.repeat)
        assert np.array_equal(auto, exact) or np.array_equal(auto, tree)
        scan_distance, tree_distance = (np.linalg.norm(queries - points[found], axis=1) for found in (scan, tree))
        farther = np.mean(scan_distance > tree_distance * (1 + 1e-12))
        print(
            f"{name:<40} {tree_time:>9.3f}s {scan_time:>9.3f}s {scan_time / tree_time:>11.1f}x"
            f" {np.mean(tree == scan):>7.4f} {farther:>13.4f}"
            f" {exact_time:>10.3f}s {exact_time / tree_time:>6.2f}x {np.mean(tree == exact):>7.4f}"
            f" {auto_time:>7.3f}s {auto_time / tree_time:>6.2f}x"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
