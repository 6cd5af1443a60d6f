"""The ``hamsa`` command-line tool.

Bad input exits with code 2 and one line on stderr naming the problem (no traceback), and never
leaves a partial output file behind (outputs are written to a temporary file, then renamed).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import signal
import sys
import threading
import time
import warnings
from pathlib import Path
from typing import NamedTuple

import numpy as np

from hamsa import __version__
from hamsa.errors import ConvergenceError, HamsaError, MeshError

EXIT_BAD_INPUT = 2
EXIT_SOLVER_FAILED = 3


def _integer_at_least(least: int):
    """An argparse type: an integer >= ``least``, refused with the value named otherwise."""
    wanted = "a positive integer" if least == 1 else f"an integer >= {least}"

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {wanted}, got '{text}'") from None
        if value < least:
            raise argparse.ArgumentTypeError(f"expected {wanted}, got {value}")
        return value

    return parse


_positive_int = _integer_at_least(1)
_nonnegative_int = _integer_at_least(0)


def _nonnegative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got '{text}'") from None
    if not (np.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {value}")
    return value


REPAIR_HELP = (
    "fix what has one right fix (duplicate or degenerate faces, non-manifold vertices, orientation, unreferenced "
    "vertices) and keep the largest connected component, instead of refusing the mesh; of a point cloud, drop "
    "the points with NaN coordinates, repeated points and stray points far off the surface, and keep its largest "
    "piece"
)


POTENTIAL_HELP = (
    "potential V: a specification [SCALE*]KIND:ARGS -- geodesic:I[,J..] (distance from vertices, in [0, 1]), "
    "step:AXIS>VALUE or step:AXIS<VALUE (1 there, 0 elsewhere; coordinates as in the file), eigsum:I-J (sum of "
    "LBO eigenfunctions I..J, 0-based: eigsum:1-4 is the paper's matching potential), curvature:mean|gaussian, "
    "texture:FILE (luminance of FILE's vertex colours in [0, 1]: PLY red/green/blue, COFF, OBJ v x y z r g b) -- "
    "e.g. 100*geodesic:12,40; or a .npy / text file with one value per vertex (of the input, also with --repair)"
)


GEODESICS_HELP = (
    "distances that score the maps: heat (the heat method, fast, first-order accurate) or exact (polyhedral "
    "geodesics as in the published curves; the [geodesics] extra, much slower)"
)
COMMUTATIVITY_HELP = (
    "descriptor-commutativity weight of the functional map that starts fmap (and sgfe), and of ICSKM's landmark fit: "
    "||C M_g - M_f C||^2 over the descriptor columns (default {default:g}, chosen for fmap on half of the SCAPE pairs; "
    "0: the plain descriptor fit)"
)
ORIENTATION_HELP = (
    "orientation-preserving weight of that functional map, which tells a map from its mirror image (a left-right "
    "symmetric shape's descriptors cannot), kept only where it gives the better oriented map; meshes' faces are "
    "oriented consistently first, point clouds' normals estimated (default 0; 0.03 is the measured weight)"
)
POINTS_HELP = "a point cloud (.xyz .pts .txt .csv .pcd .npy, or a .ply / .off / .obj without faces)"


class _Loaded(NamedTuple):
    """A mesh fit for spectral work; after ``--repair``, ``vertex_ids`` (n,) gives the input vertex of each of
    its vertices (None when the mesh is the input's), and ``input_vertices`` is the input's vertex count."""

    mesh: object
    vertex_ids: np.ndarray | None
    input_vertices: int


def _add_basis_options(command, k: int | None) -> None:
    """--repair, -k, --potential and --basis of a command that works on an eigenbasis (:func:`_basis_for`);
    ``k`` the default of -k (None: the least the command needs)."""
    command.add_argument("--repair", action="store_true", help=REPAIR_HELP + " (as when --basis was computed)")
    default = f"default {k}" if k else "default: as many as the command needs"
    command.add_argument("-k", type=_positive_int, default=k, help=f"eigenpairs computed ({default})")
    command.add_argument("--potential", help=POTENTIAL_HELP)
    command.add_argument("--basis", help="use a saved basis (.npz of hamsa basis) of MESH instead of computing one")


def _add_cloud_options(command) -> None:
    """How the operators of a point file are built (``PointCloud(neighbors=, separate_sheets=)``)."""
    from hamsa.pointcloud import DEFAULT_NEIGHBORS

    group = command.add_argument_group("point clouds")
    group.add_argument(
        "--neighbors",
        type=_positive_int,
        help=f"nearest points in each point's local triangulation (default {DEFAULT_NEIGHBORS}; at least 3)",
    )
    group.add_argument(
        "--joined-sheets",
        action="store_true",
        help="also join the neighbours on the facing sides of nearly touching parts (robust_laplacian's operator; "
        "by default they are left out where the estimated outward normals point apart): for clouds whose normals "
        "cannot be oriented, such as open scans; hamsa info counts the pairs left out",
    )
    group.add_argument(
        "--off-sheet",
        type=float,
        metavar="SPACINGS",
        help="also leave out the neighbours this many local spacings off a point's smooth sheet, whatever the "
        "normals say (e.g. 0.7: parts touching over a wide area, such as hands on thighs; default: off)",
    )
    group.add_argument(
        "--estimate-normals",
        action="store_true",
        help="estimate the normals even when the point file holds some (PLY nx ny nz, NOFF, OBJ vn, XYZ columns "
        "4-6 of unit length; by default those are used, their signs trusted)",
    )


def _cloud_options(args) -> dict:
    """The point-cloud keywords of :func:`hamsa.io.load_shape` in ``args`` (of :func:`_add_cloud_options`)."""
    from hamsa.pointcloud import DEFAULT_NEIGHBORS

    return {
        "neighbors": args.neighbors or DEFAULT_NEIGHBORS,
        "separate_sheets": not args.joined_sheets,
        "off_sheet": args.off_sheet,
        "file_normals": not args.estimate_normals,
    }


def _repaired_cloud(points: np.ndarray, normals: np.ndarray | None, cloud: dict, keep: str = "all"):
    """:func:`hamsa.repair.repair_point_cloud` of a point file's points and normals (from
    :func:`hamsa.io.read_shape_arrays`, asked for when ``cloud["file_normals"]``) with the other
    :func:`_cloud_options` of ``cloud`` (and ``modes``, from ``hamsa repair``)."""
    from hamsa.repair import repair_point_cloud

    options = {name: value for name, value in cloud.items() if name != "file_normals"}
    return repair_point_cloud(points, keep=keep, normals=normals, **options)


def _check_cloud_options(args, *shapes) -> None:
    """Refuses the point-cloud options (--neighbors, --off-sheet, ...) when no loaded shape is a point cloud, and
    --off-sheet with --joined-sheets (nothing is left out then)."""
    from hamsa.pointcloud import PointCloud

    options = (
        ("--neighbors", args.neighbors),
        ("--joined-sheets", args.joined_sheets),
        ("--off-sheet", args.off_sheet),
        ("--estimate-normals", args.estimate_normals),
    )
    given = [name for name, value in options if value is not None and value is not False]
    if args.joined_sheets and args.off_sheet is not None:
        raise HamsaError("--off-sheet leaves out neighbours, --joined-sheets keeps them all: choose one")
    if given and not any(isinstance(shape, PointCloud) for shape in shapes):
        raise HamsaError(f"{' and '.join(given)}: for point clouds, and no input here is one")


def _load_for_operators(path: str, repair: bool, laplacian: str | None = None, cloud: dict | None = None) -> _Loaded:
    """The mesh (or point cloud) of ``path`` for every command, by one policy. Refused (a MeshError naming the
    CLI option that fixes it) when the numbers would be wrong: unreferenced vertices (no area, so a singular
    mass matrix) and edges shared by more than two faces (the cotan Laplacian is undefined there; ``--laplacian
    tufted`` takes them). Accepted with a warning on stderr when it is only unusual: non-manifold vertices,
    faces not consistently oriented (the spectrum does not depend on it; normals do) and several pieces
    (each has its own spectrum). A point file (.xyz, .npy, a PLY without faces, ...) gives a PointCloud, built
    with the keywords ``cloud`` (:func:`_cloud_options`)."""
    from hamsa.io import load_shape
    from hamsa.pointcloud import PointCloud

    if repair:
        repaired, report = _repaired_file(path, cloud or {"file_normals": True}, keep="largest")
        if report.changed:
            print(f"{path}: {report}; outputs give input vertex ids ('vertex_ids')")
        return repaired
    tufted = laplacian == "tufted"
    mesh = load_shape(path, manifold=not tufted, **(cloud or {}))
    if not isinstance(mesh, PointCloud) and len(mesh.unreferenced_vertices):
        raise MeshError(
            f"'{path}' has {len(mesh.unreferenced_vertices)} unreferenced vertices (no area: the mass matrix would "
            "be singular); --repair drops them and keeps the way back to the input's vertex ids"
        )
    for warning in _unusual(mesh, tufted):
        print(f"warning: '{path}' {warning}", file=sys.stderr)
    return _Loaded(mesh, None, mesh.n_vertices)


def _repaired_file(path: str, cloud: dict, keep: str):
    """(the :class:`_Loaded` shape of ``path`` after :func:`hamsa.repair.repair_mesh` or, for a point file,
    :func:`hamsa.repair.repair_point_cloud` with the :func:`_cloud_options` ``cloud``; the repair report).
    ``vertex_ids`` is None when nothing changed."""
    from hamsa.io import read_shape_arrays
    from hamsa.repair import repair_mesh

    vertices, faces, normals = read_shape_arrays(path, normals=cloud["file_normals"])
    if faces is None:
        shape, kept, report = _repaired_cloud(vertices, normals, cloud, keep=keep)
    else:
        shape, kept, report = repair_mesh(vertices, faces, keep=keep)
    return _Loaded(shape, kept if report.changed else None, len(vertices)), report


def _unusual(mesh, tufted: bool) -> list[str]:
    """What is unusual about a mesh or a point cloud but still gives right numbers, each with the option that
    changes it."""
    from hamsa.pointcloud import PointCloud

    notes = []
    if not isinstance(mesh, PointCloud) and not tufted:
        if mesh.non_manifold_vertices.size:
            notes.append(
                f"has {mesh.non_manifold_vertices.size} non-manifold vertices (first: "
                f"{int(mesh.non_manifold_vertices[0])}; separate fans of faces meet there); the operators are "
                "defined, --repair splits them (new vertex ids)"
            )
        if not mesh.is_consistently_oriented:
            notes.append(
                "has faces that are not consistently oriented; the spectrum is unaffected, --repair orients them"
            )
    count, labels = mesh.vertex_components
    if count > 1:
        sizes = np.sort(np.bincount(labels[labels >= 0]))[::-1]
        notes.append(
            f"has {count} disconnected pieces ({', '.join(map(str, sizes[:5]))}{', ...' if count > 5 else ''} "
            f"{'points' if isinstance(mesh, PointCloud) else 'vertices'}), each with its own spectrum; --repair "
            "keeps the largest"
        )
    return notes


def _parser() -> argparse.ArgumentParser:
    from hamsa.geodesic import GEODESIC_METHODS
    from hamsa.matching.functional import COMMUTATIVITY_WEIGHT
    from hamsa.paper.benchmark import METHODS as BENCHMARK_METHODS

    parser = argparse.ArgumentParser(
        prog="hamsa",
        description="Hamiltonian spectral shape analysis: eigenbases of -Laplacian + V on meshes and point clouds.",
    )
    parser.add_argument("--version", action="version", version=f"hamsa {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    info = commands.add_parser(
        "info", help="describe a mesh or a point cloud: size, area, components, boundaries, defects"
    )
    info.add_argument("mesh", help=f"mesh file (.off .obj .ply .stl, optionally .gz) or {POINTS_HELP}")
    _add_cloud_options(info)

    repair = commands.add_parser("repair", help="write a repaired copy of a mesh or point file, and its vertex ids")
    repair.add_argument("mesh", help=f"mesh file (.off .obj .ply .stl, optionally .gz) or {POINTS_HELP}")
    repair.add_argument(
        "--all-pieces", action="store_true", help="keep every connected piece (default: the largest, as --repair)"
    )
    repair.add_argument(
        "--ids", help="also write a .npy with the input vertex id of each output vertex (row i came from ids[i])"
    )
    repair.add_argument(
        "--modes",
        type=_positive_int,
        metavar="K",
        help="of a point cloud, also drop the points that eigenpairs among the K lowest live on alone (fewer than "
        "50 points each: points just off the surface, patches of normals with the wrong sign; the warning of "
        "basis names them); one to three eigensolves",
    )
    repair.add_argument(
        "-o",
        "--output",
        required=True,
        help="output mesh (.off .obj .ply .stl) or, for a point file, points (.xyz .txt .pts .csv .ply .npy)",
    )
    _add_cloud_options(repair)

    basis = commands.add_parser("basis", help="compute the k smallest eigenpairs of W + A diag(V) and save them")
    basis.add_argument("mesh", help=f"mesh file (.off .obj .ply .stl, optionally .gz) or {POINTS_HELP}")
    basis.add_argument("--repair", action="store_true", help=REPAIR_HELP)
    basis.add_argument(
        "-k", type=_positive_int, default=100, help="number of eigenpairs (default 100, as match, benchmark-matching)"
    )
    basis.add_argument("--potential", help=POTENTIAL_HELP)
    basis.add_argument("--mass", choices=("voronoi", "barycentric", "full"), default="voronoi")
    basis.add_argument("--backend", choices=("auto", "cholmod", "superlu"), default="auto")
    basis.add_argument(
        "--laplacian",
        choices=("cotan", "intrinsic_delaunay", "tufted", "point_cloud"),
        help="default: cotan for a mesh, point_cloud for a point file; intrinsic_delaunay: robust to needles and "
        "obtuse triangles; tufted: also meshes with non-manifold edges or vertices, taken as they are (both need "
        "the [robust] extra)",
    )
    basis.add_argument(
        "--boundary",
        default="neumann",
        help="neumann (default), dirichlet (psi = 0 on the mesh's boundary), or a .npy / text file of the vertex "
        "ids to hold at psi = 0",
    )
    basis.add_argument(
        "--device", choices=("cpu", "cuda"), default="cpu", help="cuda: solve on an NVIDIA GPU (CuPy; [gpu-cuda12])"
    )
    basis.add_argument("-o", "--output", required=True, help="output .npz (see hamsa.Eigenbasis.load)")
    _add_cloud_options(basis)

    optimize = commands.add_parser(
        "optimize", help="optimize the potential whose k eigenvectors best represent data (paper 3)"
    )
    optimize.add_argument("mesh", help=f"mesh file (.off .obj .ply .stl, optionally .gz) or {POINTS_HELP}")
    optimize.add_argument("--repair", action="store_true", help=REPAIR_HELP)
    optimize.add_argument("-k", type=_positive_int, required=True, help="number of eigenvectors")
    optimize.add_argument(
        "--data",
        help="(n,) or (n, d) .npy to represent, one row per vertex (of the input, with --repair; default: the vertex "
        "coordinates)",
    )
    optimize.add_argument(
        "-m", type=_positive_int, help="LBO eigenvectors of the reduced problem (default max(4k, k+100))"
    )
    optimize.add_argument(
        "--iterations", type=_positive_int, help="L-BFGS iterations in all (default 150; 200 with --plain)"
    )
    optimize.add_argument(
        "--plain",
        action="store_true",
        help="the paper's plain L-BFGS: no smoothed stages, one round (faster; stalls where eigenvalues cross)",
    )
    optimize.add_argument("--square", action="store_true", help="optimize V = v^2 >= 0 instead of a signed V")
    optimize.add_argument(
        "--center",
        action="store_true",
        help="remove the data's (area-weighted) mean first: the result no longer depends on where the shape sits",
    )
    optimize.add_argument("-o", "--output", required=True, help="output .npy with the potential")
    _add_cloud_options(optimize)

    compress = commands.add_parser("compress", help="spectral geometry compression (Karni-Gotsman / Hamiltonian)")
    compress.add_argument("mesh", help="mesh file (.off .obj .ply .stl, optionally .gz)")
    compress.add_argument("--repair", action="store_true", help=REPAIR_HELP)
    compress.add_argument("-o", "--output", required=True, help="output .hmz")
    compress.add_argument("-k", type=_positive_int, required=True, help="basis functions (coefficients per coordinate)")
    compress.add_argument("--bits", type=_positive_int, default=12, help="bits per coefficient (default 12)")
    compress.add_argument("--method", choices=("mhb", "hamiltonian", "hamiltonian-opt"), default="mhb")

    decompress = commands.add_parser("decompress", help="rebuild a mesh from an .hmz file and the connectivity")
    decompress.add_argument("compressed", help="the .hmz file")
    decompress.add_argument(
        "--faces", required=True, help="a mesh file with the connectivity (its coordinates are ignored)"
    )
    decompress.add_argument("-o", "--output", required=True, help="output mesh file")

    modes = commands.add_parser("modes", help="compressed manifold modes by IRLS Hamiltonian eigenproblems (paper 4)")
    modes.add_argument("mesh", help=f"mesh file (.off .obj .ply .stl, optionally .gz) or {POINTS_HELP}")
    modes.add_argument("--repair", action="store_true", help=REPAIR_HELP)
    modes.add_argument("-k", type=_positive_int, required=True, help="number of modes")
    modes.add_argument("--mu", type=float, required=True, help="L1 weight (for a unit-area mesh, 10-500)")
    modes.add_argument("--method", choices=("hamiltonian", "admm"), default="hamiltonian")
    modes.add_argument("--unit-area", action="store_true", help="scale the mesh to unit area first")
    modes.add_argument("-o", "--output", required=True, help="output .npz (modes, objective, mu)")
    _add_cloud_options(modes)

    match = commands.add_parser("match", help="a dense vertex map from SOURCE to TARGET (descriptors, functional maps)")
    match.add_argument("source", help=f"source mesh file or {POINTS_HELP}")
    match.add_argument("target", help=f"target mesh file or {POINTS_HELP}")
    match.add_argument(
        "--method",
        choices=("fmap", "hks", "wks", "icskm", "sgfe"),
        default="fmap",
        help="fmap: HKS-fitted functional map + ICP + ZoomOut (default); hks / wks: descriptor nearest neighbours; "
        "icskm: iterative closest spectral kernel maps from --landmarks; sgfe: spectral gradient fields embedding "
        "from the fmap start (triangle meshes only)",
    )
    match.add_argument(
        "--landmarks",
        nargs="+",
        metavar="S:T",
        help="known pairs 'source_vertex:target_vertex' (0-based), e.g. --landmarks 12:40 300:310: needed by icskm; "
        "fmap adds their heat kernel maps to its descriptors",
    )
    match.add_argument(
        "--landmark-scale",
        type=float,
        default=1.0,
        help="icskm: scale s of the Hamiltonian basis, V = s x geodesic distance from the landmarks in [0, 1] "
        "(default 1; 0 = the LBO)",
    )
    match.add_argument(
        "--basis",
        choices=("hamiltonian", "lbo"),
        default="hamiltonian",
        help="fmap, hks, wks, sgfe: the Hamiltonian basis with the paper's matching potential (sum of phi_2..phi_5, "
        "its signs made consistent from the shapes alone, no ground truth; default) or the plain LBO basis",
    )
    match.add_argument(
        "--repair",
        action="store_true",
        help=REPAIR_HELP + "; the map is saved in the inputs' vertex ids (-1 for source vertices removed)",
    )
    match.add_argument(
        "--source-potential",
        metavar="POTENTIAL",
        help="with --target-potential: the Hamiltonian bases of these potentials instead of --basis (any method); "
        "each is a specification or a file as in 'hamsa basis --potential', evaluated on the mesh as read (e.g. "
        "100*geodesic:12 and 100*geodesic:40 for one known pair)",
    )
    match.add_argument("--target-potential", metavar="POTENTIAL", help="the target's, see --source-potential")
    match.add_argument(
        "--truth",
        help="score the map by the Kim et al. protocol against this ground truth: 'identity' (vertex i <-> i) or a "
        ".npy / text file of target vertex ids per source vertex (-1: unknown); prints the scores and writes them "
        "with the curve to --scores",
    )
    match.add_argument("--points", type=_positive_int, default=1000, help="--truth: scored vertices (default 1000)")
    match.add_argument("--geodesics", choices=GEODESIC_METHODS, default="heat", help=GEODESICS_HELP)
    match.add_argument(
        "--commutativity",
        type=_nonnegative_float,
        default=COMMUTATIVITY_WEIGHT,
        help=COMMUTATIVITY_HELP.format(default=COMMUTATIVITY_WEIGHT),
    )
    match.add_argument("--orientation", type=_nonnegative_float, default=0.0, help=ORIENTATION_HELP)
    match.add_argument("--scores", help="--truth: output .json (default: the output's name with .scores.json)")
    match.add_argument("--fmap", help="also save the functional map C (k x k, source rows) of the final map as .npy")
    match.add_argument(
        "-k",
        type=_positive_int,
        default=100,
        help="eigenpairs of each shape (default 100, as benchmark-matching and the paper; fmap needs >= 20, wks >= 60)",
    )
    match.add_argument("-o", "--output", required=True, help="output .npy: for each source vertex, a target vertex")
    _add_cloud_options(match)

    bench = commands.add_parser(
        "benchmark-matching", help="every evaluation pair of a dataset, LBO vs Hamiltonian, Kim et al. table"
    )
    bench.add_argument("dataset", help="dataset folder (TOSCA or SCAPE layout, or a folder of meshes)")
    bench.add_argument("--kind", choices=("auto", "tosca", "scape", "folder"), default="auto")
    bench.add_argument(
        "--method",
        nargs="+",
        choices=BENCHMARK_METHODS,
        default=list(BENCHMARK_METHODS),
        help="hks, wks: descriptor nearest neighbours; fmap: functional map + ICP + ZoomOut; icskm: the paper's "
        "ICSKM from --landmarks ground-truth pairs; icskm_geo: the same plus geodesic distances from the landmarks "
        "as features; sgfe: spectral gradient fields (with --oracle: the area-distortion potential); texture: HKS "
        "with a synthetic dalmatian-coat potential carried by the ground truth (default: all)",
    )
    bench.add_argument(
        "--landmarks",
        type=_positive_int,
        default=3,
        help="icskm, icskm_geo: ground-truth landmark pairs per pair (default 3)",
    )
    bench.add_argument(
        "--draws",
        type=_positive_int,
        default=1,
        help="icskm, icskm_geo: independent random landmark draws per pair, errors pooled (default 1)",
    )
    bench.add_argument(
        "--landmark-scale",
        type=float,
        default=1.0,
        help="icskm, icskm_geo: scale s of the Hamiltonian's landmark potential, s x geodesic distance from the "
        "landmarks in [0, 1] on the unit-area shape (default 1)",
    )
    bench.add_argument(
        "--eigensum-scale",
        type=float,
        default=1.0,
        help="hks/wks/fmap/sgfe: scale of the matching potential (normalized sum of phi_2..phi_5 in [0, 1]; default 1)",
    )
    bench.add_argument(
        "--oracle",
        action="store_true",
        help="build the Hamiltonians' potentials from the ground truth, as the paper does (the eigenfunction sum's "
        "signs, SGFE's area distortion); default: from the shapes alone, the truth only scores",
    )
    bench.add_argument("-k", type=_positive_int, default=100, help="eigenpairs per basis (default 100)")
    bench.add_argument("--points", type=_positive_int, default=1000, help="evaluated vertices per pair (default 1000)")
    bench.add_argument("--geodesics", choices=GEODESIC_METHODS, default="heat", help=GEODESICS_HELP)
    bench.add_argument(
        "--commutativity",
        type=_nonnegative_float,
        default=COMMUTATIVITY_WEIGHT,
        help=COMMUTATIVITY_HELP.format(default=COMMUTATIVITY_WEIGHT),
    )
    bench.add_argument("--orientation", type=_nonnegative_float, default=0.0, help=ORIENTATION_HELP)
    bench.add_argument("--jobs", type=_positive_int, default=1, help="parallel worker processes (default 1)")
    bench.add_argument("--limit", type=_positive_int, help="at most this many pairs per class (a quick look)")
    bench.add_argument("--scheduler", help="Dask scheduler address: run the pairs on that cluster")
    bench.add_argument("-o", "--output", required=True, help="results folder (resumable: finished pairs are kept)")

    view = commands.add_parser(
        "view", help="an interactive HTML page: eigenfunctions, a saved basis, fields, modes, or a map (colours)"
    )
    view.add_argument("mesh", help=f"mesh file (OFF, OBJ, PLY, STL; .gz too) or {POINTS_HELP}")
    view.add_argument("--repair", action="store_true", help=REPAIR_HELP + " (as when the shown file was computed)")
    view.add_argument("-k", type=_positive_int, default=10, help="eigenfunctions (or modes) to show (default 10)")
    view.add_argument("--potential", help=POTENTIAL_HELP + "; shown first, then the Hamiltonian's eigenfunctions")
    shown = view.add_mutually_exclusive_group()
    shown.add_argument("--basis", help="show the eigenfunctions of a saved basis (.npz of hamsa basis) of MESH")
    shown.add_argument("--field", nargs="+", metavar="F.npy", help="show per-vertex fields (.npy: (n,) or (n, m))")
    shown.add_argument("--modes", help="show the compressed modes of a .npz of hamsa modes")
    shown.add_argument(
        "--map",
        help="show a map (.npy of hamsa match) from MESH to --target: target coloured by position, MESH by "
        "the colours of its images",
    )
    view.add_argument("--target", help="--map: the target mesh")
    view.add_argument(
        "--constant", action="store_true", help="also show a constant first eigenfunction (skipped by default)"
    )
    view.add_argument("-o", "--output", required=True, help="output .html (self-contained, opens offline)")
    _add_cloud_options(view)

    signature = commands.add_parser(
        "signature", help="heat or wave kernel signatures (HKS / WKS) of every vertex, saved as .npy"
    )
    signature.add_argument("mesh", help=f"mesh file (.off .obj .ply .stl, optionally .gz) or {POINTS_HELP}")
    signature.add_argument("--kind", choices=("hks", "wks"), default="hks", help="default hks")
    signature.add_argument(
        "--count",
        type=_positive_int,
        default=100,
        help="time scales (hks: geometric over the spectrum, Sun et al.) or log-energies (wks: Aubry et al.) "
        "(default 100)",
    )
    signature.add_argument(
        "--scaled", action="store_true", help="hks: each time's column divided by the heat trace (across shapes)"
    )
    _add_basis_options(signature, 100)
    signature.add_argument("-o", "--output", required=True, help="output .npy, (vertices, count)")
    _add_cloud_options(signature)

    segment = commands.add_parser(
        "segment", help="segments of a mesh or point cloud: the nodal domains of one eigenfunction"
    )
    segment.add_argument("mesh", help=f"mesh file (.off .obj .ply .stl, optionally .gz) or {POINTS_HELP}")
    segment.add_argument(
        "--index", type=_nonnegative_int, required=True, help="the eigenfunction: its 0-based column in the basis"
    )
    segment.add_argument(
        "--min-vertices",
        type=_positive_int,
        default=1,
        help="smaller domains join the neighbouring segment they share most edges with (default 1: none)",
    )
    _add_basis_options(segment, None)
    segment.add_argument("-o", "--output", required=True, help="output .npy of one segment label per vertex")
    _add_cloud_options(segment)

    reproduce = commands.add_parser(
        "reproduce", help="run every experiment of the paper and write report/index.html + results.json"
    )
    reproduce.add_argument(
        "--data",
        help="data folder with tosca_hires/, scape/ and classic/ (see docs/reproduce.md); default: built-in shapes",
    )
    reproduce.add_argument("--quick", action="store_true", help="smaller sizes: a few minutes on 2 cores")
    reproduce.add_argument("--force", action="store_true", help="re-run experiments whose cached results are intact")
    reproduce.add_argument(
        "--only", nargs="+", metavar="NAME", help="experiments to run (names or prefixes: fig2 fig7)"
    )
    reproduce.add_argument("-o", "--output", default="report", help="report folder (default: report)")
    commands.add_parser("config", help="versions, the sparse factorization and BLAS in use, threads, GPU")
    demo = commands.add_parser("demo", help="the step-potential experiment (paper Fig. 2) on a built-in surface")
    demo.add_argument("-k", type=_positive_int, default=12, help="number of eigenpairs (default 12)")
    demo.add_argument("--height", type=float, help="step height V0 (default: the 8th LBO eigenvalue)")
    for command in commands.choices.values():
        command.add_argument("-q", "--quiet", action="store_true", help="no progress output on stderr")
    return parser


class _Steps:
    """The steps of a long command as one progress line on stderr (the current step and the time so far);
    silent with ``--quiet`` or when stderr is not a terminal. ``steps("name")`` starts the next step."""

    def __init__(self, args, total: int):
        from tqdm import tqdm

        quiet = getattr(args, "quiet", False) or not sys.stderr.isatty()
        self.bar = tqdm(total=total, disable=quiet, file=sys.stderr, leave=False,
                        bar_format="{desc} ({n}/{total}, {elapsed}){postfix}")  # fmt: skip
        self.started = False

    def __call__(self, name: str) -> None:
        if self.started:
            self.bar.update()
        self.started = True
        self.bar.set_postfix_str("", refresh=False)
        self.bar.set_description_str(name)

    def counter(self, unit: str):
        """A ``progress(done, total)`` callback that ends the current step's line with "done/total unit"."""
        return lambda done, total: self.bar.set_postfix_str(f"{done}/{total} {unit}")

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.bar.close()


