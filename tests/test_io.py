import gzip
import os
import struct

import numpy as np
import pytest

import hamsa
from hamsa import MeshError, shapes

from conftest import DATA


@pytest.fixture
def mesh():
    # a shuffled vertex order: the loaders must keep it exactly
    base = shapes.icosphere(2)
    order = np.random.default_rng(3).permutation(base.n_vertices)
    inverse = np.argsort(order)
    return hamsa.TriMesh(base.vertices[order], inverse[base.faces])


@pytest.mark.parametrize("suffix", [".off", ".obj", ".ply", ".off.gz", ".obj.gz", ".ply.gz"])
def test_round_trip_keeps_vertex_order_and_values(tmp_path, mesh, suffix):
    path = tmp_path / f"m{suffix}"
    hamsa.save_mesh(mesh, path)
    back = hamsa.load_mesh(path)
    np.testing.assert_array_equal(back.vertices, mesh.vertices)
    np.testing.assert_array_equal(back.faces, mesh.faces)
    assert not [p for p in os.listdir(tmp_path) if p.endswith(".tmp")]


def test_stl_round_trip_merges_corners_in_first_appearance_order(tmp_path, mesh):
    path = tmp_path / "m.stl"
    hamsa.save_mesh(mesh, path)
    back = hamsa.load_mesh(path)
    assert back.n_vertices == mesh.n_vertices and back.n_faces == mesh.n_faces
    # same triangles (float32 coordinates), vertices numbered by first appearance
    np.testing.assert_allclose(back.vertices[back.faces], mesh.vertices[mesh.faces], atol=1e-6)


def test_ascii_stl_and_ascii_ply_and_obj_variants(tmp_path):
    (tmp_path / "a.stl").write_text(
        "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\n"
        "facet normal 0 0 1\nouter loop\nvertex 1 0 0\nvertex 1 1 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n"
    )
    stl = hamsa.load_mesh(tmp_path / "a.stl")
    assert stl.n_vertices == 4 and stl.faces.tolist() == [[0, 1, 2], [1, 3, 2]]
    (tmp_path / "a.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "property uchar red\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0 255\n1 0 0 255\n0 1 0 255\n3 0 1 2\n"
    )
    assert hamsa.load_mesh(tmp_path / "a.ply").faces.tolist() == [[0, 1, 2]]
    (tmp_path / "a.obj").write_text("# c\nv 0 0 0\nv 1 0 0\nvn 0 0 1\nv 0 1 0\nf 1//1 2//1 -1//1\n")
    assert hamsa.load_mesh(tmp_path / "a.obj").faces.tolist() == [[0, 1, 2]]
    (tmp_path / "b.off").write_text("OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 255 0 0\n")
    assert hamsa.load_mesh(tmp_path / "b.off").n_faces == 1


