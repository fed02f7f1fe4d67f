"""Junk stays out of the tree: no stray outputs, no local settings, no development paths."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: Absolute paths of a development machine (home directories, the workspace of the sessions).
DEV_PATH = re.compile(r"(?<![\w.])/(?:work|root|home)/[\w.-]")


def tracked() -> list[str]:
    out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True)
    return [name for name in out.stdout.decode().split("\0") if name]


def test_openapi_export_help_prints_usage_and_writes_nothing(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "service.api.openapi_export", "--help"],
        cwd=tmp_path, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("usage: python -m service.api.openapi_export")
    assert list(tmp_path.iterdir()) == []  # no file named --help (or anything else)


def test_openapi_export_rejects_an_unknown_option(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "service.api.openapi_export", "--bogus"],
        cwd=tmp_path, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 2 and "unrecognized arguments: --bogus" in done.stderr
    assert list(tmp_path.iterdir()) == []


def test_no_local_settings_or_build_outputs_are_tracked() -> None:
    names = tracked()
    assert ".env" not in names and ".env.example" in names
    assert not [n for n in names if Path(n).name.startswith("-")], "a file named like an option"
    junk = re.compile(r"(^|/)(build|dist|__pycache__|[^/]+\.egg-info)/")
    assert not [n for n in names if junk.search(n)]


def test_gitignore_covers_build_outputs_and_local_settings() -> None:
    probes = [".env", "build/x", "dist/x", "clients/python/build/lib/x.py", "x.egg-info/PKG-INFO",
              "clients/python/geosmooth_client.egg-info/PKG-INFO"]  # fmt: skip
    done = subprocess.run(["git", "check-ignore", "--no-index", *probes], cwd=ROOT,
                          capture_output=True, text=True)  # fmt: skip
    assert sorted(done.stdout.split()) == sorted(probes)


def test_no_absolute_development_paths_in_the_tree() -> None:
    found = []
    for name in tracked():
        path = ROOT / name
        if not path.is_file() or path.suffix in {".png", ".glb", ".laz", ".las", ".e57", ".npy"}:
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        found += [f"{name}:{i}" for i, line in enumerate(text.splitlines(), 1)
                  if DEV_PATH.search(line)]  # fmt: skip
    assert not found, found
