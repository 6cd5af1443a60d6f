"""Safe file access: bounded reads, checked output paths and atomic writes.

Every file hamsa reads or writes goes through this module, so the same rules hold everywhere:

* **Reading** takes only regular files (never a device, a pipe or a socket, which may never end), and
  never more than :func:`read_limit` bytes, before or after gzip/LZMA decompression.
* **Arrays** (``.npy`` files and ``.npz`` members) are checked from their header — dtype, shape and
  the size it claims — before any data is allocated; object arrays (pickles) are never loaded.
* **Writing** goes to a temporary file in the destination folder, renamed onto the output only when
  complete; the output must be a new path or a regular file, must not be one of the command's inputs,
  and its folder must exist and be writable. :func:`check_output` checks all of that *before* a long
  computation, :func:`atomic_write` again at write time.

Every refusal is a :class:`~hamsa.errors.FileAccessError` naming the path and the problem.
"""

from __future__ import annotations

import errno
import gzip
import io
import lzma
import os
import stat
import tempfile
import zipfile
import zlib
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from numpy.lib import format as npy_format

from hamsa.errors import FileAccessError
from hamsa.resources import available_memory

DEFAULT_READ_LIMIT = 1 << 30  # bytes: 1 GiB (a mesh of ten million vertices), or less on a small machine
_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def read_limit() -> int:
    """The most bytes one read may produce (after decompression).

    ``HAMSA_READ_LIMIT`` sets it (bytes, or with a K/M/G/T suffix: ``HAMSA_READ_LIMIT=16G``); the default is
    1 GiB, or a quarter of the available memory when that is less (parsing a text mesh takes several times
    its size).
    """
    text = os.environ.get("HAMSA_READ_LIMIT", "").strip().upper().removesuffix("B")
    if text:
        unit = text[-1] if text[-1] in _UNITS else ""
        try:
            return int(float(text[: len(text) - len(unit)]) * _UNITS[unit])
        except ValueError:
            raise FileAccessError(f"HAMSA_READ_LIMIT={text!r} is not a size such as 8G or 500M") from None
    available = available_memory()
    return DEFAULT_READ_LIMIT if available is None else min(DEFAULT_READ_LIMIT, available // 4)


def _too_large(path, limit: int, stage: str = "") -> FileAccessError:
    return FileAccessError(
        f"'{path}' is larger than the read limit of {limit / 2**20:.0f} MiB{stage} (set HAMSA_READ_LIMIT to allow more)"
    )


_BINARY_MAGIC = {b"PK\x03\x04": "an .npz (zip) archive", b"\x93NUMPY": "an .npy array", b"\x1f\x8b": "gzip-compressed"}


def read_bytes(path: str | os.PathLike, *, limit: int | None = None, decompress: str | None = None) -> bytes:
    """The content of a regular file, at most ``limit`` bytes (default :func:`read_limit`).

    ``decompress="gzip"`` returns the decompressed content, also bounded by ``limit``. Raises
    FileAccessError if the path does not exist, is a folder or not a regular file (device, pipe, socket),
    cannot be read, is larger than the limit, or is not a valid gzip stream.
    """
    limit = read_limit() if limit is None else limit
    try:
        # O_NONBLOCK: opening a pipe must not wait for a writer; the mode check below refuses it anyway.
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError:
        raise FileAccessError(f"cannot read '{path}': no such file") from None
    except IsADirectoryError:
        raise FileAccessError(f"cannot read '{path}': it is a folder") from None
    except OSError as exc:
        raise FileAccessError(f"cannot read '{path}': {exc.strerror or exc}") from None
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode):
        os.close(fd)
        kind = "it is a folder" if stat.S_ISDIR(info.st_mode) else "not a regular file (a device, pipe or socket)"
        raise FileAccessError(f"cannot read '{path}': {kind}")
    with os.fdopen(fd, "rb") as handle:
        if info.st_size > limit:
            raise _too_large(path, limit)
        os.set_blocking(fd, True)
        try:
            data = handle.read(limit + 1)
        except OSError as exc:
            raise FileAccessError(f"cannot read '{path}': {exc.strerror or exc}") from None
    if len(data) > limit:
        raise _too_large(path, limit)
    if decompress == "gzip":
        try:
            data = bounded_decompress(data, "gzip", limit, path)
        except _Overflow:
            raise _too_large(path, limit, " once decompressed (gzip)") from None
    return data


def read_text(path: str | os.PathLike, *, limit: int | None = None) -> str:
    """The content of a UTF-8 text file (without the byte-order mark some editors write first), read like
    :func:`read_bytes`; a binary file (an array, an archive,
    anything with NUL bytes or invalid UTF-8) is refused with a FileAccessError that says what it looks like."""
    data = read_bytes(path, limit=limit)
    kind = next((name for magic, name in _BINARY_MAGIC.items() if data.startswith(magic)), None)
    try:
        text = None if kind or b"\0" in data else data.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = None
    if text is None:
        raise FileAccessError(f"'{path}' is {kind or 'a binary file'}, not text")
    return text


