"""Issue 41 item 6: the progress model (:class:`service.core.progress.ProgressModel`): the
percent never goes back and the time left never freezes, checked on a synthetic timeline
against the arithmetic written out and on every recorded run of ``benchmarks/progress``.

The time left is NOT yet within 1.5x of the truth on the recorded runs of the test half
(service/cli/README.md, issue 41: the search's duration at one size varies from 0.01 to 6 s
with the engine's extra iterations after convergence); the replay measures it, this test
does not claim it."""

from __future__ import annotations

import itertools
import json

import pytest

from benchmarks.progress.fit import CALIBRATION, RUNS, replay
from service.core.progress import PHASES, ProgressModel, phase_of, phase_shares


def test_shares_sum_to_one_and_grow_with_the_input_where_the_work_does() -> None:
    for n in (1_000, 100_000, 10_000_000):
        assert sum(phase_shares(n).values()) == pytest.approx(1.0)
    small, large = phase_shares(10_000), phase_shares(1_000_000)
    assert large["neighborhoods"] > small["neighborhoods"]  # per-point work
    assert large["reading"] < small["reading"]  # a fixed start-up cost
    assert phase_of("laplacian") == "neighborhoods" and phase_of("queued") is None
    assert phase_of("neighborhoods", "noise") == "neighborhoods:noise"


def test_the_model_on_a_timeline_it_was_made_for() -> None:
    """A run whose phases take exactly their shares of T: from the second phase on the time
    left is exact, the percent is the time fraction, and neither stalls."""
    n, T = 200_000, 100.0
    shares = phase_shares(n)
    model = ProgressModel(n)
    starts, at = {}, 0.0
    for phase in PHASES:
        starts[phase] = at
        at += shares[phase] * T
    last_pct, etas = 0.0, []
    t = 0.0
    while t < T:
        for phase, s in starts.items():
            if s <= t:
                model.enter(phase, s)
        pct, eta = model.percent(t), model.eta(t)
        assert pct >= last_pct - 1e-9
        last_pct = pct
        if t >= starts[PHASES[1]] + 1e-9 and eta is not None:
            assert eta == pytest.approx(T - t, rel=1e-6, abs=1e-6)
            assert pct == pytest.approx(100 * t / T, rel=1e-6, abs=1e-6)
            etas.append(eta)
        t += 0.5
    assert all(b < a for a, b in itertools.pairwise(etas))  # moves every step


def test_an_overrunning_phase_stretches_the_estimate_instead_of_freezing() -> None:
    model = ProgressModel(100_000)
    model.enter("reading", 0.0)
    model.enter("neighborhoods", 2.0)
    total = model.total(2.0)
    assert total is not None and model.eta(2.0) == pytest.approx(total - 2.0)
    share = model.shares["neighborhoods"]
    late = 2.0 + 3 * share * total  # three times the phase's expected time
    assert model.total(late) == pytest.approx(late / (model.before + share))
    assert model.eta(late + 1.0) != model.eta(late)  # still moving
    assert model.percent(late) == pytest.approx(100 * (model.before + share))  # capped, no jump


def _recorded() -> list[dict[str, object]]:
    return [json.loads(p.read_text()) for p in sorted(RUNS.glob("*.json"))]


@pytest.mark.parametrize("run", _recorded(), ids=lambda r: str(r["name"]))
def test_recorded_runs_never_go_back_nor_freeze(run: dict[str, object]) -> None:
    row = replay(run)
    assert not row["percent_went_back"] and row["longest_frozen_seconds"] == 0.0, row
    assert row["worst_eta_ratio"] >= 1.0 and (run["name"] in CALIBRATION) == row["calibration"]
