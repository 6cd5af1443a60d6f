"""Typed experiment results: JSON in and out, and refusals that name the field that does not fit."""

from dataclasses import dataclass

import numpy as np
import pytest

from hamsa.paper.results import (
    NodalCount,
    NodalResult,
    PairScores,
    ResultFormatError,
    Scores,
    StepPotentialResult,
    from_json,
    to_json,
)


def _nodal(**changes):
    record = {
        "mesh": "m",
        "n_vertices": 10,
        "scale": 2.0,
        "operators": {"LBO": {"values": [0.0, 1.5], "domains": [1, 2], "bounds": [1, 2], "courant_holds": True,
                              "violations": []}},
        "seconds": 0.1,
    }  # fmt: skip
    record.update(changes)
    return record


def test_round_trip_with_numpy_values_and_nested_types():
    result = NodalResult(
        mesh="m",
        n_vertices=np.int64(10),
        scale=np.float64(2.0),
        operators={"LBO": NodalCount(np.array([0.0, 1.5]), [1, 2], [1, 2], np.bool_(True), [])},
        seconds=0.1,
    )
    plain = to_json(result)
    assert plain == _nodal()
    assert type(plain["n_vertices"]) is int and type(plain["operators"]["LBO"]["courant_holds"]) is bool
    back = from_json(NodalResult, plain)
    assert back.operators["LBO"].values == [0.0, 1.5] and back.operators["LBO"].courant_holds is True


def test_json_names_that_are_not_python_names():
    scores = from_json(Scores, {"auc": 0.5, "mean_error": 0.1, "within_0.05": 0.25})
    assert scores.within_005 == 0.25
    assert list(to_json(scores)) == ["auc", "mean_error", "within_0.05"]
    with pytest.raises(ResultFormatError, match="has no field 'within_005'"):
        from_json(Scores, {"auc": 0.5, "mean_error": 0.1, "within_005": 0.25})


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"seconds": "1 s"}, r"result\.seconds: expected float, got str"),
        ({"n_vertices": 10.0}, r"result\.n_vertices: expected int, got float"),
        ({"n_vertices": True}, r"result\.n_vertices: expected int, got bool"),
        ({"operators": []}, r"result\.operators: expected an object, got list"),
        ({"extra": 1}, r"NodalResult has no field 'extra'"),
        (
            {"operators": {"LBO": {"values": [0.0], "domains": [1], "bounds": [1], "courant_holds": 1,
                                   "violations": []}}},
            r"result\.operators\['LBO'\]\.courant_holds: expected bool, got int",
        ),
        (
            {"operators": {"LBO": {"values": [0.0, None], "domains": [], "bounds": [], "courant_holds": True,
                                   "violations": []}}},
            r"result\.operators\['LBO'\]\.values\[1\]: expected float, got NoneType",
        ),
    ],
)  # fmt: skip
def test_a_record_that_does_not_fit_is_refused_naming_the_field(changes, message):
    with pytest.raises(ResultFormatError, match=message):
        from_json(NodalResult, _nodal(**changes))


def test_a_missing_field_is_named():
    record = _nodal()
    del record["scale"]
    with pytest.raises(ResultFormatError, match="NodalResult misses the field 'scale'"):
        from_json(NodalResult, record)


def test_optional_fields_take_null_and_their_type_only():
    record = {
        "mesh": "m", "n_vertices": 3, "V0": 1.0, "area_fraction_V0": 0.5, "lbo_values": [0.0], "values": [1.0],
        "theorem1_lower": [0.0], "theorem1_upper": [1.0], "theorem1_holds": True,
        "lbo_mass_in_V0_free_region": [0.5], "mass_in_V0_free_region": [0.9], "trapped_mean_mass": None,
        "seconds": 0.0,
    }  # fmt: skip
    assert from_json(StepPotentialResult, record).trapped_mean_mass is None
    assert from_json(StepPotentialResult, {**record, "trapped_mean_mass": 1}).trapped_mean_mass == 1.0
    with pytest.raises(ResultFormatError, match="trapped_mean_mass: expected float, got str"):
        from_json(StepPotentialResult, {**record, "trapped_mean_mass": "n/a"})


def test_nan_scores_survive_and_tuples_come_back_as_tuples():
    row = {"source": "a", "target": "b", "method": "hks", "basis": "lbo", "mean_error": float("nan"), "auc": 0.0,
           "within_0.05": 0.0, "unreachable": 1.0}  # fmt: skip
    assert np.isnan(from_json(PairScores, row).mean_error)

    @dataclass(frozen=True)
    class Pairs:
        pairs: list[tuple[str, ...]]

    assert from_json(Pairs, {"pairs": [["a", "b"]]}).pairs == [("a", "b")]


def test_unsupported_annotations_are_a_programming_error():
    @dataclass(frozen=True)
    class Odd:
        value: set

    with pytest.raises(TypeError, match="unsupported field type"):
        from_json(Odd, {"value": [1]})
