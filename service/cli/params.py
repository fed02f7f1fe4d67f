"""Command-line options generated from :class:`service.core.params.SmoothingParams`.

Every field of the model becomes an option ``--`` + the field name with ``_`` -> ``-``, in the
model's order, with the model's description and default as help: a field added to the model
appears in ``geosmooth smooth`` and ``geosmooth submit`` by itself. Values stay strings until
the model parses them, so validation happens once, by pydantic; its complaints become one line
naming the option (:func:`params_from_args`).
"""

from __future__ import annotations

import argparse
import os
import re
import textwrap
import typing

from pydantic import ValidationError
from pydantic.fields import FieldInfo
from pydantic_core import PydanticUndefined

from service.cli.errors import CliError, option_name
from service.core.params import SmoothingParams
from service.exit_codes import EXIT_USAGE

__all__ = [
    "TARGET_FIELDS",
    "add_smoothing_options",
    "literal_names",
    "option_name",
    "params_from_args",
    "threads",
]

#: The ways to pick lambda: mutually exclusive options. Whether one is required is the model's
#: business (its validator), not argparse's.
TARGET_FIELDS = tuple(f for f in ("tau", "rms", "lam") if f in SmoothingParams.model_fields)
_METAVARS = {
    "tau": "T",
    "rms": "R",
    "lam": "L",
    "k": "K",
    "sigma_f": "SIGMA",
    "sigma_h": "SIGMA",
    "tolerance": "XI",
    "max_iterations": "N",
}
_SHORT = {"k": "-k"}
_HELP_PREFIX = {
    "tau": "Smoothing factor: target for phi = sum_i w_i^2 ||x_i - p_i||^2.",
    "rms": "Target RMS displacement (tau = sum_i w_i^2 * R^2).",
    "lam": "Use this lambda directly (no tau search).",
}


def _default_text(info: FieldInfo) -> str:
    if info.default is PydanticUndefined or info.default_factory is not None:
        return "auto"
    return "off" if info.default is False else str(info.default)


def _field_help(name: str) -> str:
    info = SmoothingParams.model_fields[name]
    text = _HELP_PREFIX.get(name) or (info.description or "")
    text = text.replace("%", "%%")
    if name not in TARGET_FIELDS:
        text += f" [default: {_default_text(info)}]"
    return text


def _literals(annotation: object) -> list[object]:
    """The members of a ``Literal`` (or of several, in a union); other types as themselves."""
    if typing.get_origin(annotation) is typing.Literal:
        return list(typing.get_args(annotation))
    args = typing.get_args(annotation)
    if not args:
        return [annotation]
    return [m for a in args if a is not type(None) for m in _literals(a)]


def literal_names(annotation: object) -> tuple[str, ...] | None:
    """The names a type allows (``{normalized,curvature,feature}``), if it allows only names."""
    members = _literals(annotation)
    if members and all(isinstance(m, str) for m in members):
        return tuple(str(m) for m in members)
    return None


def add_smoothing_options(parser: argparse.ArgumentParser) -> None:
    """Add one option per :class:`SmoothingParams` field (defaults stay in the model)."""
    target = parser.add_argument_group(
        "smoothing target",
        textwrap.fill(
            "tau is the budget for the weighted sum of squared displacements (report eq. 3 and "
            "15); it must lie in (0, phi(0)), phi(0) being the deviation from the weighted "
            "centroid (of each connected part).",
            78,
        ),
    )
    group = target.add_mutually_exclusive_group()
    for target_name in TARGET_FIELDS:
        group.add_argument(
            option_name(target_name),
            dest=target_name,
            metavar=_METAVARS[target_name],
            help=_field_help(target_name),
        )
    opts = parser.add_argument_group("smoothing options")
    opts.add_argument(
        "--params", metavar="FILE.json", dest="params_file", default=None,
        help="the parameters as data: a JSON object of the options below (names with '_'), "
        "or a --report file (its 'params' are used, and its 'where', 'fix_classes' and 'crs' "
        "pipeline options); options given on the command line win",
    )  # fmt: skip
    for name, info in SmoothingParams.model_fields.items():
        if name in TARGET_FIELDS:
            continue
        flags = [option_name(name)] + ([_SHORT[name]] if name in _SHORT else [])
        if info.annotation is bool:
            action = argparse.BooleanOptionalAction if info.default is True else "store_true"
            opts.add_argument(
                *flags, dest=name, action=action, default=None, help=_field_help(name)
            )
            continue
        choices = literal_names(info.annotation)
        metavar = "{" + ",".join(choices) + "}" if choices else _METAVARS.get(name, name.upper())
        opts.add_argument(*flags, dest=name, metavar=metavar, default=None, help=_field_help(name))


