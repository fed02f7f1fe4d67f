"""The page at ``/`` end to end in Firefox ESR, driven over WebDriver BiDi (``bidi.py``).

The same checks as the Chromium run of ``test_web_page_e2e.py``, in the other engine: a real
file chosen in the file input (``input.setFiles``), real mouse clicks and key presses, the job
followed to the final phi(lambda) point, both WebGL panes drawn (llvmpipe under Xvfb), the result
saved through the page's download button into Firefox's download directory and checked against
phi = sum_i ||x_i - p_i||^2 (eq. 15) computed here, no script errors and no request that leaves
the machine (``network.beforeRequestSent``).
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from service.io import read_geometry
from tests.web.bidi import Firefox, firefox_missing
from tests.web.test_page_e2e import PANE_BACKGROUND, deviation_phi
from tests.web.web_helpers import SAMPLES, WebServer, is_local, nonblank_fraction


@pytest.fixture(scope="module")
def firefox() -> Iterator[Firefox]:
    why = firefox_missing()
    if why:
        pytest.skip(why)
    browser = Firefox()
    try:
        browser.subscribe("log.entryAdded", "network.beforeRequestSent")
        yield browser
    finally:
        browser.close()


@pytest.fixture
def page(firefox: Firefox, web_server: WebServer) -> Firefox:
    """The page freshly loaded, with an empty event log."""
    firefox.events.clear()
    firefox.navigate(f"{web_server.url}/")
    firefox.wait_for("document.body.dataset.ready === 'true'")
    return firefox


def assert_clean(ff: Firefox, server: WebServer) -> None:
    """No script errors, and no request left the machine (the API was used, from this host)."""
    ff.evaluate("1")  # collect the events still in flight
    errors = [
        e["params"]
        for e in ff.events
        if e["method"] == "log.entryAdded" and e["params"]["level"] == "error"
    ]
    assert not errors, f"script errors in Firefox: {errors}"
    urls = [
        e["params"]["request"]["url"]
        for e in ff.events
        if e["method"] == "network.beforeRequestSent"
    ]
    assert any(u.startswith(f"{server.url}/v1/jobs") for u in urls), urls
    outside = [u for u in urls if not is_local(u)]
    assert not outside, f"requests leaving the machine: {outside}"


def shot(ff: Firefox, shots: Path, name: str) -> None:
    (shots / f"firefox-{name}.png").write_bytes(ff.screenshot())


def wait_info(ff: Firefox, kind: str) -> dict[str, str]:
    ff.wait_for(
        "!document.getElementById('info').hidden"
        " || document.querySelector(\"[data-error-for='file']\").textContent"
    )
    assert ff.evaluate("document.querySelector(\"[data-error-for='file']\").textContent") == ""
    info: dict[str, str] = dict(
        ff.evaluate(
            "[...document.querySelectorAll('#info-table th')]"
            ".map(th => [th.textContent, th.nextElementSibling.textContent])"
        )
    )
    assert info["kind"] == kind
    return info


def select(ff: Firefox, selector: str, label: str) -> None:
    """Choose the option with this text or value in a <select>, as a user does (change event)."""
    ff.evaluate(
        f"(s => {{ s.value = [...s.options]"
        f".find(o => [o.text, o.value].includes({json.dumps(label)})).value;"
        f" s.dispatchEvent(new Event('change', {{bubbles: true}})) }})"
        f"(document.querySelector({json.dumps(selector)}))"
    )


def set_rms(ff: Firefox, rms: float) -> None:
    ff.evaluate("['tau', 'lam'].forEach(n => { document.getElementById(`param-${n}`).value = '' })")
    ff.type("#param-rms", str(rms))
    assert ff.evaluate("document.getElementById('param-rms').value") == str(rms)


def submit_and_finish(ff: Firefox, server: WebServer) -> dict[str, Any]:
    ff.click("#submit")
    ff.wait_for(
        "document.querySelector('#phi-plot[data-final=true]')"
        " && document.querySelector('#pane-after[data-result-loaded=true]')",
        60,
    )
    job_id = ff.evaluate("document.body.dataset.jobId")
    with server.client() as client:
        job = client.get(f"/v1/jobs/{job_id}").json()
    assert job["status"] == "succeeded", job
    report: dict[str, Any] = job["report"]
    plot = ff.evaluate("({...document.getElementById('phi-plot').dataset})")
    assert plot["lastIteration"] == str(report["iterations"])
    assert plot["iterations"] == str(len(report["history"]))
    assert ff.evaluate("document.getElementById('p-stage').textContent") == "done"
    assert ff.evaluate("document.getElementById('progress-bar').value") == 100
    return report


def assert_panes_drawn(ff: Firefox, min_fraction: float) -> None:
    time.sleep(0.2)  # the render loop's next frame
    for pane in ("#pane-before canvas", "#pane-after canvas"):
        fraction = nonblank_fraction(ff.screenshot(pane), PANE_BACKGROUND)
        assert fraction > min_fraction, f"{pane}: only {fraction:.4f} of the pixels drawn"


def download(ff: Firefox, button: str, timeout: float = 30.0) -> bytes:
    """Click a download button; the file Firefox saved in its download directory."""
    before = set(ff.downloads.iterdir())
    ff.click(button)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        new = [p for p in set(ff.downloads.iterdir()) - before if p.suffix != ".part"]
        if new and not any(p.suffix == ".part" for p in ff.downloads.iterdir()):
            data = new[0].read_bytes()
            if data:
                return data
        time.sleep(0.05)
    raise AssertionError(f"no download from {button} in {timeout} s: {before}")


def check_download(ff: Firefox, fmt: str, points: np.ndarray, report: dict[str, Any]) -> None:
    select(ff, "#download-format", fmt)
    result = read_geometry(download(ff, "#download-result"), fmt).geometry.points
    assert result.shape == points.shape
    assert deviation_phi(points, result) == pytest.approx(report["phi"], rel=1e-7)
    saved = json.loads(download(ff, "#download-report"))
    assert saved["phi"] == report["phi"] and saved["lambda"] == report["lambda"]


def test_firefox_mesh_file_upload(
    page: Firefox, web_server: WebServer, screenshot_dir: Path
) -> None:
    renderer = page.evaluate(
        "document.createElement('canvas').getContext('webgl2')?.getParameter(0x1F01)"
    )  # RENDERER
    assert renderer, "no WebGL2 in Firefox"
    shot(page, screenshot_dir, "01-empty")
    sample = SAMPLES / "noisy-sphere.ply"
    page.set_files("#file-input", sample)
    info = wait_info(page, "mesh")
    assert info["points"] == "642" and info["faces"] == "1,280"
    set_rms(page, 0.01)
    report = submit_and_finish(page, web_server)
    assert report["tau"] == pytest.approx(642 * 0.01**2, rel=1e-12)
    assert abs(report["phi"] - report["tau"]) / report["tau"] <= 1e-3
    assert_panes_drawn(page, 0.05)
    vmax = float(page.evaluate("document.getElementById('viewer-note').dataset.vmax"))
    assert vmax == pytest.approx(report["max_displacement"], rel=1e-3)
    shot(page, screenshot_dir, "02-mesh-done")
    check_download(page, "ply", read_geometry(sample).geometry.points, report)
    assert_clean(page, web_server)


def test_firefox_curve_sample(page: Firefox, web_server: WebServer, screenshot_dir: Path) -> None:
    select(page, "#sample-select", "noisy-helix.obj")
    info = wait_info(page, "curve")
    assert info["points"] == "200" and info["polylines"] == "1"
    set_rms(page, 0.035)
    report = submit_and_finish(page, web_server)
    assert_panes_drawn(page, 0.002)  # thin lines
    shot(page, screenshot_dir, "03-curve-done")
    helix = read_geometry(SAMPLES / "noisy-helix.obj").geometry.points
    check_download(page, "json", helix, report)  # another format than the input's
    assert_clean(page, web_server)
