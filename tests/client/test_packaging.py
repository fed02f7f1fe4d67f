"""The client is its own pure-Python distribution: httpx only, no server code, no compiler."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CLIENT = ROOT / "clients" / "python"


def test_declared_dependencies_are_httpx_only() -> None:
    project = tomllib.loads((CLIENT / "pyproject.toml").read_text())["project"]
    assert project["name"] == "geosmooth-client"
    assert [d.split(">")[0].split("<")[0] for d in project["dependencies"]] == ["httpx"]
    server = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert any(d.startswith("geosmooth-client") for d in server["dependencies"])


def test_import_loads_no_server_or_numeric_code() -> None:
    code = (
        "import sys, geosmooth_client; "
        "print(sorted({m.split('.')[0] for m in sys.modules} & "
        "{'service', 'geosmooth', 'numpy', 'scipy', 'sksparse', 'fastapi', 'pydantic'}))"
    )
    res = subprocess.run(
        [sys.executable, "-c", code],
        cwd=CLIENT,  # the repository's packages are not importable from here
        env={"PYTHONPATH": str(CLIENT), "PATH": "/usr/bin:/bin"},
        capture_output=True, text=True, timeout=60, check=True,
    )  # fmt: skip
    assert res.stdout.strip() == "[]", res.stderr


def test_nothing_to_compile() -> None:
    """Only Python sources (and the typing marker) in the package; no setup.py, no extension."""
    files = [p for p in (CLIENT / "geosmooth_client").rglob("*") if p.is_file()]
    suffixes = {p.suffix for p in files if "__pycache__" not in p.parts}
    assert suffixes == {".py", ".typed"}
    assert not (CLIENT / "setup.py").exists()
    build = tomllib.loads((CLIENT / "pyproject.toml").read_text())["build-system"]
    assert build["build-backend"] == "setuptools.build_meta"
