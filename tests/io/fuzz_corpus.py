"""A seeded corpus of mutated files of the formats with third-party parsers (issue 42 item 4).

``python -m tests.io.fuzz_corpus DIR N``: writes ``N`` mutants per format into ``DIR`` (the
same files for the same ``N``). Each mutant comes from a valid file (written by the format's
reference writer: laspy/lazrs, pye57, ezdxf, plain GeoJSON/GPX text) by one seeded mutation:
bytes overwritten, a cut, a span repeated, or a hostile token put in place of a number (a
400-digit integer, ``1e308``, ``nan``, non-UTF-8 bytes).

:func:`read_all` reads a directory of them with :func:`service.io.read_geometry` and counts
the outcome of each file by format: ``ok``, a typed error class, or ``internal`` (anything
else). It runs in a child process (``python -m tests.io.fuzz_corpus --read DIR``) so that a
native abort shows as the child's death, naming the file it was reading.
"""

from __future__ import annotations

import collections
import io
import json
import re
import sys
from pathlib import Path

import numpy as np

from tests.io.hostile_files import e57_bytes, las_bytes

TOKENS = [b"9" * 400, b"1e308", b"-1e308", b"nan", b"inf", b"\xff\xfe\x80", b"0", b"-1",
          b"4294967295", b"1e-320"]  # fmt: skip


def _geojson() -> bytes:
    t = np.linspace(0, 1, 40)
    coords = np.c_[7 + 0.01 * t, 46 + 0.01 * np.sin(6 * t), 100 + t].round(6).tolist()
    line = {"type": "LineString", "coordinates": coords}
    feature = {"type": "Feature", "properties": {}, "geometry": line}
    return json.dumps({"type": "FeatureCollection", "features": [feature]}).encode()


def _gpx() -> bytes:
    t = np.linspace(0, 1, 40)
    pts = b"".join(b'<trkpt lat="%.6f" lon="%.6f"><ele>%.1f</ele></trkpt>\n'
                   % (46 + 0.01 * np.sin(6 * a), 7 + 0.01 * a, 100 + a) for a in t)  # fmt: skip
    return (b'<?xml version="1.0"?>\n<gpx version="1.1" creator="t" '
            b'xmlns="http://www.topografix.com/GPX/1/1"><trk><trkseg>\n' + pts
            + b"</trkseg></trk></gpx>\n")  # fmt: skip


def _dxf() -> bytes:
    import ezdxf

    doc = ezdxf.new("R2000")
    msp = doc.modelspace()
    msp.add_lwpolyline([(i, np.sin(i / 3.0)) for i in range(30)])
    msp.add_line((0, 0), (5, 5))
    msp.add_arc((0, 0), 2.0, 0, 90)
    out = io.StringIO()
    doc.write(out)
    return out.getvalue().encode()


def seeds() -> dict[str, bytes]:
    """The valid file of each format (``ext -> bytes``)."""
    return {"las": las_bytes(300), "laz": las_bytes(3000, compress=True), "e57": e57_bytes(300),
            "geojson": _geojson(), "gpx": _gpx(), "dxf": _dxf()}  # fmt: skip


_NUMBER = re.compile(rb"-?\d+(\.\d+)?([eE][-+]?\d+)?")


def mutate(data: bytes, rng: np.random.Generator) -> bytes:
    """One seeded mutation of ``data``."""
    kind = int(rng.integers(0, 4))
    buf = bytearray(data)
    n = len(buf)
    if kind == 0:  # a few bytes overwritten
        for _ in range(int(rng.integers(1, 5))):
            buf[int(rng.integers(0, n))] = int(rng.integers(0, 256))
        return bytes(buf)
    if kind == 1:  # cut
        return bytes(buf[: int(rng.integers(0, n))])
    if kind == 2:  # a span repeated
        a = int(rng.integers(0, n))
        b = min(n, a + int(rng.integers(1, 64)))
        return bytes(buf[:b] + buf[a:b] * int(rng.integers(1, 20)) + buf[b:])
    numbers = list(_NUMBER.finditer(data))  # a hostile token for a number
    if not numbers:
        return bytes(buf)
    m = numbers[int(rng.integers(0, len(numbers)))]
    return data[: m.start()] + TOKENS[int(rng.integers(0, len(TOKENS)))] + data[m.end() :]


def write_corpus(dest: Path, per_format: int, seed: int = 42) -> list[Path]:
    """``per_format`` mutants of each format in ``dest``; their paths."""
    dest.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    paths = []
    for ext, data in seeds().items():
        for i in range(per_format):
            path = dest / f"{ext}-{i:04d}.{ext}"
            path.write_bytes(mutate(data, rng))
            paths.append(path)
    return paths


def read_all(directory: Path) -> dict[str, dict[str, int]]:
    """Outcome counts by format of reading every file of ``directory`` (prints each file's
    name before reading it, so that a crash names it)."""
    from service.core.errors import GeosmoothError
    from service.io import read_geometry
    from service.io.errors import FormatError

    counts: dict[str, collections.Counter[str]] = collections.defaultdict(collections.Counter)
    for path in sorted(directory.iterdir()):
        print(f"reading {path.name}", file=sys.stdout, flush=True)
        try:
            read_geometry(path)
            outcome = "ok"
        except (FormatError, GeosmoothError) as exc:
            outcome = type(exc).__name__
        except Exception as exc:
            outcome = f"internal {type(exc).__name__}: {str(exc)[:80]}"
        counts[path.suffix[1:]][outcome] += 1
    return {fmt: dict(c) for fmt, c in counts.items()}


if __name__ == "__main__":
    if sys.argv[1] == "--read":
        print("RESULT " + json.dumps(read_all(Path(sys.argv[2]))), flush=True)
    else:
        print(len(write_corpus(Path(sys.argv[1]), int(sys.argv[2]))))
