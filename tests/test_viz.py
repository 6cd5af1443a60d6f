import numpy as np
import pytest

from hamsa import shapes

from conftest import require_rendering


@pytest.fixture(autouse=True)
def _rendering():
    require_rendering()


def test_render_fields_writes_a_non_blank_png(tmp_path):
    from hamsa import viz

    mesh = shapes.capsule(n_around=24)
    path = tmp_path / "fields.png"
    image = viz.render_fields(
        mesh,
        [mesh.vertices[:, 2], mesh.vertices[:, 0]],
        path,
        titles=["z", "x"],
        cmap="RdBu_r",
        symmetric=True,
        view="xz",
    )
    assert path.exists() and image.shape == (320, 640, 3)
    # not blank: many distinct colors, and the two panels differ
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 50
    assert np.abs(image[:, :320].astype(int) - image[:, 320:].astype(int)).mean() > 1
    assert not list(tmp_path.glob(".*.png"))


def test_render_refuses_mismatched_fields(tmp_path):
    from hamsa import HamsaError, viz

    with pytest.raises(HamsaError, match="shape"):
        viz.render_fields(shapes.icosphere(1), [np.zeros(5)], tmp_path / "x.png")


def _chromium():
    import shutil

    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        pytest.skip("headless Chromium is not installed (make test installs Debian's chromium)")
    return browser


def test_interactive_page_shows_the_mesh_in_a_headless_browser(tmp_path):
    """Open the page as a person would (Chromium, WebGL in software) and look at the screenshot."""
    import subprocess

    from PIL import Image

    import hamsa
    from hamsa.viz import to_html

    pytest.importorskip("plotly", reason="interactive views need the [viz] extra")
    mesh = shapes.humanoid(spacing=0.04)
    basis = hamsa.eigenbasis(mesh, 4)
    page = tmp_path / "view.html"
    to_html(mesh, {f"phi{i}": basis.vectors[:, i] for i in (1, 2, 3)}, page, symmetric=True, cmap="RdBu")
    html = page.read_text()
    assert "phi1" in html and "phi3" in html and "<script src=" not in html  # buttons; plotly.js embedded
    shot = tmp_path / "shot.png"
    flags = "--headless --no-sandbox --disable-gpu --enable-unsafe-swiftshader --disable-background-networking"
    command = [_chromium(), *flags.split(), "--no-first-run", "--window-size=800,600", "--virtual-time-budget=8000"]
    subprocess.run([*command, f"--screenshot={shot}", page.as_uri()], capture_output=True, timeout=120, check=True)
    pixels = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    middle = pixels[100:500, 150:650]
    saturated = (middle.max(axis=2) - middle.min(axis=2)) > 60  # red/blue shading of the field, not UI gray
    assert saturated.mean() > 0.05, f"only {saturated.mean():.1%} colored pixels: the mesh is not visible"


def test_interactive_page_rejects_bad_fields(tmp_path):
    pytest.importorskip("plotly", reason="interactive views need the [viz] extra")
    from hamsa.errors import HamsaError
    from hamsa.viz import to_html

    mesh = shapes.icosphere(1)
    with pytest.raises(HamsaError, match="finite"):
        to_html(mesh, np.zeros(3), tmp_path / "x.html")
    with pytest.raises(HamsaError, match="finite"):
        to_html(mesh, np.full(mesh.n_vertices, np.nan), tmp_path / "x.html")
    assert not list(tmp_path.iterdir())
