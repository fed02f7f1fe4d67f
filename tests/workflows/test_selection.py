"""Issue 41 item 4: ``--where`` (PDAL's grammar, parsed, never evaluated as Python) and
``--fix-classes``: masks checked against NumPy written out by hand; the CLI holds the points
outside the selection bit-identical and refuses a bad expression with one line, exit 2."""

from __future__ import annotations

import io
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import pytest

from service.exit_codes import EXIT_OK, EXIT_USAGE
from service.workflows.selection import SelectionError, class_list, fixed_outside, selected
from tests.cli.conftest import REPO

RNG = np.random.default_rng(7)
N = 500
PTS = RNG.random((N, 3)) * 100
ATTRS = {
    "classification": RNG.integers(1, 8, N).astype(np.uint8),
    "intensity": RNG.integers(0, 400, N).astype(np.uint16),
    "return_number": RNG.integers(1, 4, N).astype(np.uint8),
}
C, INT, R = ATTRS["classification"], ATTRS["intensity"], ATTRS["return_number"]


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("Classification == 2", C == 2),
        ("classification != 2", C != 2),
        ("Intensity > 100 and ReturnNumber == 1", (INT > 100) & (R == 1)),
        ("Intensity <= 50 || Classification >= 6", (INT <= 50) | (C >= 6)),
        ("not (Classification == 7 or Classification == 2)", ~((C == 7) | (C == 2))),
        ("!(Z < 50) && return_number == 2", ~(PTS[:, 2] < 50) & (R == 2)),
        (
            "X > 10 and X < 2.5e1 or Y >= 99.5",
            ((PTS[:, 0] > 10) & (PTS[:, 0] < 25)) | (PTS[:, 1] >= 99.5),
        ),
        ("Intensity > -1", np.ones(N, dtype=bool)),
    ],
)
def test_where_selects_what_numpy_selects(text: str, expected: np.ndarray) -> None:
    assert np.array_equal(selected(text, PTS, ATTRS), expected)


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("", "empty"),
        ("Classification = 2", "cannot read"),
        ("Classification == ", "ends too early"),
        ("Classification == 2 and", "expected a dimension name"),
        ("(Classification == 2", "expected ')'"),
        ("Classification 2", "expected a comparison"),
        ("Classification == Intensity", "expected a number"),
        ("__import__('os').system('true')", "cannot read"),
        ("Colour == 2", "no dimension 'Colour'"),
    ],
)
def test_a_bad_expression_is_one_line_naming_the_problem(text: str, words: str) -> None:
    with pytest.raises(SelectionError, match=words.replace("(", r"\(").replace(")", r"\)")) as e:
        selected(text, PTS, ATTRS)
    assert "\n" not in e.value.message and e.value.status == 422 and e.value.field == "where"


def test_fix_classes_and_where_combine() -> None:
    got = fixed_outside(PTS, ATTRS, "Intensity > 100", class_list("6, 7"))
    assert np.array_equal(got, np.flatnonzero(~((INT > 100) & ~np.isin(C, [6, 7]))))
    with pytest.raises(SelectionError, match="0-255"):
        class_list("300")
    with pytest.raises(SelectionError, match="no classification"):
        fixed_outside(PTS, {}, None, [2])


def _las(path: Path) -> None:
    rng = np.random.default_rng(3)
    n = 3000
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales, header.offsets = np.array([0.001] * 3), np.array([500000.0, 5e6, 0.0])
    las = laspy.LasData(header)
    las.x, las.y = 500000 + rng.random(n) * 50, 5e6 + rng.random(n) * 50
    las.z = 10 + 0.4 * np.sin(np.asarray(las.x) / 5) + rng.normal(0, 0.02, n)
    las.classification = np.where(rng.random(n) < 0.6, 2, 5).astype(np.uint8)
    buf = io.BytesIO()
    las.write(buf)
    path.write_bytes(buf.getvalue())


def _cli(*args: object) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "service.cli", *map(str, args)], cwd=REPO,
                          capture_output=True, text=True, timeout=300, check=False)  # fmt: skip


def test_cli_smooths_the_selection_and_returns_the_rest_bit_identical(tmp_path: Path) -> None:
    src, out = tmp_path / "scan.las", tmp_path / "ground.las"
    _las(src)
    res = _cli("smooth", src, "-o", out, "--where", "Classification == 2", "--rms", "0.015")
    assert res.returncode == EXIT_OK, res.stderr
    a, b = laspy.read(src), laspy.read(out)
    ground = np.asarray(a.classification) == 2
    for dim in ("X", "Y", "Z"):
        assert np.array_equal(np.asarray(a[dim])[~ground], np.asarray(b[dim])[~ground])
    assert np.mean(np.asarray(a.Z)[ground] != np.asarray(b.Z)[ground]) > 0.5
    assert f"{ground.sum()} of {ground.size} points selected" in res.stderr
    res = _cli("smooth", src, "-o", tmp_path / "x.las", "--where", "Classification = 2")
    assert res.returncode == EXIT_USAGE and len(res.stderr.strip().splitlines()) == 1
    assert "--where" in res.stderr and not (tmp_path / "x.las").exists()
