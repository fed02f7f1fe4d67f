"""Selection by attribute (issue 41): which points to smooth, the others held fixed.

``--where`` takes PDAL's ``where`` grammar, small and parsed here (never ``eval``)::

    expr       := term ("or" term)*            ("||" too)
    term       := factor ("and" factor)*       ("&&" too)
    factor     := "not" factor | "!" factor | "(" expr ")" | comparison
    comparison := NAME OP NUMBER               OP: == != < <= > >=

``NAME`` is a dimension of the file as PDAL or laspy spells it, case and underscores ignored
(``Classification``, ``Intensity``, ``ReturnNumber`` = ``return_number``, ``X``, ``Y``, ``Z``).
Examples: ``Classification == 2``, ``Intensity > 100 and ReturnNumber == 1``,
``not (Classification == 7 or Classification == 18)``.

Points outside the selection are fixed points of the run: returned bit-identical, and they
anchor the smoothing of their neighbours (report, section 2: fixed points are boundary
conditions). ``--fix-classes 6,9`` holds those classes fixed (the same as ``--where
"Classification != 6 and Classification != 9"``).
"""

from __future__ import annotations

import operator
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from service.workflows.errors import ServiceError

__all__ = ["SelectionError", "class_list", "fixed_outside", "parse_where", "selected"]

_TOKEN = re.compile(
    r"\s*(?:(?P<num>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)|(?P<op>==|!=|<=|>=|<|>|&&|\|\||!)"
    r"|(?P<paren>[()])|(?P<name>[A-Za-z_][A-Za-z0-9_]*))"
)
_OPS: dict[str, Callable[[Any, Any], Any]] = {
    "==": operator.eq, "!=": operator.ne, "<": operator.lt, "<=": operator.le,
    ">": operator.gt, ">=": operator.ge,
}  # fmt: skip
_WORDS = {"and": "&&", "or": "||", "not": "!"}


class SelectionError(ServiceError):
    """A ``where`` expression that does not parse or names no dimension of the file:
    HTTP 422 naming ``field``, CLI exit status 2."""

    code = "invalid-selection"
    title = "Invalid selection expression"
    status = 422
    exit_code = 2  # see the CLI's table, service/exit_codes.py

    def __init__(self, message: str, field: str = "where") -> None:
        super().__init__(message, field=field)


@dataclass(frozen=True)
class _Compare:
    name: str
    op: str
    value: float


@dataclass(frozen=True)
class _Node:
    op: str  # "&&", "||", "!"
    args: tuple[Any, ...]


def _tokens(text: str) -> list[tuple[str, str]]:
    out: list[tuple[str, str]] = []
    at = 0
    while at < len(text.rstrip()):
        m = _TOKEN.match(text, at)
        if m is None or m.end() == at:
            raise SelectionError(f"--where: cannot read {text[at:].strip()[:20]!r} in {text!r}")
        kind = m.lastgroup or ""
        value = m.group(kind)
        if kind == "name" and value.lower() in _WORDS:
            kind, value = "op", _WORDS[value.lower()]
        out.append((kind, value))
        at = m.end()
    return out