class _Overflow(FileAccessError):
    """Decompressed data went past its limit."""


def bounded_decompress(data: bytes, kind: str, limit: int, what="data") -> bytes:
    """Decompress ``gzip`` or ``lzma`` bytes, refusing output beyond ``limit`` bytes (FileAccessError)."""
    try:
        if kind == "gzip":
            with gzip.GzipFile(fileobj=io.BytesIO(data)) as stream:
                out = stream.read(limit + 1)
        else:
            decompressor = lzma.LZMADecompressor()
            out = decompressor.decompress(data, max_length=limit + 1)
            if not decompressor.eof and len(out) <= limit:
                raise FileAccessError(f"'{what}': the LZMA stream is truncated")
    except (OSError, EOFError, zlib.error, lzma.LZMAError) as exc:
        raise FileAccessError(f"'{what}' is not a valid {kind} stream: {exc}") from None
    if len(out) > limit:
        raise _Overflow(f"'{what}' decompresses to more than {limit} bytes")
    return out


# ------------------------------------------------------------------------------------- arrays
_NUMERIC_KINDS = "biuf"
_NO_CHECKS = {"ndim": None, "rows": None, "numeric": False}


def _check_header(shape, dtype, what, *, ndim, rows, numeric, limit) -> None:
    if dtype.hasobject:
        raise FileAccessError(f"{what} holds Python objects; hamsa never loads pickled data")
    if numeric and dtype.kind not in _NUMERIC_KINDS:
        kind = "complex" if dtype.kind == "c" else f"non-numeric ({dtype})"
        raise FileAccessError(f"{what} is {kind}; expected real numbers")
    if ndim is not None and len(shape) not in np.atleast_1d(ndim):
        raise FileAccessError(
            f"{what} has shape {shape}; expected {' or '.join(f'{d}-D' for d in np.atleast_1d(ndim))}"
        )
    if rows is not None and (not shape or shape[0] != rows):
        raise FileAccessError(f"{what} has shape {shape}; expected {rows} rows (one per vertex)")
    claimed = int(np.prod(shape, dtype=object)) * dtype.itemsize
    if claimed > limit:
        raise FileAccessError(f"{what} claims shape {shape} ({claimed / 2**20:.0f} MiB), beyond the read limit")


def _read_array(stream, size: int, what: str, limit: int, **expect) -> np.ndarray:
    """One ``.npy`` record from a binary stream of ``size`` bytes, checked from its header first."""
    try:
        version = npy_format.read_magic(stream)
        header = npy_format.read_array_header_1_0 if version == (1, 0) else npy_format.read_array_header_2_0
        shape, fortran, dtype = header(stream)
    except (ValueError, OSError, EOFError, SyntaxError) as exc:
        raise FileAccessError(f"{what} is not a valid .npy array: {exc}") from None
    _check_header(shape, dtype, what, limit=limit, **expect)
    claimed = int(np.prod(shape, dtype=object)) * dtype.itemsize
    if size - stream.tell() != claimed:
        raise FileAccessError(f"{what} has {size - stream.tell()} data bytes, its header claims {claimed}")
    try:
        data = stream.read(claimed)
    except (OSError, EOFError, zlib.error, zipfile.BadZipFile) as exc:
        raise FileAccessError(f"{what} cannot be read: {exc}") from None
    array = np.frombuffer(data, dtype=dtype, count=int(np.prod(shape)))
    return array.reshape(shape, order="F" if fortran else "C").copy()


def load_array(path, *, ndim=None, rows: int | None = None, numeric: bool = True, limit: int | None = None):
    """An array from an ``.npy`` file, checked from its header before its data is read.

    ``ndim`` (an int or a tuple of allowed ones) and ``rows`` (the first dimension, e.g. the mesh's vertex
    count) are refused from the header when they do not match; ``numeric`` refuses complex, string and
    other non-real dtypes. Raises FileAccessError naming the file and the mismatch.
    """
    limit = read_limit() if limit is None else limit
    data = read_bytes(path, limit=limit)
    if data[:4] == b"PK\x03\x04":
        raise FileAccessError(f"'{path}' is an .npz archive; give one array as an .npy file")
    return _read_array(io.BytesIO(data), len(data), f"'{path}'", limit, ndim=ndim, rows=rows, numeric=numeric)


