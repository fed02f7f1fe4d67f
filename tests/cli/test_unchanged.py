"""``geosmooth smooth`` when nothing is smoothed (issue 32): the output is the input's bytes,
the summary says so, and ``--exit-unchanged N`` lets a batch branch on it."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable
from pathlib import Path

Run = Callable[..., subprocess.CompletedProcess[str]]


def test_wrench_copied_with_opt_in_exit_status(
    cli: Run, data: Callable[[str], Path], tmp_path: Path
) -> None:
    src = data("wrench.dxf")
    out, rep = tmp_path / "w.dxf", tmp_path / "r.json"
    res = cli(["smooth", src, "-o", out, "--report", rep, "--exit-unchanged", "13"])
    assert res.returncode == 13, res.stderr
    assert "returned unchanged: input bytes copied" in res.stderr
    assert out.read_bytes() == src.read_bytes()
    assert json.loads(rep.read_text())["unchanged"] == "copied"
    default = cli(["smooth", src, "-o", tmp_path / "d.dxf", "-q"])  # default: exit 0
    assert default.returncode == 0, default.stderr
    assert (tmp_path / "d.dxf").read_bytes() == src.read_bytes()


def test_across_formats_converted_unchanged(
    cli: Run, data: Callable[[str], Path], tmp_path: Path
) -> None:
    res = cli(["smooth", data("wrench.dxf"), "-o", tmp_path / "w.obj",
               "--exit-unchanged", "3"])  # fmt: skip
    assert res.returncode == 3, res.stderr
    assert "converted unchanged" in res.stderr


def test_smoothed_run_keeps_exit_zero(cli: Run, tmp_path: Path) -> None:
    src = tmp_path / "in.xyz"
    src.write_text("".join(f"{i * 0.1:.3f} {(-1) ** i * 0.05:.3f}\n" for i in range(200)))
    res = cli(["smooth", src, "-o", tmp_path / "o.xyz", "--rms", "0.02", "--exit-unchanged",
               "13", "-q"])  # fmt: skip
    assert res.returncode == 0, res.stderr


def test_exit_unchanged_must_be_a_status(cli: Run, tmp_path: Path) -> None:
    src = tmp_path / "in.xyz"
    src.write_text("0 0\n1 1\n")
    res = cli(["smooth", src, "-o", tmp_path / "o.xyz", "--exit-unchanged", "256"])
    assert res.returncode == 2 and "exit status 0..255" in res.stderr
