"""Terminal output of ``smooth`` and ``submit``: progress and the summary (stderr).

:mod:`.display` the lambda-search line (``submit``, a batch's files), :mod:`.stages` the stage
lines of a local ``smooth`` run (a ticker thread, ``--progress json``), :mod:`.summary` the
paragraph after a run. Nothing here imports numpy or the engine.
"""

from service.cli.progress.display import ProgressDisplay
from service.cli.progress.summary import format_summary, show_summary

__all__ = ["ProgressDisplay", "format_summary", "show_summary"]
