import os
import subprocess
import sys

import numpy as np
import pytest

import hamsa
from hamsa import shapes
from hamsa.cli import main


def run(*args):
    """The CLI as a user runs it: a separate process, capturing both streams."""
    return subprocess.run([sys.executable, "-m", "hamsa.cli", *args], capture_output=True, text=True, timeout=120)


@pytest.fixture
def mesh_file(tmp_path):
    path = tmp_path / "capsule.off"
    hamsa.save_mesh(shapes.capsule(n_around=24), path)
    return path


def test_info_describes_the_mesh(mesh_file, capsys):
    assert main(["info", str(mesh_file)]) == 0
    out = capsys.readouterr().out
    assert "components      1" in out and "Euler char.     2, genus 0" in out and "defects         none" in out


def test_basis_writes_a_loadable_npz(mesh_file, tmp_path, capsys):
    mesh = hamsa.load_mesh(mesh_file)
    potential = tmp_path / "v.npy"
    np.save(potential, np.linspace(0, 3, mesh.n_vertices))
    out = tmp_path / "basis.npz"
    assert main(["basis", str(mesh_file), "-k", "6", "--potential", str(potential), "-o", str(out)]) == 0
    assert "time" in capsys.readouterr().out
    basis = hamsa.Eigenbasis.load(out)
    reference = hamsa.eigenbasis(mesh, 6, np.linspace(0, 3, mesh.n_vertices))
    np.testing.assert_allclose(basis.values, reference.values, rtol=1e-10)


def test_basis_computes_100_pairs_by_default_as_match_does(mesh_file, tmp_path):
    out = tmp_path / "basis.npz"
    assert main(["basis", str(mesh_file), "-q", "-o", str(out)]) == 0
    basis = hamsa.Eigenbasis.load(out)
    reference = hamsa.eigenbasis(hamsa.load_mesh(mesh_file), 100)
    assert basis.k == 100
    np.testing.assert_allclose(basis.values, reference.values, rtol=1e-9, atol=1e-9)


def test_basis_and_view_take_potential_specifications(mesh_file, tmp_path, capsys):
    """``--potential SPEC`` is :func:`hamsa.potentials.from_spec` on the mesh as read; a bad one exits 2."""
    from hamsa.potentials import from_spec

    mesh = hamsa.load_mesh(mesh_file)
    out = tmp_path / "basis.npz"
    for spec in ("100*geodesic:0", "40*step:z>0.2", "10*eigsum:1-4"):
        assert main(["basis", str(mesh_file), "-k", "6", "--potential", spec, "-o", str(out)]) == 0
        reference = hamsa.eigenbasis(mesh, 6, from_spec(mesh, spec))
        np.testing.assert_allclose(hamsa.Eigenbasis.load(out).values, reference.values, rtol=1e-10)
    page = tmp_path / "view.html"
    assert main(["view", str(mesh_file), "-k", "3", "--potential", "100*geodesic:0", "-o", str(page)]) == 0
    assert page.stat().st_size > 1000
    capsys.readouterr()
    assert main(["basis", str(mesh_file), "-k", "6", "--potential", "step:z>99", "-o", str(out)]) == 2
    assert "no vertex has z > 99" in capsys.readouterr().err


def test_a_potential_file_of_the_input_follows_repair(tmp_path, capsys):
    """After --repair drops a loose vertex, a potential with one value per input vertex is restricted to
    the vertices kept (as the basis' vertex_ids say)."""
    capsule = shapes.capsule(n_around=16)
    path = tmp_path / "loose.off"
    hamsa.save_mesh(hamsa.TriMesh(np.vstack([[9.0, 9.0, 9.0], capsule.vertices]), capsule.faces + 1), path)
    V = np.linspace(0, 5, capsule.n_vertices + 1)
    np.save(tmp_path / "v.npy", V)
    out = tmp_path / "basis.npz"
    assert (
        main(["basis", str(path), "-k", "5", "--repair", "--potential", str(tmp_path / "v.npy"), "-o", str(out)]) == 0
    )
    saved = hamsa.Eigenbasis.load(out)
    np.testing.assert_array_equal(saved.vertex_ids, np.arange(1, capsule.n_vertices + 1))
    np.testing.assert_allclose(saved.values, hamsa.eigenbasis(capsule, 5, V[1:]).values, rtol=1e-10)


