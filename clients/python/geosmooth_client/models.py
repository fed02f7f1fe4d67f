"""The service's JSON objects as typed, immutable Python objects.

Each class mirrors one schema of the service's OpenAPI document (``openapi/openapi.json``);
a test compares every field's wire name and type with the committed spec. The classes are
hand-written; the report's members (``Report.ATTRIBUTES``) are generated from the spec by
``make openapi`` (:mod:`geosmooth_client._report_fields`). A field whose JSON
name is not a Python identifier (``lambda``) says so in its ``wire`` metadata. Members the
service adds later are kept in ``extra`` instead of being dropped, so an older client still
round-trips newer answers.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Mapping
from datetime import datetime
from typing import Any, Literal, get_args

from geosmooth_client._report_fields import REPORT_ATTRIBUTES

__all__ = [
    "FINISHED",
    "Job",
    "JobLinks",
    "JobList",
    "JobProblem",
    "JobProgress",
    "JobStatus",
    "PageLinks",
    "Report",
    "wire_name",
]

JobStatus = Literal["queued", "running", "succeeded", "failed", "cancelled"]
#: Statuses a job never leaves.
FINISHED: frozenset[str] = frozenset({"succeeded", "failed", "cancelled"})
_STATUSES = frozenset(get_args(JobStatus))


def _wire(name: str) -> Any:
    return dataclasses.field(default=None, metadata={"wire": name})


def wire_name(f: dataclasses.Field[Any]) -> str:
    """The JSON member name of a dataclass field."""
    return str(f.metadata.get("wire", f.name))


def _fields(cls: type) -> list[dataclasses.Field[Any]]:
    return [f for f in dataclasses.fields(cls) if f.name != "extra"]


def _split(cls: type, data: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """Known members by Python field name, and the rest (``extra``)."""
    known = {wire_name(f): f.name for f in _fields(cls)}
    values = {known[k]: v for k, v in data.items() if k in known}
    extra = {k: v for k, v in data.items() if k not in known}
    return values, extra


def _time(value: Any) -> datetime | None:
    if not value:
        return None
    return datetime.fromisoformat(str(value).replace("Z", "+00:00"))


def _float(value: Any) -> float | None:
    return None if value is None else float(value)


def _int(value: Any) -> int | None:
    return None if value is None else int(value)


def _str(value: Any) -> str | None:
    return None if value is None else str(value)


def _progress_value(name: str, value: Any) -> Any:
    if name == "stage":
        return _str(value)
    return _int(value) if name == "iteration" else _float(value)


@dataclasses.dataclass(frozen=True)
class JobProgress:
    """Progress of a running job (schema ``JobProgress``).

    ``stage`` and the timing members are sent by services that report progress from the first
    stage on; older ones send only the lambda iterations of the tau search.
    """

    iteration: int | None = None
    lam: float | None = _wire("lambda")
    phi: float | None = None
    tau: float | None = None
    relative_error: float | None = None
    stage: str | None = None
    percent: float | None = None
    eta_seconds: float | None = None
    elapsed_seconds: float | None = None
    extra: dict[str, Any] = dataclasses.field(default_factory=dict)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> JobProgress:
        values, extra = _split(cls, data)
        if "lam" in data and "lam" not in values:  # the queue's own spelling
            values["lam"] = data["lam"]
            extra.pop("lam", None)
        return cls(**{k: _progress_value(k, v) for k, v in values.items()}, extra=extra)


@dataclasses.dataclass(frozen=True)
class JobProblem:
    """Why a job failed (schema ``JobProblem``); extension members are in ``extra``."""

    type: str = "about:blank"
    title: str = "Job failed"
    detail: str = ""
    code: str | None = None
    field: str | None = None
    extra: dict[str, Any] = dataclasses.field(default_factory=dict)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> JobProblem:
        values, extra = _split(cls, data)
        return cls(**{k: v for k, v in values.items() if v is not None}, extra=extra)


@dataclasses.dataclass(frozen=True)
class JobLinks:
    """Relative URLs of a job's status, result and report (schema ``JobLinks``)."""

    status: str
    result: str
    report: str
    events: str | None = None
    extra: dict[str, Any] = dataclasses.field(default_factory=dict)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> JobLinks:
        values, extra = _split(cls, data)
        return cls(**values, extra=extra)

    @classmethod
    def for_job(cls, job_id: str) -> JobLinks:
        base = f"/v1/jobs/{job_id}"
        return cls(base, f"{base}/result", f"{base}/report", f"{base}/events")