def params_from_args(ns: argparse.Namespace) -> SmoothingParams:
    """Build the :class:`SmoothingParams` of a parsed ``smooth`` or ``submit`` command line.

    Only options the user gave are passed, so every default comes from the model (and
    ``model_dump(exclude_unset=True)`` gives back exactly what the user set).

    Raises
    ------
    CliError
        Exit status 2, with pydantic's complaints as one line naming the options, e.g.
        ``--tau: must be greater than 0``.
    """
    given = {
        name: getattr(ns, name)
        for name in SmoothingParams.model_fields
        if getattr(ns, name, None) is not None
    }
    base = params_file(ns)
    if any(t in given for t in TARGET_FIELDS):  # the command line's target replaces the file's
        base = {k: v for k, v in base.items() if k not in TARGET_FIELDS}
    given = {**base, **given}
    try:
        return SmoothingParams.model_validate(given)
    except ValidationError as exc:
        raise CliError(_validation_message(exc), EXIT_USAGE) from exc


#: Pipeline options a ``--params`` file may carry besides the parameters (issue 41).
PIPELINE_OPTIONS = ("where", "fix_classes", "crs")


def params_file(ns: argparse.Namespace) -> dict[str, object]:
    """The parameters of ``--params FILE`` (empty without it); its pipeline options
    (:data:`PIPELINE_OPTIONS`) are set on ``ns`` where the command line gave none.

    Raises
    ------
    CliError
        Exit status 2: unreadable, not a JSON object, or naming an unknown parameter.
    """
    path = getattr(ns, "params_file", None)
    if not path:
        return {}
    import json
    from pathlib import Path

    try:
        obj = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise CliError(f"--params: cannot read {path}: {exc}", EXIT_USAGE) from exc
    if not isinstance(obj, dict):
        raise CliError(f"--params: {path} holds no JSON object", EXIT_USAGE)
    params = obj.get("params", obj) if isinstance(obj.get("params"), dict) else obj
    for option in PIPELINE_OPTIONS:
        if getattr(ns, option, None) is None and obj.get(option) is not None:
            setattr(ns, option, obj[option])
    if params is not obj:
        return {k: v for k, v in params.items() if v is not None}
    known = set(SmoothingParams.model_fields) | set(PIPELINE_OPTIONS)
    unknown = sorted(set(obj) - known)
    if unknown:
        raise CliError(f"--params: {path}: unknown parameter {unknown[0]!r}", EXIT_USAGE)
    return {k: v for k, v in obj.items() if k in SmoothingParams.model_fields}


def _validation_message(exc: ValidationError) -> str:
    """Pydantic's errors as one line: ``--option: must be ...`` joined by ``; ``."""
    parts = []
    for err in exc.errors(include_url=False):
        msg = str(err.get("msg", "invalid value"))
        msg = re.sub(r"^Value error, ", "", msg)
        msg = re.sub(r"^Input should be ", "must be ", msg)
        msg = re.sub(r"^Extra inputs are not permitted", "unknown parameter", msg)
        loc = [str(part) for part in err.get("loc", ()) if part != "__root__"]
        if loc:
            parts.append(f"{option_name(loc[0])}: {msg}")
            continue
        for name in TARGET_FIELDS:  # a message of the model's own validator
            msg = re.sub(rf"\b{name}\b", option_name(name), msg)
        parts.append(msg)
    return "; ".join(parts) or "invalid parameters"


def threads() -> None:
    """Set the numerical libraries' thread count: ``GEOSMOOTH_THREADS``, default 1
    (docs/threads.md); a bad value is a usage error."""
    from service.core.linalg.threads import use_default_threads

    try:
        use_default_threads(os.environ)
    except ValueError as exc:
        raise CliError(str(exc), EXIT_USAGE) from None
