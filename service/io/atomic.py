"""Writing a file the safe way: atomically for regular files, in place for devices.

Shared by the CLI (``geosmooth smooth -o``) and the library facade (``geosmooth.write``), so the
rules live in the io layer both stand on: a regular file is replaced by a fsynced temporary in
the same directory (a crash leaves the old file or the new one, never half of it; the old
file's permissions are kept); a device, FIFO, terminal or a path under ``/dev`` or ``/proc``
(``/dev/stdout`` links to whatever the shell opened) is written into, never replaced.
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["atomic_path", "in_place", "is_special", "real_target", "write_file"]


def is_special(target: str) -> bool:
    """Whether ``target`` exists and is not a regular file (after following links)."""
    try:
        return not stat.S_ISREG(os.stat(target).st_mode)
    except OSError:
        return False


def in_place(target: str) -> bool:
    """Whether to write into ``target`` rather than replace it: not a regular file, or a path
    under ``/dev`` or ``/proc``."""
    top = Path(os.path.abspath(target)).parts[1:2]
    return is_special(target) or top in (("dev",), ("proc",))


def real_target(target: str) -> Path:
    """The regular file to replace: ``target`` with every symbolic link resolved."""
    return Path(os.path.realpath(target))


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike[str]) -> Iterator[Path]:
    """A path to write the new content of ``target`` into: for a regular file, a temporary in
    the same directory that is fsynced and renamed over the target when the block ends without
    an error (and removed when it raises); for anything else (module docstring), the target.

    Raises
    ------
    OSError
        As the system reports it; a failed atomic write leaves no temporary file behind.
    """
    name = os.fspath(target)
    if in_place(name):  # a device, FIFO, terminal or /dev/stdout: never replace
        yield Path(name)
        return
    path = real_target(name)
    try:
        mode = stat.S_IMODE(path.stat().st_mode)  # keep an existing file's permissions
    except FileNotFoundError:
        mode = 0o666 & ~_umask()
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_file(target: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``target``: atomically for regular files, in place otherwise
    (:func:`atomic_path`).

    Raises
    ------
    OSError
        As the system reports it; a failed atomic write leaves no temporary file behind.
    """
    with atomic_path(target) as path, open(path, "wb") as fh:
        fh.write(data)
