"""Request and response bodies of the HTTP API (documentation and validation).

Smoothing parameters are :class:`service.core.params.SmoothingParams` and the report is
:class:`service.core.report.Report` (with its ``HistoryEntry``), both reused unchanged.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field
from pydantic.json_schema import WithJsonSchema

from service.api.examples import GEOMETRY_EXAMPLE, JOB_EXAMPLE, REPORT_EXAMPLE
from service.core.params import SmoothingParams
from service.core.report import HistoryEntry, Report
from service.io.registry import FORMATS
from service.settings import default

__all__ = [
    "COMPONENT_REFS",
    "GEOMETRY_EXAMPLE",
    "FieldError",
    "GeometryJsonDict",
    "HistoryEntry",
    "Job",
    "JobLinks",
    "JobList",
    "JobProblem",
    "JobProgress",
    "JobStatusName",
    "OutputFormat",
    "PageLinks",
    "Problem",
    "Report",
    "SmoothJsonRequest",
    "SmoothJsonResponse",
]

JobStatusName = Literal["queued", "running", "succeeded", "failed", "cancelled"]
#: Format names, from the io registry (one place to add a format); a plain ``str`` to mypy.
if TYPE_CHECKING:
    OutputFormat = str
else:
    OutputFormat = Literal[tuple(FORMATS)]


class FieldError(BaseModel):
    """One invalid input."""

    field: str = Field(description="Dotted path of the input at fault.", examples=["params.tau"])
    message: str = Field(description="What is wrong with it.", examples=["Input should be > 0"])
    type: str = Field(description="Machine readable error type.", examples=["greater_than"])


class Problem(BaseModel):
    """RFC 9457 problem details (``application/problem+json``), used for every error."""

    model_config = ConfigDict(
        extra="allow",
        json_schema_extra={
            "examples": [
                {
                    "type": "urn:geosmooth:problem:invalid-parameters",
                    "title": "Invalid parameters",
                    "status": 422,
                    "detail": "params.tau: Input should be greater than 0",
                    "instance": "/v1/jobs",
                    "code": "invalid-parameters",
                    "field": "params.tau",
                    "errors": [
                        {
                            "field": "params.tau",
                            "message": "Input should be greater than 0",
                            "type": "greater_than",
                        }
                    ],
                }
            ]
        },
    )

    type: str = Field(
        description="Problem type URI: ``urn:geosmooth:problem:<code>`` or ``about:blank``."
    )
    title: str = Field(description="Short summary of the problem type.")
    status: int = Field(description="HTTP status code.")
    detail: str = Field(description="Explanation of this occurrence (e.g. the parser's message).")
    instance: str | None = Field(default=None, description="Request path.")
    code: str | None = Field(default=None, description="Machine readable problem code.")
    field: str | None = Field(
        default=None, description="Dotted path of the input at fault (``params.tau``, ``file``)."
    )
    errors: list[FieldError] | None = Field(
        default=None, description="Every invalid input, for validation problems."
    )


class JobProblem(BaseModel):
    """Why a job failed: the problem details of the failure (no HTTP status of its own)."""

    model_config = ConfigDict(
        extra="allow",
        json_schema_extra={
            "examples": [
                {
                    "type": "urn:geosmooth:problem:tau-out-of-range",
                    "title": "Invalid parameters",
                    "detail": "tau = 12 is outside (0, phi(0)) = (0, 3.2)",
                    "code": "tau-out-of-range",
                    "field": "params.tau",
                    "valid_range": [0.0, 3.2],
                }
            ]
        },
    )

    type: str = Field(description="Problem type URI: ``urn:geosmooth:problem:<code>``.")
    title: str = Field(description="Short summary of the problem type.")
    detail: str = Field(description="What went wrong.")
    code: str | None = Field(default=None, description="Machine readable problem code.")
    field: str | None = Field(default=None, description="Dotted path of the input at fault.")


# The JSON geometry format is defined (and validated) by service.io; in the OpenAPI document the
# fields listed in COMPONENT_REFS point at the component ``GeometryJson`` (io's
# ``GEOMETRY_JSON_SCHEMA``) and ``Report`` (added by the app's openapi()).
GeometryJsonDict = dict[str, Any]


class SmoothJsonRequest(BaseModel):
    """JSON request body: the geometry inline plus the smoothing parameters."""

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={"examples": [{"geometry": GEOMETRY_EXAMPLE, "params": {"tau": 0.01}}]},
    )

    geometry: GeometryJsonDict = Field(
        description="The input geometry (the JSON format of service.io, as a .json upload)."
    )
    params: SmoothingParams = Field(description="Smoothing parameters.")
    weld: bool = Field(
        default=False,
        description="Weld exactly coincident vertices before smoothing (the result keeps the "
        "input's vertex count and order).",
        examples=[False],
    )


# Reports are passed through exactly as ``SmoothResult.report()`` made them (no re-validation,
# so new diagnostics never break the status endpoint); the ``Report`` model documents them.
ReportDict = dict[str, Any]

# (component, property) -> component the property's schema refers to in the OpenAPI document.
COMPONENT_REFS: dict[tuple[str, str], str] = {
    ("SmoothJsonRequest", "geometry"): "GeometryJson",
    ("SmoothJsonResponse", "geometry"): "GeometryJson",
    ("SmoothJsonResponse", "report"): "Report",
    ("Job", "report"): "Report",
}


class JobProgress(BaseModel):
    """Progress of a queued or running job, from its first stage on."""

    model_config = ConfigDict(
        populate_by_name=True,
        extra="allow",
        json_schema_extra={
            "examples": [
                {
                    "stage": "search",
                    "iteration": 3,
                    "lambda": 0.011,
                    "phi": 0.47,
                    "tau": 0.5,
                    "relative_error": 0.06,
                    "percent": 71.5,
                    "eta_seconds": 2.4,
                    "elapsed_seconds": 6.1,
                }
            ]
        },
    )

    stage: str | None = Field(
        default=None,
        description="queued, reading, neighborhoods, laplacian, analysis, search, postprocess, "
        "writing or done.",
    )
    iteration: int | None = Field(default=None, description="lambda iterations done so far.")
    lam: float | None = Field(default=None, alias="lambda", description="Latest lambda tried.")
    phi: float | None = Field(default=None, description="phi(lambda) of the latest lambda.")
    tau: float | None = Field(default=None, description="Target smoothing factor, once known.")
    relative_error: float | None = Field(
        default=None, description="|phi - tau| / tau (null when tau is not known)."
    )
    percent: float | None = Field(default=None, description="Estimated completion, 0-100.")
    eta_seconds: float | None = Field(default=None, description="Estimated seconds left.")
    elapsed_seconds: float | None = Field(default=None, description="Seconds since the start.")


class JobLinks(BaseModel):
    """Where to find the job's status, result, report and events."""

    status: str = Field(description="GET: job status.", examples=["/v1/jobs/3f2a9c"])
    result: str = Field(
        description="GET: smoothed geometry (when succeeded).", examples=["/v1/jobs/3f2a9c/result"]
    )
    report: str = Field(
        description="GET: diagnostics (when succeeded).", examples=["/v1/jobs/3f2a9c/report"]
    )
    events: str | None = Field(
        default=None,
        exclude_if=lambda value: value is None,  # absent where the server has no stream
        description="GET: server-sent events (progress, status), where the server streams them.",
        examples=["/v1/jobs/3f2a9c/events"],
    )


