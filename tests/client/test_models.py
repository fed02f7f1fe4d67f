"""The client's hand-written models against the committed OpenAPI document (openapi/openapi.json).

Every schema the client mirrors must match field by field: each member of the spec is a field
of the client (so no data is dropped) with a compatible type, and each field of the client is in
the spec, except members of the cross-helper contract (docs CONTRACTS.md) that services send
before the committed spec documents them (``PENDING``: empty it as the spec catches up).
"""

from __future__ import annotations

import dataclasses
import json
import types
import typing
from datetime import datetime
from pathlib import Path
from typing import Any

import pytest
from geosmooth_client import errors, models
from geosmooth_client.models import wire_name

SPEC = json.loads(
    (Path(__file__).resolve().parents[2] / "openapi" / "openapi.json").read_text("utf-8")
)
SCHEMAS: dict[str, Any] = SPEC["components"]["schemas"]

#: Members of the contract (progress dict, JobRecord.public_dict, events link) the spec may
#: not list yet.
PENDING = {
    "JobProgress": {"stage", "percent", "eta_seconds", "elapsed_seconds"},
    "Job": {"max_attempts", "weld", "webhook_url"},
    "JobLinks": {"events"},
}
MIRRORED = {
    "Job": models.Job,
    "JobProgress": models.JobProgress,
    "JobProblem": models.JobProblem,
    "JobLinks": models.JobLinks,
    "JobList": models.JobList,
    "PageLinks": models.PageLinks,
    "FieldError": errors.FieldError,
}
_JSON_TYPES = {str: "string", int: "integer", float: "number", bool: "boolean"}


def _spec_types(prop: dict[str, Any]) -> set[str]:
    """JSON types a property allows (``$ref`` -> the schema name)."""
    if "$ref" in prop:
        return {prop["$ref"].rsplit("/", 1)[-1]}
    if "anyOf" in prop:
        return set().union(*(_spec_types(p) for p in prop["anyOf"]))
    kind = prop.get("type")
    if kind == "string" and prop.get("format") == "date-time":
        return {"date-time"}
    return {kind} if kind else set()


def _client_types(annotation: Any) -> set[str]:
    """JSON types a client annotation accepts, in the spec's vocabulary."""
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        return set().union(*(_client_types(a) for a in typing.get_args(annotation)))
    if annotation is type(None):
        return {"null"}
    if origin is typing.Literal:
        return {"string"}
    if origin is dict or annotation is dict:
        return {"object"}
    if origin is list or annotation is list:
        return {"array"}
    if annotation is datetime:
        return {"date-time"}
    if annotation is models.Report:
        return {"Report"}
    if isinstance(annotation, type) and dataclasses.is_dataclass(annotation):
        return {annotation.__name__}
    return {_JSON_TYPES[annotation]}


def _client_fields(cls: type) -> dict[str, set[str]]:
    hints = typing.get_type_hints(cls, vars(models) | vars(errors))
    return {
        wire_name(f): _client_types(hints[f.name])
        for f in dataclasses.fields(cls)
        if f.name != "extra"
    }


@pytest.mark.parametrize("schema", sorted(MIRRORED))
def test_fields_and_types_match_the_spec(schema: str) -> None:
    spec = SCHEMAS[schema]["properties"]
    client = _client_fields(MIRRORED[schema])
    pending = PENDING.get(schema, set())
    assert set(spec) <= set(client), f"{schema}: the client lacks {set(spec) - set(client)}"
    extra = set(client) - set(spec)
    assert extra <= pending, f"{schema}: not in the spec: {extra - pending}"
    for name, prop in spec.items():
        # the client may be laxer (None where the spec requires a value), never stricter
        allowed = _spec_types(prop) - {"null"}
        assert allowed <= client[name], (schema, name, allowed, client[name])


def test_required_members_have_no_client_default_where_it_matters() -> None:
    """Members the spec requires of a job are required by the client's constructor too."""
    required = set(SCHEMAS["Job"].get("required", []))
    no_default = {
        wire_name(f)
        for f in dataclasses.fields(models.Job)
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    }
    assert no_default <= required and {"id", "status"} <= no_default


def test_report_attributes_name_documented_members() -> None:
    documented = set(SCHEMAS["Report"]["properties"])
    assert set(models.Report.ATTRIBUTES.values()) <= documented


def test_every_documented_report_member_is_an_attribute() -> None:
    """The attributes are generated from the spec (``make openapi``): none is missing."""
    documented = list(SCHEMAS["Report"]["properties"])
    assert list(models.Report.ATTRIBUTES.values()) == documented
    assert models.Report.ATTRIBUTES["lam"] == "lambda"
    report = models.Report(SCHEMAS["Report"]["examples"][0])
    assert report.lam == report["lambda"] and report.plan is None and report.tiles is None


def test_problem_members_are_attributes_of_api_errors() -> None:
    problem = SCHEMAS["Problem"]["properties"]
    example = SCHEMAS["Problem"]["examples"][0]
    exc = errors.error_class(example["status"])(example["status"], example)
    for name in problem:
        assert hasattr(exc, name), name
        assert name not in example or name == "errors" or getattr(exc, name) == example[name]
    assert isinstance(exc, errors.InvalidInput) and exc.field == "params.tau"
    assert exc.errors[0] == errors.FieldError("params.tau", example["errors"][0]["message"],
                                              "greater_than")  # fmt: skip


def test_statuses_in_the_spec_have_typed_errors() -> None:
    """Every 4xx/5xx the spec documents is an ApiError; the usual ones have their own class."""
    statuses = {
        int(code)
        for path in SPEC["paths"].values()
        for op in path.values()
        for code in op.get("responses", {})
        if code.isdigit() and int(code) >= 400
    }
    assert statuses, "the spec documents no error status"
    own = {400, 401, 403, 404, 409, 413, 415, 422, 429, 503, 507}
    for status in statuses | own:
        cls = errors.error_class(status)
        assert issubclass(cls, errors.ApiError)
        if status in own:
            assert cls.status == status, status
        elif status >= 500:
            assert issubclass(cls, errors.ServerError), status


def test_job_round_trip_of_the_spec_example() -> None:
    example = SCHEMAS["JobList"]["examples"][0]
    page = models.JobList.from_dict(example)
    job = page.items[0]
    assert job.status == "succeeded" and job.finished and job.format == "ply"
    assert job.created_at is not None and job.created_at.tzinfo is not None
    links = models.JobLinks.for_job(job.id)
    assert (job.links.status, job.links.result, job.links.report) == (  # type: ignore[union-attr]
        links.status, links.result, links.report
    )
    progress = models.JobProgress.from_dict(SCHEMAS["JobProgress"]["examples"][0])
    assert (progress.iteration, progress.lam, progress.phi) == (3, 0.011, 0.47)


def test_report_reads_the_displacement_measurements_under_old_and_new_names() -> None:
    """``max_displacement`` is the measurement (``max_deviation`` is the parameter's bound); a
    report from a service that still sent ``max_deviation`` reads the same."""
    from geosmooth_client.models import Report

    new = Report({"max_displacement": 0.5, "rms_displacement": 0.1})
    old = Report({"max_deviation": 0.5, "rms_deviation": 0.1})
    for report in (new, old):
        assert report.max_displacement == 0.5 and report.rms_displacement == 0.1
        assert report.max_deviation == 0.5 and report.rms_deviation == 0.1