def _potential_file(text: str | None) -> str | None:
    """The file named by a ``--potential`` option, None for a specification or no option."""
    from hamsa.potentials import is_spec

    return None if text is None or is_spec(text) else text


def _potential(text: str | None, loaded: _Loaded) -> np.ndarray | None:
    """``--potential``: a specification (:func:`hamsa.potentials.from_spec`, vertex ids of the input) or a
    file with one value per vertex of the mesh used or, after ``--repair``, of the input."""
    from hamsa.errors import PotentialError
    from hamsa.files import read_text
    from hamsa.operators import check_potential
    from hamsa.potentials import from_spec

    if text is None:
        return None
    if _potential_file(text) is None:
        return from_spec(loaded.mesh, text, loaded.vertex_ids)
    try:
        if text.endswith(".npy"):
            values = _vertex_array(text, loaded)
        else:
            values = _per_vertex(np.loadtxt(io.StringIO(read_text(text)), ndmin=1), loaded, f"'{text}'")
    except HamsaError as exc:
        raise PotentialError(f"potential: {exc}") from None
    except ValueError as exc:
        raise PotentialError(f"cannot read potential '{text}': {exc}") from None
    try:
        return check_potential(values, loaded.mesh.n_vertices)
    except PotentialError as exc:
        raise PotentialError(f"'{text}': {exc}") from None


