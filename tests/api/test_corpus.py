"""The malformed-and-extreme corpus (:mod:`api_corpus`) through the upload endpoint and the
synchronous endpoint: the expected status, problem details naming the field at fault, and no
NaN or infinity in any answer, job or result."""

from __future__ import annotations

import json
import math
from typing import Any

import httpx
import pytest

from tests.api.api_corpus import corpus
from tests.api.api_helpers import ROOT, wait_done

PROBLEM = "application/problem+json"
CORPUS = corpus()
PARAMS = json.dumps({"lam": 1.0})


def _finite(obj: Any) -> bool:
    if isinstance(obj, float):
        return math.isfinite(obj)
    if isinstance(obj, dict):
        return all(_finite(v) for v in obj.values())
    if isinstance(obj, list):
        return all(_finite(v) for v in obj)
    return True


def _check_answer(r: httpx.Response, expected: frozenset[str], ok: int) -> str:
    kind = "ok" if r.status_code == ok else str(r.status_code)
    assert kind in expected, (r.status_code, r.text[:400])
    if kind != "ok":
        assert r.headers["content-type"] == PROBLEM
        body = r.json()
        assert body["status"] == r.status_code and body["detail"] and body.get("field"), body
    assert "NaN" not in r.text and "Infinity" not in r.text
    return kind


@pytest.mark.parametrize(
    ("name", "filename", "data", "expected"), CORPUS, ids=[c[0] for c in CORPUS]
)
def test_corpus_through_upload_and_sync(
    client: httpx.Client, name: str, filename: str, data: bytes, expected: frozenset[str]
) -> None:
    files = {"file": (filename, data)}
    sync = client.post(
        "/v1/smooth", files=files, data={"params": PARAMS}, params={"format": "json"}
    )
    if _check_answer(sync, expected, 200) == "ok":
        assert _finite(sync.json()), name
    submit = client.post("/v1/jobs", files=files, data={"params": PARAMS})
    if _check_answer(submit, expected, 202) == "ok":
        job = wait_done(client, submit.json()["id"], timeout=120)
        assert _finite(job)
        if job["status"] == "failed":  # a clear problem, never an internal error
            assert job["error"]["code"] not in ("internal-error", "worker-crashed"), job["error"]
        else:
            assert job["status"] == "succeeded", job
            result = client.get(f"/v1/jobs/{job['id']}/result", params={"format": "json"})
            assert result.status_code == 200 and _finite(result.json())


# --------------------------------------------------------------------------- the io corpus

IO_CORPUS = ROOT / "tests" / "corpus"
IO_FILES = json.loads((IO_CORPUS / "manifest.json").read_text()) if IO_CORPUS.is_dir() else []


@pytest.mark.parametrize("entry", IO_FILES, ids=[e["file"] for e in IO_FILES])
def test_io_corpus_through_upload_and_sync(client: httpx.Client, entry: dict[str, Any]) -> None:
    """Every malformed file of the io helper's corpus: a 4xx with the reader's problem code."""
    data = (IO_CORPUS / "files" / entry["file"]).read_bytes()
    files = {"file": (entry["file"], data)}
    for path in ("/v1/smooth", "/v1/jobs"):
        r = client.post(path, files=files, data={"params": PARAMS})
        assert 400 <= r.status_code < 500, (path, r.status_code, r.text[:300])
        assert r.headers["content-type"] == PROBLEM
        body = r.json()
        assert body["code"] == entry["code"] and body.get("field"), (path, body)
        assert "NaN" not in r.text and "Infinity" not in r.text
