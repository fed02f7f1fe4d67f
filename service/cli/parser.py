"""The ``geosmooth`` argument parser: commands, their file options and the exit status table.

The smoothing options come from :mod:`service.cli.params` (generated from the model); the
format choices from the io registry; the exit statuses from :mod:`service.exit_codes`.
Commands other than the one being run get a stub parser (name and one-line help), so that
``geosmooth --help`` loads neither pydantic nor numpy (``python -X importtime``).
"""

from __future__ import annotations

import argparse
import os
import textwrap
from collections.abc import Callable, Collection, Mapping
from typing import NoReturn

from service.cli.errors import CliError
from service.exit_codes import EXIT_CODES, EXIT_USAGE, SERVE_EXIT_CODES, SUBMIT_EXIT_CODES

__all__ = ["build_parser", "command_of", "version"]

_EXAMPLES = (
    "geosmooth smooth bunny.ply -o bunny-smooth.ply --tau 2e-4 --report report.json",
    "geosmooth smooth track.obj -o track-smooth.obj --rms 3 --fix-boundary",
    "geosmooth info scan.xyz        # noise estimate, valid tau / rms ranges",
    "geosmooth serve --port 8000",
    "geosmooth submit bunny.ply --server http://127.0.0.1:8000 -o out.ply --tau 2e-4",
)


#: One-line help of each command (shown by ``geosmooth --help``).
_HELP = {
    "smooth": "smooth a file",
    "info": "describe a file and the smoothing budgets it admits (nothing is smoothed)",
    "serve": "run the HTTP service",
    "submit": "smooth a file on a running geosmooth server",
    "worker": "run a worker of the distributed (Redis + RQ) job queue",
}


#: Help of the writer options (``service.io.write_geometry``'s keyword arguments).
_WRITER_HELP = {
    "normals": "normals of the input: recomputed from the smoothed geometry, or left out",
    "precision": "coordinates as the input stored them (type, or digits for text formats), or "
    "forced to float32 / float64",
}


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line (no usage block) and do not exit."""

    def error(self, message: str) -> NoReturn:
        raise CliError(f"{message} (see '{self.prog} --help')", EXIT_USAGE)


def version() -> str:
    """The installed geosmooth version (``unknown`` in an uninstalled source tree)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as dist_version

    try:
        return dist_version("geosmooth")
    except PackageNotFoundError:
        return "unknown"


def _wrap(text: str) -> str:
    return textwrap.fill(text, 78)


def _epilog(*extra: Mapping[int, str]) -> str:
    table = dict(EXIT_CODES)
    for more in extra:
        for code, text in more.items():
            table[code] = f"{table[code]}; {text}" if code in table else text
    codes = "\n".join(
        textwrap.fill(text, 78, initial_indent=f"  {code:>3}  ", subsequent_indent=" " * 7)
        for code, text in sorted(table.items())
    )
    examples = "\n".join(f"  {line}" for line in _EXAMPLES)
    return (
        f"examples:\n{examples}\n\nexit status:\n{codes}\n\n"
        "Errors are one line on stderr; set GEOSMOOTH_DEBUG=1 for a traceback."
    )


def _formats() -> str:
    from service.io import FORMATS

    return "{" + ",".join(FORMATS) + "}"