def _vertex_array(path: str, loaded: _Loaded) -> np.ndarray:
    """An (n,) or (n, d) ``.npy`` array of values per vertex, by :func:`_per_vertex`'s rule."""
    from hamsa.files import load_array

    rows = loaded.mesh.n_vertices if loaded.vertex_ids is None else None  # after a repair: either count
    return _per_vertex(load_array(path, ndim=(1, 2), rows=rows), loaded, f"'{path}'")


def _per_vertex(values: np.ndarray, loaded: _Loaded, what: str) -> np.ndarray:
    """Values given per vertex of the shape used or, after ``--repair``, per vertex of the input (the rows of
    the vertices the repair kept are taken): the ids every output of a repaired shape is written in."""
    n = loaded.mesh.n_vertices
    if loaded.vertex_ids is not None and len(values) == loaded.input_vertices != n:
        return values[loaded.vertex_ids]
    if len(values) != n:
        counts = (
            f"{n}" if loaded.vertex_ids is None else f"{loaded.input_vertices} (the input's) or {n} (after --repair)"
        )
        raise HamsaError(f"{what} has {len(values)} rows; expected {counts}, one per vertex")
    return values


def _in_input_vertices(values: np.ndarray, loaded: _Loaded, fill=np.nan) -> np.ndarray:
    """Per-vertex values of a repaired shape written per input vertex, ``fill`` at the vertices the repair
    dropped (:func:`_per_vertex` reads them back); values of a shape used as given are returned as they are."""
    if loaded.vertex_ids is None:
        return values
    full = np.full((loaded.input_vertices, *values.shape[1:]), fill, dtype=np.result_type(values, fill))
    full[loaded.vertex_ids] = values
    return full


