import numpy as np
import pytest

import hamsa
from hamsa import shapes
from hamsa.cli import main
from hamsa.compression import CompressionError, decode, encode, karni_gotsman_error, rms_error, sizes

from conftest import data_mesh


@pytest.fixture(scope="module")
def mesh():
    base = shapes.capsule(radius=0.5, length=1.5, n_around=20)
    x, y, z = base.vertices.T
    return hamsa.TriMesh(base.vertices * (1 + 0.1 * np.sign(z)[:, None] * np.abs(x)[:, None]), base.faces)


def test_round_trip_is_deterministic_and_near_the_projection(mesh):
    data = encode(mesh, 30, 24, "mhb")
    a, b = decode(data, mesh.faces), decode(data, mesh.faces)
    np.testing.assert_array_equal(a, b)
    # 24-bit coefficients: the decoded mesh is the orthogonal projection onto the first 30 eigenvectors
    from hamsa.compression import _basis, combinatorial_laplacian

    phi = _basis(combinatorial_laplacian(mesh.faces, mesh.n_vertices), None, 30)
    np.testing.assert_allclose(a, phi @ (phi.T @ mesh.vertices), atol=1e-6 * np.abs(mesh.vertices).max())


def test_more_bits_never_increase_the_error(mesh):
    errors = [rms_error(mesh, decode(encode(mesh, 40, bits, "mhb"), mesh.faces)) for bits in (4, 6, 8, 10, 12, 16)]
    assert all(later <= earlier * (1 + 1e-9) for earlier, later in zip(errors, errors[1:]))
    assert errors[0] > errors[-1]


def test_more_coefficients_reduce_the_error_and_cost_bits(mesh):
    small, large = encode(mesh, 10, 12), encode(mesh, 60, 12)
    assert sizes(large).payload_bits > sizes(small).payload_bits
    assert karni_gotsman_error(mesh, decode(large, mesh.faces)) < karni_gotsman_error(mesh, decode(small, mesh.faces))


@pytest.mark.parametrize("method", ["hamiltonian", "hamiltonian-opt"])
def test_hamiltonian_methods_decode_with_the_original_faces(mesh, method):
    z = mesh.vertices[:, 2]
    potential = 0.01 * (z - z.min())  # small and smooth: the sorted-index ramp of "hamiltonian" fits it well
    data = encode(mesh, 20, 16, method, potential=potential)
    decoded = decode(data, mesh.faces)
    # the permutation is undone: the result is close to the original, as close as the LBO basis gets
    baseline = rms_error(mesh, decode(encode(mesh, 20, 16, "mhb"), mesh.faces))
    assert rms_error(mesh, decoded) < 2 * baseline
    info = sizes(data)
    if method == "hamiltonian":
        assert info.permutation_bits > 64 and info.potential_bits == 0
    else:
        assert info.potential_bits > 64


def test_corrupted_or_truncated_files_raise(mesh):
    data = encode(mesh, 10, 12)
    for position in (1, 4, 20, len(data) // 2, len(data) - 3):
        broken = bytearray(data)
        broken[position] ^= 0xFF
        with pytest.raises(CompressionError):
            decode(bytes(broken), mesh.faces)
    for cut in (2, 10, len(data) - 1):
        with pytest.raises(CompressionError, match="truncated|magic"):
            decode(data[:cut], mesh.faces)
    with pytest.raises(CompressionError, match="faces"):
        decode(data, mesh.faces + 5000)


def test_cli_compress_and_decompress(tmp_path, mesh, capsys):
    source = tmp_path / "m.off"
    hamsa.save_mesh(mesh, source)
    assert main(["compress", str(source), "-o", str(tmp_path / "m.hmz"), "-k", "20", "--bits", "10"]) == 0
    assert main(["decompress", str(tmp_path / "m.hmz"), "--faces", str(source), "-o", str(tmp_path / "d.obj")]) == 0
    decoded = hamsa.load_mesh(tmp_path / "d.obj")
    assert decoded.n_vertices == mesh.n_vertices and rms_error(mesh, decoded.vertices) < 0.05
    (tmp_path / "bad.hmz").write_bytes(b"HMZ\x01\x00garbage")
    assert main(["decompress", str(tmp_path / "bad.hmz"), "--faces", str(source), "-o", str(tmp_path / "x.obj")]) == 2
    assert not (tmp_path / "x.obj").exists()


@pytest.mark.data
def test_fandisk_ordering_at_equal_coefficients():
    """T16: error(hamiltonian-opt) <= error(hamiltonian) <= error(mhb) at 100 coefficients, 12 bits."""
    fandisk = data_mesh("classic/fandisk.obj")
    import scipy.sparse as sp

    from hamsa.compression import combinatorial_laplacian
    from hamsa.optimize import optimize_potential

    n = fandisk.n_vertices
    V = optimize_potential(
        None,
        fandisk.vertices,
        100,
        operators=(combinatorial_laplacian(fandisk.faces, n), sp.identity(n, format="csr")),
        m=250,
        mass_weighted=False,
        max_iterations=60,
        rounds=6,
    ).potential
    errors = {
        method: karni_gotsman_error(fandisk, decode(encode(fandisk, 100, 12, method, potential=V), fandisk.faces))
        for method in ("mhb", "hamiltonian", "hamiltonian-opt")
    }
    assert errors["hamiltonian-opt"] <= errors["hamiltonian"] <= errors["mhb"]
