"""Issue 42 finding 8: the data directory removed under a live server. Before: ``/readyz`` 200
(the spool check made the directory again) and every submit 500 (``FileNotFoundError``)."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path

from tests.api.api_helpers import LiveServer

XYZ = b"0 0 0\n1 0 0\n0 1 0\n1 1 0.1\n0.5 0.5 0.02\n2 0 0\n0 2 0\n2 2 0\n"


def test_a_removed_data_directory_is_503_not_500(
    make_server: Callable[..., LiveServer], tmp_path: Path
) -> None:
    data = tmp_path / "data"
    live = make_server(data_dir=data)
    with live.client() as c:
        assert c.get("/readyz").status_code == 200
        shutil.rmtree(data)
        ready = c.get("/readyz")
        assert ready.status_code == 503, ready.text
        checks = ready.json()["checks"]
        assert checks["database"] == "missing" and checks["storage"] != "ok", checks
        r = c.post("/v1/jobs", files={"file": ("p.xyz", XYZ)},
                   data={"params": json.dumps({"lam": 1.0})})  # fmt: skip
        assert r.status_code == 503, r.text
        assert r.headers["content-type"].startswith("application/problem+json")
        assert r.json()["code"] in ("storage-unavailable", "not-ready"), r.json()
        assert c.get("/healthz").status_code == 200  # alive, not ready
