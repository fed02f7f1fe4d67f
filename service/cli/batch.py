"""``geosmooth smooth A B C -o DIR/``: a batch, one file at a time or ``-j N`` at once.

The entry point of ``smooth`` (:func:`run`): several inputs, a glob or an output directory make
a batch; one input to a file is :func:`service.cli.smooth.run`.

Each file is the same use case as a single run (:func:`service.cli.smooth.smooth_one`, i.e.
:func:`service.workflows.smooth_file.smooth_file`), in this process (``-j 1``) or in worker
processes (``spawn``: a fresh interpreter each, nothing inherited from a half-initialised
BLAS). Everything that does not depend on a file (parameters, formats, ``--crs``, the name
template, the output directory, clashing output names) is checked once, before any file is
read. A file's failure is its summary line; the batch goes on, and its exit status is the
worst of the files' (:data:`SEVERITY`).
"""

from __future__ import annotations

import argparse
import contextlib
import glob
import itertools
import os
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from service.cli.errors import CliError, os_reason
from service.exit_codes import (
    EXIT_GEOMETRY,
    EXIT_INPUT,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_LIMIT,
    EXIT_OK,
    EXIT_OUTPUT,
    EXIT_SHAPE,
    EXIT_SOLVER,
    EXIT_USAGE,
)

__all__ = [
    "SEVERITY",
    "FileOutcome",
    "expand_inputs",
    "is_batch",
    "job_bound",
    "output_names",
    "run",
    "run_batch",
    "worst",
]

#: Exit statuses from the mildest to the worst: a batch exits with the worst of its files'.
#: Problems of one file's data (shape check, geometry, solver, unreadable input) rank below
#: problems of the invocation or the machine (an option the file cannot take, an output that
#: cannot be written), an internal error above those, an interruption above everything.
SEVERITY: tuple[int, ...] = (
    EXIT_OK,
    EXIT_SHAPE,
    EXIT_GEOMETRY,
    EXIT_SOLVER,
    EXIT_LIMIT,
    EXIT_INPUT,
    EXIT_USAGE,
    EXIT_OUTPUT,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
)

DEFAULT_NAME = "{stem}.{ext}"
#: One file's memory estimate: a fixed part (interpreter, numpy/scipy, the engine's caches)
#: plus this many times the input file's size (the geometry, its neighbourhoods, the factor).
JOB_BASE_BYTES = 512 * 2**20
JOB_BYTES_PER_INPUT_BYTE = 150


@dataclass(frozen=True)
class FileOutcome:
    """What happened to one file of a batch."""

    input: str
    output: str
    code: int
    line: str  # the summary line after "geosmooth: "
    seconds: float
    report: dict[str, Any] | None = field(default=None, compare=False)


def worst(codes: Sequence[int]) -> int:
    """The worst exit status of ``codes`` by :data:`SEVERITY` (unknown ones just below 1)."""

    def rank(code: int) -> float:
        return SEVERITY.index(code) if code in SEVERITY else SEVERITY.index(EXIT_INTERNAL) - 0.5

    return max(codes, key=rank, default=EXIT_OK)


# --------------------------------------------------------------------------- inputs, names


def expand_inputs(patterns: Sequence[str]) -> list[str]:
    """The input files: each argument as given, or a glob (``*``, ``?``, ``[``, ``**``)
    expanded in sorted order when no file has that very name.

    Raises
    ------
    CliError
        Exit status 3 when a glob matches no file.
    """
    out: list[str] = []
    for pattern in patterns:
        if pattern == "-" or os.path.lexists(pattern) or not glob.has_magic(pattern):
            out.append(pattern)
            continue
        found = sorted(p for p in glob.glob(pattern, recursive=True) if os.path.isfile(p))
        if not found:
            raise CliError(f"{pattern}: no file matches", EXIT_INPUT)
        out.extend(found)
    return out


def is_batch(inputs: Sequence[str], output: str) -> bool:
    """Several inputs, or an output directory (``-o DIR/`` or an existing directory)."""
    return len(inputs) > 1 or output.endswith(os.sep) or os.path.isdir(output)


