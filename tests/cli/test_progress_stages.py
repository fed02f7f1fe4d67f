"""``smooth``'s stage lines on stderr (``--progress``): text, JSON lines, quiet, the ticker."""

from __future__ import annotations

import io
import json
import time
from pathlib import Path

import numpy as np
import pytest

from service.cli.progress.stages import STAGES, StageDisplay
from service.core.progress import ProgressEvent
from tests.cli.conftest import run_cli

#: Stage lines in the order a default run of a noisy surface goes through them: the names of a
#: job's events (issue 41), the steps of ``neighborhoods`` on lines of their own.
ORDER = ["reading", "neighborhoods", "neighborhoods: weights", "neighborhoods: noise",
         "analysis", "search", "postprocess", "writing"]  # fmt: skip


@pytest.fixture(scope="module")
def surface(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A noisy height field, 3600 points (a moderate input: every stage runs, ~1 s)."""
    rng = np.random.default_rng(0)
    x, y = np.meshgrid(np.linspace(0, 3, 60), np.linspace(0, 3, 60))
    z = np.sin(x) * np.cos(y)
    P = np.column_stack([x.ravel(), y.ravel(), z.ravel()]) + 0.005 * rng.standard_normal((3600, 3))
    path = tmp_path_factory.mktemp("stages") / "surface.xyz"
    np.savetxt(path, P, fmt="%.6f")
    return path


def _shown(record: dict[str, object]) -> str:
    return f"{record['stage']}: {record['step']}" if record["step"] else str(record["stage"])


def _first_seen(names: list[str]) -> list[str]:
    return [n for i, n in enumerate(names) if n not in names[:i]]


def test_text_mode_prints_each_stage_in_order_then_the_summary(
    surface: Path, tmp_path: Path
) -> None:
    res = run_cli(["smooth", surface, "-o", tmp_path / "o.xyz", "--progress", "text"])
    assert res.returncode == 0, res.stderr
    lines = res.stderr.splitlines()
    stages = [ln for ln in lines if ln.startswith("geosmooth: [")]
    names = [ln.split("] ", 1)[1].split("  (")[0] for ln in stages]
    assert names == ORDER, res.stderr  # each stage once, in run order
    for ln, name in zip(stages, names, strict=True):
        k = STAGES.index(name.split(":")[0]) + 1
        assert ln.startswith(f"geosmooth: [{k}/6] ") and " %" in ln and ln.endswith(")"), ln
    search = [ln for ln in lines if ln.startswith("geosmooth: iteration")]
    assert search and all("lambda=" in ln and " %" in ln for ln in search)
    assert lines.index(stages[5]) < lines.index(search[0]) < lines.index(stages[6])
    assert any(ln.startswith(f"geosmooth: {surface} -> ") for ln in lines)  # the summary


def test_json_mode_is_one_object_per_line(surface: Path, tmp_path: Path) -> None:
    res = run_cli(["smooth", surface, "-o", tmp_path / "o.xyz", "--progress", "json"])
    assert res.returncode == 0, res.stderr
    records = [json.loads(ln) for ln in res.stderr.splitlines()]  # every line parses
    assert records[-1]["event"] == "summary" and str(surface) in records[-1]["text"]
    body = records[:-1]
    assert {r["event"] for r in body} <= {"stage", "iteration", "tick"}
    assert _first_seen([_shown(r) for r in body]) == ORDER
    assert [_shown(r) for r in body if r["event"] == "stage"] == ORDER
    for r in body:
        assert r["index"] == STAGES.index(r["stage"]) + 1 and r["stages"] == 6
        assert 0.0 <= r["percent"] <= 100.0 and r["elapsed_seconds"] >= 0.0
    percents = [r["percent"] for r in body]
    assert percents == sorted(percents)
    clocks = [r["elapsed_seconds"] for r in body]
    assert clocks == sorted(clocks)
    iterations = [r for r in body if r["event"] == "iteration"]
    assert iterations and all(r["stage"] == "search" for r in iterations)
    last = iterations[-1]
    assert last["relative_error"] == pytest.approx(abs(last["phi"] - last["tau"]) / last["tau"])


def test_json_mode_matches_the_report(surface: Path, tmp_path: Path) -> None:
    """The last iteration shown is the report's lambda and phi (same run, same numbers)."""
    res = run_cli(["smooth", surface, "-o", tmp_path / "o.xyz", "--progress", "json",
                   "--report", tmp_path / "r.json"])  # fmt: skip
    assert res.returncode == 0, res.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    last = [r for r in map(json.loads, res.stderr.splitlines()) if r["event"] == "iteration"][-1]
    assert last["lambda"] == report["lambda"] and last["phi"] == report["phi"]
    assert last["iteration"] == report["iterations"]


@pytest.mark.parametrize("mode", ["text", "json", "auto"])
def test_quiet_prints_nothing(surface: Path, tmp_path: Path, mode: str) -> None:
    res = run_cli(["smooth", surface, "-o", tmp_path / "o.xyz", "-q", "--progress", mode])
    assert res.returncode == 0 and res.stderr == "" and res.stdout == ""
    assert (tmp_path / "o.xyz").stat().st_size > 0


def test_auto_mode_keeps_a_small_run_to_its_search_lines(surface: Path, tmp_path: Path) -> None:
    """Below 1 MiB of input ``auto`` shows no stage lines (the 3600-point file is ~0.1 MiB)."""
    res = run_cli(["smooth", surface, "-o", tmp_path / "o.xyz"])
    assert res.returncode == 0, res.stderr
    assert not any(ln.startswith("geosmooth: [") for ln in res.stderr.splitlines())
    assert res.stderr.startswith("geosmooth: iteration  1  lambda=")


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_ticker_updates_a_silent_stage_on_a_terminal_and_stops_on_close() -> None:
    out = _Tty()
    display = StageDisplay(out, 1e-3, tick=0.05)
    display(ProgressEvent("neighborhoods"))
    time.sleep(0.5)
    display.close()
    updates = out.getvalue().split("\r")[1:]
    assert len(updates) >= 4  # the stage line, then one tick every 0.05 s of silence
    assert all(u.startswith("geosmooth: [2/6] neighborhoods") for u in updates)
    seconds = [float(u.split()[3]) for u in updates[1:]]  # "... neighborhoods 0.1 s (..."
    assert seconds == sorted(seconds) and seconds[-1] > seconds[0]
    assert out.getvalue().endswith("\n")  # the line ended by close()
    done = out.getvalue()
    time.sleep(0.2)
    assert out.getvalue() == done  # no thread writes after close


def test_steps_and_stages_map_to_the_seven_names() -> None:
    out = io.StringIO()
    display = StageDisplay(out, 1e-3, tick=60.0, json_lines=True)
    display.stage("reading")
    for event in (
        ProgressEvent("neighborhoods"),
        ProgressEvent("neighborhoods", step="weights"),
        ProgressEvent("neighborhoods", step="noise"),
        ProgressEvent("analysis", tau=2.0),
        ProgressEvent("search", tau=2.0, iteration=1, lam=0.5, phi=2.2),
        ProgressEvent("search", tau=2.0, iteration=2, lam=0.4, phi=2.0),
        ProgressEvent("postprocess", tau=2.0, iteration=2),
    ):
        display(event)
    display.stage("writing")
    display.close()
    records = [json.loads(ln) for ln in out.getvalue().splitlines()]
    assert [_shown(r) for r in records if r["event"] == "stage"] == ORDER
    second = [r for r in records if r["event"] == "iteration"][1]
    assert (second["lambda"], second["phi"], second["relative_error"]) == (0.4, 2.0, 0.0)
    assert second["percent"] == 90.0  # the jobs' estimate: the search's slice filled


def test_a_converged_search_prints_no_line_that_reads_as_the_last_one() -> None:
    """Issue 41: the engine refining a converged lambda (same lambda and phi to the digits
    shown) adds no iteration line; the summary still counts every evaluation."""
    out = io.StringIO()
    display = StageDisplay(out, 1e-3, tick=60.0, stages=False)
    for k, (lam, phi) in enumerate([(0.5, 2.2), (0.4072291, 2.0000001), (0.4072302, 2.0),
                                    (0.4072302, 1.99999993)], 1):  # fmt: skip
        display(ProgressEvent("search", tau=2.0, iteration=k, lam=lam, phi=phi))
    display.close()
    lines = out.getvalue().splitlines()
    assert [ln.split()[2] for ln in lines] == ["1", "2"] and display.calls == 4
