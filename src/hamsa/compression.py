"""Spectral mesh-geometry compression (Karni & Gotsman 2000) and the paper's Hamiltonian variant (section 3).

The decoder knows the connectivity; the file carries the first ``k`` coefficients of the
vertex coordinates in a basis the decoder can rebuild from the connectivity alone:

* ``"mhb"``: eigenvectors of the combinatorial Laplacian ``L = D - Adj`` (Karni-Gotsman; L is symmetric,
  so the basis is orthonormal).
* ``"hamiltonian"``: the encoder optimizes a potential V for representing the coordinates with
  ``H = L + diag(V)`` (:func:`hamsa.optimize.optimize_potential`, Euclidean setting), reorders the
  vertices by increasing V, and sends only the least-squares line ``V ~ alpha i + beta`` (i = 1..n in the
  new order); the decoder uses ``H = L + alpha diag(1..n) + beta I`` (paper eq. after "fixed potential").
* ``"hamiltonian-opt"``: the basis of the optimized V itself; V travels in the file but, as in the paper,
  its bits are not counted in the rate.

The paper treats the vertex order as free (a connectivity coder can send vertices in any order). We
store the permutation in the file so that decoding works with the original faces, and report its
size separately (``permutation_bits``), next to the counted geometry payload (``payload_bits``).

Coefficients are quantized uniformly per coordinate to ``bits`` bits and entropy-coded with LZMA.
File layout (little endian): magic ``HMZ``, format version, method, then length-prefixed sections
(header numbers, coefficients, permutation, potential), each with a CRC-32, and a final CRC-32 of
every byte before it (magic, version and method included). Any corruption or truncation raises
:class:`CompressionError`; the sizes a header claims are checked against the faces before anything
is allocated, and every decompressed section is bounded by the size the header implies.
"""

from __future__ import annotations

import lzma
import struct
import zlib
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hamsa.eigen import generalized_eigsh
from hamsa.errors import CompressionError, FileAccessError, HamsaError
from hamsa.files import bounded_decompress
from hamsa.mesh import TriMesh, as_trimesh

MAGIC = b"HMZ"
VERSION = 2
METHODS = ("mhb", "hamiltonian", "hamiltonian-opt")
_HEADER = struct.Struct("<IIBdd")  # n, k, bits, alpha, beta


@dataclass(frozen=True)
class EncodedSizes:
    """Sizes in bits of the parts of an encoded file."""

    payload_bits: int  # header + coefficients (+ alpha, beta): what the paper's rate counts
    permutation_bits: int  # the vertex order of "hamiltonian" (free in the paper's accounting)
    potential_bits: int  # V of "hamiltonian-opt" (not counted, as in the paper)
    n_vertices: int

    @property
    def bits_per_vertex(self) -> float:
        return self.payload_bits / self.n_vertices


def combinatorial_laplacian(faces: np.ndarray, n: int) -> sp.csr_matrix:
    """``L = D - Adj`` of the mesh graph (unit edge weights), (n, n), symmetric positive semidefinite."""
    f = np.asarray(faces)
    i = np.concatenate([f[:, 0], f[:, 1], f[:, 2]])
    j = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    adjacency = sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n)).tocsr()
    adjacency = ((adjacency + adjacency.T) > 0).astype(np.float64)
    return (sp.diags(np.asarray(adjacency.sum(axis=1)).ravel()) - adjacency).tocsr()


def _basis(L: sp.csr_matrix, diagonal: np.ndarray | None, k: int) -> np.ndarray:
    n = L.shape[0]
    H = L if diagonal is None else (L + sp.diags(diagonal)).tocsr()
    lower = 0.0 if diagonal is None else float(min(diagonal.min(), 0.0))
    _, vectors, _ = generalized_eigsh(H, sp.identity(n, format="csr"), k, lower_bound=lower)
    return vectors


def _section(data: bytes) -> bytes:
    return struct.pack("<II", len(data), zlib.crc32(data)) + data


def _read_sections(blob: bytes, count: int) -> list[bytes]:
    sections, position = [], 0
    for index in range(count):
        if position + 8 > len(blob):
            raise CompressionError(f"file is truncated (section {index} header missing)")
        length, crc = struct.unpack_from("<II", blob, position)
        position += 8
        data = blob[position : position + length]
        if len(data) != length:
            raise CompressionError(f"file is truncated (section {index} has {len(data)} of {length} bytes)")
        if zlib.crc32(data) != crc:
            raise CompressionError(f"file is corrupted (checksum of section {index} does not match)")
        sections.append(data)
        position += length
    if position != len(blob):
        raise CompressionError(f"file has {len(blob) - position} unexpected trailing bytes")
    return sections