def test_optimize_with_repair_reads_and_writes_values_per_input_vertex(tmp_path, capsys):
    """After --repair drops a loose vertex, optimize's --data is read per input vertex (as a potential file
    is), its potential is written per input vertex with NaN at the dropped one, equal to the Python API's on
    the repaired mesh, and basis/view read it back through --repair; a wrong row count names both counts."""
    from hamsa.optimize import optimize_potential

    capsule = shapes.capsule(n_around=16)
    path = tmp_path / "loose.off"
    hamsa.save_mesh(hamsa.TriMesh(np.vstack([[9.0, 9.0, 9.0], capsule.vertices]), capsule.faces + 1), path)
    data = np.vstack([[5.0, 5.0, 5.0], capsule.vertices**2])  # per input vertex; the loose row is ignored
    np.save(tmp_path / "data.npy", data)
    out = tmp_path / "v.npy"
    command = ["optimize", str(path), "--repair", "--data", str(tmp_path / "data.npy"), "-k", "5", "-m", "30"]
    assert main([*command, "--iterations", "7", "-o", str(out)]) == 0
    assert "7 iterations" in capsys.readouterr().out  # --iterations counts them all, over every stage
    written = np.load(out)
    expected = optimize_potential(capsule, capsule.vertices**2, 5, m=30, max_iterations=7)
    assert written.shape == (capsule.n_vertices + 1,) and np.isnan(written[0])
    np.testing.assert_allclose(written[1:], expected.potential, rtol=1e-8, atol=1e-10)
    basis = tmp_path / "b.npz"
    assert main(["basis", str(path), "--repair", "--potential", str(out), "-k", "5", "-q", "-o", str(basis)]) == 0
    np.testing.assert_allclose(
        hamsa.Eigenbasis.load(basis).values, hamsa.eigenbasis(capsule, 5, expected.potential).values, rtol=1e-9
    )
    assert main(["view", str(path), "--repair", "--field", str(out), "-o", str(tmp_path / "v.html")]) == 0
    np.save(tmp_path / "short.npy", data[:10])
    capsys.readouterr()
    assert main([*command[:4], str(tmp_path / "short.npy"), *command[5:], "-o", str(tmp_path / "w.npy")]) == 2
    assert f"expected {capsule.n_vertices + 1} (the input's) or {capsule.n_vertices} (after --repair)" in (
        capsys.readouterr().err
    )


@pytest.mark.parametrize(
    "case, message",
    [
        ("missing mesh", "no such file"),
        ("garbage mesh", "expected 'OFF'"),
        ("short potential", "expected 626 rows"),
        ("nan potential", "non-finite"),
        ("k too large", "between 1 and the number of vertices"),
        ("bad output", "must end in .npz"),
    ],
)
def test_bad_input_exits_2_with_one_line_and_no_output(tmp_path, mesh_file, case, message):
    out = tmp_path / "out.npz"
    n = hamsa.load_mesh(mesh_file).n_vertices
    np.save(tmp_path / "short.npy", np.zeros(n - 1))
    np.save(tmp_path / "nan.npy", np.full(n, np.nan))
    (tmp_path / "garbage.off").write_bytes(b"\x00garbage")
    args = {
        "missing mesh": ["basis", str(tmp_path / "nope.off"), "-k", "3", "-o", str(out)],
        "garbage mesh": ["info", str(tmp_path / "garbage.off")],
        "short potential": [
            "basis",
            str(mesh_file),
            "-k",
            "3",
            "--potential",
            str(tmp_path / "short.npy"),
            "-o",
            str(out),
        ],
        "nan potential": ["basis", str(mesh_file), "-k", "3", "--potential", str(tmp_path / "nan.npy"), "-o", str(out)],
        "k too large": ["basis", str(mesh_file), "-k", "100000", "-o", str(out)],
        "bad output": ["basis", str(mesh_file), "-k", "3", "-o", str(tmp_path / "out.txt")],
    }[case]
    result = run(*args)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in result.stderr
    assert not out.exists() and not [p for p in os.listdir(tmp_path) if p.endswith(".tmp")]


def test_demo_prints_the_theorem_1_table(capsys):
    assert main(["demo", "-k", "8"]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.strip()[:1].isdigit() and ("ok" in line or "FAIL" in line)]
    assert len(rows) == 8 and all(" ok " in row for row in rows)


def test_cli_view_writes_a_self_contained_page(tmp_path):
    pytest.importorskip("plotly", reason="interactive views need the [viz] extra")
    from hamsa.io import save_mesh

    mesh_path = tmp_path / "ico.off"
    save_mesh(shapes.icosphere(2), mesh_path)
    page = tmp_path / "view.html"
    assert main(["view", str(mesh_path), "-k", "4", "-o", str(page)]) == 0
    text = page.read_text()
    assert "psi 4 (E =" in text and "psi 0 (E" not in text and "<script src=" not in text  # constant skipped
    assert main(["view", str(mesh_path), "-o", str(tmp_path / "view.png")]) == 2  # wrong suffix


