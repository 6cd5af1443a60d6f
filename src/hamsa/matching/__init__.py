"""Shape matching with any eigenbasis, the LBO's or a Hamiltonian's, in layers.

- :mod:`~hamsa.matching.nearest`: exact nearest neighbours; descriptor matching.
- :mod:`~hamsa.matching.icp`: the one ICP kernel (nearest neighbours, then orthogonal Procrustes).
- :mod:`~hamsa.matching.functional`: functional maps (Ovsjanikov et al. 2012), point map <-> C, ICP, ZoomOut.
- :mod:`~hamsa.matching.signs`: eigenfunction signs across shapes; intrinsic-symmetry sign patterns.
- :mod:`~hamsa.matching.icskm`: iterative closest spectral kernel maps (Shtern & Kimmel 2014).
- :mod:`~hamsa.matching.sgfe`: the spectral gradient fields embedding (Shtern & Kimmel 2015).
- :mod:`~hamsa.matching.pipeline`: :func:`match`, one call from two eigenbases to a point map.

Directions are explicit: a point map is ``map_source_to_target`` (for each source vertex, a target
vertex), and a functional map C (k_s, k_t) pulls target functions back to the source.
"""

from hamsa.matching.functional import (
    functional_from_map,
    functional_map,
    icp_refine,
    map_from_functional,
    multiplication_operator,
    offdiagonal_energy,
    orientation_operator,
    orientation_ratio,
    zoomout,
)
from hamsa.matching.icskm import match_icskm
from hamsa.matching.nearest import match_descriptors, nearest_rows
from hamsa.matching.pipeline import METHODS, match
from hamsa.matching.sgfe import match_sgfe, spectral_gradient_fields
from hamsa.matching.signs import (
    intrinsic_symmetry_signs,
    matching_potentials,
    resolve_signs,
    resolve_signs_without_truth,
)

__all__ = [
    "METHODS",
    "functional_from_map",
    "functional_map",
    "icp_refine",
    "intrinsic_symmetry_signs",
    "map_from_functional",
    "match",
    "match_descriptors",
    "match_icskm",
    "match_sgfe",
    "matching_potentials",
    "multiplication_operator",
    "nearest_rows",
    "offdiagonal_energy",
    "orientation_operator",
    "orientation_ratio",
    "resolve_signs",
    "resolve_signs_without_truth",
    "spectral_gradient_fields",
    "zoomout",
]
