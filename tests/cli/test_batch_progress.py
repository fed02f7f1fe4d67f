"""Issue 41 item 6: a batch's lines say ``[k/N]``, the batch's time so far and the time left,
and each file's warnings in words (not "2 warnings")."""

from __future__ import annotations

import re
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

from service.cli.batch import BatchClock
from service.exit_codes import EXIT_OK
from tests.cli.conftest import REPO

Run = Callable[..., subprocess.CompletedProcess[str]]
SPHERE = REPO / "service" / "samples" / "noisy-sphere.ply"


def test_batch_lines_count_time_and_spell_out_warnings(cli: Run, tmp_path: Path) -> None:
    for name in ("a", "b", "c"):
        shutil.copy(SPHERE, tmp_path / f"{name}.ply")
    res = cli(["smooth", *(tmp_path / f"{n}.ply" for n in "abc"), "-o", f"{tmp_path}/out/",
               "--rms", "0.2"])  # fmt: skip
    assert res.returncode == EXIT_OK, res.stderr
    files = [ln for ln in res.stderr.splitlines() if re.match(r"geosmooth: \[\d/3\] ", ln)]
    assert [ln.split()[1] for ln in files] == ["[1/3]", "[2/3]", "[3/3]"]
    assert all("s left)" in ln for ln in files[:2]) and "left" not in files[2]
    warned = [ln for ln in res.stderr.splitlines() if ln.startswith("  warning: ")]
    assert len(warned) >= 3 and all("lower rms" in w or "rms" in w for w in warned)
    assert "volume changed" in res.stderr


def test_time_left_is_the_time_so_far_over_the_bytes_done() -> None:
    helix = REPO / "service" / "samples" / "noisy-helix.obj"
    clock = BatchClock([str(helix), str(SPHERE)], started=0.0)
    k, times = clock.done(str(helix))
    assert k == "[1/2]" and clock.bytes_done == helix.stat().st_size
    assert clock.total == helix.stat().st_size + SPHERE.stat().st_size
    so_far = float(times.split()[1])  # "batch 12.3 s, ~40 s left"
    left = float(times.split("~")[1].split()[0])
    expected = so_far * SPHERE.stat().st_size / helix.stat().st_size
    assert abs(left - expected) <= 0.5 + 1e-3 * expected  # rounded to whole seconds
