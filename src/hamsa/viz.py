"""Pictures of functions on meshes and point clouds: off-screen renders (pyvista), interactive HTML (plotly).

Both need the ``[viz]`` extra.

Rendering uses pyvista (VTK) off screen; without a display it selects VTK's EGL window, which works
headless with Debian's ``libegl1 libegl-mesa0 libgl1-mesa-dri``. Curves are left to matplotlib.
"""

from __future__ import annotations

import os

import numpy as np

from hamsa.errors import HamsaError, MissingDependencyError
from hamsa.pointcloud import PointCloud, as_shape

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
    """A ``pyvista.PolyData`` with the mesh's vertices and triangles, or a cloud's points (order kept)."""
    pv = _pyvista()
    mesh = as_shape(mesh)
    if isinstance(mesh, PointCloud):
        return pv.PolyData(mesh.vertices.copy())
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
    mesh : TriMesh, (vertices, faces), PointCloud (drawn as points), or a sequence of them (one per field,
        e.g. noisy copies)
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
    meshes, fields, titles = _panels(mesh, fields, titles, view)
    columns = columns or min(len(fields), 5)
    rows = -(-len(fields) // columns)
    plotter = pv.Plotter(
        off_screen=True,
        shape=(rows, columns),
        window_size=(panel_size[0] * columns, panel_size[1] * rows),
        border=False,
    )
    overall = max(np.nanmax(np.abs(f)) for f in fields)
    everything = (min(np.nanmin(f) for f in fields), max(np.nanmax(f) for f in fields))
    for index, (mesh_i, field, title) in enumerate(zip(meshes, fields, titles)):
        poly = to_polydata(mesh_i)
        if field.shape != (poly.n_points,):
            raise HamsaError(f"field {index} has shape {field.shape}, its mesh has {poly.n_points} vertices")
        poly.point_data["value"] = field
        plotter.subplot(index // columns, index % columns)
        plotter.add_mesh(
            poly,
            scalars="value",
            cmap=cmap,
            clim=_color_range(
                field, symmetric, overall if shared_range else None, everything if shared_range else None
            ),
            scalar_bar_args=dict(_SCALAR_BAR, title=" " * index),
            **({"point_size": 9} if poly.n_cells == poly.n_verts else {"smooth_shading": True}),  # a cloud: dots
        )
        plotter.add_text(title, position="upper_edge", font_size=9, color="black")
        plotter.set_background("white")
        _set_view(plotter, poly.points, view)
        plotter.camera.zoom(zoom)
    try:
        image = plotter.screenshot(None, return_img=True)
    finally:
        plotter.close()
    from PIL import Image

    from hamsa.files import atomic_write

    with atomic_write(path, "wb") as handle:
        Image.fromarray(image).save(handle, format="PNG")
    return image


def _panels(mesh, fields, titles, view):
    """(meshes, fields as float arrays, titles), one per panel, after checking that they fit together."""
    fields = [np.asarray(f, dtype=np.float64) for f in fields]
    if not fields:
        raise HamsaError("no fields to render")
    meshes = list(mesh) if isinstance(mesh, (list, tuple)) and not _is_pair(mesh) else [mesh] * len(fields)
    if len(meshes) != len(fields):
        raise HamsaError(f"{len(meshes)} meshes for {len(fields)} fields")
    if not (isinstance(view, str) and view in VIEWS) and np.shape(view) != (2, 3):
        raise HamsaError(f"view must be one of {VIEWS} or a (direction, up) pair, got {view!r}")
    return meshes, fields, [f"field {i}" for i in range(len(fields))] if titles is None else list(titles)


_SCALAR_BAR = {
    "n_labels": 3,
    "fmt": "%.2g",
    "height": 0.08,
    "width": 0.6,
    "position_x": 0.2,
    "position_y": 0.02,
    "label_font_size": 11,
}


def _color_range(field: np.ndarray, symmetric: bool, shared_bound=None, shared_range=None) -> tuple:
    """The colour limits of one panel: symmetric about 0 or the field's range, or the shared ones."""
    if symmetric:
        bound = np.nanmax(np.abs(field)) if shared_bound is None else shared_bound
        clim = (-bound, bound)
    else:
        clim = (np.nanmin(field), np.nanmax(field)) if shared_range is None else shared_range
    return (clim[0] - 1.0, clim[1] + 1.0) if clim[0] == clim[1] else clim


def _set_view(plotter, points: np.ndarray, view) -> None:
    if not isinstance(view, str):
        _directed_view(plotter, points, *np.asarray(view, dtype=np.float64))
    elif view == "auto":
        _principal_view(plotter, points)
    elif view == "iso":
        plotter.view_isometric()
    else:
        getattr(plotter, f"view_{view}")()


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


def to_html(
    mesh, fields, path, *, titles=None, cmap: str | None = None, symmetric: bool | None = None, title: str = ""
) -> None:
    """Write a self-contained interactive page: rotate / zoom the mesh, switch fields, read the colorbar.

    The page embeds plotly.js (about 4 MB), so it opens offline and can be mailed; WebGL draws it.

    Parameters
    ----------
    mesh : TriMesh, (vertices, faces) or PointCloud (drawn as coloured points)
    fields : (n,) array, a sequence of them, or a dict {name: (n,) array}; one button per field
    path : str or Path of the .html file (written atomically)
    titles : names of the fields (when ``fields`` is not a dict)
    cmap : a plotly colorscale name ("Viridis", "RdBu", "Inferno", ...); default per field: a diverging
        "RdBu" for a field of both signs (an eigenfunction), "Viridis" for one of one sign (a potential)
    symmetric : color range symmetric about 0; default per field: for those of both signs
    title : the page's heading
    """
    go = _plotly()
    from hamsa.files import atomic_write

    mesh = as_shape(mesh)
    titles, fields = _named_fields(mesh, fields, titles)

    def style(field):
        signed = bool(field.min() < 0 < field.max())
        centred = signed if symmetric is None else symmetric
        if centred:
            bound = float(np.abs(field).max()) or 1.0
            low, high = -bound, bound
        else:
            low, high = float(field.min()), float(field.max())
            low, high = (low, high) if high > low else (low - 1.0, high + 1.0)
        return {"cmin": low, "cmax": high, "colorscale": cmap or ("RdBu_r" if signed else "Viridis")}

    first = style(fields[0])
    colorbar = {"title": {"text": titles[0]}}
    if isinstance(mesh, PointCloud):
        trace = _points_trace(go, mesh, marker={"size": 2, "color": fields[0], "colorbar": colorbar, **first})
        prefix, values = "marker.", "marker.color"
    else:
        trace = _mesh_trace(go, mesh, intensity=fields[0], intensitymode="vertex", colorbar=colorbar, **first)
        prefix, values = "", "intensity"
    figure = go.Figure(trace)
    buttons = []
    for name, field in zip(titles, fields):
        restyle = {values: [field], f"{prefix}colorbar.title.text": name}
        restyle |= {f"{prefix}{key}": [value] if key == "colorscale" else value for key, value in style(field).items()}
        buttons.append({"label": name, "method": "restyle", "args": [restyle]})
    figure.update_layout(
        title=title,
        scene=_SCENE,
        updatemenus=[{"buttons": buttons, "direction": "down", "x": 0.0, "y": 1.0, "xanchor": "left"}]
        if len(fields) > 1 else [],
        margin={"l": 0, "r": 0, "t": 40, "b": 0},
    )  # fmt: skip
    with atomic_write(path, "w") as handle:
        handle.write(figure.to_html(include_plotlyjs=True, full_html=True))


def map_to_html(source, target, map_source_to_target, path, *, title: str = "") -> None:
    """Write a self-contained page with the two shapes side by side, the target coloured by its position
    (red, green, blue = its x, y, z scaled to [0, 1]) and each source vertex by the colour of its image:
    a correct map shows the same colours at corresponding places, a mirror or a swap shows at a glance.
    Source vertices mapped to -1 (unknown) are grey.

    Parameters
    ----------
    source, target : TriMesh, (vertices, faces) or PointCloud
    map_source_to_target : (n_source,) target vertex ids (-1: none)
    path : the .html file (written atomically; plotly.js embedded, opens offline)
    """
    go = _plotly()
    from plotly.subplots import make_subplots

    from hamsa.files import atomic_write

    source, target = as_shape(source), as_shape(target)
    mapping = np.asarray(map_source_to_target)
    if mapping.shape != (source.n_vertices,) or not np.issubdtype(mapping.dtype, np.integer):
        raise HamsaError(
            f"the map must be ({source.n_vertices},) integer target ids, got {mapping.dtype} {mapping.shape}"
        )
    if mapping.size and (mapping.min() < -1 or mapping.max() >= target.n_vertices):
        raise HamsaError(f"the map holds ids outside -1..{target.n_vertices - 1} (target vertices)")
    low, high = target.vertices.min(axis=0), target.vertices.max(axis=0)
    rgb = (target.vertices - low) / np.where(high > low, high - low, 1.0)
    pulled = np.where(mapping[:, None] >= 0, rgb[np.maximum(mapping, 0)], 0.6)
    figure = make_subplots(rows=1, cols=2, specs=[[{"type": "scene"}, {"type": "scene"}]],
                           subplot_titles=("source (colours of its images)", "target"))  # fmt: skip
    for column, (shape, colors) in enumerate(((source, pulled), (target, rgb)), 1):
        css = [f"rgb({r},{g},{b})" for r, g, b in np.round(255 * colors).astype(int)]
        if isinstance(shape, PointCloud):
            trace = _points_trace(go, shape, marker={"size": 2, "color": css})
        else:
            trace = _mesh_trace(go, shape, vertexcolor=css)
        figure.add_trace(trace, row=1, col=column)
    figure.update_layout(title=title, scene=_SCENE, scene2=_SCENE, margin={"l": 0, "r": 0, "t": 60, "b": 0})
    with atomic_write(path, "w") as handle:
        handle.write(figure.to_html(include_plotlyjs=True, full_html=True))


_SCENE = {"aspectmode": "data", "xaxis": {"visible": False}, "yaxis": {"visible": False},
          "zaxis": {"visible": False}, "camera": {"eye": {"x": 1.5, "y": 1.5, "z": 1.2}}}  # fmt: skip


def _plotly():
    try:
        import plotly.graph_objects as go
    except ImportError:
        raise MissingDependencyError("interactive views need plotly: pip install 'hamsa[viz]'") from None
    return go


def _named_fields(mesh, fields, titles) -> tuple[list[str], list[np.ndarray]]:
    """(titles, fields) from a dict, a sequence or one array, each field checked to be finite (n,)."""
    if isinstance(fields, dict):
        titles, fields = list(fields), list(fields.values())
    elif np.ndim(fields) == 1:
        fields = [fields]
    fields = [np.asarray(f, dtype=np.float64) for f in fields]
    titles = [f"field {i}" for i in range(len(fields))] if titles is None else [str(t) for t in titles]
    if not fields or len(titles) != len(fields):
        raise HamsaError(f"{len(fields)} fields and {len(titles)} titles: give one title per field")
    for name, field in zip(titles, fields):
        if field.shape != (mesh.n_vertices,) or not np.all(np.isfinite(field)):
            raise HamsaError(f"field '{name}' must be a finite ({mesh.n_vertices},) array, got shape {field.shape}")
    return titles, fields


def _mesh_trace(go, mesh, **style):
    x, y, z = mesh.vertices.T
    i, j, k = mesh.faces.T
    lighting = {"ambient": 0.5, "diffuse": 0.7, "specular": 0.1}
    return go.Mesh3d(x=x, y=y, z=z, i=i, j=j, k=k, flatshading=False, lighting=lighting, **style)


def _points_trace(go, cloud, marker):
    x, y, z = cloud.vertices.T
    return go.Scatter3d(x=x, y=y, z=z, mode="markers", marker=marker)
