"""Options of the commands that read and write files: ``smooth`` and ``submit``."""

from __future__ import annotations

import argparse
import os

from service.cli.parser_base import HELP, Parser, epilog, formats, wrap
from service.exit_codes import SUBMIT_EXIT_CODES

__all__ = ["add_smooth", "add_submit"]

#: Help of the writer options (``service.io.write_geometry``'s keyword arguments).
WRITER_HELP = {
    "normals": "normals of the input: recomputed from the smoothed geometry, or left out",
    "precision": "coordinates as the input stored them (type, or digits for text formats), or "
    "forced to float32 / float64",
}



def _exit_status(text: str) -> int:
    """``--exit-unchanged``: an exit status, 0 to 255."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= 255:
        raise argparse.ArgumentTypeError(f"must be an exit status 0..255, got {text!r}")
    return value

def add_result_options(parser: argparse.ArgumentParser, *, local: bool) -> None:
    """Where the result goes: -o, --output-format, --weld, --report, -q (``smooth``, ``submit``).

    ``--input-format`` / ``--output-format`` say which file each is about, on every command and
    surface (the HTTP API's ``input_format`` part and ``output_format`` query); ``--format`` is
    the former spelling of ``--output-format``, kept working (deprecated)."""
    files = parser.add_argument_group("files")
    where = "; a directory (ending in '/', or existing) for a batch" if local else ""
    files.add_argument(
        "-o", "--output", required=True, metavar="OUTPUT",
        help=f"output file ('-' writes stdout); its extension picks the format{where}",
    )  # fmt: skip
    files.add_argument(
        "--output-format", "--format", dest="format", metavar=formats(),
        help="output format when the OUTPUT extension does not say [default: the input's] "
        "(--format: former name, deprecated)",
    )  # fmt: skip
    files.add_argument(
        "--weld", action=argparse.BooleanOptionalAction, default=None,
        help="weld exactly coincident vertices before smoothing (meshes stored with split "
        "normals, e.g. STL exports); the output keeps the input's vertices [default: yes for "
        "STL and GLB; other formats when duplicate positions tie faces]",
    )  # fmt: skip
    what = "the run's diagnostics" if local else "the job's report"
    files.add_argument("--report", metavar="REPORT.json", help=f"write {what} as JSON")
    files.add_argument(
        "-q", "--quiet", action="store_true", help="print nothing on success (errors still go)"
    )
    if local:
        files.add_argument(
            "--progress", choices=("auto", "text", "json"), default="auto",
            help="the stages on stderr (reading, neighborhoods, analysis, search, postprocess, "
            "writing: a job's stage names) with progress and an estimate, updated every "
            "second on a terminal: text lines, or one JSON object per line; auto: text lines "
            "for an input of 1 MiB or more, else only the lambda search [default: auto]",
        )  # fmt: skip


def add_smooth(sub: argparse._SubParsersAction[Parser]) -> None:
    sm = sub.add_parser(
        "smooth",
        help=HELP["smooth"],
        description=wrap(
            "Smooth a mesh, polyline network or point cloud. The output keeps the "
            "input's vertex count, order and connectivity."
        ),
        epilog=epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sm.add_argument(
        "input", metavar="INPUT", nargs="+",
        help="input file ('-' reads stdin; the format is sniffed); several files or a quoted "
        "glob ('scans/*.laz', '**' recurses) make a batch written to -o DIR/",
    )  # fmt: skip
    from service.cli.output import writer_options
    from service.cli.params import add_smoothing_options

    add_smoothing_options(sm)
    add_result_options(sm, local=True)
    more = sm.add_argument_group("input and output details")
    more.add_argument(
        "--fixed", metavar="FILE",
        help="text file of 0-based point indices to keep fixed (bit-identical): separated by "
        "whitespace, commas or newlines; '#' starts a comment",
    )  # fmt: skip
    more.add_argument(
        "--in-crs", metavar="CRS",
        help="the CRS of a LAS/LAZ input that declares none (or a wrong one), an EPSG code, "
        "like PDAL's a_srs: recorded in the output, and the source of --crs",
    )  # fmt: skip
    more.add_argument(
        "--where", metavar="EXPR",
        help="smooth only the points EXPR selects, PDAL's 'where' grammar: 'Classification == "
        "2', 'Intensity > 100 and ReturnNumber == 1', and/or/not, parentheses; the others are "
        "held fixed (bit-identical) and anchor the smoothing",
    )  # fmt: skip
    more.add_argument(
        "--fix-classes", metavar="LIST",
        help="hold the points of these classes fixed, e.g. 6,9 (buildings, water)",
    )  # fmt: skip
    more.add_argument(
        "--input-format", metavar=formats(),
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
    add_limits(more)
    more.add_argument(
        "--time-limit", metavar="SECONDS",
        help="stop a file's run after SECONDS of CPU time, nothing written (exit 13) "
        "[default: 3600, the server's job time limit; 'none': no bound]",
    )  # fmt: skip
    more.add_argument(
        "--overwrite", action="store_true",
        help="allow an output that is the input itself (the same path, a symbolic or hard "
        "link): without it such an output is refused with exit status 2 (single files and "
        "batches alike), so a raw scan is never replaced by mistake",
    )  # fmt: skip
    more.add_argument(
        "--exit-unchanged", type=_exit_status, default=0, metavar="N",
        help="exit status when nothing was smoothed (the output is the input: copied, or "
        "converted to another format), so a batch can branch on it [default: 0]",
    )  # fmt: skip
    for name, (choices, default) in writer_options().items():
        more.add_argument(
            "--" + name.replace("_", "-"), dest=name, choices=choices,
            help=WRITER_HELP.get(name, "writer option") + f" [default: {default}]",
        )  # fmt: skip
    more.add_argument(
        "--crs", metavar="CRS",
        help="geographic input (GPX, GeoJSON) written to another format: easting/northing in "
        "this projected CRS, an EPSG code (32633, EPSG:32633) or 'utm' (the UTM zone of the "
        "data's centre) [default: metres east/north/up about the data's centre]",
    )  # fmt: skip
    _add_batch_options(sm)


def _add_batch_options(parser: argparse.ArgumentParser) -> None:
    """Several inputs to an output directory (:mod:`service.cli.batch`)."""
    batch = parser.add_argument_group("batches (several inputs, -o DIR/)")
    batch.add_argument(
        "--name", metavar="TEMPLATE", default=None,
        help="output file name in DIR: {stem} (input name without extension), {name} (input "
        "name), {ext} (output format's extension), {parent} (input's directory name) "
        "[default: {stem}.{ext}]",
    )  # fmt: skip
    batch.add_argument(
        "-j", "--jobs", type=int, default=1, metavar="N",
        help="files smoothed at once, each in its own process; 0: as many as the machine "
        "holds (cores, and available memory over one file's estimate); larger values are "
        "lowered to that [default: 1]",
    )  # fmt: skip


def add_submit(sub: argparse._SubParsersAction[Parser]) -> None:
    su = sub.add_parser(
        "submit",
        help=HELP["submit"],
        description=wrap(
            "Upload INPUT to a geosmooth server, follow the job and download the result. "
            "Ctrl-C cancels the job on the server."
        ),
        epilog=epilog(SUBMIT_EXIT_CODES),
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
    add_result_options(su, local=False)


def add_limits(group: argparse._ArgumentGroup) -> None:
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
