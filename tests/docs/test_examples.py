"""Every command the documentation shows is run, so that README.md and docs/*.md cannot go stale.

The convention (also stated in docs/development.md):

* a fenced block marked ``sh`` is a shell script and ``python`` a Python program: both are run;
* ``text``, ``json``, ``yaml`` and ``console`` blocks show output, formats or a session: not run;
* an HTML comment on the line before a block changes that: ``<!-- not-run: REASON -->`` skips a
  block, with the reason written down (Docker, Redis, a command that installs or runs for
  minutes), and ``<!-- own-server -->`` says that the block starts and stops its own server
  (it gets a free port of its own). Other comments are labels (``<!-- webhook-verify -->``);
* ``<!-- output -->`` before a ``text`` block says it shows the output of the block run just
  before it: every line shown must be in that output (timings and residuals below 1e-6,
  which vary from run to run, are masked).

Each document's blocks run in order, in one scratch directory per document laid out like a
checkout: the project's files are symlinked into it, ``.venv`` is the environment running the
tests (``PYTHONPATH`` points at this tree), and ``../shared/data`` is the shared real data when it
exists (blocks that read it are skipped otherwise). ``PATH`` is the system's only, so a bare
``geosmooth`` fails as it would after ``make run``. A real server (``python -m
service.api.server``, one worker) listens on a free loopback port; ``127.0.0.1:8000`` and
``--port 8000`` in a block are rewritten to it. A block fails on its first failing command
(``bash -e -o pipefail``) and after ``BLOCK_TIMEOUT`` seconds; whatever it leaves running is
killed with its process group.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import re
import signal
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.api.api_helpers import LiveServer, free_port
from tests.shared_data import shared_data_dir, shared_data_missing

ROOT = Path(__file__).resolve().parents[2]
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
RUN = {"sh", "python"}
SHOWN = {"text", "json", "yaml", "console"}
BLOCK_TIMEOUT = 120.0
README_MAX_LINES = 300

_FENCE = re.compile(r"^```\s*([\w-]*)\s*$")
_COMMENT = re.compile(r"^<!--\s*(.*?)\s*-->\s*$")
_LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")


@dataclass(frozen=True)
class Block:
    """One fenced code block of a document."""

    path: Path
    line: int  # 1-based line of the opening fence
    lang: str
    text: str
    marker: str  # the HTML comment on the line before the fence ('' if none)

    @property
    def name(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"

    @property
    def not_run(self) -> str | None:
        """The reason given for not running the block, or None."""
        if self.marker.startswith("not-run"):
            return self.marker.partition(":")[2].strip()
        return None


def blocks_of(path: Path) -> list[Block]:
    out: list[Block] = []
    lines = path.read_text(encoding="utf-8").splitlines()
    i = 0
    while i < len(lines):
        fence = _FENCE.match(lines[i])
        if not fence:
            i += 1
            continue
        start = i
        i += 1
        while i < len(lines) and lines[i].rstrip() != "```":
            i += 1
        previous = next((ln for ln in reversed(lines[:start]) if ln.strip()), "")
        comment = _COMMENT.match(previous)
        text = "\n".join(lines[start + 1 : i]) + "\n"
        marker = comment.group(1) if comment else ""
        out.append(Block(path, start + 1, fence.group(1), text, marker))
        i += 1
    return out


ALL = [block for path in DOCUMENTS for block in blocks_of(path)]
_NEXT = {a: b for a, b in itertools.pairwise(ALL) if a.path == b.path}
_NOISE = re.compile(r"\d\.\d+e-(0[6-9]|[1-9]\d)")


def masked(text: str) -> list[str]:
    """Lines of program output without what varies between runs (timings, tiny residuals)."""
    lines = (line.rstrip() for line in text.splitlines())
    return [_NOISE.sub("#", line) for line in lines if line and not line.startswith("  time ")]


RUNNABLE = [b for b in ALL if b.lang in RUN and b.not_run is None]


# --------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    base = tmp_path_factory.mktemp("docs-server")
    live = LiveServer(base / "data", workers=1)
    live.start()
    try:
        yield live
    finally:
        live.stop()


def _shared_data() -> Path:
    return shared_data_dir()


_CHECKOUTS: dict[Path, Path] = {}


def checkout(doc: Path, base: Path) -> Path:
    """The scratch directory of one document, laid out like a checkout (made once)."""
    if doc not in _CHECKOUTS:
        work = base / doc.stem
        project = work / "project"
        project.mkdir(parents=True)
        for entry in ROOT.iterdir():
            if entry.name not in {".git", ".venv", "data"}:
                (project / entry.name).symlink_to(entry)
        (project / ".venv").symlink_to(Path(sys.prefix))
        if _shared_data().is_dir():
            (work / "shared").mkdir()
            (work / "shared" / "data").symlink_to(_shared_data().resolve())
        _CHECKOUTS[doc] = project
    return _CHECKOUTS[doc]


def block_env(home: Path) -> dict[str, str]:
    return {
        "PATH": "/usr/local/bin:/usr/bin:/bin",
        "HOME": str(home),
        "LANG": "C.UTF-8",
        "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "clients" / "python")]),
        "PYTHONDONTWRITEBYTECODE": "1",
        "TMPDIR": str(home),
    }


def localize(text: str, port: int) -> str:
    """Point the documented address (127.0.0.1:8000) at the test's server."""
    text = re.sub(r"\b(127\.0\.0\.1|localhost):8000\b", rf"\g<1>:{port}", text)
    return re.sub(r"--port 8000\b", f"--port {port}", text)


