"""Reading and writing meshes (OFF, OBJ, PLY ASCII and binary, STL) and point clouds (XYZ / TXT / PTS / CSV,
PLY, NPY; PCD and the vertices of OFF / OBJ read only), optionally gzip-compressed.

The readers are our own, written for one promise: **vertex order is never changed** (ground-truth
correspondences in TOSCA/SCAPE are vertex indices). STL is the exception by nature: it stores
unindexed triangles, so identical coordinates are merged in the order they first appear. Faces with
more than three corners (OFF, OBJ, PLY) are cut into triangles by :func:`hamsa.mesh.triangulate_polygons`;
PLY triangle strips are read as their triangles, and PLY properties hamsa does not use (texture coordinates
of a face's corners, other elements) are skipped.
Files are read and written through :mod:`hamsa.files`: only regular files, never more than its read
limit (gzip included), and every writer goes through a temporary file and an atomic rename, so an
interrupted write never leaves a half-written mesh behind.
"""

from __future__ import annotations

import gzip
import os
import struct
import warnings
from pathlib import Path

import numpy as np

from hamsa.errors import FileAccessError, MeshError, RepairWarning
from hamsa.files import atomic_write, load_array, read_bytes
from hamsa.mesh import TriMesh, triangulate_polygons
from hamsa.pointcloud import DEFAULT_NEIGHBORS, PointCloud

FORMATS = ("off", "obj", "ply", "stl")
POINTS_ONLY = ("xyz", "pts", "txt", "csv", "pcd", "npy")  # formats that hold points and never faces
POINT_FORMATS = (*POINTS_ONLY, "off", "obj", "ply")
_NORMAL_NAMES = (("nx", "ny", "nz"), ("normal_x", "normal_y", "normal_z"))  # PLY properties, text columns, PCD fields


def _suffix(path: str | os.PathLike) -> tuple[str, bool]:
    """(format, gzipped) from a file name such as ``cat0.off.gz``: the last suffix before an optional ``.gz``."""
    suffixes = [s.lower() for s in Path(path).suffixes]
    gzipped = bool(suffixes) and suffixes[-1] == ".gz"
    fmt = suffixes[-2 if gzipped else -1].lstrip(".") if len(suffixes) > gzipped else ""
    return fmt, gzipped


def _naming(path, exc: MeshError) -> MeshError:
    """``exc`` with the file's name in front, unless its message names the file already."""
    return MeshError(exc.args[0] if str(path) in exc.args[0] else f"'{path}': {exc}")


def point_format(path: str | os.PathLike) -> tuple[str, bool] | None:
    """(format, gzipped) of a point file (``scan.xyz``, ``points.npy``, ``cloud.ply.gz``), None for other names."""
    fmt, gzipped = _suffix(path)
    if fmt not in POINT_FORMATS or (fmt == "npy" and gzipped):
        return None
    return fmt, gzipped


def load_shape(
    path: str | os.PathLike,
    *,
    manifold: bool = True,
    neighbors: int = DEFAULT_NEIGHBORS,
    separate_sheets: bool = True,
    off_sheet: float | None = None,
    file_normals: bool = True,
) -> TriMesh | PointCloud:
    """The file as a :class:`TriMesh`, or as a :class:`~hamsa.pointcloud.PointCloud` when it holds points without
    faces (``.xyz`` / ``.pts`` / ``.txt`` / ``.npy``, or an OFF / OBJ / PLY whose face count is zero).

    ``manifold`` as in :func:`load_mesh`, ``neighbors``, ``separate_sheets`` and ``off_sheet`` as in
    :class:`~hamsa.pointcloud.PointCloud` (a mesh ignores them); a cloud takes the normals the file holds
    (:func:`read_vertex_normals`) unless ``file_normals=False``, which estimates them. Raises
    MeshError naming the file if it cannot be read or does not make a valid mesh or cloud.
    """
    vertices, faces, normals = read_shape_arrays(path, normals=file_normals)
    try:
        if faces is None:
            return PointCloud(
                vertices, neighbors=neighbors, separate_sheets=separate_sheets, off_sheet=off_sheet, normals=normals
            )
        return TriMesh(vertices, faces, manifold=manifold)
    except MeshError as exc:
        raise _naming(path, exc) from None


