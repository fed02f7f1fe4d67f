"""The import graph of ``service/``, ``geosmooth/`` and the Python client: no circles, no arrow
pointing up (between packages and inside them), small folders.

The graph is built from the source with :mod:`ast`, nothing is imported: an edge ``a -> b`` for
every ``import`` of ``a`` that names module ``b`` (``from p import name`` names ``p.name`` when
that is a module, else ``p``), at module level, inside functions (lazy imports) and under
``if TYPE_CHECKING`` alike: a circle of lazy or type-only imports is still a circle to a reader.
Importing ``p.q`` also runs ``p/__init__``; those implicit edges are not counted (every module
would then sit in a circle with its package).

Layers, lowest first: ``service.core`` < ``service.io`` < ``service.workflows`` <
``service.jobs`` < ``service.api`` < ``service.cli``; a module imports its own layer or lower
ones only. The library facade ``geosmooth`` stands on ``service.core``, ``service.io`` and
``service.workflows`` and never imports the service layers above them; the Python client
(``geosmooth_client``) imports nothing of the server. ``service.settings`` (configuration) is
for jobs and above; ``service.exit_codes`` (the CLI's table of exit statuses) for the CLI and
the server it starts (``service.api.server``): error classes below carry their exit status as a
plain ``int``. Those two (and the modules of the ``service.settings`` package) import nothing
of the service but the core (the engine's bounds that settings default to) and themselves.

Inside a package (``service.core``, ``io``, ``jobs``, ``api``, ``cli``) the same rule holds
between its *rooms* (:data:`ROOMS`): a room is the first
name under the package (``service.core.search.roots`` is in room ``search``), the rooms are
listed on floors, lowest first, and a module imports modules of its own floor or lower ones
only. The package's ``__init__`` is its front door, above every room. A module in a room the
list does not know fails the test until it is placed (``../shared/ARCHITECTURE.md``).
In ``service.jobs`` the two backends (:data:`BACKENDS`) share the top floor and never reach each
other, not even through a third module, and of the modules outside them only the composition
point (:data:`JOBS_COMPOSITION`, ``make_queue``) imports a backend, and lazily: importing any
module of ``service.jobs`` runs ``service/jobs/__init__.py``, which must load no backend.

Failures list each offending import as ``a -> b (file:line)``. Run
``python -m tests.test_architecture`` for the counts, per package, and the arrows against the
order.
"""

from __future__ import annotations

import ast
import sys
from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = {
    "service": ROOT / "service",
    "geosmooth": ROOT / "geosmooth",
    "geosmooth_client": ROOT / "clients" / "python" / "geosmooth_client",
}
LAYERS = (
    "service.core",
    "service.io",
    "service.workflows",
    "service.jobs",
    "service.api",
    "service.cli",
)
FACADE_MAY_NOT = ("service.jobs", "service.api", "service.cli")
#: Top-level modules of ``service`` and the lowest layer that may import them.
LEAVES = {"service.settings": "service.jobs", "service.exit_codes": "service.api"}
#: Importers of ``service.exit_codes`` below the CLI (the ``serve`` process entry point).
EXIT_CODES_USERS = frozenset({"service.api.server"})
MAX_MODULES_PER_FOLDER = 16

#: The rooms of the engine in run order, lowest first, one room per floor
#: (``../shared/ARCHITECTURE.md``): bytes -> Geometry -> Plan -> operator -> target tau -> lambda
#: -> finish -> Report.
CORE_ROOMS: tuple[tuple[str, ...], ...] = tuple(
    (room,)
    for room in (
        "errors",
        "warnings",  # typed warnings (issue 38)
        "_arrays",
        "geometry",
        "frame",  # the internal frame (centre, scale, weight scale) and its conversions
        "progress",
        "run",  # clock, progress events, notes
        "params",  # flat SmoothingParams + typed views
        "linalg",
        "operator",
        "noise",  # sigma-hat, point fits, data weights
        "system",  # eqs. 4, 15, 17: deviation, elimination, displacement modes
        "search",  # tau target, lambda roots, automatic tau, budget, max-norm, windowed-sinc
        "finish",  # tangential step, volume, folds, clipping
        "checks",  # guards, spectrum, diagnostics
        "problem",  # Problem + frame conversions
        "plan",
        "report",  # the one Report model
        "result",
        "pipeline",  # smooth_one()
        "tiles",
        "info",
        "tau_range",
        "entry",  # the public smooth(): untiled or tiled
    )
)

