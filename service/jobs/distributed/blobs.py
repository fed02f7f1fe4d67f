"""Blob stores of the distributed backend: where inputs and results live, shared by API and workers.

Layout (the same keys in both stores, and the same files as the embedded queue's data dir)::

    jobs/<id>/input.<fmt>   jobs/<id>/result.npy   jobs/<id>/result.<fmt>   jobs/<id>/report.json

* :class:`DirectoryBlobs`: a directory (``GEOSMOOTH_DATA_DIR``, a volume shared by the API and
  every worker, e.g. NFS). Workers compute inside the job's directory; writes are durable
  (fsync + atomic rename), exactly as in the embedded queue.
* :class:`S3Blobs`: S3-compatible object storage (``GEOSMOOTH_STORAGE_URL=s3://bucket/prefix``;
  endpoint, region and credentials from the standard ``AWS_*`` environment, e.g.
  ``AWS_ENDPOINT_URL_S3`` for MinIO). Workers compute in a local scratch directory and upload
  the outputs; the API serves results from a local cache (streamed, with ETag/Range) or
  redirects to presigned URLs (``GEOSMOOTH_PRESIGN_SECONDS``).
"""

from __future__ import annotations

import contextlib
import shutil
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Protocol
from urllib.parse import urlsplit

from service.jobs.errors import StorageUnavailable
from service.jobs.files import JobFiles, is_job_id, probe_directory

__all__ = ["BlobStore", "DirectoryBlobs", "S3Blobs", "blob_store"]


class BlobStore(Protocol):
    """What the RQ backend needs from a blob store."""

    def put_input(self, job_id: str, fmt: str, data: bytes | Path) -> int:
        """Store a job's input durably; its size."""
        ...

    def read(self, job_id: str, name: str) -> bytes:
        """A stored file's bytes (``FileNotFoundError`` if missing)."""
        ...

    def local_file(self, job_id: str, name: str) -> Path | None:
        """A local path of the stored file (cached from object storage), ``None`` if missing."""
        ...

    def presign(self, job_id: str, name: str, seconds: int, filename: str) -> str | None:
        """A time-limited download URL, ``None`` where the store has none."""
        ...

    def workspace(self, job_id: str, fmt: str) -> contextlib.AbstractContextManager[Path]:
        """A local directory holding ``input.<fmt>`` where a worker writes the outputs."""
        ...

    def commit(self, job_id: str, workdir: Path, names: list[str]) -> None:
        """Store the outputs ``names`` a run wrote into its workspace."""
        ...

    def remove(self, job_id: str) -> None:
        """Delete every file of a job (no error if gone)."""
        ...

    def job_ids(self) -> dict[str, float]:
        """Every job that has files, with the time its files were last written."""
        ...

    def health(self) -> str:
        """``"ok"``, ``"full"``, ``"read-only"`` or ``"unavailable"``."""
        ...

    def prune_cache(self, max_age: float) -> None:
        """Drop local cache files older than ``max_age`` seconds."""
        ...


class DirectoryBlobs:
    """Blobs in a (shared) directory: ``<root>/jobs/<id>/<name>``.

    Parameters
    ----------
    root : Path
        The data directory.
    min_free : int
        Bytes below which the store counts as full.
    """

    def __init__(self, root: Path, min_free: int = 0) -> None:
        self.root = Path(root)
        self.files = JobFiles(self.root)
        self.min_free = min_free

    def put_input(self, job_id: str, fmt: str, data: bytes | Path) -> int:
        return self.files.create(job_id, fmt, data)

    def read(self, job_id: str, name: str) -> bytes:
        return (self.files.dir(job_id) / _safe(name)).read_bytes()

    def local_file(self, job_id: str, name: str) -> Path | None:
        path = self.files.dir(job_id) / _safe(name)
        return path if path.exists() else None

    def presign(self, job_id: str, name: str, seconds: int, filename: str) -> str | None:
        return None

    @contextlib.contextmanager
    def workspace(self, job_id: str, fmt: str) -> Iterator[Path]:
        yield self.files.dir(job_id)  # computed in place: outputs are written durably there

    def commit(self, job_id: str, workdir: Path, names: list[str]) -> None:
        return None

    def remove(self, job_id: str) -> None:
        self.files.remove(job_id)

    def job_ids(self) -> dict[str, float]:
        out = {}
        for entry in self.files.root.iterdir():
            if is_job_id(entry.name):
                with contextlib.suppress(FileNotFoundError):
                    out[entry.name] = entry.stat().st_mtime
        return out

    def health(self) -> str:
        return probe_directory(self.files.root, self.min_free)

    def prune_cache(self, max_age: float) -> None:
        for tmp in self.files.stray_temporaries(max_age):
            tmp.unlink(missing_ok=True)


