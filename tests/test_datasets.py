import numpy as np
import pytest

import hamsa
from hamsa import HamsaError, shapes
from hamsa.datasets import basis_key, cached_eigenbasis, load_folder, load_scape, load_tosca

from conftest import DATA


def test_generic_folder_classes_pairs_and_landmarks(tmp_path):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "kim_landmarks").mkdir()
    for name in ("ball0", "ball1", "ball10", "ring2", "ring0"):
        hamsa.save_mesh(shapes.icosphere(1), tmp_path / "meshes" / f"{name}.off.gz")
    (tmp_path / "kim_landmarks" / "ball.pid").write_text("  3 0 0 0\n  7 0 0 0\n")
    dataset = load_folder(tmp_path)
    assert list(dataset.shapes) == ["ball0", "ball1", "ball10", "ring0", "ring2"]  # numeric order
    assert dataset.pairs() == [("ball0", "ball1"), ("ball0", "ball10"), ("ring0", "ring2")]
    assert dataset.landmarks["ball"].tolist() == [3, 7]
    mesh, kept = dataset.load("ring2")
    assert mesh.n_vertices == 42 and kept.tolist() == list(range(42))
    with pytest.raises(HamsaError, match="no shape"):
        dataset.load("cube0")
    with pytest.raises(HamsaError, match="no mesh folder|no mesh files"):
        load_folder(tmp_path / "kim_landmarks")


def test_cache_reads_back_and_recomputes_corrupt_entries(tmp_path):
    mesh = shapes.icosphere(2)
    first = cached_eigenbasis(mesh, 6, tmp_path)
    files = list(tmp_path.glob("*.npz"))
    assert len(files) == 1
    again = cached_eigenbasis(mesh, 6, tmp_path)
    np.testing.assert_array_equal(again.vectors, first.vectors)
    files[0].write_bytes(b"corrupt")  # an interrupted or damaged entry is recomputed, not trusted
    redone = cached_eigenbasis(mesh, 6, tmp_path)
    np.testing.assert_allclose(redone.values, first.values)
    assert basis_key(mesh, 6) != basis_key(mesh, 7) != basis_key(mesh, 6, np.ones(mesh.n_vertices))


@pytest.mark.data
def test_tosca_and_scape_layouts():
    tosca = load_tosca(DATA / "tosca_hires")
    assert len(tosca) == 77 and len(set(tosca.classes.values())) == 8
    assert all(tosca.classes[a] == tosca.classes[b] for a, b in tosca.pairs())
    cat = tosca.symmetry_map("cat")
    assert np.array_equal(np.sort(cat), np.arange(len(cat)))  # an exact involution for the cat
    assert np.array_equal(cat[cat], np.arange(len(cat)))
    assert len(tosca.landmarks["centaur"]) == 46
    gorilla, kept = tosca.load("gorilla1")
    assert gorilla.n_vertices == 41395 - 1328 and len(kept) == gorilla.n_vertices
    scape = load_scape(DATA / "scape")
    assert len(scape) == 67 and scape.pairs()[0] == ("mesh000", "mesh001")
    assert len(scape.landmarks["scape"]) == 36
