"""Shared fixtures: built-in meshes, and the real meshes of ../shared/data (tests marked `data`)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

import hamsa
from hamsa import shapes

DATA = Path(os.environ.get("HAMSA_DATA", Path(__file__).resolve().parents[1].parent / "shared" / "data"))


def pytest_collection_modifyitems(config, items):
    if DATA.is_dir():
        return
    skip = pytest.mark.skip(reason=f"real meshes not found at {DATA} (set HAMSA_DATA to the shared/data folder)")
    for item in items:
        if "data" in item.keywords:
            item.add_marker(skip)


def data_mesh(relative: str) -> hamsa.TriMesh:
    return hamsa.load_mesh(DATA / relative)


@pytest.fixture(scope="session")
def sphere_5k() -> hamsa.TriMesh:
    return shapes.sphere(5000)


@pytest.fixture(scope="session")
def small_mesh() -> hamsa.TriMesh:
    """A small irregular closed mesh (a perturbed sphere) with obtuse triangles."""
    mesh = shapes.sphere(400)
    rng = np.random.default_rng(7)
    return hamsa.TriMesh(mesh.vertices * (1 + 0.15 * rng.standard_normal((400, 1))), mesh.faces)
