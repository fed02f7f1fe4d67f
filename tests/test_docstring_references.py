"""Every Sphinx cross-reference in a docstring of ``service/``, ``geosmooth/`` and the Python
client names something that exists.

A reference is ``:mod:``, ``:func:``, ``:class:``, ``:meth:``, ``:data:``, ``:attr:``,
``:exc:`` or ``:obj:`` around a target, in any string statement (module, class and function
docstrings, attribute docstrings). The target may carry ``~`` (show the last name only), a
title (``text <target>``), ``()`` after a callable, or a leading ``.`` (Sphinx's "search by
suffix": ``.halo`` is any object whose dotted name ends in ``.halo``).

Resolution is static, as in :mod:`tests.test_architecture`: nothing is imported. Modules come
from the files (:func:`tests.test_architecture.modules`); a name in a module is one of its
top-level ``def``/``class``/assignments/imports (inside ``if``/``try`` blocks too, e.g. under
``TYPE_CHECKING``), an import is followed to where it points, and a member of a class is a
method, a nested class, an assignment or annotation in its body, an assignment to ``self.x``
in one of its methods, or a member of one of its bases. A name is looked up as Sphinx does:
in the enclosing class, then in the module, then as a full dotted name. A target outside the
three packages is accepted when its first name is a builtin, a module of the standard library
or an installed package (found with :func:`importlib.util.find_spec`, which imports nothing
but that package's finder) and not checked further; so is a member of a class whose base is
outside the three packages (e.g. ``pydantic.BaseModel``). ``:mod:`` must name a module.

Run ``python -m tests.test_docstring_references`` for the counts and every unresolved
reference.
"""

from __future__ import annotations

import ast
import builtins
import importlib.util
import re
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import cache

from tests.test_architecture import ROOT, modules

ROLES = ("mod", "func", "class", "meth", "data", "attr", "exc", "obj")
REFERENCE = re.compile(r":(?:py:)?(" + "|".join(ROLES) + r"):`([^`]+)`")
OURS = ("service", "geosmooth", "geosmooth_client", "tests")
#: Kinds of a found name; ``external`` is outside the three packages (accepted unchecked).
MODULE, EXTERNAL = "module", "external"


@dataclass
class ClassInfo:
    members: dict[str, str] = field(default_factory=dict)  # name -> kind
    bases: list[str] = field(default_factory=list)  # dotted names as written


@dataclass
class Scope:
    names: dict[str, str] = field(default_factory=dict)  # name -> "def"/"class"/"data"
    imports: dict[str, str] = field(default_factory=dict)  # name -> absolute dotted target
    stars: list[str] = field(default_factory=list)  # modules of ``from m import *``
    classes: dict[str, ClassInfo] = field(default_factory=dict)  # qualified name -> info


@dataclass(frozen=True)
class Reference:
    module: str
    line: int
    role: str
    text: str
    cls: str | None  # qualified name of the enclosing class

    def describe(self) -> str:
        path = modules()[self.module].relative_to(ROOT)
        return f":{self.role}:`{self.text}` in {self.module} ({path}:{self.line})"


def _dotted(node: ast.expr) -> str | None:
    if isinstance(node, ast.Subscript):
        return _dotted(node.value)
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        base = _dotted(node.value)
        return f"{base}.{node.attr}" if base else None
    return None


def _targets(node: ast.stmt) -> Iterator[str]:
    if isinstance(node, ast.Assign):
        for target in node.targets:
            for name in ast.walk(target):
                if isinstance(name, ast.Name):
                    yield name.id
    elif isinstance(node, (ast.AnnAssign, ast.AugAssign)) and isinstance(node.target, ast.Name):
        yield node.target.id


def _package(module: str) -> str:
    path = modules()[module]
    return module if path.name == "__init__.py" else module.rpartition(".")[0]


def _blocks(body: list[ast.stmt]) -> Iterator[ast.stmt]:
    """Statements of a body, looking into ``if``/``try``/``with`` blocks (not defs)."""
    for node in body:
        yield node
        if isinstance(node, (ast.If, ast.Try, ast.With)):
            for inner in ("body", "orelse", "finalbody"):
                yield from _blocks(getattr(node, inner, []))
            for handler in getattr(node, "handlers", []):
                yield from _blocks(handler.body)


