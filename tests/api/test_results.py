"""Downloads are pinned: a DELETE of the job while its result streams cannot cut it short.

(schemathesis found it with two workers: ``GET /result`` and ``DELETE`` of the same job at once
gave "the server declared chunked encoding but sent an invalid chunk".)
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import httpx
import numpy as np

from service.api.results import PIN_PREFIX, pin_file
from tests.api.api_helpers import LiveServer, encode, noisy_plane_cloud, parse_points, wait_done


def test_a_pinned_file_outlives_its_original(tmp_path: Path) -> None:
    original = tmp_path / "jobs" / "result.xyz"
    original.parent.mkdir()
    original.write_bytes(b"1 2 3\n" * 1000)
    spool = tmp_path / "spool"
    pin = pin_file(original, spool)
    assert pin is not None and pin.parent == spool and pin.name.startswith(PIN_PREFIX)
    assert os.stat(pin).st_ino == os.stat(original).st_ino  # a hard link, not a copy
    original.unlink()  # the job is deleted meanwhile
    assert pin.read_bytes() == b"1 2 3\n" * 1000
    assert pin_file(original, spool) is None  # already gone: the route answers 404


def test_download_then_delete_leaves_no_pin(server: LiveServer, client: httpx.Client) -> None:
    pts = noisy_plane_cloud(3000, seed=11)
    r = client.post(
        "/v1/jobs",
        files={"file": ("p.xyz", encode("xyz", pts, None))},
        data={"params": json.dumps({"lam": 1.0})},
    )
    assert r.status_code == 202, r.text
    job = wait_done(client, r.json()["id"])
    assert job["status"] == "succeeded", job
    with client.stream("GET", f"/v1/jobs/{job['id']}/result") as response:
        assert response.status_code == 200
        chunks = response.iter_bytes(1024)
        first = next(chunks)
        assert client.delete(f"/v1/jobs/{job['id']}").status_code in (200, 204)
        body = first + b"".join(chunks)
    assert len(body) == int(response.headers["content-length"])
    assert parse_points(body, "xyz").shape == pts.shape
    spool = server.data_dir / "spool"
    deadline = time.monotonic() + 10  # removed by the response's background task, just after
    while list(spool.glob(f"{PIN_PREFIX}*")) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not list(spool.glob(f"{PIN_PREFIX}*")), "the pinned name was not removed"
    assert np.isfinite(parse_points(body, "xyz")).all()
