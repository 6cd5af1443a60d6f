"""One call from two eigenbases to a point map: :func:`match` with any of :data:`METHODS`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hamsa.eigen import Eigenbasis
from hamsa.errors import HamsaError
from hamsa.matching.functional import (
    COMMUTATIVITY_WEIGHT,
    _operator_ratio,
    _orientation_operators,
    check_term_weight,
    functional_map,
    icp_refine,
    zoomout,
)
from hamsa.matching.icskm import match_icskm
from hamsa.matching.nearest import match_descriptors
from hamsa.matching.sgfe import match_sgfe
from hamsa.pointcloud import PointCloud
from hamsa.repair import orient_faces

METHODS = ("hks", "wks", "fmap", "sgfe", "icskm", "icskm_geo")
# the functional map that starts fmap and sgfe is fitted on this many eigenpairs (with COMMUTATIVITY_WEIGHT)
START_K = 20
# a start fitted with the orientation term replaces the plain one only when its orientation_ratio is below
# this: at the ground truth of SCAPE pairs the ratio is 0.01-0.2, and near 1 a map is as close to its mirror
# image as to the asked orientation, so the ratio cannot say which start is right (set on half of the SCAPE
# pairs, docs/results/matching.md)
ORIENTED_RATIO = 0.3


@dataclass(frozen=True)
class _Request:
    """What every matcher receives: the two bases and the options of :func:`match`."""

    source: Eigenbasis
    target: Eigenbasis
    landmarks: tuple | None
    meshes: tuple | None
    progress: Callable | None
    commutativity_weight: float
    orientation_weight: float

    def start_map(self, landmarks=None) -> tuple[np.ndarray, np.ndarray]:
        """The (START_K, START_K) start of fmap and sgfe, with this request's terms."""
        return hks_functional_map(
            self.source,
            self.target,
            landmarks=landmarks,
            commutativity_weight=self.commutativity_weight,
            orientation_weight=self.orientation_weight,
            meshes=self.meshes,
        )


