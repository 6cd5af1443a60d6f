"""hamsa: Hamiltonian spectral shape analysis.

The Hamiltonian ``H = -Laplacian + V`` on triangle meshes and point clouds, discretized with linear finite elements as
``(W + A diag(V)) psi = E A psi``, and the spectral tools built on its eigenbasis. ``import hamsa`` gives
the library's submodules (``hamsa.diffusion``, ``hamsa.matching``, ...); the paper's reproduction is
``hamsa.paper`` (imported on demand).
"""

import importlib

__version__ = "0.5.0"

_SUBMODULES = (
    "cmm", "compression", "datasets", "diffusion", "errors", "evaluation", "files", "geodesic", "io", "matching",
    "mesh", "nodal", "noise", "operators", "optimize", "paper", "pointcloud", "potentials", "repair", "runtime",
    "shapes", "theory", "viz",
)  # fmt: skip
_NAMES = {
    "Eigenbasis": "hamsa.eigen",
    "eigenbasis": "hamsa.eigen",
    "generalized_eigsh": "hamsa.eigen",
    "HamsaError": "hamsa.errors",
    "MeshError": "hamsa.errors",
    "MissingDependencyError": "hamsa.errors",
    "PotentialError": "hamsa.errors",
    "SolverError": "hamsa.errors",
    "load_mesh": "hamsa.io",
    "load_point_cloud": "hamsa.io",
    "load_shape": "hamsa.io",
    "save_mesh": "hamsa.io",
    "save_point_cloud": "hamsa.io",
    "TriMesh": "hamsa.mesh",
    "PointCloud": "hamsa.pointcloud",
    "hamiltonian": "hamsa.operators",
    "mass_matrix": "hamsa.operators",
    "stiffness_matrix": "hamsa.operators",
    "optimize_potential": "hamsa.optimize",
    "show_config": "hamsa.runtime",
}


def __getattr__(name: str):
    # Submodules and the top-level names load on first use: ``import hamsa`` stays cheap (the command-line
    # tool starts fast and under its Ctrl-C handler), and ``hamsa.diffusion`` works without an import.
    if name in _SUBMODULES:
        value = importlib.import_module(f"hamsa.{name}")
    elif name in _NAMES:
        value = getattr(importlib.import_module(_NAMES[name]), name)
    else:
        raise AttributeError(f"module 'hamsa' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


__all__ = [
    "Eigenbasis",
    "cmm",
    "compression",
    "datasets",
    "diffusion",
    "errors",
    "evaluation",
    "files",
    "geodesic",
    "io",
    "matching",
    "mesh",
    "nodal",
    "noise",
    "operators",
    "optimize",
    "pointcloud",
    "potentials",
    "repair",
    "runtime",
    "theory",
    "viz",
    "HamsaError",
    "MeshError",
    "MissingDependencyError",
    "PointCloud",
    "PotentialError",
    "SolverError",
    "TriMesh",
    "eigenbasis",
    "generalized_eigsh",
    "hamiltonian",
    "load_mesh",
    "load_point_cloud",
    "load_shape",
    "mass_matrix",
    "optimize_potential",
    "save_mesh",
    "save_point_cloud",
    "shapes",
    "show_config",
    "stiffness_matrix",
]