def _load_ids(path: str) -> np.ndarray:
    """Vertex ids from a .npy file or a text file of integers (whitespace or newline separated)."""
    from hamsa.files import load_array, read_text

    try:
        ids = load_array(path, ndim=1) if path.endswith(".npy") else np.loadtxt(io.StringIO(read_text(path)), ndmin=1)
    except ValueError as exc:
        raise HamsaError(f"cannot read vertex ids from '{path}': {exc}") from None
    if ids.size and not np.all(ids == np.round(ids)):
        raise HamsaError(f"'{path}' holds non-integer vertex ids")
    return ids.astype(np.int64)


def _output_path(args, suffix: str | None = None, *inputs) -> Path:
    """``args.output``, checked before any work is done (:func:`hamsa.files.check_output`): its suffix, that
    it can be written, and that it is none of the command's input files."""
    from hamsa.files import check_output

    return check_output(args.output, suffix=suffix, inputs=[x for x in inputs if x])


def _info(args) -> None:
    from hamsa.io import load_shape, read_shape_arrays
    from hamsa.mesh import format_ids
    from hamsa.pointcloud import STRAY_JUMP, PointCloud

    dropped = ""
    try:
        mesh = load_shape(args.mesh, manifold=False, **_cloud_options(args))
    except MeshError as error:  # a cloud with NaN or repeated points: described without them
        cloud = _cloud_options(args)
        points, faces, normals = read_shape_arrays(args.mesh, normals=cloud["file_normals"])
        if faces is not None:
            raise
        try:
            mesh, _, report = _repaired_cloud(points, normals, cloud)
        except MeshError:
            raise error from None
        dropped = f" of {len(points)} in the file; the lines below leave out {str(report).removeprefix('repaired: ')}"
        dropped += " (--repair drops them too)"
    _check_cloud_options(args, mesh)
    if isinstance(mesh, PointCloud):
        cloud = mesh
        print(f"point cloud     {args.mesh}")
        print(f"points          {cloud.n_vertices}{dropped}")
        print(f"area            {cloud.area:.6g} (the point-cloud Laplacian's mass, {cloud.neighbors} neighbours)")
        print(f"bounding box    diagonal {cloud.bounding_box_diagonal:.6g}")
        print(f"mean spacing    {cloud.mean_spacing:.6g}")
        print(f"normals         {cloud.normals_origin.replace('given', 'from the file')}")
        print(f"components      {cloud.n_components}")
        stray = cloud.stray_points
        print(
            f"stray points    {len(stray)}"
            + (
                f" ({format_ids(stray)}: more than {STRAY_JUMP:g} local spacings off the rest, each adds a spurious "
                "low eigenpair; --repair drops them)"
                if len(stray)
                else ""
            )
        )
        if cloud.separate_sheets:
            pairs = cloud.n_vertices * cloud.neighbors
            rule = "normals apart" + (
                "" if cloud.off_sheet is None else f" or {cloud.off_sheet:g} spacings off the sheet"
            )
            print(
                f"sheets          {cloud.separated_neighbours} of {pairs} neighbour pairs left out ({rule}: facing "
                "sides of nearly touching parts; --joined-sheets keeps them)"
            )
        else:
            print("sheets          joined (every point's star over all its nearest points)")
        return
    loops = mesh.boundary_loops
    print(f"mesh            {args.mesh}")
    print(f"vertices        {mesh.n_vertices}")
    print(f"faces           {mesh.n_faces}")
    print(f"edges           {len(mesh.edges)}")
    print(f"area            {mesh.area:.6g}")
    print(f"bounding box    diagonal {mesh.bounding_box_diagonal:.6g}")
    print(f"mean edge       {mesh.mean_edge_length:.6g}")
    print(f"components      {mesh.n_components}")
    print(
        f"boundary loops  {len(loops)}"
        + (
            f" (lengths {', '.join(str(len(x)) for x in loops[:8])}{', ...' if len(loops) > 8 else ''})"
            if loops
            else ""
        )
    )
    chi = mesh.euler_characteristic
    genus = f", genus {(2 - chi) // 2}" if mesh.n_components == 1 and not loops and chi % 2 == 0 else ""
    print(f"Euler char.     {chi}{genus}")
    defects = []
    if not mesh.is_edge_manifold:
        defects.append(f"{len(mesh.non_manifold_edges)} non-manifold edges (--laplacian tufted takes them)")
    if len(mesh.unreferenced_vertices):
        defects.append(f"{len(mesh.unreferenced_vertices)} unreferenced vertices (--repair drops them)")
    if len(mesh.non_manifold_vertices):
        defects.append(f"{len(mesh.non_manifold_vertices)} non-manifold vertices")
    if not mesh.is_consistently_oriented:
        defects.append("inconsistent face orientation")
    print(f"defects         {'; '.join(defects) if defects else 'none'}")