@pytest.mark.parametrize(
    "name, content, message",
    [
        ("empty.off", b"", "empty"),
        ("garbage.off", b"\x00\x01\x02garbage", "OFF"),
        ("counts.off", b"OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "promises 4 vertices"),
        ("line.off", b"OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n2 0 1\n", "a face needs at least 3"),
        ("short.off", b"OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2\n", "fewer than its 4 vertex indices"),
        ("quad.obj", b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 7\n", "face 0 references vertex 6"),
        ("bowtie.obj", b"v 0 0 0\nv 2 0 0\nv 0 2 0\nv 2 2 0\nv 1 3 0\nf 1 2 3 4 5\n", "crosses itself"),
        ("nan.off", b"OFF\n3 1 0\n0 0 nan\n1 0 0\n0 1 0\n3 0 1 2\n", "non-finite"),
        ("range.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "references vertex 8"),
        (
            "trunc.ply",
            b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty double x\n"
            b"property double y\nproperty double z\nelement face 1\nproperty list uchar int vertex_indices\n"
            b"end_header\n\x00\x00",
            "truncated",
        ),
        ("garbage.stl", b"\x07" * 30, "STL"),
        ("bad.off.gz", b"not gzip at all", "not a valid gzip"),
        ("mesh.xyz", b"1 2 3", "cannot tell the mesh format"),
    ],
)
def test_bad_files_raise_mesh_error_naming_the_file(tmp_path, name, content, message):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(MeshError, match=message) as info:
        hamsa.load_mesh(path)
    if not name.endswith(".xyz"):
        assert name in str(info.value)


def test_missing_file_and_missing_folder(tmp_path, mesh):
    with pytest.raises(MeshError, match="no such file"):
        hamsa.load_mesh(tmp_path / "nope.off")
    with pytest.raises(hamsa.errors.FileAccessError, match="does not exist"):
        hamsa.save_mesh(mesh, tmp_path / "no" / "dir.off")


def test_failed_write_leaves_no_file(tmp_path, mesh, monkeypatch):
    import hamsa.io as hio

    def boom(_mesh):
        raise RuntimeError("disk full")

    monkeypatch.setitem(hio.__dict__, "_write_off", boom)
    with pytest.raises(RuntimeError):
        hamsa.save_mesh(mesh, tmp_path / "x.off")
    assert os.listdir(tmp_path) == []


@pytest.mark.data
def test_reads_the_gzipped_datasets_in_file_order():
    path = DATA / "tosca_hires" / "meshes" / "cat0.off.gz"
    mesh = hamsa.load_mesh(path)
    assert (mesh.n_vertices, mesh.n_faces) == (27894, 55712)
    with gzip.open(path, "rt") as handle:
        lines = [line for line in handle.read().splitlines() if line.strip()]
    first = np.array(lines[2].split(), float)  # after "OFF" and the counts line
    np.testing.assert_array_equal(mesh.vertices[0], first)
    gorilla = hamsa.load_mesh(DATA / "tosca_hires" / "meshes" / "gorilla1.off.gz")
    assert len(gorilla.unreferenced_vertices) == 1328
    hand = hamsa.load_mesh(DATA / "classic" / "hand_6k.off")
    assert (hand.n_vertices, hand.n_faces) == (6338, 12672)


def _coloured_files(folder, mesh, colours):
    """The mesh with 8-bit vertex colours as a binary PLY cloud (float32, uchar), an ASCII PLY mesh, a COFF
    mesh (0-255 with alpha) and an OBJ mesh ('v x y z r g b' in [0, 1], gzipped)."""
    n, faces = mesh.n_vertices, mesh.faces
    rgb = np.round(colours * 255).astype(np.uint8)
    files = {}
    header = "ply\nformat {}\nelement vertex {}\n" + "".join(
        f"property {t} {c}\n" for t, c in (("float", "x"), ("float", "y"), ("float", "z"))
    )
    colour_props = "property uchar red\nproperty uchar green\nproperty uchar blue\n"
    table = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("r", "u1"), ("g", "u1"), ("b", "u1")])
    table["x"], table["y"], table["z"] = mesh.vertices.T
    table["r"], table["g"], table["b"] = rgb.T
    files["cloud.ply"] = (header.format("binary_little_endian 1.0", n) + colour_props + "end_header\n").encode()
    files["cloud.ply"] += table.tobytes()
    rows = [f"{x!r} {y!r} {z!r} {r} {g} {b}" for (x, y, z), (r, g, b) in zip(mesh.vertices.tolist(), rgb.tolist())]
    triangles = [f"3 {a} {b} {c}" for a, b, c in faces.tolist()]
    files["mesh.ply"] = "\n".join(
        [header.format("ascii 1.0", n).replace("float", "double") + colour_props
         + f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header", *rows, *triangles]
    )  # fmt: skip
    files["mesh.off"] = "\n".join([f"COFF\n{n} {len(faces)} 0", *[row + " 255" for row in rows], *triangles])
    obj = [f"v {x!r} {y!r} {z!r} {r / 255} {g / 255} {b / 255}" for (x, y, z), (r, g, b) in
           zip(mesh.vertices.tolist(), rgb.tolist())]  # fmt: skip
    files["mesh.obj.gz"] = gzip.compress(
        ("\n".join(obj + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces.tolist()])).encode()
    )
    paths = []
    for name, content in files.items():
        path = folder / name
        path.write_bytes(content if isinstance(content, bytes) else content.encode())
        paths.append(path)
    return paths, rgb / 255.0


def test_vertex_colours_are_read_from_ply_coff_and_obj_and_make_the_texture_potential(tmp_path, mesh):
    from hamsa.cli import main
    from hamsa.io import read_vertex_colors
    from hamsa.potentials import from_spec, from_vertex_colors

    colours = np.random.default_rng(4).random((mesh.n_vertices, 3))
    paths, expected = _coloured_files(tmp_path, mesh, colours)
    for path in paths:
        np.testing.assert_array_equal(read_vertex_colors(path), expected, err_msg=path.name)
        shape = hamsa.load_shape(path) if path.name != "cloud.ply" else hamsa.load_point_cloud(path)
        np.testing.assert_allclose(shape.vertices, mesh.vertices, atol=1e-6 if path.name == "cloud.ply" else 0)
    luminance = expected @ [0.2126, 0.7152, 0.0722]
    np.testing.assert_allclose(from_spec(mesh, f"50*texture:{paths[2]}"), 50 * luminance)
    np.testing.assert_allclose(from_vertex_colors(mesh, read_vertex_colors(paths[0])), luminance)
    # a repaired copy takes the colours of the vertices it kept
    kept = np.arange(0, mesh.n_vertices, 2)
    cloud = hamsa.PointCloud(mesh.vertices[kept])
    np.testing.assert_allclose(from_spec(cloud, f"texture:{paths[1]}", vertex_ids=kept), luminance[kept])
    out = tmp_path / "basis.npz"
    assert main(["basis", str(paths[1]), "-k", "4", "--potential", f"20*texture:{paths[1]}", "-o", str(out)]) == 0
    np.testing.assert_allclose(hamsa.Eigenbasis.load(out).potential, 20 * luminance)

    plain = tmp_path / "plain.off"
    hamsa.save_mesh(mesh, plain)
    with pytest.raises(MeshError, match="plain.off.*no vertex colours"):
        read_vertex_colors(plain)
    with pytest.raises(hamsa.errors.PotentialError, match="has 162 vertex colours, the shape 100 vertices"):
        from_spec(hamsa.PointCloud(mesh.vertices[:100]), f"texture:{paths[1]}")
    bright = tmp_path / "bright.obj"
    bright.write_text("v 0 0 0 300 0 0\nv 1 0 0 0 0 0\nv 0 1 0 0 0 0\nf 1 2 3\n")
    with pytest.raises(MeshError, match="outside"):
        read_vertex_colors(bright)


def _polygon_grid():
    """A 5 x 5 grid of unit cells in the plane z = 0 (area 25) written as mixed polygons: quads, two triangles,
    a hexagon with straight corners and an L-shaped (non-convex) heptagon whose fan from its first corner
    would fold over: (vertices, polygons)."""
    xs, ys = np.meshgrid(np.arange(6.0), np.arange(6.0))
    vertices = np.c_[xs.ravel(), ys.ravel(), np.zeros(36)]

    def at(i, j):
        return j * 6 + i

    def cell(i, j):
        return [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)]

    polygons = [cell(i, j) for j in range(2) for i in range(5)]
    polygons.append([at(0, 2), at(1, 2), at(2, 2), at(2, 3), at(1, 3), at(0, 3)])  # cells (0, 2), (1, 2)
    polygons += [[at(2, 2), at(3, 2), at(3, 3)], [at(2, 2), at(3, 3), at(2, 3)]]  # cell (2, 2)
    polygons += [cell(3, 2), cell(4, 2), cell(2, 3), cell(3, 3), cell(4, 3)]
    # cells (0, 3), (1, 3), (0, 4), starting at the corner next to the reflex one (1, 4)
    polygons.append([at(2, 4), at(1, 4), at(1, 5), at(0, 5), at(0, 3), at(1, 3), at(2, 3)])
    polygons += [cell(i, 4) for i in range(1, 5)]
    return vertices, polygons