#: The rooms of the job queue, lowest first. Rooms on one floor may import each other (the
#: circle test still applies). The runner sits below the backends: a backend's worker calls
#: the job function and hands it the tile map (the runner imports no backend).
JOBS_ROOMS: tuple[tuple[str, ...], ...] = (
    ("errors", "files", "forkserver", "metrics", "preload", "progress", "results"),  # no jobs
    ("queue",),  # the protocol and its records: JobQueue, JobRecord, JobSize, NewJob
    ("limits", "problems", "webhooks", "notify"),  # shared services
    ("admit",),  # what only the queue can check at submit
    ("base",),  # the queue methods both backends share, written once
    ("tiles",),  # the in-process tile map
    ("runner",),  # the job function: read -> smooth -> write (no backend import)
    ("config", "execute"),  # frozen configs (name the default runner); a run both share
    ("embedded", "distributed"),  # the backends (BACKENDS), never importing each other
)
#: The two backends of ``service.jobs``: neither reaches the other, directly or not.
BACKENDS = ("embedded", "distributed")
#: The one module outside the backends that imports them (``make_queue``, lazily).
JOBS_COMPOSITION = "service.jobs"

#: The rooms of the file layer, lowest first: errors and the byte-level helpers, the document
#: record, the shared parsing/welding/normals/frames code, the formats' readers and writers,
#: the registry that names them, then what works on whole documents (what a format holds,
#: read/write dispatch, the streamed coordinate readers).
IO_ROOMS: tuple[tuple[str, ...], ...] = (
    ("errors",),
    ("limits", "source", "atomic"),  # read limits, byte sources, the atomic file writer
    ("document",),  # GeometryDocument: the geometry plus what writes the file back
    ("_shared",),  # text, numbers, welding, normals, geographic frames, plain documents
    ("formats",),  # one room per format (readers, writers, content tests)
    ("registry",),  # FORMATS: names the formats' modules (imported on first use)
    ("holds",),  # what an output format holds of a document; the georeference of an output
    ("dispatch",),  # read_geometry / write_geometry / check_output
    ("stream",),  # coordinates only, streamed (the tiled path)
)

#: The rooms of the HTTP API, lowest first: errors and problem documents, the wire schemas and
#: their docs, the HTTP plumbing (middleware, limits, logs), the intake of uploads, the
#: dependencies, the routers, the app that mounts them, then the processes that run the app.
API_ROOMS: tuple[tuple[str, ...], ...] = (
    ("errors", "examples"),
    ("problems", "schemas"),  # RFC 9457 problem documents; the request/response models
    ("docs", "http"),  # OpenAPI response docs; middleware, auth, limits, logs, metrics
    ("results", "intake", "job_events"),  # result downloads; uploads and their checks; job logs
    ("deps",),  # the routers' Annotated dependencies
    ("routers",),
    ("app",),  # create_app(): mounts the routers and middleware
    ("server", "openapi_export"),  # serve(); the openapi.json export
)

#: The rooms of the command line, lowest first: errors, the options, output and progress, the
#: parsers, the commands (a batch runs the single-file ``smooth``), and the entry point that
#: imports a command's module when it runs (``main``), then ``python -m``.
CLI_ROOMS: tuple[tuple[str, ...], ...] = (
    ("errors",),  # CliError, failure(): exit status and one line of any failure
    ("params", "parser_base", "progress"),  # smoothing options; what every parser shares
    ("output",),  # output format, the file writer, the report
    ("file_commands",),  # the options of the commands that read and write files
    ("parser",),  # build_parser()
    ("smooth", "serve", "submit", "worker", "completion", "datasets"),  # one command each
    # (datasets: adjacent files as one set, called by the batch with its outcome and line)
    ("info", "batch"),  # info and batches reuse the smooth command's reader and run
    ("main",),  # parse, dispatch (importlib), report a failure
    ("__main__",),
)

#: Packages whose inside is ordered, with their rooms' floors.
ROOMS: dict[str, tuple[tuple[str, ...], ...]] = {
    "service.core": CORE_ROOMS,
    "service.io": IO_ROOMS,
    "service.jobs": JOBS_ROOMS,
    "service.api": API_ROOMS,
    "service.cli": CLI_ROOMS,
}


