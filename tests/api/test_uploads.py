"""Uploads from every client: params as a field or a JSON file part, the format from the name,
the part's type or the content, and Swagger UI's "Try it out" replayed for every operation."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from tests.api.api_helpers import ROOT, encode, noisy_sphere, parse_points, wait_done
from tests.shared_data import shared_data_dir

PTS, FACES = noisy_sphere(1)
SPEC = json.loads((ROOT / "openapi" / "openapi.json").read_text())
BUNNY = shared_data_dir() / "bunny.ply"
SAMPLE = ROOT / "service" / "samples" / "noisy-sphere.ply"


def _accepted(r: httpx.Response) -> dict[str, Any]:
    assert r.status_code == 202, r.text
    return r.json()  # type: ignore[no-any-return]


@pytest.mark.parametrize("how", ["field", "json-file-part", "blob-part", "curl-style"])
def test_params_as_a_form_field_or_a_json_file_part(client: httpx.Client, how: str) -> None:
    params = json.dumps({"tau": 0.05})
    data = encode("ply", PTS, FACES)
    files: dict[str, Any] = {"file": ("s.ply", data)}
    form: dict[str, str] = {}
    if how == "field":
        form["params"] = params
    elif how == "json-file-part":  # httpx / requests with a named part
        files["params"] = ("params.json", params, "application/json")
    elif how == "blob-part":  # what Swagger UI sends for a JSON-encoded multipart member
        files["params"] = ("blob", params.encode(), "application/json")
    else:  # curl -F params=@p.json;type=application/json
        files["params"] = ("p.json", params.encode(), "application/json")
    job = _accepted(client.post("/v1/jobs", files=files, data=form))
    done = wait_done(client, job["id"])
    assert done["status"] == "succeeded" and done["params"]["tau"] == 0.05


@pytest.mark.parametrize(
    ("name", "part_type", "fmt"),
    [
        ("upload", "model/obj", "obj"),  # no extension: the part's content type
        ("upload", "application/octet-stream", "ply"),  # generic type: the content (PLY magic)
        ("scan", None, "xyz"),  # no type at all: the content (numbers)
    ],
)
def test_format_from_part_type_or_content(
    client: httpx.Client, name: str, part_type: str | None, fmt: str
) -> None:
    data = encode(fmt, PTS, FACES if fmt != "xyz" else None)
    part = (name, data, part_type) if part_type else (name, data)
    params = {"params": json.dumps({"rms": 0.005, "neighborhood": "knn"})}
    job = _accepted(client.post("/v1/jobs", files={"file": part}, data=params))
    assert job["format"] == fmt
    done = wait_done(client, job["id"])
    assert done["status"] == "succeeded", done
    out = parse_points(client.get(f"/v1/jobs/{job['id']}/result").content, fmt)
    assert out.shape == PTS.shape


@pytest.mark.parametrize(
    ("params", "field"),
    [
        ('{"tau": ' + "9" * 5000 + "}", "params"),  # beyond Python's 4,300-digit int limit
        ('{"tau": ' + "[" * 5000 + "]" * 5000 + "}", "params"),
        ('{"tau": 1e400}', "params.tau"),
        ('{"tau": NaN}', "params.tau"),
        ('{"lam": 1, "max_iterations": true}', "params.max_iterations"),  # true is not 1
    ],
)
def test_hostile_params_are_422(client: httpx.Client, params: str, field: str) -> None:
    r = client.post(
        "/v1/jobs", files={"file": ("s.ply", encode("ply", PTS, FACES))}, data={"params": params}
    )
    assert r.status_code == 422, r.text
    assert r.headers["content-type"] == "application/problem+json"
    assert r.json()["field"] == field
    big = b'{"geometry": {"points": [[' + b"1" * 5000 + b', 0, 0]]}, "params": {"lam": 1}}'
    r = client.post("/v1/jobs", content=big, headers={"content-type": "application/json"})
    assert r.status_code in (400, 422) and r.json()["field"] in ("body", "geometry")


# --------------------------------------------------------------------------- Swagger UI


def _swagger_parameters(operation: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """Path and query values Swagger UI prefills: the example, else the default, else none."""
    path: dict[str, Any] = {}
    query: dict[str, Any] = {}
    for param in operation.get("parameters", []):
        schema = param.get("schema", {})
        value = param.get("example", schema.get("example", schema.get("default")))
        if value is None and schema.get("examples"):  # OpenAPI 3.1: JSON Schema examples
            value = schema["examples"][0]
        if value is None:
            continue
        (path if param["in"] == "path" else query)[param["name"]] = value
    return path, query


def _swagger_body(operation: dict[str, Any], file: Path) -> dict[str, Any]:
    """The body Swagger UI sends: the first media type, prefilled from its examples."""
    content = operation["requestBody"]["content"]
    media = next(iter(content))
    assert media == "multipart/form-data"
    form: dict[str, str] = {}
    for name, prop in content[media]["schema"]["properties"].items():
        value = prop.get("example", prop.get("default"))
        if name != "file" and value is not None:
            form[name] = json.dumps(value) if isinstance(value, bool) else str(value)
    return {"files": {"file": (file.name, file.read_bytes())}, "data": form}


def _documented(operation: dict[str, Any], r: httpx.Response) -> None:
    assert str(r.status_code) in operation["responses"], (r.status_code, r.text[:300])
    assert r.status_code < 500, r.text


def test_swagger_try_it_out_works_for_every_operation(client: httpx.Client) -> None:
    """Replays the request Swagger UI builds from the committed spec for each operation."""
    files = [SAMPLE] + ([BUNNY] if BUNNY.exists() else [])
    created: list[str] = []
    for route, operations in SPEC["paths"].items():
        for method, operation in operations.items():
            path_values, query = _swagger_parameters(operation)
            url = route.format(**path_values)
            kwargs: dict[str, Any] = {"params": query}
            for file in files if "requestBody" in operation else [None]:
                if file is not None:
                    kwargs.update(_swagger_body(operation, file))
                r = client.request(method.upper(), url, **kwargs)
                _documented(operation, r)
                if file is not None:  # the prefilled example is accepted as is (or is too
                    # large for the synchronous endpoint of the test server: 2000 points)
                    big = route == "/v1/smooth" and file == BUNNY
                    assert r.status_code in ((413,) if big else (200, 202)), r.text
                if route == "/v1/jobs" and method == "post":
                    created.append(r.json()["id"])
    assert len(created) == len(files)
    for job_id, file in zip(created, files, strict=True):
        done = wait_done(client, job_id, timeout=120)
        assert done["status"] == "succeeded", done
        _assert_not_melted(file, client.get(f"/v1/jobs/{job_id}/result").content)


def _assert_not_melted(original: Path, smoothed: bytes) -> None:
    """The example smooths gently: points move far less than the model's size."""
    before, after = parse_points(original.read_bytes(), "ply"), parse_points(smoothed, "ply")
    size = float(np.linalg.norm(before.max(axis=0) - before.min(axis=0)))
    moved = np.linalg.norm(after - before, axis=1)
    assert float(np.sqrt(np.mean(moved**2))) < 0.02 * size, (original.name, moved.max(), size)


def test_swagger_json_example_is_accepted_and_succeeds(client: httpx.Client) -> None:
    for route in ("/v1/jobs", "/v1/smooth"):
        content = SPEC["paths"][route]["post"]["requestBody"]["content"]["application/json"]
        r = client.post(route, json=content["example"])
        assert r.status_code in (200, 202), r.text
        if route == "/v1/jobs":
            assert wait_done(client, r.json()["id"])["status"] == "succeeded"


def test_no_example_prefills_a_tau(client: httpx.Client) -> None:
    """Swagger UI prefills examples: none of the request examples may carry a fixed tau that
    would collapse a real model (the issue's {"tau": 0.5} melted the bunny)."""
    for route in ("/v1/jobs", "/v1/smooth"):
        form = SPEC["paths"][route]["post"]["requestBody"]["content"]["multipart/form-data"]
        example = json.loads(form["schema"]["properties"]["params"]["example"])
        assert "tau" not in example and "rms" not in example, example