class _Parser:
    def __init__(self, text: str) -> None:
        self.text = text
        self.tokens = _tokens(text)
        self.at = 0

    def _peek(self) -> tuple[str, str] | None:
        return self.tokens[self.at] if self.at < len(self.tokens) else None

    def _take(self) -> tuple[str, str]:
        token = self._peek()
        if token is None:
            raise SelectionError(f"--where: {self.text!r} ends too early")
        self.at += 1
        return token

    def _fail(self, wanted: str) -> SelectionError:
        token = self._peek()
        got = repr(token[1]) if token else "the end"
        return SelectionError(f"--where: expected {wanted}, got {got} in {self.text!r}")

    def parse(self) -> Any:
        if not self.tokens:
            raise SelectionError("--where: the expression is empty")
        node = self._binary("||")
        if self._peek() is not None:
            raise self._fail("'and', 'or' or the end")
        return node

    def _binary(self, op: str) -> Any:
        parts = [self._binary("&&") if op == "||" else self._factor()]
        while self._peek() == ("op", op):
            self.at += 1
            parts.append(self._binary("&&") if op == "||" else self._factor())
        return parts[0] if len(parts) == 1 else _Node(op, tuple(parts))

    def _factor(self) -> Any:
        token = self._peek()
        if token == ("op", "!"):
            self.at += 1
            return _Node("!", (self._factor(),))
        if token == ("paren", "("):
            self.at += 1
            node = self._binary("||")
            if self._peek() != ("paren", ")"):
                raise self._fail("')'")
            self.at += 1
            return node
        if token is None or token[0] != "name":
            raise self._fail("a dimension name (e.g. Classification)")
        name = self._take()[1]
        op = self._peek()
        if op is None or op[1] not in _OPS:
            raise self._fail("a comparison (== != < <= > >=)")
        self.at += 1
        kind, value = self._take()
        if kind != "num":
            self.at -= 1
            raise self._fail("a number")
        return _Compare(name, op[1], float(value))


def parse_where(text: str) -> Any:
    """The parsed expression (:class:`SelectionError` with one line when it does not parse)."""
    return _Parser(str(text)).parse()


def _key(name: str) -> str:
    return name.replace("_", "").lower()


def _evaluate(node: Any, columns: Callable[[str], NDArray[Any]]) -> NDArray[np.bool_]:
    if isinstance(node, _Compare):
        return np.asarray(_OPS[node.op](columns(node.name), node.value), dtype=bool)
    values = [_evaluate(a, columns) for a in node.args]
    if node.op == "!":
        return ~values[0]
    combine = np.logical_and if node.op == "&&" else np.logical_or
    out = values[0]
    for v in values[1:]:
        out = combine(out, v)
    return out


def selected(
    text: str, points: NDArray[np.float64], attributes: Mapping[str, NDArray[Any]]
) -> NDArray[np.bool_]:
    """The mask of the points ``text`` selects (``attributes`` in the points' numbering)."""
    tree = parse_where(text)
    n = len(points)
    columns = {k: a for k, a in attributes.items() if np.ndim(a) == 1 and len(a) == n}
    for j, axis in enumerate("XYZ"[: points.shape[1]]):
        columns.setdefault(axis, points[:, j])
    by_key = {_key(k): a for k, a in columns.items()}

    def column(name: str) -> NDArray[Any]:
        found = by_key.get(_key(name))
        if found is None:
            have = ", ".join(columns) or "none"
            raise SelectionError(f"--where: the file has no dimension {name!r} (it has {have})")
        return found

    return _evaluate(tree, column)


def class_list(text: str) -> list[int]:
    """``"6,9"`` -> ``[6, 9]`` (:class:`SelectionError` for anything but class codes)."""
    try:
        codes = [int(t) for t in re.split(r"[\s,]+", str(text).strip()) if t]
    except ValueError:
        raise SelectionError(
            f"--fix-classes: {text!r} is not a list of class codes (e.g. 6,9)", "fix_classes"
        ) from None
    if not codes or any(not 0 <= c <= 255 for c in codes):
        raise SelectionError(f"--fix-classes: class codes are 0-255, got {text!r}", "fix_classes")
    return codes


def fixed_outside(
    points: NDArray[np.float64],
    attributes: Mapping[str, NDArray[Any]],
    where: str | None = None,
    fix_classes: Sequence[int] | None = None,
) -> NDArray[np.int64]:
    """Indices of the points to hold fixed: outside ``where``, or of a class in
    ``fix_classes`` (empty when neither is given)."""
    keep = np.ones(len(points), dtype=bool)
    if where:
        keep &= selected(where, points, attributes)
    if fix_classes:
        classes = {_key(n): a for n, a in attributes.items()}.get("classification")
        if classes is None:
            raise SelectionError("--fix-classes: the file has no classification", "fix_classes")
        keep &= ~np.isin(classes, np.asarray(fix_classes))
    return np.flatnonzero(~keep).astype(np.int64)