@dataclass(frozen=True)
class Edge:
    source: str
    target: str
    line: int

    def describe(self) -> str:
        """``a -> b (file:line)``, the form every failure uses."""
        return f"{self.source} -> {self.target} ({relative(self.source)}:{self.line})"


def relative(module: str) -> str:
    path = modules().get(module)
    return str(path.relative_to(ROOT)) if path else module


_MODULES: dict[str, Path] = {}


def modules() -> dict[str, Path]:
    """Dotted name -> file of every module of the three packages (``__init__`` = the package)."""
    if _MODULES:
        return _MODULES
    found: dict[str, Path] = {}
    for top, directory in PACKAGES.items():
        for path in sorted(directory.rglob("*.py")):
            if "build" in path.relative_to(directory).parts:
                continue
            parts = [top, *path.relative_to(directory).with_suffix("").parts]
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    _MODULES.update(found)
    return found


def _resolve(name: str, known: dict[str, Path]) -> str | None:
    while name and name not in known:
        name = name.rpartition(".")[0]
    return name or None


def _imports(module: str, path: Path, known: dict[str, Path]) -> Iterator[Edge]:
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        yield from _edges_of(node, module, path, known)


def _edges_of(node: ast.AST, module: str, path: Path, known: dict[str, Path]) -> Iterator[Edge]:
    """The edges of one ``import`` statement (none for other nodes)."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
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


def eager_imports(module: str) -> Iterator[Edge]:
    """The edges of ``module`` that run when it is imported: at module level (also inside
    ``if``/``try``/``with``), not inside a function or class, not under ``TYPE_CHECKING``."""
    known = modules()
    path = known[module]
    todo = list(ast.parse(path.read_text(encoding="utf-8"), str(path)).body)
    while todo:
        node = todo.pop(0)
        yield from _edges_of(node, module, path, known)
        if isinstance(node, ast.If):
            test = _dotted_name(node.test)
            todo += node.orelse if test.endswith("TYPE_CHECKING") else [*node.body, *node.orelse]
        elif isinstance(node, ast.Try):
            todo += [*node.body, *node.orelse, *node.finalbody]
            todo += [stmt for handler in node.handlers for stmt in handler.body]
        elif isinstance(node, ast.With):
            todo += node.body


def _dotted_name(node: ast.expr) -> str:
    if isinstance(node, ast.Attribute):
        return f"{_dotted_name(node.value)}.{node.attr}"
    return node.id if isinstance(node, ast.Name) else ""


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


# ---- between packages ---------------------------------------------------------------------


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
    top = source.split(".")[0]
    if top == "geosmooth_client" and target.split(".")[0] != top:
        return True  # the client is pure Python: nothing of the server
    # `python -m geosmooth` is the command: its entry point (only) may import the CLI
    facade = top == "geosmooth" and source != "geosmooth.__main__"
    if facade and target.startswith(FACADE_MAY_NOT):
        return True
    mine, theirs = leaf(source), leaf(target)
    if mine and target.startswith("service.") and there != 0 and theirs != mine:
        return True  # the leaves import only the core (e.g. the engine's bounds) and themselves
    if theirs and theirs != mine and source not in EXIT_CODES_USERS:
        lowest = layer(LEAVES[theirs])
        return facade or (here is not None and lowest is not None and here < lowest)
    return False


def leaf(module: str) -> str | None:
    """The leaf of :data:`LEAVES` that ``module`` is or lies in (``service.settings.http`` is in
    ``service.settings``), else ``None``."""
    return next((name for name in LEAVES if module == name or module.startswith(name + ".")), None)


def upward_edges(graph: dict[str, dict[str, Edge]]) -> list[Edge]:
    """Every edge that breaks the layer order, the facade rule or the leaves' rule."""
    return [
        edge
        for source, out in graph.items()
        for target, edge in out.items()
        if _breaks_rule(source, target)
    ]


# ---- inside packages ----------------------------------------------------------------------


def room(package: str, module: str) -> str | None:
    """The room of ``module`` inside ``package`` (``None``: the package's ``__init__`` itself,
    or a module outside the package)."""
    if not module.startswith(package + "."):
        return None
    return module[len(package) + 1 :].split(".")[0]