def read_shape_arrays(
    path: str | os.PathLike, *, normals: bool = True
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """The raw ``(vertices, faces, normals)`` of a mesh file, or ``(points, None, normals)`` of a point file (a
    points-only format, or an OFF / OBJ / PLY / STL without faces), before any validation: what
    :func:`load_shape` builds its shape from, from one parse of the file.

    ``normals`` is the (n, 3) per-point normals a point file holds as :func:`read_vertex_normals` reads them, or
    None when it holds none, when ``normals=False``, or when the file has faces (a mesh's normals are not
    parsed here: :func:`read_vertex_normals` reads them). Raises MeshError naming the file if it cannot be read
    or parsed."""
    return _read_shape(path, "points" if normals else False)


def _read_shape(
    path: str | os.PathLike, normals: bool | str
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """:func:`read_shape_arrays` with ``normals`` as the format readers take it (:func:`_normals_wanted`)."""
    if _suffix(path)[0] in POINTS_ONLY:
        points, file_normals = _read_point_file(path, bool(normals))
        return points, None, file_normals
    vertices, faces, file_normals = _read_mesh_file(path, normals)
    return vertices, faces if len(faces) else None, file_normals


def _normals_wanted(normals: bool | str, has_faces: bool) -> bool:
    """Whether a format reader parses the normals a file holds: ``normals`` is True (always), False (never) or
    ``"points"`` (only in a file without faces)."""
    return normals is True or (normals == "points" and not has_faces)


def load_point_cloud(
    path: str | os.PathLike,
    neighbors: int = DEFAULT_NEIGHBORS,
    *,
    separate_sheets: bool = True,
    off_sheet: float | None = None,
    repair: bool = False,
    file_normals: bool = True,
) -> PointCloud:
    """Read a point cloud: ``.xyz`` / ``.pts`` / ``.txt`` / ``.csv`` (one point per line, separated by spaces,
    commas or semicolons: x y z first, or the columns a first line names, such as ``x,y,z,nx,ny,nz`` or
    CloudCompare's ``//X Y Z``; a PTS file's point-count lines are checked and skipped; further columns are
    ignored but normals, below), PCL's ``.pcd`` (ascii, binary, binary_compressed), ``.npy`` ((n, 3) or
    wider), or the vertices of an ``.off`` / ``.obj`` / ``.ply`` (faces, if any, are ignored); ``.gz`` except
    for ``.npy``.

    Points keep their file order; ``neighbors``, ``separate_sheets`` and ``off_sheet`` as in
    :class:`~hamsa.pointcloud.PointCloud`. The normals the file holds (:func:`read_vertex_normals`) are the
    cloud's unless ``file_normals=False``, which estimates them. ``repair=True`` drops non-finite, repeated
    and stray points (:func:`hamsa.repair.repair_point_cloud`; use it directly for the index map) with a
    :class:`~hamsa.errors.RepairWarning` saying what it dropped. Raises MeshError naming the file if it cannot
    be read or parsed, or if the points do not make a valid :class:`~hamsa.pointcloud.PointCloud` (too few,
    NaN, repeated).
    """
    points, normals = _read_point_file(path, file_normals)
    options = {"neighbors": neighbors, "separate_sheets": separate_sheets, "off_sheet": off_sheet}
    options["normals"] = normals
    try:
        if not repair:
            return PointCloud(points, **options)
        from hamsa.repair import repair_point_cloud

        cloud, _, report = repair_point_cloud(points, **options)
    except MeshError as exc:
        raise _naming(path, exc) from None
    if report.changed:
        warnings.warn(f"'{path}': {report}", RepairWarning, stacklevel=2)
    return cloud


def read_point_array(path: str | os.PathLike) -> np.ndarray:
    """The raw (n, 3) float64 points of a point file, as :func:`load_point_cloud` reads them, before any
    validation (for inspecting or repairing a cloud it refuses). Raises MeshError naming the file if it cannot
    be read or parsed."""
    return _read_point_file(path, normals=False)[0]


def _read_point_file(path: str | os.PathLike, normals: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """(points, the normals the file holds or None) of a point file, from one parse; normals only when asked."""
    fmt = point_format(path)
    if fmt is None:
        raise MeshError(
            f"cannot tell the point-cloud format of '{path}': use .xyz .pts .txt .csv .pcd .npy .off .obj .ply "
            "(optionally .gz)"
        )
    kind, gzipped = fmt
    if kind in ("off", "obj", "ply"):
        return _read_mesh_file(path, normals)[::2]
    try:
        if kind == "npy":
            points = load_array(path, ndim=2)
            if points.shape[1] < 3:
                raise MeshError(f"the array has shape {points.shape}, expected (n, 3) points")
            return np.asarray(points[:, :3], dtype=np.float64), None
        data = read_bytes(path, decompress="gzip" if gzipped else None)
        if kind == "pcd":
            return _read_pcd(data, normals)
        return _point_table(data.decode("utf-8-sig"), normals, counted=kind == "pts")
    except FileAccessError as exc:
        raise MeshError(str(exc)) from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise MeshError(f"'{path}' is not a valid {kind.upper()} point file: {exc}") from None


def _point_table(text: str, normals: bool, counted: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """(points, normals or None) of a text point file: one point per line, numbers separated by spaces, commas
    or semicolons. A first line that is not numbers names the columns (``x y z nx ny nz``, ``//X,Y,Z``, any
    case): x y z and the normals are read from the columns so named; otherwise x y z are the first three
    columns and the normals columns 4-6 when they are unit vectors (:func:`_unit_rows`). ``counted`` (PTS):
    a line holding one integer gives the number of points of the block that follows."""
    lines = _data_lines(text)
    # ';' separates where commas are decimal marks ("1,5;2,25;0,75"): then commas are left to fail as numbers
    separator = ";" if lines and ";" in lines[0] else ","
    lines = [line.replace(separator, " ") for line in lines]
    names = None
    if lines and not _numbers(lines[0].split()):
        names = [name.lower() for name in lines.pop(0).lstrip("/").split()]
    if counted:
        lines = _counted_blocks(lines)
    if not lines:
        raise MeshError("no points in the file")
    if names is None or not {"x", "y", "z"} <= set(names):
        table = _fixed_width(lines, 3, "point", spare=3 if normals else 0)
        return table[:, :3], _unit_rows(table[:, 3:])
    given = next((c for c in _NORMAL_NAMES if set(c) <= set(names)), None) if normals else None
    columns = [names.index(c) for c in ("x", "y", "z", *(given or ()))]
    table = _fixed_width(lines, max(columns) + 1, "point")[:, columns]
    return table[:, :3], table[:, 3:] if given else None


def _numbers(tokens: list[str]) -> bool:
    try:
        [float(token) for token in tokens]
    except ValueError:
        return False
    return True


def _counted_blocks(lines: list[str]) -> list[str]:
    """The point lines of a PTS file: each block starts with a line holding its point count, checked here."""
    points, at = [], 0
    while at < len(lines):
        count = lines[at].split()
        if len(count) != 1:
            if at == 0:
                return lines  # a file without count lines
            raise MeshError(f"data line {at + 1} should give the next block's point count, it has {len(count)} values")
        if not count[0].isdigit():
            raise MeshError(f"data line {at + 1} should be a point count, got '{count[0]}'")
        block = lines[at + 1 : at + 1 + int(count[0])]
        if len(block) < int(count[0]) or any(len(line.split()) == 1 for line in block):
            raise MeshError(f"the PTS block at data line {at + 1} promises {count[0]} points and has fewer")
        points += block
        at += 1 + int(count[0])
    return points


_PCD_TYPES = {("F", 4): "f4", ("F", 8): "f8", ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4", ("I", 8): "i8",
              ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8"}  # fmt: skip


def _read_pcd(data: bytes, normals: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """(points, normals or None) of a PCL point cloud file (``.pcd`` v0.7: ``DATA ascii``, ``binary`` or
    ``binary_compressed``): x y z, and ``normal_x normal_y normal_z`` when asked and present. An organized
    cloud's invalid points are NaN, as PCL writes them."""
    header, at = {}, 0
    while "DATA" not in header:
        end = data.find(b"\n", at)
        if end < 0:
            raise MeshError("no 'DATA' line in the PCD header")
        words = data[at:end].decode("ascii").split()
        at = end + 1
        if words and not words[0].startswith("#"):
            header[words[0].upper()] = words[1:]
    fields = header.get("FIELDS", [])
    missing = [c for c in "xyz" if c not in fields]
    if missing:
        raise MeshError(f"the PCD fields {fields} lack {missing}")
    count = int(header.get("POINTS", [0])[0])
    sizes = [int(x) for x in header.get("SIZE", [])]
    kinds = header.get("TYPE", [])
    counts = [int(x) for x in header.get("COUNT", ["1"] * len(fields))]
    if not len(sizes) == len(kinds) == len(counts) == len(fields):
        raise MeshError("the PCD header's FIELDS, SIZE, TYPE and COUNT differ in length")
    if any((k, z) not in _PCD_TYPES for k, z in zip(kinds, sizes)):
        raise MeshError(f"unknown PCD types {list(zip(kinds, sizes))}")
    record = np.dtype([(f, "<" + _PCD_TYPES[k, z], (c,)) for f, k, z, c in zip(fields, kinds, sizes, counts)])
    storage = header["DATA"][0] if header["DATA"] else ""
    if storage == "ascii":
        table = _fixed_width(_data_lines(data[at:].decode("ascii")), sum(counts), "point")
        columns = dict(zip(fields, np.split(table, np.cumsum(counts)[:-1], axis=1)))
    elif storage == "binary":
        if len(data) - at < record.itemsize * count:
            raise MeshError("the PCD file is shorter than its POINTS promise")
        table = np.frombuffer(data, dtype=record, count=count, offset=at)
        columns = {f: table[f] for f in fields}
    elif storage == "binary_compressed":
        if len(data) - at < 8:
            raise MeshError("the PCD file is shorter than its POINTS promise")
        packed, size = struct.unpack_from("<II", data, at)
        body = _lzf_decompress(data[at + 8 : at + 8 + packed], size)
        if len(body) < record.itemsize * count:
            raise MeshError("the PCD file is shorter than its POINTS promise")
        columns, offset = {}, 0  # field after field, each for all points
        for f, k, z, c in zip(fields, kinds, sizes, counts):
            columns[f] = np.frombuffer(body, "<" + _PCD_TYPES[k, z], count * c, offset).reshape(count, c)
            offset += count * c * z
    else:
        raise MeshError(f"unknown PCD storage 'DATA {storage}' (ascii, binary, binary_compressed)")
    points = np.hstack([columns[c][:, :1] for c in "xyz"]).astype(np.float64)
    given = next((c for c in _NORMAL_NAMES if all(name in columns for name in c)), None) if normals else None
    if given is None:
        return points, None
    return points, np.hstack([columns[c][:, :1] for c in given]).astype(np.float64)


def _lzf_decompress(packed: bytes, size: int) -> bytes:
    """LZF (liblzf, as PCL's binary_compressed uses it) expanded to ``size`` bytes: a control byte below 32
    copies that many + 1 literal bytes; otherwise its top 3 bits (7: one more length byte) + 2 bytes are
    copied from ``((control & 31) << 8) + next byte + 1`` bytes back."""
    out, at = bytearray(), 0
    while at < len(packed):
        control = packed[at]
        at += 1
        if control < 32:
            out += packed[at : at + control + 1]
            at += control + 1
            continue
        length = control >> 5
        if length == 7:
            length += packed[at]
            at += 1
        start = len(out) - ((control & 31) << 8) - packed[at] - 1
        at += 1
        if start < 0:
            raise MeshError("the PCD's compressed data refers back before its start")
        if start + length + 2 <= len(out):
            out += out[start : start + length + 2]
        else:  # the copy overlaps what it writes (a repeated pattern): byte by byte
            for i in range(length + 2):
                out.append(out[start + i])
    if len(out) != size:
        raise MeshError(f"the PCD's compressed data expands to {len(out)} bytes, its header says {size}")
    return bytes(out)


def _unit_rows(columns: np.ndarray) -> np.ndarray | None:
    """Columns 4-6 of a point file as normals when they are unit vectors on every line but those where they are
    zero or not finite (a point without a normal: ``x y z nx ny nz``), else None (``x y z r g b``, or no such
    columns)."""
    if columns.shape[1] < 3:
        return None
    length = np.linalg.norm(columns, axis=1)
    given = np.isfinite(length) & (length > 0)
    return columns if given.any() and np.all(np.abs(length[given] - 1) < 1e-3) else None


def mesh_format(path: str | os.PathLike) -> tuple[str, bool]:
    """Return (format, gzipped) from a file name such as ``cat0.off.gz``."""
    fmt, gzipped = _suffix(path)
    if fmt not in FORMATS:
        raise MeshError(f"cannot tell the mesh format of '{path}': use one of .off .obj .ply .stl (optionally .gz)")
    return fmt, gzipped


def load_mesh(path: str | os.PathLike, repair: bool = False, *, manifold: bool = True) -> TriMesh:
    """Read a triangle mesh from an OFF, OBJ, PLY or STL file (``*.gz`` is decompressed on the fly).

    Parameters
    ----------
    path : str or path-like
        The file; its suffix selects the format.
    repair : bool
        Apply the well-defined repairs of :mod:`hamsa.repair` (duplicate and degenerate faces,
        non-manifold vertices, orientation, unreferenced vertices) instead of refusing such a mesh;
        a :class:`~hamsa.errors.RepairWarning` says what changed. Use
        :func:`hamsa.repair.repair_mesh` directly to get the index map.
    manifold : bool
        False accepts edges shared by more than two faces, for ``laplacian="tufted"`` (see :class:`TriMesh`);
        not with ``repair``.

    Returns
    -------
    TriMesh
        Vertices in file order (STL: in order of first appearance), validated.

    Raises
    ------
    MeshError
        If the file is missing or unreadable, is not a valid file of its format, has non-triangle
        faces, or describes an invalid mesh (see :class:`TriMesh`). The message names the file.
    """
    try:
        vertices, faces = read_mesh_arrays(path)
        if len(faces) == 0:
            raise MeshError(f"it has {len(vertices)} vertices and no faces: read a point cloud with load_point_cloud")
        if not repair:
            return TriMesh(vertices, faces, manifold=manifold)
        from hamsa.repair import repair_mesh

        mesh, _, report = repair_mesh(vertices, faces)
    except MeshError as exc:
        raise _naming(path, exc) from None
    if report.changed:
        warnings.warn(f"'{path}': {report}", RepairWarning, stacklevel=2)
    return mesh


_PLY_COLOURS = (("red", "green", "blue"), ("r", "g", "b"), ("diffuse_red", "diffuse_green", "diffuse_blue"))


def read_vertex_normals(path: str | os.PathLike) -> np.ndarray | None:
    """The per-vertex normals a mesh or point file holds, (n, 3) float64 as written, one row per vertex in file
    order, or None when it holds none (for :class:`~hamsa.pointcloud.PointCloud`'s ``normals=``).

    Read from a PLY vertex element's ``nx ny nz`` (or ``normal_x normal_y normal_z``) properties, an ``NOFF`` /
    ``CNOFF`` file's vertex lines, OBJ ``vn`` lines when there are as many as ``v`` lines (fewer or more are
    per-corner normals that the faces index: None), a PCD file's ``normal_x normal_y normal_z`` fields, the
    columns a text point file's first line names so, or the fourth to sixth columns of an ``.xyz`` / ``.pts``
    / ``.txt`` file when they are unit vectors on every line (``x y z nx ny nz``; other columns, such as
    ``x y z r g b``, are not normals). Rows of zeros or NaN (points without a normal) are returned as they
    are, for the cloud to estimate there. ``.npy`` and STL files hold none. ``.gz`` too. Raises MeshError naming
    the file if it cannot be read or parsed; :func:`read_shape_arrays` gives the vertices and faces of the
    same parse.
    """
    return _read_shape(path, True)[2]


def read_vertex_colors(path: str | os.PathLike) -> np.ndarray:
    """The per-vertex colours of a mesh or point file, (n, 3) float64 RGB in [0, 1], one row per vertex in file
    order (for :func:`hamsa.potentials.from_vertex_colors`, the texture potential).

    Read from a PLY vertex element's ``red green blue`` (or ``r g b``, ``diffuse_red ...``) properties, an OFF
    file's ``COFF`` / ``CNOFF`` vertex lines, or OBJ ``v x y z r g b`` lines; ``.gz`` too. Integer colours are
    divided by their type's largest value (255 for ``uchar``; an OFF or OBJ file's by 255 when any exceeds 1).
    Raises MeshError naming the file if it cannot be read or has no vertex colours.
    """
    fmt, gzipped = _suffix(path)
    if fmt not in ("ply", "off", "obj"):
        raise MeshError(f"'{path}': vertex colours are read from .ply, .off (COFF) or .obj files (optionally .gz)")
    try:
        data = read_bytes(path, decompress="gzip" if gzipped else None)
        colours = {"ply": _ply_colours, "off": _off_colours, "obj": _obj_colours}[fmt](data)
    except FileAccessError as exc:
        raise MeshError(str(exc)) from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise _naming(path, MeshError(str(exc))) from None
    if not np.all(np.isfinite(colours)) or colours.min() < 0 or colours.max() > 1:
        raise MeshError(f"'{path}': vertex colours outside [0, 1] (or [0, 255] as integers)")
    return colours


def _ply_colours(data: bytes) -> np.ndarray:
    table, _ = _read_ply_tables(data)
    names = next((names for names in _PLY_COLOURS if all(name in table for name in names)), None)
    if names is None:
        raise MeshError("the PLY vertex element has no red, green and blue properties")
    columns = [table[name] for name in names]
    scale = [np.iinfo(c.dtype).max if np.issubdtype(c.dtype, np.integer) else 1.0 for c in columns]
    return np.stack([c.astype(np.float64) / k for c, k in zip(columns, scale)], axis=1)


def _off_colours(data: bytes) -> np.ndarray:
    variant, vertex_lines, _ = _off_parts(data)
    if not variant.startswith("C"):
        raise MeshError(f"an {variant} file has no vertex colours (COFF and CNOFF have)")
    first = 6 if variant == "CNOFF" else 3  # x y z [nx ny nz] r g b [a]
    return _byte_or_unit(_fixed_width(vertex_lines, first + 3, "vertex")[:, first:])


def _obj_colours(data: bytes) -> np.ndarray:
    vertex_lines, _, _ = _obj_lines(data)
    if min(len(line.split()) for line in vertex_lines) < 6:
        raise MeshError("the OBJ vertex lines have no colours ('v x y z r g b')")
    return _byte_or_unit(_fixed_width(vertex_lines, 6, "vertex")[:, 3:])


def _byte_or_unit(colours: np.ndarray) -> np.ndarray:
    """Text colours as [0, 1]: divided by 255 when any exceeds 1 (0-255 integers), else as written."""
    return colours / 255.0 if colours.max(initial=0.0) > 1 else colours


def read_mesh_arrays(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """The raw ``(vertices (n, 3) float64, faces (m, 3) int64)`` of a mesh file, before any validation.

    For inspecting or repairing a mesh that :func:`load_mesh` refuses. Raises MeshError if the file
    cannot be read or parsed as its format.
    """
    return _read_mesh_file(path, normals=False)[:2]


def _read_mesh_file(path: str | os.PathLike, normals: bool | str) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(vertices, faces, the per-vertex normals the file holds or None) of an OFF / OBJ / PLY / STL file, from
    one parse; normals only when asked (:func:`_normals_wanted`)."""
    fmt, gzipped = mesh_format(path)
    try:
        data = read_bytes(path, decompress="gzip" if gzipped else None)
    except FileAccessError as exc:
        raise MeshError(str(exc)) from None
    if not data.strip():
        raise MeshError(f"cannot read '{path}': the file is empty")
    try:
        if fmt == "stl":  # facet normals only
            return (*_read_stl(data), None)
        return {"off": _read_off, "obj": _read_obj, "ply": _read_ply}[fmt](data, normals)
    except MeshError as exc:
        raise MeshError(f"'{path}': {exc}") from None
    except (ValueError, IndexError, struct.error, UnicodeDecodeError) as exc:
        raise MeshError(f"'{path}' is not a valid {fmt.upper()} file: {exc}") from None


def save_mesh(mesh: TriMesh, path: str | os.PathLike) -> None:
    """Write ``mesh`` to ``path`` (format from the suffix, ``*.gz`` compressed), atomically.

    OFF and OBJ are ASCII with 17 significant digits (an exact float64 round trip); PLY and STL
    are binary little-endian (PLY stores float64 coordinates; STL is float32 by its definition).
    """
    fmt, gzipped = mesh_format(path)
    writer = {"off": _write_off, "obj": _write_obj, "ply": _write_ply, "stl": _write_stl}[fmt]
    data = writer(mesh)
    if gzipped:
        data = gzip.compress(data, mtime=0)
    with atomic_write(path) as handle:
        handle.write(data)


def save_point_cloud(cloud, path: str | os.PathLike) -> None:
    """Write a point cloud (a :class:`~hamsa.pointcloud.PointCloud` or an (n, 3) array) to ``path``, atomically:
    ``.xyz`` / ``.txt`` / ``.pts`` / ``.csv`` (one point per line, 17 significant digits: an exact float64
    round trip; ``.csv`` with an ``x,y,z`` header), ``.ply`` (binary little-endian, float64) or ``.npy``;
    ``.gz`` too but for ``.npy``. A cloud that was given normals keeps them (columns 4-6, ``nx ny nz``; not in
    ``.npy``), so reading the file back gives the same cloud; estimated normals are not written."""
    fmt = point_format(path)
    if fmt is None or fmt[0] in ("off", "obj"):
        raise MeshError(f"cannot tell the point-file format of '{path}': use .xyz .txt .pts .csv .ply .npy")
    kind, gzipped = fmt
    points = cloud.points if isinstance(cloud, PointCloud) else np.asarray(cloud, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise MeshError(f"points have shape {points.shape}, expected (n, 3)")
    given = isinstance(cloud, PointCloud) and cloud.normals_origin != "estimated"
    table = np.hstack([points, cloud.normals]) if given and kind != "npy" else points
    names = ("x", "y", "z", "nx", "ny", "nz")[: table.shape[1]]
    if kind == "npy":
        with atomic_write(path) as handle:
            np.save(handle, table)
        return
    if kind == "ply":
        properties = "".join(f"property double {c}\n" for c in names)
        header = f"ply\nformat binary_little_endian 1.0\nelement vertex {len(table)}\n{properties}end_header\n"
        data = header.encode() + table.astype("<f8").tobytes()
    else:
        separator = "," if kind == "csv" else " "
        head = separator.join(names) + "\n" if kind == "csv" else ""
        data = (head + _format_rows(table, separator.join(["%.17g"] * table.shape[1])) + "\n").encode()
    with atomic_write(path) as handle:
        handle.write(gzip.compress(data, mtime=0) if gzipped else data)


# ------------------------------------------------------------------------------------ text
def _data_lines(text: str) -> list[str]:
    lines = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            lines.append(line)
    return lines


def _fixed_width(lines: list[str], width: int, what: str, spare: int = 0) -> np.ndarray:
    """Parse ``lines`` of whitespace-separated numbers, keeping the first ``width`` columns, and the ``spare``
    columns after them too when every line has them."""
    tokens = [line.split() for line in lines]
    lengths = {len(t) for t in tokens}
    if min(lengths) < width:
        bad = next(i for i, t in enumerate(tokens) if len(t) < width)
        raise MeshError(f"{what} {bad} has {len(tokens[bad])} values, expected {width}")
    if min(lengths) >= width + spare:
        width += spare
    if len(lengths) == 1:
        arr = np.array(" ".join(lines).split(), dtype=np.float64).reshape(len(lines), -1)
        return arr[:, :width]
    return np.array([t[:width] for t in tokens], dtype=np.float64)


def _integer_faces(rows: np.ndarray, what: str) -> np.ndarray:
    if rows.size and not np.all(rows == np.round(rows)):
        raise MeshError(f"{what} indices must be integers")
    too_large = np.flatnonzero(np.abs(rows).max(axis=1) >= 2**53) if rows.size else []
    if len(too_large):
        raise MeshError(f"{what} {too_large[0]} has an index out of range ({rows[too_large[0]].max():.4g})")
    return rows.astype(np.int64)


def _read_off(data: bytes, normals: bool | str) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    variant, vertex_lines, face_lines = _off_parts(data)
    with_normals = _normals_wanted(normals, bool(face_lines)) and variant.endswith("NOFF")  # x y z nx ny nz ...
    table = _fixed_width(vertex_lines, 6 if with_normals else 3, "vertex")
    vertices = table[:, :3]
    counts, corners = _off_polygons(face_lines)
    return vertices, triangulate_polygons(vertices, corners, counts), table[:, 3:] if with_normals else None


def _off_parts(data: bytes) -> tuple[str, list[str], list[str]]:
    """(variant: OFF / COFF / NOFF / CNOFF, vertex lines, face lines) of an OFF file."""
    lines = _data_lines(data.decode("utf-8-sig"))
    if not lines:
        raise MeshError("no OFF header")
    header = lines[0].split()
    if not header[0].endswith("OFF"):
        raise MeshError(f"first line is '{lines[0][:40]}', expected 'OFF'")
    if header[0] != "OFF" and header[0] not in ("COFF", "NOFF", "CNOFF"):
        raise MeshError(f"unsupported OFF variant '{header[0]}'")
    rest = header[1:]
    body = lines[1:]
    if not rest:
        if not body:
            raise MeshError("OFF header has no vertex/face counts")
        rest, body = body[0].split(), body[1:]
    try:
        n, m = int(rest[0]), int(rest[1])
    except (IndexError, ValueError):
        raise MeshError("OFF counts line must start with '<vertices> <faces>'") from None
    if n < 0 or m < 0:
        raise MeshError(f"OFF header has negative counts ({n}, {m})")
    if len(body) < n + m:
        raise MeshError(f"OFF header promises {n} vertices and {m} faces, the file has only {len(body)} data lines")
    return header[0], body[:n], body[n : n + m]


def _off_polygons(face_lines: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(the corner count (m,), the corners concatenated) of OFF-style face lines ``c i1 .. ic [colour]``."""
    tokens = [line.split() for line in face_lines]
    counts = np.array([int(t[0]) for t in tokens], dtype=np.int64)
    short = [i for i, t in enumerate(tokens) if len(t) < 1 + max(int(t[0]), 0)]
    if short:
        raise MeshError(f"face {short[0]} lists fewer than its {counts[short[0]]} vertex indices")
    if np.all(counts == 3):
        rows = np.array([t[1:4] for t in tokens], dtype=np.float64).reshape(-1, 3)
    else:
        rows = np.array([x for t in tokens for x in t[1 : 1 + int(t[0])]], dtype=np.float64).reshape(-1, 1)
    return counts, _integer_faces(rows, "face").ravel()


def _read_obj(data: bytes, normals: bool | str) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    vertex_lines, face_lines, normal_lines = _obj_lines(data)
    vertices = _fixed_width(vertex_lines, 3, "vertex")
    n = len(vertices)
    flat = [int(token.split("/", 1)[0]) for _, f in face_lines for token in f]
    if flat and max(abs(min(flat)), abs(max(flat))) >= 2**53:
        raise MeshError(f"face index {max(flat, key=abs)} is out of range")
    corners = np.asarray(flat, dtype=np.int64)
    if np.any(corners == 0):
        raise MeshError("OBJ face index 0 is invalid (indices are 1-based)")
    counts = [len(f) for _, f in face_lines]
    # 1-based; a negative index counts back from the vertices defined before its face line
    defined = np.repeat([before for before, _ in face_lines], counts).astype(np.int64)
    corners = np.where(corners > 0, corners - 1, corners + defined)
    if np.any(corners < 0):
        raise MeshError(
            f"face {np.repeat(np.arange(len(counts)), counts)[np.argmax(corners < 0)]} has a negative "
            "index reaching back before the first vertex"
        )
    faces = triangulate_polygons(vertices, corners, counts)
    # as many 'vn' as 'v' lines: one normal per vertex; otherwise per-corner normals that the faces index
    per_vertex = _normals_wanted(normals, bool(face_lines)) and len(normal_lines) == n
    return vertices, faces, _fixed_width(normal_lines, 3, "normal") if per_vertex else None


def _obj_lines(data: bytes) -> tuple[list[str], list[tuple[int, list[str]]], list[str]]:
    """(the text after 'v ' of each vertex line, (the number of vertex lines before it, the tokens after 'f ') of
    each face line, the text after 'vn ' of each normal line) of an OBJ file."""
    vertex_lines, face_lines, normal_lines = [], [], []
    for raw in data.decode("utf-8-sig").splitlines():
        keyword, *rest = raw.split("#", 1)[0].split(None, 1) or [""]  # 'v 1 2 3' or 'v\t1\t2\t3'
        if keyword == "v":
            vertex_lines.append(rest[0] if rest else "")
        elif keyword == "f":
            face_lines.append((len(vertex_lines), rest[0].split() if rest else []))
        elif keyword == "vn":
            normal_lines.append(rest[0] if rest else "")
    if not vertex_lines:
        raise MeshError("no vertices ('v x y z' lines)")
    return vertex_lines, face_lines, normal_lines


# ------------------------------------------------------------------------------------- PLY
_PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}


def _read_ply(data: bytes, normals: bool | str) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    table, faces = _read_ply_tables(data)
    _require_properties(table, "xyz")
    vertices = np.stack([table[c].astype(np.float64) for c in "xyz"], axis=1)
    normals = _normals_wanted(normals, faces is not None)
    if faces is None:  # a point cloud
        faces = np.zeros((0, 3), dtype=np.int64)
    names = next((names for names in _NORMAL_NAMES if all(name in table for name in names)), None)
    if not normals or names is None:
        return vertices, faces, None
    return vertices, faces, np.stack([table[name].astype(np.float64) for name in names], axis=1)


def _read_ply_tables(data: bytes) -> tuple[dict[str, np.ndarray], np.ndarray | None]:
    """({property name: (n,) column} of the vertex element, (m, 3) faces or None) of a PLY file."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise MeshError("missing 'ply' magic or 'end_header'")
    header = data[:end].decode("ascii").splitlines()
    body_start = data.index(b"\n", end) + 1
    fmt = None
    elements: list[dict] = []
    for line in header[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format":
            fmt = words[1]
        elif words[0] == "element":
            elements.append({"name": words[1], "count": int(words[2]), "props": []})
        elif words[0] == "property":
            if not elements:
                raise MeshError("'property' before any 'element'")
            if words[1] == "list":
                elements[-1]["props"].append((words[4], "list", _ply_type(words[2]), _ply_type(words[3])))
            else:
                elements[-1]["props"].append((words[2], _ply_type(words[1]), None, None))
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise MeshError(f"unknown PLY format '{fmt}'")
    if "vertex" not in [e["name"] for e in elements]:
        raise MeshError("PLY needs a 'vertex' element")
    if fmt == "ascii":
        table, polygons = _read_ply_ascii(data[body_start:].decode("ascii"), elements)
    else:
        table, polygons = _read_ply_binary(data[body_start:], elements, "<" if fmt == "binary_little_endian" else ">")
    if polygons is None:
        return table, None
    _require_properties(table, "xyz")
    points = np.stack([table[c].astype(np.float64) for c in "xyz"], axis=1)
    return table, triangulate_polygons(points, polygons[1], polygons[0])


def _ply_type(name: str) -> str:
    if name not in _PLY_TYPES:
        raise MeshError(f"unknown PLY property type '{name}'")
    return _PLY_TYPES[name]


def _require_properties(table: dict, names) -> None:
    missing = [c for c in names if c not in table]
    if missing:
        raise MeshError(f"PLY vertex element lacks properties {missing}")


_PLY_FACES = ("face", "tristrips")  # the elements that make triangles (a polygon per row / strips)


def _face_list_index(element: dict) -> int:
    for i, p in enumerate(element["props"]):
        if p[1] == "list" and p[0] in ("vertex_indices", "vertex_index"):
            return i
    raise MeshError(f"PLY {element['name']} element lacks a 'vertex_indices' list")


def _ply_polygons(element: dict, lists: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The polygons of a face or tristrips element, as :func:`_off_polygons` gives them, from its vertex index
    lists ``(lengths (m,), indices concatenated)``."""
    counts, corners = lists[0].astype(np.int64), _integer_faces(lists[1].reshape(-1, 1), "face").ravel()
    return (counts, corners) if element["name"] == "face" else _strip_triangles(counts, corners)


def _strip_triangles(counts: np.ndarray, corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(3s, corners) of the triangles of PLY triangle strips: each list holds strips separated by -1, and strip
    a b c d e ... gives (a b c), (c b d), (c d e), ...: every other triangle with its first two corners swapped,
    so all face one way. Triangles with a repeated corner (where a strip turns) are left out."""
    triangles = [np.zeros((0, 3), dtype=np.int64)]
    for strips in np.split(corners, np.cumsum(counts)[:-1]):
        for strip in np.split(strips, np.flatnonzero(strips < 0)):
            strip = strip[strip >= 0]
            run = np.stack([strip[:-2], strip[1:-1], strip[2:]], axis=1)
            run[1::2, :2] = run[1::2, 1::-1]
            triangles.append(run)
    run = np.concatenate(triangles)
    run = run[(run[:, 0] != run[:, 1]) & (run[:, 1] != run[:, 2]) & (run[:, 0] != run[:, 2])]
    return np.full(len(run), 3, dtype=np.int64), run.ravel()


def _joined(polygons: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray] | None:
    """The polygons of several face / tristrips elements as one ``(counts, corners)``; None when there are none."""
    if not polygons:
        return None
    return np.concatenate([p[0] for p in polygons]), np.concatenate([p[1] for p in polygons])


def _read_ply_ascii(text: str, elements: list[dict]) -> tuple[dict[str, np.ndarray], tuple | None]:
    """({property name: column} of the vertex element, the faces as :func:`_off_polygons` gives them, None when
    there is no face or tristrips element)."""
    lines = [line for line in text.splitlines() if line.strip()]
    pos = 0
    vertices, polygons = None, []
    for element in elements:
        rows = lines[pos : pos + element["count"]]
        if len(rows) < element["count"]:
            raise MeshError(f"PLY promises {element['count']} '{element['name']}' rows, found {len(rows)}")
        pos += element["count"]
        if element["name"] == "vertex":
            if any(p[1] == "list" for p in element["props"]):
                raise MeshError("PLY vertex element with list properties is not supported")
            table = _fixed_width(rows, len(element["props"]), "vertex")
            # integer properties (colours) keep their declared type; coordinates keep every digit of the text
            vertices = {
                p[0]: table[:, i] if p[1].startswith("f") else table[:, i].astype(p[1])
                for i, p in enumerate(element["props"])
            }
        elif element["name"] in _PLY_FACES:
            counts, corners = _off_polygons(_from_index_list(rows, element))
            polygons.append(_ply_polygons(element, (counts, corners)))
    return vertices, _joined(polygons)


def _from_index_list(rows: list[str], element: dict) -> list[str]:
    """The ASCII rows of a face element from its vertex index list on (the properties before it dropped)."""
    before = element["props"][: _face_list_index(element)]
    if not before:
        return rows
    cut = []
    for row in rows:
        tokens, at = row.split(), 0
        for p in before:
            at += 1 + (int(tokens[at]) if p[1] == "list" else 0)
        cut.append(" ".join(tokens[at:]))
    return cut


def _read_ply_binary(body: bytes, elements: list[dict], order: str) -> tuple[dict[str, np.ndarray], tuple | None]:
    """({property name: column} of the vertex element, the faces as :func:`_off_polygons` gives them, None when
    there is no face or tristrips element)."""
    pos = 0
    vertices, polygons = None, []
    for element in elements:
        columns, size = _ply_binary_element(body, element, order, pos)
        pos += size
        if element["name"] == "vertex":
            if any(p[1] == "list" for p in element["props"]):
                raise MeshError("PLY vertex element with list properties is not supported")
            vertices = columns
        elif element["name"] in _PLY_FACES:
            polygons.append(_ply_polygons(element, columns[element["props"][_face_list_index(element)][0]]))
    return vertices, _joined(polygons)


def _ply_binary_element(body: bytes, element: dict, order: str, pos: int) -> tuple[dict, int]:
    """({property name: (count,) column, or (lengths (count,), values concatenated) for a list property}, bytes
    read) of a binary PLY element at ``pos``. Read at once when every record's lists are as long as the first
    record's (a triangle mesh's faces); otherwise record by record."""
    props, count, name = element["props"], element["count"], element["name"]
    lists = [p[0] for p in props if p[1] == "list"]
    records: dict[tuple, np.dtype] = {}

    def record(lengths: tuple) -> np.dtype:  # the record whose list properties have these lengths
        if lengths not in records:
            fields, given = [], iter(lengths)
            for p in props:
                if p[1] == "list":
                    fields += [(p[0] + " length", order + p[2]), (p[0], order + p[3], (next(given),))]
                else:
                    fields.append((p[0], order + p[1]))
            records[lengths] = np.dtype(fields)
        return records[lengths]

    # (struct format of the list length or None, bytes of the length or the scalar, bytes of a list value)
    layout = [
        (order + np.dtype(p[2]).char, np.dtype(p[2]).itemsize, np.dtype(p[3]).itemsize)
        if p[1] == "list"
        else (None, np.dtype(p[1]).itemsize, 0)
        for p in props
    ]

    def lengths_at(at: int) -> tuple:  # the list lengths of the record at ``at``
        lengths = []
        for length_format, size, value_size in layout:
            if length_format is not None:
                if at + size > len(body):
                    raise MeshError(f"PLY file is truncated inside the '{name}' element")
                length = struct.unpack_from(length_format, body, at)[0]
                if length < 0:
                    raise MeshError(f"a '{name}' record has a list of {length} values")
                lengths.append(length)
                at += length * value_size
            at += size
        return tuple(lengths)

    first = lengths_at(pos) if count and lists else (0,) * len(lists)
    size = record(first).itemsize * count
    if len(body) >= pos + size:  # one read when every record is as long as the first
        table = np.frombuffer(body, dtype=record(first), count=count, offset=pos)
        lengths = np.stack([table[n + " length"] for n in lists], axis=1).astype(np.int64) if lists else None
        if not lists or np.all(lengths == first):
            columns = {p[0]: table[p[0]] for p in props if p[1] != "list"}
            return columns | {n: (lengths[:, j], table[n].reshape(-1)) for j, n in enumerate(lists)}, size
    if not lists:
        raise MeshError(f"PLY file is truncated inside the '{name}' element")
    rows, lengths, at = [], [], pos
    for _ in range(count):  # lists of several lengths: records of several sizes
        lengths.append(lengths_at(at))
        rows.append(_frombuffer(body, record(lengths[-1]), 1, at, name)[0])
        at += record(lengths[-1]).itemsize
    columns = {p[0]: np.array([row[p[0]] for row in rows]) for p in props if p[1] != "list"}
    for j, n in enumerate(lists):
        columns[n] = (np.array(lengths, dtype=np.int64)[:, j], np.concatenate([np.ravel(row[n]) for row in rows]))
    return columns, at - pos


def _frombuffer(body: bytes, dtype: np.dtype, count: int, pos: int, what: str) -> np.ndarray:
    need = dtype.itemsize * count
    if len(body) < pos + need:
        raise MeshError(f"PLY file is truncated inside the '{what}' element")
    return np.frombuffer(body, dtype=dtype, count=count, offset=pos)


# ------------------------------------------------------------------------------------- STL
def _read_stl(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    if len(data) >= 84:
        count = struct.unpack("<I", data[80:84])[0]
        if len(data) == 84 + 50 * count:
            record = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attr", "<u2")])
            corners = np.frombuffer(data, dtype=record, count=count, offset=84)["corners"]
            return _merge_corners(corners.reshape(-1, 3).astype(np.float64))
    text = data.decode("ascii")
    if not text.lstrip().startswith("solid"):
        raise MeshError("neither a binary STL (size does not match its triangle count) nor ASCII STL")
    coords = [line.split()[1:4] for line in text.splitlines() if line.strip().startswith("vertex")]
    if not coords or len(coords) % 3:
        raise MeshError(f"ASCII STL has {len(coords)} 'vertex' lines, expected a multiple of 3")
    return _merge_corners(np.array(coords, dtype=np.float64))


def _merge_corners(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge identical corner coordinates, numbering vertices in order of first appearance."""
    unique, first, inverse = np.unique(corners, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return unique[order], rank[inverse.ravel()].reshape(-1, 3)


# ---------------------------------------------------------------------------------- writers
def _format_rows(array: np.ndarray, fmt: str) -> str:
    return "\n".join(fmt % tuple(row) for row in array.tolist())


def _write_off(mesh: TriMesh) -> bytes:
    head = f"OFF\n{mesh.n_vertices} {mesh.n_faces} 0\n"
    faces = np.hstack([np.full((mesh.n_faces, 1), 3), mesh.faces])
    body = _format_rows(mesh.vertices, "%.17g %.17g %.17g") + "\n" + _format_rows(faces, "%d %d %d %d") + "\n"
    return (head + body).encode()


def _write_obj(mesh: TriMesh) -> bytes:
    body = _format_rows(mesh.vertices, "v %.17g %.17g %.17g") + "\n" + _format_rows(mesh.faces + 1, "f %d %d %d") + "\n"
    return body.encode()


def _write_ply(mesh: TriMesh) -> bytes:
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment written by hamsa\n"
        f"element vertex {mesh.n_vertices}\nproperty double x\nproperty double y\nproperty double z\n"
        f"element face {mesh.n_faces}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    record = np.dtype([("n", "u1"), ("idx", "<i4", (3,))])
    faces = np.empty(mesh.n_faces, dtype=record)
    faces["n"] = 3
    faces["idx"] = mesh.faces
    return header.encode() + mesh.vertices.astype("<f8").tobytes() + faces.tobytes()


def _write_stl(mesh: TriMesh) -> bytes:
    record = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attr", "<u2")])
    table = np.zeros(mesh.n_faces, dtype=record)
    v = mesh.vertices[mesh.faces]
    normals = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    table["normal"] = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    table["corners"] = v
    header = b"binary STL written by hamsa".ljust(80, b" ")
    return header + struct.pack("<I", mesh.n_faces) + table.tobytes()
