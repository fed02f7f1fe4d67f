"""Where the shared real data is: the ONE place every test, conftest and ``tests.golden`` asks.

The shared data (real meshes, scans, curves and clouds; ``MANIFEST.md`` gives each file's source
and licence) lives outside the repository. It is found, in this order:

1. ``$GEOSMOOTH_SHARED_DATA``, when set and not empty (used as given, even if it is wrong, so a
   mistyped path shows up as a skip naming it rather than silently reading other data);
2. ``shared/data`` beside the checkout (``../shared/data``: a fresh clone next to ``shared/``,
   which is how CI lays it out);
3. ``shared/data`` beside the checkout's parent (``../../shared/data``: a git worktree kept in a
   folder of worktrees next to ``shared/``).

Without either, :func:`shared_data_dir` still answers the expected place (``../shared/data``),
so that a check of a file there fails and the test is skipped with a message saying where it
looked. Plain module (no pytest import): ``python -m tests.golden.cases`` uses it too.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["ENV", "REPO", "shared_data_candidates", "shared_data_dir", "shared_data_missing"]

ENV = "GEOSMOOTH_SHARED_DATA"
REPO = Path(__file__).resolve().parents[1]
#: A file every copy of the shared data has (its index of sources and licences).
_MARKER = "MANIFEST.md"


def shared_data_candidates() -> list[Path]:
    """The places looked at, in order (only the variable's value when it is set)."""
    env = os.environ.get(ENV, "").strip()
    if env:
        return [Path(env).expanduser()]
    # Not resolved again: a checkout reached through a symlinked folder looks beside the link
    # as well as beside its target.
    here = Path(__file__).absolute().parents[1]
    places = [here.parent / "shared" / "data", REPO.parent / "shared" / "data"]
    places += [here.parent.parent / "shared" / "data", REPO.parent.parent / "shared" / "data"]
    return list(dict.fromkeys(places))


def shared_data_dir() -> Path:
    """The shared data directory: the first candidate holding the data, else the first one."""
    places = shared_data_candidates()
    for path in places:
        if (path / _MARKER).is_file() or (path / "bunny.ply").is_file():
            return path
    return places[0]


def shared_data_missing(*names: str) -> str | None:
    """Why the shared data (or one of ``names`` in it) is not there; None when it all is."""
    path = shared_data_dir()
    if not path.is_dir():
        looked = ", ".join(str(p) for p in shared_data_candidates())
        return f"shared test data not found (looked at {looked}; set {ENV} to its directory)"
    absent = [n for n in names if not (path / n).is_file()]
    if absent:
        return f"{', '.join(absent)} not in the shared data at {path}"
    return None
