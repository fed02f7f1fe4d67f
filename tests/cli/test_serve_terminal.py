"""``geosmooth serve`` talks to people (issue 25.7): a real pseudo-terminal and real subprocesses.

* on a terminal: one human line with the page's and the docs' addresses (both answer), no JSON;
* off a terminal (a pipe) and with ``--log-format json`` on a terminal: JSON lines, no human line;
* an invalid setting (a directory as ``GEOSMOOTH_STORAGE_URL``): one line naming the variable and
  the forms it accepts, exit status 2, no traceback, nothing started.
"""

from __future__ import annotations

import json
import os
import pty
import select
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx

from service.exit_codes import EXIT_USAGE
from tests.cli.conftest import REPO, run_cli


def _port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _env(tmp_path: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("GEOSMOOTH_")}
    env["GEOSMOOTH_DATA_DIR"] = str(tmp_path / "d")
    return env


def _serve_on_pty(tmp_path: Path, *extra: str) -> tuple[str, int, list[int]]:
    """Run ``serve`` with stdin/stdout/stderr on a pty until it answers; the text it printed
    until then, its port, and the statuses of the page and the docs."""
    port = _port()
    master, slave = pty.openpty()
    cmd = [sys.executable, "-m", "service.cli", "serve", "--port", str(port), "--workers", "1",
           *extra]  # fmt: skip
    proc = subprocess.Popen(
        cmd, cwd=REPO, env=_env(tmp_path), stdin=slave, stdout=slave, stderr=slave
    )
    os.close(slave)
    chunks: list[bytes] = []
    statuses: list[int] = []
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None:
            ready, _, _ = select.select([master], [], [], 0.1)
            if ready:
                chunks.append(os.read(master, 65536))
            try:
                if httpx.get(f"http://127.0.0.1:{port}/readyz", timeout=1).status_code == 200:
                    break
            except httpx.TransportError:
                continue
        time.sleep(0.3)  # the ready line is printed right after startup
        while select.select([master], [], [], 0.2)[0]:
            chunks.append(os.read(master, 65536))
        statuses = [
            httpx.get(f"http://127.0.0.1:{port}{path}", timeout=5).status_code
            for path in ("/", "/docs")
        ]
        proc.send_signal(signal.SIGINT)
        proc.wait(30)
    finally:
        proc.kill()
        os.close(master)
    return b"".join(chunks).decode(errors="replace"), port, statuses


def test_terminal_gets_one_human_line(tmp_path: Path) -> None:
    text, port, statuses = _serve_on_pty(tmp_path)
    lines = [ln for ln in text.replace("\r", "").splitlines() if ln.strip()]
    url = f"http://127.0.0.1:{port}"
    human = f"geosmooth is serving {url}/ (API docs: {url}/docs); press Ctrl-C to stop"
    assert lines.count(human) == 1, text
    others = [ln for ln in lines if ln != human]  # only warnings, as text (none expected)
    assert all("[warning" in ln or "[error" in ln for ln in others), text
    assert not any(ln.lstrip().startswith("{") for ln in lines), text
    assert statuses == [200, 200]


def test_json_logs_with_the_flag_on_a_terminal(tmp_path: Path) -> None:
    text, _, _ = _serve_on_pty(tmp_path, "--log-format", "json")
    lines = [ln for ln in text.replace("\r", "").splitlines() if ln.strip()]
    assert lines and all(json.loads(ln)["event"] for ln in lines), text
    assert "geosmooth is serving" not in text


def test_json_logs_off_a_terminal(tmp_path: Path) -> None:
    port = _port()
    cmd = [sys.executable, "-m", "service.cli", "serve", "--port", str(port), "--workers", "1"]
    proc = subprocess.Popen(
        cmd, cwd=REPO, env=_env(tmp_path), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                if httpx.get(f"http://127.0.0.1:{port}/readyz", timeout=1).status_code == 200:
                    break
            except httpx.TransportError:
                time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        proc.wait(30)
    finally:
        proc.kill()
    log = proc.stderr.read().decode() if proc.stderr else ""
    events = [json.loads(ln)["event"] for ln in log.splitlines() if ln.strip()]
    assert "server.start" in events and "geosmooth is serving" not in log


def test_directory_as_storage_url_is_one_line(tmp_path: Path) -> None:
    store = tmp_path / "store"
    store.mkdir()
    env = {"GEOSMOOTH_QUEUE": "rq", "GEOSMOOTH_STORAGE_URL": str(store),
           "GEOSMOOTH_DATA_DIR": str(tmp_path / "d")}  # fmt: skip
    res = run_cli(["serve", "--port", str(_port())], env=env, timeout=60)
    assert res.returncode == EXIT_USAGE, res.stderr
    lines = res.stderr.splitlines()
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith(f"geosmooth: error: GEOSMOOTH_STORAGE_URL='{store}': ")
    assert "s3://bucket" in lines[0] and "GEOSMOOTH_DATA_DIR" in lines[0]
    assert "Traceback" not in res.stderr and not (tmp_path / "d").exists()


def test_file_as_data_dir_is_one_line(tmp_path: Path) -> None:
    afile = tmp_path / "file"
    afile.write_text("x")
    res = run_cli(["serve", "--port", str(_port())], env={"GEOSMOOTH_DATA_DIR": str(afile)})
    assert res.returncode == EXIT_USAGE and len(res.stderr.splitlines()) == 1, res.stderr
    assert "GEOSMOOTH_DATA_DIR=" in res.stderr and "must be a directory" in res.stderr
