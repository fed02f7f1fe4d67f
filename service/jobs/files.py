"""File layout of the job store and durable (fsynced, atomic) writes.

::

    data_dir/
      jobs.sqlite3            metadata (see service.jobs.embedded.store)
      jobs/<id>/input.<fmt>   the uploaded file, fsynced before submit returns
      jobs/<id>/result.npy    smoothed points, shape (n, s), same order as the input geometry
      jobs/<id>/result.<fmt>  the smoothed document written back in the input's format
      jobs/<id>/report.json   SmoothResult.report() (read by ``get``: not kept in the row)
"""

from __future__ import annotations

import errno
import json
import os
import re
import shutil
import tempfile
import time
from pathlib import Path

__all__ = [
    "JobFiles",
    "is_job_id",
    "move_durable",
    "probe_directory",
    "result_name",
    "sole_user",
    "write_durable",
]

_JOB_ID = re.compile(r"^[0-9a-f]{32}$")
_FMT = re.compile(r"^[a-z0-9]{1,16}$")


_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


def result_name(filename: str | None, default: str) -> str:
    """``<stem>.smoothed`` for a download, from the uploaded name (only safe characters kept)."""
    base = (filename or "").replace("\\", "/").rsplit("/", 1)[-1]
    stem = _UNSAFE.sub("_", base.rsplit(".", 1)[0]).strip("._")[:100]
    return f"{stem or default}.smoothed"


