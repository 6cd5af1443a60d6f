"""Typed results of the paper's experiments, and their JSON form.

Every experiment's ``run`` returns one of the frozen dataclasses below; :mod:`hamsa.paper.claims` judges
the claims from their attributes. :func:`to_json` turns a result into plain JSON values (what each
``<experiment>.json``, ``results.json`` and the report's cache hold) and :func:`from_json` reads them back,
checking every field against its annotation: a cached record written by another version of the code, or
edited by hand, is refused with the path of the first field that does not fit, never read by a key that
is not there. A field whose JSON name is not a Python name (``within_0.05``) says so in its metadata.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from dataclasses import dataclass, field

import numpy as np

from hamsa.errors import HamsaError


class ResultFormatError(HamsaError):
    """A JSON record does not have the shape of the result type it is read as."""


def _json_name(f: dataclasses.Field) -> str:
    return f.metadata.get("json", f.name)


def to_json(value):
    """Plain JSON values (dicts, lists, numbers, strings, None) of a result, its parts or numpy values."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {_json_name(f): to_json(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {k: to_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_json(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_json(value.tolist())
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    return value


def from_json(kind, data, path: str = "result"):
    """``data`` (plain JSON values) as an instance of ``kind``: a result dataclass, or a type built from
    dataclasses, ``float``, ``int``, ``bool``, ``str``, ``None``, ``X | None``, ``list[X]``,
    ``tuple[X, ...]`` and ``dict[str, X]``. Raises :class:`ResultFormatError` naming the first field
    (``path``) that is missing, unexpected or of the wrong type."""
    origin, arguments = typing.get_origin(kind), typing.get_args(kind)
    if kind is type(None):
        if data is not None:
            raise ResultFormatError(f"{path}: expected null, got {type(data).__name__}")
        return None
    if origin in (typing.Union, types.UnionType):
        options = [a for a in arguments if a is not type(None)]
        if len(options) != 1 or len(arguments) != 2:
            raise TypeError(f"{path}: only 'X | None' unions are supported, got {kind}")
        return None if data is None else from_json(options[0], data, path)
    if dataclasses.is_dataclass(kind):
        return _dataclass_from_json(kind, data, path)
    if origin is list or origin is tuple:
        if not isinstance(data, list):
            raise ResultFormatError(f"{path}: expected a list, got {type(data).__name__}")
        items = [from_json(arguments[0], item, f"{path}[{i}]") for i, item in enumerate(data)]
        return items if origin is list else tuple(items)
    if origin is dict:
        if not isinstance(data, dict):
            raise ResultFormatError(f"{path}: expected an object, got {type(data).__name__}")
        return {key: from_json(arguments[1], item, f"{path}[{key!r}]") for key, item in data.items()}
    return _scalar_from_json(kind, data, path)


def _scalar_from_json(kind, data, path: str):
    if kind is float:
        fits = isinstance(data, (int, float)) and not isinstance(data, bool)  # JSON writes 2.0 as 2.0, ints as ints
        return _checked(fits, float(data) if fits else None, kind, data, path)
    if kind is int or kind is str:
        return _checked(isinstance(data, kind) and not isinstance(data, bool), data, kind, data, path)
    if kind is bool:
        return _checked(isinstance(data, bool), data, kind, data, path)
    raise TypeError(f"{path}: unsupported field type {kind!r}")


def _checked(fits: bool, value, kind, data, path: str):
    if not fits:
        raise ResultFormatError(f"{path}: expected {kind.__name__}, got {type(data).__name__} {data!r:.40}")
    return value


def _dataclass_from_json(kind, data, path: str):
    if not isinstance(data, dict):
        raise ResultFormatError(f"{path}: expected an object for {kind.__name__}, got {type(data).__name__}")
    hints = typing.get_type_hints(kind)
    fields = {_json_name(f): f for f in dataclasses.fields(kind)}
    unexpected = sorted(set(data) - set(fields))
    if unexpected:
        raise ResultFormatError(f"{path}: {kind.__name__} has no field {unexpected[0]!r}")
    values = {}
    for name, f in fields.items():
        if name not in data:
            raise ResultFormatError(f"{path}: {kind.__name__} misses the field {name!r}")
        values[f.name] = from_json(hints[f.name], data[name], f"{path}.{name}")
    return kind(**values)


