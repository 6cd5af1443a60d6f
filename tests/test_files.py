"""hamsa.files and the places that rely on it: bounded reads, header-checked arrays, safe outputs,
strictly validated basis and compressed files."""

from __future__ import annotations

import errno
import gzip
import hashlib
import os
import time
import zlib

import numpy as np
import pytest

import hamsa
from hamsa import compression, shapes
from hamsa.cli import main
from hamsa.errors import CompressionError, ConvergenceError, FileAccessError, HamsaError
from hamsa.files import atomic_write, check_output, load_array, load_npz, read_bytes


@pytest.fixture(scope="module")
def sphere():
    return shapes.icosphere(2)


@pytest.fixture(scope="module")
def basis(sphere):
    return hamsa.eigenbasis(sphere, 6)


# ------------------------------------------------------------------------------------- reading
def test_read_bytes_refuses_what_is_not_a_regular_file(tmp_path):
    fifo = tmp_path / "pipe.off"
    os.mkfifo(fifo)
    start = time.perf_counter()
    with pytest.raises(FileAccessError, match="not a regular file"):
        read_bytes(fifo)  # a pipe without writer: refused, not waited on
    assert time.perf_counter() - start < 5
    (tmp_path / "zero.off").symlink_to("/dev/zero")
    with pytest.raises(hamsa.MeshError, match="not a regular file"):
        hamsa.io.read_mesh_arrays(tmp_path / "zero.off")
    with pytest.raises(FileAccessError, match="folder"):
        read_bytes(tmp_path)
    with pytest.raises(FileAccessError, match="no such file"):
        read_bytes(tmp_path / "missing")


def test_read_limit_bounds_plain_and_gzip_reads(tmp_path, monkeypatch):
    plain = tmp_path / "a.off"
    plain.write_bytes(b"x" * 5000)
    assert read_bytes(plain, limit=5000) == b"x" * 5000
    with pytest.raises(FileAccessError, match="read limit"):
        read_bytes(plain, limit=4999)
    bomb = tmp_path / "bomb.off.gz"
    bomb.write_bytes(gzip.compress(b"0" * (8 << 20)))  # 8 KiB that expand to 8 MiB
    assert bomb.stat().st_size < 100_000
    monkeypatch.setenv("HAMSA_READ_LIMIT", "1M")
    with pytest.raises(hamsa.MeshError, match="read limit of 1 MiB once decompressed"):
        hamsa.load_mesh(bomb)
    monkeypatch.setenv("HAMSA_READ_LIMIT", "lots")
    with pytest.raises(FileAccessError, match="HAMSA_READ_LIMIT"):
        read_bytes(plain)
    damaged = bytearray(gzip.compress(b"OFF\n" * 1000))
    damaged[30] ^= 0xFF
    (tmp_path / "damaged.off.gz").write_bytes(bytes(damaged))
    monkeypatch.delenv("HAMSA_READ_LIMIT")
    with pytest.raises(hamsa.MeshError, match="not a valid gzip"):
        hamsa.load_mesh(tmp_path / "damaged.off.gz")