def _basis(args) -> None:
    from hamsa.eigen import eigenbasis
    from hamsa.pointcloud import PointCloud

    output = _output_path(args, ".npz", args.mesh, _potential_file(args.potential))
    start = time.perf_counter()
    with _Steps(args, 3) as step:
        step(f"reading {Path(args.mesh).name}")
        given = _load_for_operators(args.mesh, args.repair, args.laplacian, _cloud_options(args))
        _check_cloud_options(args, given.mesh)
        mesh, vertex_ids = given.mesh, given.vertex_ids
        loaded = time.perf_counter()
        potential = _potential(args.potential, given)
        boundary = args.boundary if args.boundary in ("neumann", "dirichlet") else _load_ids(args.boundary)
        step(f"solving for {args.k} eigenpairs of n = {mesh.n_vertices}")
        basis = eigenbasis(
            mesh,
            args.k,
            potential,
            mass=args.mass,
            backend=args.backend,
            laplacian=args.laplacian,
            device=args.device,
            boundary=boundary,
            progress=step.counter("eigenpairs converged"),
        )
        solved = time.perf_counter()
        step(f"writing {output.name}")
        (basis if vertex_ids is None else basis.with_vertex_ids(vertex_ids)).save(output)
    done = time.perf_counter()
    kind = "LBO (V = 0)" if potential is None else f"Hamiltonian (V in [{potential.min():.4g}, {potential.max():.4g}])"
    shape = "point cloud" if isinstance(mesh, PointCloud) else "mesh"
    print(f"{kind} on a {shape}, n = {mesh.n_vertices}, k = {args.k}, {basis.mass_kind} mass, {args.boundary} boundary")
    print(f"eigenvalues     {basis.values[0]:.6g} .. {basis.values[-1]:.6g}")
    print(
        f"solver          {basis.info.method}, {basis.info.solves} solves, {basis.info.cycles} cycles, "
        f"max relative residual {basis.info.max_residual:.1e}"
    )
    if basis.info.fallback:
        print(f"fallback        {basis.info.method}: {basis.info.fallback}")
    print(f"time            load {loaded - start:.2f} s, solve {solved - loaded:.2f} s, save {done - solved:.2f} s")
    print(f"wrote           {output}")


def _optimize(args) -> None:
    from hamsa.files import atomic_write
    from hamsa.optimize import optimize_potential

    output = _output_path(args, ".npy", args.mesh, args.data)
    loaded = _load_for_operators(args.mesh, args.repair, cloud=_cloud_options(args))
    mesh = loaded.mesh
    _check_cloud_options(args, mesh)
    data = _vertex_array(args.data, loaded) if args.data else mesh.vertices
    start = time.perf_counter()
    optimizer = {"smoothing": (), "rounds": 1, "max_iterations": 200} if args.plain else {}
    if args.iterations is not None:
        optimizer["max_iterations"] = args.iterations
    result = optimize_potential(
        mesh,
        data,
        args.k,
        m=args.m,
        parametrization="square" if args.square else "signed",
        progress=sys.stderr.isatty() and not args.quiet,
        center=args.center,
        **optimizer,
    )
    with atomic_write(output) as handle:
        np.save(handle, _in_input_vertices(result.potential, loaded))
    print(
        f"representation error{' of the centred data' if args.center else ''} with k = {args.k}: LBO "
        f"{result.lbo_loss:.4g}, optimized Hamiltonian "
        f"{result.loss:.4g} ({result.ratio:.2f}x smaller)"
    )
    print(
        f"potential in [{result.potential.min():.4g}, {result.potential.max():.4g}], "
        f"{len(result.history) - 1} iterations ({'plain' if args.plain else 'smoothed, then plain'}), "
        f"{time.perf_counter() - start:.1f} s"
    )
    print(f"wrote           {output}{_dropped(loaded, 'NaN')}")


def _compress(args) -> None:
    from hamsa import compression
    from hamsa.files import atomic_write

    output = _output_path(args, None, args.mesh)
    mesh = _load_for_operators(args.mesh, args.repair).mesh
    start = time.perf_counter()
    data = compression.encode(mesh, args.k, args.bits, args.method)
    with atomic_write(output) as handle:
        handle.write(data)
    size = compression.sizes(data)
    decoded = compression.decode(data, mesh.faces)
    print(
        f"{args.method}: {args.k} coefficients x 3 at {args.bits} bits -> {len(data)} bytes, "
        f"{size.bits_per_vertex:.2f} bits/vertex (payload)"
        + (
            f", vertex order {size.permutation_bits / mesh.n_vertices:.2f} bits/vertex"
            if size.permutation_bits > 64
            else ""
        )
    )
    print(
        f"Karni-Gotsman error {compression.karni_gotsman_error(mesh, decoded):.4g}, RMS / bbox diagonal "
        f"{compression.rms_error(mesh, decoded):.4g}; {time.perf_counter() - start:.1f} s"
    )
    print(f"wrote           {args.output}")


def _decompress(args) -> None:
    from hamsa import compression
    from hamsa.files import read_bytes
    from hamsa.io import load_mesh, mesh_format, save_mesh
    from hamsa.mesh import TriMesh

    output = _output_path(args, None, args.compressed, args.faces)
    mesh_format(output)
    data = read_bytes(args.compressed)
    connectivity = load_mesh(args.faces)
    vertices = compression.decode(data, connectivity.faces)
    save_mesh(TriMesh(vertices, connectivity.faces), output)
    print(f"wrote           {args.output} ({len(vertices)} vertices)")


def _modes(args) -> None:
    from hamsa.cmm import compressed_modes
    from hamsa.files import atomic_write

    output = _output_path(args, ".npz", args.mesh)
    mesh, vertex_ids, _ = _load_for_operators(args.mesh, args.repair, cloud=_cloud_options(args))
    _check_cloud_options(args, mesh)
    if args.unit_area:
        mesh = mesh.scaled_to_unit_area()

    def report(stage, index, iterations, objective):
        if args.quiet:
            return
        if stage == "admm":
            if iterations % 100 == 0:
                print(f"  ADMM iteration {iterations}: objective {objective:.6g}", file=sys.stderr, flush=True)
            return
        what = "mode" if stage == "greedy" else "refining mode"
        print(
            f"  {what} {index + 1}/{args.k}: {iterations} IRLS iterations, objective {objective:.6g}",
            file=sys.stderr,
            flush=True,
        )

    result = compressed_modes(mesh, args.k, args.mu, method=args.method, callback=report)
    with atomic_write(output) as handle:
        np.savez(
            handle,
            modes=result.modes,
            objective=result.objective,
            mu=result.mu,
            iterations=np.asarray(result.iterations),
            **({} if vertex_ids is None else {"vertex_ids": vertex_ids}),
        )
    print(
        f"{args.k} compressed modes, mu = {args.mu:g}: objective {result.objective:.6g}, "
        f"max |Phi^T A Phi - I| = {result.orthogonality_error:.1e}, {result.seconds:.1f} s"
    )
    print(f"wrote           {output}")


