"""A tiled run's progress numbers in the job's progress dict (issue 43)."""

from __future__ import annotations

import io

from service.cli.progress.stages import StageDisplay
from service.core.progress import ProgressEvent
from service.jobs.progress import ProgressTracker


def test_the_tile_counter_and_the_runs_own_time_left() -> None:
    tracker = ProgressTracker()
    event = ProgressEvent("search", lam=0.1, iteration=1, elapsed=30.0, fraction=0.25,
                          tiles_done=1, tiles_total=4, points_per_second=5000.0,
                          seconds_left=90.0)  # fmt: skip
    got = tracker.update(event)
    assert (got["tiles_done"], got["tiles_total"], got["points_per_second"]) == (1, 4, 5000.0)
    assert got["eta_seconds"] == 90.0  # the run's measured rate, not the stage slices'
    assert got["percent"] == 40.0 + 50.0 * 0.25  # the search slice, a quarter done
    plain = tracker.update(ProgressEvent("postprocess", elapsed=40.0))
    assert "tiles_done" not in plain


def test_the_cli_line_and_json_record_show_the_tiles() -> None:
    out = io.StringIO()
    display = StageDisplay(out, 1e-3, tty=False, json_lines=True)
    display(ProgressEvent("search", lam=0.1, iteration=1, fraction=0.5, tiles_done=2,
                          tiles_total=4, points_per_second=1234.0, seconds_left=10.0))  # fmt: skip
    display.close()
    import json

    last = json.loads(out.getvalue().splitlines()[-1])
    assert (last["tiles_done"], last["tiles_total"]) == (2, 4)
    text = StageDisplay(io.StringIO(), 1e-3, tty=False)
    text(ProgressEvent("search", lam=0.1, iteration=1, fraction=0.5, tiles_done=2,
                       tiles_total=4, points_per_second=1234.0, seconds_left=10.0))  # fmt: skip
    assert "tile 2/4, 1234 points/s" in text.text("tick", 1.0)
    text.close()