def load_npz(path, expected: dict[str, dict] | None = None, *, limit: int | None = None) -> dict[str, np.ndarray]:
    """The arrays of an ``.npz`` archive, each member checked from its header before it is allocated.

    ``expected`` maps member names to the checks of :func:`load_array` (``ndim``, ``rows``, ``numeric``);
    members not named are checked for size and pickles only. The total may not exceed ``limit``.
    Raises FileAccessError for a missing or damaged archive or a member that fails its check.
    """
    limit = read_limit() if limit is None else limit
    expected = expected or {}
    try:
        archive = zipfile.ZipFile(io.BytesIO(read_bytes(path, limit=limit)))
    except zipfile.BadZipFile as exc:
        raise FileAccessError(f"'{path}' is not an .npz archive: {exc}") from None
    arrays, total = {}, 0
    with archive:
        for info in archive.infolist():
            name = info.filename.removesuffix(".npy")
            total += info.file_size
            if total > limit:
                raise _too_large(path, limit, " once decompressed")
            what = f"'{path}' member '{name}'"
            checks = expected.get(name, {})
            try:
                with archive.open(info) as stream:
                    arrays[name] = _read_array(stream, info.file_size, what, limit, **{**_NO_CHECKS, **checks})
            except (zipfile.BadZipFile, zlib.error, EOFError, OSError) as exc:
                raise FileAccessError(f"{what} cannot be read: {exc}") from None
    return arrays


# ------------------------------------------------------------------------------------- output
def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return a.resolve() == b.resolve()


def check_output(path: str | os.PathLike, *, suffix: str | None = None, inputs=()) -> Path:
    """Check that ``path`` can receive an output, before any work is done; return it as a Path.

    Refused (FileAccessError): a wrong ``suffix``; an existing folder, device, pipe or socket (or a symlink
    to one); the same file as one of ``inputs`` (compared by resolved path and inode); a folder that does
    not exist or is not writable; a name longer than the file system allows.
    """
    output = Path(path)
    if suffix and not output.name.endswith(suffix):
        raise FileAccessError(f"output '{output}' must end in {suffix}")
    parent = output.parent if str(output.parent) else Path(".")
    try:
        name_max = os.pathconf(parent if parent.is_dir() else ".", "PC_NAME_MAX")
    except (OSError, ValueError):
        name_max = 255
    if len(os.fsencode(output.name)) > name_max:
        raise FileAccessError(f"cannot write '{output}': the file name is longer than {name_max} bytes")
    for given in inputs:
        if given is not None and _same_file(output, Path(given)):
            raise FileAccessError(f"output '{output}' is the same file as the input '{given}'; choose another name")
    if os.path.lexists(output):
        if output.is_dir():
            raise FileAccessError(f"cannot write '{output}': it is an existing folder")
        if output.exists() and not output.is_file():
            raise FileAccessError(f"cannot write '{output}': it is not a regular file (a device, pipe or socket)")
    target = output.resolve() if output.is_symlink() else output
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise FileAccessError(f"cannot write '{output}': folder '{folder}' does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise FileAccessError(f"cannot write '{output}': folder '{folder}' is not writable")
    return output


def check_output_folder(path: str | os.PathLike) -> Path:
    """Check that ``path`` is an existing folder or can be created as one, missing parents included (as
    ``mkdir -p``): the nearest part of it that exists must be a writable folder. Returns it; nothing is
    created here."""
    folder = Path(path)
    if os.path.lexists(folder) and not folder.is_dir():
        raise FileAccessError(f"output '{folder}' exists and is not a folder")
    existing = folder
    while not existing.is_dir():
        if os.path.lexists(existing):
            raise FileAccessError(f"cannot create the folder '{folder}': '{existing}' exists and is not a folder")
        existing = existing.parent
    if not os.access(existing, os.W_OK | os.X_OK):
        raise FileAccessError(f"cannot write into '{folder}': '{existing}' is not writable")
    return folder


@contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "wb"):
    """Open a temporary file beside ``path``; rename it onto ``path`` only if the block succeeds.

    The output is checked first (:func:`check_output`); a symlink is followed, so its target is replaced.
    An ``OSError`` while writing (disk full, permission) becomes one FileAccessError naming the path.
    """
    output = check_output(path)
    target = output.resolve() if output.is_symlink() else output
    folder = target.parent if str(target.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=".hamsa-", suffix=".tmp", dir=folder)
    except OSError as exc:
        raise FileAccessError(f"cannot write '{output}': {exc.strerror or exc}") from None
    _PENDING.add(tmp)
    try:
        with os.fdopen(fd, mode) as handle:
            yield handle
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes it private; the output gets the usual permissions
        os.replace(tmp, target)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            reason = "the disk is full" if exc.errno == errno.ENOSPC else exc.strerror or str(exc)
            raise FileAccessError(f"cannot write '{output}': {reason}") from None
        raise
    finally:
        _PENDING.discard(tmp)


_PENDING: set[str] = set()  # temporary files of writes in progress


def remove_pending() -> None:
    """Delete the temporary files of unfinished writes (for a process that must exit at once)."""
    for tmp in list(_PENDING):
        try:
            os.unlink(tmp)
        except OSError:
            pass


_UMASK = os.umask(0)
os.umask(_UMASK)
