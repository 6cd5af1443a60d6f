"""One call from two eigenbases to a point map: :func:`match` with any of :data:`METHODS`."""

from __future__ import annotations

import numpy as np

from hamsa.eigen import Eigenbasis
from hamsa.errors import HamsaError
from hamsa.matching.functional import functional_map, icp_refine, zoomout
from hamsa.matching.icskm import match_icskm
from hamsa.matching.nearest import match_descriptors
from hamsa.matching.sgfe import match_sgfe
from hamsa.pointcloud import PointCloud

METHODS = ("hks", "wks", "fmap", "sgfe", "icskm", "icskm_geo")
# the functional map that starts fmap and sgfe is fitted on this many eigenpairs
START_K = 20
# and with this descriptor-commutativity weight (chosen on half of the SCAPE pairs, docs/results/matching.md)
COMMUTATIVITY_WEIGHT = 0.03


def match(
    source: Eigenbasis,
    target: Eigenbasis,
    method: str = "fmap",
    *,
    landmarks=None,
    meshes=None,
    progress=None,
    commutativity_weight: float = COMMUTATIVITY_WEIGHT,
) -> np.ndarray:
    """``map_source_to_target`` (n_s,): for each source vertex, a target vertex, by one of :data:`METHODS`.

    - ``hks`` / ``wks``: nearest neighbours of 50 heat / wave kernel signature columns;
    - ``fmap``: an HKS-fitted functional map on the first 20 eigenpairs (:func:`hks_functional_map`; with
      ``landmarks``, their heat kernel maps as further descriptors), ICP, then ZoomOut up to k;
    - ``sgfe``: the spectral gradient fields embedding (:func:`~hamsa.matching.match_sgfe`) from that
      functional map (needs ``meshes``);
    - ``icskm``: iterative closest spectral kernel maps (:func:`~hamsa.matching.match_icskm`) from
      ``landmarks``;
    - ``icskm_geo``: the same with the geodesic distances from each landmark as extra embedding coordinates
      (needs ``meshes``).

    Parameters
    ----------
    source, target : the two shapes' eigenbases (the LBO's or Hamiltonians'), with the same k for the
        spectral methods; use shapes scaled alike (e.g. :meth:`hamsa.TriMesh.scaled_to_unit_area`)
    landmarks : (source ids, target ids) of known pairs, for ``icskm`` and ``icskm_geo``; optional for ``fmap``
    meshes : (source, target) meshes for ``sgfe``; meshes or point clouds for ``icskm_geo``. Every other
        method needs only the eigenbases, so it runs on point clouds' bases as on meshes'.
    progress : optional ``progress(done, total)`` of the long steps: ZoomOut's sizes (``fmap``), SGFE's ICP
        iterations (``sgfe``), ICSKM's ICP runs (``icskm``, ``icskm_geo``); the descriptor methods do not
        call it
    commutativity_weight : the descriptor-commutativity weight of the functional map that starts ``fmap``
        and ``sgfe`` (:func:`~hamsa.matching.functional_map`; 0: the row-wise fit); the other methods ignore it

    Raises
    ------
    HamsaError
        On an unknown method or a missing ``landmarks`` / ``meshes``.
    """
    if method not in _MATCHERS:
        raise HamsaError(f"unknown matching method {method!r}; known: {', '.join(METHODS)}")
    check_commutativity_weight(commutativity_weight)
    return _MATCHERS[method](source, target, landmarks, meshes, progress, commutativity_weight)


def check_commutativity_weight(weight: float) -> None:
    """Raise a HamsaError unless ``weight`` is a finite number >= 0 (the start map's commutativity weight)."""
    if not (np.isfinite(weight) and weight >= 0):
        raise HamsaError(f"the commutativity weight must be finite and >= 0, got {weight}")


