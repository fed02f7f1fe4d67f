"""``--normals`` and ``--precision``: options of the writer (``service.io.write_geometry``).

The CLI generates them from the writer's keyword arguments, so they exist exactly when the
writer has them (the io helper's write options; the writer has them, so the tests always run).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from service import cli
from service.cli.output import writer_options


def test_the_writer_has_the_options() -> None:
    assert {"normals", "precision"} <= set(writer_options())


def _ply_with_normals(path: Path) -> np.ndarray:
    """A noisy octahedron-ish sphere with unit vertex normals, ASCII PLY with doubles."""
    rng = np.random.default_rng(7)
    t = rng.normal(size=(60, 3))
    pts = t / np.linalg.norm(t, axis=1)[:, None] + rng.normal(0, 0.01, (60, 3))
    normals = pts / np.linalg.norm(pts, axis=1)[:, None]
    header = [
        "ply", "format ascii 1.0", "element vertex 60",
        *(f"property double {c}" for c in ("x", "y", "z", "nx", "ny", "nz")), "end_header",
    ]  # fmt: skip
    rows = [" ".join(repr(float(v)) for v in (*p, *n)) for p, n in zip(pts, normals, strict=True)]
    path.write_text("\n".join(header + rows) + "\n")
    return pts


def _header(path: Path) -> list[str]:
    head = path.read_bytes().split(b"end_header", 1)[0].decode("ascii")
    return [line for line in head.splitlines() if line.startswith("property")]


def test_normals_recomputed_or_dropped(tmp_path: Path) -> None:
    src = tmp_path / "cloud.ply"
    _ply_with_normals(src)
    kept, dropped = tmp_path / "kept.ply", tmp_path / "dropped.ply"
    common = ["--rms", "0.01", "--neighborhood", "knn", "--k", "8", "-q"]
    assert cli.main(["smooth", str(src), "-o", str(kept), *common]) == 0
    assert cli.main(["smooth", str(src), "-o", str(dropped), "--normals", "drop", *common]) == 0
    assert any(p.endswith(" nx") for p in _header(kept))
    assert not any(p.endswith(" nx") for p in _header(dropped))


def test_precision_float32_and_float64(tmp_path: Path) -> None:
    src = tmp_path / "cloud.ply"
    _ply_with_normals(src)
    for precision, kind in (("float32", "float"), ("float64", "double")):
        out = tmp_path / f"{precision}.ply"
        argv = ["smooth", str(src), "-o", str(out), "--rms", "0.01", "--neighborhood", "knn",
                "--precision", precision, "--normals", "drop", "-q"]  # fmt: skip
        assert cli.main(argv) == 0
        assert [p.split()[1] for p in _header(out) if p.split()[-1] in "xyz"] == [kind] * 3


def test_bad_choice_is_a_usage_error(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    argv = ["smooth", str(tmp_path / "in.ply"), "-o", str(tmp_path / "o.ply"), "--tau", "1",
            "--precision", "float16"]  # fmt: skip
    assert cli.main(argv) == 2
    assert "--precision: invalid choice: 'float16'" in capsys.readouterr().err
