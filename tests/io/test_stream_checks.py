"""Issue 34 items 4 and 5 (io side): the streamed readers run the ordinary readers' checks, and
reader limits bound every path before anything is allocated.

Every hostile file of :mod:`tests.io.hostile_files` (and the corpus's LAS, LAZ, PLY and XYZ
files) that the streamed path takes is refused by :func:`service.io.stream.read_coordinates`
with the class, code and message :func:`service.io.read_geometry` gives it.
"""

from __future__ import annotations

import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from service.io import InputTooLarge, ReadLimits, read_geometry
from service.io.limits import limits_of, parse_count, reading
from service.io.stream import read_coordinates, streamable
from tests.io.hostile_files import all_cases, las_bytes

CASES = all_cases()
FMT = {".las": "las", ".laz": "laz", ".ply": "ply", ".xyz": "xyz"}
ROOT = Path(__file__).resolve().parents[2]


def _outcome(call: object) -> tuple[str, str, str]:
    try:
        call()  # type: ignore[operator]
    except Exception as exc:  # the class is what is compared
        return type(exc).__name__, str(getattr(exc, "code", "")), str(exc)
    return "ok", "", ""


@pytest.mark.parametrize("name", sorted(CASES))
def test_streamed_and_ordinary_readers_refuse_alike(name: str, tmp_path: Path) -> None:
    path = tmp_path / name
    path.write_bytes(CASES[name])
    fmt = FMT[path.suffix]
    ordinary = _outcome(lambda: read_geometry(path))
    if path.stat().st_size and not streamable(path, fmt):
        assert ordinary[0] != "ok"
        return
    streamed = _outcome(lambda: read_coordinates(path, fmt))
    if streamed[0] == "ok":  # non-finite coordinates are the engine's check (Geometry), later
        assert ordinary[0] in ("ok", "NonFiniteCoordinates"), ordinary
        return
    assert streamed == ordinary
    assert ordinary[0] != "InternalError" and "\n" not in ordinary[2]


HUGE = ["las_huge_count.las", "laz_huge_count.laz", "las14_huge_count.las",
        "ply_bin_huge_vertex_count.ply"]  # fmt: skip


@pytest.mark.parametrize("name", HUGE)
def test_a_huge_declared_count_allocates_nothing(name: str, tmp_path: Path) -> None:
    path = tmp_path / name
    path.write_bytes(CASES[name])
    tracemalloc.start()
    try:
        with pytest.raises(Exception, match=r"declares|truncated"):
            read_coordinates(path, FMT[path.suffix])
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64 << 20


def test_max_points_bounds_both_paths(tmp_path: Path) -> None:
    path = tmp_path / "p.las"
    path.write_bytes(las_bytes(400))
    small = ReadLimits(max_points=100)
    for read in (lambda: read_geometry(path, limits=small),
                 lambda: read_coordinates(path, "las", limits=small)):  # fmt: skip
        with pytest.raises(
            InputTooLarge, match=r"400 points, more than the limit of 100 .*--max-points"
        ):
            read()
    assert read_geometry(path, limits=ReadLimits(max_points=400)).geometry.n == 400
    assert read_coordinates(path, "las", limits=ReadLimits(max_points=None))[0].shape == (400, 3)


def test_max_memory_is_an_estimate_before_allocating(tmp_path: Path) -> None:
    path = tmp_path / "p.xyz"
    np.savetxt(path, np.random.default_rng(1).random((2000, 3)), fmt="%.6f")
    tight = ReadLimits(max_memory=10_000)
    for read in (lambda: read_geometry(path, limits=tight),
                 lambda: read_coordinates(path, "xyz", limits=tight)):  # fmt: skip
        with pytest.raises(InputTooLarge, match=r"needs about .* more than the limit of 9\.8 KiB"):
            read()
    with reading(ReadLimits(max_memory=None)):  # the context variable, as the CLI sets it
        assert read_geometry(path).geometry.n == 2000
    assert InputTooLarge.code == "input-too-large" and InputTooLarge.exit_code == 3


def test_every_format_counts_points_after_reading(tmp_path: Path) -> None:
    path = tmp_path / "p.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InputTooLarge, match="holds 3 points"):
        read_geometry(path, limits=ReadLimits(max_points=2))


@pytest.mark.parametrize(("text", "units", "value"), [
    ("1000", False, 1000), ("none", False, None), ("0", False, None), ("8G", True, 8 << 30),
    ("512MiB", True, 512 << 20), ("1.5k", True, 1536), ("123", True, 123),
])  # fmt: skip
def test_parse_count(text: str, units: bool, value: int | None) -> None:
    assert parse_count(text, units=units) == value


@pytest.mark.parametrize("text", ["lots", "-5", "8X"])
def test_parse_count_refuses(text: str) -> None:
    with pytest.raises(ValueError, match=r"expected|negative"):
        limits_of(max_memory=text)


def test_the_streamed_las_path_holds_a_huge_header_under_a_small_address_space(
    tmp_path: Path,
) -> None:
    """In a child limited to 1 GiB of address space: the 2**32-1 point header is a FormatError
    (before issue 34: MemoryError for 96 GiB, exit 1 in the CLI)."""
    path = tmp_path / "huge.las"
    path.write_bytes(CASES["las_huge_count.las"])
    code = (
        "import resource, sys\nresource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))\n"
        "from service.io.stream import read_coordinates\nfrom service.io.errors import "
        "FormatError\ntry:\n    read_coordinates(sys.argv[1], 'las')\nexcept FormatError as e:\n"
        "    print(e)\n"
    )
    out = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True,
                         timeout=120, cwd=ROOT, check=False)  # fmt: skip
    assert out.returncode == 0, out.stderr[-1500:]
    assert "declares 4294967295 points" in out.stdout