class S3Blobs:
    """Blobs in an S3-compatible bucket: ``s3://bucket/prefix/jobs/<id>/<name>``.

    Parameters
    ----------
    url : str
        ``s3://bucket`` or ``s3://bucket/prefix``.
    cache_dir : Path
        Local directory for results served by the API and for worker scratch space.
    client : optional
        A boto3 S3 client (default: ``boto3.client("s3")``, configured by the environment).
    """

    def __init__(self, url: str, cache_dir: Path, client: Any = None) -> None:
        parts = urlsplit(url)
        if parts.scheme != "s3" or not parts.netloc:
            raise ValueError(f"not an s3:// URL: {url!r}")
        self.bucket = parts.netloc
        self.prefix = parts.path.strip("/")
        self.cache = Path(cache_dir)
        self.cache.mkdir(parents=True, exist_ok=True)
        if client is None:
            import boto3  # type: ignore[import-untyped]
            from botocore.config import Config  # type: ignore[import-untyped]

            # SigV4 presigned URLs (every region and S3-compatible server accepts them)
            client = boto3.client("s3", config=Config(signature_version="s3v4"))
        self.client = client

    def key(self, job_id: str, name: str) -> str:
        if not is_job_id(job_id):
            raise ValueError(f"not a job id: {job_id!r}")
        path = f"jobs/{job_id}/{_safe(name)}"
        return f"{self.prefix}/{path}" if self.prefix else path

    def _call(self, method: str, **kw: Any) -> Any:
        from botocore.exceptions import BotoCoreError, ClientError  # type: ignore[import-untyped]

        try:
            return getattr(self.client, method)(Bucket=self.bucket, **kw)
        except ClientError as exc:
            code = str(exc.response.get("Error", {}).get("Code", ""))
            if code in ("NoSuchKey", "404", "NotFound"):
                raise FileNotFoundError(kw.get("Key", "")) from None
            raise StorageUnavailable(f"the object store refused the request ({code})") from exc
        except BotoCoreError as exc:
            raise StorageUnavailable("the object store cannot be reached") from exc

    def put_input(self, job_id: str, fmt: str, data: bytes | Path) -> int:
        self._put(self.key(job_id, f"input.{fmt}"), data)
        if isinstance(data, Path):
            size = data.stat().st_size
            data.unlink(missing_ok=True)
            return size
        return len(data)

    def _put(self, key: str, data: bytes | Path) -> None:
        if isinstance(data, Path):
            with open(data, "rb") as fh:
                self._call("put_object", Key=key, Body=fh)
        else:
            self._call("put_object", Key=key, Body=data)

    def read(self, job_id: str, name: str) -> bytes:
        body = self._call("get_object", Key=self.key(job_id, name))["Body"]
        return bytes(body.read())

    def _download(self, key: str, dest: Path) -> None:
        tmp = dest.with_name(f".{dest.name}.{time.monotonic_ns()}.tmp")
        try:
            body = self._call("get_object", Key=key)["Body"]
            with open(tmp, "wb") as fh:
                shutil.copyfileobj(body, fh, 1024 * 1024)
            tmp.replace(dest)
        finally:
            tmp.unlink(missing_ok=True)

    def local_file(self, job_id: str, name: str) -> Path | None:
        dest = self.cache / "results" / job_id / _safe(name)
        if dest.exists():
            return dest
        dest.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._download(self.key(job_id, name), dest)
        except FileNotFoundError:
            return None
        return dest

    def presign(self, job_id: str, name: str, seconds: int, filename: str) -> str | None:
        params = {
            "Bucket": self.bucket,
            "Key": self.key(job_id, name),
            "ResponseContentDisposition": f'attachment; filename="{filename}"',
        }
        url = self.client.generate_presigned_url("get_object", Params=params, ExpiresIn=seconds)
        return str(url)

    @contextlib.contextmanager
    def workspace(self, job_id: str, fmt: str) -> Iterator[Path]:
        scratch = self.cache / "work"
        scratch.mkdir(parents=True, exist_ok=True)
        workdir = Path(tempfile.mkdtemp(prefix=f"{job_id}.", dir=scratch))
        try:
            self._download(self.key(job_id, f"input.{fmt}"), workdir / f"input.{fmt}")
            yield workdir
        finally:
            shutil.rmtree(workdir, ignore_errors=True)

    def commit(self, job_id: str, workdir: Path, names: list[str]) -> None:
        for name in names:
            self._put(self.key(job_id, name), workdir / name)

    def remove(self, job_id: str) -> None:
        prefix = self.key(job_id, "x")[:-1]
        listing = self._call("list_objects_v2", Prefix=prefix)
        keys = [{"Key": item["Key"]} for item in listing.get("Contents", [])]
        if keys:
            self._call("delete_objects", Delete={"Objects": keys, "Quiet": True})
        shutil.rmtree(self.cache / "results" / job_id, ignore_errors=True)

    def job_ids(self) -> dict[str, float]:
        base = f"{self.prefix}/jobs/" if self.prefix else "jobs/"
        out: dict[str, float] = {}
        paginator = self.client.get_paginator("list_objects_v2")
        for page in paginator.paginate(Bucket=self.bucket, Prefix=base):
            for item in page.get("Contents", []):
                job_id = item["Key"][len(base):].split("/", 1)[0]
                if is_job_id(job_id):
                    stamp = item["LastModified"].timestamp()
                    out[job_id] = max(out.get(job_id, 0.0), stamp)
        return out

    def health(self) -> str:
        try:
            self._call("head_bucket")
        except Exception:
            return "unavailable"
        return "ok"

    def prune_cache(self, max_age: float) -> None:
        now = time.time()
        for sub in ("results", "work"):
            root = self.cache / sub
            if not root.exists():
                continue
            for entry in root.iterdir():
                with contextlib.suppress(FileNotFoundError):
                    if now - entry.stat().st_mtime >= max_age:
                        shutil.rmtree(entry, ignore_errors=True)


def _safe(name: str) -> str:
    if "/" in name or name.startswith(".") or not name:
        raise ValueError(f"not a blob name: {name!r}")
    return name


def blob_store(storage_url: str | None, data_dir: Path, min_free: int = 0) -> BlobStore:
    """The store named by ``GEOSMOOTH_STORAGE_URL`` (unset: the directory ``data_dir``)."""
    if not storage_url:
        return DirectoryBlobs(data_dir, min_free)
    if storage_url.startswith("s3://"):
        return S3Blobs(storage_url, Path(data_dir) / "cache")
    raise ValueError(f"GEOSMOOTH_STORAGE_URL must be s3://bucket/prefix, got {storage_url!r}")

