"""``geosmooth --help`` loads neither pydantic nor numpy; a command's own help is complete."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

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


#: Libraries a small input does not use: the compiled kernels (numba from 50,000 points),
#: the GCV optimizer, the tiles, other formats' readers, the HTTP and queue stacks (the jobs'
#: progress estimate only with the stage lines).
NOT_FOR_A_SMALL_RUN = (
    "numba",
    "llvmlite",
    "open3d",
    "trimesh",
    "laspy",
    "lazrs",
    "ezdxf",
    "pyproj",
    "pye57",
    "structlog",
    "httpx",
    "fastapi",
    "starlette",
    "uvicorn",
    "rq",
    "redis",
    "scipy.optimize",
    "service.api",
    "service.core.tiles",
    "service.core.operator.kernels",
    "service.jobs",
)

_SMALL_RUN = (
    "import sys\n"
    "import numpy as np\n"
    "t = np.linspace(0, 6 * np.pi, 200)\n"
    "rng = np.random.default_rng(0)\n"
    "P = np.c_[np.cos(t), np.sin(t), 0.1 * t] + 0.01 * rng.standard_normal((200, 3))\n"
    "np.savetxt(sys.argv[1], P)\n"
    "from service.cli import main\n"
    "code = main(['smooth', '-q', sys.argv[1], '-o', sys.argv[2]])\n"
    "assert code == 0, code\n"
    "print(' '.join(sorted(sys.modules)))\n"
)


def test_a_small_smooth_run_imports_only_what_it_uses(tmp_path: Path) -> None:
    """200 points through ``smooth`` (default parameters: noise estimate, data weights,
    Delaunay neighbourhoods, CHOLMOD): none of :data:`NOT_FOR_A_SMALL_RUN` is imported."""
    done = subprocess.run(
        [sys.executable, "-c", _SMALL_RUN, tmp_path / "helix.xyz", tmp_path / "out.xyz"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    loaded = set(done.stdout.split())
    assert "service.core.pipeline" in loaded and "numpy" in loaded  # the run did run
    found = [m for m in NOT_FOR_A_SMALL_RUN if m in loaded or any(
        name.startswith(m + ".") for name in loaded)]  # fmt: skip
    assert found == []
    assert (tmp_path / "out.xyz").stat().st_size > 0
