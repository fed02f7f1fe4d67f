"""Helpers of the web tests: a live uvicorn server, Debian's chromium, geometry, pixel checks."""

from __future__ import annotations

import io
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import httpx
import numpy as np
from numpy.typing import NDArray

from tests.timing import patience

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "service" / "samples"
CHROMIUM = os.environ.get("GEOSMOOTH_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
LOCAL_HOSTS = frozenset({"127.0.0.1", "localhost", "::1", "[::1]"})


def chromium_missing() -> str | None:
    """Why the browser tests cannot run here, or ``None``."""
    if not (Path(CHROMIUM).exists() or shutil.which(CHROMIUM)):
        return f"no browser at {CHROMIUM}: run scripts/install-system-deps.sh (installs chromium)"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "the playwright package is missing: pip install -e '.[dev]'"
    return None


@dataclass
class Browsing:
    """A page plus everything it asked for (the network log) and its console errors."""

    page: Any
    requests: list[str] = field(default_factory=list)
    blocked: list[str] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)
    console: list[str] = field(default_factory=list)
    shots: Path | None = None

    def shot(self, name: str) -> Path:
        assert self.shots is not None
        path = self.shots / f"{name}.png"
        self.page.screenshot(path=str(path), full_page=True)
        return path

    def assert_offline(self) -> None:
        """Zero requests to non-local hosts, and no uncaught script errors."""
        outside = [u for u in self.requests if not is_local(u)]
        assert not outside and not self.blocked, f"requests leaving the machine: {outside}"
        assert not self.errors, f"script errors: {self.errors}"
        assert self.requests, "the network log is empty"


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


class WebServer:
    """``python -m service.api.server`` on a free port of 127.0.0.1, with its own data dir."""

    def __init__(self, data_dir: Path, env: Mapping[str, str] | None = None, workers: int = 2):
        self.data_dir = data_dir
        self.env = dict(env or {})
        self.workers = workers
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.log_path = data_dir.parent / f"web-server-{self.port}.log"
        self.proc: subprocess.Popen[bytes] | None = None

    def _launch(self) -> subprocess.Popen[bytes]:
        cmd = [sys.executable, "-m", "service.api.server", "--host", "127.0.0.1"]
        cmd += ["--port", str(self.port), "--workers", str(self.workers)]
        cmd += ["--data-dir", str(self.data_dir)]
        env = {**os.environ, **self.env, "PYTHONUNBUFFERED": "1"}
        with self.log_path.open("ab") as log:
            self.proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=log, stderr=log)
        return self.proc

    def start(self, timeout: float = 60.0) -> WebServer:
        """Launch and wait for ``/readyz`` (``timeout``: a hang guard, stretched for a busy
        machine); a port taken meanwhile by a parallel test is replaced by another one."""
        timeout = patience(timeout)
        self.proc = self._launch()
        deadline = time.monotonic() + timeout
        retries = 3
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                if retries and "address already in use" in self.log().lower():
                    retries -= 1
                    self.port = free_port()
                    self.url = f"http://127.0.0.1:{self.port}"
                    self.log_path = self.data_dir.parent / f"web-server-{self.port}.log"
                    self.proc = self._launch()
                    continue
                raise RuntimeError(f"server exited with {self.proc.returncode}: {self.log()}")
            try:
                if httpx.get(f"{self.url}/readyz", timeout=1.0).status_code == 200:
                    return self
            except httpx.TransportError:
                pass
            time.sleep(0.05)
        self.stop()
        raise RuntimeError(f"server not ready after {timeout:.0f} s: {self.log()}")

    def log(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")[-4000:]
        except OSError:
            return ""

    def stop(self) -> None:
        if self.proc is None or self.proc.poll() is not None:
            return
        self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(10)

    def client(self) -> httpx.Client:
        return httpx.Client(base_url=self.url, timeout=60.0)


def is_local(url: str) -> bool:
    """Whether a request stays on this machine (data: and blob: URLs never leave the page)."""
    parts = urlsplit(url)
    if parts.scheme in ("data", "blob", "about", "chrome", "chrome-extension"):
        return True
    return (parts.hostname or "") in LOCAL_HOSTS


def nonblank_fraction(png: bytes, background: tuple[int, int, int], tol: int = 12) -> float:
    """Fraction of pixels of a screenshot that differ from ``background`` by more than ``tol``."""
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int16)
    diff = np.abs(img - np.array(background, dtype=np.int16)).max(axis=2)
    return float(np.mean(diff > tol))


def grid_mesh(m: int, sigma: float = 0.005, seed: int = 0) -> tuple[NDArray[Any], NDArray[Any]]:
    """A noisy height field on an m x m grid over the unit square (2 (m-1)^2 triangles)."""
    x, y = np.meshgrid(np.linspace(0, 1, m), np.linspace(0, 1, m))
    rng = np.random.default_rng(seed)
    z = 0.1 * np.sin(4 * x) * np.cos(3 * y) + rng.normal(0, sigma, x.shape)
    points = np.c_[x.ravel(), y.ravel(), z.ravel()]
    i = np.arange(m * m).reshape(m, m)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    return points, np.r_[np.c_[a, b, d], np.c_[a, d, c]]


def ply_ascii(points: NDArray[Any], faces: NDArray[Any] | None = None) -> bytes:
    """An ASCII PLY file, written here independently of service.io."""
    head = ["ply", "format ascii 1.0", f"element vertex {len(points)}"]
    head += ["property double x", "property double y", "property double z"]
    if faces is not None:
        head += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
    lines = [*head, "end_header"]
    lines += [" ".join(repr(float(v)) for v in p) for p in points]
    if faces is not None:
        lines += ["3 " + " ".join(str(int(i)) for i in f) for f in faces]
    return ("\n".join(lines) + "\n").encode()


def noisy_cloud(n: int = 1500, sigma: float = 0.01, seed: int = 3) -> NDArray[Any]:
    """Points on a torus (radii 1 and 0.35) with Gaussian noise, as an unstructured cloud."""
    rng = np.random.default_rng(seed)
    u, v = rng.uniform(0, 2 * np.pi, (2, n))
    r = 1 + 0.35 * np.cos(v)
    pts = np.c_[r * np.cos(u), r * np.sin(u), 0.35 * np.sin(v)]
    return pts + rng.normal(0, sigma, pts.shape)
