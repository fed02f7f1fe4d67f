"""Issue 42 findings 3 and 4 (io side): counts are checked before allocating, and a failure in a
third-party parser is the file's error.

E57 files are written by pye57 and their ``recordCount`` changed afterwards (the XML's page
checksums redone, :func:`tests.io.hostile_files.e57_with_record_count`); the four files that
were internal errors (:func:`tests.io.hostile_files.parser_cases`) are read by the library and by
the CLI in a child process (a lazrs abort would kill the test process otherwise).
"""

from __future__ import annotations

import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from service.io import InputTooLarge, ReadLimits, read_geometry
from service.io.errors import FormatError
from tests.io.hostile_files import e57_bytes, e57_with_record_count, parser_cases

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def e57_file() -> bytes:
    return e57_bytes(1000)


def test_an_honest_e57_is_read_as_pye57_reads_it(e57_file: bytes, tmp_path: Path) -> None:
    import pye57

    path = tmp_path / "scan.e57"
    path.write_bytes(e57_with_record_count(e57_file, 1000))  # the rewrite itself is harmless
    ref = pye57.E57(str(path)).read_scan_raw(0)
    got = read_geometry(path).geometry.points
    expected = np.column_stack([ref["cartesianX"], ref["cartesianY"], ref["cartesianZ"]])
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("count", [300_000_000, 1_000_000_000, 2**40])
def test_a_record_count_the_file_cannot_hold_allocates_nothing(
    e57_file: bytes, tmp_path: Path, count: int
) -> None:
    """Before: 3e8 reached 15.2 GB in the CLI, 1e9 was OOM-killed at 20.3 GB."""
    path = tmp_path / "lie.e57"
    path.write_bytes(e57_with_record_count(e57_file, count))
    tracemalloc.start()
    try:
        with pytest.raises(FormatError, match=rf"declares {count} points \(recordCount\)"):
            read_geometry(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 16 << 20


@pytest.mark.parametrize("count", [1001, 1200])
def test_a_record_count_beyond_the_data_is_no_uninitialised_points(
    e57_file: bytes, tmp_path: Path, count: int
) -> None:
    """pye57 hands back its np.empty buffers whole: 1001 declared, 1000 stored gave a 1001st
    point of uninitialised memory (smoothed and written)."""
    path = tmp_path / "lie.e57"
    path.write_bytes(e57_with_record_count(e57_file, count))
    with pytest.raises(FormatError, match=rf"holds 1000 points, its recordCount says {count}"):
        read_geometry(path)


def test_an_e57_over_max_memory_is_input_too_large(e57_file: bytes, tmp_path: Path) -> None:
    path = tmp_path / "scan.e57"
    path.write_bytes(e57_file)
    with pytest.raises(InputTooLarge, match="1000 points"):
        read_geometry(path, limits=ReadLimits(max_memory=100_000))  # ~200 bytes a point
    with pytest.raises(InputTooLarge, match="limit of 999 points"):
        read_geometry(path, limits=ReadLimits(max_points=999))
    assert read_geometry(path, limits=ReadLimits(max_points=1000)).geometry.n == 1000


EXPECTED = {  # file: (error class, code, words of the message, CLI exit status)
    "big_integer.geojson": ("FormatError", "format-error", "coordinate is out of range", 3),
    "ele_1e308.gpx": ("NonFiniteCoordinates", "non-finite-coordinates", "span 1e+308", 4),
    "non_utf8.dxf": ("FormatError", "format-error", "damaged beyond recovery", 3),
    "chunk_table.laz": ("FormatError", "format-error", "declares 3254779905 chunks", 3),
}


@pytest.mark.parametrize("name", [n for n in sorted(EXPECTED) if not n.endswith(".laz")])
def test_the_four_files_are_clean_errors_in_the_library(name: str) -> None:
    """(The LAZ file is read in the child processes below: an abort would end this one.)"""
    kind, code, words, _ = EXPECTED[name]
    with pytest.raises(Exception) as info:
        read_geometry(parser_cases()[name], filename=name)
    assert type(info.value).__name__ == kind and info.value.code == code  # type: ignore[attr-defined]
    assert words in str(info.value)


@pytest.mark.parametrize("name", sorted(EXPECTED))
@pytest.mark.parametrize("command", ["smooth", "info"])
def test_the_four_files_are_one_line_and_a_documented_status_in_the_cli(
    name: str, command: str, tmp_path: Path
) -> None:
    _, _, words, status = EXPECTED[name]
    path = tmp_path / name
    path.write_bytes(parser_cases()[name])
    args = [str(path)] + (["-q", "-o", str(tmp_path / f"o-{name}")] if command == "smooth" else [])
    env = {"PATH": "/usr/bin:/bin", "RUST_BACKTRACE": "1"}  # a Rust panic would print its trace
    done = subprocess.run([sys.executable, "-m", "service.cli", command, *args], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=300,
                          check=False)  # fmt: skip
    assert done.returncode == status, done.stderr[-2000:]
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("geosmooth: error:"), done.stderr[-2000:]
    assert words in lines[0]


def test_a_point_format_the_version_cannot_hold_is_refused_at_the_read() -> None:
    """Point format 6 in a LAS 1.2 file was smoothed, then refused by the writer (exit 6)."""
    from tests.io.hostile_files import las_cases

    with pytest.raises(FormatError, match=r"point format 6 does not exist in LAS 1\.2"):
        read_geometry(las_cases()["las_version_contradiction.las"], filename="a.las")


def test_parser_failures_are_the_files_errors() -> None:
    """What a reader hits inside a third-party parser (dispatch.parser_failures): a real
    allocation failure is input-too-large (the CLI's exit 3, not exit 1), an overflow or an
    assertion is a format error."""
    from service.io.dispatch import parser_failures

    with pytest.raises(InputTooLarge, match="ran out of memory"), parser_failures("json"):
        np.empty(2**62, dtype=np.uint8)  # numpy raises its MemoryError subclass
    with pytest.raises(FormatError, match="OverflowError"), parser_failures("json"):
        float(10**400)
    with pytest.raises(FormatError, match="AssertionError"), parser_failures("dxf"):
        assert isinstance(b"x", str)


def test_gpx_entity_expansion_is_refused_before_it_grows() -> None:
    """A 'billion laughs' GPX (10**9 copies of an entity, 3 GB expanded): expat's amplification
    limit (100x, from 8 MiB of expansion on) refuses it as a format error."""
    ents = "".join(f'<!ENTITY e{i} "{f"&e{i - 1};" * 10}">' for i in range(1, 10))
    data = (f'<?xml version="1.0"?><!DOCTYPE gpx [<!ENTITY e0 "lol">{ents}]>'
            '<gpx version="1.1" creator="t" xmlns="http://www.topografix.com/GPX/1/1">'
            "<metadata><desc>&e9;</desc></metadata><trk><trkseg><trkpt lat='1' lon='1'/>"
            "<trkpt lat='1.001' lon='1'/><trkpt lat='1.002' lon='1.001'/>"
            "</trkseg></trk></gpx>")  # fmt: skip
    with pytest.raises(FormatError, match="amplification"):
        read_geometry(data.encode(), filename="laughs.gpx")
