"""The summary of a finished ``smooth`` or ``submit`` run, on stderr.

It reads a :meth:`service.core.SmoothResult.report` dictionary (local, or a job's report) and
imports neither numpy nor the engine.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from service.cli.progress.display import ProgressDisplay
from service.cli.progress.display import fmt_g as _g

if TYPE_CHECKING:
    from service.core.params import SmoothingParams

__all__ = ["format_summary", "show_summary"]


def _timings(timings: Mapping[str, float]) -> str:
    stages = [
        f"{name} {float(sec):.3f}"
        for name, sec in timings.items()
        if name != "total" and isinstance(sec, int | float)
    ]
    return f" ({', '.join(stages)})" if stages else ""


def _noise_lines(report: Mapping[str, Any]) -> list[str]:
    """The noise estimate and how tau was chosen (automatic tau and GCV)."""
    out = []
    found = report.get("noise_found")
    sigma = report.get("sigma_estimate")
    if found is False:
        out.append("  noise: no noise found (sigma = 0).")
    elif sigma is not None:
        out.append(f"  noise: sigma = {_g(sigma, 4)} (estimated).")
    how = report.get("tau_how")
    if how:
        out.append(f"  tau: {how}.")
    if report.get("outlier_count"):
        what = {"flag": "flagged, kept in place", "drop": "dropped from the output",
                "pull": "pulled into their ring"}.get(report.get("outlier_mode") or "",
                                                      "treated as outliers")
        out.append(f"  outliers: {report['outlier_count']} points {what} "
                   f"({report.get('data_weights')} weights; indices in the report).")
    return out


def format_summary(
    report: Mapping[str, Any],
    *,
    source: str,
    target: str,
    wall_seconds: float,
    wall_label: str = "read, smooth, write",
    tolerance: float | None = None,
    details: Sequence[str] = (),
    notes: Sequence[str] = (),
) -> str:
    """One paragraph describing a finished run, for stderr.

    Parameters
    ----------
    report : mapping
        :meth:`service.core.SmoothResult.report` of the run.
    source, target : str
        Input and output file names as the user gave them.
    wall_seconds : float
        Time measured by the CLI for the whole run (start-up excluded).
    wall_label : str
        What ``wall_seconds`` covers (``"upload, queue, smooth, download"`` for ``submit``).
    tolerance : float, optional
        The relative tolerance xi the search used.
    details : sequence of str
        Facts about the input (``"16301 faces"``, ``"welded from 5096 vertices"``).
    notes : sequence of str
        What the reader repaired or ignored; one ``note:`` line each.

    Returns
    -------
    str
        Several lines, the last one without a trailing newline.
    """
    n_fixed = int(report.get("n_fixed") or 0)
    lines = [
        f"geosmooth: {source} -> {target}: {report.get('kind', 'geometry')}, "
        f"{report['n_points']} points in {report['dimension']}-D"
        + "".join(f", {d}" for d in details)
        + (f" ({n_fixed} fixed)" if n_fixed else "")
        + f"; laplacian {report['laplacian']}, weights {report['weights']}, "
        f"solver {report['solver']}."
    ]
    iters = int(report["iterations"])
    facts = int(report["factorizations"])
    search = (
        f"  lambda={_g(report['lambda'])} after {iters} iteration{'s' if iters != 1 else ''}"
        f" ({facts} factorization{'s' if facts != 1 else ''})"
    )
    if report.get("tau") is not None:
        state = "converged" if report.get("converged") else "NOT converged"
        tol = f", tolerance {tolerance:g}" if tolerance is not None else ""
        search += (
            f": phi={_g(report['phi'])} vs tau={_g(report['tau'])}"
            f" (relative error {_g(report.get('relative_error'), 2)}{tol}, {state})."
        )
    elif report.get("tau_rule") == "auto":
        search = "  not smoothed: the input is returned unchanged (see noise and tau below)."
    else:
        search += f": phi={_g(report['phi'])} (lambda given, no search)."
    if report.get("unchanged") == "copied":
        search = "  not smoothed: returned unchanged: input bytes copied (see noise and tau below)."
    elif report.get("unchanged") == "converted":
        search = "  not smoothed: converted unchanged (see noise and tau below)."
    lines.append(search)
    lines.extend(_noise_lines(report))
    lines.append(
        f"  displacement RMS {_g(report['rms_displacement'], 3)}, "
        f"max {_g(report['max_displacement'], 3)}"
        + (
            f"; volume scale {report['volume_scale']:.6f}"
            if report.get("volume_scale") is not None
            else ""
        )
        + "."
    )
    timings: Mapping[str, float] = report.get("timings") or {}
    total = timings.get("total")
    lines.append(
        f"  time {wall_seconds:.2f} s ({wall_label})"
        + (f", smoothing {float(total):.3f} s{_timings(timings)}" if total is not None else "")
        + "."
    )
    lines.extend(f"  note: {n}" for n in notes)
    warnings: Sequence[str] = report.get("warnings") or []
    lines.extend(f"  warning: {w}" for w in warnings)
    return "\n".join(lines)


def show_summary(
    display: ProgressDisplay,
    report: Mapping[str, Any],
    ns: argparse.Namespace,
    params: SmoothingParams,
    started: float,
    **extra: Any,
) -> None:
    """The summary of a finished ``smooth`` or ``submit`` run, below its progress lines.

    ``started`` is a :func:`time.perf_counter` reading; ``extra`` goes to
    :func:`format_summary` (``details``, ``notes``, ``wall_label``). Nothing with ``--quiet``.
    """
    if not display.enabled:
        return
    text = format_summary(
        report,
        source=ns.input,
        target=ns.output,
        wall_seconds=time.perf_counter() - started,
        tolerance=params.tolerance if params.lam is None else None,
        **extra,
    )
    display.note(text)