def _write_polygons(path, vertices, polygons, kind):
    if kind == "off":
        lines = ["OFF", f"{len(vertices)} {len(polygons)} 0"] + [f"{x:g} {y:g} {z:g}" for x, y, z in vertices]
        path.write_text("\n".join(lines + [" ".join(map(str, [len(p), *p])) for p in polygons]) + "\n")
    elif kind == "obj":
        lines = [f"v {x:g} {y:g} {z:g}" for x, y, z in vertices]
        path.write_text("\n".join(lines + ["f " + " ".join(f"{i + 1}/{i + 1}" for i in p) for p in polygons]) + "\n")
    else:  # binary PLY, a face property after the list
        header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\nproperty float x\n"
                  f"property float y\nproperty float z\nelement face {len(polygons)}\n"
                  "property list uchar int vertex_indices\nproperty uchar flags\nend_header\n")  # fmt: skip
        body = vertices.astype("<f4").tobytes()
        for p in polygons:
            body += np.uint8(len(p)).tobytes() + np.asarray(p, dtype="<i4").tobytes() + b"\x07"
        path.write_bytes(header.encode() + body)


@pytest.mark.parametrize("kind", ["off", "obj", "ply"])
def test_polygon_faces_are_cut_into_triangles_that_tile_each_polygon(tmp_path, kind):
    """Quads, a pentagon and a non-convex hexagon mixed with triangles: the vertices stay as written, each
    polygon of c corners gives c - 2 triangles in file order, every triangle faces the polygons' way (+z)
    and together they cover the grid's area exactly (a fan of the L-shaped hexagon would fold over it)."""
    vertices, polygons = _polygon_grid()
    path = tmp_path / f"grid.{kind}"
    _write_polygons(path, vertices, polygons, kind)
    mesh = hamsa.load_mesh(path)
    np.testing.assert_allclose(mesh.vertices, vertices)
    assert mesh.n_faces == sum(len(p) - 2 for p in polygons)
    a, b, c = (mesh.vertices[mesh.faces[:, i]] for i in range(3))
    normals = np.cross(b - a, c - a)
    assert np.all(normals[:, 2] > 0)
    assert np.isclose(normals[:, 2].sum() / 2, 25.0) and np.isclose(mesh.area, 25.0)
    assert mesh.is_consistently_oriented and mesh.boundary_loops and len(mesh.boundary_loops) == 1
    owner = np.repeat(np.arange(len(polygons)), [len(p) - 2 for p in polygons])  # triangles in polygon order
    assert all(set(face) <= set(polygons[o]) for face, o in zip(mesh.faces.tolist(), owner))