class Report(Mapping[str, Any]):
    """Diagnostics of a run, exactly as the service sent them (schema ``Report``).

    A read-only mapping (``report["lambda"]``, ``dict(report)``, ``json.dumps(dict(report))``)
    whose common members are also attributes. Members a newer engine adds are in the mapping.
    """

    #: attribute -> JSON member: every member of the spec's ``Report`` (generated, ``lam`` for
    #: ``lambda``).
    ATTRIBUTES: Mapping[str, str] = REPORT_ATTRIBUTES
    #: JSON member -> the name a service before 2026-11 sent (read when the new one is absent).
    FORMERLY: Mapping[str, str] = {
        "rms_displacement": "rms_deviation",
        "max_displacement": "max_deviation",
    }
    #: Deprecated attributes -> current ones.
    ALIASES: Mapping[str, str] = {
        "rms_deviation": "rms_displacement",
        "max_deviation": "max_displacement",
    }

    def __init__(self, data: Mapping[str, Any]) -> None:
        self._data = dict(data)

    def __getitem__(self, key: str) -> Any:
        return self._data[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __getattr__(self, name: str) -> Any:
        cls = type(self)
        key = cls.ATTRIBUTES.get(cls.ALIASES.get(name, name))
        if key is None:
            raise AttributeError(name)
        if key not in self._data and key in cls.FORMERLY:
            return self._data.get(cls.FORMERLY[key])
        return self._data.get(key)

    def __repr__(self) -> str:
        return f"Report({self._data!r})"


@dataclasses.dataclass(frozen=True)
class Job:
    """A smoothing job (schema ``Job``)."""

    id: str
    status: JobStatus
    input_format: str | None = None
    format: str | None = None  # deprecated name of input_format (services before 2026-11)
    filename: str | None = None
    created_at: datetime | None = None
    started_at: datetime | None = None
    finished_at: datetime | None = None
    params: dict[str, Any] | None = None
    progress: JobProgress | None = None
    report: Report | None = None
    error: JobProblem | None = None
    attempts: int = 0
    run_seconds: float | None = None
    expires_at: datetime | None = None
    links: JobLinks | None = None
    max_attempts: int | None = None
    weld: bool | None = None
    webhook_url: str | None = None
    extra: dict[str, Any] = dataclasses.field(default_factory=dict)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Job:
        values, extra = _split(cls, data)
        status = str(values.get("status"))
        if status not in _STATUSES:
            raise ValueError(f"unknown job status {status!r}")
        if values.get("input_format") is None:  # a service before 2026-11: "format" only
            values["input_format"] = values.get("format")
        for key in ("created_at", "started_at", "finished_at", "expires_at"):
            values[key] = _time(values.get(key))
        if values.get("progress") is not None:
            values["progress"] = JobProgress.from_dict(values["progress"])
        if values.get("error") is not None:
            values["error"] = JobProblem.from_dict(values["error"])
        if values.get("report") is not None:
            values["report"] = Report(values["report"])
        if values.get("links") is not None:
            values["links"] = JobLinks.from_dict(values["links"])
        values["attempts"] = int(values.get("attempts") or 0)
        values["run_seconds"] = _float(values.get("run_seconds"))
        return cls(**values, extra=extra)

    @property
    def finished(self) -> bool:
        """Whether the job reached a final status."""
        return self.status in FINISHED

    def with_progress(self, progress: JobProgress) -> Job:
        """This job, running, with newer progress (from an events stream)."""
        status: JobStatus = "running" if self.status == "queued" else self.status
        return dataclasses.replace(self, status=status, progress=progress)


@dataclasses.dataclass(frozen=True)
class PageLinks:
    """Neighbouring pages of a job list (schema ``PageLinks``)."""

    next: str | None = None
    prev: str | None = None


@dataclasses.dataclass(frozen=True)
class JobList:
    """A page of jobs, newest first (schema ``JobList``)."""

    items: list[Job]
    total: int
    offset: int
    limit: int
    links: PageLinks = dataclasses.field(default_factory=PageLinks)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> JobList:
        links = data.get("links") or {}
        return cls(
            items=[Job.from_dict(item) for item in data.get("items", [])],
            total=int(data.get("total", 0)),
            offset=int(data.get("offset", 0)),
            limit=int(data.get("limit", 0)),
            links=PageLinks(links.get("next"), links.get("prev")),
        )
