"""``geosmooth submit`` (the console script) against a live server."""

from __future__ import annotations

import json
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from service.exit_codes import (
    EXIT_CANCELLED,
    EXIT_JOB_FAILED,
    EXIT_REJECTED,
    EXIT_UNREACHABLE,
)
from tests.api.api_helpers import (
    LiveServer,
    encode,
    free_port,
    noisy_plane_cloud,
    noisy_sphere,
    parse_points,
    phi,
)

_SCRIPT = Path(sys.executable).with_name("geosmooth")
#: ``geosmooth``: the console script when installed (make setup), else the same entry point
#: (``service.cli:main``) through ``python -m service.cli``, so that no test skips.
GEOSMOOTH = [str(_SCRIPT)] if _SCRIPT.exists() else [sys.executable, "-m", "service.cli"]
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    server = LiveServer(tmp_path_factory.mktemp("submit") / "data", workers=2).start()
    try:
        yield server
    finally:
        server.stop()


def _run(*args: str | Path, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*GEOSMOOTH, "submit", *map(str, args)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def test_submit_downloads_result_and_report(live: LiveServer, tmp_path: Path) -> None:
    pts, faces = noisy_sphere(2, seed=40)
    src = tmp_path / "sphere.ply"
    src.write_bytes(encode("ply", pts, faces))
    out, report = tmp_path / "out.ply", tmp_path / "report.json"
    done = _run(src, "--server", live.url, "-o", out, "--tau", "0.05", "--report", report)
    assert done.returncode == 0, done.stderr
    assert done.stdout == ""
    after = parse_points(out.read_bytes(), "ply")
    assert abs(phi(pts, after) - 0.05) / 0.05 <= 1e-3
    data = json.loads(report.read_text())
    assert data["phi"] == pytest.approx(phi(pts, after), rel=1e-9) and data["converged"] is True
    assert "sphere.ply -> " in done.stderr

    converted = tmp_path / "out.obj"  # output format from the file name
    done = _run(src, "--server", live.url, "-o", converted, "--tau", "0.05", "-q")
    assert done.returncode == 0 and done.stderr == ""
    assert parse_points(converted.read_bytes(), "obj").shape == pts.shape


def test_submit_shows_progress(live: LiveServer, tmp_path: Path) -> None:
    """The iterations the job went through are shown in order, up to the one that met tau:
    later evaluations at the same lambda add nothing and are not printed (issue 41); the last
    line is the report's lambda and phi."""
    src = tmp_path / "cloud.xyz"
    src.write_bytes(encode("xyz", noisy_plane_cloud(2000, seed=41), None))
    out, report = tmp_path / "cloud.out.xyz", tmp_path / "report.json"
    done = _run(src, "--server", live.url, "-o", out, "--tau", "1", "--tolerance", "1e-9",
                "--report", report)  # fmt: skip
    assert done.returncode == 0, done.stderr
    data = json.loads(report.read_text())
    lines = [ln for ln in done.stderr.splitlines() if ln.startswith("geosmooth: iteration")]
    assert lines, done.stderr
    numbers = [int(ln.split()[2]) for ln in lines]
    assert numbers == sorted(set(numbers)) and numbers[-1] <= data["iterations"]
    for line in lines:
        assert "lambda=" in line and "phi=" in line and "tau=" in line and "rel.error=" in line
    assert f"lambda={data['lambda']:.4e}" in lines[-1] and f"phi={data['phi']:.4e}" in lines[-1]
    assert "upload, queue, smooth, download" in done.stderr


def test_submit_rejected_input(live: LiveServer, tmp_path: Path) -> None:
    src = tmp_path / "bad.xyz"
    src.write_text("0 0 0\n1 1\n")
    done = _run(src, "--server", live.url, "-o", tmp_path / "o.xyz", "--tau", "1")
    assert done.returncode == EXIT_REJECTED, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert "Malformed input file" in done.stderr and "line 2" in done.stderr
    assert not (tmp_path / "o.xyz").exists()


def test_submit_failed_job(tmp_path: Path) -> None:
    """A job that fails on the server ends with exit status 9 and the reason: here the job time
    limit, hit by the report's spectrum (a dense SVD of a 3000-point L, seconds of work the
    submit-time estimate does not count); the dry run at submit is switched off."""
    env = {"GEOSMOOTH_JOB_TIMEOUT": "1", "GEOSMOOTH_SUBMIT_DRY_RUN_POINTS": "0"}
    server = LiveServer(tmp_path / "data", workers=1, env=env).start()
    try:
        src = tmp_path / "c.xyz"
        src.write_bytes(encode("xyz", noisy_plane_cloud(3000, seed=45), None))
        slow = ["--tau", "1", "--spectrum", "--neighborhood", "knn"]
        done = _run(src, "--server", server.url, "-o", tmp_path / "o.xyz", *slow)
    finally:
        server.stop()
    assert done.returncode == EXIT_JOB_FAILED, done.stderr
    last = done.stderr.splitlines()[-1]
    assert last.startswith("geosmooth: error: job ") and "failed: Job timed out" in last, last


def test_submit_unreachable_server(tmp_path: Path) -> None:
    pts, faces = noisy_sphere(1)
    src = tmp_path / "s.ply"
    src.write_bytes(encode("ply", pts, faces))
    url = f"http://127.0.0.1:{free_port()}"
    done = _run(src, "--server", url, "-o", tmp_path / "o.ply", "--tau", "0.1")
    assert done.returncode == EXIT_UNREACHABLE, done.stderr
    assert "cannot reach" in done.stderr


def _start_slow_submit(
    live: LiveServer, tmp_path: Path, seed: int
) -> tuple[subprocess.Popen[str], list[dict]]:
    """Start ``geosmooth submit`` on a slow input; return it once its job is running."""
    src = tmp_path / "slow.xyz"
    src.write_bytes(encode("xyz", noisy_plane_cloud(40000, seed=seed), None))
    args = ["--tau", "1", "--tolerance", "1e-9", "--neighborhood", "knn", "--k", "64"]
    cmd = [*GEOSMOOTH, "submit", str(src), "--server", live.url, "-o", str(tmp_path / "o")]
    proc = subprocess.Popen([*cmd, *args], cwd=ROOT, stderr=subprocess.PIPE, text=True)
    with live.client() as client:
        deadline = time.monotonic() + 180  # a state, with a bound generous for a busy machine
        running: list[dict] = []
        while not running and time.monotonic() < deadline:
            running = client.get("/v1/jobs", params={"status": "running"}).json()["items"]
            time.sleep(0.05)
    if not running:
        proc.kill()
        assert running, f"the job did not start: {proc.communicate()[1][-3000:]}"
    return proc, running


def test_submit_cancelled_job(live: LiveServer, tmp_path: Path) -> None:
    proc, running = _start_slow_submit(live, tmp_path, seed=42)
    try:
        with live.client() as client:
            assert client.post(f"/v1/jobs/{running[0]['id']}/cancel").status_code == 200
        _, stderr = proc.communicate(timeout=180)
    finally:
        proc.kill()
    assert proc.returncode == EXIT_CANCELLED, stderr
    assert "cancelled" in stderr.splitlines()[-1]


def test_ctrl_c_cancels_the_job(live: LiveServer, tmp_path: Path) -> None:
    proc, running = _start_slow_submit(live, tmp_path, seed=43)
    try:
        with live.client() as client:
            proc.send_signal(signal.SIGINT)
            _, stderr = proc.communicate(timeout=180)
            job = client.get(f"/v1/jobs/{running[0]['id']}").json()
    finally:
        proc.kill()
    assert proc.returncode == 130, stderr
    assert "cancelled" in stderr
    assert job["status"] == "cancelled"


def test_submit_weld_keeps_split_vertices_together(live: LiveServer, tmp_path: Path) -> None:
    # a closed octahedron stored STL-style: every face has its own three vertices
    v = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    tri = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5],
                    [3, 1, 5], [0, 3, 5]])  # fmt: skip
    pts = v[tri.ravel()] * 1.3
    faces = np.arange(pts.shape[0]).reshape(-1, 3)
    src = tmp_path / "soup.ply"
    src.write_bytes(encode("ply", pts, faces))
    out, report = tmp_path / "out.ply", tmp_path / "report.json"
    done = _run(src, "--server", live.url, "-o", out, "--lam", "1", "--weld", "--report", report)
    assert done.returncode == 0, done.stderr
    after = parse_points(out.read_bytes(), "ply")
    assert after.shape == pts.shape
    for corner in range(6):  # the copies of each octahedron corner moved together
        copies = np.flatnonzero(np.all(pts == v[corner] * 1.3, axis=1))
        assert np.all(after[copies] == after[copies[0]])
    assert json.loads(report.read_text())["n_points"] == 6
    assert not np.allclose(after, pts)  # it did smooth: a welded octahedron shrinks


