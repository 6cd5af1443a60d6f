"""Pictures of functions on meshes: a grid of off-screen renders with titles and colorbars (``[viz]`` extra).

Rendering uses pyvista (VTK) off screen; without a display it selects VTK's EGL window, which works
headless with Debian's ``libegl1 libegl-mesa0 libgl1-mesa-dri``. Curves are left to matplotlib.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from hamsa.errors import HamsaError, MissingDependencyError
from hamsa.mesh import as_trimesh

VIEWS = ("auto", "xy", "xz", "yz", "yx", "zx", "zy", "iso")


def _pyvista():
    if not os.environ.get("DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    try:
        import pyvista
    except ImportError:
        raise MissingDependencyError("rendering needs pyvista: pip install 'hamsa[viz]'") from None
    pyvista.OFF_SCREEN = True
    return pyvista


def to_polydata(mesh):
    """A ``pyvista.PolyData`` with the mesh's vertices and triangles (vertex order kept)."""
    pv = _pyvista()
    mesh = as_trimesh(mesh)
    cells = np.hstack([np.full((mesh.n_faces, 1), 3), mesh.faces]).ravel()
    return pv.PolyData(mesh.vertices.copy(), cells)


def render_fields(
    mesh,
    fields,
    path,
    *,
    titles=None,
    cmap: str = "viridis",
    symmetric: bool = False,
    shared_range: bool = False,
    columns: int | None = None,
    panel_size: tuple[int, int] = (320, 320),
    view="auto",
    zoom: float = 1.0,
) -> np.ndarray:
    """Render per-vertex scalar fields on a mesh as a grid of panels and save a PNG (atomically).

    Parameters
    ----------
    mesh : TriMesh, (vertices, faces), or a sequence of them (one per field, e.g. noisy copies)
    fields : sequence of (n,) arrays
    path : str or Path of the PNG
    titles : sequence of str, optional (one per field)
    cmap : matplotlib colormap name
    symmetric : bool
        Color range symmetric about 0 (for eigenfunctions: white = 0 with "RdBu_r").
    shared_range : bool
        One color range for all panels instead of one per panel.
    columns : int, optional
        Panels per row (default: all in one row up to 5).
    panel_size : (width, height) in pixels
    view : "auto" (default: look along the shape's thinnest principal axis with +z up, which shows a
        standing or T-posed body from the front and an animal from the side), "xy", "xz", "yz", "yx", "zx",
        "zy", "iso", or
        a pair (direction, up) of 3-vectors: the camera looks from ``center + direction``
    zoom : float

    Returns
    -------
    (H, W, 3) uint8 image (also written to ``path``).
    """
    pv = _pyvista()
    fields = [np.asarray(f, dtype=np.float64) for f in fields]
    if not fields:
        raise HamsaError("no fields to render")
    meshes = list(mesh) if isinstance(mesh, (list, tuple)) and not _is_pair(mesh) else [mesh] * len(fields)
    if len(meshes) != len(fields):
        raise HamsaError(f"{len(meshes)} meshes for {len(fields)} fields")
    if not (isinstance(view, str) and view in VIEWS) and np.shape(view) != (2, 3):
        raise HamsaError(f"view must be one of {VIEWS} or a (direction, up) pair, got {view!r}")
    titles = [f"field {i}" for i in range(len(fields))] if titles is None else list(titles)
    columns = columns or min(len(fields), 5)
    rows = -(-len(fields) // columns)
    plotter = pv.Plotter(
        off_screen=True,
        shape=(rows, columns),
        window_size=(panel_size[0] * columns, panel_size[1] * rows),
        border=False,
    )
    overall = max(np.nanmax(np.abs(f)) for f in fields)
    low_all, high_all = min(np.nanmin(f) for f in fields), max(np.nanmax(f) for f in fields)
    for index, (mesh_i, field, title) in enumerate(zip(meshes, fields, titles)):
        poly = to_polydata(mesh_i)
        if field.shape != (poly.n_points,):
            raise HamsaError(f"field {index} has shape {field.shape}, its mesh has {poly.n_points} vertices")
        if symmetric:
            bound = overall if shared_range else np.nanmax(np.abs(field))
            clim = (-bound, bound)
        else:
            clim = (low_all, high_all) if shared_range else (np.nanmin(field), np.nanmax(field))
        if clim[0] == clim[1]:
            clim = (clim[0] - 1.0, clim[1] + 1.0)
        poly.point_data["value"] = field
        plotter.subplot(index // columns, index % columns)
        plotter.add_mesh(
            poly,
            scalars="value",
            cmap=cmap,
            clim=clim,
            smooth_shading=True,
            scalar_bar_args={
                "title": " " * index,
                "n_labels": 3,
                "fmt": "%.2g",
                "height": 0.08,
                "width": 0.6,
                "position_x": 0.2,
                "position_y": 0.02,
                "label_font_size": 11,
            },
        )
        plotter.add_text(title, position="upper_edge", font_size=9, color="black")
        plotter.set_background("white")
        if not isinstance(view, str):
            _directed_view(plotter, poly.points, *np.asarray(view, dtype=np.float64))
        elif view == "auto":
            _principal_view(plotter, poly.points)
        elif view == "iso":
            plotter.view_isometric()
        else:
            getattr(plotter, f"view_{view}")()
        plotter.camera.zoom(zoom)
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".png", dir=path.parent if str(path.parent) else ".")
    os.close(fd)
    try:
        image = plotter.screenshot(tmp, return_img=True)
        os.replace(tmp, path)
    finally:
        plotter.close()
        if os.path.exists(tmp):
            os.unlink(tmp)
    return image


def _principal_view(plotter, points: np.ndarray) -> None:
    """Look along the thinnest principal axis; +z (TOSCA's up) is up unless it is that axis."""
    _, _, axes = np.linalg.svd(points - points.mean(axis=0), full_matrices=False)  # longest .. thinnest
    direction = axes[2] if axes[2][np.argmax(np.abs(axes[2]))] > 0 else -axes[2]
    z = np.array([0.0, 0.0, 1.0])
    up = z - (z @ direction) * direction
    if np.linalg.norm(up) < 0.3:
        up = axes[0]
    _directed_view(plotter, points, direction, up)


def _directed_view(plotter, points: np.ndarray, direction: np.ndarray, up: np.ndarray) -> None:
    center = points.mean(axis=0)
    distance = 3.0 * np.linalg.norm(points.max(axis=0) - points.min(axis=0))
    eye = center + distance * direction / np.linalg.norm(direction)
    plotter.camera_position = [tuple(eye), tuple(center), tuple(up)]
    plotter.reset_camera()


def _is_pair(value) -> bool:
    return (
        len(value) == 2 and isinstance(value[0], np.ndarray) and isinstance(value[1], np.ndarray) and value[1].ndim == 2
    )
