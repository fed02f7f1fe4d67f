"""Issue 34 items 4 and 5 through ``geosmooth smooth``: every hostile LAS/LAZ/PLY/XYZ file gives
the same one-line error and exit status on the ordinary path and the streamed one
(``--tile-points 1000``), never ``internal error`` (exit 1); ``--max-points`` / ``--max-memory``
bound both paths.

The commands run in-process (:func:`service.cli.main.main`); the one run in a child process
shows that a header claiming 2**32 - 1 points does not make the command allocate 96 GiB.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from service.cli.main import main
from service.exit_codes import EXIT_CODES, EXIT_INPUT, EXIT_USAGE
from tests.cli.conftest import run_cli
from tests.io.hostile_files import all_cases, las_bytes

CASES = all_cases()


def _smooth(capsys: pytest.CaptureFixture[str], *args: str | Path) -> tuple[int, list[str]]:
    code = main(["smooth", *map(str, args), "-q"])
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    return code, lines


@pytest.mark.parametrize("name", sorted(CASES))
def test_both_paths_answer_alike(
    name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / name
    path.write_bytes(CASES[name])
    ordinary = _smooth(capsys, path, "-o", tmp_path / f"o-{name}")
    streamed = _smooth(capsys, path, "-o", tmp_path / f"t-{name}", "--tile-points", "1000")
    assert ordinary == streamed
    code, lines = ordinary
    assert code in EXIT_CODES and code != 1, lines
    if code:
        assert len(lines) == 1 and lines[0].startswith("geosmooth: error: "), lines
        assert "internal error" not in lines[0]


def test_max_points_and_max_memory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "p.las"
    path.write_bytes(las_bytes(400))
    out = tmp_path / "o.las"
    for tiled in ([], ["--tile-points", "1000"]):
        code, lines = _smooth(capsys, path, "-o", out, "--max-points", "100", *tiled)
        assert code == EXIT_INPUT and len(lines) == 1
        assert "400 points, more than the limit of 100 points" in lines[0]
        assert "--max-points" in lines[0]
        code, lines = _smooth(capsys, path, "-o", out, "--max-memory", "4K", *tiled)
        assert code == EXIT_INPUT and "more than the limit of 4.0 KiB" in lines[0]
    code, lines = _smooth(capsys, path, "-o", out, "--max-memory", "lots")
    assert code == EXIT_USAGE and "--max-memory: expected a byte count" in lines[0]
    assert not out.exists()


def test_a_huge_las_header_in_a_child(tmp_path: Path) -> None:
    """The command a user runs: exit 3 and one line, not ``internal error: MemoryError``."""
    path = tmp_path / "huge.las"
    path.write_bytes(CASES["las_huge_count.las"])
    done = run_cli(["smooth", path, "-o", tmp_path / "o.las", "--tile-points", "1000"])
    assert done.returncode == EXIT_INPUT, done.stderr
    assert "the header declares 4294967295 points" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