def _match(args) -> None:
    from hamsa.evaluation import THRESHOLDS, map_distortion, map_scores
    from hamsa.files import atomic_write
    from hamsa.geodesic import geodesic_solver
    from hamsa.matching import functional_from_map, match
    from hamsa.matching.pipeline import START_K

    outputs = _match_outputs(args)
    start = time.perf_counter()
    if args.method not in ("icskm", "fmap") and args.landmarks:
        raise HamsaError("--landmarks is for --method icskm or fmap")
    if (args.source_potential is None) != (args.target_potential is None):
        raise HamsaError("--source-potential and --target-potential go together (one potential per shape)")
    least = {"wks": 60, "fmap": START_K, "sgfe": START_K}.get(args.method, 1)  # (the start map's size)
    k = max(args.k, least)
    if k != args.k:
        print(f"-k {args.k} is too few for {args.method}: using k = {k}", file=sys.stderr)
    with _Steps(args, 8) as step:
        step("reading the meshes")
        loaded = [
            _load_for_operators(path, args.repair, cloud=_cloud_options(args)) for path in (args.source, args.target)
        ]
        _check_cloud_options(args, *(item.mesh for item in loaded))
        truth = _truth(args.truth, *loaded) if args.truth else None
        meshes = [item.mesh.scaled_to_unit_area() for item in loaded]  # comparable spectra
        wanted = args.method == "icskm" or args.landmarks  # (icskm needs them, fmap takes them)
        landmarks = _landmark_pairs(args.landmarks, loaded) if wanted else None
        bases, basis = _match_bases(args, loaded, meshes, landmarks, k, step)
        step(f"matching ({args.method})")
        unit = {"fmap": "ZoomOut sizes", "icskm": "ICP runs", "sgfe": "ICP iterations"}.get(args.method, "")
        mapping = match(
            *bases,
            args.method,
            landmarks=landmarks,
            meshes=meshes,
            progress=step.counter(unit),
            commutativity_weight=args.commutativity,
            orientation_weight=args.orientation,
        )
        solver = None  # the target's geodesics, built once for the scores and the distortion
        if truth is not None:
            step(f"scoring at {min(args.points, int(np.sum(truth >= 0)))} vertices (Kim et al.)")
            solver = geodesic_solver(meshes[1], method=args.geodesics)
            scores = map_scores(meshes[1], mapping, truth, args.points, solver=solver)
        step("measuring the map's distortion")
        quality = map_distortion(*meshes, mapping, target_solver=solver if args.geodesics == "heat" else None)
    saved = _in_input_ids(mapping, *loaded) if any(item.vertex_ids is not None for item in loaded) else mapping
    if saved is not mapping:
        print(f"map in input vertex ids; {int(np.sum(saved < 0))} source vertices removed by --repair map to -1")
    with atomic_write(outputs["map"]) as handle:
        np.save(handle, saved)
    print(
        f"{args.method} ({basis} basis): mapped {len(mapping)} source vertices onto {meshes[1].n_vertices} target "
        f"vertices (k = {k}) in {time.perf_counter() - start:.1f} s"
    )
    print(
        f"distortion      {quality['distortion']:.4f} geodesic (mean |d_T(f a, f b) - d_S(a, b)| / sqrt(area) over "
        f"{quality['pairs']} pairs; an isometry or its mirror image 0), target area covered "
        f"{100 * quality['coverage']:.1f}%"
    )
    if args.fmap:
        with atomic_write(outputs["fmap"]) as handle:
            np.save(handle, functional_from_map(mapping, *bases))
    if truth is not None:
        print(
            f"scores          AUC {scores['auc']:.4f} on [0, 0.25], within 0.05: {scores['within_0.05']:.4f}, "
            f"mean error {scores['mean_error']:.4f} (geodesic / sqrt(area), {scores['points']} vertices)"
        )
        with atomic_write(outputs["scores"], "w") as handle:
            json.dump({**scores, "thresholds": THRESHOLDS.tolist(), "method": args.method, "basis": basis,
                       "geodesics": args.geodesics}, handle)  # fmt: skip
    print("wrote           " + ", ".join(str(path) for path in outputs.values()))


def _match_outputs(args) -> dict:
    """The files ``hamsa match`` writes, each checked before any work: the map, and C and the scores when asked."""
    from hamsa.files import check_output

    inputs = (args.source, args.target, args.truth, _potential_file(args.source_potential),
              _potential_file(args.target_potential))  # fmt: skip
    outputs = {"map": _output_path(args, ".npy", *inputs)}
    if args.fmap:
        outputs["fmap"] = check_output(args.fmap, suffix=".npy", inputs=[x for x in (*inputs, args.output) if x])
    if args.truth:
        scores = args.scores or str(outputs["map"].with_suffix(".scores.json"))
        outputs["scores"] = check_output(scores, suffix=".json", inputs=[x for x in (*inputs, args.output) if x])
    elif args.scores:
        raise HamsaError("--scores is for --truth")
    return outputs


def _match_bases(args, loaded, meshes, landmarks, k: int, step):
    """The two eigenbases ``hamsa match`` matches in and their name: the given potentials', the landmark
    potential's (icskm), the paper's matching potential (``--basis hamiltonian``) or the LBO's."""
    from hamsa.eigen import eigenbasis
    from hamsa.geodesic import geodesic_distance
    from hamsa.matching import matching_potentials

    if args.source_potential is not None:
        V = [_potential(text, item) for text, item in zip((args.source_potential, args.target_potential), loaded)]
        name = "given potentials"
    elif args.method == "icskm":
        scale = args.landmark_scale
        V = [scale * geodesic_distance(m, ids, normalize=True, unreachable="farthest") if scale else None
             for m, ids in zip(meshes, landmarks)]  # fmt: skip
        name = "landmark potential" if scale else "LBO"
    elif args.basis == "hamiltonian":
        lbo = []
        for side, mesh in zip(("source", "target"), meshes):
            step(f"{side} LBO eigenbasis (k = {k}, n = {mesh.n_vertices})")
            lbo.append(eigenbasis(mesh, k, progress=step.counter("eigenpairs converged")))
        V, name = matching_potentials(*lbo, meshes=meshes), "matching potential"
    else:
        V, name = [None, None], "LBO"
    bases = []
    for side, mesh, potential in zip(("source", "target"), meshes, V):
        step(f"{side} {'LBO' if potential is None else 'Hamiltonian'} eigenbasis (k = {k}, n = {mesh.n_vertices})")
        bases.append(eigenbasis(mesh, k, potential, progress=step.counter("eigenpairs converged")))
    return bases, name


def _truth(text: str, source: _Loaded, target: _Loaded) -> np.ndarray:
    """``--truth`` in the meshes used: (n_source used,) target ids, -1 where unknown or removed by --repair.
    The file (or 'identity') gives one target id per source vertex of the input."""
    if text == "identity":
        given = np.arange(source.input_vertices)
        given[given >= target.input_vertices] = -1
    else:
        given = _load_ids(text)
        if given.shape != (source.input_vertices,):
            raise HamsaError(
                f"--truth '{text}' has {given.size} entries, the source has {source.input_vertices} vertices"
            )
        if given.size and (given.min() < -1 or given.max() >= target.input_vertices):
            raise HamsaError(f"--truth '{text}' holds ids outside -1..{target.input_vertices - 1} (target vertices)")
    source_ids = np.arange(source.mesh.n_vertices) if source.vertex_ids is None else source.vertex_ids
    position = np.arange(target.input_vertices)
    if target.vertex_ids is not None:  # input target vertex -> its first copy in the repaired mesh, or -1
        position = np.full(target.input_vertices, -1)
        position[target.vertex_ids[::-1]] = np.arange(len(target.vertex_ids))[::-1]
    wanted = given[source_ids]
    return np.where(wanted >= 0, position[np.maximum(wanted, 0)], -1)


def _in_input_ids(mapping: np.ndarray, source: _Loaded, target: _Loaded) -> np.ndarray:
    """A map between repaired meshes as one between the inputs: (input source vertices,) input target ids,
    -1 for source vertices the repair removed (a split vertex takes its first copy's image)."""
    source_ids = np.arange(len(mapping)) if source.vertex_ids is None else source.vertex_ids
    target_ids = np.arange(target.mesh.n_vertices) if target.vertex_ids is None else target.vertex_ids
    result = np.full(source.input_vertices, -1, dtype=np.int64)
    result[source_ids[::-1]] = target_ids[mapping][::-1]  # reversed: the first copy is written last
    return result


def _to_repaired(vertex: int, loaded: _Loaded) -> int:
    """The repaired mesh's vertex for an input vertex id (its first copy), or -1 if the repair removed it."""
    if loaded.vertex_ids is None:
        return vertex
    hits = np.flatnonzero(loaded.vertex_ids == vertex)
    return int(hits[0]) if len(hits) else -1


