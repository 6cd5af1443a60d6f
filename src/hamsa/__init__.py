"""hamsa: Hamiltonian spectral shape analysis.

The Hamiltonian ``H = -Laplacian + V`` on triangle meshes, discretized with linear finite elements as
``(W + A diag(V)) psi = E A psi``, and the spectral tools built on its eigenbasis. ``import hamsa`` gives
the library's submodules (``hamsa.diffusion``, ``hamsa.matching``, ...); the paper's reproduction is
``hamsa.paper`` (imported on demand).
"""

from hamsa import (
    cmm,
    compression,
    datasets,
    diffusion,
    errors,
    evaluation,
    geodesic,
    io,
    matching,
    mesh,
    nodal,
    noise,
    operators,
    optimize,
    potentials,
    repair,
    shapes,
    theory,
    viz,
)
from hamsa.eigen import Eigenbasis, eigenbasis, generalized_eigsh
from hamsa.errors import HamsaError, MeshError, MissingDependencyError, PotentialError, SolverError
from hamsa.io import load_mesh, save_mesh
from hamsa.mesh import TriMesh
from hamsa.operators import hamiltonian, mass_matrix, stiffness_matrix
from hamsa.optimize import optimize_potential

__version__ = "0.2.0"

__all__ = [
    "Eigenbasis",
    "cmm",
    "compression",
    "datasets",
    "diffusion",
    "errors",
    "evaluation",
    "geodesic",
    "io",
    "matching",
    "mesh",
    "nodal",
    "noise",
    "operators",
    "optimize",
    "potentials",
    "repair",
    "theory",
    "viz",
    "HamsaError",
    "MeshError",
    "MissingDependencyError",
    "PotentialError",
    "SolverError",
    "TriMesh",
    "eigenbasis",
    "generalized_eigsh",
    "hamiltonian",
    "load_mesh",
    "mass_matrix",
    "optimize_potential",
    "save_mesh",
    "shapes",
    "stiffness_matrix",
]
