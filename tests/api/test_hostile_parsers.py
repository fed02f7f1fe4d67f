"""Issue 42 finding 4 on a live server: the four files that gave HTTP 500 (``internal``) on
``/v1/jobs``, ``/v1/smooth`` and ``/v1/info`` are 4xx problem+json naming the field."""

from __future__ import annotations

import json

import httpx
import pytest

from tests.io.hostile_files import parser_cases

STATUS = {  # file: (HTTP status, code, words of the detail)
    "big_integer.geojson": (400, "format-error", "coordinate is out of range"),
    "ele_1e308.gpx": (422, "non-finite-coordinates", "span 1e+308"),
    "non_utf8.dxf": (400, "format-error", "damaged beyond recovery"),
    "chunk_table.laz": (400, "format-error", "declares 3254779905 chunks"),
}


@pytest.mark.parametrize("name", sorted(STATUS))
def test_the_four_files_are_typed_4xx_on_every_channel(client: httpx.Client, name: str) -> None:
    status, code, words = STATUS[name]
    files = {"file": (name, parser_cases()[name])}
    params = {"params": json.dumps({"lam": 1.0})}
    answers = {
        "jobs": client.post("/v1/jobs", files=files, data=params),
        "smooth": client.post("/v1/smooth", files=files, data=params),
        "info": client.post("/v1/info", files=files),
    }
    for channel, r in answers.items():
        assert r.status_code == status, (channel, r.text)
        assert r.headers["content-type"].startswith("application/problem+json"), channel
        body = r.json()
        assert body["code"] == code and words in body["detail"], (channel, body)
        assert body.get("field") or body.get("errors"), (channel, body)  # names the field
    assert client.get("/readyz").status_code == 200  # the server is still there
