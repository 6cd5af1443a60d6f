import numpy as np
import pytest

from hamsa import shapes

from conftest import require_rendering, screenshot


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


def test_interactive_page_shows_the_mesh_in_a_headless_browser(tmp_path):
    """Open the page as a person would (Chromium, WebGL in software) and look at the screenshot."""
    import hamsa
    from hamsa.viz import to_html

    pytest.importorskip("plotly", reason="interactive views need the [viz] extra")
    mesh = shapes.humanoid(spacing=0.04)
    basis = hamsa.eigenbasis(mesh, 4)
    page = tmp_path / "view.html"
    to_html(mesh, {f"phi{i}": basis.vectors[:, i] for i in (1, 2, 3)}, page, symmetric=True, cmap="RdBu")
    html = page.read_text()
    assert "phi1" in html and "phi3" in html and "<script src=" not in html  # buttons; plotly.js embedded
    pixels = screenshot(page, tmp_path / "shot.png")
    middle = pixels[100:500, 150:650]
    saturated = (middle.max(axis=2) - middle.min(axis=2)) > 60  # red/blue shading of the field, not UI gray
    assert saturated.mean() > 0.05, f"only {saturated.mean():.1%} colored pixels: the mesh is not visible"


def test_a_map_page_shows_both_shapes_in_the_colours_of_the_correspondence(tmp_path):
    """hamsa view MESH --map MAP --target TARGET: the identity between two poses paints both humanoids in
    the target's position colours (seen in a headless browser: both halves coloured)."""
    pytest.importorskip("plotly", reason="interactive views need the [viz] extra")
    import hamsa
    from hamsa.cli import main

    rest, walk = shapes.humanoid("rest", spacing=0.05), shapes.humanoid("walk", spacing=0.05)
    hamsa.save_mesh(rest, tmp_path / "rest.off")
    hamsa.save_mesh(walk, tmp_path / "walk.off")
    np.save(tmp_path / "map.npy", np.arange(rest.n_vertices))
    page = tmp_path / "map.html"
    command = ["view", str(tmp_path / "rest.off"), "--map", str(tmp_path / "map.npy"), "--target"]
    assert main(command + [str(tmp_path / "walk.off"), "-o", str(page)]) == 0
    html = page.read_text()
    assert "scene2" in html and "vertexcolor" in html and "source (colours of its images)" in html
    pixels = screenshot(page, tmp_path / "shot.png")
    colored = (pixels.max(axis=2) - pixels.min(axis=2)) > 60
    left, right = colored[80:560, :400].mean(), colored[80:560, 400:].mean()
    assert left > 0.02 and right > 0.02, (left, right)
    np.save(tmp_path / "bad.npy", np.full(rest.n_vertices, walk.n_vertices))
    assert main(command[:3] + [str(tmp_path / "bad.npy"), "--target", str(tmp_path / "walk.off"), "-o",
                               str(tmp_path / "bad.html")]) == 2  # fmt: skip


def test_view_shows_a_saved_basis_fields_and_modes_labelled_as_in_python(tmp_path, capsys):
    """A saved LBO basis is shown without its constant first eigenfunction, each labelled by its column of
    basis.vectors; fields take their file's name; signed fields get a diverging scale centred at 0, a
    potential a sequential one."""
    pytest.importorskip("plotly", reason="interactive views need the [viz] extra")
    import json

    import hamsa
    from hamsa.cli import main

    mesh = shapes.capsule(n_around=16)
    path = tmp_path / "capsule.off"
    hamsa.save_mesh(mesh, path)
    assert main(["basis", str(path), "-k", "5", "-o", str(tmp_path / "b.npz")]) == 0
    page = tmp_path / "v.html"
    assert main(["view", str(path), "--basis", str(tmp_path / "b.npz"), "-o", str(page)]) == 0
    html = page.read_text()
    basis = hamsa.Eigenbasis.load(tmp_path / "b.npz")
    assert f"psi 1 (E = {basis.values[1]:.4g})" in html and "psi 4 (E =" in html and "psi 0 (E" not in html
    np.save(tmp_path / "height.npy", mesh.vertices[:, 2] - mesh.vertices[:, 2].min())
    np.save(tmp_path / "pair.npy", np.c_[mesh.vertices[:, 0], mesh.vertices[:, 1]])
    command = ["view", str(path), "--field", str(tmp_path / "height.npy"), str(tmp_path / "pair.npy")]
    assert main(command + ["-o", str(page)]) == 0
    html = page.read_text()
    assert "height" in html and "pair[:, 0]" in html and "pair[:, 1]" in html
    start = html.rindex('"updatemenus":') + len('"updatemenus":')  # the figure's layout, after plotly.js
    menus = json.JSONDecoder().raw_decode(html[start:])[0]
    restyles = {b["label"]: b["args"][0] for b in menus[0]["buttons"]}
    assert restyles["height"]["colorscale"] == ["Viridis"] and restyles["height"]["cmin"] == 0
    signed = restyles["pair[:, 0]"]
    assert signed["colorscale"] == ["RdBu_r"] and signed["cmin"] == -signed["cmax"]
    assert main(["modes", str(path), "-k", "2", "--mu", "100", "-q", "-o", str(tmp_path / "m.npz")]) == 0
    assert main(["view", str(path), "--modes", str(tmp_path / "m.npz"), "-o", str(page)]) == 0
    assert "mode 0" in page.read_text() and "mode 1" in page.read_text()
    with pytest.raises(SystemExit, match="2"):  # argparse: one thing to show at a time
        main(["view", str(path), "--basis", str(tmp_path / "b.npz"), "--field", str(tmp_path / "height.npy"),
              "-o", str(page)])  # fmt: skip
    assert main(["view", str(path), "--basis", str(tmp_path / "pair.npy"), "-o", str(page)]) == 2


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
