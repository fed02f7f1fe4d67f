"""Issue 24 item 2: every HTML page carries a CSP with ``frame-ancestors 'none'`` and every
response ``X-Content-Type-Options: nosniff`` (live server; pages, API answers, errors, results)."""

from __future__ import annotations

import json

import httpx
import pytest

from tests.api.api_helpers import LiveServer, encode, noisy_plane_cloud, wait_done

PAGES = ["/", "/static/index.html", "/docs", "/redoc", "/docs/oauth2-redirect"]


def _directives(csp: str) -> dict[str, str]:
    return {d.strip().split(" ", 1)[0]: d.strip() for d in csp.split(";") if d.strip()}


@pytest.mark.parametrize("path", PAGES)
def test_every_page_forbids_framing(client: httpx.Client, path: str) -> None:
    r = client.get(path)
    assert r.status_code == 200
    assert r.headers["content-type"].startswith("text/html")
    csp = _directives(r.headers["content-security-policy"])
    assert csp["frame-ancestors"] == "frame-ancestors 'none'"
    assert csp["default-src"] == "default-src 'self'"
    assert r.headers["x-frame-options"] == "DENY"
    assert r.headers["x-content-type-options"] == "nosniff"


def test_every_response_is_nosniff(server: LiveServer, client: httpx.Client) -> None:
    cloud = noisy_plane_cloud(200, seed=4)
    answers = [
        client.get("/healthz"),
        client.get("/readyz"),
        client.get("/openapi.json"),
        client.get("/static/app.css"),
        client.get("/v1/jobs/does-not-exist"),  # problem+json
        client.post("/v1/jobs", content=b"{", headers={"content-type": "application/json"}),
        client.options("/v1/jobs"),
    ]
    submit = client.post(
        "/v1/jobs",
        files={"file": ("c.xyz", encode("xyz", cloud, None))},
        data={"params": json.dumps({"lam": 1.0})},
    )
    answers.append(submit)
    job = wait_done(client, submit.json()["id"])
    assert job["status"] == "succeeded", job
    answers.append(client.get(f"/v1/jobs/{job['id']}/result"))
    with httpx.Client(base_url=server.url, headers={"host": "evil.example"}) as evil:
        answers.append(evil.get("/healthz"))  # refused by the Host guard (400)
    assert {r.status_code for r in answers} >= {200, 202, 400, 404}
    for r in answers:
        assert r.headers.get("x-content-type-options") == "nosniff", (r.request.url, r.headers)
        if not r.headers.get("content-type", "").startswith("text/html"):
            assert "x-frame-options" not in r.headers