def _add_result_options(parser: argparse.ArgumentParser, *, local: bool) -> None:
    """Where the result goes: -o, --output-format, --weld, --report, -q (``smooth``, ``submit``).

    ``--input-format`` / ``--output-format`` say which file each is about, on every command and
    surface (the HTTP API's ``input_format`` part and ``output_format`` query); ``--format`` is
    the former spelling of ``--output-format``, kept working (deprecated)."""
    files = parser.add_argument_group("files")
    files.add_argument(
        "-o", "--output", required=True, metavar="OUTPUT",
        help="output file ('-' writes stdout); its extension picks the format",
    )  # fmt: skip
    files.add_argument(
        "--output-format", "--format", dest="format", metavar=_formats(),
        help="output format when the OUTPUT extension does not say [default: the input's] "
        "(--format: former name, deprecated)",
    )  # fmt: skip
    files.add_argument(
        "--weld", action=argparse.BooleanOptionalAction, default=None,
        help="weld exactly coincident vertices before smoothing (meshes stored with split "
        "normals, e.g. STL exports); the output keeps the input's vertices [default: yes for "
        "STL and GLB, no for other formats]",
    )  # fmt: skip
    what = "the run's diagnostics" if local else "the job's report"
    files.add_argument("--report", metavar="REPORT.json", help=f"write {what} as JSON")
    files.add_argument(
        "-q", "--quiet", action="store_true", help="print nothing on success (errors still go)"
    )


