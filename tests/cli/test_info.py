"""``geosmooth info``: the facts of an input and its valid budgets, checked independently."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np

from service.exit_codes import EXIT_INPUT, EXIT_USAGE

Run = Callable[..., subprocess.CompletedProcess[str]]
HELIX = Path(__file__).resolve().parents[2] / "service" / "samples" / "noisy-helix.obj"


def _obj_points(path: Path) -> np.ndarray:
    rows = [line.split()[1:4] for line in path.read_text().splitlines() if line.startswith("v ")]
    return np.asarray(rows, dtype=float)


def test_info_of_a_curve_matches_closed_forms(cli: Run) -> None:
    res = cli(["info", HELIX, "--ends", "pulled"])  # fixed ends (the default) have no closed form
    assert res.returncode == 0, res.stderr
    facts = json.loads(res.stdout)
    P = _obj_points(HELIX)
    assert (facts["input_format"], facts["kind"], facts["n_points"]) == ("obj", "curve", len(P))
    assert facts["format"] == facts["input_format"]  # the deprecated name, same value
    assert facts["n_edges"] == len(P) - 1  # one open polyline
    np.testing.assert_allclose(facts["bbox"]["min"], P.min(axis=0))
    np.testing.assert_allclose(facts["bbox"]["max"], P.max(axis=0))
    spacing = np.linalg.norm(np.diff(P, axis=0), axis=1).mean()
    assert np.isclose(facts["mean_spacing"], spacing)
    # eq. (14) with D = I and one connected part: phi(0) = sum ||p_i - centroid||^2
    phi0 = float(((P - P.mean(axis=0)) ** 2).sum())
    assert np.isclose(facts["phi0"], phi0, rtol=1e-9)
    assert facts["tau_range"] == [0.0, facts["phi0"]]
    assert np.isclose(facts["rms_range"][1], np.sqrt(phi0 / len(P)), rtol=1e-9)
    assert 0 < facts["suggested_tau"] < phi0
    assert np.isclose(facts["suggested_rms"] ** 2 * len(P), facts["suggested_tau"], rtol=1e-9)


def test_info_suggests_the_budget_smooth_uses_by_default(cli: Run, tmp_path: Path) -> None:
    facts = json.loads(cli(["info", HELIX, "--compact"]).stdout)
    report = tmp_path / "r.json"
    res = cli(["smooth", HELIX, "-o", tmp_path / "o.obj", "--report", report, "-q"])
    assert res.returncode == 0, res.stderr
    assert np.isclose(json.loads(report.read_text())["tau"], facts["suggested_tau"], rtol=1e-9)


def test_info_errors_are_one_line(cli: Run, tmp_path: Path) -> None:
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 1\n")
    res = cli(["info", bad])
    assert res.returncode == EXIT_INPUT and len(res.stderr.splitlines()) == 1, res.stderr
    assert "line 2" in res.stderr
    res = cli(["info", HELIX, "--k", "0"])
    assert res.returncode == EXIT_USAGE and res.stderr.count("\n") == 1 and "--k" in res.stderr


def test_info_prose_quotes_the_suggested_tau(cli: Run) -> None:
    """The noise sentence names the tau of ``suggested_tau`` (phi at the automatic rule's
    lambda, issue 37), not only the discrepancy budget it starts from (issue 32 item 8)."""
    sphere = HELIX.parent / "noisy-sphere.ply"
    for path in (HELIX, sphere):
        res = cli(["info", path, "--compact"])
        assert res.returncode == 0 and res.stderr == "", res.stderr
        facts = json.loads(res.stdout)
        assert f"tau = {facts['suggested_tau']:.6g}" in facts["noise"], facts


def test_local_sigma_warns_nothing_on_rows_without_an_estimate() -> None:
    """numpy's "Mean of empty slice" (the mug scene's stderr) came from rows of neighbours
    none of which had a noise estimate: they are NaN now, silently, as before."""
    import warnings

    from service.core.noise.uneven import local_sigma

    rng = np.random.default_rng(0)
    v = rng.random(50)
    v[:10] = 0.0  # exact fits: no estimate
    nbr = rng.integers(0, 50, size=(50, 6))
    nbr[:3] = rng.integers(0, 10, size=(3, 6))  # rows made only of those
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sigma = local_sigma(v, nbr, 3)
    assert sigma.shape == (50,) and np.isfinite(sigma[10:]).any()