def _landmark_pairs(texts, loaded) -> tuple[np.ndarray, np.ndarray]:
    """'S:T' strings (input vertex ids) -> (source ids, target ids) in the meshes used, checked."""
    if not texts:
        raise HamsaError("--method icskm needs --landmarks S:T [S:T ...] (known source:target vertex pairs)")
    pairs = []
    for text in texts:
        try:
            s, t = (int(part) for part in text.split(":"))
        except ValueError:
            raise HamsaError(f"landmark {text!r} is not 'source_vertex:target_vertex' (two integers)") from None
        pair = []
        for vertex, item, side in ((s, loaded[0], "source"), (t, loaded[1], "target")):
            if not 0 <= vertex < item.input_vertices:
                raise HamsaError(f"landmark {text!r}: {side} vertex {vertex} is not in 0..{item.input_vertices - 1}")
            pair.append(_to_repaired(vertex, item))
            if pair[-1] < 0:
                raise HamsaError(f"landmark {text!r}: {side} vertex {vertex} was removed by --repair")
        pairs.append(pair)
    ids = np.array(pairs, dtype=np.int64)
    return ids[:, 0], ids[:, 1]


def _benchmark_matching(args) -> None:
    from hamsa.datasets import load_folder, load_scape, load_tosca
    from hamsa.paper.benchmark import benchmark_dataset, table_markdown

    root = Path(args.dataset)
    if not root.is_dir():
        raise HamsaError(f"dataset folder '{root}' does not exist")
    kind = args.kind
    if kind == "auto":
        kind = "scape" if "scape" in root.name.lower() else "tosca" if "tosca" in root.name.lower() else "folder"
    dataset = {"tosca": load_tosca, "scape": load_scape, "folder": load_folder}[kind](root)
    if not dataset.pairs():
        raise HamsaError(f"'{root}' has no evaluation pairs (each class needs at least two shapes)")
    from hamsa.files import check_output_folder

    output = check_output_folder(args.output)
    table = benchmark_dataset(
        dataset,
        output,
        args.method,
        args.k,
        args.points,
        args.jobs,
        args.limit,
        args.scheduler,
        landmarks=args.landmarks,
        eigensum_scale=args.eigensum_scale,
        oracle=args.oracle,
        draws=args.draws,
        landmark_scale=args.landmark_scale,
        geodesics=args.geodesics,
        commutativity_weight=args.commutativity,
        orientation_weight=args.orientation,
    )
    print(table_markdown(table), end="")
    print(f"wrote {output / 'table.md'}, {output / 'table.json'} and {output / 'curves.png'}")
    if table.get("failed"):
        raise HamsaError(
            f"{len(table['failed'])} of {len(table['failed']) + table['pairs']} pairs failed (listed above and in "
            "table.json); the table covers the others, and a rerun with the same options retries only the failed ones"
        )


def _view(args) -> None:
    from hamsa.viz import map_to_html, to_html

    inputs = (
        args.mesh,
        _potential_file(args.potential),
        args.basis,
        args.modes,
        args.map,
        args.target,
        *(args.field or ()),
    )
    output = _output_path(args, ".html", *inputs)
    if (args.map is None) != (args.target is None):
        raise HamsaError("--map and --target go together (the map's target mesh)")
    if args.potential and (args.basis or args.field or args.modes or args.map):
        raise HamsaError(
            "--potential is for the eigenfunctions view computed here (not with --basis/--field/--modes/--map)"
        )
    shape = _load_for_operators(args.mesh, args.repair, cloud=_cloud_options(args))
    target = _load_for_operators(args.target, args.repair, cloud=_cloud_options(args)) if args.map else None
    _check_cloud_options(args, shape.mesh, *([] if target is None else [target.mesh]))
    if args.map:
        mapping = _load_ids(args.map)
        if shape.vertex_ids is not None or target.vertex_ids is not None:
            raise HamsaError("--map shows a map between the meshes as given: leave out --repair")
        map_to_html(shape.mesh, target.mesh, mapping, output, title=f"{Path(args.map).name}: {Path(args.mesh).name} -> "
                    f"{Path(args.target).name}")  # fmt: skip
        print(f"wrote {output} (the map in colours; open it in a browser)")
        return
    fields, kind = _view_fields(args, shape)
    to_html(shape.mesh, fields, output, title=f"{Path(args.mesh).name}: {kind}")
    print(f"wrote {output} ({len(fields)} fields; open it in a browser)")


def _view_fields(args, shape: _Loaded) -> tuple[dict, str]:
    """The fields ``hamsa view`` shows ({title: (n,) array}) and what they are. Eigenfunctions are titled by
    their column in ``basis.vectors`` (0-based, as in Python); a constant first one is left out unless
    ``--constant``."""
    from hamsa.files import load_npz

    n = shape.mesh.n_vertices
    if args.field:
        fields = {}
        for path in args.field:
            values = _vertex_array(path, shape)
            columns = values.reshape(n, -1)
            fields |= {Path(path).stem + ("" if values.ndim == 1 else f"[:, {j}]"): c for j, c in enumerate(columns.T)}
        return fields, "fields"
    if args.modes:
        archive = load_npz(args.modes, {"modes": {"ndim": 2}})
        if "modes" not in archive:
            raise HamsaError(f"'{args.modes}' has no 'modes' array (write it with hamsa modes)")
        modes = archive["modes"]
        if modes.shape[0] != n:
            raise HamsaError(f"'{args.modes}': modes of shape {modes.shape}, the mesh has {n} vertices{_REPAIR_HINT}")
        return {f"mode {j}": modes[:, j] for j in range(min(args.k, modes.shape[1]))}, "compressed modes"
    basis, potential, kind = _basis_for(args, shape, args.k + 1)  # one more: the constant is skipped
    vectors, first = basis.vectors, 0
    if not args.constant and np.ptp(vectors[:, 0]) <= 1e-8 * np.abs(vectors[:, 0]).max():
        first = 1  # the constant eigenfunction of V = 0 (Neumann): nothing to see
    fields = {} if potential is None else {"potential V": potential}
    chosen = range(first, min(first + args.k, basis.k))
    fields |= {f"psi {i} (E = {basis.values[i]:.4g})": vectors[:, i] for i in chosen}
    return fields, kind


_REPAIR_HINT = " (computed with --repair? then pass --repair here too)"


def _basis_for(args, shape: _Loaded, k: int, progress=None):
    """(basis, potential or None, what the basis is) of a command with ``--basis`` / ``--potential``: the saved
    basis, its rows checked against the shape's vertices (repaired as it was), or the ``k`` smallest
    eigenpairs of the shape with the potential, computed here (``progress`` as :func:`hamsa.eigen.eigenbasis`'s)."""
    from hamsa.eigen import Eigenbasis, eigenbasis

    if args.basis and args.potential:
        raise HamsaError("--potential is for a basis computed here: a saved --basis has its own")
    if not args.basis:
        potential = _potential(args.potential, shape)
        basis = eigenbasis(shape.mesh, k, potential, progress=progress)
        return basis, potential, "LBO" if potential is None else "Hamiltonian"
    basis, n = Eigenbasis.load(args.basis), shape.mesh.n_vertices
    same_ids = basis.vertex_ids is None or (
        shape.vertex_ids is not None and np.array_equal(basis.vertex_ids, shape.vertex_ids)
    )
    if basis.n != n or not same_ids:
        raise HamsaError(f"'{args.basis}' has {basis.n} rows, not those of the mesh's {n} vertices{_REPAIR_HINT}")
    return basis, None, f"basis {Path(args.basis).name}"


def _repair(args) -> None:
    from hamsa.files import atomic_write, check_output
    from hamsa.io import mesh_format, point_format, save_mesh, save_point_cloud
    from hamsa.mesh import TriMesh

    output = _output_path(args, None, args.mesh)
    ids = check_output(args.ids, suffix=".npy", inputs=[args.mesh, args.output]) if args.ids else None
    if ids is not None and ids.resolve() == output.resolve():
        raise HamsaError("--ids and -o name the same file")
    points_format = point_format(output)
    as_points = points_format is not None and points_format[0] not in ("off", "obj")
    try:
        as_mesh = bool(mesh_format(output))
    except MeshError:
        as_mesh = False
    if not (as_mesh or as_points):
        raise HamsaError(f"cannot tell the format of '{output}': a mesh .off .obj .ply .stl, points .xyz .txt .pts "
                         ".csv .ply .npy (optionally .gz)")  # fmt: skip
    if ids is not None and output.name.lower().removesuffix(".gz").endswith(".stl"):
        raise HamsaError("STL does not keep the vertex order that --ids refers to: write .off, .obj or .ply")
    cloud = {**_cloud_options(args), "modes": args.modes or 0}
    repaired, report = _repaired_file(args.mesh, cloud, keep="all" if args.all_pieces else "largest")
    _check_cloud_options(args, repaired.mesh)
    is_mesh = isinstance(repaired.mesh, TriMesh)
    if is_mesh and args.modes:
        raise HamsaError(f"--modes is for point clouds, and '{args.mesh}' is a mesh")
    if not (as_mesh if is_mesh else as_points):
        kind = "a mesh: write .off .obj .ply or .stl" if is_mesh else "points: write .xyz .txt .pts .csv .ply or .npy"
        raise HamsaError(f"'{args.mesh}' holds {kind}, not '{output}'")
    (save_mesh if is_mesh else save_point_cloud)(repaired.mesh, output)
    kept = np.arange(repaired.input_vertices) if repaired.vertex_ids is None else repaired.vertex_ids
    if ids is not None:
        with atomic_write(ids) as handle:
            np.save(handle, kept)
    print(f"{args.mesh}: {report if report.changed else 'nothing to repair'}")
    print(f"wrote           {output} ({repaired.mesh.n_vertices} of {repaired.input_vertices} vertices)" +
          (f", {ids}" if ids else ""))  # fmt: skip


