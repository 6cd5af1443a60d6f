"""Feed hamsa hostile inputs through the CLI and the Python API and count how each one ends.

The corpus is generated here (no data files), with warnings visible. Four groups:

* **mesh files** through ``hamsa basis FILE -k 4 -o OUT.npz`` (and ``hamsa info FILE``): malformed
  formats, huge claimed counts and indices, overflowing coordinates, gzip bombs, devices and pipes;
* **command lines** that aim an output at an input or a device, hand over damaged arrays, potentials
  or compressed files, or are interrupted during start-up;
* **API calls** with wrong shapes, dtypes and values, and **saved files** whose arrays were re-written
  with a recomputed checksum (anyone can), all of which must raise a :class:`hamsa.HamsaError`;
* **repairs**: the defects with one right fix must be repaired by ``--repair`` (exit 0).

A CLI outcome is a "clear error" (exit 2, or 3 for a solver failure, or 130 for Ctrl-C, and exactly one
line on stderr, no traceback and no warning), "warned" (exit 0 with a warning naming ``--repair``: what
:data:`UNUSUAL` lists gives right numbers as it is, so it is taken), "accepted" (exit 0 otherwise: the
input was not hostile after all),
a "traceback" (anything else), a "hang" (timeout), a "partial file" (an output or temporary file left
behind) or "unsafe" (an input changed, a device replaced, or the interpreter killed by a signal).
Prints one line per case and the summary lines

    N cases, N clear errors, 3 accepted with a warning naming --repair (of 3 meant to be), 0 accepted
    otherwise, 0 tracebacks, 0 hangs, 0 partial files, 0 unsafe
    R repairable cases, R repaired by --repair; I info runs, 0 tracebacks

Run: ``python benchmarks/hostile_inputs.py`` (about five minutes on two cores).
"""

from __future__ import annotations

import gzip
import hashlib
import lzma
import os
import signal
import stat
import struct
import subprocess
import sys
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np

import hamsa
from hamsa import compression, shapes

TIMEOUT = 120

TRIANGLE = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
SQUARE_VERTICES = "0 0 0\n1 0 0\n1 1 0\n0 1 0\n"


def _off(vertices: list[str], faces: list[str]) -> str:
    return f"OFF\n{len(vertices)} {len(faces)} 0\n" + "\n".join(vertices) + "\n" + "\n".join(faces) + "\n"


def _sphere_lines(scale: float = 1.0) -> tuple[list[str], list[str]]:
    ok = shapes.icosphere(1)
    return [f"{x * scale:.9g} {y * scale:.9g} {z * scale:.9g}" for x, y, z in ok.vertices], [
        f"3 {a} {b} {c}" for a, b, c in ok.faces
    ]


