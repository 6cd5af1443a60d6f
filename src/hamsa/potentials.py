"""Potentials V on a mesh: functions mesh -> (n,) float64 arrays, in units of 1/length^2.

Only the step potential lives here so far (the paper's section 2.3 and Fig. 2); the geometric,
geodesic, eigenfunction-sum and texture potentials build on the same conventions.
"""

from __future__ import annotations

import numpy as np

from hamsa.errors import PotentialError
from hamsa.mesh import as_trimesh


def step(mesh, region, height: float, threshold: float | None = None) -> np.ndarray:
    """Finite step potential: ``V = height`` on a region of the surface, 0 elsewhere.

    Parameters
    ----------
    mesh : TriMesh or (vertices, faces)
    region : (n,) bool array, or (n,) float array with ``threshold``
        The vertices where V = height: a mask, or the vertices whose field value is > threshold.
    height : float
        V0, in units of 1/length^2 (comparable to the eigenvalues: modes with E < V0 are
        concentrated where V = 0, paper section 2.3 and Fig. 2).
    threshold : float, optional
        Required when ``region`` is a scalar field.

    Returns
    -------
    (n,) float64
    """
    mesh = as_trimesh(mesh)
    field = np.asarray(region)
    if field.shape != (mesh.n_vertices,):
        raise PotentialError(f"region has shape {field.shape}, the mesh has {mesh.n_vertices} vertices")
    if field.dtype == bool:
        if threshold is not None:
            raise PotentialError("threshold is only used with a scalar-field region, not a mask")
        mask = field
    else:
        if threshold is None:
            raise PotentialError("a scalar-field region needs a threshold (V = height where field > threshold)")
        mask = np.asarray(field, dtype=np.float64) > threshold
    if not np.isfinite(height):
        raise PotentialError(f"step height must be finite, got {height}")
    return np.where(mask, float(height), 0.0)