def _ply_header(form: str, vertices: int, elements: str) -> bytes:
    return (f"ply\nformat {form} 1.0\nelement vertex {vertices}\nproperty float x\nproperty float y\n"
            f"property float z\n{elements}end_header\n").encode()  # fmt: skip


def test_ply_faces_with_texture_lists_flags_and_other_elements(tmp_path):
    """Faces as photogrammetry and MeshLab write them: a flag before the index list and per-corner texture
    coordinates after it, then an edge element and one with lists, binary (triangles; triangles and quads,
    read record by record) and ASCII: the mesh is the one written."""
    sphere = hamsa.shapes.icosphere(2)
    vertices, faces = sphere.vertices.astype("<f4"), sphere.faces
    face = ("element face {}\nproperty uchar flags\nproperty list uchar int vertex_indices\n"
            "property list uchar float texcoord\n")  # fmt: skip
    others = ("element edge 1\nproperty int vertex1\nproperty int vertex2\n"
              "element material 1\nproperty list uchar float shine\n")  # fmt: skip
    elements = face.format(len(faces)) + others
    body = vertices.tobytes()
    for triangle in faces:
        body += b"\x01\x03" + triangle.astype("<i4").tobytes() + b"\x06" + np.zeros(6, "<f4").tobytes()
    body += np.array([0, 1], "<i4").tobytes() + b"\x02" + np.ones(2, "<f4").tobytes()
    (tmp_path / "b.ply").write_bytes(_ply_header("binary_little_endian", len(vertices), elements) + body)
    text = "\n".join(" ".join(map(repr, v.tolist())) for v in vertices) + "\n"
    text += "".join(f"1 3 {a} {b} {c} 6 0 0 0 0 0 0\n" for a, b, c in faces) + "0 1\n2 1.0 1.0\n"
    (tmp_path / "a.ply").write_bytes(_ply_header("ascii", len(vertices), elements) + text.encode())
    for name in ("b.ply", "a.ply"):
        mesh = hamsa.load_mesh(tmp_path / name)
        np.testing.assert_array_equal(mesh.faces, faces, err_msg=name)
        np.testing.assert_allclose(mesh.vertices, vertices, err_msg=name)
    grid, polygons = _polygon_grid()
    quads = [p for p in polygons if len(p) in (3, 4)]
    body = grid.astype("<f4").tobytes()
    for p in quads:
        body += b"\x01" + bytes([len(p)]) + np.asarray(p, "<i4").tobytes()
        body += bytes([2 * len(p)]) + np.zeros(2 * len(p), "<f4").tobytes()
    (tmp_path / "q.ply").write_bytes(_ply_header("binary_little_endian", len(grid), face.format(len(quads))) + body)
    assert hamsa.load_mesh(tmp_path / "q.ply", repair=False).n_faces == sum(len(p) - 2 for p in quads)


