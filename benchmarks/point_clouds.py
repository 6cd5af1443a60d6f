"""Matching on point clouds beside the same methods on the meshes, LBO vs Hamiltonian (Kim et al. protocol).

Each pair (SCAPE: mesh000 against the next ``--scape`` meshes; TOSCA: the first pair of every class) is
scaled to unit area (as a mesh, reduced to its largest component as in Kim et al.) and matched on three
representations of the same shapes:

* ``mesh``: the triangle meshes, cotan Laplacian (the reference);
* ``cloud``: their vertices with the faces dropped (the point-cloud Laplacian of Sharp & Crane 2020, with
  hamsa's local triangulations that keep nearly touching parts apart; ``--joined-sheets``: robust_laplacian's,
  which joins them);
* ``cloud 50%``: a seeded random half of each shape's vertices, drawn independently on source and target;
  the true image of a source point is the target point nearest (Euclidean) to its true vertex.

Methods and settings are ``hamsa benchmark-matching``'s defaults: ``hks`` (nearest neighbours of scaled
HKS), ``fmap`` (HKS functional map + ICP + ZoomOut) with the paper's eigenfunction-sum potential (its signs
chosen from the shapes alone, as there), and ``icskm`` from 3 seeded ground-truth landmarks with the landmark potential
(geodesic distance, scale 1); k = 100, 1000 evaluated points. Errors are measured by geodesics on the target
itself: the heat method on a mesh, the point-cloud heat method (potpourri3d) on a cloud. The table gives the
AUC on [0, 0.25] and the fraction within 0.05, averaged over pairs, and the bar of the point-cloud issue:
on clouds the Hamiltonian is at least as good as the LBO for every method, and within 5 points (fraction
within 0.05) of the same method on the mesh (the LBO's own gaps to the mesh are listed, not counted).

    OMP_NUM_THREADS=1 python benchmarks/point_clouds.py [--scape 5] [--scape-skip 0] [--tosca-classes centaur horse]
        [--jobs 2] [--methods hks] [--representations cloud] [--joined-sheets | --off-sheet 0.7] [--mesh-normals]
        [-o point_clouds.json]
    python benchmarks/point_clouds.py --spectra SHAPE...          # cloud spectra against the meshes
    python benchmarks/point_clouds.py --signs SOURCE:TARGET...    # wrong signs of the matching potential
    python benchmarks/point_clouds.py --build 50000 200000         # the operators' cost against robust_laplacian
    python benchmarks/point_clouds.py --strays                     # stray points: false alarms and detection
    python benchmarks/point_clouds.py --table scape.json tosca.json  # the table and the bar of saved rows
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

import hamsa
from hamsa.datasets import load_scape, load_tosca
from hamsa.files import atomic_write
from hamsa.paper.benchmark import dataset_pairs, evaluate_pair, identity_truth
from hamsa.repair import orient_faces

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
METHODS = ("hks", "fmap", "icskm")
REPRESENTATIONS = ("mesh", "cloud", "cloud 50%")


def unit_area_pair(dataset, source_name: str, target_name: str):
    """(source, target, truth): the pair's meshes reduced to their largest components and scaled to unit area,
    and the target vertex of each source vertex (-1 where unknown)."""
    source, source_kept = dataset.load(source_name, largest_component=True)
    target, target_kept = dataset.load(target_name, largest_component=True)
    truth = identity_truth(source_kept, target_kept, int(max(source_kept.max(), target_kept.max())) + 1)
    return source.scaled_to_unit_area(), target.scaled_to_unit_area(), truth


def pair_scores(
    dataset,
    source_name: str,
    target_name: str,
    k: int,
    points: int,
    methods=METHODS,
    orientation: float = 0.0,
    cloud_options: dict | None = None,
    representations=REPRESENTATIONS,
    mesh_normals: bool = False,
) -> list[dict]:
    """Rows {dataset, pair, representation, method, basis, auc, within_0.05} of one pair, for the
    ``representations`` named; ``cloud_options``: keywords of :class:`hamsa.PointCloud` (``separate_sheets``,
    ``off_sheet``); ``mesh_normals``: the clouds take their meshes' vertex normals (faces oriented
    consistently first), as a scanner's."""
    source, target, truth = unit_area_pair(dataset, source_name, target_name)
    rng = np.random.default_rng(0)
    half_s = np.sort(rng.choice(source.n_vertices, source.n_vertices // 2, replace=False))
    half_t = np.sort(rng.choice(target.n_vertices, target.n_vertices // 2, replace=False))
    known = truth[half_s] >= 0

    def cloud(mesh, rows=slice(None)):
        normals = orient_faces(mesh).vertex_normals[rows] if mesh_normals else None
        return hamsa.PointCloud(mesh.vertices[rows], normals=normals, **(cloud_options or {}))

    nearest = cKDTree(target.vertices[half_t]).query(target.vertices[np.where(known, truth[half_s], 0)])[1]
    shapes = {
        "mesh": (source, target, truth),
        "cloud": (cloud(source), cloud(target), truth),
        "cloud 50%": (cloud(source, half_s), cloud(target, half_t), np.where(known, nearest, -1)),
    }
    rows = []
    for representation in representations:
        s, t, true_map = shapes[representation]
        start = time.perf_counter()
        result = evaluate_pair(s, t, true_map, k, methods, points, landmarks=3, orientation_weight=orientation)
        seconds = time.perf_counter() - start
        for row in result["rows"]:
            rows.append(
                {"dataset": dataset.name, "pair": f"{source_name}-{target_name}", "representation": representation,
                 "method": row["method"], "basis": row["basis"], "auc": row["auc"],
                 "within_0.05": row["within_0.05"], "seconds": seconds}
            )  # fmt: skip
    return rows


def spectrum_errors(dataset, name: str, variants: dict, k: int = 10) -> dict:
    """Relative errors |E_i(cloud) / E_i(mesh) - 1| of the k lowest nonzero eigenvalues of one shape's vertices
    as a cloud, one (mean, max) per entry {label: PointCloud keywords} of ``variants`` (``normals="mesh"``:
    the mesh's vertex normals, its faces oriented consistently, as a scanner's)."""
    mesh = dataset.load(name, largest_component=True)[0].scaled_to_unit_area()
    on_mesh = hamsa.eigenbasis(mesh, k + 1).values[1:]
    row = {"shape": name, "n": mesh.n_vertices}
    for label, options in variants.items():
        if options.get("normals") == "mesh":
            options = {**options, "normals": orient_faces(mesh).vertex_normals}
        errors = np.abs(hamsa.eigenbasis(hamsa.PointCloud(mesh.vertices, **options), k + 1).values[1:] / on_mesh - 1)
        row[label] = (float(errors.mean()), float(errors.max()))
    return row


def stray_alarms(dataset, seed: int = 0) -> dict:
    """Stray points (:func:`hamsa.pointcloud.stray_points`) among every shape's raw vertices (unreferenced ones
    included) and a seeded random half of them: shapes, points, stray points found, how many of those are
    vertices that no face uses, and how many shapes have any that are not."""
    from hamsa.pointcloud import stray_points

    rng = np.random.default_rng(seed)
    totals = {"shapes": 0, "points": 0, "stray": 0, "unreferenced": 0, "shapes with others": 0}
    for name in dataset.shapes:
        mesh = dataset.load(name, drop_unreferenced=False)[0]
        unreferenced = mesh.unreferenced_vertices
        for subset in (np.arange(mesh.n_vertices), np.flatnonzero(rng.random(mesh.n_vertices) < 0.5)):
            stray = subset[stray_points(mesh.vertices[subset])]
            loose = int(np.isin(stray, unreferenced).sum())
            totals["shapes"] += 1
            totals["points"] += len(subset)
            totals["stray"] += len(stray)
            totals["unreferenced"] += loose
            totals["shapes with others"] += int(loose < len(stray))
    return totals


def stray_detection(points: np.ndarray, bands, count: int = 40, seed: int = 0) -> list[tuple[int, int]]:
    """For each (low, high) band of distances in median point spacings: ``count`` outliers added at seeded random
    places at that distance from the points (a random vertex moved in a random direction, kept when its
    distance to the cloud falls in the band; all of a band at once, at least ``high`` spacings apart), and
    (added, found by :func:`hamsa.pointcloud.stray_points`)."""
    from hamsa.pointcloud import stray_points

    rng = np.random.default_rng(seed)
    tree = cKDTree(points)
    spacing = float(np.median(tree.query(points, 2)[0][:, 1]))
    rows = []
    for low, high in bands:
        chosen: list[np.ndarray] = []
        for _ in range(200 * count):
            direction = rng.standard_normal(3)
            candidate = points[rng.integers(len(points))] + rng.uniform(
                low, high
            ) * spacing * direction / np.linalg.norm(direction)
            if low * spacing <= tree.query(candidate)[0] < high * spacing and all(
                np.linalg.norm(candidate - c) >= high * spacing for c in chosen
            ):
                chosen.append(candidate)
            if len(chosen) == count:
                break
        found = stray_points(np.vstack([points, *chosen])) if chosen else np.zeros(0)
        rows.append((len(chosen), int(np.sum(found >= len(points)))))
    return rows


def sign_errors(dataset, source_name: str, target_name: str, k: int = 100) -> dict:
    """Wrong signs among the matching potential's functions psi_1..psi_4 when the target's are chosen without
    ground truth (:func:`hamsa.matching.resolve_signs_without_truth`), by the HKS moments alone and with the
    chirality term, on the meshes and on their vertices as clouds: {representation: (moments, chirality,
    decided)}, ``decided`` counting the functions whose true sign is clear (|<psi_s, psi_t o map>_A| > 0.5)."""
    from hamsa.matching import resolve_signs, resolve_signs_without_truth

    source, target, truth = unit_area_pair(dataset, source_name, target_name)
    known = truth >= 0
    indices = (1, 2, 3, 4)
    counts = {}
    for representation, shapes in (
        ("mesh", (source, target)),
        ("cloud", (hamsa.PointCloud(source.vertices), hamsa.PointCloud(target.vertices))),
    ):
        bases = [hamsa.eigenbasis(shape, k) for shape in shapes]
        weights = bases[0].mass.diagonal()[known]
        agreement = np.sum(
            weights[:, None] * bases[0].vectors[known][:, 1:5] * bases[1].vectors[truth[known]][:, 1:5], axis=0
        )
        clear = np.abs(agreement) > 0.5
        true_signs = resolve_signs(*bases, truth, indices)
        counts[representation] = tuple(
            int(np.sum((resolve_signs_without_truth(*bases, indices, meshes=meshes) != true_signs) & clear))
            for meshes in (None, shapes)
        ) + (int(clear.sum()),)
    return counts


def build_seconds(points: np.ndarray, repeats: int = 3) -> dict:
    """Median (wall, CPU) seconds over ``repeats`` builds of the operators of the cloud ``points``, BLAS on one
    thread: hamsa's :class:`hamsa.PointCloud` by stage (``normals``, ``local triangles``, ``operators`` from
    them) and in all, and robust_laplacian's ``point_cloud_laplacian`` (the same 30 neighbours, sheets joined)."""
    import robust_laplacian
    from threadpoolctl import threadpool_limits

    stages = ("normals", "local triangles", "operators", "hamsa", "robust_laplacian")
    times = {stage: [] for stage in stages}
    with threadpool_limits(limits=1):
        for _ in range(repeats):
            cloud = hamsa.PointCloud(points)
            clocks = [(time.perf_counter(), time.process_time())]
            for stage in ("normals", "local_triangles", "operators"):
                getattr(cloud, stage)
                clocks.append((time.perf_counter(), time.process_time()))
            robust_laplacian.point_cloud_laplacian(points, n_neighbors=hamsa.pointcloud.DEFAULT_NEIGHBORS)
            clocks.append((time.perf_counter(), time.process_time()))
            spans = np.diff(np.array(clocks), axis=0)
            for stage, span in zip(stages, [*spans[:3], spans[:3].sum(axis=0), spans[3]]):
                times[stage].append(span)
    return {stage: tuple(np.median(np.array(values), axis=0)) for stage, values in times.items()}


def table(rows: list[dict], methods=METHODS) -> tuple[str, list[str], list[str]]:
    """The markdown table of pair means, the bar's failures and the LBO's gaps to the mesh.

    The bar (the point-cloud issue): on every cloud representation and for every method the Hamiltonian's AUC
    is at least the LBO's, and its fraction within 0.05 at most 5 points below the same method's Hamiltonian
    on the mesh. The LBO's own gaps to the mesh are listed apart: they are not part of the bar."""
    lines = [
        "| dataset | method | representation | pairs | LBO AUC | H AUC | LBO within 0.05 | H within 0.05 |",
        "|---|---|---|---|---|---|---|---|",
    ]
    failures, lbo_gaps, mean = [], [], {}
    for dataset in dict.fromkeys(r["dataset"] for r in rows):
        for method in methods:
            for representation in REPRESENTATIONS:
                cell = {}
                for basis in ("lbo", "hamiltonian"):
                    chosen = [r for r in rows if (r["dataset"], r["method"], r["representation"], r["basis"])
                              == (dataset, method, representation, basis)]  # fmt: skip
                    cell[basis] = (
                        (np.mean([r["auc"] for r in chosen]), np.mean([r["within_0.05"] for r in chosen]))
                        if chosen
                        else (np.nan, np.nan)
                    )
                mean[dataset, method, representation] = cell
                (lbo_auc, lbo_within), (h_auc, h_within) = cell["lbo"], cell["hamiltonian"]
                lines.append(
                    f"| {dataset} | {method} | {representation} | {len(chosen)} | {lbo_auc:.3f} | {h_auc:.3f} | "
                    f"{100 * lbo_within:.1f}% | {100 * h_within:.1f}% |"
                )
            for representation in REPRESENTATIONS[1:]:
                cloud, mesh = mean[dataset, method, representation], mean[dataset, method, "mesh"]
                missing = [name for name, cell in ((representation, cloud), ("mesh", mesh)) if np.isnan(cell["lbo"][0])]
                if missing:  # the bar compares both: not checked
                    failures.append(f"{dataset} {method} {representation}: no {' or '.join(missing)} rows to compare")
                    continue
                if cloud["hamiltonian"][0] < cloud["lbo"][0]:
                    failures.append(
                        f"{dataset} {method} {representation}: Hamiltonian AUC {cloud['hamiltonian'][0]:.3f} below "
                        f"the LBO's {cloud['lbo'][0]:.3f}"
                    )
                for basis, found in (("hamiltonian", failures), ("lbo", lbo_gaps)):
                    gap = 100 * (mesh[basis][1] - cloud[basis][1])
                    if gap > 5:
                        found.append(f"{dataset} {method} {representation} {basis}: {gap:.1f} points below the mesh")
    return "\n".join(lines), failures, lbo_gaps


def report(rows: list[dict], methods=METHODS) -> None:
    """Print the table of ``rows`` (SCAPE first), whether the bar is met, and the LBO's gaps to the mesh."""
    text, failures, lbo_gaps = table(sorted(rows, key=lambda r: (r["dataset"] != "scape", r["pair"])), methods)
    print(text)
    print("bar met" if not failures else "bar not met:\n  " + "\n  ".join(failures))
    if lbo_gaps:
        print("the LBO more than 5 points below the mesh (not part of the bar):\n  " + "\n  ".join(lbo_gaps))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scape", type=int, default=5, help="SCAPE pairs: mesh000 -> mesh001..mesh00N (default 5)")
    parser.add_argument("--scape-skip", type=int, default=0, help="start the SCAPE pairs after the first N of them")
    parser.add_argument("--tosca-limit", type=int, default=1, help="TOSCA pairs per class (default 1)")
    parser.add_argument("--tosca-classes", nargs="+", help="only these TOSCA classes (default: all)")
    parser.add_argument("-k", type=int, default=100)
    parser.add_argument("--points", type=int, default=1000)
    parser.add_argument("--jobs", type=int, default=1, help="pairs solved in parallel processes")
    parser.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS))
    parser.add_argument(
        "--representations",
        nargs="+",
        choices=REPRESENTATIONS,
        default=list(REPRESENTATIONS),
        help="only these representations of each pair (default: all three)",
    )
    parser.add_argument(
        "--orientation", type=float, default=0.0, help="orientation-term weight of fmap's start map (default 0)"
    )
    sheets = parser.add_mutually_exclusive_group()
    sheets.add_argument(
        "--joined-sheets",
        action="store_true",
        help="clouds with robust_laplacian's point-cloud Laplacian (PointCloud(separate_sheets=False))",
    )
    sheets.add_argument(
        "--off-sheet",
        type=float,
        help="PointCloud(off_sheet=X): also leave out the neighbours X local spacings off a point's smooth sheet",
    )
    parser.add_argument(
        "--mesh-normals",
        action="store_true",
        help="the clouds take their meshes' vertex normals (PointCloud(normals=)), as a scanner's normals",
    )
    parser.add_argument(
        "--spectra",
        nargs="+",
        metavar="SHAPE",
        help="instead of matching: the 10 lowest eigenvalues of these shapes (SCAPE meshNNN, TOSCA names) as "
        "clouds against their meshes: sheets separated by the normals, also off the sheet (--off-sheet, default 0.7), "
        "joined, and separated by the mesh's normals",
    )
    parser.add_argument(
        "--signs",
        nargs="+",
        metavar="SOURCE:TARGET",
        help="instead of matching: the wrong signs of the matching potential's functions chosen without ground "
        "truth on these pairs (e.g. mesh000:mesh004 cat0:cat1), meshes and clouds, moments alone and with chirality",
    )
    parser.add_argument(
        "--build",
        nargs="+",
        type=int,
        metavar="N",
        help="instead of matching: the seconds of building the operators of N sphere samples (and of TOSCA "
        "david0's vertices when the data is there), hamsa's stages against robust_laplacian's point-cloud Laplacian",
    )
    parser.add_argument(
        "--strays",
        action="store_true",
        help="instead of matching: stray points among every SCAPE and TOSCA vertex set and a random half of each "
        "(false alarms), and the outliers found at each distance from the built-in humanoid and SCAPE mesh000",
    )
    parser.add_argument(
        "--table",
        nargs="+",
        metavar="JSON",
        help="instead of matching: the table and the bar of rows written by earlier runs (-o), joined (a later "
        "file's row replaces an earlier one's for the same pair, representation, method and basis)",
    )
    parser.add_argument("-o", "--output", help="write the rows as JSON (after every pair)")
    args = parser.parse_args(argv)
    if args.table:
        keyed = {}  # a later file's row replaces an earlier one's of the same pair, representation, method, basis
        for name in args.table:
            for row in json.loads(Path(name).read_text()):
                keyed[row["dataset"], row["pair"], row["representation"], row["method"], row["basis"]] = row
        rows = list(keyed.values())
        report(rows, [m for m in METHODS if any(r["method"] == m for r in rows)])
        return 0
    if args.build:
        clouds = {f"sphere {n}": hamsa.shapes.sphere(n).vertices for n in args.build}
        if DATA.is_dir():
            clouds["TOSCA david0"] = load_tosca(DATA / "tosca_hires").load("david0")[0].vertices
        print(f"hamsa {hamsa.__version__}, one BLAS thread, median of 3 builds: wall / CPU seconds")
        print("| cloud | normals | local triangles | operators | hamsa | robust_laplacian | ratio (wall) |")
        print("|---|---|---|---|---|---|---|")
        for label, points in clouds.items():
            seconds = build_seconds(points)
            cells = " | ".join(f"{wall:.2f} / {cpu:.2f}" for wall, cpu in seconds.values())
            ratio = seconds["hamsa"][0] / seconds["robust_laplacian"][0]
            print(f"| {label} | {cells} | {ratio:.2f} |", flush=True)
        return 0
    if not DATA.is_dir():
        print(f"needs the shared datasets at {DATA}")
        return 1
    scape, tosca = load_scape(DATA / "scape"), load_tosca(DATA / "tosca_hires")
    if args.strays:
        print(
            f"hamsa {hamsa.__version__}: stray points among the raw vertices (unreferenced included) and a random half"
        )
        print("| dataset | clouds | points | stray found | of them unreferenced vertices | clouds with other stray |")
        print("|---|---|---|---|---|---|")
        for dataset in (scape, tosca):
            t = stray_alarms(dataset)
            print(f"| {dataset.name} | {t['shapes']} | {t['points']} | {t['stray']} | {t['unreferenced']} | "
                  f"{t['shapes with others']} |", flush=True)  # fmt: skip
        bands = ((3, 5), (5, 10), (10, 15), (15, 20), (20, 40))
        print("\noutliers added at a distance from the cloud (median spacings), 40 per band, and found")
        print(f"| cloud | {' | '.join(f'{low}-{high}' for low, high in bands)} |")
        print(f"|---|{'---|' * len(bands)}")
        clouds = {
            "humanoid (built-in)": hamsa.shapes.humanoid().vertices,
            "SCAPE mesh000": scape.load("mesh000")[0].vertices,
        }
        for label, points in clouds.items():
            cells = " | ".join(f"{found} / {added}" for added, found in stray_detection(points, bands))
            print(f"| {label} | {cells} |", flush=True)
        return 0
    if args.spectra:
        off_sheet = args.off_sheet or 0.7
        variants = {
            "separated (normals)": {},
            f"off_sheet={off_sheet:g}": {"off_sheet": off_sheet},
            "joined (robust_laplacian)": {"separate_sheets": False},
            "the mesh's normals": {"normals": "mesh"},
        }
        print(f"| shape | n | {' | '.join(f'{label}: mean / max rel. error' for label in variants)} |")
        print(f"|---|---|{'---|' * len(variants)}")
        for name in args.spectra:
            row = spectrum_errors(scape if name.startswith("mesh") else tosca, name, variants)
            cells = " | ".join(f"{row[label][0]:.3f} / {row[label][1]:.3f}" for label in variants)
            print(f"| {name} | {row['n']} | {cells} |", flush=True)
        return 0
    if args.signs:
        print("| pair | mesh: moments / with chirality | cloud: moments / with chirality | clear (mesh / cloud) |")
        print("|---|---|---|---|")
        total = np.zeros(6, dtype=int)
        for pair in args.signs:
            source_name, target_name = pair.split(":")
            counts = sign_errors(scape if source_name.startswith("mesh") else tosca, source_name, target_name, args.k)
            (mesh_m, mesh_c, mesh_n), (cloud_m, cloud_c, cloud_n) = counts["mesh"], counts["cloud"]
            total += [mesh_m, mesh_c, cloud_m, cloud_c, mesh_n, cloud_n]
            print(f"| {pair} | {mesh_m} / {mesh_c} | {cloud_m} / {cloud_c} | {mesh_n} / {cloud_n} |", flush=True)
        print(f"| total | {total[0]} / {total[1]} | {total[2]} / {total[3]} | {total[4]} / {total[5]} |")
        return 0
    work = [(scape, *p) for p in dataset_pairs(scape)[args.scape_skip : args.scape_skip + args.scape]]
    work += [
        (tosca, *p)
        for p in dataset_pairs(tosca, args.tosca_limit)
        if args.tosca_classes is None or tosca.classes[p[0]] in args.tosca_classes
    ]
    from joblib import Parallel, delayed

    cloud_options = {"separate_sheets": not args.joined_sheets, "off_sheet": args.off_sheet}
    start = time.perf_counter()
    results = Parallel(n_jobs=args.jobs, return_as="generator_unordered")(
        delayed(pair_scores)(
            dataset,
            s,
            t,
            args.k,
            args.points,
            args.methods,
            args.orientation,
            cloud_options,
            args.representations,
            args.mesh_normals,
        )
        for dataset, s, t in work
    )
    rows = []
    for pair_rows in results:
        rows += pair_rows
        print(f"  {pair_rows[0]['dataset']} {pair_rows[0]['pair']} done", file=sys.stderr, flush=True)
        if args.output:  # the pairs so far, so that a long run stopped early keeps them
            with atomic_write(args.output, "w") as handle:
                handle.write(json.dumps(rows, indent=1))
    print(f"hamsa {hamsa.__version__}, {len(work)} pairs, {time.perf_counter() - start:.0f} s wall")
    report(rows, args.methods)
    return 0


if __name__ == "__main__":
    sys.exit(main())