# --------------------------------------------------------------------------------- shared parts
@dataclass(frozen=True)
class Scores:
    """Kim et al. scores of one method and basis: AUC of the curve on [0, 0.25], mean geodesic error
    (fraction of sqrt(area)), fraction of points within 0.05."""

    auc: float
    mean_error: float
    within_005: float = field(metadata={"json": "within_0.05"})


@dataclass(frozen=True)
class BasisScores:
    """One method's mean scores with the LBO basis and with the Hamiltonian basis."""

    lbo: Scores
    hamiltonian: Scores


@dataclass(frozen=True)
class PairScores:
    """The scores of one method and basis on one pair (``unreachable``: fraction mapped to another piece)."""

    source: str
    target: str
    method: str
    basis: str
    mean_error: float
    auc: float
    within_005: float = field(metadata={"json": "within_0.05"})
    unreachable: float


# --------------------------------------------------------------------------------- per experiment
@dataclass(frozen=True)
class Spectrum1D:
    """Numeric vs analytic eigenvalues of one 1-D potential."""

    numeric: list[float]
    analytic: list[float]
    relative_error: list[float]


@dataclass(frozen=True)
class HarmonicsResult:
    """fig1_harmonics_1d."""

    grid_points: int
    box: Spectrum1D
    step: Spectrum1D
    oscillator: Spectrum1D
    max_relative_error: float
    seconds: float


@dataclass(frozen=True)
class StepPotentialResult:
    """fig2_step_potential: ``*_mass_in_V0_free_region`` is each mode's A-mass fraction where V = 0."""

    mesh: str
    n_vertices: int
    V0: float
    area_fraction_V0: float
    lbo_values: list[float]
    values: list[float]
    theorem1_lower: list[float]
    theorem1_upper: list[float]
    theorem1_holds: bool
    lbo_mass_in_V0_free_region: list[float]
    mass_in_V0_free_region: list[float]
    trapped_mean_mass: float | None
    seconds: float


@dataclass(frozen=True)
class HeatAtTime:
    """fig3: the heat of one operator at one time, and its centroid's geodesic distance to the leg."""

    operator: str
    t: float
    total_heat: float
    mean_distance_to_leg: float


@dataclass(frozen=True)
class DiffusionResult:
    """fig3_diffusion."""

    mesh: str
    n_vertices: int
    k: int
    mu: float
    source_vertex: int
    leg_vertex: int
    times: list[float]
    rows: list[HeatAtTime]
    seconds: float


@dataclass(frozen=True)
class NodalCount:
    """fig4: nodal domains of the first eigenfunctions of one operator and Courant's bound for each."""

    values: list[float]
    domains: list[int]
    bounds: list[int]
    courant_holds: bool
    violations: list[int]


@dataclass(frozen=True)
class NodalResult:
    """fig4_nodal: ``operators`` maps "LBO", "step", "geodesic" to their counts."""

    mesh: str
    n_vertices: int
    scale: float
    operators: dict[str, NodalCount]
    seconds: float


@dataclass(frozen=True)
class NoiseCase:
    """fig5: per mode, |<psi, psi~>_A| between the clean and the perturbed basis, and the first five's mean."""

    hamiltonian_stability: list[float]
    lbo_stability: list[float]
    hamiltonian_mean_first5: float
    lbo_mean_first5: float


@dataclass(frozen=True)
class NoiseResult:
    """fig5_noise: ``cases`` maps "vertex noise", "potential noise", "30% holes" to their stability."""

    mesh: str
    n_vertices: int
    mu: float
    cases: dict[str, NoiseCase]
    seconds: float


@dataclass(frozen=True)
class OptimizedPotential1D:
    """fig6: one parametrization's loss against the LBO's and where its potential is large."""

    loss: float
    lbo_loss: float
    ratio: float
    mean_V_near_ends: float
    mean_V_interior: float
    argmax_x: float
    argmin_x: float
    high_near_boundary: bool


@dataclass(frozen=True)
class Optimize1DResult:
    """fig6_optimize_1d: ``parametrizations`` maps "signed" and "square" to their results."""

    grid_points: int
    k: int
    parametrizations: dict[str, OptimizedPotential1D]
    seconds: float


@dataclass(frozen=True)
class ReconstructionErrors:
    """Representation errors of the LBO and of the optimized Hamiltonian, and their ratio."""

    lbo_error: float
    hamiltonian_error: float
    ratio: float


