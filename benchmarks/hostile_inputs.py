"""Feed hamsa hostile inputs through the CLI and the Python API and count how each one ends.

The corpus is generated here (no data files). Every file goes through ``hamsa basis FILE -k 4 -o OUT.npz``
in a subprocess with a timeout; an outcome is a "clear error" (exit 2, exactly one line on stderr, no
traceback), "accepted" (exit 0: the input was not hostile after all — a defect of the corpus or of
hamsa), a "traceback" (anything else), a "hang" (timeout) or a "partial file" (an output or temporary
file left after a failure). API cases must raise a HamsaError subclass. The bar is every case a clear
error. Separately, the defects with one right fix must be repaired by ``--repair`` (exit 0), and
``hamsa info`` must describe (exit 0) or refuse clearly (exit 2) every file. Prints one line per case
and the summary lines

    N cases, N clear errors, 0 accepted, 0 tracebacks, 0 hangs, 0 partial files
    R repairable cases, R repaired by --repair; I info runs, 0 tracebacks
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

import hamsa
from hamsa import shapes

TIMEOUT = 120

TRIANGLE = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
SQUARE_VERTICES = "0 0 0\n1 0 0\n1 1 0\n0 1 0\n"


def mesh_files() -> dict[str, bytes]:
    """name -> file content; the suffix picks the format."""
    ok = shapes.icosphere(1)
    lines = [f"{x:.9g} {y:.9g} {z:.9g}" for x, y, z in ok.vertices]
    faces = [f"3 {a} {b} {c}" for a, b, c in ok.faces]

    def off(vertices, faces_):
        return f"OFF\n{len(vertices)} {len(faces_)} 0\n" + "\n".join(vertices) + "\n" + "\n".join(faces_) + "\n"

    two = off(
        lines + [f"{x + 5:.9g} {y:.9g} {z:.9g}" for x, y, z in ok.vertices],
        faces + [f"3 {a + 42} {b + 42} {c + 42}" for a, b, c in ok.faces],
    )
    flipped = faces[:5] + [" ".join(["3"] + f.split()[1:][::-1]) for f in faces[5:6]] + faces[6:]
    return {
        "empty.off": b"",
        "whitespace.obj": b"   \n\n",
        "truncated.off": off(lines, faces)[:200].encode(),
        "garbage.ply": bytes(range(256)) * 4,
        "garbage.stl": b"\x13" * 1000,
        "wrong_counts.off": f"OFF\n10 20 0\n{SQUARE_VERTICES}3 0 1 2\n".encode(),
        "nan.off": TRIANGLE.replace("0 1 0\n3", "0 nan 0\n3").encode(),
        "inf.obj": b"v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n",
        "huge.off": TRIANGLE.replace("1 0 0\n", "1e300 0 0\n").encode(),
        "negative_index.off": f"OFF\n4 2 0\n{SQUARE_VERTICES}3 0 1 2\n3 0 2 -1\n".encode(),
        "out_of_range.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n",
        "float_index.off": f"OFF\n4 2 0\n{SQUARE_VERTICES}3 0 1 2.5\n3 0 2 3\n".encode(),
        "repeated_vertex.off": f"OFF\n4 2 0\n{SQUARE_VERTICES}3 0 1 1\n3 0 2 3\n".encode(),
        "zero_area.off": b"OFF\n3 1 0\n0 0 0\n1 0 0\n2 0 0\n3 0 1 2\n",
        "duplicate_faces.off": f"OFF\n4 3 0\n{SQUARE_VERTICES}3 0 1 2\n3 0 2 3\n3 2 1 0\n".encode(),
        "nonmanifold_edge.off": b"OFF\n5 3 0\n0 0 0\n1 0 0\n0 1 0\n0 -1 0\n0 0 1\n3 0 1 2\n3 1 0 3\n3 0 1 4\n",
        "quad.off": f"OFF\n4 1 0\n{SQUARE_VERTICES}4 0 1 2 3\n".encode(),
        "binary_ply_short.ply": b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
        b"property float y\nproperty float z\nelement face 1\n"
        b"property list uchar int vertex_indices\nend_header\n\x00\x00\x80",
        "not_gzip.off.gz": b"plain text, not gzip",
        "unknown.xyz": b"1 2 3\n",
        # repairable with --repair (REPAIRABLE below); refused without it
        "needle.off": b"OFF\n3 1 0\n0 0 0\n1 0 0\n0.5 1e-9 0\n3 0 1 2\n",
        "single_triangle.off": TRIANGLE.encode(),
        "isolated_vertex.off": off(lines + ["9 9 9"], faces).encode(),
        "two_pieces.off": two.encode(),
        "inconsistent_orientation.off": off(lines, flipped).encode(),
        "nonmanifold_vertex.off": b"OFF\n7 6 0\n0 0 0\n1 0 0\n0 1 0\n1 1 1\n-1 0 0\n0 -1 0\n-1 -1 -1\n"
        b"3 0 1 2\n3 0 2 3\n3 0 3 1\n3 0 4 5\n3 0 5 6\n3 0 6 4\n",
    }


REPAIRABLE = (
    "duplicate_faces.off",
    "repeated_vertex.off",
    "isolated_vertex.off",
    "two_pieces.off",
    "inconsistent_orientation.off",
    "nonmanifold_vertex.off",
)


def run_cli(args: list[str], folder: Path) -> tuple[str, str]:
    out = folder / "out.npz"
    if out.exists():
        out.unlink()
    try:
        result = subprocess.run(
            [sys.executable, "-m", "hamsa.cli", *args, *(["-o", str(out)] if args[0] == "basis" else [])],
            capture_output=True,
            text=True,
            timeout=TIMEOUT,
        )
    except subprocess.TimeoutExpired:
        return "hang", f"no answer in {TIMEOUT} s"
    leftovers = [p.name for p in folder.iterdir() if p.name.endswith(".tmp")]
    if result.returncode == 0:
        return ("partial file", f"temporary files left: {leftovers}") if leftovers else ("accepted", "")
    stderr = result.stderr.strip().splitlines()
    if result.returncode == 2 and len(stderr) == 1 and "Traceback" not in result.stderr:
        if out.exists() or leftovers:
            return "partial file", f"{out.name if out.exists() else leftovers} left after: {stderr[0]}"
        return "clear error", stderr[0]
    return "traceback", (stderr[-1] if stderr else f"exit {result.returncode}")


def _corrupted_basis(basis):
    def case():
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "basis.npz"
            basis.save(path)
            with np.load(path) as data:
                arrays = dict(data)
            arrays["vectors"][0, 0] += 1e-6
            np.savez(path, **arrays)
            hamsa.Eigenbasis.load(path)

    return case


def api_cases() -> dict[str, callable]:
    from hamsa import diffusion, potentials
    from hamsa.geodesic import geodesic_distance
    from hamsa.paper.benchmark import match_pair
    from hamsa.paper.reproduce import reproduce
    from hamsa.repair import repair_mesh
    from hamsa.viz import to_html

    sphere = shapes.icosphere(2)
    basis = hamsa.eigenbasis(sphere, 8)
    n = sphere.n_vertices
    return {
        "k >= n": lambda: hamsa.eigenbasis(sphere, n + 1),
        "k = 0": lambda: hamsa.eigenbasis(sphere, 0),
        "k negative": lambda: hamsa.eigenbasis(sphere, -3),
        "k float": lambda: hamsa.eigenbasis(sphere, 2.5),
        "potential too short": lambda: hamsa.eigenbasis(sphere, 4, np.zeros(n - 1)),
        "potential with NaN": lambda: hamsa.eigenbasis(sphere, 4, np.where(np.arange(n) == 3, np.nan, 0.0)),
        "potential 2-D": lambda: hamsa.eigenbasis(sphere, 4, np.zeros((n, 2))),
        "potential of 1e300": lambda: hamsa.eigenbasis(sphere, 4, np.full(n, 1e300)),
        "potential of strings": lambda: hamsa.eigenbasis(sphere, 4, ["a"] * n),
        "diffusion time 0": lambda: diffusion.heat_kernel(basis, 0.0, [0]),
        "diffusion time negative": lambda: diffusion.diffuse(basis, np.ones(n), -1.0),
        "empty landmark list": lambda: geodesic_distance(sphere, [], normalize=True),
        "landmark out of range": lambda: geodesic_distance(sphere, [n + 5], normalize=True),
        "mismatched vertex counts": lambda: potentials.area_distortion(sphere, shapes.icosphere(1)),
        "project wrong length": lambda: basis.project(np.ones(n + 1)),
        "mesh from a string": lambda: hamsa.eigenbasis("sphere.off", 4),
        "vertices (n, 2)": lambda: hamsa.TriMesh(np.zeros((3, 2)), [[0, 1, 2]]),
        "basis from non-orthonormal arrays": lambda: hamsa.Eigenbasis.from_arrays(
            basis.values, 2 * basis.vectors, basis.mass.diagonal()
        ),
        "corrupted basis file": _corrupted_basis(basis),
        "repair a non-manifold edge": lambda: repair_mesh(
            np.eye(3).tolist() + [[0, 0, 0], [1, 1, 1]], [[0, 1, 2], [1, 0, 3], [0, 1, 4]]
        ),
        "unknown matching method": lambda: match_pair("sift", basis, basis),
        "view field of wrong length": lambda: to_html(sphere, np.zeros(n + 3), "never.html"),
        "unknown experiment": lambda: reproduce("never", only=["fig99"], progress=False),
        "intrinsic Laplacian, full mass": lambda: hamsa.eigenbasis(
            sphere, 4, mass="full", laplacian="intrinsic_delaunay"
        ),
    }


def main() -> int:
    counts = {"clear error": 0, "accepted": 0, "traceback": 0, "hang": 0, "partial file": 0}
    cases = repaired = info_runs = info_tracebacks = 0
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for name, content in mesh_files().items():
            path = folder / name
            path.write_bytes(content)
            outcome, detail = run_cli(["basis", str(path), "-k", "4"], folder)
            counts[outcome] += 1
            cases += 1
            print(f"cli basis   {name:<28} {outcome:<12} {detail}")
            info, detail = run_cli(["info", str(path)], folder)
            info_runs += 1
            info_tracebacks += info not in ("clear error", "accepted")
            if name in REPAIRABLE:
                fixed, detail = run_cli(["basis", str(path), "-k", "2", "--repair"], folder)
                repaired += fixed == "accepted"
                print(f"cli repair  {name:<28} {'repaired' if fixed == 'accepted' else fixed:<12} {detail}")
    for name, case in api_cases().items():
        cases += 1
        try:
            case()
            outcome, detail = "accepted", ""
        except hamsa.HamsaError as exc:
            outcome, detail = "clear error", f"{type(exc).__name__}: {exc}"
        except Exception as exc:  # what the corpus is here to find
            outcome, detail = "traceback", f"{type(exc).__name__}: {exc}"
        counts[outcome] += 1
        print(f"api         {name:<28} {outcome:<12} {detail[:150]}")
    print(
        f"{cases} cases, {counts['clear error']} clear errors, {counts['accepted']} accepted, "
        f"{counts['traceback']} tracebacks, {counts['hang']} hangs, {counts['partial file']} partial files"
    )
    print(f"{len(REPAIRABLE)} repairable cases, {repaired} repaired by --repair; {info_runs} info runs, "
          f"{info_tracebacks} tracebacks")  # fmt: skip
    bad = counts["traceback"] + counts["hang"] + counts["partial file"] + counts["accepted"] + info_tracebacks
    return 0 if bad == 0 and repaired == len(REPAIRABLE) else 1


if __name__ == "__main__":
    os.environ.setdefault("PYTHONWARNINGS", "ignore")
    sys.exit(main())