def test_basis_shows_its_steps_and_the_converged_pairs_on_a_terminal(tmp_path, capsys, monkeypatch):
    """On a terminal the solve's line counts the converged eigenpairs (the solver's progress callback);
    with --quiet, or when stderr is not a terminal, nothing is shown."""
    path = tmp_path / "sphere.off"
    hamsa.save_mesh(shapes.sphere(5000), path)
    out = tmp_path / "b.npz"
    calls = []
    basis = hamsa.eigenbasis(hamsa.load_mesh(path), 30, progress=lambda c, k: calls.append((c, k)))
    assert calls[-1] == (30, 30) and len(calls) > 2 and all(0 <= c <= k == 30 for c, k in calls)
    assert basis.info.method == "krylov"
    assert main(["basis", str(path), "-k", "30", "-o", str(out)]) == 0
    assert "eigenpairs converged" not in capsys.readouterr().err  # not a terminal
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    assert main(["basis", str(path), "-k", "30", "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "solving for 30 eigenpairs of n = 5000" in err and "30/30 eigenpairs converged" in err
    assert main(["basis", str(path), "-k", "30", "-q", "-o", str(out)]) == 0
    assert "eigenpairs converged" not in capsys.readouterr().err


def test_modes_and_optimize_take_a_point_file(tmp_path):
    pytest.importorskip("robust_laplacian", reason="point clouds need the [pointcloud] extra")
    from hamsa.cmm import compressed_modes

    points = tmp_path / "humanoid.npy"
    np.save(points, shapes.humanoid(spacing=0.05).vertices)
    out = tmp_path / "modes.npz"
    assert main(["modes", str(points), "-k", "2", "--mu", "30", "--neighbors", "20", "-o", str(out), "-q"]) == 0
    expected = compressed_modes(hamsa.PointCloud(np.load(points), neighbors=20), k=2, mu=30.0).modes
    with np.load(out) as saved:
        np.testing.assert_allclose(saved["modes"], expected, atol=1e-10)
    potential = tmp_path / "potential.npy"
    assert main(["optimize", str(points), "-k", "5", "-m", "30", "--iterations", "5", "-o", str(potential)]) == 0
    assert np.load(potential).shape == (len(np.load(points)),)
    assert main(["compress", str(points), "-k", "5", "-o", str(tmp_path / "c.hmz")]) == 2


def test_signature_gives_the_spheres_analytic_hks_and_wks(tmp_path, capsys):
    """On the unit sphere HKS(x, t) = sum_l (2l + 1) exp(-l(l + 1) t) / 4 pi at every vertex, the HKS scaled
    by the heat trace and the WKS are 1 / area; a saved --basis gives the same array; --repair writes a row
    per input vertex, NaN at the dropped one."""
    from hamsa.diffusion import default_hks_times

    sphere = shapes.icosphere(4)
    path, basis = tmp_path / "sphere.off", tmp_path / "basis.npz"
    hamsa.save_mesh(sphere, path)
    assert main(["signature", str(path), "-k", "36", "--count", "8", "-o", str(tmp_path / "hks.npy")]) == 0
    times = default_hks_times(hamsa.eigenbasis(sphere, 36), 8)
    degree = np.arange(6)[:, None]  # l <= 5: the 36 pairs
    expected = ((2 * degree + 1) * np.exp(-degree * (degree + 1) * times)).sum(axis=0) / (4 * np.pi)
    hks = np.load(tmp_path / "hks.npy")
    assert hks.shape == (sphere.n_vertices, 8) and np.abs(hks / expected - 1).max() < 0.02
    assert main(["basis", str(path), "-k", "36", "-q", "-o", str(basis)]) == 0
    for kind in ("--scaled", "wks"):
        options = ["--scaled"] if kind == "--scaled" else ["--kind", "wks"]
        output = tmp_path / f"{kind.strip('-')}.npy"
        assert main(["signature", str(path), "--basis", str(basis), *options, "-o", str(output)]) == 0
        assert np.abs(np.load(output) * sphere.area - 1).max() < 0.03, kind
    loose = tmp_path / "loose.off"
    hamsa.save_mesh(hamsa.TriMesh(np.vstack([[9.0, 9.0, 9.0], sphere.vertices]), sphere.faces + 1), loose)
    assert main(["signature", str(loose), "--repair", "-k", "36", "--count", "8", "-o", str(tmp_path / "r.npy")]) == 0
    repaired = np.load(tmp_path / "r.npy")
    assert np.isnan(repaired[0]).all() and np.abs(repaired[1:] / expected - 1).max() < 0.02
    assert "NaN at the 1 --repair dropped" in capsys.readouterr().out
    assert main(["signature", str(path), "--basis", str(basis), "--potential", "eigsum:1-4", "-o", str(output)]) == 2
    assert "--potential is for a basis computed here" in capsys.readouterr().err


def test_segment_cuts_the_sphere_into_hemispheres(tmp_path, capsys):
    """The nodal domains of the sphere's first nonconstant eigenfunction (linear in the coordinates) are two
    hemispheres; --repair writes -1 at the dropped vertex; an index beyond -k is refused."""
    sphere = shapes.icosphere(4)
    loose = tmp_path / "loose.off"
    hamsa.save_mesh(hamsa.TriMesh(np.vstack([[9.0, 9.0, 9.0], sphere.vertices]), sphere.faces + 1), loose)
    assert main(["segment", str(loose), "--repair", "--index", "1", "-o", str(tmp_path / "s.npy")]) == 0
    labels = np.load(tmp_path / "s.npy")
    assert labels[0] == -1 and labels.dtype == np.int64
    sizes = np.bincount(labels[1:])
    assert len(sizes) == 2 and sizes.min() > 0.45 * sphere.n_vertices
    direction = np.linalg.lstsq(sphere.vertices, np.where(labels[1:] == 0, -1.0, 1.0), rcond=None)[0]
    sides = np.sign(sphere.vertices @ direction)  # the plane through the centre that the nodal line follows
    assert np.mean(sides == np.where(labels[1:] == 0, -1.0, 1.0)) > 0.99
    assert "2 segments from eigenfunction 1" in capsys.readouterr().out
    assert main(["segment", str(loose), "--index", "5", "-k", "3", "-o", str(tmp_path / "t.npy")]) == 2
    assert "--index 5 needs at least k = 6" in capsys.readouterr().err


def test_repair_writes_the_repaired_mesh_or_cloud_and_its_input_ids(tmp_path, capsys):
    """hamsa repair: a mesh with a loose vertex, three duplicate faces and a second piece comes out without them
    (every piece kept with --all-pieces), its vertices the input's rows ids; a point file with a NaN and a
    repeated point comes out without them, its normals kept; a wrong kind of output is refused unwritten."""
    capsule, ball = shapes.capsule(n_around=16), shapes.icosphere(1)
    vertices = np.vstack([[9.0, 9.0, 9.0], capsule.vertices, 0.3 * ball.vertices + 5])  # the smaller piece
    faces = np.vstack([capsule.faces + 1, capsule.faces[:3] + 1, ball.faces + 1 + capsule.n_vertices])
    rows = [f"{x!r} {y!r} {z!r}" for x, y, z in vertices.tolist()] + [f"3 {a} {b} {c}" for a, b, c in faces]
    (tmp_path / "in.off").write_text(f"OFF\n{len(vertices)} {len(faces)} 0\n" + "\n".join(rows) + "\n")
    for options, pieces in (([], 1), (["--all-pieces"], 2)):
        out, ids = tmp_path / f"out{len(options)}.off", tmp_path / f"ids{len(options)}.npy"
        assert main(["repair", str(tmp_path / "in.off"), *options, "--ids", str(ids), "-o", str(out)]) == 0
        mesh, kept = hamsa.load_mesh(out), np.load(ids)
        np.testing.assert_array_equal(mesh.vertices, vertices[kept])
        assert mesh.n_components == pieces and mesh.n_faces == capsule.n_faces + (pieces - 1) * ball.n_faces
    assert "3 duplicate faces" in capsys.readouterr().out
    points = shapes.icosphere(2).vertices
    normals = points / np.linalg.norm(points, axis=1, keepdims=True)
    table = np.vstack([np.hstack([points, normals]), [np.nan, 0, 0, 0, 0, 1], np.hstack([points[:1], normals[:1]])])
    np.savetxt(tmp_path / "scan.xyz", table)
    assert (
        main(["repair", str(tmp_path / "scan.xyz"), "--ids", str(tmp_path / "p.npy"), "-o", str(tmp_path / "c.ply")])
        == 0
    )
    cloud, kept = hamsa.load_point_cloud(tmp_path / "c.ply"), np.load(tmp_path / "p.npy")
    np.testing.assert_array_equal(kept, np.arange(len(points)))
    np.testing.assert_array_equal(cloud.points, points)
    assert cloud.normals_origin == "given" and np.abs(cloud.normals - normals).max() < 1e-12
    for source, target in (("in.off", "x.xyz"), ("scan.xyz", "x.off")):
        assert main(["repair", str(tmp_path / source), "-o", str(tmp_path / target)]) == 2
        assert not (tmp_path / target).exists()
    assert "holds points: write .xyz" in capsys.readouterr().err