def _bytes_acked(port: int) -> int:
    """Bytes the server acknowledged on established connections to ``port`` (``ss -ti``)."""
    out = subprocess.run(
        ["ss", "-Htin", "state", "established", f"( dport = :{port} )"],
        capture_output=True, text=True, check=True,
    ).stdout  # fmt: skip
    return max((int(n) for n in re.findall(r"bytes_acked:(\d+)", out)), default=0)


@pytest.mark.skipif(shutil.which("ss") is None, reason="needs ss (iproute2)")
def test_ctrl_c_after_the_upload_cancels_the_new_job(live: LiveServer, tmp_path: Path) -> None:
    """Ctrl-C once every byte is sent, while the server still parses the upload: the client
    waits for the job id and cancels that job (issue 12: it used to keep running)."""
    src = tmp_path / "big.xyz"
    src.write_bytes(encode("xyz", noisy_plane_cloud(200_000, seed=44), None))
    size = src.stat().st_size
    with live.client() as client:
        before = {j["id"] for j in client.get("/v1/jobs", params={"limit": 500}).json()["items"]}
    args = ["--tau", "1", "--tolerance", "1e-9", "--neighborhood", "knn", "--k", "16"]
    cmd = [*GEOSMOOTH, "submit", str(src), "--server", live.url, "-o", str(tmp_path / "o")]
    proc = subprocess.Popen([*cmd, *args], cwd=ROOT, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while _bytes_acked(live.port) < size and time.monotonic() < deadline:
            time.sleep(0.002)  # the server's kernel has every byte of the file
        proc.send_signal(signal.SIGINT)
        with live.client() as client:  # the server is still parsing: no new job yet
            listed = client.get("/v1/jobs", params={"limit": 500}).json()["items"]
        assert {j["id"] for j in listed} == before, "the upload was not interrupted in time"
        _, stderr = proc.communicate(timeout=60)
    finally:
        proc.kill()
    with live.client() as client:
        jobs = client.get("/v1/jobs", params={"limit": 500}).json()["items"]
    new = [j for j in jobs if j["id"] not in before]
    assert proc.returncode == 130, stderr
    assert len(new) == 1 and new[0]["status"] == "cancelled", (new, stderr)
    assert f"job {new[0]['id']} cancelled" in stderr
