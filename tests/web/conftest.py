"""Fixtures of the web tests: one live server, Debian's chromium, pages with a network log.

Screenshots go to ``$GEOSMOOTH_SCREENSHOTS`` (default: a pytest temporary directory, printed
in the test summary).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.timing import patience
from tests.web.web_helpers import (
    CHROMIUM,
    CHROMIUM_ARGS,
    Browsing,
    WebServer,
    chromium_missing,
    is_local,
)

# Short poll so that the events of sub-second jobs are seen; small limits keep 413s cheap.
SERVER_ENV = {
    "GEOSMOOTH_EVENTS_POLL_SECONDS": "0.03",
    "GEOSMOOTH_JOB_TIMEOUT": "120",
}


@pytest.fixture(scope="session")
def web_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[WebServer]:
    """A real uvicorn server (subprocess on 127.0.0.1, temp data dir, 2 workers)."""
    live = WebServer(tmp_path_factory.mktemp("web") / "data", env=SERVER_ENV).start()
    try:
        yield live
    finally:
        live.stop()


_SHOTS: list[Path] = []


@pytest.fixture(scope="session")
def screenshot_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    env = os.environ.get("GEOSMOOTH_SCREENSHOTS")
    path = Path(env) if env else tmp_path_factory.mktemp("screenshots")
    path.mkdir(parents=True, exist_ok=True)
    _SHOTS.append(path)
    return path


@pytest.fixture(scope="session")
def browser() -> Iterator[Any]:
    """Debian's chromium driven by Playwright (skipped only when there is no browser)."""
    why = chromium_missing()
    if why:
        pytest.skip(why)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        try:
            yield b
        finally:
            b.close()


@pytest.fixture
def browsing(browser: Any, screenshot_dir: Path) -> Iterator[Browsing]:
    """A fresh browser context; every request is logged, non-local ones are also blocked."""
    context = browser.new_context(viewport={"width": 1400, "height": 1500}, accept_downloads=True)
    page = context.new_page()
    page.set_default_timeout(patience(30) * 1000)  # a hang guard: 30 s, stretched for load
    log = Browsing(page=page, shots=screenshot_dir)

    def route(r: Any) -> None:
        if is_local(r.request.url):
            r.continue_()
        else:
            log.blocked.append(r.request.url)
            r.abort()

    context.route("**/*", route)
    page.on("request", lambda req: log.requests.append(req.url))
    page.on("pageerror", lambda exc: log.errors.append(str(exc)))
    page.on("console", lambda m: log.console.append(m.text) if m.type == "error" else None)
    try:
        yield log
    finally:
        context.close()


def pytest_terminal_summary(terminalreporter: Any) -> None:
    for path in _SHOTS:
        terminalreporter.write_line(f"web screenshots (GEOSMOOTH_SCREENSHOTS): {path}")
