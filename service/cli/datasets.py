"""The files of a batch that form one surface (issue 43): adjacent point clouds smoothed
together (:mod:`service.workflows.dataset`), each file's outcome a line of the batch."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

__all__ = ["smooth_sets"]

#: ``(input, output, code, line, seconds[, report]) -> outcome`` and ``(ns, report, seconds)
#: -> the batch's line``: the batch's own (:mod:`service.cli.batch` calls this room, not the
#: other way round).
Outcome = Callable[..., Any]
OkLine = Callable[[argparse.Namespace, dict[str, Any], float], str]


def smooth_sets(
    each: Sequence[argparse.Namespace], outcome: Outcome, ok_line: OkLine,
) -> tuple[list[argparse.Namespace], list[Any]]:  # fmt: skip
    """The files left to the per-file path and the outcomes of the sets smoothed here: point
    clouds in a streamable format (:func:`~service.workflows.dataset.streamed_cloud`) whose
    boxes touch (:func:`~service.workflows.dataset.adjacent_sets`, two files or more)."""
    from service.workflows.dataset import adjacent_sets, file_box, streamed_cloud

    cand = [(ns, fmt) for ns in each
            if not getattr(ns, "unknown_format", False)
            and (fmt := streamed_cloud(Path(ns.input), Path(ns.output), ns.input_format))]
    try:
        boxes = [file_box(Path(ns.input), fmt) for ns, fmt in cand]
    except Exception:  # an unreadable file: every file takes its own path and error line
        return list(each), []
    together = [g for g in adjacent_sets(boxes) if len(g) > 1]
    if not together:
        return list(each), []
    taken = {id(cand[i][0]) for g in together for i in g}
    outcomes = [o for g in together
                for o in _one_set([cand[i] for i in g], outcome, ok_line)]  # fmt: skip
    return [ns for ns in each if id(ns) not in taken], outcomes


def _one_set(
    members: Sequence[tuple[argparse.Namespace, str]], outcome: Outcome, ok_line: OkLine,
) -> list[Any]:  # fmt: skip
    from service.cli.errors import failure
    from service.cli.output import json_safe
    from service.cli.params import params_from_args
    from service.workflows.dataset import DatasetFile, smooth_dataset

    started = time.perf_counter()
    ns0 = members[0][0]
    files = [DatasetFile(Path(ns.input), Path(ns.output), fmt) for ns, fmt in members]
    try:
        done = smooth_dataset(files, params_from_args(ns0))
    except Exception as exc:
        code, line = failure(exc, ns0)
        seconds = time.perf_counter() - started
        return [outcome(ns.input, ns.output, code,
                            f"{ns.input}: error (exit {code}, smoothed as one set with "
                            f"{len(members) - 1} adjacent files): {line}", seconds)
                for ns, _ in members]  # fmt: skip
    seconds = time.perf_counter() - started
    out = []
    for (ns, _), f in zip(members, done, strict=True):
        assert f.result is not None
        report = json_safe(f.result.report())
        line = ok_line(ns, report, seconds) + f" (one set of {len(members)} adjacent files)"
        out.append(outcome(ns.input, ns.output, 0, line, seconds, report))
    return out