def run_block(block: Block, cwd: Path, port: int) -> subprocess.CompletedProcess[str]:
    home = cwd.parent / "home"
    home.mkdir(exist_ok=True)
    text = localize(block.text, port)
    if block.lang == "sh":
        cmd = ["bash", "-e", "-o", "pipefail", "-c", text]
    else:
        script = home / f"block-{block.line}.py"
        script.write_text(text, encoding="utf-8")
        cmd = [sys.executable, str(script)]
    proc = subprocess.Popen(
        cmd, cwd=cwd, env=block_env(home), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        text=True, start_new_session=True,
    )  # fmt: skip
    try:
        out, _ = proc.communicate(timeout=BLOCK_TIMEOUT)
    except subprocess.TimeoutExpired:
        out = ""
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)  # whatever the block left running
        proc.wait()
    return subprocess.CompletedProcess(cmd, proc.returncode, out, "")


# --------------------------------------------------------------------------- tests


@pytest.mark.parametrize("block", [
    pytest.param(b, id=b.name, marks=pytest.mark.xdist_group(f"docs:{b.path}")) for b in RUNNABLE
])  # a page's blocks share its checkout: one worker runs them all, in order
def test_documented_block_runs(
    block: Block, server: LiveServer, tmp_path_factory: pytest.TempPathFactory
) -> None:
    if "../shared/data" in block.text and not _shared_data().is_dir():
        pytest.skip(str(shared_data_missing()))
    base = tmp_path_factory.getbasetemp() / "docs-checkouts"
    base.mkdir(exist_ok=True)
    cwd = checkout(block.path, base)
    port = free_port() if block.marker == "own-server" else server.port
    done = run_block(block, cwd, port)
    assert done.returncode == 0, (
        f"{block.name} ({block.lang}) exited with {done.returncode}:\n{done.stdout[-4000:]}"
    )
    shown = _NEXT.get(block)
    if shown is not None and shown.marker == "output":
        actual = set(masked(done.stdout))
        stale = [line for line in masked(shown.text) if line not in actual]
        assert not stale, f"{shown.name} is stale; the output now is:\n{done.stdout}"


def test_every_block_says_whether_it_runs() -> None:
    unknown = [f"{b.name}: ```{b.lang}" for b in ALL if b.lang not in RUN | SHOWN]
    assert not unknown, f"use ```sh or ```python (run) or ```text / json (shown): {unknown}"
    unexplained = [b.name for b in ALL if b.not_run is not None and len(b.not_run) < 10]
    assert not unexplained, f"a not-run block needs its reason: {unexplained}"
    assert len(RUNNABLE) >= 15


def test_documents_do_not_call_a_bare_geosmooth() -> None:
    """The command is .venv/bin/geosmooth after `make run` (not on PATH); inside containers
    (not-run Docker blocks) `geosmooth` is on PATH."""
    bare = re.compile(r"(^|[;&|(]\s*|\$\(\s*)geosmooth\s", re.M)
    found = [b.name for b in ALL if b.lang == "sh" and b.not_run is None and bare.search(b.text)]
    assert not found, found


def test_relative_links_resolve() -> None:
    broken = []
    for doc in DOCUMENTS:
        for target in _LINK.findall(doc.read_text(encoding="utf-8")):
            if "://" in target or target.startswith("mailto:"):
                continue
            if not (doc.parent / target).exists():
                broken.append(f"{doc.relative_to(ROOT)} -> {target}")
    assert not broken, broken


def test_readme_is_short() -> None:
    lines = (ROOT / "README.md").read_text(encoding="utf-8").count("\n")
    assert lines <= README_MAX_LINES, f"README.md has {lines} lines; move sections to docs/"


