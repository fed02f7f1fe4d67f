"""Smoke test of ``python -m benchmarks``: the solver table on a tiny synthetic torus.

No timing is asserted: only that the run completes, writes its JSON, and that every solver that
is installed reproduces CHOLMOD's deviations phi(lambda) on the same lambda sequence.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from benchmarks.__main__ import main


def test_solvers_quick_tiny(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["solvers", "--quick", "--sizes", "1K", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "speedup vs UMFPACK" in out and "| 1K |" in out
    files = list(tmp_path.glob("solvers-quick-*.json"))
    assert len(files) == 1
    result = json.loads(files[0].read_text())
    rows = {r["solver"]: r for r in result["rows"]}
    assert rows["cholmod"]["status"] == "ok"
    assert rows["cholmod"]["iterations"] == len(rows["cholmod"]["history"]) >= 1
    assert rows["cholmod"]["peak_rss_mb"] > 0
    for name in ("umfpack", "spqr", "superlu"):
        r = rows[name]
        if r["status"] == "not installed":
            continue
        assert r["status"] == "ok", r
        assert r["factorizations"] == rows["cholmod"]["factorizations"]
        assert r["phi_rel_diff"] < 1e-6


def test_umfpack_binding_solves() -> None:
    from benchmarks.umfpack import UmfpackError, UmfpackLU

    A = (sp.random(300, 300, density=0.02, random_state=1) + 10 * sp.eye(300)).tocsc()
    A.sort_indices()
    try:
        lu = UmfpackLU(A)
    except UmfpackError as exc:
        pytest.skip(str(exc))
    lu.factor(A.data)
    B = np.random.default_rng(0).normal(size=(300, 3))
    np.testing.assert_allclose(A @ lu.solve(B), B, atol=1e-10)
