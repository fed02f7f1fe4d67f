"""The committed OpenAPI document is the app's, and it documents everything."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from service.api.app import create_app
from service.api.openapi_export import CLIENT_FIELDS, client_report_fields, openapi_spec, render
from service.settings import Settings

ROOT = Path(__file__).resolve().parents[2]
COMMITTED = ROOT / "openapi" / "openapi.json"


def test_committed_openapi_is_not_stale() -> None:
    committed = json.loads(COMMITTED.read_text())
    assert committed == create_app().openapi(), (
        "openapi/openapi.json is stale: run `make openapi` and commit the result"
    )
    assert COMMITTED.read_text() == render(openapi_spec())


def test_client_report_fields_are_generated_from_the_committed_spec() -> None:
    """The client's list of report members is the export step's, from openapi/openapi.json."""
    assert CLIENT_FIELDS == ROOT / "clients/python/geosmooth_client/_report_fields.py"
    assert CLIENT_FIELDS.read_text() == client_report_fields(json.loads(COMMITTED.read_text())), (
        f"{CLIENT_FIELDS.relative_to(ROOT)} is stale: run `make openapi` and commit the result"
    )


def test_spec_does_not_depend_on_the_environment(tmp_path: Path) -> None:
    env = {**os.environ, "GEOSMOOTH_SYNC_MAX_POINTS": "7", "GEOSMOOTH_WORKERS": "9"}
    out, client = tmp_path / "spec.json", tmp_path / "fields.py"
    subprocess.run(
        [sys.executable, "-m", "service.api.openapi_export", str(out), "--client", str(client)],
        cwd=ROOT,
        env=env,
        check=True,
        timeout=60,
    )
    assert out.read_text() == COMMITTED.read_text()
    assert client.read_text() == CLIENT_FIELDS.read_text()
    assert create_app(Settings(sync_max_points=7)).openapi() == json.loads(COMMITTED.read_text())


def test_every_operation_and_schema_is_documented() -> None:
    spec = json.loads(COMMITTED.read_text())
    for path, operations in spec["paths"].items():
        for method, op in operations.items():
            where = f"{method.upper()} {path}"
            assert op.get("summary") and op.get("description"), where
            for status, answer in op["responses"].items():
                assert answer.get("description"), f"{where} {status}"
                if status.startswith(("4", "5")):
                    assert "application/problem+json" in answer.get("content", {}), (
                        f"{where} {status} is not documented as problem details"
                    )
            for param in op.get("parameters", []):
                assert param.get("description"), f"{where} parameter {param['name']}"
    for name, schema in spec["components"]["schemas"].items():
        assert schema.get("description"), name
        has_examples = "examples" in schema or all(
            "examples" in p or "example" in p or "$ref" in p
            for p in schema.get("properties", {}).values()
        )
        assert has_examples, f"schema {name} has no examples"
    assert "HTTPValidationError" not in spec["components"]["schemas"]