def test_ply_triangle_strips_are_read(tmp_path):
    """A 5 x 5 grid of squares written as PLY triangle strips, one per row, in one list separated by -1
    (ASCII) and one list per row with a repeated corner (binary): 50 triangles all facing one way, area 25."""
    x, y = np.meshgrid(np.arange(6.0), np.arange(6.0))
    grid = np.stack([x.ravel(), y.ravel(), np.zeros(36)], axis=1)
    strips = [[i + 6 * (row + up) for i in range(6) for up in (0, 1)] for row in range(5)]
    joined = [i for strip in strips for i in [*strip, -1]][:-1]
    element = "element tristrips {}\nproperty list int int vertex_indices\n"
    text = "\n".join(" ".join(map(str, v)) for v in grid.tolist()) + f"\n{len(joined)} {' '.join(map(str, joined))}\n"
    (tmp_path / "a.ply").write_bytes(_ply_header("ascii", 36, element.format(1)) + text.encode())
    body = grid.astype("<f4").tobytes()
    for strip in strips:
        strip = [*strip, strip[-1]]  # a repeated corner: a triangle of no area, left out
        body += np.array([len(strip), *strip], "<i4").tobytes()
    (tmp_path / "b.ply").write_bytes(_ply_header("binary_little_endian", 36, element.format(5)) + body)
    for name in ("a.ply", "b.ply"):
        mesh = hamsa.load_mesh(tmp_path / name)
        a, b, c = (mesh.vertices[mesh.faces[:, i]] for i in range(3))
        normals = np.cross(b - a, c - a)[:, 2]
        assert mesh.n_faces == 50 and (np.all(normals > 0) or np.all(normals < 0)), name
        assert np.isclose(mesh.area, 25.0) and mesh.is_consistently_oriented, name


def test_text_files_with_a_byte_order_mark_read_as_without(tmp_path, mesh):
    """Windows editors start UTF-8 text with a byte-order mark: the OBJ reader took that first line for no
    vertex (so every face pointed one vertex off), OFF refused its header, XYZ its first number."""
    from hamsa.files import read_text

    np.savetxt(tmp_path / "p.xyz", mesh.vertices)
    for name in ("m.obj", "m.off", "p.xyz"):
        if name != "p.xyz":
            hamsa.save_mesh(mesh, tmp_path / name)
        (tmp_path / f"bom_{name}").write_bytes(b"\xef\xbb\xbf" + (tmp_path / name).read_bytes())
        plain, marked = (hamsa.io.read_shape_arrays(tmp_path / f) for f in (name, f"bom_{name}"))
        np.testing.assert_array_equal(marked[0], plain[0], err_msg=name)
        assert (marked[1] is None and plain[1] is None) or np.array_equal(marked[1], plain[1]), name
    assert read_text(tmp_path / "bom_p.xyz") == read_text(tmp_path / "p.xyz")