def is_job_id(job_id: object) -> bool:
    """Whether ``job_id`` has the shape of a job id (guards every path built from it)."""
    return isinstance(job_id, str) and bool(_JOB_ID.match(job_id))


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_durable(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically: temp file, fsync, rename, fsync the directory.

    Parameters
    ----------
    path : Path
        Destination; its directory must exist.
    data : bytes
        Content.
    """
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)  # e.g. ENOSPC half way: no stray temp file
        raise
    _fsync_dir(path.parent)


def move_durable(source: Path, path: Path) -> None:
    """Move ``source`` to ``path`` durably: a rename on the same file system, else a copy to a
    temp file next to ``path`` (fsync, rename, fsync the directory) and the source removed."""
    try:
        os.replace(source, path)
    except OSError as exc:
        if exc.errno != errno.EXDEV:
            raise
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        try:
            with open(source, "rb") as src, open(tmp, "wb") as dst:
                shutil.copyfileobj(src, dst, 1024 * 1024)
                dst.flush()
                os.fsync(dst.fileno())
            os.replace(tmp, path)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
        source.unlink(missing_ok=True)
    else:
        with open(path, "rb") as fh:
            os.fsync(fh.fileno())
    _fsync_dir(path.parent)


class JobFiles:
    """Paths of one data directory's job files.

    Parameters
    ----------
    data_dir : Path
        Root of the job store.
    """

    def __init__(self, data_dir: Path) -> None:
        self.root = Path(data_dir) / "jobs"
        self.root.mkdir(parents=True, exist_ok=True)

    def dir(self, job_id: str) -> Path:
        """Directory of one job (``ValueError`` for anything that is not a job id)."""
        if not is_job_id(job_id):
            raise ValueError(f"not a job id: {job_id!r}")
        return self.root / job_id

    def input(self, job_id: str, fmt: str) -> Path:
        """The stored input file."""
        if not _FMT.match(fmt):
            raise ValueError(f"not a format name: {fmt!r}")
        return self.dir(job_id) / f"input.{fmt}"

    def result_points(self, job_id: str) -> Path:
        """Smoothed points as ``.npy``."""
        return self.dir(job_id) / "result.npy"

    def result_file(self, job_id: str, fmt: str) -> Path:
        """The smoothed document in the input's format."""
        if not _FMT.match(fmt):
            raise ValueError(f"not a format name: {fmt!r}")
        return self.dir(job_id) / f"result.{fmt}"

    def report(self, job_id: str) -> Path:
        """``SmoothResult.report()`` as JSON."""
        return self.dir(job_id) / "report.json"

    def create(self, job_id: str, fmt: str, data: bytes | Path) -> int:
        """Create the job directory and store its input durably; returns its size in bytes.

        ``data`` is the content, or a spooled file that is moved (or copied, across file
        systems) into the store.
        """
        path = self.input(job_id, fmt)
        path.parent.mkdir()
        _fsync_dir(self.root)
        if isinstance(data, Path):
            move_durable(data, path)
        else:
            write_durable(path, data)
        return path.stat().st_size

    def legacy_weld(self, job_id: str) -> bool:
        """Whether a job of a version-0 data dir had ``weld`` in its ``options.json``.

        The file is removed (the flag lives in the job's row from version 1 on).
        """
        path = self.dir(job_id) / "options.json"
        try:
            weld = bool(json.loads(path.read_text()).get("weld", False))
        except (OSError, ValueError, AttributeError):
            return False
        path.unlink(missing_ok=True)
        return weld

    def stray_temporaries(self, min_age: float) -> list[Path]:
        """Temporary files of interrupted durable writes (``.<name>.<pid>.tmp``), older than
        ``min_age`` seconds."""
        now, out = time.time(), []
        for tmp in self.root.glob("*/.*.tmp"):
            try:
                if now - tmp.stat().st_mtime >= min_age:
                    out.append(tmp)
            except FileNotFoundError:
                continue
        return out

    def remove(self, job_id: str) -> None:
        """Delete a job's directory (no error if it is gone)."""
        shutil.rmtree(self.dir(job_id), ignore_errors=True)

    @property
    def quarantine_dir(self) -> Path:
        """Where job directories without a record go (``data_dir/quarantine``)."""
        return self.root.parent / "quarantine"

    def quarantine(self, job_id: str) -> Path | None:
        """Move a job directory into :attr:`quarantine_dir` (never deleted: its record may be
        lost with a database, its result is still someone's); its new path (``None``: gone)."""
        self.quarantine_dir.mkdir(parents=True, exist_ok=True)
        dest = self.quarantine_dir / job_id
        if dest.exists():
            dest = self.quarantine_dir / f"{job_id}.{int(time.time() * 1000)}"
        try:
            os.rename(self.dir(job_id), dest)
        except FileNotFoundError:
            return None
        return dest

    def orphans(self, known: set[str], min_age: float) -> list[str]:
        """Job directories without a record, older than ``min_age`` seconds.

        They are left by a crash between writing the input and committing the record (or
        between deleting a record and its files).
        """
        now = time.time()
        out = []
        for entry in self.root.iterdir():
            if is_job_id(entry.name) and entry.name not in known:
                try:
                    age = now - entry.stat().st_mtime
                except FileNotFoundError:
                    continue
                if age >= min_age:
                    out.append(entry.name)
        return out


# -- directories in use: health and who else uses one -------------------------------------


def probe_directory(path: Path, min_free: int) -> str:
    """``"ok"``, ``"full"`` (less than ``min_free`` bytes or ENOSPC), ``"read-only"`` or
    ``"unavailable"``."""
    try:
        st = os.statvfs(path)
        fd, name = tempfile.mkstemp(prefix=".probe-", dir=path)
        os.close(fd)
        os.unlink(name)
    except OSError as exc:
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            return "full"
        if exc.errno in (errno.EROFS, errno.EACCES, errno.EPERM):
            return "read-only"
        return "unavailable"
    return "full" if st.f_bavail * st.f_frsize < min_free else "ok"


_HELD: list[int] = []  # lock files of the directories this process uses (kept open)


def sole_user(directory: Path, name: str = ".live") -> bool:
    """Register this process as a user of ``directory``; whether no other live process is one.

    Every user holds a shared ``flock`` on ``directory/name`` for its whole life (the kernel
    drops it when the process dies, SIGKILL included). Before taking it, an exclusive lock is
    tried: granted means nobody else holds one, so whatever a crash left in the directory
    (partial uploads, orphan job directories) belongs to no live process and can go at once;
    refused means other servers share it, and their files in flight are left to the age rule.
    """
    import fcntl

    directory.mkdir(parents=True, exist_ok=True)
    path = directory / name
    if not path.exists():
        path.touch()
    fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)  # read-only: a remount ro stays possible
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        alone = True
    except OSError:
        alone = False
    fcntl.flock(fd, fcntl.LOCK_SH)
    _HELD.append(fd)
    return alone
