"""The web page (``/``), its static assets, the bundled samples, and offline API docs.

Everything the page and the documentation load comes from this package
(``service/web/static``; vendored libraries at pinned versions under ``static/vendor``, see
``service/web/README.md``): no request leaves the machine. FastAPI's own ``/docs`` and
``/redoc`` pages load Swagger UI, ReDoc and fonts from public CDNs; the app disables them and
this router serves the same pages with the vendored copies.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fastapi import APIRouter, Request, Response
from fastapi.openapi.docs import (
    get_redoc_html,
    get_swagger_ui_html,
    get_swagger_ui_oauth2_redirect_html,
)
from fastapi.responses import FileResponse, HTMLResponse
from starlette.staticfiles import StaticFiles

from service.api.deps import SettingsDep
from service.api.http.headers import CSP
from service.api.problems import ApiProblem
from service.io.registry import FORMATS, format_for_name

__all__ = ["REDOC", "STATIC_DIR", "SWAGGER_UI", "THREE", "router"]

STATIC_DIR = Path(__file__).resolve().parents[2] / "web" / "static"
SAMPLES_DIR = Path(__file__).resolve().parents[2] / "samples"
#: Vendored library directories under /static/vendor (name@version, as published on npm).
SWAGGER_UI = "swagger-ui-dist@5.35.0"
REDOC = "redoc@2.5.4"
THREE = "three@0.187.0"
_VENDOR = "/static/vendor"
_FAVICON = "/static/favicon.svg"

router = APIRouter(include_in_schema=False)
_static = StaticFiles(directory=STATIC_DIR, check_dir=False)


def _html(response: Response) -> Response:
    response.headers["Content-Security-Policy"] = CSP
    response.headers["Cache-Control"] = "no-cache"
    return response


def _cache_control(path: str) -> str:
    """Vendored files never change under a versioned path; the page's own files revalidate."""
    return "public, max-age=604800, immutable" if path.startswith("vendor/") else "no-cache"


@router.get("/", response_class=HTMLResponse)
async def index() -> Response:
    """The web page."""
    return _html(FileResponse(STATIC_DIR / "index.html", media_type="text/html"))


@router.get("/static/{path:path}")
async def static(path: str, request: Request) -> Response:
    """A file of ``service/web/static`` (ETag and Last-Modified from Starlette)."""
    response = await _static.get_response(path, request.scope)
    if response.status_code < 400:
        response.headers["Cache-Control"] = _cache_control(path)
    return response


def _samples() -> list[dict[str, Any]]:
    out = []
    for path in sorted(SAMPLES_DIR.iterdir()) if SAMPLES_DIR.is_dir() else []:
        fmt = format_for_name(path.name)
        if path.is_file() and fmt is not None:
            out.append({"name": path.name, "format": fmt.name, "url": f"/samples/{path.name}"})
    return out


@router.get("/samples/{name}")
async def sample(name: str) -> FileResponse:
    """A bundled sample file (``service/samples``)."""
    names = {s["name"]: s for s in _samples()}
    if name not in names:
        raise ApiProblem(404, f"no sample called {name!r}", code="sample-not-found", field="name")
    fmt = FORMATS[names[name]["format"]]
    return FileResponse(SAMPLES_DIR / name, media_type=fmt.media_type, filename=name)


@router.get("/app/config.json")
async def config(settings: SettingsDep) -> dict[str, Any]:
    """What the page needs from the server: formats (from the io registry: what each can hold),
    samples, and the default limits (the page states the key's own from ``GET /v1/limits``)."""
    formats = [
        {
            "name": f.name,
            "title": f.title,
            "extensions": list(f.extensions),
            "media_type": f.media_type,
            "writable": f.write is not None,
            "kinds": sorted(f.kinds),
            "geographic_only": f.geographic_only,
        }
        for f in FORMATS.values()
    ]
    return {
        "formats": formats,
        "samples": _samples(),
        "max_upload_bytes": settings.max_upload_bytes,
        "max_points": settings.max_points,
        "sync_max_points": settings.sync_max_points,
    }


@router.get("/docs")
async def swagger_ui(request: Request) -> Response:
    """Swagger UI from the vendored swagger-ui-dist."""
    return _html(
        get_swagger_ui_html(
            openapi_url=request.app.openapi_url,
            title=f"{request.app.title} - Swagger UI",
            oauth2_redirect_url="/docs/oauth2-redirect",
            swagger_js_url=f"{_VENDOR}/{SWAGGER_UI}/swagger-ui-bundle.js",
            swagger_css_url=f"{_VENDOR}/{SWAGGER_UI}/swagger-ui.css",
            swagger_favicon_url=_FAVICON,
        )
    )


@router.get("/docs/oauth2-redirect")
async def swagger_ui_redirect() -> Response:
    """OAuth2 redirect page of Swagger UI."""
    return _html(get_swagger_ui_oauth2_redirect_html())


@router.get("/redoc")
async def redoc(request: Request) -> Response:
    """ReDoc from the vendored standalone bundle, without Google fonts."""
    return _html(
        get_redoc_html(
            openapi_url=request.app.openapi_url,
            title=f"{request.app.title} - ReDoc",
            redoc_js_url=f"{_VENDOR}/{REDOC}/redoc.standalone.js",
            redoc_favicon_url=_FAVICON,
            with_google_fonts=False,
        )
    )
