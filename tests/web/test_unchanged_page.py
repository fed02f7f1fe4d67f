"""Issue 32 on the page: a finished job that came back unchanged shows "unchanged" instead of a
colour map of float32 rounding, and a finished job's phi(lambda) panel shows its history (or
says why there is none) instead of "submit a job to see phi(lambda) converge".

The bunny (shared data: read by the test, never copied into the repository) has no noise: the
default run returns it unchanged. Its view is the screenshot of docs/img/unchanged.png.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from tests.web.test_page_e2e import open_page, submit_and_finish, wait_info
from tests.web.web_helpers import Browsing, WebServer

REPO = Path(__file__).resolve().parents[2]
SHARED = Path(os.environ.get("GEOSMOOTH_SHARED_DATA") or REPO.parent / "shared" / "data")
BUNNY = SHARED / "bunny.ply"

UNCHANGED_RULE = """async () => {
  const { unchangedReason } = await import('/static/js/compare.js');
  const positions = Float32Array.from([0.1, -0.08, 0.05, -0.1, 0.09, 0.02]);
  return {
    rounding: unchangedReason({ max_displacement: 8.4e-9 }, 8.4e-9, positions),
    moved: unchangedReason({ max_displacement: 1e-3 }, 1e-3, positions),
    copied: unchangedReason({ unchanged: 'copied', max_displacement: 0 }, 0, positions),
    converted: unchangedReason({ unchanged: 'converted' }, 0, positions),
  };
}"""

PLOT_OF_A_FINISHED_JOB = """async () => {
  const { PhiPlot } = await import('/static/js/plot.js');
  const canvas = document.createElement('canvas');
  canvas.width = 400; canvas.height = 200;
  document.body.append(canvas);
  const plot = new PhiPlot(canvas);
  plot.finish([{ lambda: 0.1, phi: 0.5 }, { lambda: 1, phi: 2 }, { lambda: 0.5, phi: 1.2 }], 1.2);
  const drawn = { ...canvas.dataset };
  plot.reset();
  plot.finish([], null, 'no noise found: returned unchanged, no λ tried');
  const empty = { ...canvas.dataset };
  canvas.remove();
  return { drawn, empty };
}"""


def test_unchanged_rule_and_finished_plot(browsing: Browsing, web_server: WebServer) -> None:
    page = open_page(browsing, web_server)
    rule = page.evaluate(UNCHANGED_RULE)
    assert "float32 rounding" in rule["rounding"] and rule["moved"] is None
    assert rule["copied"].startswith("returned unchanged") and "converted" in rule["converted"]
    plot = page.evaluate(PLOT_OF_A_FINISHED_JOB)
    assert plot["drawn"]["iterations"] == "3" and plot["drawn"]["final"] == "true"
    assert plot["drawn"]["message"] == ""
    assert plot["empty"]["iterations"] == "0" and "returned unchanged" in plot["empty"]["message"]
    browsing.assert_offline()


@pytest.mark.skipif(not BUNNY.exists(), reason="shared data not found (set GEOSMOOTH_SHARED_DATA)")
def test_unchanged_bunny_shows_unchanged(browsing: Browsing, web_server: WebServer) -> None:
    page = open_page(browsing, web_server)
    page.set_input_files("#file-input", str(BUNNY))
    wait_info(page, "mesh")
    for name in ("tau", "rms", "lam"):  # the default: automatic tau
        page.fill(f"#param-{name}", "")
    with web_server.client() as client:
        done = submit_and_finish(browsing, client)
    report = done["report"]
    assert report["noise_found"] is False and report["unchanged"] == "copied"
    page.wait_for_selector("#legend[data-unchanged=true]")
    assert page.get_attribute("#pane-after", "data-unchanged") == "true"
    assert page.text_content("#legend-unchanged").startswith("unchanged — returned unchanged")
    assert "float32 rounding" in page.text_content("#viewer-note")
    assert not page.locator("#legend-bar").is_visible()  # no colour map of rounding
    assert "returned unchanged" in (page.get_attribute("#phi-plot", "data-message") or "")
    page.wait_for_timeout(300)
    assert browsing.shots is not None
    page.locator("#viewer-section").screenshot(path=str(browsing.shots / "unchanged.png"))
    browsing.shot("08-unchanged")
    browsing.assert_offline()