@dataclass(frozen=True)
class OptimizeHandResult:
    """fig7_optimize_hand (``paper``: the numbers the paper reports for its own hand)."""

    mesh: str
    n_vertices: int
    k: int
    m: int
    iterations: int
    lbo_error: float
    hamiltonian_error: float
    ratio: float
    paper: ReconstructionErrors
    V_min: float
    V_max: float
    mean_lbo_error_where_V_lowest_10pct: float
    mean_lbo_error_elsewhere: float
    seconds: float


@dataclass(frozen=True)
class CompressionPoint:
    """fig8: one basis at one coefficient count (bits per vertex, Karni-Gotsman and RMS errors)."""

    method: str
    coefficients: int
    bits: int
    bpv: float
    permutation_bpv: float
    kg_error: float
    rms_error: float
    representation_gain: float


@dataclass(frozen=True)
class CompressionResult:
    """fig8_compression: ``ordering_holds_per_count``: error(H opt) <= error(H) <= error(MHB) per count."""

    mesh: str
    n_vertices: int
    rows: list[CompressionPoint]
    ordering_holds_per_count: list[bool]
    ordering_holds: bool
    seconds: float


@dataclass(frozen=True)
class ModesRun:
    """fig9: one compressed-modes solve (time over ``runs`` repeats, objective, orthogonality)."""

    mesh: str
    n_vertices: int
    K: int
    mu: float
    method: str
    seconds_mean: float
    seconds_std: float
    runs: int
    objective: float
    orthogonality_error: float


@dataclass(frozen=True)
class ModesRatio:
    """fig9: ADMM against the Hamiltonian IRLS on one mesh and K."""

    time_admm_over_hamiltonian: float
    objective_hamiltonian_over_admm: float


@dataclass(frozen=True)
class ModesAgreement:
    """fig9: mean best overlap of the modes of a capsule and of its half-refined copy, per
    "method/l1" ("hamiltonian/area", "admm/vector", ...)."""

    n_vertices: list[int]
    K: int
    mu: float
    agreement: dict[str, float]


@dataclass(frozen=True)
class ModesResult:
    """fig9_cmm: ``ratios`` keyed "<mesh>-<n>-K<K>"."""

    rows: list[ModesRun]
    ratios: dict[str, ModesRatio]
    discretization: ModesAgreement
    seconds: float


@dataclass(frozen=True)
class OffDiagonalEnergy:
    """||C - diag C|| / ||C|| of the ground-truth |C| in the LBO and in the area-distortion Hamiltonian bases."""

    lbo: float
    hamiltonian: float


@dataclass(frozen=True)
class MatchingResult:
    """fig10_matching: ``methods`` maps each matcher to its mean scores over ``pairs``."""

    dataset: str
    pairs: list[tuple[str, ...]]
    k: int
    mu: float
    potentials: str
    methods: dict[str, BasisScores]
    rows: list[PairScores]
    offdiagonal_energy: OffDiagonalEnergy
    seconds: float


@dataclass(frozen=True)
class TextureResult:
    """fig11_dalmatian: HKS and WKS with the LBO and with the texture Hamiltonian."""

    dataset: str
    pairs: list[tuple[str, ...]]
    k: int
    mu: float
    spot_area_fraction: float
    methods: dict[str, BasisScores]
    rows: list[PairScores]
    seconds: float


@dataclass(frozen=True)
class MuRule:
    """T2: first-order error ratios when mu halves, and E_i / (mu max V) at half the critical scale."""

    error_ratios_halving_mu: list[float]
    E_at_half_bound_over_mu_maxV: float


@dataclass(frozen=True)
class SparsityAndCost:
    """T5: nonzeros of H and W and the eigensolve cost of H over the LBO's (sparse solves, time)."""

    nnz_W: int
    nnz_H: int
    solves_ratio_hamiltonian_over_lbo: float
    time_ratio_hamiltonian_over_lbo: float


@dataclass(frozen=True)
class BasisChecks:
    """T15: max |Psi^T A Psi - I|, whether E is ascending, and E_1."""

    orthonormality_error: float
    ascending: bool
    E1: float


@dataclass(frozen=True)
class TheoremChecks:
    """claims_checks: the numbers behind T1-T5, T8, T13 and T15."""

    mesh: str
    T1_max_relative_violation: float
    T2: MuRule
    T3_max_ratio_lhs_over_bound: float
    T4_random_basis_max_ratio: float
    T5: SparsityAndCost
    T8_gradient_relative_error: float
    T13_error_ratios_halving_eps: list[float]
    T15: BasisChecks
    seconds: float