def test_formats_page_lists_every_format_of_the_registry() -> None:
    from service.io.registry import FORMATS

    text = (ROOT / "docs" / "formats.md").read_text(encoding="utf-8")
    lines = [line for line in text.splitlines() if line.startswith("| **")]
    rows = {line.split("|")[1].strip(): line for line in lines}
    for fmt in FORMATS.values():
        row = next((r for cell, r in rows.items() if cell.endswith(f"`{fmt.name}`")), None)
        assert row is not None, f"docs/formats.md lacks {fmt.name}"
        exts = ", ".join(f"`.{ext}`" for ext in fmt.extensions)
        assert f"| {exts} | `{fmt.media_type.split(';')[0]}` |" in row, (fmt.name, row)
    assert len(rows) == len(FORMATS)


def test_settings_table_is_generated_from_the_settings() -> None:
    from tests.docs.settings_table import PAGE, render

    text = PAGE.read_text(encoding="utf-8")
    assert text == render(text), "stale: run python -m tests.docs.settings_table and commit"


def test_every_setting_named_in_the_documents_exists() -> None:
    from service.settings import Settings

    known = {f"GEOSMOOTH_{name.upper()}" for name in Settings.model_fields}
    # read by the CLI (debug, submit's key, the library's threads) and the test suite,
    # not by the service's settings
    known |= {"GEOSMOOTH_DEBUG", "GEOSMOOTH_API_KEY", "GEOSMOOTH_SHARED_DATA",
              "GEOSMOOTH_SCREENSHOTS", "GEOSMOOTH_THREADS",
              "GEOSMOOTH_TILE_WORKERS"}  # fmt: skip
    pattern = re.compile(r"GEOSMOOTH_[A-Z0-9_]*[A-Z0-9]")
    named = {name for doc in DOCUMENTS for name in pattern.findall(doc.read_text())}
    assert named <= known, sorted(named - known)


def _quoted(doc: str) -> str:
    return (ROOT / doc).read_text(encoding="utf-8")


def test_budgets_quoted_from_info_are_current() -> None:
    """The τ ranges and noise estimates the documents quote are what `info` says today."""
    import geosmooth

    sphere = geosmooth.describe(geosmooth.read(ROOT / "service/samples/noisy-sphere.ply"))
    readme, method = _quoted("README.md"), _quoted("docs/method.md")
    assert f'"tau_range": [0.0, {sphere["tau_range"][1]:.2f}]' in readme
    assert f'"sigma_estimate": {sphere["sigma_estimate"]:.4f}' in readme
    assert f'"suggested_tau": {sphere["suggested_tau"]:.4f}' in readme
    assert f"`(0, {sphere['phi0']:.1f})`" in method
    assert f"(0, {sphere['phi0']:.3f})" in _quoted("docs/http-api.md")  # the problem's detail
    bunny_file = _shared_data() / "bunny.ply"
    if not bunny_file.is_file():
        pytest.skip(f"{bunny_file} not found: the bunny's figures are not checked")
    bunny = geosmooth.describe(geosmooth.read(bunny_file))
    cli = _quoted("docs/cli.md")
    assert f'`"tau_range": [0.0, {bunny["tau_range"][1]:.4f}]`' in cli
    assert f'`"rms_range": [0.0, {bunny["rms_range"][1]:.6f}]`' in cli
    assert f'`"sigma_estimate": {bunny["sigma_estimate"]:.2e}`' in cli
    tau = bunny["suggested_tau"]
    quoted = f'`"suggested_tau": {tau:.2e}`' if tau is not None else '`"suggested_tau": null`'
    assert quoted in cli
    assert f"`(0, {bunny['phi0']:.3f})`" in method


def test_cli_page_documents_every_option_of_every_command() -> None:
    import argparse

    from service.cli.parser import build_parser

    text = _quoted("docs/cli.md")
    parser = build_parser()
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    missing = []
    for name, sub in commands.choices.items():
        assert f"`geosmooth {name}" in text, f"docs/cli.md lacks the command {name}"
        for action in sub._actions:
            options = [o for o in action.option_strings if o not in ("-h", "--help")]
            if options and not any(re.search(rf"(?<![\w-]){o}(?![\w-])", text) for o in options):
                missing.append(f"{name} {options[-1]}")
    assert not missing, missing


def test_http_page_documents_every_operation_of_the_openapi_document() -> None:
    import json

    spec = json.loads(_quoted("openapi/openapi.json"))
    text = re.sub(r"\{[^}]+\}", "{}", _quoted("docs/http-api.md"))
    missing = [
        f"{method.upper()} {path}"
        for path, operations in spec["paths"].items()
        for method in operations
        if f"{method.upper()} {re.sub(r'{[^}]+}', '{}', path)}" not in text
    ]
    assert not missing, f"docs/http-api.md lacks {missing}"