def _add_smooth(sub: argparse._SubParsersAction[_Parser]) -> None:
    sm = sub.add_parser(
        "smooth",
        help=_HELP["smooth"],
        description=_wrap(
            "Smooth a mesh, polyline network or point cloud. The output keeps the "
            "input's vertex count, order and connectivity."
        ),
        epilog=_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sm.add_argument(
        "input", metavar="INPUT", help="input file ('-' reads stdin; the format is sniffed)"
    )
    from service.cli.output import writer_options
    from service.cli.params import add_smoothing_options

    add_smoothing_options(sm)
    _add_result_options(sm, local=True)
    more = sm.add_argument_group("input and output details")
    more.add_argument(
        "--fixed", metavar="FILE",
        help="text file of 0-based point indices to keep fixed (bit-identical): separated by "
        "whitespace, commas or newlines; '#' starts a comment",
    )  # fmt: skip
    more.add_argument(
        "--input-format", metavar=_formats(),
        help="input format when the INPUT extension does not say",
    )  # fmt: skip
    more.add_argument(
        "--xyz-dims", type=int, metavar="D",
        help="XYZ input: the first D columns are coordinates (any dimension) [default: 2 for "
        "two columns, else 3; other columns are ignored]",
    )  # fmt: skip
    more.add_argument(
        "--ascii", action=argparse.BooleanOptionalAction, default=None,
        help="PLY output: ASCII (--ascii) or binary little-endian (--no-ascii) [default: the "
        "input's encoding for PLY input, else binary]",
    )  # fmt: skip
    _add_limits(more)
    for name, (choices, default) in writer_options().items():
        more.add_argument(
            "--" + name.replace("_", "-"), dest=name, choices=choices,
            help=_WRITER_HELP.get(name, "writer option") + f" [default: {default}]",
        )  # fmt: skip


def _add_info(sub: argparse._SubParsersAction[_Parser]) -> None:
    inf = sub.add_parser(
        "info",
        help=_HELP["info"],
        description=_wrap(
            "Print, as JSON, what INPUT is (points, dimension, kind, faces, edges, bounding "
            "box, mean spacing) and the smoothing budgets it admits: phi(0), the valid ranges "
            "of tau and rms, the estimated noise level and the tau / rms the automatic rule "
            "would choose (report eq. 14; the same body as POST /v1/info). Neighbourhood, "
            "weight and fixed-point options change the analysis as they would change 'smooth'."
        ),
        epilog=_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    inf.add_argument(
        "input", metavar="INPUT", help="input file ('-' reads stdin; the format is sniffed)"
    )
    from service.cli.params import add_smoothing_options

    add_smoothing_options(inf)
    more = inf.add_argument_group("input details")
    more.add_argument(
        "--input-format", metavar=_formats(), help="input format when the extension does not say"
    )
    more.add_argument(
        "--xyz-dims", type=int, metavar="D", help="XYZ input: the first D columns are coordinates"
    )
    more.add_argument(
        "--weld", action=argparse.BooleanOptionalAction, default=None,
        help="weld exactly coincident vertices first, as smooth does [default: the format's]",
    )  # fmt: skip
    more.add_argument("--compact", action="store_true", help="one line of JSON")
    _add_limits(more)


def _add_limits(group: argparse._ArgumentGroup) -> None:
    """Reader limits (``service.io.limits``), on every path of the command (streamed too)."""
    group.add_argument(
        "--max-points", metavar="N",
        help="refuse an input that holds or declares more than N points, before reading it "
        "[default: 1000000000; 'none': no bound]",
    )  # fmt: skip
    group.add_argument(
        "--max-memory", metavar="BYTES",
        help="refuse an input whose reading is estimated (before allocating) to need more "
        "than BYTES, e.g. 8G or 512M [default: 3/4 of the machine's memory; 'none': no bound]",
    )  # fmt: skip


def _add_serve(sub: argparse._SubParsersAction[_Parser]) -> None:
    sv = sub.add_parser(
        "serve",
        help=_HELP["serve"],
        description="Run the HTTP service (embedded job queue, no Redis needed).",
        epilog=_epilog(SERVE_EXIT_CODES),
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


def _add_submit(sub: argparse._SubParsersAction[_Parser]) -> None:
    su = sub.add_parser(
        "submit",
        help=_HELP["submit"],
        description=_wrap(
            "Upload INPUT to a geosmooth server, follow the job and download the result. "
            "Ctrl-C cancels the job on the server."
        ),
        epilog=_epilog(SUBMIT_EXIT_CODES),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    su.add_argument("input", metavar="INPUT", help="input file")
    su.add_argument("--server", required=True, metavar="URL", help="e.g. http://127.0.0.1:8000")
    su.add_argument(
        "--api-key", metavar="KEY", default=os.environ.get("GEOSMOOTH_API_KEY"),
        help="API key of the server [default: $GEOSMOOTH_API_KEY]",
    )  # fmt: skip
    from service.cli.params import add_smoothing_options

    add_smoothing_options(su)
    _add_result_options(su, local=False)


def _add_worker(sub: argparse._SubParsersAction[_Parser]) -> None:
    wk = sub.add_parser(
        "worker",
        help=_HELP["worker"],
        description=_wrap(
            "Run one RQ worker for GEOSMOOTH_QUEUE=rq (GEOSMOOTH_REDIS_URL, the blob store and "
            "the limits come from the same GEOSMOOTH_* settings as 'serve'). Options: "
            "--burst (exit when the queue is empty), --max-jobs N, --name NAME, --log-level L."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    wk.add_argument("worker_args", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)  # see main


#: command -> builder of its full parser
_COMMANDS: dict[str, Callable[[argparse._SubParsersAction[_Parser]], None]] = {
    "smooth": _add_smooth,
    "info": _add_info,
    "serve": _add_serve,
    "submit": _add_submit,
    "worker": _add_worker,
}


def command_of(args: Collection[str]) -> str | None:
    """The command named in ``args`` (the first argument that is not an option), if any."""
    first = next((a for a in args if not a.startswith("-")), None)
    return first if first in _COMMANDS else None


def build_parser(full: Collection[str] | None = None) -> argparse.ArgumentParser:
    """The ``geosmooth`` argument parser: smooth, info, serve, submit and worker.

    Parameters
    ----------
    full : collection of str, optional
        Commands whose options are built; the others get a stub (name and help only, enough
        for ``geosmooth --help``). Default: all.
    """
    parser = _Parser(
        prog="geosmooth",
        description=_wrap(
            "Smooth triangle meshes, polylines / curve networks and point clouds in any "
            "dimension with a global deviation budget tau (KU Leuven report TW 451)."
        ),
        epilog=_epilog(SUBMIT_EXIT_CODES, SERVE_EXIT_CODES),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"geosmooth {version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, add in _COMMANDS.items():
        if full is None or name in full:
            add(sub)
        else:
            sub.add_parser(name, help=_HELP[name])
    return parser
