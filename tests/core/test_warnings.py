"""Typed warnings (issue 38): every warning a run gives has a known code, the report's
``warnings`` are their messages in the same order and ``warning_details`` their records."""

from __future__ import annotations

import json

import numpy as np
import pytest

from service.core import smooth
from service.core.geometry import Geometry
from service.core.params import SmoothingParams
from service.core.warnings import CODES, EngineWarning, to_wire, warning


def test_a_warning_is_a_record_of_a_known_code() -> None:
    w = warning("halo-capped", "the halo was capped at 12 hops: seams may show", hops=12)
    assert (w.code, str(w), w.numbers) == ("halo-capped", w.message, {"hops": 12})
    assert hash(w) == hash(EngineWarning("halo-capped", w.message, (("hops", 12),)))
    with pytest.raises(KeyError):
        warning("no-such-code", "text")
    wire = to_wire([w])
    assert wire == {"warnings": [w.message], "warning_details": [
        {"code": "halo-capped", "message": w.message, "values": {"hops": 12}}]}  # fmt: skip
    assert json.loads(json.dumps(wire)) == wire


def test_a_runs_warnings_are_typed_and_the_report_maps_them_in_order() -> None:
    """A cloud with fixed points asked for its spectrum and given weights: the plan's, the
    set-up's and the checks' warnings, each with its code, in run order."""
    rng = np.random.default_rng(5)
    P = np.column_stack([rng.uniform(-1, 1, (2, 400)).T, 0.01 * rng.standard_normal(400)])
    g = Geometry(P, weights=np.ones(400), fixed=[0, 1])
    params = SmoothingParams(rms=0.005, spectrum=True, fix_boundary=True, neighborhood="knn")
    res = smooth(g, params)
    codes = [w.code for w in res.warnings]
    assert codes == ["data-weights-not-applied", "fix-boundary-ignored", "spectrum-unavailable"]
    assert all(code in CODES for code in codes)
    report = res.report()
    assert report["warnings"] == [w.message for w in res.warnings]
    assert [d["code"] for d in report["warning_details"]] == codes


def test_numpy_numbers_become_json_numbers() -> None:
    w = warning("folds-kept", "3 faces of the result are folded", folded=np.int64(3),
                share=np.float64(0.5))  # fmt: skip
    assert json.loads(json.dumps(w.to_dict()))["values"] == {"folded": 3, "share": 0.5}
