"""Shape-correspondence datasets (TOSCA, SCAPE, any folder of meshes) and an on-disk eigenbasis cache.

The data are never shipped with hamsa: every loader takes the dataset folder as an argument (laid out as
in the Kim et al. benchmark: ``meshes/*.off(.gz)``, ``kim_landmarks/<class>.pid``, ``symmetry/<class>.sym``).

Ground-truth convention: within a class, vertex i of one shape corresponds to vertex i of every other
(TOSCA's classes and SCAPE are registered this way), so the true map between two shapes of a class is the
identity. Symmetry maps (TOSCA) give, per vertex, the vertex of its left-right partner (0-based here; the
files are 1-based). Evaluation pairs: every shape against the first shape of its class (lowest number).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hamsa.cache import code_fingerprint, content_key
from hamsa.eigen import Eigenbasis, eigenbasis
from hamsa.errors import HamsaError
from hamsa.io import load_mesh
from hamsa.mesh import TriMesh, as_trimesh

_MESH_SUFFIXES = (".off", ".off.gz", ".obj", ".obj.gz", ".ply", ".ply.gz")


@dataclass(frozen=True)
class Dataset:
    """A collection of meshes with classes, landmarks and symmetry maps.

    Attributes
    ----------
    name : str
    shapes : dict shape name -> mesh file path (sorted by class, then number)
    classes : dict shape name -> class name
    landmarks : dict class name -> (L,) 0-based vertex ids (Kim et al. landmarks), when available
    symmetry : dict class name -> path of the symmetry file, when available
    """

    name: str
    shapes: dict
    classes: dict
    landmarks: dict = field(default_factory=dict)
    symmetry: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.shapes)

    def load(
        self, shape: str, drop_unreferenced: bool = True, largest_component: bool = False
    ) -> tuple[TriMesh, np.ndarray]:
        """(mesh, kept): the mesh, without unreferenced vertices unless asked (or only its largest connected
        component), and the kept original ids."""
        if shape not in self.shapes:
            raise HamsaError(f"dataset {self.name!r} has no shape {shape!r}")
        mesh = load_mesh(self.shapes[shape])
        if largest_component:
            return mesh.largest_component()
        if drop_unreferenced:
            return mesh.without_unreferenced()
        return mesh, np.arange(mesh.n_vertices)

    def symmetry_map(self, class_name: str) -> np.ndarray:
        """(n,) 0-based vertex ids of each vertex's left-right partner in the class."""
        if class_name not in self.symmetry:
            raise HamsaError(f"dataset {self.name!r} has no symmetry map for class {class_name!r}")
        values = np.loadtxt(self.symmetry[class_name], dtype=np.int64, ndmin=1)
        return values - 1

    def pairs(self) -> list[tuple[str, str]]:
        """(source, target) evaluation pairs: each shape against the first shape of its class."""
        first: dict[str, str] = {}
        for shape, class_name in self.classes.items():
            first.setdefault(class_name, shape)
        return [(first[c], s) for s, c in self.classes.items() if s != first[c]]


def _split_name(name: str) -> tuple[str, int]:
    match = re.fullmatch(r"(.*?)(\d+)", name)
    return (match.group(1), int(match.group(2))) if match else (name, -1)


def _mesh_files(folder: Path) -> dict[str, Path]:
    if not folder.is_dir():
        raise HamsaError(f"no mesh folder at '{folder}'")
    files = {}
    for path in folder.iterdir():
        for suffix in _MESH_SUFFIXES:
            if path.name.endswith(suffix):
                files[path.name[: -len(suffix)]] = path
    if not files:
        raise HamsaError(f"'{folder}' holds no mesh files ({', '.join(_MESH_SUFFIXES)})")
    return files


def load_folder(root, name: str | None = None, class_of=None) -> Dataset:
    """A generic dataset: the meshes of ``root/meshes`` (or ``root``), classes from the names.

    ``class_of(shape_name) -> class`` defaults to the name without its trailing number (``cat10`` -> ``cat``).
    Landmarks ``kim_landmarks/<class>.pid`` (first column, 0-based) and symmetry files
    ``symmetry/<class>.sym`` are picked up when present.
    """
    root = Path(root)
    folder = root / "meshes" if (root / "meshes").is_dir() else root
    files = _mesh_files(folder)
    class_of = class_of or (lambda shape: _split_name(shape)[0])
    ordered = sorted(files, key=lambda s: (class_of(s), _split_name(s)[1], s))
    classes = {s: class_of(s) for s in ordered}
    landmarks, symmetry = {}, {}
    for class_name in sorted(set(classes.values())):
        pid = root / "kim_landmarks" / f"{class_name}.pid"
        if pid.exists():
            landmarks[class_name] = np.loadtxt(pid, dtype=np.int64, ndmin=2)[:, 0]
        sym = root / "symmetry" / f"{class_name}.sym"
        if sym.exists():
            symmetry[class_name] = sym
    return Dataset(name or root.name, {s: files[s] for s in ordered}, classes, landmarks, symmetry)


def load_tosca(root) -> Dataset:
    """TOSCA high-resolution (Bronstein et al. 2008): classes cat, centaur, david, dog, gorilla, horse, michael,
    victoria; identity ground truth within a class; Kim et al. landmarks and symmetry maps where shipped.
    (The gorilla has unreferenced vertices: :meth:`Dataset.load` drops them and returns the kept ids.)"""
    return load_folder(root, "TOSCA")


def load_scape(root) -> Dataset:
    """SCAPE (Anguelov et al. 2005) as in the Kim et al. benchmark: one class, identity ground truth,
    per-mesh faces; pairs are the first mesh (in name order) against the others."""
    dataset = load_folder(root, "SCAPE", class_of=lambda shape: "scape")
    pid = Path(root) / "kim_landmarks" / "scape.pid"
    landmarks = {"scape": np.loadtxt(pid, dtype=np.int64, ndmin=2)[:, 0]} if pid.exists() else {}
    return Dataset(dataset.name, dataset.shapes, dataset.classes, landmarks, dataset.symmetry)


def basis_key(mesh, k: int, potential=None, mass: str = "voronoi") -> str:
    """A hex digest identifying (mesh, potential, k, mass) and the code that solves it
    (:func:`~hamsa.cache.code_fingerprint`): the cache key of :func:`cached_eigenbasis`."""
    mesh = as_trimesh(mesh)
    V = np.zeros(0) if potential is None else np.asarray(potential, dtype=np.float64)
    return content_key(code_fingerprint(), mesh.vertices, mesh.faces, V, {"k": int(k), "mass": mass})


def cached_eigenbasis(mesh, k: int, cache_dir, potential=None, mass: str = "voronoi") -> Eigenbasis:
    """:func:`hamsa.eigenbasis`, stored in ``cache_dir`` under a hash of its inputs and read back when present.

    Entries are written atomically; an entry that cannot be read, or whose stored key does not match, is
    recomputed (so an interrupted run never leaves a corrupt cache behind it).
    """
    mesh = as_trimesh(mesh)
    folder = Path(cache_dir)
    folder.mkdir(parents=True, exist_ok=True)
    key = basis_key(mesh, k, potential, mass)
    path = folder / f"{key[:32]}.npz"
    if path.exists():
        try:
            basis, extra = Eigenbasis.load_with_extra(path)
            stored = extra.get("cache_key")
            if stored is not None and str(stored) == key and basis.k == k and basis.n == mesh.n_vertices:
                return basis
        except HamsaError:
            pass
        os.unlink(path)
    basis = eigenbasis(mesh, k, potential, mass)
    basis.save(path, extra={"cache_key": np.array(key)})
    return basis
