"""The import graph of ``service/``, ``geosmooth/`` and the Python client: no circles, no arrow
pointing up, small folders.

The graph is built from the source with :mod:`ast`, nothing is imported: an edge ``a -> b`` for
every ``import`` of ``a`` that names module ``b`` (``from p import name`` names ``p.name`` when
that is a module, else ``p``), at module level, inside functions (lazy imports) and under
``if TYPE_CHECKING`` alike: a circle of lazy or type-only imports is still a circle to a reader.
Importing ``p.q`` also runs ``p/__init__``; those implicit edges are not counted (every module
would then sit in a circle with its package).

Layers, lowest first: ``service.core`` < ``service.io`` < ``service.jobs`` < ``service.api`` <
``service.cli``; a module imports its own layer or lower ones only. The library facade
``geosmooth`` stands on ``service.io`` and ``service.core`` and never imports the service
layers. ``service.settings`` (configuration) is for jobs and above; ``service.exit_codes`` (the
CLI's table of exit statuses) for the CLI and the server it starts (``service.api.server``):
error classes below carry their exit status as a plain ``int``. Those two import nothing of the
service but the core (the engine's bounds that settings default to).

Run ``python -m tests.test_architecture`` for the counts.
"""

from __future__ import annotations

import ast
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = {
    "service": ROOT / "service",
    "geosmooth": ROOT / "geosmooth",
    "geosmooth_client": ROOT / "clients" / "python" / "geosmooth_client",
}
LAYERS = (
    "service.core", "service.io", "service.workflows", "service.jobs", "service.api", "service.cli"
)
FACADE_MAY_NOT = ("service.jobs", "service.api", "service.cli")
#: Top-level modules of ``service`` and the lowest layer that may import them.
LEAVES = {"service.settings": "service.jobs", "service.exit_codes": "service.api"}
#: Importers of ``service.exit_codes`` below the CLI (the ``serve`` process entry point).
EXIT_CODES_USERS = frozenset({"service.api.server"})
MAX_MODULES_PER_FOLDER = 16


@dataclass(frozen=True)
class Edge:
    source: str
    target: str
    line: int


def modules() -> dict[str, Path]:
    """Dotted name -> file of every module of the three packages (``__init__`` = the package)."""
    found: dict[str, Path] = {}
    for top, directory in PACKAGES.items():
        for path in sorted(directory.rglob("*.py")):
            if "build" in path.relative_to(directory).parts:
                continue
            parts = [top, *path.relative_to(directory).with_suffix("").parts]
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    return found


def _resolve(name: str, known: dict[str, Path]) -> str | None:
    while name and name not in known:
        name = name.rpartition(".")[0]
    return name or None


def _imports(module: str, path: Path, known: dict[str, Path]) -> Iterator[Edge]:
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                target = _resolve(alias.name, known)
                if target:
                    yield Edge(module, target, node.lineno)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                origin = ".".join([*base, *([node.module] if node.module else [])])
            else:
                origin = node.module or ""
            for alias in node.names:
                full = f"{origin}.{alias.name}"
                target = full if full in known else _resolve(origin, known)
                if target:
                    yield Edge(module, target, node.lineno)


def import_graph() -> dict[str, dict[str, Edge]]:
    """Module -> {imported module -> first edge}."""
    known = modules()
    graph: dict[str, dict[str, Edge]] = {}
    for module, path in known.items():
        out: dict[str, Edge] = {}
        for edge in _imports(module, path, known):
            if edge.target != module:
                out.setdefault(edge.target, edge)
        graph[module] = out
    return graph


def strongly_connected(graph: dict[str, dict[str, Edge]]) -> list[list[str]]:
    """Tarjan's strongly connected components with more than one module (= import circles),
    iterative (no recursion limit)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    circles: list[list[str]] = []
    counter = 0
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(graph[root]))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(graph[child])))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    circles.append(sorted(component))
    return circles


def layer(module: str) -> int | None:
    """Position of ``module``'s layer in :data:`LAYERS` (``None``: not in a layer)."""
    for position, name in enumerate(LAYERS):
        if module == name or module.startswith(name + "."):
            return position
    return None