def _npy_with_header(shape, dtype="<f8", data=b""):
    header = repr({"descr": dtype, "fortran_order": False, "shape": shape}).encode()
    header += b" " * (63 - (10 + len(header)) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header + data


def test_load_array_checks_the_header_before_reading(tmp_path):
    path = tmp_path / "v.npy"
    np.save(path, np.arange(10.0))
    np.testing.assert_array_equal(load_array(path, ndim=1, rows=10), np.arange(10.0))
    with pytest.raises(FileAccessError, match="expected 12 rows"):
        load_array(path, rows=12)
    path.write_bytes(_npy_with_header((2**40, 3), data=b"\0" * 64))  # claims 24 TiB
    with pytest.raises(FileAccessError, match="beyond the read limit"):
        load_array(path)
    path.write_bytes(_npy_with_header((100,), data=b"\0" * 64))
    with pytest.raises(FileAccessError, match="header claims 800"):
        load_array(path)
    for value, message in ((np.ones(10) * 1j, "complex"), (np.array(["a"] * 10), "non-numeric"),
                           (np.ones((10, 2, 2)), "expected 1-D or 2-D")):  # fmt: skip
        np.save(path, value)
        with pytest.raises(FileAccessError, match=message):
            load_array(path, ndim=(1, 2), rows=10)
    np.save(path, np.array([{"a": 1}] * 10, dtype=object), allow_pickle=True)
    with pytest.raises(FileAccessError, match="never loads pickled"):
        load_array(path)
    np.savez(tmp_path / "two.npz", a=np.ones(3))
    os.replace(tmp_path / "two.npz", path)
    with pytest.raises(FileAccessError, match="npz archive"):
        load_array(path)


def test_load_npz_refuses_a_member_claiming_a_huge_shape(tmp_path):
    import zipfile

    path = tmp_path / "b.npz"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("values.npy", _npy_with_header((2**33,), data=b"\0" * 80))
    with pytest.raises(FileAccessError, match="beyond the read limit|header claims"):
        load_npz(path)


# -------------------------------------------------------------------------------------- output
def test_check_output_refuses_inputs_devices_folders_and_long_names(tmp_path):
    source = tmp_path / "m.off"
    source.write_text("x")
    with pytest.raises(FileAccessError, match="same file as the input"):
        check_output(source, inputs=[source])
    os.link(source, tmp_path / "hard.off")
    with pytest.raises(FileAccessError, match="same file as the input"):
        check_output(tmp_path / "hard.off", inputs=[source])
    (tmp_path / "link.off").symlink_to(source)
    with pytest.raises(FileAccessError, match="same file as the input"):
        check_output(tmp_path / "link.off", inputs=[str(source)])
    with pytest.raises(FileAccessError, match="not a regular file"):
        check_output("/dev/null")
    (tmp_path / "null.npz").symlink_to("/dev/null")
    with pytest.raises(FileAccessError, match="not a regular file"):
        check_output(tmp_path / "null.npz")
    with pytest.raises(FileAccessError, match="existing folder"):
        check_output(tmp_path)
    with pytest.raises(FileAccessError, match="does not exist"):
        check_output(tmp_path / "no" / "x.npz")
    with pytest.raises(FileAccessError, match="longer than"):
        check_output(tmp_path / ("x" * 300 + ".npz"))
    with pytest.raises(FileAccessError, match="must end in .npz"):
        check_output(tmp_path / "x.npy", suffix=".npz")
    assert check_output(tmp_path / ("y" * 240 + ".npz")).name.startswith("y")  # the temporary name fits too


def test_atomic_write_turns_os_errors_into_one_clear_error(tmp_path, monkeypatch):
    def full(*args):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "replace", full)
    with pytest.raises(FileAccessError, match="disk is full"):
        with atomic_write(tmp_path / "x.bin") as handle:
            handle.write(b"data")
    assert os.listdir(tmp_path) == []


def test_atomic_write_through_a_symlink_replaces_the_target(tmp_path):
    (tmp_path / "real.txt").write_text("old")
    (tmp_path / "link.txt").symlink_to(tmp_path / "real.txt")
    with atomic_write(tmp_path / "link.txt", "w") as handle:
        handle.write("new")
    assert (tmp_path / "link.txt").is_symlink() and (tmp_path / "real.txt").read_text() == "new"


# --------------------------------------------------------------------------- saved bases are input
def _rewrite(path, **changes):
    """Re-write members of a saved basis and recompute its checksum, as anyone can."""
    from hamsa.eigen import _checksum

    with np.load(path) as data:
        arrays = dict(data)
    arrays.update(changes)
    for name in [name for name, value in changes.items() if value is None]:
        del arrays[name]
    arrays["checksum"] = np.array(_checksum(arrays))
    np.savez(path, **arrays)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"mass_indices": np.arange(162) + 10**6}, "column indices outside"),
        ({"mass_indices": -np.arange(162)}, "column indices outside"),
        ({"mass_indptr": np.arange(161)}, "do not describe"),
        ({"mass_indptr": np.r_[0, np.arange(162)[::-1]]}, "row pointers"),
        ({"mass_data": np.full(162, np.nan)}, "mass must be finite"),
        ({"mass_data": -np.ones(162)}, "positive"),
        ({"mass_indices": np.arange(162.0)}, "must be integers"),
        ({"values": np.zeros(5)}, "must be \\(k,\\) and \\(n, k\\)"),
        ({"values": np.full(6, np.inf)}, "values must be finite"),
        ({"vectors": np.ones((162, 6))}, "not mass-orthonormal"),
        ({"vectors": np.ones(162 * 6)}, "expected 2-D"),
        ({"vectors": np.ones((162, 6)) * 1j}, "complex"),
        ({"potential": np.ones(161)}, "potential must be"),
        ({"mass_kind": np.array("bogus")}, "mass kind"),
        ({"format_version": np.array(99)}, "format 99"),
        ({"values": None}, "has no values"),
    ],
)
def test_tampered_basis_files_are_refused_before_use(tmp_path, basis, changes, message):
    path = tmp_path / "b.npz"
    basis.save(path)
    _rewrite(path, **changes)
    with pytest.raises(HamsaError, match=message):
        hamsa.Eigenbasis.load(path)


