"""Where ``-o`` and ``--report`` write: never a device, FIFO or link replaced by a regular file.

Issue 15 (items 7 and 11): ``-o /dev/full`` used to replace the device with a regular file
(the atomic rename). Regular files are still replaced atomically; symbolic links are followed
(the link stays, its target is replaced); anything else is written in place.
"""

from __future__ import annotations

import os
import stat
import threading
from pathlib import Path

import numpy as np
import pytest

from service import cli
from service.cli.output import write_file
from service.io import read_geometry

SAMPLE = Path(__file__).resolve().parents[2] / "service" / "samples" / "noisy-helix.obj"


def _smooth(output: Path | str, *extra: str) -> int:
    return cli.main(["smooth", str(SAMPLE), "-o", str(output), "--rms", "0.03", "-q", *extra])


def _expected_points(tmp_path: Path) -> np.ndarray:
    assert _smooth(tmp_path / "reference.obj") == 0
    return read_geometry(tmp_path / "reference.obj").geometry.points


def test_dev_full_is_an_output_error_and_stays_a_device(
    capsys: pytest.CaptureFixture[str],
) -> None:
    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full")
    before = os.stat("/dev/full")
    assert _smooth("/dev/full", "--format", "obj") == 6
    line = capsys.readouterr().err.strip()
    assert line == "geosmooth: error: cannot write output /dev/full: No space left on device"
    after = os.stat("/dev/full")
    assert stat.S_ISCHR(after.st_mode) and after.st_rdev == before.st_rdev


def test_dev_null_is_written_in_place(tmp_path: Path) -> None:
    assert _smooth("/dev/null", "--format", "obj", "--report", "/dev/null") == 0
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


def test_fifo_gets_the_data_and_stays_a_fifo(tmp_path: Path) -> None:
    fifo = tmp_path / "out.obj"
    os.mkfifo(fifo)
    received: list[bytes] = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()), daemon=True)
    reader.start()
    assert _smooth(fifo) == 0
    reader.join(30)
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    copy = tmp_path / "copy.obj"
    copy.write_bytes(received[0])
    np.testing.assert_array_equal(
        read_geometry(copy).geometry.points, _expected_points(tmp_path)
    )


def test_symlink_is_followed_and_stays_a_link(tmp_path: Path) -> None:
    target_dir = tmp_path / "real"
    target_dir.mkdir()
    target = target_dir / "result.obj"
    target.write_text("old contents\n")
    target.chmod(0o640)
    link = tmp_path / "link.obj"
    link.symlink_to(target)
    assert _smooth(link) == 0
    assert link.is_symlink() and link.resolve() == target
    assert stat.S_IMODE(target.stat().st_mode) == 0o640  # the replaced file keeps its mode
    points = read_geometry(target).geometry.points
    np.testing.assert_array_equal(points, _expected_points(tmp_path))
    assert sorted(p.name for p in target_dir.iterdir()) == ["result.obj"]  # no stray temp file

    dangling = tmp_path / "dangling.obj"
    dangling.symlink_to(target_dir / "new.obj")
    assert _smooth(dangling) == 0
    assert dangling.is_symlink() and (target_dir / "new.obj").is_file()


def test_failed_atomic_write_keeps_the_old_file(tmp_path: Path) -> None:
    target = tmp_path / "keep.obj"
    target.write_text("old\n")

    with pytest.raises(TypeError):  # fails while writing the temporary file
        write_file(target, 42)  # type: ignore[arg-type]
    assert target.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.obj"]
