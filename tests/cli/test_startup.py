"""``geosmooth --help`` loads neither pydantic nor numpy; a command's own help is complete."""

from __future__ import annotations

import subprocess
import sys

from service.cli.parser import build_parser, command_of

_PROBE = (
    "import sys, contextlib, io\n"
    "from service.cli import main\n"
    "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
    "    code = main(['--help'])\n"
    "assert code == 0 and 'smooth' in out.getvalue(), out.getvalue()\n"
    "heavy = sorted(m for m in ('numpy', 'pydantic', 'scipy') if m in sys.modules)\n"
    "print(','.join(heavy))\n"
)


def test_top_level_help_imports_no_numerics() -> None:
    done = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == ""


def test_stub_and_full_parsers_list_the_same_commands() -> None:
    stub, full = build_parser(full=()), build_parser()
    assert stub.format_help() == full.format_help()
    assert (
        "--tau"
        in build_parser(full=("smooth",))
        ._subparsers._group_actions[0]
        .choices[  # type: ignore[union-attr]
            "smooth"
        ]
        .format_help()
    )


def test_command_of() -> None:
    assert command_of(["--version"]) is None
    assert command_of(["smooth", "a.ply", "-o", "b.ply"]) == "smooth"
    assert command_of(["-h"]) is None
    assert command_of(["frobnicate"]) is None
