"""hamsa: Hamiltonian spectral shape analysis.

The Hamiltonian ``H = -Laplacian + V`` on triangle meshes, discretized with linear finite elements as
``(W + A diag(V)) psi = E A psi``, and the spectral tools built on its eigenbasis.
"""

from hamsa import shapes
from hamsa.eigen import Eigenbasis, eigenbasis, generalized_eigsh
from hamsa.errors import HamsaError, MeshError, MissingDependencyError, PotentialError, SolverError
from hamsa.io import load_mesh, save_mesh
from hamsa.mesh import TriMesh
from hamsa.operators import hamiltonian, mass_matrix, stiffness_matrix
from hamsa.optimize import optimize_potential

__version__ = "0.1.8"

__all__ = [
    "Eigenbasis",
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
