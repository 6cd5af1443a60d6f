"""Well-defined repairs (repair=True / --repair) and the refusals that remain."""

import numpy as np
import pytest

import hamsa
from hamsa import shapes
from hamsa.cli import main
from hamsa.errors import MeshError, RepairWarning
from hamsa.io import load_mesh, save_mesh
from hamsa.repair import orient_faces, repair_mesh


@pytest.fixture(scope="module")
def ico():
    return shapes.icosphere(2)


def _write_off(path, vertices, faces):
    lines = [f"OFF\n{len(vertices)} {len(faces)} 0"]
    lines += [" ".join(f"{x:.17g}" for x in v) for v in vertices]
    lines += ["3 " + " ".join(str(int(i)) for i in f) for f in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_clean_mesh_is_unchanged(ico):
    mesh, kept, report = repair_mesh(ico.vertices, ico.faces)
    assert not report.changed and str(report) == "nothing to repair"
    np.testing.assert_array_equal(mesh.faces, ico.faces)
    np.testing.assert_array_equal(kept, np.arange(ico.n_vertices))


def test_flipped_faces_duplicates_and_degenerates_are_fixed(ico):
    faces = ico.faces.copy()
    faces[[3, 17, 40]] = faces[[3, 17, 40], ::-1]
    faces = np.vstack([faces, faces[5][::-1], [[0, 0, 1]]])  # a duplicate (reversed) and a degenerate face
    vertices = np.vstack([ico.vertices, [[5.0, 5.0, 5.0]]])  # and an unreferenced vertex
    mesh, kept, report = repair_mesh(vertices, faces)
    assert (report.flipped_faces, report.duplicate_faces, report.degenerate_faces) == (3, 1, 1)
    assert report.unreferenced_vertices == 1 and kept.tolist() == list(range(ico.n_vertices))
    assert mesh.is_consistently_oriented
    np.testing.assert_array_equal(mesh.faces, ico.faces)  # back to the outward orientation
    # a whole sphere turned inside out comes back outward
    inside_out, _, report = repair_mesh(ico.vertices, ico.faces[:, ::-1])
    np.testing.assert_array_equal(inside_out.faces, ico.faces)


def test_non_manifold_vertex_is_split_and_mapped_back():
    a = shapes.icosphere(1)
    b_vertices = a.vertices + [2.0, 0.0, 0.0]  # a second sphere touching the first at one vertex
    touch_a = int(np.argmax(a.vertices[:, 0]))
    touch_b = int(np.argmin(b_vertices[:, 0]))
    b_vertices[touch_b] = a.vertices[touch_a]
    remap = np.arange(a.n_vertices) + a.n_vertices
    remap[touch_b] = touch_a
    vertices = np.vstack([a.vertices, b_vertices])
    faces = np.vstack([a.faces, remap[a.faces]])
    assert hamsa.TriMesh(vertices, faces).non_manifold_vertices.tolist() == [touch_a]
    mesh, kept, report = repair_mesh(vertices, faces)
    assert report.split_vertices == 1 and mesh.non_manifold_vertices.size == 0
    assert np.sum(kept == touch_a) == 2  # the vertex and its copy both map to the original
    np.testing.assert_allclose(mesh.vertices, vertices[kept])
    largest, _, report = repair_mesh(vertices, faces, keep="largest")
    assert report.dropped_components == 1 and largest.vertex_components[0] == 1


def test_what_has_no_single_fix_is_still_refused():
    with pytest.raises(MeshError, match="more than two faces"):
        repair_mesh(np.eye(3).tolist() + [[0, 0, 0], [1, 1, 1]], [[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    # a Moebius strip: no consistent orientation exists
    n = 12
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    rim = []
    for s in (-0.3, 0.3):
        rim.append(
            np.stack([(1 + s * np.cos(t / 2)) * np.cos(t), (1 + s * np.cos(t / 2)) * np.sin(t), s * np.sin(t / 2)], 1)
        )
    vertices = np.vstack(rim)
    faces = []
    for i in range(n):
        j = (i + 1) % n
        a, b = (i, j) if j else (i, n)  # the last quad closes with a half twist: swap the two rims
        c, d = (n + i, n + j) if j else (n + i, 0)
        faces += [[a, b, d], [a, d, c]]
    with pytest.raises(MeshError, match="not orientable"):
        repair_mesh(vertices, np.array(faces))
    with pytest.raises(MeshError, match="not orientable"):
        orient_faces(hamsa.TriMesh(vertices, np.array(faces)))


def test_load_mesh_repair_warns_and_the_cli_warns_on_what_is_only_unusual_then_repairs(tmp_path, ico, capsys):
    """One validation policy: a flipped face and a second piece give right numbers, so every entry point
    takes them (the CLI with a warning naming --repair) and answers as hamsa.eigenbasis does."""
    faces = ico.faces.copy()
    faces[7] = faces[7, ::-1]
    path = _write_off(tmp_path / "flipped.off", ico.vertices, faces)
    with pytest.warns(RepairWarning, match="1 flipped faces"):
        mesh = load_mesh(path, repair=True)
    assert mesh.is_consistently_oriented
    out = tmp_path / "basis.npz"
    assert main(["basis", str(path), "-k", "4", "-o", str(out)]) == 0
    assert "not consistently oriented; the spectrum is unaffected, --repair orients them" in capsys.readouterr().err
    reference = hamsa.eigenbasis(ico, 4).values
    np.testing.assert_allclose(hamsa.Eigenbasis.load(out).values, reference, rtol=1e-10)
    np.testing.assert_allclose(hamsa.eigenbasis(load_mesh(path), 4).values, reference, rtol=1e-10)
    assert main(["basis", str(path), "-k", "4", "--repair", "-o", str(out)]) == 0
    np.testing.assert_allclose(hamsa.Eigenbasis.load(out).values, reference, rtol=1e-10)
    two = tmp_path / "two.off"
    both = hamsa.TriMesh(
        np.vstack([ico.vertices, ico.vertices + 3]), np.vstack([ico.faces, ico.faces + ico.n_vertices])
    )
    save_mesh(both, two)
    assert main(["basis", str(two), "-k", "4", "-o", str(out)]) == 0
    assert "2 disconnected pieces" in capsys.readouterr().err
    np.testing.assert_allclose(hamsa.Eigenbasis.load(out).values, hamsa.eigenbasis(both, 4).values, atol=1e-10)
    loose = _write_off(tmp_path / "loose.off", np.vstack([ico.vertices, [[5.0, 5.0, 5.0]]]), ico.faces)
    assert main(["basis", str(loose), "-k", "4", "-o", str(tmp_path / "loose.npz")]) == 2  # singular mass: refused
    assert "1 unreferenced vertices" in capsys.readouterr().err and not (tmp_path / "loose.npz").exists()
    # --repair keeps the largest piece (the copy that comes second, equal areas tie to it): the saved basis
    # maps its rows back to the input's vertices
    assert main(["basis", str(two), "-k", "4", "--repair", "-o", str(out)]) == 0
    with np.load(out) as saved:
        np.testing.assert_array_equal(saved["vertex_ids"], ico.n_vertices + np.arange(ico.n_vertices))
    assert hamsa.Eigenbasis.load(out).n == ico.n_vertices


def test_orient_faces_restores_the_outward_faces_and_keeps_the_vertices(ico):
    assert orient_faces(ico) is ico  # already consistent: returned as it is
    faces = ico.faces.copy()
    faces[::7] = faces[::7, ::-1]
    mixed = hamsa.TriMesh(ico.vertices, faces)
    assert not mixed.is_consistently_oriented
    oriented = orient_faces(mixed)
    np.testing.assert_array_equal(oriented.vertices, ico.vertices)
    np.testing.assert_array_equal(oriented.faces, ico.faces)  # every face as it was, outward
    inward = orient_faces(hamsa.TriMesh(ico.vertices, np.vstack([ico.faces[:1], ico.faces[1:, ::-1]])))
    np.testing.assert_array_equal(inward.faces, ico.faces)  # a closed piece is turned outward


def test_a_point_cloud_repair_drops_nan_repeated_and_stray_points_and_keeps_the_way_back(tmp_path, capsys):
    pytest.importorskip("robust_laplacian", reason="point clouds need the [pointcloud] extra")
    from test_pointcloud import _with_strays

    from hamsa.io import load_point_cloud
    from hamsa.repair import repair_point_cloud

    mesh = shapes.humanoid().scaled_to_unit_area()
    points, strays = _with_strays(mesh)
    messy = np.vstack([points[:100], [[np.nan, 0.0, 0.0]], points[100:], points[[5, 7]], [[0.0, np.inf, 1.0]]])
    cloud, kept, report = repair_point_cloud(messy)
    assert (report.non_finite_points, report.repeated_points, report.stray_points) == (2, 2, len(strays))
    assert str(report) == f"repaired: 2 non finite points, 2 repeated points, {len(strays)} stray points"
    np.testing.assert_array_equal(messy[kept], mesh.vertices)  # the humanoid's vertices, in their order
    np.testing.assert_array_equal(cloud.points, mesh.vertices)
    clean, same, nothing = repair_point_cloud(mesh.vertices, neighbors=20)
    assert not nothing.changed and clean.neighbors == 20
    np.testing.assert_array_equal(same, np.arange(mesh.n_vertices))

    path = tmp_path / "scan.xyz"
    np.savetxt(path, messy)
    with pytest.raises(MeshError, match=r"non-finite coordinates .* \(--repair on the command line\) drops them"):
        load_point_cloud(path)
    with pytest.warns(RepairWarning, match="2 repeated points"):
        assert load_point_cloud(path, repair=True).n_vertices == mesh.n_vertices
    assert main(["info", str(path)]) == 0  # described without them, saying so
    assert (
        f"points          {mesh.n_vertices} of {len(messy)} in the file; the lines below leave out 2 non finite "
        f"points, 2 repeated points, {len(strays)} stray points" in capsys.readouterr().out
    )
    np.savetxt(path, points)
    assert main(["info", str(path)]) == 0
    assert f"stray points    {len(strays)} ({strays[0]}, " in capsys.readouterr().out
    np.savetxt(path, messy)
    out = tmp_path / "scan.npz"
    assert main(["basis", str(path), "-k", "6", "--repair", "-o", str(out)]) == 0
    assert "outputs give input vertex ids" in capsys.readouterr().out
    with np.load(out) as saved:
        np.testing.assert_array_equal(saved["vertex_ids"], kept)
    reference = hamsa.eigenbasis(hamsa.PointCloud(mesh.vertices), 6).values
    np.testing.assert_allclose(hamsa.Eigenbasis.load(out).values, reference, rtol=1e-8, atol=1e-10)


def test_a_point_cloud_in_pieces_keeps_its_largest_with_keep_largest_and_the_cli_warns(tmp_path, capsys):
    pytest.importorskip("robust_laplacian", reason="point clouds need the [pointcloud] extra")
    from hamsa.repair import repair_point_cloud

    body = shapes.humanoid().scaled_to_unit_area().vertices
    ball = 0.15 * shapes.sphere(500).vertices + [3.0, 0.0, 0.0]  # area 0.28 beside the body's 1
    points = np.vstack([ball, body])
    cloud, kept, report = repair_point_cloud(points, keep="largest")
    assert report.dropped_pieces == 1 and str(report) == "repaired: 1 dropped pieces"
    np.testing.assert_array_equal(kept, len(ball) + np.arange(len(body)))
    np.testing.assert_array_equal(cloud.points, body)
    assert repair_point_cloud(points)[0].n_components == 2  # keep="all" (the default) keeps both
    path = tmp_path / "two.npy"
    np.save(path, points)
    out = tmp_path / "two.npz"
    assert main(["basis", str(path), "-k", "4", "-o", str(out)]) == 0
    assert f"has 2 disconnected pieces ({len(body)}, {len(ball)} points)" in capsys.readouterr().err
    assert main(["basis", str(path), "-k", "4", "--repair", "-o", str(out)]) == 0
    with np.load(out) as saved:
        np.testing.assert_array_equal(saved["vertex_ids"], kept)