#: An ISO 8601 UTC time as the queue writes it (``2026-01-01T12:00:00Z``), passed through as is.
IsoTime = Annotated[str, WithJsonSchema({"type": "string", "format": "date-time"})]


class Job(BaseModel):
    """A smoothing job: exactly ``JobRecord.public_dict()`` of the queue."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [JOB_EXAMPLE]})

    id: str = Field(description="Job id.")
    status: JobStatusName = Field(description="queued, running, succeeded, failed or cancelled.")
    input_format: str = Field(description="Input format (default result format).")
    format: str = Field(
        description="Deprecated: the former name of ``input_format``.", deprecated=True
    )
    filename: str | None = Field(default=None, description="Uploaded file name, if any.")
    params: dict[str, Any] = Field(description="Smoothing parameters.")
    weld: bool = Field(default=False, description="Coincident vertices are welded on reading.")
    webhook_url: str | None = Field(default=None, description="Where the final job is POSTed.")
    created_at: IsoTime = Field(description="When the job was submitted (ISO 8601 UTC).")
    started_at: IsoTime | None = Field(default=None, description="When its latest run started.")
    finished_at: IsoTime | None = Field(default=None, description="When it ended.")
    expires_at: IsoTime | None = Field(
        default=None, description="When a finished job and its files are purged."
    )
    attempts: int = Field(default=0, description="Runs started (interrupted runs are retried).")
    max_attempts: int = Field(
        default=default("max_attempts"), description="Runs allowed before it is given up."
    )
    run_seconds: float | None = Field(default=None, description="Wall time of the successful run.")
    progress: JobProgress | None = Field(
        default=None, description="Latest progress (while queued or running)."
    )
    report: ReportDict | None = Field(default=None, description="Diagnostics (when succeeded).")
    error: JobProblem | None = Field(default=None, description="Problem details (when failed).")
    links: JobLinks = Field(description="Related resources.")


class PageLinks(BaseModel):
    """Neighbouring pages of a job list."""

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {"next": "/v1/jobs?offset=100&limit=50", "prev": "/v1/jobs?offset=0&limit=50"}
            ]
        }
    )

    next: str | None = Field(default=None, description="Next page, if any.")
    prev: str | None = Field(default=None, description="Previous page, if any.")


class JobList(BaseModel):
    """A page of jobs, newest first."""

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "items": [
                        {
                            **JOB_EXAMPLE,
                            "status": "succeeded",
                            "progress": None,
                            "finished_at": "2026-01-01T12:00:03Z",
                            "run_seconds": 1.9,
                        }
                    ],
                    "total": 1,
                    "offset": 0,
                    "limit": 50,
                    "links": {"next": None, "prev": None},
                }
            ]
        }
    )

    items: list[Job] = Field(description="Jobs on this page (without their reports).")
    total: int = Field(description="Jobs matching the filter, over all pages.", examples=[42])
    offset: int = Field(description="Index of the first item.", examples=[0])
    limit: int = Field(description="Page size.", examples=[50])
    links: PageLinks = Field(description="Neighbouring pages.")


class SmoothJsonResponse(BaseModel):
    """Result of ``POST /v1/smooth?format=json``: the smoothed geometry and its diagnostics."""

    model_config = ConfigDict(
        json_schema_extra={"examples": [{"geometry": GEOMETRY_EXAMPLE, "report": REPORT_EXAMPLE}]}
    )

    geometry: GeometryJsonDict = Field(
        description="Smoothed geometry in the JSON format (same schema as the input)."
    )
    report: ReportDict = Field(description="Diagnostics.")
