"""``geosmooth smooth A B … -o DIR/``: batches, their summary and exit status (issue 32 item 5),
``python -m geosmooth``, ``geosmooth completion``, ``--crs`` and ``worker`` without RQ."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from service.cli.batch import SEVERITY, job_bound, worst
from service.exit_codes import (
    EXIT_GEOMETRY,
    EXIT_INPUT,
    EXIT_INTERNAL,
    EXIT_OK,
    EXIT_OUTPUT,
    EXIT_SHAPE,
    EXIT_USAGE,
)
from tests.cli.conftest import REPO

Run = Callable[..., subprocess.CompletedProcess[str]]
SAMPLES = REPO / "service" / "samples"
HELIX, SPHERE = SAMPLES / "noisy-helix.obj", SAMPLES / "noisy-sphere.ply"


def _lines(res: subprocess.CompletedProcess[str]) -> list[str]:
    return res.stderr.splitlines()


def test_a_batch_writes_each_file_and_one_line_each_plus_a_total(cli: Run, tmp_path: Path) -> None:
    out = tmp_path / "out"
    report = tmp_path / "batch.json"
    res = cli(["smooth", HELIX, SPHERE, "-o", f"{out}/", "--name", "{stem}-smooth.{ext}",
               "--output-format", "ply", "-j", "2", "--rms", "0.02",
               "--report", report])  # fmt: skip
    assert res.returncode == EXIT_OK, res.stderr
    assert sorted(p.name for p in out.iterdir()) == ["noisy-helix-smooth.ply",
                                                     "noisy-sphere-smooth.ply"]  # fmt: skip
    lines = [line for line in _lines(res) if "lowered" not in line]
    assert len(lines) == 3, res.stderr
    assert any(f"{HELIX} -> {out}/noisy-helix-smooth.ply: curve, 200 points" in x for x in lines)
    assert lines[-1].startswith("geosmooth: 2 files: 2 smoothed, 0 failed;")
    assert lines[-1].endswith("exit status 0")
    body = json.loads(report.read_text())
    assert body["exit_status"] == 0 and len(body["files"]) == 2
    assert all(f["report"]["rms_displacement"] > 0 for f in body["files"])


def test_the_batch_exit_status_is_the_worst_of_the_files(cli: Run, tmp_path: Path) -> None:
    broken = tmp_path / "broken.obj"
    broken.write_text("v 0 0 0\nv 1 1\n")
    notes = tmp_path / "notes.md"
    notes.write_text("# not geometry\n")
    res = cli(["smooth", HELIX, broken, notes, "-o", f"{tmp_path}/out/", "-q"])
    assert res.returncode == EXIT_INPUT, res.stderr
    lines = _lines(res)  # -q: the failures and the total only
    assert len(lines) == 3, res.stderr
    assert any(f"{broken}: error (exit 3):" in x and "line 2" in x for x in lines)
    assert any(f"{notes}: error (exit 3): unknown format" in x for x in lines)
    assert "1 smoothed, 2 failed (2 with exit 3)" in lines[-1]
    assert (tmp_path / "out" / "noisy-helix.obj").is_file()


def test_a_quoted_glob_is_expanded_and_an_empty_one_is_an_input_error(
    cli: Run, tmp_path: Path
) -> None:
    scans = tmp_path / "scans" / "day1"
    scans.mkdir(parents=True)
    shutil.copy(HELIX, scans / "a.obj")
    shutil.copy(HELIX, tmp_path / "scans" / "b.obj")
    res = cli(["smooth", f"{tmp_path}/scans/**/*.obj", "-o", f"{tmp_path}/out/", "-q"])
    assert res.returncode == EXIT_OK, res.stderr
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["a.obj", "b.obj"]
    res = cli(["smooth", f"{tmp_path}/none/*.ply", "-o", f"{tmp_path}/out/"])
    assert res.returncode == EXIT_INPUT and "no file matches" in res.stderr


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["{h}", "{s}", "-o", "{t}/one.ply"], "need an output directory"),
        (["{h}", "-", "-o", "{t}/d/"], "takes one input"),
        (["{h}", "{s}", "-o", "{t}/d/", "--fixed", "{h}"], "--fixed"),
        (["{h}", "{t}/x/noisy-helix.obj", "-o", "{t}/d/"], "would both be written"),
        (["{h}", "{s}", "-o", "{samples}/"], "overwritten by its own output"),
        (["{h}", "{s}", "-o", "{t}/d/", "--name", "{{bad}}.obj"], "--name"),
        (["{h}", "{s}", "-o", "{t}/d/", "-j", "-1"], "-j"),
    ],
)
def test_batch_mistakes_are_usage_errors_before_any_work(
    cli: Run, tmp_path: Path, args: list[str], words: str
) -> None:
    (tmp_path / "x").mkdir()
    shutil.copy(HELIX, tmp_path / "x" / "noisy-helix.obj")
    fill = {"h": str(HELIX), "s": str(SPHERE), "t": str(tmp_path), "samples": str(SAMPLES)}
    res = cli(["smooth", *(a.format(**fill) for a in args)])
    assert res.returncode == EXIT_USAGE, res.stderr
    assert len(_lines(res)) == 1 and words in res.stderr, res.stderr
    assert not (tmp_path / "d").exists()


def test_severity_orders_the_documented_statuses() -> None:
    assert worst([EXIT_OK, EXIT_SHAPE, EXIT_GEOMETRY]) == EXIT_GEOMETRY
    assert worst([EXIT_INPUT, EXIT_OUTPUT, EXIT_USAGE]) == EXIT_OUTPUT
    assert worst([EXIT_OUTPUT, EXIT_INTERNAL]) == EXIT_INTERNAL
    assert worst([EXIT_OK, 7]) == 7 and worst([7, EXIT_INTERNAL]) == EXIT_INTERNAL
    assert worst([]) == EXIT_OK
    docs = (REPO / "docs" / "cli.md").read_text()
    assert " < ".join(str(c) for c in SEVERITY) in docs


def test_jobs_are_bounded_by_the_machine(cli: Run, tmp_path: Path) -> None:
    bound, why = job_bound([str(HELIX), str(SPHERE), str(HELIX)])
    assert 1 <= bound <= min(len(os.sched_getaffinity(0)), 3) and "core" in why
    res = cli(["smooth", HELIX, SPHERE, "-o", f"{tmp_path}/d/", "-j", "64", "--rms", "0.02"])
    assert res.returncode == EXIT_OK, res.stderr
    assert f"-j 64 lowered to {min(bound, 2)}" in res.stderr


def test_python_m_geosmooth_is_the_command() -> None:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(REPO / "clients/python")])}
    res = subprocess.run([sys.executable, "-m", "geosmooth", "--version"], capture_output=True,
                         text=True, env=env, cwd=REPO, timeout=60, check=False)  # fmt: skip
    assert res.returncode == 0 and res.stdout.startswith("geosmooth "), res.stderr


def test_bash_completion_completes_commands_choices_and_files(cli: Run, tmp_path: Path) -> None:
    res = cli(["completion", "bash"])
    assert res.returncode == 0, res.stderr
    script = tmp_path / "geosmooth.bash"
    script.write_text(res.stdout)
    (tmp_path / "scan.ply").write_text("")

    def complete(*words: str) -> list[str]:
        shell = (
            f"source {script}; COMP_WORDS=(geosmooth {' '.join(words)}); "
            f"COMP_CWORD={len(words)}; _shtab_geosmooth; printf '%s\\n' \"${{COMPREPLY[@]}}\""
        )
        out = subprocess.run(["bash", "-c", shell], cwd=tmp_path, capture_output=True, text=True,
                             timeout=30, check=False)  # fmt: skip
        return out.stdout.split()

    assert complete("co") == ["completion"]
    assert complete("smooth", "--lapl") == ["--laplacian"]
    assert complete("smooth", "--laplacian", "f") == ["feature"]
    assert complete("smooth", "sc") == ["scan.ply"]
    zsh = cli(["completion", "zsh"])
    assert zsh.returncode == 0 and zsh.stdout.startswith("#compdef geosmooth")


def test_worker_without_the_distributed_extra_is_one_line_and_exit_2() -> None:
    code = ("import sys; sys.modules['rq'] = None\n"
            "from service.cli import main\nraise SystemExit(main(['worker']))")  # fmt: skip
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(REPO / "clients/python")])}
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         cwd=REPO, timeout=60, check=False)  # fmt: skip
    assert res.returncode == EXIT_USAGE
    assert res.stderr == (
        "geosmooth: error: geosmooth worker needs the distributed extra: pip install "
        "'geosmooth[distributed]' and GEOSMOOTH_QUEUE=rq\n"
    )


@pytest.mark.parametrize(
    ("value", "words"),
    [("foo", "must be an EPSG code"), ("4326", "not a projected CRS"),
     ("EPSG:99999999", "not a CRS pyproj knows")],
)  # fmt: skip
def test_a_bad_crs_is_a_usage_error(cli: Run, tmp_path: Path, value: str, words: str) -> None:
    res = cli(["smooth", HELIX, "-o", tmp_path / "o.las", "--crs", value])
    assert res.returncode == EXIT_USAGE and len(_lines(res)) == 1 and words in res.stderr


def test_crs_on_input_that_is_not_geographic_is_refused_before_smoothing(
    cli: Run, tmp_path: Path
) -> None:
    res = cli(["smooth", HELIX, "-o", tmp_path / "o.obj", "--crs", "utm"])
    assert res.returncode == EXIT_USAGE and len(_lines(res)) == 1, res.stderr
    assert "--crs: crs applies to input whose CRS is known" in res.stderr
    assert "iteration" not in res.stderr
    assert not (tmp_path / "o.obj").exists()


def test_crs_writes_a_projected_las(cli: Run, data: Callable[[str], Path], tmp_path: Path) -> None:
    laspy = pytest.importorskip("laspy")
    gpx = data("korita-zbevnica.gpx")
    out = tmp_path / "track.las"
    res = cli(["smooth", gpx, "-o", out, "--rms", "3", "--crs", "utm", "-q"])
    assert res.returncode == EXIT_OK, res.stderr
    crs = laspy.read(out).header.parse_crs()
    assert crs is not None and crs.to_epsg() == 32633


def test_one_input_to_a_directory_is_written_inside_it(cli: Run, tmp_path: Path) -> None:
    """``-o DIR`` (an existing directory) was exit status 6, "Is a directory"."""
    (tmp_path / "out").mkdir()
    res = cli(["smooth", HELIX, "-o", tmp_path / "out", "--rms", "0.02"])
    assert res.returncode == EXIT_OK, res.stderr
    assert (tmp_path / "out" / "noisy-helix.obj").is_file()
    assert _lines(res)[-1].startswith("geosmooth: 1 file: 1 smoothed, 0 failed;")
