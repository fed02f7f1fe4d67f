"""Issue 41 item 2: an output that is the input itself (same path, a symbolic or a hard link)
is refused with exit status 2 in single-file and batch mode alike, unless ``--overwrite``."""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest

from service.exit_codes import EXIT_OK, EXIT_USAGE
from tests.cli.conftest import REPO

Run = Callable[..., subprocess.CompletedProcess[str]]
HELIX = REPO / "service" / "samples" / "noisy-helix.obj"


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _alias(tmp_path: Path, scan: Path, how: str) -> Path:
    if how == "same":
        return scan
    if how == "relative":
        return tmp_path / "." / "scan.obj"
    alias = tmp_path / "alias.obj"
    if how == "symlink":
        alias.symlink_to(scan)
    else:
        os.link(scan, alias)
    return alias


@pytest.mark.parametrize("how", ["same", "relative", "symlink", "hardlink"])
def test_single_file_output_resolving_to_the_input_is_refused(
    cli: Run, tmp_path: Path, how: str
) -> None:
    scan = tmp_path / "scan.obj"
    shutil.copy(HELIX, scan)
    before = _digest(scan)
    res = cli(["smooth", scan, "-o", _alias(tmp_path, scan, how), "--tau", "0.01"])
    assert res.returncode == EXIT_USAGE, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "overwritten by its own output" in lines[0]
    assert _digest(scan) == before


@pytest.mark.parametrize("how", ["symlink", "hardlink"])
def test_batch_output_linked_to_an_input_is_refused(cli: Run, tmp_path: Path, how: str) -> None:
    scans, out = tmp_path / "scans", tmp_path / "out"
    scans.mkdir()
    out.mkdir()
    scan = scans / "a.obj"
    shutil.copy(HELIX, scan)
    shutil.copy(HELIX, scans / "b.obj")
    if how == "symlink":
        (out / "a.obj").symlink_to(scan)
    else:
        os.link(scan, out / "a.obj")
    before = _digest(scan)
    res = cli(["smooth", scan, scans / "b.obj", "-o", f"{out}/", "--tau", "0.01"])
    assert res.returncode == EXIT_USAGE and "overwritten by its own output" in res.stderr
    assert _digest(scan) == before and not (out / "b.obj").exists()


def test_overwrite_replaces_the_input_on_purpose(cli: Run, tmp_path: Path) -> None:
    scan = tmp_path / "scan.obj"
    shutil.copy(HELIX, scan)
    before = _digest(scan)
    res = cli(["smooth", scan, "-o", scan, "--tau", "0.01", "--overwrite", "-q"])
    assert res.returncode == EXIT_OK, res.stderr
    assert _digest(scan) != before
