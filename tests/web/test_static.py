"""The page's files as served: every reference resolves on this server, caching, traversal,
samples, the docs pages' assets, and the vendored libraries' checksums."""

from __future__ import annotations

import hashlib
import re
from pathlib import Path
from typing import Any

import httpx
import pytest

from service.api.routers.web import REDOC, STATIC_DIR, SWAGGER_UI, THREE
from service.io.registry import FORMATS
from tests.web.web_helpers import SAMPLES, WebServer

VENDOR = STATIC_DIR / "vendor"
REDOC_UPSTREAM_SHA256 = "dcaf76612bc4a3fbcc923a8966dee2f6146a5f32e5ce1b6f02dd60cbbf89500b"
_REFS = re.compile(r"""(?:src|href)\s*=\s*["']([^"']+)["']""")
_IMPORTS = re.compile(r"""(?:import|from)\s*["']([^"']+)["']""")


@pytest.fixture
def client(web_server: WebServer) -> Any:
    with web_server.client() as c:
        yield c


def _page_references(html: str) -> set[str]:
    refs = set(_REFS.findall(html))
    importmap = re.search(r'<script type="importmap">(.*?)</script>', html, re.S)
    if importmap:
        refs |= set(re.findall(r'"(/static/[^"]+\.js)"', importmap.group(1)))
    return {r for r in refs if not r.startswith("#")}


def test_every_reference_of_the_page_resolves_locally(client: httpx.Client) -> None:
    page = client.get("/")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    assert "default-src 'self'" in page.headers["content-security-policy"]
    refs = _page_references(page.text)
    assert f"/static/vendor/{THREE}/three.module.js" in refs
    todo = sorted(refs)
    seen: set[str] = set()
    while todo:
        url = todo.pop()
        if url in seen:
            continue
        seen.add(url)
        assert url.startswith("/"), f"the page refers to another host: {url}"
        response = client.get(url)
        assert response.status_code == 200, url
        if url.startswith("/static/js/"):  # the page's own modules: follow their imports
            for target in _IMPORTS.findall(response.text):
                if target.startswith("."):
                    todo.append(str(Path(url).parent / target).replace("\\", "/"))
    assert "/static/js/viewer.js" in seen and "/static/js/schemaform.js" in seen


@pytest.mark.parametrize("path", ["/docs", "/redoc"])
def test_docs_pages_load_only_vendored_assets(client: httpx.Client, path: str) -> None:
    response = client.get(path)
    assert response.status_code == 200
    assert "default-src 'self'" in response.headers["content-security-policy"]
    refs = _page_references(response.text)
    assert refs and all(r.startswith("/") for r in refs), refs
    assert any(f"/static/vendor/{SWAGGER_UI if path == '/docs' else REDOC}/" in r for r in refs)
    assert "fonts.googleapis" not in response.text
    for ref in refs:
        assert client.get(ref).status_code == 200, ref


def test_caching_and_conditional_requests(client: httpx.Client) -> None:
    vendored = client.get(f"/static/vendor/{THREE}/three.core.js")
    assert vendored.status_code == 200 and "immutable" in vendored.headers["cache-control"]
    again = client.get(
        f"/static/vendor/{THREE}/three.core.js", headers={"If-None-Match": vendored.headers["etag"]}
    )
    assert again.status_code == 304
    own = client.get("/static/js/main.js")
    assert own.headers["cache-control"] == "no-cache"
    assert own.headers["content-type"].startswith(("text/javascript", "application/javascript"))


@pytest.mark.parametrize(
    "path",
    [
        "/static/../routers/web.py",
        "/static/%2e%2e/%2e%2e/api/app.py",
        "/static/missing.js",
        "/samples/generate.py",
        "/samples/..%2Fsettings.py",
    ],
)
def test_nothing_outside_the_asset_directories(client: httpx.Client, path: str) -> None:
    assert client.get(path).status_code == 404


def test_config_and_samples(client: httpx.Client) -> None:
    config = client.get("/app/config.json").json()
    assert [f["name"] for f in config["formats"]] == list(FORMATS)
    for f in config["formats"]:
        assert f["extensions"] == list(FORMATS[f["name"]].extensions)
    names = {s["name"] for s in config["samples"]}
    assert {"noisy-sphere.ply", "noisy-helix.obj"} <= names
    for sample in config["samples"]:
        response = client.get(sample["url"])
        assert response.status_code == 200
        assert response.content == (SAMPLES / sample["name"]).read_bytes()


def test_vendored_files_match_their_checksums() -> None:
    sums = (VENDOR / "SHA256SUMS").read_text().split("\n")
    checked = 0
    for line in filter(None, sums):
        digest, name = line.split()
        assert hashlib.sha256((VENDOR / name).read_bytes()).hexdigest() == digest, name
        checked += 1
    assert checked >= 6
    # The one local change to a vendored file (service/web/README.md): ReDoc's CDN logo URL.
    redoc = (VENDOR / REDOC / "redoc.standalone.js").read_bytes()
    assert b"cdn.redoc.ly" not in redoc
    upstream = redoc.replace(b'src:"data:,"', b'src:"https://cdn.redoc.ly/redoc/logo-mini.svg"')
    assert hashlib.sha256(upstream).hexdigest() == REDOC_UPSTREAM_SHA256
    for directory in (THREE, SWAGGER_UI, REDOC):
        assert (VENDOR / directory / "LICENSE").is_file()