def _hks(source, target, landmarks, meshes, progress, commutativity_weight):
    from hamsa.diffusion import default_hks_times, heat_kernel_signature

    times = default_hks_times(source, 50)
    return match_descriptors(
        heat_kernel_signature(source, times, scaled=True), heat_kernel_signature(target, times, scaled=True)
    )


def _wks(source, target, landmarks, meshes, progress, commutativity_weight):
    from hamsa.diffusion import default_wks_energies, wave_kernel_signature

    energies, sigma = default_wks_energies(source, 50)
    return match_descriptors(
        wave_kernel_signature(source, energies, sigma), wave_kernel_signature(target, energies, sigma)
    )


def hks_functional_map(
    source: Eigenbasis,
    target: Eigenbasis,
    k: int = START_K,
    landmarks=None,
    commutativity_weight: float = COMMUTATIVITY_WEIGHT,
) -> tuple[np.ndarray, np.ndarray]:
    """A (k, k) functional map fitted to 30 scaled HKS columns on the first k eigenpairs, refined by ICP:
    ``(C, map_source_to_target)``; the start of ``fmap`` and ``sgfe``. With ``landmarks`` (source ids,
    target ids), their heat kernel maps (:func:`hamsa.diffusion.landmark_descriptors`) join the HKS;
    ``commutativity_weight``: that of :func:`functional_map` (0: the row-wise fit)."""
    from hamsa.diffusion import default_hks_times, heat_kernel_signature, landmark_descriptors

    small = source.truncate(k), target.truncate(k)
    times = default_hks_times(source, 30)
    descriptors = [heat_kernel_signature(basis, times, scaled=True) for basis in (source, target)]
    if landmarks is not None:
        kernel_times = default_hks_times(source, 5)  # the same times on both shapes, as for the HKS
        descriptors = [
            np.hstack([d, landmark_descriptors(basis, ids, kernel_times)])
            for d, basis, ids in zip(descriptors, (source, target), landmarks)
        ]
    return icp_refine(functional_map(*small, *descriptors, commutativity_weight=commutativity_weight), *small)


def _fmap(source, target, landmarks, meshes, progress, commutativity_weight):
    _, initial = hks_functional_map(source, target, landmarks=landmarks, commutativity_weight=commutativity_weight)
    return zoomout(initial, source, target, range(START_K, min(source.k, target.k) + 1, 4), progress)[1]


def _sgfe(source, target, landmarks, meshes, progress, commutativity_weight):
    if meshes is None:
        raise HamsaError("sgfe needs the two meshes (for the eigenfunction gradients)")
    if any(isinstance(shape, PointCloud) for shape in meshes):
        raise HamsaError("sgfe needs triangle meshes (its gradients are per face), not point clouds: use fmap")
    C, _ = hks_functional_map(source, target, commutativity_weight=commutativity_weight)
    start = np.eye(source.k)
    start[:START_K, :START_K] = C
    return match_sgfe(*meshes, source, target, start, progress=progress)[1]


def _icskm(source, target, landmarks, meshes, progress, commutativity_weight, features=None):
    if landmarks is None:
        raise HamsaError("icskm needs landmark pairs (source ids, target ids)")
    return match_icskm(source, target, *landmarks, features=features, progress=progress)[1]


def _icskm_geo(source, target, landmarks, meshes, progress, commutativity_weight):
    from hamsa.geodesic import geodesic_solver

    if landmarks is None:
        raise HamsaError("icskm_geo needs landmark pairs (source ids, target ids)")
    if meshes is None:
        raise HamsaError("icskm_geo needs the two shapes (for the geodesic distances from the landmarks)")
    features = tuple(
        geodesic_solver(shape).distances_from(ids, unreachable="farthest") for shape, ids in zip(meshes, landmarks)
    )
    return _icskm(source, target, landmarks, meshes, progress, commutativity_weight, features)


_MATCHERS = {"hks": _hks, "wks": _wks, "fmap": _fmap, "sgfe": _sgfe, "icskm": _icskm, "icskm_geo": _icskm_geo}