def match(
    source: Eigenbasis,
    target: Eigenbasis,
    method: str = "fmap",
    *,
    landmarks=None,
    meshes=None,
    progress=None,
    commutativity_weight: float = COMMUTATIVITY_WEIGHT,
    orientation_weight: float = 0.0,
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
    meshes : (source, target) meshes for ``sgfe``; meshes or point clouds for ``icskm_geo``; for ``fmap``,
        optional, for the orientation term. Every other method needs only the eigenbases, so it runs on
        point clouds' bases as on meshes'.
    progress : optional ``progress(done, total)`` of the long steps: ZoomOut's sizes (``fmap``), SGFE's ICP
        iterations (``sgfe``), ICSKM's ICP runs (``icskm``, ``icskm_geo``); the descriptor methods do not
        call it
    commutativity_weight : the descriptor-commutativity weight of the functional map that starts ``fmap``
        and ``sgfe``, and of ICSKM's landmark fit (:func:`~hamsa.matching.functional_map`; 0: the row-wise
        fit); the descriptor methods ignore it
    orientation_weight : the weight of the orientation-preserving term of that functional map, which tells
        a map from its mirror image (a left-right symmetric shape's HKS cannot): the start is fitted with and
        without it, and the term's fit is kept only when it is clearly the better oriented
        (:func:`hks_functional_map`); > 0
        needs ``meshes``: triangle meshes (faces oriented consistently first,
        :func:`~hamsa.repair.orient_faces`) or point clouds (their estimated outward
        :attr:`~hamsa.PointCloud.normals`). Meshes whose normals point opposite ways (signed volumes of
        opposite signs) are matched orientation-reversing, i.e. as the same surface. Default 0; 0.03 is the
        weight measured in docs/results/matching.md.

    Raises
    ------
    HamsaError
        On an unknown method, a missing ``landmarks`` / ``meshes``, a negative or non-finite weight, or an
        orientation weight > 0 without two shapes (a MeshError if a mesh is not orientable).
    """
    if method not in _MATCHERS:
        raise HamsaError(f"unknown matching method {method!r}; known: {', '.join(METHODS)}")
    check_term_weight("commutativity", commutativity_weight)
    check_term_weight("orientation", orientation_weight)
    if orientation_weight:
        if meshes is None:
            raise HamsaError(
                "the orientation term (orientation_weight, hamsa match --orientation) needs the two shapes "
                "(meshes=(source, target)); set it to 0 to go without it"
            )
        meshes = tuple(shape if isinstance(shape, PointCloud) else orient_faces(shape) for shape in meshes)  # once
    request = _Request(source, target, landmarks, meshes, progress, commutativity_weight, orientation_weight)
    return _MATCHERS[method](request)


def _outward_sign(shape) -> float:
    """+1 where a shape's normals point outward, -1 where inward: a mesh's by the sign of the signed volume
    of its consistently oriented faces (:func:`~hamsa.repair.orient_faces`); a point cloud's
    :attr:`~hamsa.PointCloud.normals` are outward by construction."""
    if isinstance(shape, PointCloud):
        return 1.0
    return float(np.sign(orient_faces(shape).signed_volume) or 1.0)


def _hks(request):
    from hamsa.diffusion import default_hks_times, heat_kernel_signature

    times = default_hks_times(request.source, 50)
    return match_descriptors(*(heat_kernel_signature(b, times, scaled=True) for b in (request.source, request.target)))


def _wks(request):
    from hamsa.diffusion import default_wks_energies, wave_kernel_signature

    energies, sigma = default_wks_energies(request.source, 50)
    return match_descriptors(*(wave_kernel_signature(b, energies, sigma) for b in (request.source, request.target)))


def hks_functional_map(
    source: Eigenbasis,
    target: Eigenbasis,
    k: int = START_K,
    landmarks=None,
    commutativity_weight: float = COMMUTATIVITY_WEIGHT,
    orientation_weight: float = 0.0,
    meshes=None,
) -> tuple[np.ndarray, np.ndarray]:
    """A (k, k) functional map fitted to 30 scaled HKS columns on the first k eigenpairs, refined by ICP:
    ``(C, map_source_to_target)``; the start of ``fmap`` and ``sgfe``. With ``landmarks`` (source ids,
    target ids), their heat kernel maps (:func:`hamsa.diffusion.landmark_descriptors`) join the HKS;
    ``commutativity_weight``: that of :func:`functional_map` (0: the row-wise fit).

    ``orientation_weight`` > 0 (needs ``meshes``) fits the map a second time with the orientation term
    of :func:`functional_map`, orientation-preserving with respect to each surface's outward normals (a
    mesh's by the sign of its signed volume, a point cloud's estimated), and keeps that ICP-refined map only if its
    :func:`~hamsa.matching.orientation_ratio` is lower than the plain one's and below
    :data:`ORIENTED_RATIO` (clearly closer to the right orientation than to the mirror image). The term's
    energy is homogeneous in C, so on its own it shrinks C and can pull a good fit away; the ratio is
    scale-free."""
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
    if not orientation_weight:
        return _fitted_start(small, descriptors, commutativity_weight)
    if meshes is None:
        raise HamsaError("the orientation term needs the two meshes (meshes=(source, target))")
    orientation = "preserving" if _outward_sign(meshes[0]) == _outward_sign(meshes[1]) else "reversing"
    plain, oriented = (
        _fitted_start(small, descriptors, commutativity_weight, weight, meshes, orientation)
        for weight in (0.0, orientation_weight)
    )
    operators = _orientation_operators(*small, *descriptors, meshes, orientation)  # built once for both maps
    ratios = [_operator_ratio(fit[0], operators) for fit in (plain, oriented)]
    return oriented if ratios[1] < min(ratios[0], ORIENTED_RATIO) else plain


def _fitted_start(
    small, descriptors, commutativity_weight, orientation_weight=0.0, meshes=None, orientation="preserving"
):
    """``(C, map_source_to_target)``: :func:`functional_map` on the truncated bases, refined by ICP."""
    C = functional_map(
        *small,
        *descriptors,
        commutativity_weight=commutativity_weight,
        orientation_weight=orientation_weight,
        meshes=meshes,
        orientation=orientation,
    )
    return icp_refine(C, *small)


def _fmap(request):
    _, initial = request.start_map(request.landmarks)
    sizes = range(START_K, min(request.source.k, request.target.k) + 1, 4)
    return zoomout(initial, request.source, request.target, sizes, request.progress)[1]


def _sgfe(request):
    if request.meshes is None:
        raise HamsaError("sgfe needs the two meshes (for the eigenfunction gradients)")
    if any(isinstance(shape, PointCloud) for shape in request.meshes):
        raise HamsaError("sgfe needs triangle meshes (its gradients are per face), not point clouds: use fmap")
    C, _ = request.start_map()
    start = np.eye(request.source.k)
    start[:START_K, :START_K] = C
    return match_sgfe(*request.meshes, request.source, request.target, start, progress=request.progress)[1]


def _icskm(request, features=None):
    if request.landmarks is None:
        raise HamsaError("icskm needs landmark pairs (source ids, target ids)")
    return match_icskm(
        request.source,
        request.target,
        *request.landmarks,
        features=features,
        commutativity_weight=request.commutativity_weight,
        progress=request.progress,
    )[1]


def _icskm_geo(request):
    from hamsa.geodesic import geodesic_solver

    if request.landmarks is None:
        raise HamsaError("icskm_geo needs landmark pairs (source ids, target ids)")
    if request.meshes is None:
        raise HamsaError("icskm_geo needs the two shapes (for the geodesic distances from the landmarks)")
    features = tuple(
        geodesic_solver(shape).distances_from(ids, unreachable="farthest")
        for shape, ids in zip(request.meshes, request.landmarks)
    )
    return _icskm(request, features)


_MATCHERS = {"hks": _hks, "wks": _wks, "fmap": _fmap, "sgfe": _sgfe, "icskm": _icskm, "icskm_geo": _icskm_geo}
