"""Write the OpenAPI document of the app: ``python -m service.api.openapi_export PATH``."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from service.api.app import create_app
from service.settings import Settings

__all__ = ["main", "openapi_spec", "render"]


def openapi_spec() -> dict[str, Any]:
    """The spec of an app built with default settings (independent of the environment)."""
    return create_app(Settings.model_construct(**_defaults())).openapi()


def _defaults() -> dict[str, Any]:
    return {
        name: (f.default_factory() if f.default_factory else f.default)  # type: ignore[call-arg]
        for name, f in Settings.model_fields.items()
    }


def render(spec: dict[str, Any]) -> str:
    """The committed text form: FastAPI's key order, 2-space indent, final newline."""
    return json.dumps(spec, indent=2, ensure_ascii=False) + "\n"


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m service.api.openapi_export",
        description="Write the OpenAPI document of the geosmooth HTTP API (built with default "
        "settings, independent of the environment).",
    )
    parser.add_argument(
        "path",
        nargs="?",
        default="-",
        metavar="PATH",
        help="file to write, e.g. openapi/openapi.json ('-' or nothing: stdout)",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Write the spec to the path given (``-`` or nothing: stdout); ``--help`` prints usage."""
    args = _parser().parse_args(sys.argv[1:] if argv is None else list(argv))
    text = render(openapi_spec())
    if args.path == "-":
        sys.stdout.write(text)
    else:
        Path(args.path).write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
