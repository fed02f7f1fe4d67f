"""The documented models are the data: ``Report`` has exactly the keys of
``SmoothResult.report()``, and ``Job`` validates ``JobRecord.public_dict()`` as it is."""

from __future__ import annotations

import time

import pytest

from service.api import schemas
from service.api.examples import REPORT_EXAMPLE
from service.api.schemas import Job, Report
from service.core import Geometry, SmoothingParams, smooth
from service.jobs.queue import JobRecord, JobStatus
from tests.api.api_helpers import noisy_helix, noisy_plane_cloud, noisy_sphere


def _documented_keys() -> set[str]:
    return {field.alias or name for name, field in Report.model_fields.items()}


@pytest.mark.parametrize(
    ("geometry", "params"),
    [
        (Geometry(noisy_sphere(1)[0], faces=noisy_sphere(1)[1]), {"tau": 0.05, "spectrum": True}),
        (Geometry(noisy_helix(60)), {"rms": 0.005, "fix_boundary": True}),
        (Geometry(noisy_plane_cloud(200)), {"lam": 1.0, "neighborhood": "knn"}),
    ],
)
def test_report_schema_has_exactly_the_keys_of_a_report(geometry: Geometry, params: dict) -> None:
    report = smooth(geometry, SmoothingParams(**params)).report()
    documented = _documented_keys()
    optional = {n for n, f in Report.model_fields.items() if not f.is_required()}
    assert set(report) <= documented, f"undocumented report keys: {set(report) - documented}"
    assert documented - set(report) <= {Report.model_fields[n].alias or n for n in optional}
    Report.model_validate(report)


def test_the_api_documents_the_core_model() -> None:
    """One model: the API's ``Report`` and its example are service.core.report's."""
    from service.core import report

    assert Report is report.Report and schemas.HistoryEntry is report.HistoryEntry
    assert report.report_example() == REPORT_EXAMPLE


def _record(status: JobStatus, **extra: object) -> JobRecord:
    now = time.time()
    return JobRecord(
        id="0123456789abcdef0123456789abcdef",
        status=status,
        fmt="ply",
        filename="bunny.ply",
        params={"tau": 0.0002},
        input_bytes=1000,
        created_at=now,
        updated_at=now,
        **extra,  # type: ignore[arg-type]
    )


@pytest.mark.parametrize(
    "record",
    [
        _record(JobStatus.QUEUED),
        _record(
            JobStatus.RUNNING,
            started_at=time.time(),
            attempts=1,
            progress={
                "stage": "search",
                "iteration": 2,
                "lambda": 0.5,
                "phi": 1e-4,
                "tau": 2e-4,
                "relative_error": 0.5,
                "percent": 40.0,
                "eta_seconds": 1.0,
                "elapsed_seconds": 0.7,
            },
        ),
        _record(
            JobStatus.SUCCEEDED,
            finished_at=time.time(),
            run_seconds=1.5,
            report={"lambda": 0.5, "phi": 2e-4},
            webhook_url="https://example.org/h",
        ),
        _record(
            JobStatus.FAILED,
            finished_at=time.time(),
            problem={
                "code": "tau-out-of-range",
                "title": "Invalid parameters",
                "detail": "too big",
                "field": "params.tau",
            },
        ),
    ],
)
def test_job_model_validates_the_public_dict_unchanged(record: JobRecord) -> None:
    public = record.public_dict()
    job = Job.model_validate(public)  # extra="forbid": every member is documented
    assert job.model_dump(mode="json", by_alias=True, exclude_unset=True) == public
    assert public["created_at"].endswith("Z") and isinstance(public["created_at"], str)
    assert job.created_at == public["created_at"]  # a string in, the same string out
