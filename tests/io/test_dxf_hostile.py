"""DXF entities with non-finite or overflowing numbers: a FormatError in bounded time (issue 20).

ezdxf's geometry loops forever on a NaN-centre circle or a 1e300 radius; the reader checks every
number of a supported entity before any geometry call. Each file is read in a child process with
a wall-clock bound, so a regression fails instead of hanging the suite.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from service.io import read_geometry
from service.io.errors import FormatError

BOUND = 60.0  # seconds per file in a child (measured: < 1 s each, 2-core machine under load)


def _entities(body: str) -> bytes:
    return f"0\nSECTION\n2\nENTITIES\n{body}0\nENDSEC\n0\nEOF\n".encode()


def _entity(kind: str, codes: list[tuple[int, object]]) -> str:
    return f"0\n{kind}\n8\n0\n" + "".join(f"{c}\n{v}\n" for c, v in codes)


HOSTILE = {
    "nan_circle": _entity("CIRCLE", [(10, "nan"), (20, 0), (40, 1)]),
    "huge_circle": _entity("CIRCLE", [(10, 0), (20, 0), (40, "1e300")]),
    "inf_line": _entity("LINE", [(10, 0), (20, 0), (11, "inf"), (21, 1)]),
    "nan_arc_angle": _entity("ARC", [(10, 0), (20, 0), (40, 1), (50, "nan"), (51, 90)]),
    "huge_arc": _entity("ARC", [(10, 0), (20, 0), (40, "1e200"), (50, 0), (51, 90)]),
    "nan_ellipse": _entity(
        "ELLIPSE", [(10, 0), (20, 0), (11, 1), (21, 0), (40, "nan"), (41, 0), (42, 6.28)]
    ),
    "nan_extrusion": _entity(
        "CIRCLE", [(10, 0), (20, 0), (40, 1), (210, "nan"), (220, 0), (230, 1)]
    ),
    "polyline_nan": "0\nPOLYLINE\n8\n0\n66\n1\n70\n8\n0\nVERTEX\n8\n0\n10\n0\n20\n0\n30\n0\n70\n32"
    "\n0\nVERTEX\n8\n0\n10\nnan\n20\n1\n30\n0\n70\n32\n0\nSEQEND\n",
    "zero_arc": _entity("ARC", [(10, 0), (20, 0), (40, 0), (50, 0), (51, 90)]),
}


def test_the_nan_circle_is_71_bytes_or_less() -> None:
    assert len(_entities(HOSTILE["nan_circle"])) <= 71


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_hostile_entity_is_a_format_error_in_bounded_time(name: str, tmp_path: Path) -> None:
    path = tmp_path / f"{name}.dxf"
    path.write_bytes(_entities(HOSTILE[name]))
    code = (
        "import sys\nfrom service.io import read_geometry\nfrom service.io.errors import "
        "FormatError\ntry:\n    read_geometry(sys.argv[1])\nexcept FormatError as e:\n"
        "    print('FormatError', e)\n    sys.exit(0)\nsys.exit(2)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[2])}
    out = subprocess.run(
        [sys.executable, "-c", code, str(path)], capture_output=True, text=True,
        timeout=BOUND, env=env,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.startswith("FormatError DXF")


def test_message_names_the_entity_and_the_value(tmp_path: Path) -> None:
    path = tmp_path / "c.dxf"
    path.write_bytes(_entities(HOSTILE["huge_circle"]))
    with pytest.raises(FormatError, match=r"CIRCLE .* 1e\+300"):
        read_geometry(path)


def test_large_finite_drawing_still_reads(tmp_path: Path) -> None:
    """Georeferenced coordinates (6e5 / 5e6) are far inside the bound."""
    body = _entity("LINE", [(10, 6.0e5), (20, 5.6e6), (11, 6.0e5 + 10), (21, 5.6e6 + 3)])
    path = tmp_path / "geo.dxf"
    path.write_bytes(_entities(body))
    doc = read_geometry(path)
    assert doc.geometry.n == 2
    assert doc.geometry.points[1, 0] == pytest.approx(6.0e5 + 10)
