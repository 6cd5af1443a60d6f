"""Shared fixtures: built-in meshes, and the real meshes of ../shared/data (tests marked `data`)."""

from __future__ import annotations

import os
import tempfile
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


_RENDERING: list = []


def require_rendering() -> None:
    """Skip the calling test, with the reason, when pyvista cannot render off screen here."""
    pytest.importorskip("pyvista", reason="rendering needs the [viz] extra: pip install 'hamsa[viz]'")
    if not _RENDERING:
        from hamsa import viz

        try:
            mesh = shapes.icosphere(1)
            with tempfile.TemporaryDirectory() as folder:
                viz.render_fields(mesh, [mesh.vertices[:, 0]], Path(folder) / "probe.png")
            _RENDERING.append(None)
        except Exception as exc:  # no EGL/OpenGL here: say why
            _RENDERING.append(
                f"off-screen rendering is unavailable ({type(exc).__name__}: {exc}); "
                "install Debian's libegl1 libegl-mesa0 libgl1-mesa-dri"
            )
    if _RENDERING[0]:
        pytest.skip(_RENDERING[0])


def chromium() -> str:
    """The headless Chromium binary, or skip the calling test saying how to get one."""
    import shutil

    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        pytest.skip("headless Chromium is not installed (make test installs Debian's chromium)")
    return browser


def screenshot(page: Path, shot: Path) -> np.ndarray:
    """Open ``page`` in headless Chromium (WebGL in software) and return its 800 x 600 screenshot, RGB ints."""
    import subprocess

    from PIL import Image

    flags = "--headless --no-sandbox --disable-gpu --enable-unsafe-swiftshader --disable-background-networking"
    command = [chromium(), *flags.split(), "--no-first-run", "--window-size=800,600", "--virtual-time-budget=8000"]
    subprocess.run([*command, f"--screenshot={shot}", page.as_uri()], capture_output=True, timeout=120, check=True)
    return np.asarray(Image.open(shot).convert("RGB")).astype(int)


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