def _class_info(node: ast.ClassDef, scope: Scope, prefix: str) -> None:
    info = ClassInfo(bases=[b for b in map(_dotted, node.bases) if b])
    qualified = f"{prefix}{node.name}"
    scope.classes[qualified] = info
    for item in _blocks(node.body):
        if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)):
            info.members[item.name] = "def"
            for inner in ast.walk(item):
                for target in getattr(inner, "targets", [getattr(inner, "target", None)]):
                    if (
                        isinstance(target, ast.Attribute)
                        and isinstance(target.value, ast.Name)
                        and target.value.id == "self"
                    ):
                        info.members.setdefault(target.attr, "data")
        elif isinstance(item, ast.ClassDef):
            info.members[item.name] = "class"
            _class_info(item, scope, qualified + ".")
        else:
            for name in _targets(item):
                info.members[name] = "data"


@cache
def scope(module: str) -> Scope:
    """The top-level names of ``module``."""
    tree = ast.parse(modules()[module].read_text(encoding="utf-8"))
    found = Scope()
    package = _package(module)
    for node in _blocks(tree.body):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            found.names[node.name] = "def"
        elif isinstance(node, ast.ClassDef):
            found.names[node.name] = "class"
            _class_info(node, found, "")
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.asname:
                    found.imports[alias.asname] = alias.name
                else:
                    top = alias.name.split(".")[0]
                    found.imports[top] = top
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = parts[: len(parts) - (node.level - 1)]
                origin = ".".join([*base, *([node.module] if node.module else [])])
            else:
                origin = node.module or ""
            for alias in node.names:
                if alias.name == "*":
                    found.stars.append(origin)
                else:
                    found.imports[alias.asname or alias.name] = f"{origin}.{alias.name}"
        else:
            for name in _targets(node):
                found.names.setdefault(name, "data")
    return found


@dataclass(frozen=True)
class Found:
    kind: str  # module, class, def, data, external
    module: str = ""
    qualname: str = ""


def _external(dotted: str) -> Found | None:
    top = dotted.split(".")[0]
    if top in OURS:
        return None
    if "." not in dotted and hasattr(builtins, dotted):
        return Found(EXTERNAL)
    if top in sys.stdlib_module_names or importlib.util.find_spec(top) is not None:
        return Found(EXTERNAL)
    return None


def find(dotted: str, seen: frozenset[str] = frozenset()) -> Found | None:
    """What the absolute name ``dotted`` is (``None``: nothing of that name)."""
    if dotted in seen:
        return None
    seen = seen | {dotted}
    parts = dotted.split(".")
    known = modules()
    for cut in range(len(parts), 0, -1):
        module = ".".join(parts[:cut])
        if module in known:
            rest = parts[cut:]
            return Found(MODULE, module) if not rest else in_module(module, rest, seen)
    return _external(dotted)


def in_module(module: str, rest: list[str], seen: frozenset[str] = frozenset()) -> Found | None:
    """``rest`` (a dotted name split) looked up among ``module``'s top-level names."""
    names = scope(module)
    head, tail = rest[0], rest[1:]
    if head in names.imports:
        return find(".".join([names.imports[head], *tail]), seen)
    kind = names.names.get(head)
    if kind is None:
        for origin in names.stars:
            found = find(".".join([origin, *rest]), seen)
            if found:
                return found
        return None
    if not tail:
        return Found(kind, module, head)
    if kind == "class":
        return in_class(module, head, tail, seen)
    return None


def in_class(
    module: str,
    qualname: str,
    rest: list[str],
    seen: frozenset[str] = frozenset(),
    *,
    outside: bool = True,
) -> Found | None:
    """``rest`` looked up among the members of class ``qualname`` of ``module`` and its bases
    (``outside``: a base outside the three packages may hold it, unchecked)."""
    info = scope(module).classes.get(qualname)
    if info is None:
        return None
    head, tail = rest[0], rest[1:]
    kind = info.members.get(head)
    if kind is not None:
        if not tail:
            return Found(kind, module, f"{qualname}.{head}")
        if kind == "class":
            return in_class(module, f"{qualname}.{head}", tail, seen, outside=outside)
        return None
    for base in info.bases:
        where = in_module(module, base.split("."), seen) or find(base, seen)
        if where is None:
            continue
        if where.kind == EXTERNAL:
            if outside:
                return where  # a member of a class outside the three packages: not checked
            continue
        if where.kind == "class":
            found = in_class(where.module, where.qualname, rest, seen, outside=outside)
            if found:
                return found
    return None


@cache
def everything() -> tuple[str, ...]:
    """Dotted names of every module, top-level name and class member (the suffix search)."""
    names = []
    for module in modules():
        names.append(module)
        names += [f"{module}.{name}" for name in scope(module).names]
        for qualname, info in scope(module).classes.items():
            names += [f"{module}.{qualname}.{member}" for member in info.members]
    return tuple(names)


def target_of(text: str) -> str:
    """The target of a reference's text: no title, ``~`` or trailing ``()``."""
    if text.endswith(">") and "<" in text:
        text = text[text.rindex("<") + 1 : -1]
    text = text.strip().lstrip("~!")
    return text.removesuffix("()")