def _quantize(coefficients: np.ndarray, bits: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    low, high = coefficients.min(axis=0), coefficients.max(axis=0)
    span = np.where(high > low, high - low, 1.0)
    levels = (1 << bits) - 1
    q = np.round((coefficients - low) / span * levels).astype(np.uint32)
    return q, low, span


def _dequantize(q: np.ndarray, low: np.ndarray, span: np.ndarray, bits: int) -> np.ndarray:
    return low + q.astype(np.float64) * span / ((1 << bits) - 1)


def encode(
    mesh, k: int, bits: int = 12, method: str = "mhb", *, potential=None, optimize_iterations: int = 60
) -> bytes:
    """Compress the vertex coordinates of ``mesh`` to bytes.

    Parameters
    ----------
    mesh : TriMesh or (vertices, faces)
    k : number of basis functions (coefficients per coordinate), < n
    bits : bits per quantized coefficient, 2..24
    method : "mhb", "hamiltonian" or "hamiltonian-opt"
    potential : (n,) optional precomputed optimized potential (in the mesh's vertex order), to share one
        optimization between the two Hamiltonian methods; by default it is optimized here
    optimize_iterations : L-BFGS iterations of the potential optimization
    """
    mesh = as_trimesh(mesh)
    n = mesh.n_vertices
    if method not in METHODS:
        raise HamsaError(f"method must be one of {METHODS}, got {method!r}")
    if not 1 <= k < n - 1:
        raise HamsaError(f"k = {k} must be between 1 and n - 2 = {n - 2}")
    if not 2 <= bits <= 24:
        raise HamsaError(f"bits = {bits} must be between 2 and 24")
    L = combinatorial_laplacian(mesh.faces, n)
    X = mesh.vertices
    order = np.arange(n)
    alpha = beta = 0.0
    diagonal = None
    potential_bytes = b""
    if method != "mhb":
        if potential is None:
            from hamsa.optimize import optimize_potential

            potential = optimize_potential(
                None,
                X,
                k,
                operators=(L, sp.identity(n, format="csr")),
                mass_weighted=False,
                m=min(n, 2 * k + 50),
                max_iterations=optimize_iterations,
                rounds=max(1, optimize_iterations // 10),
                smoothing=(),  # the optimizer the compression results were measured with
            ).potential
        potential = np.asarray(potential, dtype=np.float64)
        if potential.shape != (n,):
            raise HamsaError(f"potential has shape {potential.shape}, expected ({n},)")
        if method == "hamiltonian":
            order = np.argsort(potential, kind="stable")
            index = np.arange(1, n + 1, dtype=np.float64)
            alpha, beta = np.polyfit(index, potential[order], 1)
            diagonal = alpha * index + beta
        else:
            diagonal = potential
            potential_bytes = lzma.compress(potential.astype("<f8").tobytes())
    inverse = np.empty(n, dtype=np.int64)
    inverse[order] = np.arange(n)
    L_sorted = L[order][:, order]
    basis = _basis(L_sorted, diagonal, k)
    q, low, span = _quantize(basis.T @ X[order], bits)
    header = _HEADER.pack(n, k, bits, alpha, beta) + low.astype("<f8").tobytes() + span.astype("<f8").tobytes()
    coefficients = lzma.compress(q.astype("<u4").tobytes(), preset=9 | lzma.PRESET_EXTREME)
    permutation = lzma.compress(np.diff(order, prepend=0).astype("<i4").tobytes()) if method == "hamiltonian" else b""
    body = b"".join(_section(x) for x in (header, coefficients, permutation, potential_bytes))
    blob = MAGIC + bytes([VERSION, METHODS.index(method)]) + body
    return blob + struct.pack("<I", zlib.crc32(blob))


def sizes(data: bytes) -> EncodedSizes:
    """How the bits of an encoded file split into the counted payload and the uncounted side parts."""
    method, sections = _parse(data)
    n = _HEADER.unpack_from(sections[0])[0]
    overhead = 8 * (len(MAGIC) + 2 + 4)
    payload = overhead + 8 * (len(sections[0]) + len(sections[1]) + 16)
    return EncodedSizes(payload, 8 * (len(sections[2]) + 8), 8 * (len(sections[3]) + 8) if sections[3] else 0, n)


def _parse(data: bytes) -> tuple[str, list[bytes]]:
    if not isinstance(data, (bytes, bytearray)) or len(data) < len(MAGIC) + 6 or data[: len(MAGIC)] != MAGIC:
        raise CompressionError("not a hamsa compressed mesh (bad magic)")
    version, method = data[len(MAGIC)], data[len(MAGIC) + 1]
    if version != VERSION:
        raise CompressionError(f"file has format version {version}, this hamsa reads {VERSION} (re-encode it)")
    if zlib.crc32(data[:-4]) != struct.unpack("<I", data[-4:])[0]:
        raise CompressionError("file is truncated or corrupted (the checksum over the whole file does not match)")
    if method >= len(METHODS):
        raise CompressionError(f"unknown method id {method}")
    sections = _read_sections(bytes(data[len(MAGIC) + 2 : -4]), 4)
    if len(sections[0]) != _HEADER.size + 48:
        raise CompressionError(f"file is corrupted: its header has {len(sections[0])} bytes")
    return METHODS[method], sections


def _unpack(blob: bytes, dtype: str, count: int, what: str) -> np.ndarray:
    """``count`` values of ``dtype`` from an LZMA section, never decompressing more than they need."""
    size = np.dtype(dtype).itemsize * count
    try:
        raw = bounded_decompress(blob, "lzma", size, what)
    except FileAccessError as exc:
        raise CompressionError(f"file is corrupted: {exc}") from None
    if len(raw) != size:
        raise CompressionError(f"file is corrupted: the {what} has {len(raw)} bytes, expected {size}")
    return np.frombuffer(raw, dtype)


def decode(data: bytes, faces) -> np.ndarray:
    """Rebuild the vertex coordinates (n, 3), in the original vertex order, from ``encode``'s bytes and the faces.

    Raises CompressionError if the file is not an intact file of this format version, or if ``faces``
    do not reference exactly the encoded number of vertices.
    """
    method, (header, coefficient_bytes, permutation_bytes, potential_bytes) = _parse(data)
    n, k, bits, alpha, beta = _HEADER.unpack_from(header)
    faces = np.asarray(faces)
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.size == 0 or faces.dtype.kind not in "iu":
        raise CompressionError(f"faces must be an (m, 3) integer array, got {faces.shape} {faces.dtype}")
    if faces.min() < 0 or faces.max() + 1 != n:
        raise CompressionError(f"faces reference vertices 0..{faces.max()}, the file encodes {n} vertices")
    if not (1 <= k < n - 1 and 2 <= bits <= 24):
        raise CompressionError(f"file is corrupted: k = {k}, bits = {bits} do not fit n = {n}")
    low = np.frombuffer(header, "<f8", 3, _HEADER.size)
    span = np.frombuffer(header, "<f8", 3, _HEADER.size + 24)
    q = _unpack(coefficient_bytes, "<u4", 3 * k, "coefficients").reshape(k, 3)
    order = np.cumsum(_unpack(permutation_bytes, "<i4", n, "vertex order")) if permutation_bytes else np.arange(n)
    potential = _unpack(potential_bytes, "<f8", n, "potential") if potential_bytes else None
    if (method == "hamiltonian") != bool(permutation_bytes) or (method == "hamiltonian-opt") != bool(potential_bytes):
        raise CompressionError(f"file is corrupted: its sections do not match the method {method!r}")
    if not np.array_equal(np.sort(order), np.arange(n)):
        raise CompressionError("file is corrupted: the stored vertex order is not a permutation")
    parameters = [low, span, alpha, beta] + ([] if potential is None else [potential])
    if not all(np.all(np.isfinite(p)) for p in parameters):
        raise CompressionError("file is corrupted: non-finite quantization or potential parameters")
    L = combinatorial_laplacian(faces, n)[order][:, order]
    if method == "mhb":
        diagonal = None
    elif method == "hamiltonian":
        diagonal = alpha * np.arange(1, n + 1, dtype=np.float64) + beta
    else:
        diagonal = potential
    basis = _basis(L, diagonal, k)
    coordinates = basis @ _dequantize(q, low, span, bits)
    out = np.empty_like(coordinates)
    out[order] = coordinates
    return out


def geometric_laplacian(mesh: TriMesh, vertices: np.ndarray) -> np.ndarray:
    """Karni-Gotsman's GL(v_i) = v_i - sum_j w_ij v_j / sum_j w_ij, w_ij = 1 / |e_ij| of the ORIGINAL mesh."""
    e = mesh.edges
    w = 1.0 / mesh.edge_lengths
    n = mesh.n_vertices
    weights = sp.coo_matrix(
        (np.concatenate([w, w]), (np.concatenate([e[:, 0], e[:, 1]]), np.concatenate([e[:, 1], e[:, 0]]))), shape=(n, n)
    ).tocsr()
    return vertices - (weights @ vertices) / np.asarray(weights.sum(axis=1))


def karni_gotsman_error(mesh: TriMesh, decoded: np.ndarray) -> float:
    """``(1/2n) (sum_i |v_i - v'_i| + sum_i |GL(v_i) - GL(v'_i)|)`` (Karni & Gotsman 2000's visual metric)."""
    original = mesh.vertices
    gl = geometric_laplacian(mesh, original) - geometric_laplacian(mesh, decoded)
    return float(
        (np.linalg.norm(original - decoded, axis=1).sum() + np.linalg.norm(gl, axis=1).sum()) / (2 * mesh.n_vertices)
    )


def rms_error(mesh: TriMesh, decoded: np.ndarray) -> float:
    """Root-mean-square vertex error divided by the bounding-box diagonal."""
    return float(np.sqrt(np.mean(np.sum((mesh.vertices - decoded) ** 2, axis=1))) / mesh.bounding_box_diagonal)
