"""In-process checks of the pieces a live server cannot easily provoke (fake queue, no workers)."""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import pytest
from fastapi.exceptions import RequestValidationError
from pydantic import ValidationError
from starlette.exceptions import HTTPException

from service.api.app import create_app
from service.api.problems import (
    ApiProblem,
    FiniteJSONResponse,
    InvalidInlineGeometry,
    InvalidParams,
    problem_from_exception,
)
from service.api.results import REPORT_HEADER_MAX, report_header
from service.core.errors import IndexOutOfRange, SolverError, TauOutOfRange
from service.core.params import SmoothingParams
from service.io import FormatError, UnsupportedFormat
from service.jobs.errors import IdempotencyConflict, JobTooLarge, StorageFull
from service.settings import ConfigError, Settings

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient


class BrokenQueue:
    """A queue whose reads fail like a bug would."""

    def start(self) -> None: ...

    def stop(self) -> None: ...

    def get(self, job_id: str, *, tenant: Any = None) -> Any:
        raise RuntimeError("secret internal detail /etc/passwd")

    def list(
        self, offset: int = 0, limit: int = 50, status: Any = None, *, tenant: Any = None
    ) -> Any:
        return [], 0

    def health(self) -> Any:
        raise RuntimeError("health broke")

    def stats(self) -> dict[str, Any]:
        raise RuntimeError("stats broke")


def _params_error() -> ValidationError:
    try:
        SmoothingParams.model_validate({"tau": -1})
    except ValidationError as exc:
        return exc
    raise AssertionError("unreachable")


@pytest.mark.parametrize(
    ("exc", "status", "field"),
    [
        (UnsupportedFormat("GPX is not supported", fmt="gpx"), 415, "format"),
        (FormatError("line 3: expected 3 numbers", fmt="xyz", line=3), 400, "file"),
        (IndexOutOfRange("face 0 refers to 9", field="geometry.faces"), 422, "geometry.faces"),
        (TauOutOfRange("too big", field="params.tau", tau=9.0, tau_max=2.0), 422, "params.tau"),
        (SolverError("not positive definite", field="params.lam"), 422, "params.lam"),
        (InvalidParams(_params_error()), 422, "params.tau"),
        (InvalidInlineGeometry("unknown key 'face'"), 422, "geometry"),
        (IdempotencyConflict("key reused", field="Idempotency-Key"), 409, "Idempotency-Key"),
        (StorageFull("the job store is out of space"), 507, None),
        (JobTooLarge("needs 9 GiB", field="file", estimate_bytes=9, limit_bytes=1), 422, "file"),
        (
            ConfigError("GEOSMOOTH_WORKERS='abc': bad", field="GEOSMOOTH_WORKERS"),
            500,
            "GEOSMOOTH_WORKERS",
        ),
        (RequestValidationError([{"loc": ("query", "limit"), "msg": "bad"}]), 422, "limit"),
        (HTTPException(405), 405, None),
        (ApiProblem(409, "not ready", code="result-not-ready"), 409, None),
        (KeyError("boom"), 500, None),
    ],
)
def test_problem_mapping(exc: Exception, status: int, field: str | None) -> None:
    problem = problem_from_exception(exc)
    body = problem.body("/x")
    assert body["status"] == status and body.get("field") == field
    json.dumps(body)  # JSON-ready
    if status == 422:
        assert body["errors"][0]["field"] == field
    if isinstance(exc, TauOutOfRange):
        assert body["valid_range"] == [0.0, 2.0]
    if isinstance(exc, JobTooLarge):
        assert body["estimate_bytes"] == 9 and body["limit_bytes"] == 1


class _NewError(Exception):
    """A typed error class the HTTP layer has never heard of (like a future jobs error)."""

    code = "brand-new"
    title = "Brand new"
    status = 418

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message, self.field = message, "params.k"

    def to_dict(self) -> dict[str, Any]:
        return {"code": self.code, "message": self.message, "field": self.field, "x": 1.5}


def test_any_typed_error_maps_generically_and_config_errors_stay_internal() -> None:
    body = problem_from_exception(_NewError("teapot")).body()
    assert body["status"] == 418 and body["title"] == "Brand new" and body["x"] == 1.5
    assert body["type"] == "urn:geosmooth:problem:brand-new" and body["field"] == "params.k"


def test_non_finite_numbers_never_break_a_problem_or_a_json_answer() -> None:
    exc = TauOutOfRange(
        "nothing can move", field="params.tau", tau=float("nan"), tau_max=float("inf")
    )
    body = problem_from_exception(exc).body()
    assert body["valid_range"] == [0.0, None] and body["tau"] is None
    assert json.loads(FiniteJSONResponse({"a": [1.0, float("-inf")]}).body) == {"a": [1.0, None]}


def test_pydantic_errors_outside_params_are_not_blamed_on_the_client() -> None:
    assert problem_from_exception(_params_error()).status == 500


def test_unexpected_errors_are_500_problems_without_internals(tmp_path: Path) -> None:
    app = create_app(Settings(data_dir=tmp_path), queue=BrokenQueue())  # type: ignore[arg-type]
    with TestClient(app, base_url="http://localhost", raise_server_exceptions=False) as client:
        r = client.get("/v1/jobs/0123456789abcdef0123456789abcdef")
        assert r.status_code == 500
        assert r.headers["content-type"] == "application/problem+json"
        assert "secret" not in r.text and "Traceback" not in r.text
        metrics = client.get("/metrics")  # a failing stats() does not break the scrape
        assert metrics.status_code == 200 and "geosmooth_jobs" in metrics.text
        assert client.get("/healthz").status_code == 200


def test_not_ready_without_started_queue_or_writable_dir(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    app = create_app(Settings(data_dir=blocker / "sub"), queue=BrokenQueue())  # type: ignore[arg-type]
    client = TestClient(
        app, base_url="http://localhost", raise_server_exceptions=False
    )  # no lifespan: queue not started
    r = client.get("/readyz")
    assert r.status_code == 503 and r.json()["checks"] == {"queue": "not-started"}
    r = client.get("/v1/jobs")
    assert r.status_code == 503 and r.json()["code"] == "queue-unavailable"
    with TestClient(app, base_url="http://localhost", raise_server_exceptions=False) as started:
        r = started.get("/readyz")  # started, but its health check fails, and no spool
        assert r.status_code == 503 and r.json()["checks"]["queue"] == "health-check-failed"
        assert r.json()["checks"]["spool"] == "not-writable" and "broke" not in r.text


def test_report_header_is_compact_ascii_and_bounded() -> None:
    report = {
        "lambda": 0.1,
        "phi": 1.0,
        "warnings": ["λ search did not converge"],
        "history": [{"lambda": 1e-3 * i, "phi": 0.5 + i} for i in range(500)],
        "spectrum": {"sigma": [1.0] * 3000, "gamma": [0.5] * 3000},
    }
    text = report_header(report)
    assert text.isascii() and len(text) <= REPORT_HEADER_MAX
    decoded = json.loads(text)
    assert "spectrum" not in decoded
    assert decoded["history_omitted"] == 480 and len(decoded["history"]) == 20
    assert decoded["history"][-1] == report["history"][-1]
    assert decoded["warnings"] == report["warnings"]