def _extension(source: str, out_fmt: str | None, in_fmt: str | None) -> str | None:
    """The output file's extension: the output format's, else the input's own (``None``: the
    input is in no format geosmooth reads)."""
    from service.io import FORMATS
    from service.io.registry import format_for_name, sniff

    if format_for_name(source) is not None:
        own = Path(source).suffix[1:].lower()
    elif in_fmt:
        own = FORMATS[in_fmt].extensions[0]
    else:
        own = None
        with contextlib.suppress(OSError), open(source, "rb") as fh:
            kind = sniff(fh.read(1 << 16), os.fstat(fh.fileno()).st_size)
            own = FORMATS[kind].extensions[0] if kind else None
    if own is None:
        return None
    return FORMATS[out_fmt].extensions[0] if out_fmt else own


def output_names(
    inputs: Sequence[str],
    directory: str,
    template: str,
    out_fmt: str | None,
    in_fmt: str | None,
    overwrite: bool = False,
) -> list[str]:
    """The output path of each input (``template`` rendered in ``directory``).

    Raises
    ------
    CliError
        Exit status 2: a bad template, two inputs with the same output, an output that is
        its own input (a link to it too) without ``overwrite``.
    """
    from service.cli.output import refuse_own_input

    names: list[str] = []
    for source in inputs:
        path = Path(source)
        ext = _extension(source, out_fmt, in_fmt)
        fields = {"stem": path.stem, "name": path.name, "parent": path.resolve().parent.name,
                  "ext": ext or path.suffix[1:] or "out"}  # fmt: skip
        try:
            name = template.format(**fields)
        except (KeyError, IndexError, ValueError) as exc:
            raise CliError(
                f"--name {template!r}: {exc!s} is not one of {{stem}}, {{name}}, {{ext}}, "
                "{parent}",
                EXIT_USAGE,
            ) from None
        if not name or "/" in name or name in (".", ".."):
            raise CliError(f"--name {template!r} gives {name!r} for {source}: not a file name",
                           EXIT_USAGE)  # fmt: skip
        names.append(os.path.join(directory, name))
    seen: dict[str, str] = {}
    for source, target in zip(inputs, names, strict=True):
        real = os.path.realpath(target)
        refuse_own_input(source, target, overwrite)
        if real in seen:
            raise CliError(f"{seen[real]} and {source} would both be written to {target}; "
                           "give --name with {parent}", EXIT_USAGE)  # fmt: skip
        seen[real] = source
    return names


# --------------------------------------------------------------------------- parallelism


def _available_memory() -> int | None:
    """Bytes this process may still use: MemAvailable, capped by a cgroup v2 limit."""
    values: list[int] = []
    with contextlib.suppress(OSError, ValueError), open("/proc/meminfo") as fh:
        for line in fh:
            if line.startswith("MemAvailable:"):
                values.append(int(line.split()[1]) * 1024)
    with contextlib.suppress(OSError, ValueError):
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        used = int(Path("/sys/fs/cgroup/memory.current").read_text())
        if limit != "max":
            values.append(max(0, int(limit) - used))
    return min(values) if values else None