def floor(package: str, name: str) -> int | None:
    """The floor of room ``name`` in ``package``'s order (``None``: not placed)."""
    for position, rooms in enumerate(ROOMS[package]):
        if name in rooms:
            return position
    return None


def _floor_of(package: str, module: str) -> int | None:
    name = room(package, module)
    return None if name is None else floor(package, name)


def unplaced_modules(package: str) -> list[str]:
    """Modules of ``package`` whose room is not in its order."""
    return sorted(
        module
        for module in modules()
        if (name := room(package, module)) is not None and floor(package, name) is None
    )


def edges_against_the_order(graph: dict[str, dict[str, Edge]], package: str) -> list[Edge]:
    """Edges inside ``package`` from a room to a room on a higher floor (the package's
    ``__init__`` may import every room; unplaced rooms are reported by
    :func:`unplaced_modules`)."""
    found = []
    for source, out in graph.items():
        here = _floor_of(package, source)
        if here is None:
            continue
        for target, edge in out.items():
            there = _floor_of(package, target)
            if there is not None and there > here:
                found.append(edge)
    return found


def backend_imports_outside_composition(graph: dict[str, dict[str, Edge]]) -> list[Edge]:
    """Modules of ``service.jobs`` outside the backends that import a backend, other than
    :data:`JOBS_COMPOSITION`."""
    package = "service.jobs"
    return [
        edge
        for source, out in graph.items()
        if (source == package or source.startswith(package + "."))
        and source != JOBS_COMPOSITION
        and room(package, source) not in BACKENDS
        for target, edge in out.items()
        if room(package, target) in BACKENDS
    ]


def backends_loaded_by_the_packages() -> list[Edge]:
    """Imports of a backend that run whenever any module of ``service.jobs`` is imported: the
    eager imports of the ``__init__`` of ``service`` and ``service.jobs`` (Python runs them
    first), e.g. an RQ worker importing ``service.jobs.distributed.tasks`` would load the
    embedded backend through ``service/jobs/__init__.py``."""
    return [
        edge
        for package in ("service", "service.jobs")
        for edge in eager_imports(package)
        if room("service.jobs", edge.target) in BACKENDS
    ]


def backends_reaching_each_other(graph: dict[str, dict[str, Edge]]) -> list[list[Edge]]:
    """For every module of one backend that reaches the other backend through imports
    (directly or through other modules), the shortest such path."""
    package = "service.jobs"
    paths = []
    for source in sorted(graph):
        mine = room(package, source)
        if mine not in BACKENDS:
            continue
        parent: dict[str, Edge] = {}
        seen = {source}
        todo = deque([source])
        while todo:
            node = todo.popleft()
            there = room(package, node)
            if there in BACKENDS and there != mine:
                path = []
                while node != source:
                    path.append(parent[node])
                    node = parent[node].source
                paths.append(path[::-1])
                break
            for target, edge in graph[node].items():
                if target not in seen and target != JOBS_COMPOSITION:
                    seen.add(target)
                    parent[target] = edge
                    todo.append(target)
    return paths


def _path_text(path: list[Edge]) -> str:
    return "; ".join(edge.describe() for edge in path)


def _listing(title: str, items: Iterable[str]) -> str:
    found = list(items)
    return "\n".join([f"{len(found)} {title}:", *(f"  {item}" for item in found)])


# ---- sizes and summary --------------------------------------------------------------------


def folder_sizes() -> dict[str, int]:
    """Modules directly in each folder under ``service/`` (``__init__.py`` not counted)."""
    sizes = {}
    for directory in [PACKAGES["service"], *PACKAGES["service"].rglob("*")]:
        if directory.is_dir() and directory.name != "__pycache__":
            count = sum(1 for p in directory.glob("*.py") if p.name != "__init__.py")
            if count:
                sizes[str(directory.relative_to(ROOT))] = count
    return sizes


def _package_of(module: str) -> str:
    for name in (*LAYERS, "geosmooth_client", "geosmooth"):
        if module == name or module.startswith(name + "."):
            return name
    return "service (other)"


