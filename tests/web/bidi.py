"""A small synchronous WebDriver BiDi client for Firefox ESR (under Xvfb, a throw-away profile).

Playwright cannot drive Debian's Firefox, and there is no geckodriver; Firefox speaks WebDriver
BiDi itself (``--remote-debugging-port``). WebGL needs a display: headless Firefox finds no GL
driver here, so Firefox runs non-headless on its own Xvfb server with Mesa's llvmpipe.
Spec: https://w3c.github.io/webdriver-bidi/
"""

from __future__ import annotations

import base64
import json
import os
import re
import shutil
import signal
import subprocess
import tempfile
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

FIREFOX = os.environ.get("GEOSMOOTH_FIREFOX", "firefox-esr")
XVFB = "Xvfb"
# Quiet Firefox: nothing but the page may talk to the network, so the test's network log is
# about the page (updates, telemetry, remote settings, captive portal, normandy, safebrowsing).
# Downloads go to the profile's downloads/ without a dialog; WebGL on Mesa's llvmpipe.
PREFS_OFF = """app.normandy.enabled browser.safebrowsing.malware.enabled
    browser.safebrowsing.phishing.enabled browser.safebrowsing.downloads.enabled
    browser.safebrowsing.blockedURIs.enabled browser.newtabpage.enabled
    browser.aboutwelcome.enabled browser.topsites.contile.enabled browser.ping-centre.telemetry
    network.captive-portal-service.enabled network.connectivity-service.enabled
    network.prefetch-next datareporting.healthreport.uploadEnabled
    datareporting.policy.dataSubmissionEnabled toolkit.telemetry.enabled toolkit.telemetry.unified
    extensions.update.enabled extensions.getAddons.cache.enabled extensions.blocklist.enabled
    browser.download.always_ask_before_handling_new_types browser.download.alwaysOpenPanel"""
PREFS: dict[str, object] = {
    **dict.fromkeys(PREFS_OFF.split(), False),
    **dict.fromkeys(["app.update.disabledForTesting", "network.dns.disablePrefetch"], True),
    **dict.fromkeys(["webgl.force-enabled", "browser.download.useDownloadDir"], True),
    "browser.startup.homepage_override.mstone": "ignore",
    "captivedetect.canonicalURL": "",
    "services.settings.server": "http://127.0.0.1:9/remote-settings",
    "media.gmp-manager.url": "",
    "browser.download.folderList": 2,
}


class BidiError(RuntimeError):
    """An error answer of the remote end, or no answer in time."""


def firefox_missing() -> str | None:
    """Why the Firefox tests cannot run here, or ``None``."""
    for name, pkg in ((FIREFOX, "firefox-esr"), (XVFB, "xvfb")):
        if not shutil.which(name):
            return f"no {name}: run scripts/install-system-deps.sh (installs {pkg})"
    try:
        import websockets.sync.client  # noqa: F401
    except ImportError:
        return "the websockets package is missing: pip install -e '.[dev]'"
    return None