def _signature(args) -> None:
    from hamsa.diffusion import (
        default_hks_times,
        default_wks_energies,
        heat_kernel_signature,
        wave_kernel_signature,
    )
    from hamsa.files import atomic_write

    output = _output_path(args, ".npy", args.mesh, args.basis, _potential_file(args.potential))
    if args.scaled and args.kind != "hks":
        raise HamsaError("--scaled is for --kind hks (the heat trace)")
    with _Steps(args, 3) as step:
        step(f"reading {Path(args.mesh).name}")
        shape = _load_for_operators(args.mesh, args.repair, cloud=_cloud_options(args))
        _check_cloud_options(args, shape.mesh)
        step("loading the basis" if args.basis else f"solving for {args.k} eigenpairs")
        basis, _, kind = _basis_for(args, shape, args.k, step.counter("eigenpairs converged"))
        step(f"{args.kind.upper()} at {args.count} scales")
        if args.kind == "hks":
            scales = default_hks_times(basis, args.count)
            values = heat_kernel_signature(basis, scales, scaled=args.scaled)
            what = f"times {scales[0]:.4g} .. {scales[-1]:.4g}{' (scaled by the heat trace)' if args.scaled else ''}"
        else:
            scales, sigma = default_wks_energies(basis, args.count)
            values = wave_kernel_signature(basis, scales, sigma)
            what = f"log-energies {scales[0]:.4g} .. {scales[-1]:.4g}, sigma {sigma:.4g}"
        saved = _in_input_vertices(values, shape)
        with atomic_write(output) as handle:
            np.save(handle, saved)
    print(f"{args.kind.upper()} of the {kind} (k = {basis.k}): {what}")
    print(f"wrote           {output} {saved.shape}{_dropped(shape, 'NaN')}")


def _segment(args) -> None:
    from hamsa.files import atomic_write
    from hamsa.nodal import segment

    output = _output_path(args, ".npy", args.mesh, args.basis, _potential_file(args.potential))
    k = args.k or args.index + 1
    if args.index >= k:
        raise HamsaError(f"--index {args.index} needs at least k = {args.index + 1} eigenpairs, -k is {k}")
    with _Steps(args, 3) as step:
        step(f"reading {Path(args.mesh).name}")
        shape = _load_for_operators(args.mesh, args.repair, cloud=_cloud_options(args))
        _check_cloud_options(args, shape.mesh)
        step("loading the basis" if args.basis else f"solving for {k} eigenpairs")
        basis, _, kind = _basis_for(args, shape, k, step.counter("eigenpairs converged"))
        step("nodal domains")
        labels = segment(shape.mesh, basis, args.index, args.min_vertices)
        saved = _in_input_vertices(labels, shape, fill=-1)
        with atomic_write(output) as handle:
            np.save(handle, saved)
    sizes = np.bincount(labels)
    print(
        f"{len(sizes)} segments from eigenfunction {args.index} of the {kind} (E = {basis.values[args.index]:.6g}), "
        f"{sizes.min()} .. {sizes.max()} vertices each"
    )
    print(f"wrote           {output}{_dropped(shape, '-1')}")


def _dropped(shape: _Loaded, fill: str) -> str:
    """What an output written per input vertex holds at the vertices --repair dropped ("" without a repair)."""
    if shape.vertex_ids is None:
        return ""
    return f" (one row per input vertex; {fill} at the {shape.input_vertices - shape.mesh.n_vertices} --repair dropped)"


def _reproduce(args) -> None:
    from hamsa.files import check_output_folder
    from hamsa.paper.reproduce import reproduce

    check_output_folder(args.output)
    results = reproduce(args.output, data=args.data, quick=args.quick, force=args.force, only=args.only)
    failed = [name for name, r in results["experiments"].items() if r["status"] != "ok"]
    verdicts = [c["verdict"] for c in results["claims"]]
    print(
        f"hamsa reproduce: {len(results['experiments']) - len(failed)} experiments ok"
        + (f", failed: {', '.join(failed)}" if failed else "")
        + f"; claims: {verdicts.count('reproduced')} reproduced, {verdicts.count('not reproduced')} not reproduced, "
        f"{len(verdicts) - verdicts.count('reproduced') - verdicts.count('not reproduced')} other"
    )
    print(f"report: {Path(args.output).resolve() / 'index.html'}")


def _demo(args) -> None:
    from hamsa.paper.demo import step_potential_demo

    result = step_potential_demo(k=args.k, height=args.height)
    mesh = result.mesh
    print("hamsa demo: a finite step potential on a built-in capsule (paper section 2.3, Fig. 2 in numbers)")
    print(f"mesh: capsule, {mesh.n_vertices} vertices, {mesh.n_faces} faces, area {mesh.area:.4f}")
    print(
        f"potential: V = {result.height:.4f} on the upper part (z > 0.3), 0 elsewhere "
        f"(the V = 0 region holds {100 * result.region_fraction:.1f}% of the area)"
    )
    print()
    print(result.table())
    print()
    print("lambda_i / phi_i: Laplace-Beltrami; E_i / psi_i: Hamiltonian. 'lower/upper': Theorem 1,")
    print("lambda_i + min V <= E_i <= lambda_i + max V. The last columns give each eigenfunction's share of")
    print("A-mass inside the V = 0 region: modes with E_i below the step stay trapped there; above it they leak.")
    trapped = result.inside[result.values < result.height]
    print(
        f"modes below the step: {len(trapped)}, mean mass inside {100 * trapped.mean():.1f}%; "
        f"time {result.seconds:.2f} s"
    )


def _config(args) -> None:
    from hamsa.runtime import show_config

    show_config()


class _Terminated(KeyboardInterrupt):
    """SIGTERM, raised as an interrupt so that what runs stops as on Ctrl-C."""


@contextlib.contextmanager
def _terminate_as_interrupt():
    """While a command runs, SIGTERM (``kill``, a batch scheduler's time limit) raises :class:`_Terminated`:
    the parallel benchmark then shuts its worker processes down as on Ctrl-C instead of leaving them computing,
    and no output is left half-written (outputs are written to a temporary file, then renamed)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def terminated(signum, frame):
        raise _Terminated

    previous = signal.signal(signal.SIGTERM, terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _warning_line(command: str):
    """A ``warnings.showwarning`` that prints hamsa's warnings as one line naming the command (the message says
    what to do) and leaves other libraries' warnings as Python prints them."""
    default = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if category.__module__.startswith("hamsa"):
            print(f"{command}: warning: {message}", file=sys.stderr)
        else:
            default(message, category, filename, lineno, file, line)

    return show


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns the exit code: 0, 2 for bad input (one line on stderr naming it), 3 when a
    solver did not converge, 130 on Ctrl-C, 1 for an operating-system error (e.g. disk full)."""
    command = "hamsa"
    handlers = {
        "info": _info,
        "repair": _repair,
        "basis": _basis,
        "optimize": _optimize,
        "compress": _compress,
        "decompress": _decompress,
        "modes": _modes,
        "match": _match,
        "view": _view,
        "signature": _signature,
        "segment": _segment,
        "benchmark-matching": _benchmark_matching,
        "reproduce": _reproduce,
        "demo": _demo,
        "config": _config,
    }
    try:
        args = _parser().parse_args(argv)
        command = f"hamsa {args.command}"
        with _terminate_as_interrupt(), warnings.catch_warnings():
            warnings.showwarning = _warning_line(command)
            handlers[args.command](args)
    except _Terminated:
        print(f"{command}: terminated", file=sys.stderr)
        return 128 + signal.SIGTERM
    except ConvergenceError as exc:
        print(f"{command}: solver failed: {exc}", file=sys.stderr)
        return EXIT_SOLVER_FAILED
    except HamsaError as exc:
        print(f"{command}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("hamsa: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except OSError as exc:
        print(f"{command}: error: {exc.strerror or exc}{f': {exc.filename}' if exc.filename else ''}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    from hamsa.__main__ import run

    sys.exit(run())