def resolve(reference: Reference) -> Found | None:
    """What a reference names (``None``: nothing), looked up as Sphinx does."""
    target = target_of(reference.text)
    suffix = target.startswith(".")
    target = target.lstrip(".")
    parts = target.split(".")
    found: Found | None = None
    if reference.role != "mod":
        if reference.cls:  # the enclosing class's own members (and its bases' in the packages)
            found = in_class(reference.module, reference.cls, parts, outside=False)
        found = found or in_module(reference.module, parts)
    found = found or find(target)
    if suffix and (found is None or found.kind == EXTERNAL):
        found = _by_suffix(reference, target)  # ``.name`` searches the packages only
    if found and reference.role == "mod" and found.kind not in (MODULE, EXTERNAL):
        return None
    return found


def _by_suffix(reference: Reference, target: str) -> Found | None:
    """Sphinx's ``.name``: the object nearest to the reference whose name ends in ``.name``
    (of the role's kind for ``:mod:``)."""
    here = reference.module.split(".")
    candidates = []
    for name in everything():
        if name.endswith("." + target):
            where = find(name)
            if where and (reference.role != "mod" or where.kind == MODULE):
                shared = next(
                    (
                        i
                        for i, (a, b) in enumerate(zip(here, name.split("."), strict=False))
                        if a != b
                    ),
                    len(here),
                )
                candidates.append((-shared, name, where))
    return min(candidates)[2] if candidates else None


def references() -> Iterator[Reference]:
    """Every reference in a string statement of the three packages."""
    for module, path in modules().items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        yield from _walk(module, tree.body, None)


def _walk(module: str, body: list[ast.stmt], cls: str | None) -> Iterator[Reference]:
    for node in body:
        if (
            isinstance(node, ast.Expr)
            and isinstance(node.value, ast.Constant)
            and isinstance(node.value.value, str)
        ):
            text = node.value.value
            for match in REFERENCE.finditer(text):
                line = node.lineno + text[: match.start()].count("\n")
                yield Reference(module, line, match.group(1), match.group(2), cls)
        if isinstance(node, ast.ClassDef):
            yield from _walk(module, node.body, f"{cls}.{node.name}" if cls else node.name)
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield from _walk(module, node.body, cls)
        else:
            for inner in ("body", "orelse", "finalbody"):
                yield from _walk(module, getattr(node, inner, []), cls)
            for handler in getattr(node, "handlers", []):
                yield from _walk(module, handler.body, cls)


def unresolved() -> list[Reference]:
    return [reference for reference in references() if resolve(reference) is None]


def summary() -> str:
    found = list(references())
    kinds: dict[str, int] = {}
    broken = []
    for reference in found:
        where = resolve(reference)
        kind = "unresolved" if where is None else where.kind
        kinds[kind] = kinds.get(kind, 0) + 1
        if where is None:
            broken.append(reference)
    counts = ", ".join(f"{kind} {count}" for kind, count in sorted(kinds.items()))
    return "\n".join(
        [
            f"docstring references: {len(found)} ({counts})",
            *(f"  {reference.describe()}" for reference in broken),
        ]
    )


def test_every_docstring_reference_resolves() -> None:
    broken = unresolved()
    assert not broken, "\n".join(
        [
            f"{len(broken)} docstring references name nothing:",
            *(f"  {r.describe()}" for r in broken),
        ]
    )


def test_the_resolver_itself() -> None:
    """Absolute, relative, suffix and inherited forms; a stale module; ``:mod:`` of a function."""

    def ref(role: str, text: str, module: str = "service.core", cls: str | None = None) -> bool:
        return resolve(Reference(module, 1, role, text, cls)) is not None

    assert len(list(references())) > 300
    assert ref("mod", "service.core.geometry")
    assert ref("class", "~service.core.geometry.Geometry")
    assert ref("func", "service.core.smooth()")  # re-exported by the package
    assert ref("func", "the engine <service.core.smooth>")
    assert ref("class", "Geometry", module="service.core.geometry")
    assert ref("class", "numpy.ndarray") and ref("exc", "ValueError")
    assert ref("mod", ".geometry")  # suffix search
    assert ref("meth", "LocalQueue.submit", module="service.jobs")  # imported, then its class
    assert not ref("mod", "service.core.no_such_module")
    assert not ref("func", "service.core.geometry.no_such_function")
    assert not ref("mod", "service.core.smooth")  # a function, not a module
    assert not ref("func", "no_such_name_anywhere")


if __name__ == "__main__":
    sys.stdout.write(summary() + "\n")
