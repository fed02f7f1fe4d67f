"""The page takes what the API takes (issue 25.5), in Debian's chromium against a live server.

* the limits the page states are the server's (``GET /v1/limits`` of the page's key);
* the 209,280-point ``table_scene_mug_stereo_textured.xyz`` (5.8 MB) is read, shown decimated,
  submitted, smoothed, and its result shown next to it (``/v1/info`` answered 413 before);
* a file above the key's ``max_upload_bytes`` is refused by the page before it is sent;
* result formats that cannot hold the result are not offered (the API refuses them with 422).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.shared_data import shared_data_dir, shared_data_missing
from tests.web.conftest import SERVER_ENV
from tests.web.web_helpers import Browsing, WebServer

MUG = shared_data_dir() / "table_scene_mug_stereo_textured.xyz"


def _open(b: Browsing, server: WebServer) -> object:
    page = b.page
    page.goto(f"{server.url}/")
    page.wait_for_selector("body[data-ready=true]")
    return page


def test_page_states_the_servers_limits(browsing: Browsing, web_server: WebServer) -> None:
    page = _open(browsing, web_server)
    limits = httpx.get(f"{web_server.url}/v1/limits").json()
    hint = page.text_content("#format-hint")
    assert f"up to {limits['max_points']:,} points" in hint
    assert f"{limits['max_faces']:,} faces" in hint
    assert f"{round(limits['max_upload_bytes'] / 2**20):,} MiB" in hint
    browsing.assert_offline()


@pytest.fixture
def small_server(tmp_path: Path) -> Iterator[WebServer]:
    env = {**SERVER_ENV, "GEOSMOOTH_MAX_UPLOAD_BYTES": "4096", "GEOSMOOTH_MAX_POINTS": "1234"}
    live = WebServer(tmp_path / "data", env=env, workers=1).start()
    try:
        yield live
    finally:
        live.stop()


def test_too_large_file_refused_by_the_page(browsing: Browsing, small_server: WebServer) -> None:
    page = _open(browsing, small_server)
    hint = page.text_content("#format-hint")
    assert "up to 1,234 points" in hint and "files of up to 4,096 bytes" in hint
    text = "".join(f"{i} {i % 7} {i % 3}\n" for i in range(2000))  # ~17 kB > 4096 bytes
    page.evaluate(
        """([name, text]) => {
            const dt = new DataTransfer();
            dt.items.add(new File([text], name, {type: "text/plain"}));
            const zone = document.getElementById("drop-zone");
            const init = {dataTransfer: dt, bubbles: true, cancelable: true};
            zone.dispatchEvent(new DragEvent("drop", init));
        }""",
        ["big.xyz", text],
    )
    error = page.locator("[data-error-for='file']")
    error.wait_for(state="visible")
    page.wait_for_function(
        "() => document.querySelector(\"[data-error-for='file']\").textContent.includes('4,096')"
    )
    assert "Request Entity Too Large" in error.text_content()
    assert page.is_disabled("#submit")
    assert not [u for u in browsing.requests if "/v1/info" in u]  # never sent


@pytest.mark.skipif(not MUG.exists(), reason=str(shared_data_missing(MUG.name)))
def test_mug_scan_from_the_page(browsing: Browsing, web_server: WebServer) -> None:
    page = _open(browsing, web_server)
    page.set_default_timeout(600_000)
    page.set_input_files("#file-input", str(MUG))
    page.wait_for_function(
        "() => !document.getElementById('info').hidden"
        " || document.querySelector(\"[data-error-for='file']\").textContent"
    )
    assert page.text_content("[data-error-for='file']") == ""
    cells = page.eval_on_selector_all(
        "#info-table th",
        "ths => ths.map(th => [th.textContent, th.nextElementSibling.textContent])",
    )
    info = dict(cells)
    assert info["kind"] == "cloud" and info["points"] == "209,280"
    assert "closed-form bound" in info["φ(0) ≤"]
    assert page.is_enabled("#submit")
    assert "Decimated for display only" in page.text_content("#viewer-note")
    for other in ("tau", "lam"):
        page.fill(f"#param-{other}", "")
    page.fill("#param-rms", "0.0002")
    page.click("#submit")
    page.wait_for_selector("#pane-after[data-result-loaded=true]")
    job_id = page.get_attribute("body", "data-job-id")
    with web_server.client() as client:
        job = client.get(f"/v1/jobs/{job_id}").json()
    assert job["status"] == "succeeded", job
    assert job["report"]["n_points"] == 209_280
    note = page.text_content("#viewer-note")
    assert "Decimated for display only" in note and "of 209,280 points" in note
    options = page.eval_on_selector_all(
        "#download-format option", "os => os.map(o => [o.value, o.disabled])"
    )
    offered = {name for name, disabled in options if not disabled}
    assert {"xyz", "ply", "las", "pcd", "e57", "dxf"} <= offered
    assert not offered & {"stl", "gpx", "geojson"}  # faces only / longitude-latitude only
    browsing.shot("mug-done")
    browsing.assert_offline()
