"""Helpers of the HTTP tests: a live uvicorn server in a subprocess, test geometry, file codecs.

The geometry files are written and the downloaded results parsed here, independently of
``service.io``, so that the tests check the service against plain text formats.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from numpy.typing import NDArray

from tests.timing import patience

ROOT = Path(__file__).resolve().parents[2]
FINISHED = ("succeeded", "failed", "cancelled")

#: API keys of the keyed server: two from GEOSMOOTH_API_KEYS, one (carol, tight bounds) from a
#: keys file of sha256 digests, one for the schemathesis run.
KEYS = {"alice": "alice-key-0001", "bob": "bob-key-0002", "carol": "carol-key-0003",
        "fuzz": "schemathesis-key-0004"}  # fmt: skip

#: Short timeouts, small connection bounds and a trusted CORS origin.
TIGHT_ENV = {
    "GEOSMOOTH_TIMEOUT_REQUEST_HEADER": "2",
    "GEOSMOOTH_TIMEOUT_BODY_READ": "2",
    "GEOSMOOTH_TIMEOUT_GRACEFUL_SHUTDOWN": "3",
    "GEOSMOOTH_MAX_CONNECTIONS": "500",
    "GEOSMOOTH_MAX_CONNECTIONS_PER_CLIENT": "200",
    "GEOSMOOTH_SYNC_MAX_POINTS": "60000",
    "GEOSMOOTH_SYNC_TIMEOUT": "3",
    "GEOSMOOTH_MAX_UPLOAD_BYTES": str(64 * 1024 * 1024),
    "GEOSMOOTH_CORS_ORIGINS": "https://app.example",
}


# --------------------------------------------------------------------------- live server


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


class LiveServer:
    """``python -m service.api.server`` in a subprocess on a free port of 127.0.0.1.

    Parameters
    ----------
    data_dir : Path
        Job store of the server.
    workers : int
        Solver worker processes.
    env : mapping, optional
        Extra environment (``GEOSMOOTH_*`` settings).
    port : int, optional
        Default: a free port.
    """

    def __init__(
        self,
        data_dir: Path,
        workers: int | None = 2,
        env: Mapping[str, str] | None = None,
        port: int | None = None,
        args: tuple[str, ...] = (),
        headers: Mapping[str, str] | None = None,
    ) -> None:
        self.data_dir = Path(data_dir)
        self.workers = workers
        self.env = dict(env or {})
        self._free_port = port is None  # ours to choose: another one if it is taken meanwhile
        self.port = port or free_port()
        self.args = args
        self.headers = dict(headers or {})
        self.url = f"http://127.0.0.1:{self.port}"
        self.proc: subprocess.Popen[bytes] | None = None
        self.log_path = self.data_dir.parent / f"server-{self.port}.log"

    def command(self) -> list[str]:
        workers = ["--workers", str(self.workers)] if self.workers is not None else []
        cmd = [sys.executable, "-m", "service.api.server", "--port", str(self.port), *workers]
        return [*cmd, "--data-dir", str(self.data_dir), *self.args]

    def launch(self) -> subprocess.Popen[bytes]:
        env = {"GEOSMOOTH_HOST": "127.0.0.1", **os.environ, **self.env, "PYTHONUNBUFFERED": "1"}
        self.data_dir.parent.mkdir(parents=True, exist_ok=True)
        log = self.log_path.open("ab")
        self.proc = subprocess.Popen(self.command(), cwd=ROOT, env=env, stdout=log, stderr=log)
        log.close()
        return self.proc

    def start(self, timeout: float = 60.0) -> LiveServer:
        """Launch and wait until ``/readyz`` answers (``timeout``: a hang guard, stretched by
        :func:`tests.timing.patience`). A free port taken by someone else between choosing and
        binding it (parallel tests) is replaced by another one."""
        timeout = patience(timeout)
        proc = self.launch()
        deadline = time.monotonic() + timeout
        retries = 3
        while time.monotonic() < deadline:
            if proc.poll() is not None:
                if self._free_port and retries and "address already in use" in self.log().lower():
                    retries -= 1
                    self.port = free_port()
                    self.url = f"http://127.0.0.1:{self.port}"
                    self.log_path = self.data_dir.parent / f"server-{self.port}.log"
                    proc = self.launch()
                    continue
                raise RuntimeError(f"server exited with {proc.returncode}:\n{self.log()}")
            try:
                if httpx.get(f"{self.url}/readyz", timeout=1.0).status_code == 200:
                    return self
            except httpx.TransportError:
                pass
            time.sleep(0.05)
        self.stop()
        raise RuntimeError(f"server not ready after {timeout:.0f} s:\n{self.log()}")

    def records(self) -> list[dict[str, Any]]:
        """The server's JSON log lines, parsed (other lines skipped)."""
        out = []
        for line in self.log_path.read_text(errors="replace").splitlines():
            if line.startswith("{"):
                try:
                    out.append(json.loads(line))
                except ValueError:
                    continue
        return out

    def rss(self, with_children: bool = False) -> int:
        """Resident memory of the server process (and its descendants), bytes."""
        assert self.proc is not None
        pids = {self.proc.pid} | (descendants(self.proc.pid) if with_children else set())
        return sum(rss_of(pid) for pid in pids)

    def log(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")[-5000:]
        except OSError:
            return ""

    def kill(self) -> None:
        """SIGKILL, as a crash would (worker processes die with it)."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(10)

    def stop(self) -> None:
        """SIGTERM (graceful shutdown), SIGKILL if it hangs."""
        if self.proc is None or self.proc.poll() is not None:
            return
        self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(20)
        except subprocess.TimeoutExpired:
            self.kill()

    def client(self, timeout: float = 30.0, **headers: str) -> httpx.Client:
        return httpx.Client(base_url=self.url, timeout=timeout, headers={**self.headers, **headers})


def rss_of(pid: int) -> int:
    """Resident set size of a live process in bytes (0 if gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def wait_done(client: httpx.Client, job_id: str, timeout: float = 60.0) -> dict[str, Any]:
    """Poll a job until it is finished; returns its last status (``timeout``: a hang guard,
    stretched by :func:`tests.timing.patience` for a busy machine)."""
    timeout = patience(timeout)
    deadline = time.monotonic() + timeout
    while True:
        job = client.get(f"/v1/jobs/{job_id}").json()
        if job["status"] in FINISHED:
            return job
        if time.monotonic() > deadline:
            raise AssertionError(f"job {job_id} not finished after {timeout:.0f} s: {job}")
        time.sleep(0.05)


def descendants(pid: int) -> set[int]:
    """Live (non-zombie) descendant processes of ``pid`` (Linux /proc)."""
    parents: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2 :].split()
        if fields[0] == "Z":
            continue
        parents.setdefault(int(fields[1]), []).append(int(entry.name))
    out: set[int] = set()
    todo = [pid]
    while todo:
        for child in parents.get(todo.pop(), []):
            if child not in out:
                out.add(child)
                todo.append(child)
    return out


def cpu_ticks(pid: int) -> int | None:
    """User + system CPU ticks of a live process, ``None`` if gone or a zombie."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = stat[stat.rindex(")") + 2 :].split()
    if fields[0] == "Z":
        return None
    return int(fields[11]) + int(fields[12])


# --------------------------------------------------------------------------- geometry


def icosphere(subdivisions: int = 2) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Unit icosphere: 12 * 4^k-ish vertices (k=2: 162), closed triangle mesh."""
    t = (1 + 5**0.5) / 2
    verts = [
        (-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
        (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1),
    ]  # fmt: skip
    faces = [
        (0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
        (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
        (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1),
    ]  # fmt: skip
    points = [np.array(v, float) / np.linalg.norm(v) for v in verts]
    for _ in range(subdivisions):
        cache: dict[tuple[int, int], int] = {}

        def mid(a: int, b: int, cache: dict[tuple[int, int], int] = cache) -> int:
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = points[a] + points[b]
                points.append(m / np.linalg.norm(m))
                cache[key] = len(points) - 1
            return cache[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    return np.array(points), np.array(faces, dtype=np.int64)


def noisy_sphere(
    subdivisions: int = 2, noise: float = 0.02, seed: int = 0
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    pts, faces = icosphere(subdivisions)
    rng = np.random.default_rng(seed)
    return pts + rng.normal(scale=noise, size=pts.shape), faces


def noisy_plane_cloud(n: int = 400, noise: float = 0.01, seed: int = 1) -> NDArray[np.float64]:
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-1, 1, size=(n, 2))
    z = 0.2 * np.sin(2 * xy[:, 0]) + rng.normal(scale=noise, size=n)
    return np.column_stack([xy, z])


def noisy_helix(n: int = 200, noise: float = 0.01, seed: int = 2) -> NDArray[np.float64]:
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 4 * np.pi, n)
    pts = np.column_stack([np.cos(t), np.sin(t), 0.1 * t])
    return pts + rng.normal(scale=noise, size=pts.shape)


def phi(before: NDArray[np.float64], after: NDArray[np.float64]) -> float:
    """``sum_i ||x_i - p_i||^2`` (unit weights)."""
    return float(np.sum((np.asarray(after) - np.asarray(before)) ** 2))


# --------------------------------------------------------------------------- file codecs


def _num(v: float) -> str:
    return repr(float(v))


def ply_bytes(points: NDArray[np.float64], faces: NDArray[np.int64] | None = None) -> bytes:
    faces = np.zeros((0, 3), np.int64) if faces is None else faces
    head = [
        "ply",
        "format ascii 1.0",
        "comment geosmooth api test",
        f"element vertex {len(points)}",
        "property double x",
        "property double y",
        "property double z",
    ]
    if len(faces):
        head += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
    head.append("end_header")
    lines = head + [" ".join(_num(v) for v in p) for p in points]
    lines += ["3 " + " ".join(str(int(i)) for i in f) for f in faces]
    return ("\n".join(lines) + "\n").encode()


def obj_bytes(
    points: NDArray[np.float64],
    faces: NDArray[np.int64] | None = None,
    polyline: bool = False,
) -> bytes:
    lines = ["# geosmooth api test"] + ["v " + " ".join(_num(v) for v in p) for p in points]
    if faces is not None:
        lines += ["f " + " ".join(str(int(i) + 1) for i in f) for f in faces]
    if polyline:
        lines.append("l " + " ".join(str(i + 1) for i in range(len(points))))
    return ("\n".join(lines) + "\n").encode()


def xyz_bytes(points: NDArray[np.float64]) -> bytes:
    return ("\n".join(" ".join(_num(v) for v in p) for p in points) + "\n").encode()


def json_geometry(
    points: NDArray[np.float64],
    faces: NDArray[np.int64] | None = None,
    edges: NDArray[np.int64] | None = None,
) -> dict[str, Any]:
    out: dict[str, Any] = {"points": np.asarray(points).tolist()}
    if faces is not None:
        out["faces"] = np.asarray(faces).tolist()
    if edges is not None:
        out["edges"] = np.asarray(edges).tolist()
    return out


def encode(fmt: str, points: NDArray[np.float64], faces: NDArray[np.int64] | None) -> bytes:
    if fmt == "ply":
        return ply_bytes(points, faces)
    if fmt == "obj":
        return obj_bytes(points, faces)
    if fmt == "xyz":
        return xyz_bytes(points)
    return json.dumps(json_geometry(points, faces)).encode()


_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip


def _ply_points(data: bytes) -> NDArray[np.float64]:
    end = data.index(b"end_header") + len(b"end_header")
    end = data.index(b"\n", end) + 1
    header = data[:end].decode("ascii").splitlines()
    assert header[0].strip() == "ply"
    fmt = next(ln.split()[1] for ln in header if ln.startswith("format"))
    n, props, in_vertex, first = 0, [], False, True
    for ln in header:
        words = ln.split()
        if words[:1] == ["element"]:
            in_vertex = words[1] == "vertex"
            assert not in_vertex or first, "vertex must be the first element"
            first = False
            if in_vertex:
                n = int(words[2])
        elif words[:1] == ["property"] and in_vertex:
            assert words[1] != "list"
            props.append((words[2], _PLY_TYPES[words[1]]))
    names = [name for name, _ in props]
    if fmt == "ascii":
        rows = data[end:].decode().splitlines()[:n]
        table = np.array([[float(v) for v in r.split()[: len(props)]] for r in rows])
        return table[:, [names.index(c) for c in "xyz"]]
    order = {"binary_little_endian": "<", "binary_big_endian": ">"}[fmt]
    dtype = np.dtype([(name, order + t) for name, t in props])
    table = np.frombuffer(data, dtype=dtype, count=n, offset=end)
    return np.column_stack([table[c].astype(np.float64) for c in "xyz"])


def parse_points(data: bytes, fmt: str) -> NDArray[np.float64]:
    """Vertex coordinates of a PLY (ASCII or binary), OBJ, XYZ or JSON file."""
    if fmt == "ply":
        return _ply_points(data)
    text = data.decode()
    if fmt == "json":
        return np.asarray(json.loads(text)["points"], dtype=float)
    if fmt == "xyz":
        rows = [ln.split() for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]
        return np.array([[float(v) for v in r[:3]] for r in rows])
    if fmt == "obj":
        rows = [ln.split()[1:4] for ln in text.splitlines() if ln.startswith("v ")]
        return np.array([[float(v) for v in r] for r in rows])
    raise ValueError(fmt)
