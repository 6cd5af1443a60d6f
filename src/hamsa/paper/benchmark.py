"""Matching benchmarks over whole datasets: every pair, every method, LBO vs Hamiltonian bases (paper §5).

For a pair (source, target) with a ground-truth map, :func:`evaluate_pair` builds the bases — the LBO's
and the Hamiltonian's with the paper's matching potential V = normalized sum of phi_2..phi_5 scaled to
[0, 1], its eigenfunction signs made consistent across the pair without the ground truth
(:func:`hamsa.matching.resolve_signs_without_truth`; ``oracle=True``: by the ground truth, as the
paper assumes) — runs the matchers and scores them by the Kim et al. protocol (geodesic error on the
target / sqrt(area), no symmetries, on a seeded sample of source vertices; in :func:`benchmark_dataset`
each shape is reduced to its largest connected component first, as in Kim et al.'s benchmark, whose
gorilla is the body alone):

* ``hks`` / ``wks``: nearest neighbours of the heat / wave kernel signatures;
* ``fmap``: an HKS-fitted 20 x 20 functional map, ICP, then ZoomOut up to k;
* ``icskm``: iterative closest spectral kernel maps (Shtern & Kimmel 2014) from ``landmarks`` ground-truth
  pairs drawn at random (seeded), as in the paper; its Hamiltonian is the paper's landmark potential,
  V = ``landmark_scale`` x geodesic distance from the nearest landmark (normalized to [0, 1]) on each shape;
* ``icskm_geo``: the same with the geodesic distances from each landmark as extra coordinates of the
  embedding (both bases) — hamsa's best pipeline on SCAPE, not one of the paper's;
* ``sgfe``: the spectral gradient fields embedding (Shtern & Kimmel 2015) refining the ``fmap`` start
  (HKS functional map + ICP on 20 eigenpairs), with the same matching potential; with ``oracle=True``
  its Hamiltonian is the paper's area-distortion potential instead (eq. stablePotential, ``AREA_MU`` x V
  with V >= 1 from the ground-truth map, as in the paper's Fig. bench_area: what a good mask of the
  stretching regions buys).
* ``texture`` (always an oracle): HKS nearest neighbours with the paper's texture potential, V =
  ``TEXTURE_MU`` x luminance of a synthetic dalmatian coat (:func:`hamsa.potentials.dalmatian_texture`,
  seeded) painted on the source and carried to the target by the ground truth (the datasets have no
  photometry; the paper shows it on the TOSCA dogs).

:func:`benchmark_dataset` runs every evaluation pair of a :class:`~hamsa.datasets.Dataset` in parallel
(joblib processes; a Dask cluster through joblib's backend when given a scheduler address) with a
progress bar. Each pair's result is written atomically to ``output/pairs/<source>__<target>.json``
together with a hash of the settings, so an interrupted run resumes where it stopped; the summary
table (method x basis -> mean AUC on [0, 0.25], mean error, fraction within 0.05) goes to
``output/table.json``, ``output/table.md`` and the mean curves to ``output/curves.png``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hamsa import potentials
from hamsa.cache import code_fingerprint, content_key, load_record, save_record
from hamsa.datasets import Dataset, cached_eigenbasis
from hamsa.eigen import eigenbasis
from hamsa.errors import HamsaError
from hamsa.evaluation import TruthDistances, error_curve, evaluated_points, summary
from hamsa.files import atomic_write
from hamsa.geodesic import GEODESIC_METHODS, geodesic_distance
from hamsa.matching import match, matching_potentials, resolve_signs
from hamsa.matching.functional import COMMUTATIVITY_WEIGHT, check_term_weight
from hamsa.mesh import TriMesh

METHODS = ("hks", "wks", "fmap", "icskm", "icskm_geo", "sgfe", "texture")
AREA_MU = 100.0
TEXTURE_MU = 100.0
# the Hamiltonian of these methods has its own potential (the others: the paper's eigenfunction sum)
_POTENTIAL_OF = {"icskm": "landmarks", "icskm_geo": "landmarks", "texture": "texture"}
_ORACLE_POTENTIAL_OF = {**_POTENTIAL_OF, "sgfe": "area"}
SIGNS = ("truth", "descriptors")
BASES = ("lbo", "hamiltonian")
SCORES = ("auc", "mean_error", "within_0.05")


def match_pair(
    method: str,
    source,
    target,
    landmarks=None,
    meshes=None,
    commutativity_weight: float = COMMUTATIVITY_WEIGHT,
    orientation_weight: float = 0.0,
) -> np.ndarray:
    """``map_source_to_target`` by one of :data:`METHODS` (:func:`hamsa.matching.match`; ``texture`` is HKS
    matching, its difference being the potential of its Hamiltonian basis)."""
    if method not in METHODS:
        raise HamsaError(f"unknown matching method {method!r}; known: {', '.join(METHODS)}")
    method = "hks" if method == "texture" else method
    return match(
        source,
        target,
        method,
        landmarks=landmarks,
        meshes=meshes,
        commutativity_weight=commutativity_weight,
        orientation_weight=orientation_weight,
    )


def paired_bases(
    source: TriMesh,
    target: TriMesh,
    ground_truth=None,
    k: int = 100,
    cache_dir=None,
    eigensum_scale: float = 1.0,
    signs: str = "descriptors",
) -> dict:
    """{"lbo": (source basis, target basis), "hamiltonian": (...)} with the paper's matching potential
    ``eigensum_scale x`` (normalized sum of phi_2..phi_5, scaled to [0, 1]).

    ``signs``: "descriptors" (default) makes the target's eigenfunction signs agree with the source's from
    the two shapes alone (:func:`hamsa.matching.resolve_signs_without_truth`, intrinsic moments and the
    surfaces' orientation); "truth" with ``ground_truth`` (n_source,) target ids (-1 where unknown), as
    the paper assumes (an oracle).
    """
    if signs not in SIGNS:
        raise HamsaError(f"signs must be one of {SIGNS}, got {signs!r}")
    if not (np.isfinite(eigensum_scale) and eigensum_scale > 0):
        raise HamsaError(f"eigensum_scale must be a positive number, got {eigensum_scale}")
    if signs == "truth" and ground_truth is None:
        raise HamsaError("signs='truth' needs the ground truth")
    solve = _basis_solver(k, cache_dir)
    lbo = solve(source), solve(target)
    truth_signs = resolve_signs(*lbo, np.asarray(ground_truth), (1, 2, 3, 4)) if signs == "truth" else None
    V_s, V_t = matching_potentials(*lbo, meshes=(source, target), signs=truth_signs)
    return {
        "lbo": lbo,
        "hamiltonian": (
            solve(source, eigensum_scale * V_s),
            solve(target, eigensum_scale * V_t),
        ),
    }


def evaluate_pair(
    source: TriMesh,
    target: TriMesh,
    ground_truth,
    k: int = 100,
    methods=METHODS,
    points: int = 1000,
    seed: int = 0,
    cache_dir=None,
    landmarks: int = 3,
    eigensum_scale: float = 1.0,
    oracle: bool = False,
    draws: int = 1,
    landmark_scale: float = 1.0,
    geodesics: str = "heat",
    commutativity_weight: float = COMMUTATIVITY_WEIGHT,
    orientation_weight: float = 0.0,
) -> dict:
    """Scores of every method x basis on one pair: {"rows": [...], "curves": {method: {basis: curve}}}.

    ``landmarks``: ground-truth pairs given to ``icskm`` / ``icskm_geo`` (drawn with ``seed`` among the
    vertices that have a true image; the same for both bases). ``draws``: independent landmark draws
    (seeds ``seed + 1``, ``seed + 2``, ...; the first is the single draw's) whose errors are pooled, so
    the scores of the landmark methods are means over draws. ``eigensum_scale``: the matching potential's
    scale (see :func:`paired_bases`). ``oracle``: build the potentials from the ground truth as the paper
    does (the matching potential's signs, SGFE's area distortion) instead of from the shapes alone; the
    ground truth is otherwise used only to score (and, as always, for ``texture`` and the landmarks).
    ``landmark_scale``: the scale of the landmark potential, the geodesic distance from the landmarks in
    [0, 1]; on a unit-area shape the Laplacian eigenvalues are O(10)-O(1000) at k = 100, so a scale of 1
    barely moves the basis and 10-100 starts to localize the low functions near the landmarks.
    ``geodesics``: the distances that score the maps, ``"heat"`` or ``"exact"``
    (:func:`hamsa.evaluation.geodesic_errors`); the landmark potentials always use the heat method.
    ``commutativity_weight``: that of the functional map starting ``fmap`` and ``sgfe`` and of ICSKM's
    landmark fit; ``orientation_weight``: that of the ``fmap`` / ``sgfe`` start (:func:`hamsa.matching.match`)."""
    truth = np.asarray(ground_truth)
    if truth.shape != (source.n_vertices,):
        raise HamsaError(f"ground truth has shape {truth.shape}, the source has {source.n_vertices} vertices")
    if int(draws) < 1:
        raise HamsaError(f"need at least one landmark draw, got draws = {draws}")
    if not (np.isfinite(landmark_scale) and landmark_scale > 0):
        raise HamsaError(f"landmark_scale must be a positive number, got {landmark_scale}")
    candidates = np.flatnonzero(truth >= 0)
    chosen = evaluated_points(truth, points, seed)
    distances = TruthDistances(target, truth[chosen], geodesics=geodesics)
    solve = _basis_solver(k, cache_dir)
    potential_of = _ORACLE_POTENTIAL_OF if oracle else _POTENTIAL_OF
    if all(method in potential_of for method in methods):  # the eigenfunction-sum Hamiltonian is not used
        bases = {"lbo": (solve(source), solve(target))}
    else:
        signs = "truth" if oracle else "descriptors"
        bases = paired_bases(source, target, truth, k, cache_dir, eigensum_scale, signs)
    wanted = {potential_of.get(method) for method in methods}
    special = {}  # potential name -> (source V, target V) of the Hamiltonians other than the paper's default
    if "area" in wanted:
        V_s, V_t = _area_distortion_potentials(source, target, truth)
        special["area"] = (AREA_MU * V_s, AREA_MU * V_t)
    if "texture" in wanted:
        special["texture"] = tuple(TEXTURE_MU * V for V in _texture_potentials(source, target, truth))
    for name, (V_s, V_t) in special.items():
        special[name] = (solve(source, V_s), solve(target, V_t))
    runs = {None: [(None, special)]}  # landmark pairs -> the Hamiltonian bases that go with them, per draw
    if "landmarks" in wanted:
        runs["landmarks"] = []
        for draw in range(int(draws)):
            p = np.random.default_rng(seed + 1 + draw).choice(candidates, landmarks, replace=False)
            V_s = landmark_scale * geodesic_distance(source, p, normalize=True, unreachable="farthest")
            V_t = landmark_scale * geodesic_distance(target, truth[p], normalize=True, unreachable="farthest")
            runs["landmarks"].append(((p, truth[p]), {"landmarks": (solve(source, V_s), solve(target, V_t))}))
    rows, curves = [], {}
    for method in methods:
        for basis in BASES:
            pooled = []
            for pairs, hamiltonians in runs["landmarks" if potential_of.get(method) == "landmarks" else None]:
                if basis == "hamiltonian" and method in potential_of:
                    pair = hamiltonians[potential_of[method]]
                else:
                    pair = bases[basis]
                mapping = match_pair(method, *pair, pairs, (source, target), commutativity_weight, orientation_weight)
                pooled.append(distances.errors(mapping[chosen]))
            errors = np.concatenate(pooled)
            rows.append({"method": method, "basis": basis, **summary(errors)})
            curves.setdefault(method, {})[basis] = error_curve(errors).tolist()
    return {"rows": rows, "curves": curves}


def _basis_solver(k: int, cache_dir):
    """``solve(mesh, V=None)`` -> Eigenbasis with k pairs, through the on-disk cache when there is one."""
    if cache_dir:
        return lambda mesh, V=None: cached_eigenbasis(mesh, k, cache_dir, V)
    return lambda mesh, V=None: eigenbasis(mesh, k, V)


def carried_to_target(values: np.ndarray, truth: np.ndarray, n_target: int, fill: float = 1.0) -> np.ndarray:
    """Per-vertex source ``values`` (n_s,) moved to the target by the ground truth (n_s,) target ids (-1:
    unknown): (n_target,), ``fill`` where no source vertex maps (1.0: white, for a luminance)."""
    known = np.flatnonzero(truth >= 0)
    carried = np.full(n_target, fill, dtype=np.float64)
    carried[truth[known]] = values[known]
    return carried


def _texture_potentials(source: TriMesh, target: TriMesh, truth: np.ndarray):
    """Luminance in [0, 1] of a seeded dalmatian coat painted on the source and carried to the target by
    the ground truth (white where no source vertex maps)."""
    luminance = potentials.from_vertex_colors(source, potentials.dalmatian_texture(source))
    return luminance, carried_to_target(luminance, truth, target.n_vertices)


def _area_distortion_potentials(source: TriMesh, target: TriMesh, truth: np.ndarray):
    """Area distortion (>= 1) of the ground-truth map on each shape; 1 where a vertex has no known image."""
    V_s = np.ones(source.n_vertices)
    known = truth >= 0
    inverse = np.full(target.n_vertices, -1, dtype=np.int64)
    inverse[truth[known]] = np.flatnonzero(known)
    V_t = np.ones(target.n_vertices)
    back = inverse >= 0
    V_s[known] = potentials.area_distortion(source, target, np.where(known, truth, 0))[known]
    V_t[back] = potentials.area_distortion(target, source, np.where(back, inverse, 0))[back]
    return V_s, V_t


def dataset_pairs(dataset: Dataset, limit: int | None = None) -> list[tuple[str, str]]:
    """The dataset's evaluation pairs, optionally only the first ``limit`` of each class (a quick look)."""
    pairs = dataset.pairs()
    if limit is None:
        return pairs
    taken: dict[str, int] = {}
    chosen = []
    for source, target in pairs:
        c = dataset.classes[source]
        if taken.get(c, 0) < limit:
            chosen.append((source, target))
            taken[c] = taken.get(c, 0) + 1
    return chosen


def identity_truth(source_kept: np.ndarray, target_kept: np.ndarray, n_target_original: int) -> np.ndarray:
    """Identity ground truth in original ids, carried through the vertices each side kept (-1: dropped)."""
    position = np.full(max(n_target_original, int(source_kept.max()) + 1), -1, dtype=np.int64)
    position[target_kept] = np.arange(len(target_kept))
    return position[source_kept]


def load_pair(dataset: Dataset, source_name: str, target_name: str) -> tuple[TriMesh, TriMesh, np.ndarray]:
    """``(source, target, ground_truth)`` as the dataset benchmark scores a pair: each shape reduced to its
    largest connected component (as Kim et al.: loose pieces dropped, TOSCA's gorilla is the body alone)
    and scaled to unit area, and the identity truth (within a class) carried through the vertices each side
    kept, -1 where the source vertex's partner was dropped."""
    source, source_kept = dataset.load(source_name, largest_component=True)
    target, target_kept = dataset.load(target_name, largest_component=True)
    truth = identity_truth(source_kept, target_kept, int(max(source_kept.max(), target_kept.max())) + 1)
    return source.scaled_to_unit_area(), target.scaled_to_unit_area(), truth


def _run_pair(dataset: Dataset, source_name: str, target_name: str, settings: dict, path: Path) -> dict:
    source, target, truth = load_pair(dataset, source_name, target_name)
    result = evaluate_pair(
        source,
        target,
        truth,
        settings["k"],
        settings["methods"],
        settings["points"],
        cache_dir=settings["cache"],
        landmarks=settings.get("landmarks", 3),
        eigensum_scale=settings.get("eigensum_scale", 1.0),
        oracle=settings.get("oracle", False),
        draws=settings.get("draws", 1),
        landmark_scale=settings.get("landmark_scale", 1.0),
        geodesics=settings.get("geodesics", "heat"),
        commutativity_weight=settings.get("commutativity_weight", COMMUTATIVITY_WEIGHT),
        orientation_weight=settings.get("orientation_weight", 0.0),
    )
    record = {"source": source_name, "target": target_name, "settings_key": _settings_key(settings), **result}
    save_record(path, record)
    return record


def _run_pair_or_failure(dataset: Dataset, source_name: str, target_name: str, settings: dict, path: Path) -> dict:
    """:func:`_run_pair`, or ``{"source", "target", "error"}`` when the pair fails (an unreadable mesh, a
    failed solve): one bad pair does not stop a run of hours. Nothing is written for it, so the next run
    retries it."""
    try:
        return _run_pair(dataset, source_name, target_name, settings, path)
    except Exception as error:  # reported in the table and by the CLI's exit status, never dropped
        return {"source": source_name, "target": target_name, "error": f"{type(error).__name__}: {error}"}


def _settings_key(settings: dict) -> str:
    return content_key(code_fingerprint(), {k: v for k, v in settings.items() if k != "cache"})


def _finished(path: Path, key: str) -> dict | None:
    record = load_record(path, key, field="settings_key")
    return record if record and record.get("rows") else None


def benchmark_dataset(
    dataset: Dataset,
    output,
    methods=METHODS,
    k: int = 100,
    points: int = 1000,
    jobs: int = 1,
    limit: int | None = None,
    scheduler: str | None = None,
    progress: bool = True,
    landmarks: int = 3,
    eigensum_scale: float = 1.0,
    oracle: bool = False,
    draws: int = 1,
    landmark_scale: float = 1.0,
    geodesics: str = "heat",
    commutativity_weight: float = COMMUTATIVITY_WEIGHT,
    orientation_weight: float = 0.0,
) -> dict:
    """Run every evaluation pair (resumably, in parallel) and write the summary table; returns it.

    A pair that fails (an unreadable mesh, a failed solve) does not stop the others: it is left out of the
    means and listed under ``table["failed"]`` (source, target, error), in ``table.md`` too; a rerun
    retries only the failed and unfinished pairs.

    Parameters
    ----------
    dataset : a Dataset (:func:`hamsa.datasets.load_tosca`, ``load_scape``, ``load_folder``)
    output : folder for ``pairs/*.json``, ``table.json``, ``table.md``, ``curves.png`` and the basis cache
    methods : subset of :data:`METHODS`
    k : eigenpairs per basis; points : evaluated source vertices per pair (seeded sample)
    jobs : parallel worker processes (joblib); scheduler : a Dask scheduler address ("tcp://host:8786")
        to run the pairs on a cluster instead (needs ``dask.distributed``)
    limit : at most this many pairs per class
    landmarks : ground-truth landmark pairs given to ``icskm`` (1, 2 or 3 in the paper)
    draws : independent landmark draws per pair, pooled (:func:`evaluate_pair`)
    landmark_scale : scale of the icskm / icskm_geo Hamiltonian's landmark potential (:func:`evaluate_pair`)
    eigensum_scale : the hks/wks/fmap/sgfe matching potential's scale (:func:`paired_bases`)
    oracle : build the potentials from the ground truth, as the paper does (:func:`evaluate_pair`); the
        table's ``potentials`` field says which
    geodesics : ``"heat"`` or ``"exact"`` distances for the scores (:func:`evaluate_pair`)
    commutativity_weight, orientation_weight : those of the functional maps that start the methods
        (:func:`evaluate_pair`)
    """
    unknown = set(methods) - set(METHODS)
    if unknown:
        raise HamsaError(f"unknown matching methods {sorted(unknown)}; known: {', '.join(METHODS)}")
    if geodesics not in GEODESIC_METHODS:  # (checked here, not once per pair in the workers)
        raise HamsaError(f"geodesics must be one of {GEODESIC_METHODS}, got {geodesics!r}")
    check_term_weight("commutativity", commutativity_weight)  # (likewise)
    check_term_weight("orientation", orientation_weight)
    output = Path(output)
    (output / "pairs").mkdir(parents=True, exist_ok=True)
    settings = {"k": int(k), "methods": list(methods), "points": int(points), "cache": str(output / "bases")}
    if {"icskm", "icskm_geo"} & set(methods):
        settings["landmarks"] = int(landmarks)
        if draws != 1:  # (one draw stays out of the key: earlier results remain valid)
            settings["draws"] = int(draws)
        if landmark_scale != 1.0:  # (likewise)
            settings["landmark_scale"] = float(landmark_scale)
    if eigensum_scale != 1.0:  # (the default stays out of the key: earlier results remain valid)
        settings["eigensum_scale"] = float(eigensum_scale)
    if oracle:
        settings["oracle"] = True
    if geodesics != "heat":  # (likewise)
        settings["geodesics"] = str(geodesics)
    # (always: results from before its default was 0.03 had none)
    if {"fmap", "sgfe", "icskm", "icskm_geo"} & set(methods):
        settings["commutativity_weight"] = float(commutativity_weight)
    if {"fmap", "sgfe"} & set(methods) and orientation_weight:  # (0, the default, stays out of the key)
        settings["orientation_weight"] = float(orientation_weight)
    key = _settings_key(settings)
    todo, records = [], []
    for source, target in dataset_pairs(dataset, limit):
        path = output / "pairs" / f"{source}__{target}.json"
        done = _finished(path, key)
        if done:
            records.append(done)
        else:
            todo.append((source, target, path))
    results = _run_parallel(dataset, todo, settings, jobs, scheduler, progress)
    records += [result for result in results if "error" not in result]
    table = summarize(records, dataset.name, dataset.classes)
    table["potentials"] = "oracle (from the ground truth)" if oracle else "estimated (no ground truth)"
    table["geodesics"] = "exact (MMP)" if geodesics == "exact" else "heat method"
    for name in ("commutativity_weight", "orientation_weight"):
        if name in settings:
            table[name] = settings[name]
    failed = [result for result in results if "error" in result]
    if failed:
        table["failed"] = sorted(failed, key=lambda result: (result["source"], result["target"]))
    _write_outputs(output, table, records, dataset.name)
    return table


def _run_parallel(dataset, todo, settings, jobs, scheduler, progress) -> list[dict]:
    if not todo:
        return []
    try:
        import joblib
    except ImportError:
        raise HamsaError("dataset benchmarks need joblib: pip install 'hamsa[bench]'") from None
    from tqdm.auto import tqdm

    tasks = (joblib.delayed(_run_pair_or_failure)(dataset, s, t, settings, path) for s, t, path in todo)
    results = []
    if scheduler:
        try:
            from dask.distributed import Client
        except ImportError:
            raise HamsaError("a Dask scheduler needs dask.distributed: pip install 'dask[distributed]'") from None
        with Client(scheduler), joblib.parallel_config(backend="dask"):
            stream = joblib.Parallel(return_as="generator_unordered")(tasks)
            results = list(tqdm(stream, total=len(todo), desc="pairs", disable=not progress))
    else:
        stream = joblib.Parallel(n_jobs=jobs, return_as="generator_unordered")(tasks)
        results = list(tqdm(stream, total=len(todo), desc="pairs", disable=not progress))
    return results


def summarize(records: list[dict], dataset_name: str, classes: dict | None = None) -> dict:
    """Mean AUC, mean error and fraction within 0.05 per method x basis over the pairs; with ``classes``
    (shape name -> class, e.g. :attr:`Dataset.classes`) of more than one class, also per class of the
    source shape (``by_class``)."""
    table = {"dataset": dataset_name, "pairs": len(records), "rows": _mean_rows(records, {"dataset": dataset_name})}
    groups: dict[str, list[dict]] = {}
    for record in records:
        groups.setdefault((classes or {}).get(record.get("source"), ""), []).append(record)
    if classes and len(groups) > 1:
        table["by_class"] = [row for name in sorted(groups) for row in _mean_rows(groups[name], {"class": name})]
    return table


def _mean_rows(records: list[dict], label: dict) -> list[dict]:
    rows = []
    for method in METHODS:
        for basis in BASES:
            found = [r for record in records for r in record["rows"] if r["method"] == method and r["basis"] == basis]
            if found:
                scores = {key: float(np.mean([r[key] for r in found])) for key in SCORES}
                rows.append({**label, "method": method, "basis": basis, "pairs": len(found), **scores})
    return rows


def table_markdown(table: dict) -> str:
    """The summary as Markdown: one table per dataset, then one per class when there are several."""
    notes = {
        "potentials": "Hamiltonian potentials",
        "geodesics": "Geodesic errors",
        "commutativity_weight": "Descriptor-commutativity weight of the fmap / sgfe start and the ICSKM landmark fit",
        "orientation_weight": "Orientation-preserving weight of that start",
    }
    lines = [f"{label}: {table[key]}." for key, label in notes.items() if key in table]
    lines += [""] if lines else []
    for key, rows in (("dataset", table["rows"]), ("class", table.get("by_class", []))):
        if not rows:
            continue
        if key == "class":
            lines.append("")
        lines += [
            f"| {key} | method | basis | pairs | AUC [0, 0.25] | mean error | within 0.05 |",
            "|---|---|---|---|---|---|---|",
        ]
        for r in rows:
            lines.append(
                f"| {r[key]} | {r['method']} | {r['basis']} | {r['pairs']} | {r['auc']:.3f} | "
                f"{r['mean_error']:.4f} | {100 * r['within_0.05']:.1f}% |"
            )
    failed = table.get("failed", [])
    if failed:
        lines += ["", f"{len(failed)} pair(s) failed (not in the table; a rerun retries them):"]
        lines += [f"- {f['source']} -> {f['target']}: {f['error']}" for f in failed]
    return "\n".join(lines) + "\n"


def _write_outputs(output: Path, table: dict, records: list[dict], name: str) -> None:
    save_record(output / "table.json", table, indent=2)
    with atomic_write(output / "table.md", "w") as handle:
        handle.write(table_markdown(table))
    if not records:
        return
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return  # the table is the result; the plot needs the [viz] extra
    from hamsa.paper.experiments._common import kim_curve_panel, save_figure

    methods = [m for m in METHODS if m in records[0]["curves"]]
    aucs = {(row["method"], row["basis"]): row["auc"] for row in table["rows"]}
    figure, axes = plt.subplots(1, len(methods), figsize=(4.2 * len(methods), 3.6), sharey=True, squeeze=False)
    for ax, method in zip(axes[0], methods):
        curves = {basis: [record["curves"][method][basis] for record in records] for basis in BASES}
        scores = {basis: aucs[method, basis] for basis in BASES}
        kim_curve_panel(ax, curves, scores, f"{method} — {name} ({len(records)} pairs)")
    axes[0][0].set_ylabel("% correspondences")
    figure.tight_layout()
    save_figure(figure, output / "curves.png")
    plt.close(figure)
