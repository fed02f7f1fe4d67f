"""Issue 24 item 9: what a SIGKILL mid-upload leaves (a partial spool file, an orphan job
directory) is swept when the next server starts and no live process uses the data directory;
while another server shares it, its fresh files are left alone."""

from __future__ import annotations

import socket
import time
import uuid
from collections.abc import Callable
from pathlib import Path

from tests.api.api_helpers import LiveServer


def _wait(predicate: Callable[[], bool], timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.05)
    return predicate()


def _partial_upload(live: LiveServer) -> socket.socket:
    """A multipart upload that announces 1 MiB and sends 64 KiB of it (left open)."""
    boundary = "b0undary"
    head = (
        f'--{boundary}\r\nContent-Disposition: form-data; name="file"; filename="a.xyz"\r\n'
        "Content-Type: text/plain\r\n\r\n"
    ).encode()
    sock = socket.create_connection(("127.0.0.1", live.port), 30)
    sock.sendall(
        (
            f"POST /v1/jobs HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: {2**20}\r\n"
            f"Content-Type: multipart/form-data; boundary={boundary}\r\n\r\n"
        ).encode()
        + head
        + b"0 0 0\n" * 10923
    )
    return sock


def _orphan(data_dir: Path) -> Path:
    """A job directory with an input and no record (a crash between the two)."""
    job = data_dir / "jobs" / uuid.uuid4().hex
    job.mkdir(parents=True)
    (job / "input.xyz").write_text("0 0 0\n")
    return job


def test_leftovers_of_a_killed_server_are_swept_at_start(
    make_server: Callable[..., LiveServer], tmp_path: Path
) -> None:
    data_dir = tmp_path / "shared"
    first = make_server(data_dir=data_dir)
    sock = _partial_upload(first)
    spool = data_dir / "spool"
    assert _wait(lambda: any(spool.glob("upload-*")), 60), first.log()
    first.kill()  # SIGKILL mid-upload
    sock.close()
    orphan = _orphan(data_dir)
    partial = list(spool.glob("upload-*"))
    assert partial and orphan.is_dir()
    second = make_server(data_dir=data_dir)  # alone on the data directory: sweeps at once
    assert not any(p.exists() for p in partial)
    assert not orphan.exists()
    # With a live server on the data directory, a new one leaves fresh files alone.
    fresh_upload = spool / "upload-fresh.upload"
    fresh_upload.write_bytes(b"in flight")
    fresh_orphan = _orphan(data_dir)
    third = make_server(data_dir=data_dir)
    assert fresh_upload.exists() and fresh_orphan.is_dir()
    with third.client() as c:
        assert c.get("/readyz").status_code == 200
    with second.client() as c:
        assert c.get("/readyz").status_code == 200
