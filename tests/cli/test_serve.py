"""``geosmooth serve``: documented exit statuses for a busy port and a bad configuration.

Issue 12: a port in use exited 3 (documented as "input file missing") and
``GEOSMOOTH_WORKERS=abc`` gave "internal error: ValidationError" without naming the variable.
"""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import httpx

from service.exit_codes import EXIT_ADDRESS, EXIT_USAGE, SERVE_EXIT_CODES

Run = Callable[..., subprocess.CompletedProcess[str]]
ROOT = Path(__file__).resolve().parents[2]


def _one_line(res: subprocess.CompletedProcess[str], code: int) -> str:
    assert res.returncode == code, (res.returncode, res.stderr)
    assert code in SERVE_EXIT_CODES
    lines = res.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("geosmooth: error: "), res.stderr
    return lines[0]


def test_port_in_use(cli: Run, tmp_path: Path) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        res = cli(["serve", "--port", port, "--data-dir", tmp_path / "d"], timeout=60)
    line = _one_line(res, EXIT_ADDRESS)
    assert f"127.0.0.1:{port}: Address already in use" in line


def test_configuration_error_names_the_variable(cli: Run, tmp_path: Path) -> None:
    env = {"GEOSMOOTH_WORKERS": "abc", "GEOSMOOTH_DATA_DIR": str(tmp_path / "d")}
    line = _one_line(cli(["serve", "--port", "1"], env=env, timeout=60), EXIT_USAGE)
    assert "GEOSMOOTH_WORKERS='abc'" in line and "integer" in line and "internal" not in line


def test_network_address_without_keys_is_refused(cli: Run, tmp_path: Path) -> None:
    env = {"GEOSMOOTH_DATA_DIR": str(tmp_path / "d"), "GEOSMOOTH_API_KEYS": ""}
    res = cli(["serve", "--host", "0.0.0.0", "--port", "1"], env=env, timeout=60)
    line = _one_line(res, EXIT_USAGE)
    assert "without API keys" in line and "--insecure-no-auth" in line
    assert not (tmp_path / "d").exists()  # nothing was started


def test_serve_runs_until_sigterm(tmp_path: Path) -> None:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    cmd = [sys.executable, "-m", "service.cli", "serve", "--port", str(port), "--workers", "1",
           "--data-dir", str(tmp_path / "d")]  # fmt: skip
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
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
    # uvicorn shuts down gracefully, then re-raises SIGTERM (the status a signal death gives)
    assert proc.returncode in (0, -signal.SIGTERM), log
    assert "application shutdown complete" in log.lower() and "traceback" not in log.lower()