def summary() -> str:
    graph = import_graph()
    circles, upward, sizes = strongly_connected(graph), upward_edges(graph), folder_sizes()
    biggest = max(sizes.items(), key=lambda kv: kv[1])
    packages = [*LAYERS, "service (other)", "geosmooth", "geosmooth_client"]
    against = {package: edges_against_the_order(graph, package) for package in ROOMS}
    unplaced = {package: unplaced_modules(package) for package in ROOMS}
    rows = []
    for package in packages:
        members = [m for m in graph if _package_of(m) == package]
        inside = sum(1 for m in members for t in graph[m] if _package_of(t) == package)
        outside = sum(1 for m in members for t in graph[m] if _package_of(t) != package)
        order = f"{len(against[package]):>8}" if package in ROOMS else f"{'-':>8}"
        places = f"{len(unplaced[package]):>9}" if package in ROOMS else f"{'-':>9}"
        rows.append(f"  {package:<18} {len(members):>7} {inside:>7} {outside:>7} {order} {places}")
    backend_edges = backend_imports_outside_composition(graph)
    reaching = backends_reaching_each_other(graph)
    lines = [
        f"modules: {len(graph)}, import edges: {sum(len(out) for out in graph.values())}",
        f"import circles (SCCs > 1 module): {len(circles)}",
        *(f"  {' -> '.join(c)}" for c in circles),
        f"arrows up the layers (between packages): {len(upward)}",
        *(f"  {e.describe()}" for e in upward),
        "per package (edges inside / out; arrows against the rooms' order; modules in rooms"
        " not placed):",
        f"  {'package':<18} {'modules':>7} {'inside':>7} {'out':>7} {'against':>8} {'unplaced':>9}",
        *rows,
    ]
    for package in ROOMS:
        order = " < ".join("/".join(rooms) for rooms in ROOMS[package])
        lines += [
            f"{package}: rooms lowest first: {order}",
            f"  against the order: {len(against[package])}",
            *(f"    {e.describe()}" for e in against[package]),
            f"  modules in rooms not placed in the order: {len(unplaced[package])}",
            *(f"    {m} ({relative(m)})" for m in unplaced[package]),
        ]
    eager = backends_loaded_by_the_packages()
    lines += [
        f"service.jobs: backend imports not from {JOBS_COMPOSITION}: {len(backend_edges)}",
        *(f"    {e.describe()}" for e in backend_edges),
        f"service.jobs: backend modules reaching the other backend: {len(reaching)}",
        *(f"    {_path_text(p)}" for p in reaching),
        f"service.jobs: backend imports run by every import of a jobs module: {len(eager)}",
        *(f"    {e.describe()}" for e in eager),
        f"folders under service/: {len(sizes)}, largest {biggest[0]} with {biggest[1]} modules",
    ]
    return "\n".join(lines)


# ---- tests --------------------------------------------------------------------------------


def test_the_import_graph_has_no_circles() -> None:
    graph = import_graph()
    print(summary())
    assert len(graph) > 150  # the three packages were found
    assert strongly_connected(graph) == []


def test_no_import_points_up_the_layers() -> None:
    upward = upward_edges(import_graph())
    assert not upward, _listing("imports up the layers", map(Edge.describe, upward))


def test_every_module_of_an_ordered_package_sits_in_a_placed_room() -> None:
    """A new room of ``service.core``, ``io``, ``jobs``, ``api`` or ``cli`` is placed in
    :data:`ROOMS` (and in ``../shared/ARCHITECTURE.md``) before it is used: its floor says what
    it may import."""
    unplaced = [m for package in ROOMS for m in unplaced_modules(package)]
    title = "modules whose room is not placed: place the room in ROOMS (lowest first) or move it"
    assert not unplaced, _listing(title, (f"{m} ({relative(m)})" for m in unplaced))


@pytest.mark.parametrize("package", list(ROOMS))
def test_no_import_inside_a_package_points_up_its_floors(package: str) -> None:
    """Inside ``service.core`` the floors are the run order; inside ``io``, ``jobs``, ``api``
    and ``cli`` what each room does (:data:`ROOMS`)."""
    against = edges_against_the_order(import_graph(), package)
    title = f"imports up the floors of {package}"
    assert not against, _listing(title, map(Edge.describe, against))


def test_only_the_composition_point_imports_a_job_backend() -> None:
    found = backend_imports_outside_composition(import_graph())
    title = f"backend imports not from {JOBS_COMPOSITION}"
    assert not found, _listing(title, map(Edge.describe, found))


