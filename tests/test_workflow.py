"""A researcher's first afternoon, through the command line only, on a real SCAPE pair: repair and basis with
its index map, a Hamiltonian match with a geodesic potential given on the command line, scored against the
ground truth, and the viewer pages of the saved basis and of the map — each number equal to the Python API's
on the same inputs."""

import json

import numpy as np
import pytest

import hamsa
from hamsa.cli import main

from conftest import DATA, screenshot

pytestmark = pytest.mark.data


def test_repair_basis_match_score_and_view_through_the_cli_equal_the_python_api(tmp_path, capsys):
    from hamsa import matching
    from hamsa.evaluation import map_scores
    from hamsa.io import read_mesh_arrays
    from hamsa.potentials import from_spec
    from hamsa.repair import repair_mesh

    source, target = (str(DATA / f"scape/meshes/mesh{i:03d}.off.gz") for i in (0, 1))
    landmark = int(np.loadtxt(DATA / "scape/kim_landmarks/scape.pid", dtype=np.int64)[0, 0])
    # 1. mesh000 has a non-manifold vertex: taken as it is with a warning, split by --repair (ids recorded)
    assert main(["basis", source, "-k", "20", "-q", "-o", str(tmp_path / "plain.npz")]) == 0
    assert "non-manifold vertices" in capsys.readouterr().err
    assert main(["basis", source, "-k", "20", "--repair", "-q", "-o", str(tmp_path / "basis.npz")]) == 0
    saved = hamsa.Eigenbasis.load(tmp_path / "basis.npz")
    repaired, kept, report = repair_mesh(*read_mesh_arrays(source), keep="largest")
    assert report.changed and saved.n == repaired.n_vertices == 12501
    np.testing.assert_array_equal(saved.vertex_ids, kept)
    np.testing.assert_allclose(saved.values, hamsa.eigenbasis(repaired, 20).values, rtol=1e-9)
    # 2. a Hamiltonian fmap with the landmark's geodesic potential on both shapes, scored by the Kim protocol
    spec = f"50*geodesic:{landmark}"
    command = ["match", source, target, "--repair", "--method", "fmap", "-k", "30", "--source-potential", spec,
               "--target-potential", spec, "--truth", "identity", "--points", "500", "-q",
               "-o", str(tmp_path / "map.npy")]  # fmt: skip
    assert main(command) == 0
    capsys.readouterr()
    scores = json.loads((tmp_path / "map.scores.json").read_text())
    meshes, bases, ids = [], [], []
    for path in (source, target):
        mesh, kept, _ = repair_mesh(*read_mesh_arrays(path), keep="largest")
        meshes.append(mesh.scaled_to_unit_area())
        bases.append(hamsa.eigenbasis(meshes[-1], 30, from_spec(mesh, spec, kept)))
        ids.append(kept)
    mapping = matching.match(*bases, "fmap", meshes=meshes)
    first_copy = {int(v): i for i, v in reversed(list(enumerate(ids[1])))}
    truth = np.array([first_copy.get(int(v), -1) for v in ids[0]])  # identity in input ids, carried to the repairs
    expected = map_scores(meshes[1], mapping, truth, points=500)
    for key in ("auc", "within_0.05", "mean_error", "curve"):
        np.testing.assert_allclose(scores[key], expected[key], rtol=1e-12)
    assert scores["auc"] > 0.6, scores["auc"]  # measured 0.90
    # 3. the viewer: the saved basis (of the repaired mesh) and the map in colours, both opened in a browser
    assert (
        main(["view", source, "--repair", "--basis", str(tmp_path / "basis.npz"), "-o", str(tmp_path / "b.html")]) == 0
    )
    assert (
        main(["view", source, "--map", str(tmp_path / "map.npy"), "--target", target, "-o", str(tmp_path / "m.html")])
        == 0
    )
    for page in ("b.html", "m.html"):
        pixels = screenshot(tmp_path / page, tmp_path / f"{page}.png")
        assert ((pixels.max(axis=2) - pixels.min(axis=2)) > 60).mean() > 0.02, page
