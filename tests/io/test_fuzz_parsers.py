"""Issue 42 item 4: 1,200 seeded mutants of the formats with third-party parsers (LAS, LAZ, E57,
GeoJSON, GPX, DXF; :mod:`tests.io.fuzz_corpus`) give 0 internal errors, no native abort and
nothing on stderr; through the CLI with ``-q``, a malformed one gives one stderr line."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.io.fuzz_corpus import write_corpus

ROOT = Path(__file__).resolve().parents[2]
PER_FORMAT = 200


@pytest.fixture(scope="module")
def corpus(tmp_path_factory: pytest.TempPathFactory) -> Path:
    dest = tmp_path_factory.mktemp("fuzz")
    write_corpus(dest, PER_FORMAT)
    return dest


def test_no_mutant_is_an_internal_error_or_an_abort(corpus: Path) -> None:
    done = subprocess.run([sys.executable, "-m", "tests.io.fuzz_corpus", "--read", str(corpus)],
                          cwd=ROOT, capture_output=True, text=True, timeout=1800,
                          check=False)  # fmt: skip
    last = done.stdout.strip().splitlines()[-1] if done.stdout.strip() else ""
    assert done.returncode == 0 and last.startswith("RESULT "), (
        f"the reader died (status {done.returncode}) at: {last}\n{done.stderr[-1500:]}"
    )
    counts = json.loads(last.removeprefix("RESULT "))
    print(json.dumps(counts, sort_keys=True))  # the table of the closing note (pytest -s)
    assert sum(sum(c.values()) for c in counts.values()) == 6 * PER_FORMAT
    internal = {f: [k for k in c if k.startswith("internal")] for f, c in counts.items()}
    assert not any(internal.values()), internal
    assert all(c.get("FormatError", 0) > 0 for c in counts.values()), counts  # really hostile
    assert done.stderr == "", done.stderr[-2000:]  # no warnings, no ezdxf or Rust lines


@pytest.mark.parametrize("ext", ["las", "laz", "e57", "geojson", "gpx", "dxf"])
def test_a_malformed_mutant_is_one_line_with_q(corpus: Path, ext: str, tmp_path: Path) -> None:
    from service.io import read_geometry
    from service.io.errors import FormatError

    for path in sorted(corpus.glob(f"*.{ext}")):  # the first one the reader refuses
        try:
            read_geometry(path)
        except FormatError:
            break
    else:
        pytest.fail(f"no malformed {ext} mutant")
    done = subprocess.run([sys.executable, "-m", "service.cli", "smooth", str(path), "-q", "-o",
                           str(tmp_path / f"out.{ext}")], cwd=ROOT, capture_output=True,
                          text=True, timeout=300, check=False)  # fmt: skip
    assert done.returncode == 3, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("geosmooth: error:"), done.stderr
