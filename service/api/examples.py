"""Examples of the documented models (OpenAPI ``examples``; Swagger UI shows and prefills them)."""

from __future__ import annotations

from typing import Any

from service.core.report import report_example

__all__ = ["GEOMETRY_EXAMPLE", "JOB_EXAMPLE", "REPORT_EXAMPLE"]


GEOMETRY_EXAMPLE: dict[str, Any] = {
    "points": [[0.0, 0.0, 0.0], [1.0, 0.0, 0.1], [1.0, 1.0, -0.1], [0.0, 1.0, 0.05]],
    "faces": [[0, 1, 2], [0, 2, 3]],
}

#: The report's example is the model's (each member every report has, with its example).
REPORT_EXAMPLE: dict[str, Any] = report_example()

JOB_EXAMPLE: dict[str, Any] = {
    "id": "3f2a9c0d4b5e6f708192a3b4c5d6e7f8",
    "status": "running",
    "input_format": "ply",
    "format": "ply",
    "filename": "bunny.ply",
    "params": {"tau": 0.0002},
    "weld": False,
    "webhook_url": None,
    "created_at": "2026-01-01T12:00:00Z",
    "started_at": "2026-01-01T12:00:01Z",
    "finished_at": None,
    "expires_at": None,
    "attempts": 1,
    "max_attempts": 3,
    "run_seconds": None,
    "progress": {
        "stage": "search",
        "iteration": 3,
        "lambda": 0.011,
        "phi": 0.00019,
        "tau": 0.0002,
        "relative_error": 0.05,
        "percent": 80.0,
        "eta_seconds": 0.4,
        "elapsed_seconds": 1.6,
    },
    "report": None,
    "error": None,
    "links": {
        "status": "/v1/jobs/3f2a9c0d4b5e6f708192a3b4c5d6e7f8",
        "result": "/v1/jobs/3f2a9c0d4b5e6f708192a3b4c5d6e7f8/result",
        "report": "/v1/jobs/3f2a9c0d4b5e6f708192a3b4c5d6e7f8/report",
        "events": "/v1/jobs/3f2a9c0d4b5e6f708192a3b4c5d6e7f8/events",
    },
}