class Firefox:
    """Xvfb + Firefox + one BiDi session on the first tab. ``close()`` removes everything."""

    def __init__(self, width: int = 1400, height: int = 1500, timeout: float = 60.0) -> None:
        self.profile = Path(tempfile.mkdtemp(prefix="geosmooth-firefox-"))
        self.downloads = self.profile / "downloads"
        self.downloads.mkdir()
        prefs = {**PREFS, "browser.download.dir": str(self.downloads)}
        (self.profile / "user.js").write_text(
            "".join(f"user_pref({json.dumps(k)}, {json.dumps(v)});\n" for k, v in prefs.items())
        )
        self.events: list[dict[str, Any]] = []
        self._next_id = 0
        self.xvfb: subprocess.Popen[bytes] | None = None
        self.firefox: subprocess.Popen[bytes] | None = None
        self._stack = ExitStack()  # the websocket
        try:
            self._start(width, height, timeout)
        except BaseException:
            self.close()
            raise

    def _start(self, width: int, height: int, timeout: float) -> None:
        read, write = os.pipe()  # Xvfb picks a free display number and writes it here
        screen = f"{width + 100}x{height + 200}x24"
        xvfb = [XVFB, "-displayfd", str(write), "-screen", "0", screen, "-nolisten", "tcp"]
        self.xvfb = subprocess.Popen(xvfb, pass_fds=(write,), stderr=subprocess.DEVNULL)
        os.close(write)
        with os.fdopen(read) as pipe:
            display = pipe.readline().strip()
        if not display:
            raise BidiError("Xvfb did not start")
        env = {**os.environ, "DISPLAY": f":{display}", "LIBGL_ALWAYS_SOFTWARE": "1"}
        env["MOZ_CRASHREPORTER_DISABLE"] = "1"
        cmd = [FIREFOX, "--remote-debugging-port=0", "--profile", str(self.profile)]
        cmd += ["--no-remote", "--new-instance", "about:blank"]
        self.log_path = self.profile.parent / f"{self.profile.name}.log"
        with self.log_path.open("wb") as log:
            self.firefox = subprocess.Popen(cmd, env=env, stdout=log, stderr=log)
        url = self._wait_listening(timeout)
        from websockets.sync.client import connect

        self.ws = self._stack.enter_context(
            connect(f"{url}/session", max_size=None, open_timeout=timeout, proxy=None)
        )
        self.call("session.new", {"capabilities": {}})
        self.context = self.call("browsingContext.getTree", {})["contexts"][0]["context"]
        viewport = {"width": width, "height": height}
        self.call("browsingContext.setViewport", {"context": self.context, "viewport": viewport})

    def _wait_listening(self, timeout: float) -> str:
        deadline = time.monotonic() + timeout
        assert self.firefox is not None
        while time.monotonic() < deadline:
            found = re.search(r"WebDriver BiDi listening on (ws://\S+)", self.log())
            if found:
                return found.group(1)
            if self.firefox.poll() is not None:
                break
            time.sleep(0.05)
        raise BidiError(f"Firefox did not start its BiDi server: {self.log()}")

    def log(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")[-4000:]
        except OSError:
            return ""

    def call(self, method: str, params: dict[str, Any], timeout: float = 60.0) -> Any:
        """Send one command and return its result; events that arrive meanwhile are kept."""
        self._next_id += 1
        mine = self._next_id
        self.ws.send(json.dumps({"id": mine, "method": method, "params": params}))
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise BidiError(f"{method}: no answer in {timeout} s")
            try:
                message = json.loads(self.ws.recv(timeout=left))
            except TimeoutError:
                continue
            if message.get("type") == "event":
                self.events.append(message)
            elif message.get("id") == mine:
                if message.get("type") == "error":
                    raise BidiError(f"{method}: {message.get('error')}: {message.get('message')}")
                return message["result"]

    def subscribe(self, *events: str) -> None:
        self.call("session.subscribe", {"events": list(events)})

    def navigate(self, url: str) -> None:
        self.call(
            "browsingContext.navigate", {"context": self.context, "url": url, "wait": "complete"}
        )

    def _evaluate(self, expression: str, **extra: Any) -> dict[str, Any]:
        params = {"expression": expression, "target": {"context": self.context}, **extra}
        params["awaitPromise"] = True
        answer: dict[str, Any] = self.call("script.evaluate", params)
        if answer["type"] == "exception":
            details = answer["exceptionDetails"]
            raise BidiError(f"{expression[:80]!r}: {details.get('text')}")
        return dict(answer["result"])

    def evaluate(self, expression: str) -> Any:
        """Evaluate JavaScript in the page; JSON-able results come back as Python values."""
        return json.loads(self._evaluate(f"JSON.stringify(({expression}) ?? null)")["value"])

    def element(self, selector: str) -> dict[str, str]:
        """A shared reference to the first element matching ``selector``."""
        found = self._evaluate(
            f"document.querySelector({json.dumps(selector)})",
            serializationOptions={"maxDomDepth": 0},
        )
        if found["type"] != "node":
            raise BidiError(f"no element {selector!r}")
        return {"sharedId": found["sharedId"]}

    def wait_for(self, condition: str, timeout: float = 30.0, poll: float = 0.05) -> None:
        """Poll the JavaScript expression ``condition`` until it is truthy."""
        deadline = time.monotonic() + timeout
        while not self.evaluate(f"!!({condition})"):
            if time.monotonic() > deadline:
                raise BidiError(f"timed out after {timeout} s waiting for {condition!r}")
            time.sleep(poll)

    def screenshot(self, selector: str | None = None) -> bytes:
        """PNG of the whole document, or of one element's box."""
        params: dict[str, Any] = {"context": self.context, "origin": "document"}
        if selector:
            params["clip"] = {"type": "element", "element": self.element(selector)}
        return base64.b64decode(self.call("browsingContext.captureScreenshot", params)["data"])

    def set_files(self, selector: str, *paths: Path) -> None:
        """Choose files in an ``<input type=file>`` as a user would (fires input and change)."""
        files = [str(p) for p in paths]
        element = self.element(selector)
        self.call("input.setFiles", {"context": self.context, "element": element, "files": files})

    def _actions(self, kind: str, name: str, actions: list[dict[str, Any]]) -> None:
        source: dict[str, Any] = {"type": kind, "id": name, "actions": actions}
        if kind == "pointer":
            source["parameters"] = {"pointerType": "mouse"}
        self.call("input.performActions", {"context": self.context, "actions": [source]})

    def click(self, selector: str) -> None:
        """A real mouse click at the element's centre (scrolled into view first)."""
        self.evaluate(
            f"document.querySelector({json.dumps(selector)}).scrollIntoView({{block: 'center'}})"
        )
        origin = {"type": "element", "element": self.element(selector)}
        move = {"type": "pointerMove", "x": 0, "y": 0, "origin": origin}
        down, up = ({"type": f"pointer{t}", "button": 0} for t in ("Down", "Up"))
        self._actions("pointer", "mouse", [move, down, up])

    def type(self, selector: str, text: str) -> None:
        """Click into a text field, select what it holds and type ``text`` over it."""
        self.click(selector)
        self.evaluate(f"document.querySelector({json.dumps(selector)}).select()")
        keys = [{"type": "keyDown", "value": "\ue017"}, {"type": "keyUp", "value": "\ue017"}]
        for char in text:  # "\ue017" is the Delete key
            keys += [{"type": "keyDown", "value": char}, {"type": "keyUp", "value": char}]
        self._actions("key", "keyboard", keys)

    def close(self) -> None:
        """End the session, stop Firefox and Xvfb, delete the profile."""
        try:
            if getattr(self, "ws", None) is not None:
                self.call("session.end", {}, timeout=5)
            self._stack.close()
        except Exception:  # the processes are killed below anyway
            pass
        for proc in (self.firefox, self.xvfb):
            if proc is not None and proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
                try:
                    proc.wait(10)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait(10)
        shutil.rmtree(self.profile, ignore_errors=True)
        Path(str(self.profile) + ".log").unlink(missing_ok=True)
