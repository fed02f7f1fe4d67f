"""Issue 41 item 5: ``--params FILE.json``: a ``--report``'s ``params`` (and its pipeline
options) fed back give the same bytes; a plain parameters object works; the command line wins;
a bad file is one line and exit 2."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable
from pathlib import Path

from service.exit_codes import EXIT_OK, EXIT_USAGE
from tests.workflows.test_selection import _las

Run = Callable[..., subprocess.CompletedProcess[str]]


def test_a_report_fed_back_gives_the_same_bytes(cli: Run, tmp_path: Path) -> None:
    src = tmp_path / "scan.las"
    _las(src)
    first, report = tmp_path / "a.las", tmp_path / "a.json"
    res = cli(["smooth", src, "-o", first, "--rms", "0.015", "--where", "Classification == 2",
               "--laplacian", "curvature", "--report", report, "-q"])  # fmt: skip
    assert res.returncode == EXIT_OK, res.stderr
    saved = json.loads(report.read_text())
    assert saved["where"] == "Classification == 2" and saved["params"]["rms"] == 0.015
    again = tmp_path / "b.las"
    res = cli(["smooth", src, "-o", again, "--params", report, "-q"])
    assert res.returncode == EXIT_OK, res.stderr
    assert again.read_bytes() == first.read_bytes()
    plain = tmp_path / "p.json"  # a plain object; the command line's target replaces its own
    plain.write_text(json.dumps({"tau": 5.0, "laplacian": "curvature",
                                 "where": "Classification == 2"}))  # fmt: skip
    third, report3 = tmp_path / "c.las", tmp_path / "c.json"
    res = cli(["smooth", src, "-o", third, "--params", plain, "--rms", "0.015",
               "--report", report3, "-q"])  # fmt: skip
    assert res.returncode == EXIT_OK, res.stderr
    assert json.loads(report3.read_text())["params"] == saved["params"]
    assert third.read_bytes() == first.read_bytes()


def test_a_bad_parameters_file_is_one_line_and_exit_2(cli: Run, tmp_path: Path) -> None:
    src = tmp_path / "scan.las"
    _las(src)
    cases = {"[1, 2]": "no JSON object", '{"rmss": 1}': "unknown parameter 'rmss'",
             "{": "cannot read", '{"rms": -1}': "--rms"}  # fmt: skip
    for text, words in cases.items():
        path = tmp_path / "p.json"
        path.write_text(text)
        res = cli(["smooth", src, "-o", tmp_path / "o.las", "--params", path])
        assert res.returncode == EXIT_USAGE, (text, res.stderr)
        assert len(res.stderr.strip().splitlines()) == 1 and words in res.stderr, res.stderr