def test_from_arrays_checks_finiteness_before_orthonormality(basis):
    with pytest.raises(HamsaError, match="mass must be finite"):
        hamsa.Eigenbasis.from_arrays(basis.values, basis.vectors, np.full(basis.n, np.nan))
    with pytest.raises(HamsaError, match="function has shape"):
        basis.project(np.ones((basis.n, 2, 2)))
    with pytest.raises(HamsaError, match="coefficients have shape"):
        basis.reconstruct(np.ones((basis.k, 2, 2)))


def test_the_basis_cache_recomputes_a_tampered_entry(tmp_path, sphere):
    from hamsa.datasets import cached_eigenbasis

    first = cached_eigenbasis(sphere, 6, tmp_path)
    (entry,) = tmp_path.glob("*.npz")
    _rewrite(entry, mass_indices=np.arange(sphere.n_vertices) + 999)
    again = cached_eigenbasis(sphere, 6, tmp_path)
    np.testing.assert_allclose(again.values, first.values, atol=1e-10)


# ------------------------------------------------------------------------------ compressed files
def test_every_byte_of_a_compressed_file_is_covered(sphere):
    data = compression.encode(sphere, 10, 10)
    for position in range(len(data)):
        for bit in (0x01, 0x80):
            broken = bytearray(data)
            broken[position] ^= bit
            with pytest.raises(CompressionError):
                compression.decode(bytes(broken), sphere.faces)


def _reseal(blob: bytes) -> bytes:
    return blob[:-4] + zlib.crc32(blob[:-4]).to_bytes(4, "little")


def test_claimed_sizes_are_bounded_before_allocation(sphere):
    import struct

    data = compression.encode(sphere, 10, 10)
    header_start = len(compression.MAGIC) + 2 + 8
    for n, k in ((2**32 - 1, 10), (sphere.n_vertices, 2**31), (sphere.n_vertices, 0)):
        blob = bytearray(data)
        blob[header_start : header_start + 8] = struct.pack("<II", n, k)
        section = bytes(blob[header_start : header_start + compression._HEADER.size + 48])
        blob[header_start - 4 : header_start] = zlib.crc32(section).to_bytes(4, "little")
        with pytest.raises(CompressionError, match="faces reference|do not fit"):
            compression.decode(_reseal(bytes(blob)), sphere.faces)
    method = bytearray(data)
    method[len(compression.MAGIC) + 1] = 2  # mhb -> hamiltonian-opt, checksums recomputed
    with pytest.raises(CompressionError, match="do not match the method"):
        compression.decode(_reseal(bytes(method)), sphere.faces)
    old = bytearray(data)
    old[len(compression.MAGIC)] = 1
    with pytest.raises(CompressionError, match="version 1"):
        compression.decode(bytes(old), sphere.faces)


# ----------------------------------------------------------------------------------------- CLI
def _digest(path):
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def test_cli_never_writes_over_an_input(tmp_path, capsys):
    mesh = tmp_path / "m.off"
    hamsa.save_mesh(shapes.icosphere(1), mesh)
    before = _digest(mesh)
    assert main(["compress", str(mesh), "-k", "6", "-o", str(mesh)]) == 2
    assert main(["compress", str(mesh), "-k", "6", "-o", str(tmp_path / "m.hmz")]) == 0
    assert main(["decompress", str(tmp_path / "m.hmz"), "--faces", str(mesh), "-o", str(mesh)]) == 2
    assert main(["decompress", str(tmp_path / "m.hmz"), "--faces", str(mesh), "-o", str(tmp_path / "m.hmz")]) == 2
    assert main(["compress", str(mesh), "-k", "6", "-o", "/dev/null"]) == 2
    assert _digest(mesh) == before
    errors = capsys.readouterr().err.strip().splitlines()
    assert sum("same file as the input" in line for line in errors) == 3 and "not a regular file" in errors[-1]


def test_cli_checks_the_output_before_solving(tmp_path, capsys, monkeypatch):
    mesh = tmp_path / "m.off"
    hamsa.save_mesh(shapes.icosphere(1), mesh)
    monkeypatch.setattr(hamsa.eigen, "eigenbasis", lambda *a, **k: pytest.fail("solved before the output check"))
    assert main(["basis", str(mesh), "-k", "4", "-o", str(tmp_path / ("x" * 300 + ".npz"))]) == 2
    (tmp_path / "out.npz").mkdir()
    assert main(["basis", str(mesh), "-k", "4", "-o", str(tmp_path / "out.npz")]) == 2
    assert "existing folder" in capsys.readouterr().err