def test_a_mesh_files_normals_are_read_only_when_asked(tmp_path, mesh):
    """read_vertex_normals gives a mesh file's per-vertex normals (OBJ vn, NOFF, PLY nx ny nz); loading the mesh
    does not parse them, so a normal line the mesh does not need (two numbers) does not refuse the mesh."""
    normals = mesh.vertex_normals
    hamsa.save_mesh(mesh, tmp_path / "m.obj")
    vn = "".join(f"vn {x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in normals)
    (tmp_path / "n.obj").write_text((tmp_path / "m.obj").read_text() + vn)
    (tmp_path / "bad.obj").write_text((tmp_path / "m.obj").read_text() + vn.rsplit(" ", 1)[0] + "\n")  # last: 2
    off_rows = "".join(" ".join(f"{x:.17g}" for x in row) + "\n" for row in np.hstack([mesh.vertices, normals]))
    faces = "".join(f"3 {a} {b} {c}\n" for a, b, c in mesh.faces)
    (tmp_path / "n.off").write_text(f"NOFF\n{mesh.n_vertices} {mesh.n_faces} 0\n" + off_rows + faces)
    for name in ("n.obj", "n.off"):
        np.testing.assert_allclose(hamsa.io.read_vertex_normals(tmp_path / name), normals, atol=1e-15, err_msg=name)
        vertices, read_faces, given = hamsa.io.read_shape_arrays(tmp_path / name)
        assert given is None and np.array_equal(read_faces, mesh.faces), name
    np.testing.assert_array_equal(hamsa.io.load_shape(tmp_path / "bad.obj").faces, mesh.faces)
    with pytest.raises(MeshError, match="normal .* has 2 values"):
        hamsa.io.read_vertex_normals(tmp_path / "bad.obj")


def test_obj_negative_indices_count_back_from_their_face_line(tmp_path, mesh):
    """Objects written one after another with relative (negative) indices: each face refers to the vertices
    defined before it (the reader counted back from the end of the file: every face on the last object)."""
    n = mesh.n_vertices
    blocks = []
    for shift in (0.0, 5.0):
        blocks += [f"o piece{shift:g}"] + [f"v {x:.17g} {y:.17g} {z + shift:.17g}" for x, y, z in mesh.vertices]
        blocks += [f"f {a - n} {b - n} {c - n}" for a, b, c in mesh.faces]
    (tmp_path / "relative.obj").write_text("\n".join(blocks) + "\n")
    read = hamsa.load_mesh(tmp_path / "relative.obj", manifold=False)
    np.testing.assert_array_equal(read.faces, np.vstack([mesh.faces, mesh.faces + n]))
    assert read.vertex_components[0] == 2
    (tmp_path / "before.obj").write_text("v 0 0 0\nv 1 0 0\nf -3 -2 -1\nv 0 1 0\n")
    with pytest.raises(MeshError, match="face 0 has a negative index reaching back before the first vertex"):
        hamsa.load_mesh(tmp_path / "before.obj")


def test_obj_lines_separated_by_tabs(tmp_path, mesh):
    """'v\t1\t2\t3' is a vertex line as 'v 1 2 3' is (the reader looked for 'v ' and skipped it)."""
    hamsa.save_mesh(mesh, tmp_path / "m.obj")
    text = (tmp_path / "m.obj").read_text().replace("v ", "v\t").replace("f ", "f\t")
    (tmp_path / "tab.obj").write_text(text)
    tabbed = hamsa.load_mesh(tmp_path / "tab.obj")
    np.testing.assert_array_equal(tabbed.vertices, mesh.vertices)
    np.testing.assert_array_equal(tabbed.faces, mesh.faces)


def test_text_point_files_as_scanners_and_cloudcompare_write_them(tmp_path):
    """A PTS file's point counts (one block or several; a wrong count refused), a first line naming the
    columns (CloudCompare's '//X Y Z Nx Ny Nz', 'x y z', columns in any order in a ';' separated .csv): the
    points, and the named normals, are the ones written."""
    points = shapes.icosphere(2).vertices
    normals = points / np.linalg.norm(points, axis=1, keepdims=True)
    rows = [f"{x} {y} {z} 100 20 30 40" for x, y, z in points]  # x y z intensity r g b
    files = {
        "one.pts": [str(len(rows)), *rows],
        "two.pts": ["100", *rows[:100], str(len(rows) - 100), *rows[100:]],
        "cc.txt": ["//X Y Z Nx Ny Nz", *(" ".join(map(str, [*p, *q])) for p, q in zip(points, normals))],
        "named.xyz": ["x y z", *(" ".join(map(str, p)) for p in points)],
        "columns.csv": ["r;g;b;X;Y;Z", *(";".join(map(str, [1, 2, 3, *p])) for p in points)],
    }
    for name, lines in files.items():
        (tmp_path / name).write_text("\n".join(lines) + "\n")
        read, _, given = hamsa.io.read_shape_arrays(tmp_path / name)
        np.testing.assert_array_equal(read, points, err_msg=name)
        if name == "cc.txt":
            np.testing.assert_array_equal(given, normals)
        else:
            assert given is None, name
    (tmp_path / "comma.csv").write_text("1,5;2,25;0,75\n" * 20)  # decimal commas: refused, not split
    with pytest.raises(MeshError, match="could not convert string to float: '1,5'"):
        hamsa.io.read_point_array(tmp_path / "comma.csv")
    (tmp_path / "short.pts").write_text("\n".join([str(len(rows) + 5), *rows]))
    with pytest.raises(MeshError, match="block at data line 1 promises 167 points and has fewer"):
        hamsa.io.read_point_array(tmp_path / "short.pts")


def test_point_clouds_are_written_and_read_back_exactly(tmp_path):
    """save_point_cloud: the points to the last bit in every point format (gzipped too), and a cloud's given
    normals in all but .npy (estimated ones are not written)."""
    from hamsa.io import save_point_cloud

    points = shapes.icosphere(2).vertices * [1.0, 2.0, 3.0] + 1e-3
    normals = points + np.random.default_rng(0).normal(scale=0.1, size=points.shape)  # outward, not exact
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    given = hamsa.PointCloud(points, normals=normals)
    for name in ("a.xyz", "a.txt.gz", "a.pts", "a.csv", "a.ply", "a.ply.gz", "a.npy"):
        save_point_cloud(given, tmp_path / name)
        read, _, read_normals = hamsa.io.read_shape_arrays(tmp_path / name)
        np.testing.assert_array_equal(read, points, err_msg=name)
        if name == "a.npy":
            assert read_normals is None
        else:
            np.testing.assert_allclose(read_normals, normals, atol=1e-15, err_msg=name)
    save_point_cloud(hamsa.PointCloud(points), tmp_path / "b.xyz")
    assert hamsa.io.read_vertex_normals(tmp_path / "b.xyz") is None
    with pytest.raises(MeshError, match="cannot tell the point-file format"):
        save_point_cloud(given, tmp_path / "a.off")


def _lzf_literals(data: bytes) -> bytes:
    """``data`` LZF-encoded as literal runs only (a valid stream; the reader's back-references are tested
    on their own)."""
    return b"".join(bytes([len(data[i : i + 32]) - 1]) + data[i : i + 32] for i in range(0, len(data), 32))


def test_pcd_point_clouds_as_pcl_writes_them(tmp_path):
    """PCL's .pcd, ascii, binary and binary_compressed (fields stored one after another), with normals, a
    curvature and an rgb field around them: the points and normals written (float32), NaN rows kept."""
    from hamsa.io import _lzf_decompress

    points = shapes.icosphere(2).vertices.astype("<f4")
    points[7] = np.nan  # an organized cloud's invalid point
    normals = (points / np.linalg.norm(points, axis=1, keepdims=True)).astype("<f4")
    rgb = np.arange(len(points), dtype="<u4")
    head = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb normal_x normal_y normal_z curvature\nSIZE 4 4 4 4 4 4 4 4\n"
            f"TYPE F F F U F F F F\nCOUNT 1 1 1 1 1 1 1 1\nWIDTH {len(points)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n"
            f"POINTS {len(points)}\nDATA ")  # fmt: skip
    columns = [*points.T, rgb, *normals.T, np.zeros(len(points), "<f4")]
    record = np.dtype([(f"c{i}", c.dtype) for i, c in enumerate(columns)])
    rows = np.empty(len(points), record)
    for i, c in enumerate(columns):
        rows[f"c{i}"] = c
    text = "\n".join(
        " ".join(repr(float(v)) if j != 3 else str(int(v)) for j, v in enumerate(r)) for r in rows.tolist()
    )
    by_field = b"".join(c.tobytes() for c in columns)
    files = {
        "a.pcd": (head + "ascii\n" + text + "\n").encode(),
        "b.pcd": (head + "binary\n").encode() + rows.tobytes(),
        "c.pcd": (head + "binary_compressed\n").encode()
        + struct.pack("<II", len(_lzf_literals(by_field)), len(by_field))
        + _lzf_literals(by_field),
    }
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
        read, _, read_normals = hamsa.io.read_shape_arrays(tmp_path / name)
        np.testing.assert_array_equal(read, points.astype(np.float64), err_msg=name)
        np.testing.assert_array_equal(read_normals, normals.astype(np.float64), err_msg=name)
    # literals "ab"; 10 bytes from 2 back (7 << 5, one more length byte 1, offset 1: overlapping what it writes);
    # 3 bytes from 12 back (1 << 5, offset 11)
    assert _lzf_decompress(bytes([1]) + b"ab" + bytes([7 << 5, 1, 1, 1 << 5, 11]), 15) == b"ab" * 6 + b"aba"
    (tmp_path / "d.pcd").write_bytes(files["b.pcd"][:-10])
    with pytest.raises(MeshError, match="shorter than its POINTS"):
        hamsa.io.read_point_array(tmp_path / "d.pcd")
