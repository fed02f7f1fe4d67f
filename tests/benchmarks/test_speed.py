"""Smoke test of benchmarks/speed at its tiniest size (speed is never asserted)."""

from __future__ import annotations

from benchmarks.speed.child import run_job
from benchmarks.speed.jobs import Job


def test_one_speed_job_reports_work_and_errors() -> None:
    out = run_job(
        {
            "job": {"name": "ico:2/medium/plain", "input": "ico:2", "level": "medium"},
            "path": "auto",
            "open3d": True,
        }
    )
    assert out["converged"] and out["relative_error"] <= 1e-3
    assert out["factorizations"] >= 1 and out["ratio_one"] > 0
    assert 0 < out["error_ours"] < out["error_input"]
    assert out["rss_mb"] > 0
    assert Job(**{"name": "x", "input": "ico:2", "level": "light"}).level == "light"