def job_bound(inputs: Sequence[str]) -> tuple[int, str]:
    """How many files may be smoothed at once, and why: the cores this process may use and
    the available memory over one file's estimate (the largest input's)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    cores = cores or 1
    largest = max((os.path.getsize(p) for p in inputs if os.path.isfile(p)), default=0)
    per_job = JOB_BASE_BYTES + JOB_BYTES_PER_INPUT_BYTE * largest
    memory = _available_memory()
    by_memory = cores if memory is None else max(1, memory // per_job)
    why = f"{cores} core{'s' if cores != 1 else ''}"
    if memory is not None:
        why += f", {memory / 2**30:.1f} GB available at about {per_job / 2**30:.1f} GB per file"
    return max(1, min(cores, by_memory, len(inputs))), why


def _jobs(ns: argparse.Namespace, inputs: Sequence[str], err: TextIO) -> int:
    bound, why = job_bound(inputs)
    if ns.jobs == 0:
        return bound
    if ns.jobs > bound and ns.jobs > 1:
        if not ns.quiet:
            err.write(f"geosmooth: -j {ns.jobs} lowered to {bound} ({why})\n")
        return bound
    return ns.jobs


# --------------------------------------------------------------------------- one file


def smooth_one_file(ns: argparse.Namespace) -> FileOutcome:
    """Smooth ``ns.input`` into ``ns.output`` quietly; any failure becomes the outcome."""
    from service.cli.errors import failure
    from service.cli.params import threads
    from service.cli.progress import ProgressDisplay
    from service.cli.smooth import smooth_one

    started = time.perf_counter()
    try:
        if getattr(ns, "unknown_format", False):
            from service.io.registry import supported_text

            raise CliError(f"{ns.input}: unknown format; {supported_text()}", EXIT_INPUT)
        threads()
        _params, done = smooth_one(ns, ProgressDisplay(sys.stderr, enabled=False))
    except Exception as exc:
        code, line = failure(exc, ns)
        if line.startswith(f"{ns.input}: "):
            line = line[len(ns.input) + 2 :]
        return FileOutcome(ns.input, ns.output, code, f"{ns.input}: error (exit {code}): {line}",
                           time.perf_counter() - started)  # fmt: skip
    from service.cli.output import json_safe

    seconds = time.perf_counter() - started
    report = json_safe(done.result.report())
    return FileOutcome(ns.input, ns.output, EXIT_OK, _ok_line(ns, report, seconds), seconds,
                       report)  # fmt: skip


def _ok_line(ns: argparse.Namespace, report: dict[str, Any], seconds: float) -> str:
    what = f"{report.get('kind', 'geometry')}, {report['n_points']} points"
    if _unchanged(report):
        result = "returned unchanged (no noise found)"
    else:
        tau = f"tau={report['tau']:.4g}, " if report.get("tau") is not None else ""
        result = f"{tau}displacement RMS {report['rms_displacement']:.3g}"
    warnings = len(report.get("warnings") or [])
    more = f", {warnings} warning{'s' if warnings != 1 else ''}" if warnings else ""
    return f"{ns.input} -> {ns.output}: {what}; {result}{more}; {seconds:.2f} s"


# --------------------------------------------------------------------------- the batch


def _prepare(ns: argparse.Namespace, inputs: Sequence[str]) -> list[argparse.Namespace]:
    """Check what does not depend on a file; one namespace per file."""
    from service.cli.output import check_crs, check_format, check_writable
    from service.cli.params import params_from_args

    if "-" in inputs or ns.output == "-":
        raise CliError("a batch reads and writes files: '-' (stdin/stdout) takes one input",
                       EXIT_USAGE)  # fmt: skip
    if not (ns.output.endswith(os.sep) or os.path.isdir(ns.output)):
        raise CliError(f"{len(inputs)} inputs need an output directory: -o DIR/ (got "
                       f"{ns.output!r})", EXIT_USAGE)  # fmt: skip
    if ns.jobs < 0:
        raise CliError(f"-j: must be 0 (as many as the machine holds) or more, got {ns.jobs}",
                       EXIT_USAGE)  # fmt: skip
    if ns.fixed:
        raise CliError("--fixed names the points of one file: not with several inputs",
                       EXIT_USAGE)  # fmt: skip
    params_from_args(ns)
    check_format(ns.input_format, "--input-format")
    out_fmt = check_format(ns.format, "--output-format")
    check_crs(ns.crs)
    if ns.report:
        check_writable(ns.report, "report")
    names = output_names(inputs, ns.output, ns.name or DEFAULT_NAME, out_fmt, ns.input_format,
                         getattr(ns, "overwrite", False))  # fmt: skip
    try:
        os.makedirs(ns.output, exist_ok=True)
    except OSError as exc:
        raise CliError(f"cannot create the output directory {ns.output}: {os_reason(exc)}",
                       EXIT_OUTPUT) from exc  # fmt: skip
    return [replace_ns(ns, input=s, output=t, quiet=True, report=None,
                       unknown_format=ns.input_format is None and _extension(s, None, None) is None)
            for s, t in zip(inputs, names, strict=True)]  # fmt: skip


def replace_ns(ns: argparse.Namespace, **changes: Any) -> argparse.Namespace:
    """A copy of ``ns`` with ``changes``."""
    return argparse.Namespace(**{**vars(ns), **changes})


def _outcomes(each: Sequence[argparse.Namespace], jobs: int) -> Iterator[FileOutcome]:
    """The files' outcomes as they finish (in order with one job)."""
    if jobs <= 1:
        yield from map(smooth_one_file, each)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    pool = ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"))
    try:
        futures = [pool.submit(smooth_one_file, one) for one in each]
        for future in as_completed(futures):
            yield future.result()
    except BaseException:  # Ctrl-C (the workers get it too): do not wait for queued files
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()


def run(ns: argparse.Namespace, err: TextIO) -> int:
    """Run ``geosmooth smooth``: a batch, or the one file :func:`service.cli.smooth.run` smooths."""
    inputs = expand_inputs(ns.input)
    if is_batch(inputs, ns.output):
        return run_batch(ns, inputs, err)
    from service.cli.smooth import run as run_one

    ns.input = inputs[0]
    return run_one(ns, err)