def test_cli_solver_failure_has_its_own_exit_code(tmp_path, capsys, monkeypatch):
    mesh = tmp_path / "m.off"
    hamsa.save_mesh(shapes.icosphere(1), mesh)

    def stalls(*args, **kwargs):
        raise ConvergenceError("eigensolver did not converge in 200 restarts")

    monkeypatch.setattr(hamsa.eigen, "eigenbasis", stalls)
    assert main(["basis", str(mesh), "-k", "4", "-o", str(tmp_path / "b.npz")]) == 3
    assert capsys.readouterr().err.strip() == "hamsa basis: solver failed: eigensolver did not converge in 200 restarts"


def test_cli_potential_files_are_checked_from_their_header(tmp_path, capsys):
    mesh = tmp_path / "m.off"
    hamsa.save_mesh(shapes.icosphere(1), mesh)
    for name, value in (
        ("short.npy", np.zeros(41)),
        ("complex.npy", np.zeros(42) * 1j),
        ("cube.npy", np.zeros((42, 2, 2))),
    ):
        np.save(tmp_path / name, value)
        assert (
            main(["basis", str(mesh), "-k", "4", "--potential", str(tmp_path / name), "-o", str(tmp_path / "b.npz")])
            == 2
        )
    errors = capsys.readouterr().err
    assert "expected 42 rows" in errors and "complex" in errors and "expected 1-D or 2-D" in errors
    assert not (tmp_path / "b.npz").exists()


def test_vertex_ids_travel_with_the_basis_and_are_validated(tmp_path, basis):
    ids = np.arange(basis.n)[::-1].copy()
    path = tmp_path / "b.npz"
    basis.with_vertex_ids(ids).truncate(3).save(path)
    back = hamsa.Eigenbasis.load(path)
    np.testing.assert_array_equal(back.vertex_ids, ids)
    assert back.k == 3 and hamsa.Eigenbasis.load(_saved(tmp_path, basis)).vertex_ids is None
    for bad in (ids[:-1], ids - 5, ids * 1.0):
        with pytest.raises(HamsaError, match="vertex_ids must be"):
            basis.with_vertex_ids(bad)
    _rewrite(path, vertex_ids=-np.ones(basis.n, dtype=np.int64))
    with pytest.raises(HamsaError, match="vertex_ids must be"):
        hamsa.Eigenbasis.load(path)


def _saved(folder, basis):
    path = folder / "plain.npz"
    basis.save(path)
    return path


def test_an_intrinsic_delaunay_basis_loads_back(tmp_path, sphere):
    pytest.importorskip("robust_laplacian")
    basis = hamsa.eigenbasis(sphere, 5, laplacian="intrinsic_delaunay")
    basis.save(tmp_path / "b.npz")
    back = hamsa.Eigenbasis.load(tmp_path / "b.npz")
    assert back.mass_kind == "intrinsic_delaunay"
    np.testing.assert_array_equal(back.values, basis.values)


def test_extra_arrays_come_back_from_one_read(tmp_path, basis):
    basis.save(tmp_path / "b.npz", extra={"cache_key": np.array("abc"), "labels": np.arange(3)})
    back, extra = hamsa.Eigenbasis.load_with_extra(tmp_path / "b.npz")
    assert sorted(extra) == ["cache_key", "labels"] and str(extra["cache_key"]) == "abc"
    np.testing.assert_array_equal(back.values, basis.values)


def test_an_output_folder_may_be_created_with_its_parents_but_not_through_a_file(tmp_path):
    from hamsa.files import check_output_folder

    deep = tmp_path / "results" / "scape" / "run1"
    assert check_output_folder(deep) == deep and not (tmp_path / "results").exists()  # checked, not created
    (tmp_path / "plain.txt").write_text("x")
    with pytest.raises(FileAccessError, match="'.*plain.txt' exists and is not a folder"):
        check_output_folder(tmp_path / "plain.txt" / "run1")
    with pytest.raises(FileAccessError, match="exists and is not a folder"):
        check_output_folder(tmp_path / "plain.txt")
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    if os.geteuid() != 0:  # root writes anywhere
        with pytest.raises(FileAccessError, match="not writable"):
            check_output_folder(locked / "a" / "b")


def test_reproduce_creates_a_nested_output_folder(tmp_path):
    pytest.importorskip("matplotlib", reason="the figures need the [viz] extra")
    from hamsa.cli import main

    assert main(["reproduce", "--quick", "--only", "fig1", "-o", str(tmp_path / "a" / "b" / "report")]) == 0
    assert (tmp_path / "a" / "b" / "report" / "index.html").is_file()
