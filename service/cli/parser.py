"""The ``geosmooth`` argument parser: commands, their file options and the exit status table.

``smooth`` and ``submit`` are built in :mod:`service.cli.file_commands`, the shared pieces
in :mod:`service.cli.parser_base`. The smoothing options come from :mod:`service.cli.params`
(generated from the model); the format choices from the io registry; the exit statuses
from :mod:`service.exit_codes`.
Commands other than the one being run get a stub parser (name and one-line help), so that
``geosmooth --help`` loads neither pydantic nor numpy (``python -X importtime``).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Collection

from service.cli.file_commands import add_limits, add_smooth, add_submit
from service.cli.parser_base import HELP, Parser, epilog, formats, version, wrap
from service.exit_codes import SERVE_EXIT_CODES, SUBMIT_EXIT_CODES

__all__ = ["build_parser", "command_of", "version"]


def _add_info(sub: argparse._SubParsersAction[Parser]) -> None:
    inf = sub.add_parser(
        "info",
        help=HELP["info"],
        description=wrap(
            "Print, as JSON, what INPUT is (points, dimension, kind, faces, edges, bounding "
            "box, mean spacing) and the smoothing budgets it admits: phi(0), the valid ranges "
            "of tau and rms, the estimated noise level and the tau / rms the automatic rule "
            "would choose (report eq. 14; the same body as POST /v1/info). Neighbourhood, "
            "weight and fixed-point options change the analysis as they would change 'smooth'."
        ),
        epilog=epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    inf.add_argument(
        "input", metavar="INPUT", help="input file ('-' reads stdin; the format is sniffed)"
    )
    from service.cli.params import add_smoothing_options

    add_smoothing_options(inf)
    more = inf.add_argument_group("input details")
    more.add_argument(
        "--input-format", metavar=formats(), help="input format when the extension does not say"
    )
    more.add_argument(
        "--xyz-dims", type=int, metavar="D", help="XYZ input: the first D columns are coordinates"
    )
    more.add_argument(
        "--weld", action=argparse.BooleanOptionalAction, default=None,
        help="weld exactly coincident vertices first, as smooth does [default: the format's]",
    )  # fmt: skip
    more.add_argument("--compact", action="store_true", help="one line of JSON")
    add_limits(more)


def _add_serve(sub: argparse._SubParsersAction[Parser]) -> None:
    sv = sub.add_parser(
        "serve",
        help=HELP["serve"],
        description="Run the HTTP service (embedded job queue, no Redis needed).",
        epilog=epilog(SERVE_EXIT_CODES),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sv.add_argument(
        "--host", default=None, help="interface to bind [default: $GEOSMOOTH_HOST or 127.0.0.1]"
    )
    sv.add_argument(
        "--port", type=int, default=None, help="TCP port [default: $GEOSMOOTH_PORT or 8000]"
    )
    sv.add_argument(
        "--workers", type=int, default=None, help="solver worker processes [default: settings]"
    )
    sv.add_argument("--data-dir", default=None, help="job store directory [default: settings]")
    sv.add_argument(
        "--insecure-no-auth",
        action="store_true",
        help="serve a non-loopback address without API keys (anyone who reaches the port may "
        "submit, read and delete jobs) [default: $GEOSMOOTH_INSECURE_NO_AUTH or off]",
    )
    sv.add_argument(
        "--log-format",
        choices=("auto", "json", "console"),
        default=None,
        help="json: one JSON object per line; console: text; auto: one human line with the "
        "page's address on a terminal, JSON elsewhere [default: $GEOSMOOTH_LOG_FORMAT or auto]",
    )


def _add_worker(sub: argparse._SubParsersAction[Parser]) -> None:
    wk = sub.add_parser(
        "worker",
        help=HELP["worker"],
        description=wrap(
            "Run one RQ worker for GEOSMOOTH_QUEUE=rq (GEOSMOOTH_REDIS_URL, the blob store and "
            "the limits come from the same GEOSMOOTH_* settings as 'serve'). Options: "
            "--burst (exit when the queue is empty), --max-jobs N, --name NAME, --log-level L."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    wk.add_argument("worker_args", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)  # see main


def _add_completion(sub: argparse._SubParsersAction[Parser]) -> None:
    co = sub.add_parser(
        "completion",
        help=HELP["completion"],
        description=wrap(
            "Print a completion script for SHELL on stdout: commands, options, their choices "
            'and file names. bash: eval "$(geosmooth completion bash)" in ~/.bashrc; zsh: '
            "geosmooth completion zsh > a directory of $fpath, as _geosmooth."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    co.add_argument("shell", metavar="SHELL", choices=("bash", "zsh"), help="bash or zsh")


#: command -> builder of its full parser
_COMMANDS: dict[str, Callable[[argparse._SubParsersAction[Parser]], None]] = {
    "smooth": add_smooth,
    "info": _add_info,
    "serve": _add_serve,
    "submit": add_submit,
    "worker": _add_worker,
    "completion": _add_completion,
}


def command_of(args: Collection[str]) -> str | None:
    """The command named in ``args`` (the first argument that is not an option), if any."""
    first = next((a for a in args if not a.startswith("-")), None)
    return first if first in _COMMANDS else None


def build_parser(full: Collection[str] | None = None) -> argparse.ArgumentParser:
    """The ``geosmooth`` argument parser: smooth, info, serve, submit, worker and completion.

    Parameters
    ----------
    full : collection of str, optional
        Commands whose options are built; the others get a stub (name and help only, enough
        for ``geosmooth --help``). Default: all.
    """
    parser = Parser(
        prog="geosmooth",
        description=wrap(
            "Smooth triangle meshes, polylines / curve networks and point clouds in any "
            "dimension with a global deviation budget tau (KU Leuven report TW 451)."
        ),
        epilog=epilog(SUBMIT_EXIT_CODES, SERVE_EXIT_CODES),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"geosmooth {version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, add in _COMMANDS.items():
        if full is None or name in full:
            add(sub)
        else:
            sub.add_parser(name, help=HELP[name])
    return parser