def run_batch(ns: argparse.Namespace, inputs: Sequence[str], err: TextIO) -> int:
    """Run a batch; one summary line per file and a total on stderr; the worst status."""
    started = time.perf_counter()
    each = _prepare(ns, inputs)
    jobs = _jobs(ns, inputs, err)
    from service.cli.datasets import smooth_sets  # issue 43: adjacent clouds as one surface

    each, together = smooth_sets(each, FileOutcome, _ok_line)
    outcomes: list[FileOutcome] = []
    clock = BatchClock(inputs, started)
    for outcome in itertools.chain(together, _outcomes(each, jobs)):
        outcomes.append(outcome)
        if outcome.code != EXIT_OK or not ns.quiet:
            k, times = clock.done(outcome.input)
            err.write(f"geosmooth: {k} {outcome.line} ({times})\n")
            for warning in (outcome.report or {}).get("warnings") or []:
                err.write(f"  warning: {warning}\n")
            err.flush()
    code = worst([o.code for o in outcomes])
    failed = [o for o in outcomes if o.code != EXIT_OK]
    if failed or not ns.quiet:
        err.write(f"geosmooth: {_total(outcomes, time.perf_counter() - started, jobs, code)}\n")
    if ns.report:
        _write_report(ns, replace_ns(ns, input=list(inputs)), outcomes, code)
    return code


class BatchClock:
    """``[k/N]``, the time so far and the time left of a batch (issue 41): the time left is
    the time so far over the input bytes done times the bytes still to do (a file's cost
    grows with its size; files of one kind and density make it a fair proxy)."""

    def __init__(self, inputs: Sequence[str], started: float) -> None:
        self.sizes = {p: _size(p) for p in inputs}
        self.total = sum(self.sizes.values())
        self.started = started
        self.count = 0
        self.bytes_done = 0

    def done(self, source: str) -> tuple[str, str]:
        """``("[k/N]", "batch 12.3 s, ~40 s left")`` once the file ``source`` is finished."""
        self.count += 1
        self.bytes_done += self.sizes.get(source, 0)
        elapsed = time.perf_counter() - self.started
        n = len(self.sizes)
        text = f"batch {elapsed:.1f} s"
        if self.count < n and self.bytes_done > 0:
            left = elapsed * (self.total - self.bytes_done) / self.bytes_done
            text += f", ~{left:.0f} s left"
        return f"[{self.count}/{n}]", text


def _size(path: str) -> int:
    try:
        return max(os.path.getsize(path), 1)
    except OSError:
        return 1


def _unchanged(report: dict[str, Any] | None) -> bool:
    """The automatic rule found nothing to remove: the file was returned unchanged."""
    return report is not None and report.get("tau") is None and report.get("tau_rule") == "auto"


def _total(outcomes: Sequence[FileOutcome], seconds: float, jobs: int, code: int) -> str:
    failed = [o for o in outcomes if o.code != EXIT_OK]
    unchanged = sum(_unchanged(o.report) for o in outcomes if o.code == EXIT_OK)
    by_code: dict[int, int] = {}
    for o in failed:
        by_code[o.code] = by_code.get(o.code, 0) + 1
    how = ", ".join(f"{n} with exit {c}" for c, n in sorted(by_code.items()))
    return (f"{len(outcomes)} file{'s' if len(outcomes) != 1 else ''}: "
            f"{len(outcomes) - len(failed) - unchanged} smoothed, "
            + (f"{unchanged} returned unchanged, " if unchanged else "")
            + f"{len(failed)} failed" + (f" ({how})" if how else "")
            + f"; {seconds:.2f} s with -j {jobs}; exit status {code}")  # fmt: skip


def _write_report(
    ns: argparse.Namespace, whole: argparse.Namespace, outcomes: Sequence[FileOutcome], code: int
) -> None:
    from service.cli.output import write_json_report
    from service.cli.parser_base import version

    files = [{"input": o.input, "output": o.output, "exit_status": o.code, "summary": o.line,
              "wall_seconds": o.seconds, "report": o.report} for o in outcomes]  # fmt: skip
    write_json_report(ns.report, {"inputs": whole.input, "output_directory": ns.output,
                                  "exit_status": code, "geosmooth_version": version(),
                                  "files": files})  # fmt: skip
