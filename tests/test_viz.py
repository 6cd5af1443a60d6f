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