def _gzip_bomb(expanded: int) -> bytes:
    """About expanded / 1000 bytes of gzip (concatenated members) that decompress to ``expanded`` zero bytes."""
    chunk = 16 << 20
    member = gzip.compress(b"0" * chunk, compresslevel=9, mtime=0)
    return member * (expanded // chunk)


def mesh_files() -> dict[str, bytes]:
    """name -> file content; the suffix picks the format."""
    lines, faces = _sphere_lines()
    two = _off(
        lines + [f"{float(x) + 5:.9g} {y} {z}" for x, y, z in (line.split() for line in lines)],
        faces + [f"3 {int(a) + 42} {int(b) + 42} {int(c) + 42}" for _, a, b, c in (f.split() for f in faces)],
    )
    flipped = faces[:5] + [" ".join(["3"] + f.split()[1:][::-1]) for f in faces[5:6]] + faces[6:]
    good_gz = gzip.compress(_off(lines, faces).encode(), mtime=0)
    damaged_gz = bytearray(good_gz)
    damaged_gz[len(good_gz) // 2] ^= 0xFF
    return {
        "empty.off": b"",
        "whitespace.obj": b"   \n\n",
        "truncated.off": _off(lines, faces)[:200].encode(),
        "garbage.ply": bytes(range(256)) * 4,
        "garbage.stl": b"\x13" * 1000,
        "wrong_counts.off": f"OFF\n10 20 0\n{SQUARE_VERTICES}3 0 1 2\n".encode(),
        "nan.off": TRIANGLE.replace("0 1 0\n3", "0 nan 0\n3").encode(),
        "inf.obj": b"v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n",
        "huge.off": TRIANGLE.replace("1 0 0\n", "1e300 0 0\n").encode(),
        "coordinates_1e76.off": _off(*_sphere_lines(1e76)).encode(),
        "coordinates_1e100.obj": "".join(f"v {line}\n" for line in _sphere_lines(1e100)[0]).encode()
        + "".join(f"f {int(a) + 1} {int(b) + 1} {int(c) + 1}\n" for _, a, b, c in (f.split() for f in faces)).encode(),
        "coordinates_1e149.off": _off(*_sphere_lines(1e149)).encode(),
        "complex_coordinate.off": TRIANGLE.replace("1 0 0\n", "1+2j 0 0\n").encode(),
        "negative_index.off": f"OFF\n4 2 0\n{SQUARE_VERTICES}3 0 1 2\n3 0 2 -1\n".encode(),
        "index_2pow63.off": f"OFF\n4 2 0\n{SQUARE_VERTICES}3 0 1 2\n3 0 2 9223372036854775808\n".encode(),
        "index_1e300.off": f"OFF\n4 2 0\n{SQUARE_VERTICES}3 0 1 2\n3 0 2 1e300\n".encode(),
        "index_beyond_int64.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999999999\n",
        "index_negative_huge.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -99999999999999999999999999\n",
        "out_of_range.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n",
        "float_index.off": f"OFF\n4 2 0\n{SQUARE_VERTICES}3 0 1 2.5\n3 0 2 3\n".encode(),
        "repeated_vertex.off": f"OFF\n4 2 0\n{SQUARE_VERTICES}3 0 1 1\n3 0 2 3\n".encode(),
        "zero_area.off": b"OFF\n3 1 0\n0 0 0\n1 0 0\n2 0 0\n3 0 1 2\n",
        "duplicate_faces.off": f"OFF\n4 3 0\n{SQUARE_VERTICES}3 0 1 2\n3 0 2 3\n3 2 1 0\n".encode(),
        "nonmanifold_edge.off": b"OFF\n5 3 0\n0 0 0\n1 0 0\n0 1 0\n0 -1 0\n0 0 1\n3 0 1 2\n3 1 0 3\n3 0 1 4\n",
        "self_crossing_polygon.off": b"OFF\n5 1 0\n0 0 0\n2 0 0\n0 2 0\n2 2 0\n1 3 0\n5 0 1 2 3 4\n",
        "binary_ply_short.ply": b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
        b"property float y\nproperty float z\nelement face 1\n"
        b"property list uchar int vertex_indices\nend_header\n\x00\x00\x80",
        "not_gzip.off.gz": b"plain text, not gzip",
        "damaged.off.gz": bytes(damaged_gz),
        "truncated.off.gz": good_gz[: len(good_gz) // 2],
        "bomb.off.gz": _gzip_bomb(3 << 29),  # 1.5 MB that expand to 1.5 GiB
        "unknown.xyz": b"1 2 3\n",
        # repairable with --repair (REPAIRABLE below); refused without it
        "needle.off": b"OFF\n3 1 0\n0 0 0\n1 0 0\n0.5 1e-9 0\n3 0 1 2\n",
        "single_triangle.off": TRIANGLE.encode(),
        "isolated_vertex.off": _off(lines + ["9 9 9"], faces).encode(),
        "two_pieces.off": two.encode(),
        "inconsistent_orientation.off": _off(lines, flipped).encode(),
        "nonmanifold_vertex.off": b"OFF\n7 6 0\n0 0 0\n1 0 0\n0 1 0\n1 1 1\n-1 0 0\n0 -1 0\n-1 -1 -1\n"
        b"3 0 1 2\n3 0 2 3\n3 0 3 1\n3 0 4 5\n3 0 5 6\n3 0 6 4\n",
    }


def special_files(folder: Path) -> list[str]:
    """Mesh paths that are not regular files: a symlink to /dev/zero, a named pipe, a folder."""
    (folder / "zero.off").symlink_to("/dev/zero")
    os.mkfifo(folder / "pipe.obj")
    (folder / "folder.off").mkdir()
    return ["zero.off", "pipe.obj", "folder.off"]


REPAIRABLE = (
    "duplicate_faces.off",
    "repeated_vertex.off",
    "isolated_vertex.off",
    "two_pieces.off",
    "inconsistent_orientation.off",
    "nonmanifold_vertex.off",
)
# right numbers as they are: every command takes them, with a warning that names --repair
UNUSUAL = ("two_pieces.off", "inconsistent_orientation.off", "nonmanifold_vertex.off")


# ---------------------------------------------------------------------------------- the runner
def _digest(path: Path) -> str | None:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None
    except OSError:
        return None


def wait_until_mapped(pid: int, library: str, timeout: float = 60.0) -> None:
    """Wait until process ``pid`` maps a shared library whose path contains ``library`` (Linux /proc)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if library in Path(f"/proc/{pid}/maps").read_text():
                return
        except OSError:
            pass
        time.sleep(0.005)
    raise RuntimeError(f"process {pid} never loaded {library}")


def run_cli(args: list[str], folder: Path, protect=(), output: Path | None = None, interrupt: str | None = None):
    """Run ``python -m hamsa ARGS``; returns (outcome, detail). ``protect``: files that must not change;
    ``output``: the output the command must not leave behind on failure; ``interrupt``: send Ctrl-C once the
    process loads the shared library of that name (a point in its start-up, on a fast or a loaded machine)."""
    protected = {Path(p): _digest(Path(p)) for p in protect}
    if output is not None and output.is_file():
        output.unlink()
    process = subprocess.Popen(
        [sys.executable, "-m", "hamsa", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        if interrupt is not None:
            wait_until_mapped(process.pid, interrupt)
            process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        process.kill()
        process.communicate()
        return "hang", f"no answer in {TIMEOUT} s"
    changed = [p.name for p, digest in protected.items() if _digest(p) != digest]
    if changed or process.returncode < 0 or not stat.S_ISCHR(os.stat("/dev/null").st_mode):
        return "unsafe", f"inputs changed: {changed}" if changed else f"exit {process.returncode}"
    leftovers = [p.name for p in folder.rglob("*.tmp")]
    lines = [line for line in stderr.strip().splitlines() if not line.startswith("reproduce:")]
    if process.returncode == 0:
        return ("partial file", f"temporary files left: {leftovers}") if leftovers else ("accepted", " | ".join(lines))
    if process.returncode in (2, 3, 130) and len(lines) == 1 and "Traceback" not in stderr:
        if (output is not None and output.is_file()) or leftovers:
            return "partial file", f"{output.name if output and output.is_file() else leftovers} left: {lines[0]}"
        return "clear error", lines[0]
    return "traceback", (lines[-1] if lines else f"exit {process.returncode}")


# ------------------------------------------------------------------------------- command lines
def _npy_header(shape, dtype="<f8") -> bytes:
    header = repr({"descr": dtype, "fortran_order": False, "shape": shape}).encode()
    header += b" " * (63 - (10 + len(header)) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header


def _reseal(blob: bytes) -> bytes:
    """Recompute an .hmz file's whole-file checksum (the per-section ones are left as they are)."""
    return blob[:-4] + zlib.crc32(blob[:-4]).to_bytes(4, "little")


def _with_header(data: bytes, n: int, k: int) -> bytes:
    """An .hmz file whose header claims n vertices and k coefficients, every checksum recomputed."""
    start = len(compression.MAGIC) + 2 + 8
    blob = bytearray(data)
    blob[start : start + 8] = struct.pack("<II", n, k)
    section = bytes(blob[start : start + compression._HEADER.size + 48])
    blob[start - 4 : start] = zlib.crc32(section).to_bytes(4, "little")
    return _reseal(bytes(blob))


def _with_coefficients(data: bytes, payload: bytes) -> bytes:
    """An .hmz file whose coefficient section is replaced by ``payload`` with valid checksums."""
    offset = len(compression.MAGIC) + 2
    header_length = struct.unpack_from("<I", data, offset)[0]
    start = offset + 8 + header_length
    length = struct.unpack_from("<I", data, start)[0]
    body = data[:start] + struct.pack("<II", len(payload), zlib.crc32(payload)) + payload
    return _reseal(body + data[start + 8 + length :])


def command_cases(folder: Path) -> list[tuple[str, list[str], list[Path], Path | None, str | None]]:
    """(name, argv, files to protect, output, Ctrl-C point) for the command-line cases."""
    sphere = shapes.icosphere(1)
    n = sphere.n_vertices
    mesh = folder / "m.off"
    hamsa.save_mesh(sphere, mesh)
    hamsa.save_mesh(shapes.icosphere(1), folder / "other.off")
    encoded = compression.encode(sphere, 8, 10)
    (folder / "m.hmz").write_bytes(encoded)
    arrays = {
        "short.npy": np.zeros(n - 1),
        "long.npy": np.zeros(n + 1),
        "complex.npy": np.zeros(n) * 1j,
        "strings.npy": np.array(["a"] * n),
        "cube.npy": np.zeros((n, 2, 2)),
        "nan.npy": np.where(np.arange(n) == 3, np.nan, 0.0),
        "good.npy": np.zeros(n),
    }
    for name, value in arrays.items():
        np.save(folder / name, value)
    np.save(folder / "pickle.npy", np.array([{"a": 1}] * n, dtype=object), allow_pickle=True)
    (folder / "huge_header.npy").write_bytes(_npy_header((2**40,)) + b"\0" * 64)
    (folder / "lying_header.npy").write_bytes(_npy_header((n,)) + b"\0" * 16)
    np.savez(folder / "archive.npz", a=np.zeros(n))
    (folder / "complex.txt").write_text("\n".join(["1+2j"] * n))
    (folder / "words.txt").write_text("\n".join(["high"] * n))
    (folder / "zero.npy").symlink_to("/dev/zero")
    (folder / "link_to_mesh.npz").symlink_to(mesh)
    (folder / "link_to_mesh.html").symlink_to(mesh)
    (folder / "link_to_null.hmz").symlink_to("/dev/null")
    (folder / "link_to_good.npy").symlink_to(folder / "good.npy")
    os.link(mesh, folder / "hardlink.off")
    (folder / "existing.npz").mkdir()
    hmz = {
        "v1.hmz": encoded[:3] + b"\x01" + encoded[4:],
        "empty.hmz": b"",
        "truncated.hmz": encoded[: len(encoded) // 2],
        "n_2pow32.hmz": _with_header(encoded, 2**32 - 1, 8),
        "k_2pow31.hmz": _with_header(encoded, n, 2**31),
        "k_zero.hmz": _with_header(encoded, n, 0),
        "method_resealed.hmz": _reseal(encoded[:4] + b"\x02" + encoded[5:]),
        "lzma_bomb.hmz": _with_coefficients(encoded, lzma.compress(b"\0" * (64 << 20))),
        "garbage_coefficients.hmz": _with_coefficients(encoded, b"not lzma at all"),
    }
    for position in (0, 3, 4, 6, 12, 20, 40, len(encoded) // 2, len(encoded) - 1):
        flipped = bytearray(encoded)
        flipped[position] ^= 0x01
        hmz[f"bit_{position}.hmz"] = bytes(flipped)
    for name, content in hmz.items():
        (folder / name).write_bytes(content)
    out_npz, out_npy, out_hmz = folder / "out.npz", folder / "out.npy", folder / "out.hmz"
    m, protect = str(mesh), [mesh]
    cases = [
        ("compress onto its input", ["compress", m, "-k", "6", "-o", m], protect, None, None),
        ("compress onto ./input", ["compress", m, "-k", "6", "-o", str(folder / "." / "m.off")], protect, None, None),
        ("compress onto a hard link", ["compress", m, "-k", "6", "-o", str(folder / "hardlink.off")], protect, None,
         None),
        ("decompress onto its faces", ["decompress", str(folder / "m.hmz"), "--faces", m, "-o", m],
         [mesh, folder / "m.hmz"], None, None),
        ("basis onto a symlinked input", ["basis", m, "-k", "4", "-o", str(folder / "link_to_mesh.npz")], protect,
         None, None),
        ("view onto a symlinked input", ["view", m, "-k", "4", "-o", str(folder / "link_to_mesh.html")], protect,
         None, None),
        ("optimize onto its data", ["optimize", m, "-k", "4", "--data", str(folder / "good.npy"), "-o",
                                    str(folder / "good.npy")], [folder / "good.npy"], None, None),
        ("optimize onto a link to its data", ["optimize", m, "-k", "4", "--data", str(folder / "good.npy"), "-o",
                                              str(folder / "link_to_good.npy")], [folder / "good.npy"], None, None),
        ("match onto its source", ["match", m, str(folder / "other.off"), "-o", m], protect, None, None),
        ("compress to /dev/null", ["compress", m, "-k", "6", "-o", "/dev/null"], protect, None, None),
        ("compress to a link to /dev/null", ["compress", m, "-k", "6", "-o", str(folder / "link_to_null.hmz")],
         protect, None, None),
        ("basis to an existing folder", ["basis", m, "-k", "4", "-o", str(folder / "existing.npz")], protect, None,
         None),
        ("basis to a missing folder", ["basis", m, "-k", "4", "-o", str(folder / "no" / "x.npz")], protect, None,
         None),
        ("basis to a 300-byte name", ["basis", m, "-k", "4", "-o", str(folder / ("x" * 300 + ".npz"))], protect,
         None, None),
        ("benchmark into a file", ["benchmark-matching", str(folder), "-o", m], protect, None, None),
        ("Ctrl-C during start-up", ["reproduce", "--quick", "-o", str(folder / "report")], [], None,
         "_multiarray_umath"),
    ]  # fmt: skip
    for name in (*arrays, "pickle.npy", "huge_header.npy", "lying_header.npy", "archive.npz", "complex.txt",
                 "words.txt", "zero.npy"):  # fmt: skip
        if name != "good.npy":
            cases.append((f"potential {name}", ["basis", m, "-k", "4", "--potential", str(folder / name), "-o",
                                               str(out_npz)], protect, out_npz, None))  # fmt: skip
    for name in ("short.npy", "strings.npy", "cube.npy", "complex.npy", "archive.npz", "pickle.npy", "zero.npy"):
        cases.append((f"optimize --data {name}", ["optimize", m, "-k", "4", "--data", str(folder / name), "-o",
                                                  str(out_npy)], protect, out_npy, None))  # fmt: skip
    cases.append(("view --potential long.npy", ["view", m, "--potential", str(folder / "long.npy"), "-o",
                                                str(folder / "v.html")], protect, folder / "v.html", None))  # fmt: skip
    for name in hmz:
        cases.append((f"decompress {name}", ["decompress", str(folder / name), "--faces", m, "-o",
                                             str(folder / "d.off")], protect, folder / "d.off", None))  # fmt: skip
    cases.append(("decompress, faces of another size", ["decompress", str(folder / "m.hmz"), "--faces",
                                                        str(folder / "two_pieces.off"), "-o", str(folder / "d.off")],
                  protect, folder / "d.off", None))  # fmt: skip
    cases.append(("compress -k n", ["compress", m, "-k", str(n), "-o", str(out_hmz)], protect, out_hmz, None))
    return cases


# ------------------------------------------------------------------------------------ API cases
def _rewritten_basis(basis, reseal: bool, **changes):
    """A saved basis whose arrays are re-written (``changes``: name -> array, or a function of the old
    array), its checksum recomputed when ``reseal`` (as anyone can), then loaded."""
    from hamsa.eigen import _checksum

    def case():
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "basis.npz"
            basis.save(path)
            with np.load(path) as data:
                arrays = dict(data)
            arrays.update(
                {name: change(arrays[name]) if callable(change) else change for name, change in changes.items()}
            )
            if reseal:
                arrays["checksum"] = np.array(_checksum(arrays))
            np.savez(path, **arrays)
            hamsa.Eigenbasis.load(path)

    return case


def _tampered_basis(basis, **changes):
    return _rewritten_basis(basis, True, **changes)


def _load_special(kind: str, name: str = "basis.npz", load=None):
    """Load (default: ``Eigenbasis.load``) a symlink to /dev/zero, a named pipe or a broken zip."""

    def case():
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / name
            if kind == "zero":
                path.symlink_to("/dev/zero")
            elif kind == "pipe":
                os.mkfifo(path)
            else:
                path.write_bytes(b"PK\x03\x04" + b"\0" * 100)
            (load or hamsa.Eigenbasis.load)(path)

    return case


def api_cases() -> dict[str, callable]:
    from hamsa import diffusion, potentials
    from hamsa.geodesic import geodesic_distance
    from hamsa.matching import match
    from hamsa.paper.reproduce import reproduce
    from hamsa.repair import repair_mesh
    from hamsa.viz import to_html

    sphere = shapes.icosphere(2)
    basis = hamsa.eigenbasis(sphere, 8)
    n = sphere.n_vertices
    encoded = compression.encode(shapes.icosphere(1), 8, 10)
    cases = {
        "k >= n": lambda: hamsa.eigenbasis(sphere, n + 1),
        "k = 0": lambda: hamsa.eigenbasis(sphere, 0),
        "k negative": lambda: hamsa.eigenbasis(sphere, -3),
        "k float": lambda: hamsa.eigenbasis(sphere, 2.5),
        "potential too short": lambda: hamsa.eigenbasis(sphere, 4, np.zeros(n - 1)),
        "potential with NaN": lambda: hamsa.eigenbasis(sphere, 4, np.where(np.arange(n) == 3, np.nan, 0.0)),
        "potential 2-D": lambda: hamsa.eigenbasis(sphere, 4, np.zeros((n, 2))),
        "potential of 1e300": lambda: hamsa.eigenbasis(sphere, 4, np.full(n, 1e300)),
        "potential of strings": lambda: hamsa.eigenbasis(sphere, 4, ["a"] * n),
        "potential complex": lambda: hamsa.eigenbasis(sphere, 4, np.ones(n) * (1 + 1j)),
        "diffusion time 0": lambda: diffusion.heat_kernel(basis, 0.0, [0]),
        "diffusion time negative": lambda: diffusion.diffuse(basis, np.ones(n), -1.0),
        "empty landmark list": lambda: geodesic_distance(sphere, [], normalize=True),
        "landmark out of range": lambda: geodesic_distance(sphere, [n + 5], normalize=True),
        "mismatched vertex counts": lambda: potentials.area_distortion(sphere, shapes.icosphere(1)),
        "project wrong length": lambda: basis.project(np.ones(n + 1)),
        "project (n, 2, 2)": lambda: basis.project(np.ones((n, 2, 2))),
        "project complex": lambda: basis.project(np.ones(n) * 1j),
        "project strings": lambda: basis.project(["x"] * n),
        "reconstruct (k, 2, 2)": lambda: basis.reconstruct(np.ones((basis.k, 2, 2))),
        "mesh from a string": lambda: hamsa.eigenbasis("sphere.off", 4),
        "vertices (n, 2)": lambda: hamsa.TriMesh(np.zeros((3, 2)), [[0, 1, 2]]),
        "vertices complex": lambda: hamsa.TriMesh(np.eye(3) * (1 + 1j), [[0, 1, 2]]),
        "vertices 1e76": lambda: hamsa.TriMesh(sphere.vertices * 1e76, sphere.faces),
        "faces ragged": lambda: hamsa.TriMesh(np.eye(3), [[0, 1, 2], [0, 1]]),
        "faces uint64 max": lambda: hamsa.TriMesh(np.eye(3), np.array([[0, 1, 2**64 - 1]], dtype=np.uint64)),
        "faces float": lambda: hamsa.TriMesh(np.eye(3), [[0.0, 1.0, 2.0]]),
        "basis from non-orthonormal arrays": lambda: hamsa.Eigenbasis.from_arrays(
            basis.values, 2 * basis.vectors, basis.mass.diagonal()
        ),
        "basis from a NaN mass": lambda: hamsa.Eigenbasis.from_arrays(basis.values, basis.vectors, np.full(n, np.nan)),
        "basis from complex vectors": lambda: hamsa.Eigenbasis.from_arrays(
            basis.values, basis.vectors * 1j, np.ones(n)
        ),
        "basis from a 2-D mass array": lambda: hamsa.Eigenbasis.from_arrays(
            basis.values, basis.vectors, np.ones((n, 2))
        ),
        "basis from ragged values": lambda: hamsa.Eigenbasis.from_arrays(
            [[1.0], [1.0, 2.0]], basis.vectors, np.ones(n)
        ),
        "corrupted basis file": _rewritten_basis(basis, False, vectors=lambda vectors: vectors + 1e-6),
        "basis file: indices out of range": _tampered_basis(basis, mass_indices=np.arange(n) + 10**6),
        "basis file: negative indices": _tampered_basis(basis, mass_indices=-np.arange(n)),
        "basis file: short indptr": _tampered_basis(basis, mass_indptr=np.arange(n)),
        "basis file: decreasing indptr": _tampered_basis(basis, mass_indptr=np.r_[0, np.arange(n)[::-1]]),
        "basis file: float indices": _tampered_basis(basis, mass_indices=np.arange(n) + 0.5),
        "basis file: NaN mass": _tampered_basis(basis, mass_data=np.full(n, np.nan)),
        "basis file: negative mass": _tampered_basis(basis, mass_data=-np.ones(n)),
        "basis file: k mismatch": _tampered_basis(basis, values=np.zeros(basis.k - 1)),
        "basis file: vectors 1-D": _tampered_basis(basis, vectors=np.ones(n * basis.k)),
        "basis file: not orthonormal": _tampered_basis(basis, vectors=np.ones((n, basis.k))),
        "basis file: infinite values": _tampered_basis(basis, values=np.full(basis.k, np.inf)),
        "basis file: string values": _tampered_basis(basis, values=np.array(["a"] * basis.k)),
        "basis file: potential too short": _tampered_basis(basis, potential=np.ones(n - 1)),
        "basis file: unknown mass kind": _tampered_basis(basis, mass_kind=np.array("bogus")),
        "basis file: format 99": _tampered_basis(basis, format_version=np.array(99)),
        "basis file: a symlink to /dev/zero": _load_special("zero"),
        "basis file: a named pipe": _load_special("pipe"),
        "basis file: a broken zip": _load_special("zip"),
        "decode: method byte flipped": lambda: compression.decode(encoded[:4] + b"\x01" + encoded[5:], np.zeros(3)),
        "decode: not bytes": lambda: compression.decode("HMZ", np.zeros((1, 3), dtype=int)),
        "decode: float faces": lambda: compression.decode(encoded, shapes.icosphere(1).faces * 1.0),
        "decode: faces of another mesh": lambda: compression.decode(encoded, shapes.icosphere(2).faces),
        "decode: n = 2^32 - 1": lambda: compression.decode(
            _with_header(encoded, 2**32 - 1, 8), shapes.icosphere(1).faces
        ),
        "repair a non-manifold edge": lambda: repair_mesh(
            np.eye(3).tolist() + [[0, 0, 0], [1, 1, 1]], [[0, 1, 2], [1, 0, 3], [0, 1, 4]]
        ),
        "unknown matching method": lambda: match(basis, basis, "sift"),
        "view field of wrong length": lambda: to_html(sphere, np.zeros(n + 3), "never.html"),
        "view onto /dev/null": lambda: to_html(sphere, np.zeros(n), "/dev/null"),
        "unknown experiment": lambda: reproduce("never", only=["fig99"], progress=False),
        "intrinsic Laplacian, full mass": lambda: hamsa.eigenbasis(
            sphere, 4, mass="full", laplacian="intrinsic_delaunay"
        ),
        "save a mesh to a folder": lambda: hamsa.save_mesh(sphere, tempfile.gettempdir()),
        "load a mesh from /dev/zero": _load_special("zero", "mesh.off", hamsa.load_mesh),
        "load a mesh from a pipe": _load_special("pipe", "mesh.obj", hamsa.load_mesh),
    }
    return cases


def run_api_cases(print_line=print) -> dict[str, int]:
    """Run every API case in-process; returns the outcome counts."""
    counts = {"clear error": 0, "accepted": 0, "traceback": 0}
    for name, case in api_cases().items():
        try:
            case()
            outcome, detail = "accepted", ""
        except hamsa.HamsaError as exc:
            outcome, detail = "clear error", f"{type(exc).__name__}: {exc}"
        except Exception as exc:  # what the corpus is here to find
            outcome, detail = "traceback", f"{type(exc).__name__}: {exc}"
        counts[outcome] += 1
        print_line(f"api         {name:<34} {outcome:<12} {detail[:150]}")
    return counts


def main() -> int:
    counts = {"clear error": 0, "warned": 0, "accepted": 0, "traceback": 0, "hang": 0, "partial file": 0, "unsafe": 0}
    cases = repaired = info_runs = info_tracebacks = unwarned = 0
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        names = []
        for name, content in mesh_files().items():
            (folder / name).write_bytes(content)
            names.append(name)
        names += special_files(folder)
        out = folder / "out.npz"
        for name in names:
            path = str(folder / name)
            outcome, detail = run_cli(["basis", path, "-k", "4", "-o", str(out)], folder, [folder / name], out)
            if name in UNUSUAL and outcome == "accepted" and "warning:" in detail and "--repair" in detail:
                outcome = "warned"
            unwarned += name in UNUSUAL and outcome != "warned"
            counts[outcome] += 1
            cases += 1
            print(f"cli basis   {name:<34} {outcome:<12} {detail}", flush=True)
            info, detail = run_cli(["info", path], folder, [folder / name])
            info_runs += 1
            info_tracebacks += info not in ("clear error", "accepted")
            if info not in ("clear error", "accepted"):
                print(f"cli info    {name:<34} {info:<12} {detail}", flush=True)
            if name in REPAIRABLE:
                fixed, detail = run_cli(["basis", path, "-k", "2", "--repair", "-o", str(out)], folder)
                repaired += fixed == "accepted"
                print(f"cli repair  {name:<34} {'repaired' if fixed == 'accepted' else fixed:<12} {detail}")
        for name, args, protect, output, interrupt in command_cases(folder):
            outcome, detail = run_cli(args, folder, protect, output, interrupt)
            counts[outcome] += 1
            cases += 1
            print(f"cli         {name:<34} {outcome:<12} {detail}", flush=True)
    api = run_api_cases()
    cases += sum(api.values())
    for outcome, count in api.items():
        counts[outcome] += count
    print(
        f"{cases} cases, {counts['clear error']} clear errors, {counts['warned']} accepted with a warning "
        f"naming --repair (of {len(UNUSUAL)} meant to be), {counts['accepted']} accepted otherwise, "
        f"{counts['traceback']} tracebacks, {counts['hang']} hangs, {counts['partial file']} partial files, "
        f"{counts['unsafe']} unsafe"
    )
    print(f"{len(REPAIRABLE)} repairable cases, {repaired} repaired by --repair; {info_runs} info runs, "
          f"{info_tracebacks} tracebacks")  # fmt: skip
    bad = cases - counts["clear error"] - counts["warned"] + unwarned + info_tracebacks
    return 0 if bad == 0 and repaired == len(REPAIRABLE) else 1


if __name__ == "__main__":
    sys.exit(main())