def test_the_two_job_backends_never_reach_each_other() -> None:
    """``embedded`` (SQLite, worker pool) and ``distributed`` (Redis, RQ) load none of each
    other's modules, not even through a shared module: an RQ worker never opens the SQLite
    store."""
    found = backends_reaching_each_other(import_graph())
    assert not found, _listing("one backend reaching the other", map(_path_text, found))


def test_importing_a_jobs_module_loads_no_backend() -> None:
    """The composition point imports the backends lazily (inside ``make_queue``), so that a
    process of one backend never loads the other through the packages' ``__init__``."""
    found = backends_loaded_by_the_packages()
    title = "backend imports run by every import of a jobs module (make them lazy)"
    assert not found, _listing(title, map(Edge.describe, found))


def test_the_graph_builder_sees_lazy_and_type_only_imports() -> None:
    """The counting rules themselves: a function-level import of the engine inside the API and a
    ``TYPE_CHECKING`` import inside the jobs are edges."""
    graph = import_graph()
    assert "service.core.info" in graph["service.api.intake.ingest"]  # inside describe_input
    assert "service.settings" in graph["service.jobs.notify"]  # under TYPE_CHECKING
    assert strongly_connected({"a": {"b": Edge("a", "b", 1)}, "b": {"a": Edge("b", "a", 1)}}) == [
        ["a", "b"]
    ]


def test_the_rooms_rules_themselves() -> None:
    """Rooms, floors and the backends' reach on a made-up graph."""
    assert room("service.core", "service.core.search.roots") == "search"
    assert room("service.core", "service.core") is None
    assert floor("service.core", "errors") == 0
    assert floor("service.core", "entry") == len(CORE_ROOMS) - 1
    assert floor("service.jobs", "embedded") == floor("service.jobs", "distributed")
    assert floor("service.core", "no-such-room") is None

    def below(package: str, lower: str, upper: str) -> bool:
        floors = floor(package, lower), floor(package, upper)
        return floors[0] is not None and floors[1] is not None and floors[0] < floors[1]

    assert below("service.io", "formats", "registry") and below("service.io", "holds", "dispatch")
    assert below("service.api", "schemas", "intake") and below("service.api", "routers", "app")
    assert below("service.cli", "smooth", "batch") and below("service.cli", "batch", "main")
    assert leaf("service.settings.http") == "service.settings" and leaf("service.io") is None
    assert not _breaks_rule("service.settings", "service.settings.http")
    assert _breaks_rule("service.settings.http", "service.io.registry")
    assert _breaks_rule("service.io.dispatch", "service.settings.jobs")

    def edge(a: str, b: str) -> tuple[str, Edge]:
        return b, Edge(a, b, 1)

    graph = {
        "service.core": dict([edge("service.core", "service.core.entry")]),
        "service.core.entry": dict([edge("service.core.entry", "service.core.geometry")]),
        "service.core.geometry": dict([edge("service.core.geometry", "service.core.params")]),
        "service.core.params": {},
        "service.jobs": dict([edge("service.jobs", "service.jobs.embedded.queue")]),
        "service.jobs.embedded.queue": dict(
            [edge("service.jobs.embedded.queue", "service.jobs.runner")]
        ),
        "service.jobs.runner": dict([edge("service.jobs.runner", "service.jobs.distributed.x")]),
        "service.jobs.distributed.x": {},
    }
    assert edges_against_the_order(graph, "service.core") == [
        Edge("service.core.geometry", "service.core.params", 1)
    ]
    assert edges_against_the_order(graph, "service.jobs") == [
        Edge("service.jobs.runner", "service.jobs.distributed.x", 1)
    ]
    assert backend_imports_outside_composition(graph) == [
        Edge("service.jobs.runner", "service.jobs.distributed.x", 1)
    ]
    assert backends_reaching_each_other(graph) == [
        [
            Edge("service.jobs.embedded.queue", "service.jobs.runner", 1),
            Edge("service.jobs.runner", "service.jobs.distributed.x", 1),
        ]
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

    classes: list[type] = [ConfigError]
    for module in (core_errors, io_errors, jobs_errors):
        found = [c for c in vars(module).values() if isinstance(c, type)]
        classes += [c for c in found if "exit_code" in vars(c)]
    assert len(classes) >= 6
    for cls in classes:
        code = getattr(cls, "exit_code", None)
        assert type(code) is int and code in EXIT_CODES, cls


if __name__ == "__main__":
    sys.stdout.write(summary() + "\n")