def _breaks_rule(source: str, target: str) -> bool:
    here, there = layer(source), layer(target)
    if here is not None and there is not None and there > here:
        return True  # up the layers
    facade = source.split(".")[0] == "geosmooth"
    if facade and target.startswith(FACADE_MAY_NOT):
        return True
    if source in LEAVES and target.startswith("service.") and there != 0:
        return True  # the leaves import only the core (e.g. the engine's bounds)
    if target in LEAVES and source not in EXIT_CODES_USERS:
        lowest = layer(LEAVES[target])
        return facade or (here is not None and lowest is not None and here < lowest)
    return False


def upward_edges(graph: dict[str, dict[str, Edge]]) -> list[Edge]:
    """Every edge that breaks the layer order, the facade rule or the leaves' rule."""
    return [
        edge
        for source, out in graph.items()
        for target, edge in out.items()
        if _breaks_rule(source, target)
    ]


def folder_sizes() -> dict[str, int]:
    """Modules directly in each folder under ``service/`` (``__init__.py`` not counted)."""
    sizes = {}
    for directory in [PACKAGES["service"], *PACKAGES["service"].rglob("*")]:
        if directory.is_dir() and directory.name != "__pycache__":
            count = sum(1 for p in directory.glob("*.py") if p.name != "__init__.py")
            if count:
                sizes[str(directory.relative_to(ROOT))] = count
    return sizes


def summary() -> str:
    graph = import_graph()
    circles, upward, sizes = strongly_connected(graph), upward_edges(graph), folder_sizes()
    biggest = max(sizes.items(), key=lambda kv: kv[1])
    lines = [
        f"modules: {len(graph)}, import edges: {sum(len(out) for out in graph.values())}",
        f"import circles (SCCs > 1 module): {len(circles)}",
        *(f"  {' -> '.join(c)}" for c in circles),
        f"upward arrows: {len(upward)}",
        *(f"  {e.source}:{e.line} -> {e.target}" for e in upward),
        f"folders under service/: {len(sizes)}, largest {biggest[0]} with {biggest[1]} modules",
    ]
    return "\n".join(lines)


def test_the_import_graph_has_no_circles() -> None:
    graph = import_graph()
    print(summary())
    assert len(graph) > 150  # the three packages were found
    assert strongly_connected(graph) == []


def test_no_import_points_up_the_layers() -> None:
    upward = upward_edges(import_graph())
    assert [f"{e.source}:{e.line} -> {e.target}" for e in upward] == []


def test_the_graph_builder_sees_lazy_and_type_only_imports() -> None:
    """The counting rules themselves: a function-level import of the engine inside the API and a
    ``TYPE_CHECKING`` import inside the jobs are edges."""
    graph = import_graph()
    assert "service.core.info" in graph["service.api.intake.ingest"]  # inside describe_input
    assert "service.settings" in graph["service.jobs.notify"]  # under TYPE_CHECKING
    assert strongly_connected({"a": {"b": Edge("a", "b", 1)}, "b": {"a": Edge("b", "a", 1)}}) == [
        ["a", "b"]
    ]


def test_no_folder_under_service_holds_more_than_16_modules() -> None:
    sizes = folder_sizes()
    assert {k: v for k, v in sizes.items() if v > MAX_MODULES_PER_FOLDER} == {}


def test_every_error_class_exit_code_is_a_documented_status() -> None:
    """Exit statuses are metadata of the error classes; the CLI's one table documents them."""
    from service.core import errors as core_errors
    from service.exit_codes import EXIT_CODES
    from service.io import errors as io_errors
    from service.jobs import errors as jobs_errors
    from service.settings import ConfigError

    classes = [ConfigError]
    for module in (core_errors, io_errors, jobs_errors):
        found = [c for c in vars(module).values() if isinstance(c, type)]
        classes += [c for c in found if "exit_code" in vars(c)]
    assert len(classes) >= 6
    for cls in classes:
        code = cls.exit_code
        assert type(code) is int and code in EXIT_CODES, cls


if __name__ == "__main__":
    sys.stdout.write(summary() + "\n")
