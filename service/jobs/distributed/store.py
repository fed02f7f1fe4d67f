"""Job records in Redis (the RQ backend's metadata): small hashes and sorted-set indexes.

Keys (``P`` = ``geosmooth:<queue name>``; one Redis, not a cluster: scripts build key names)::

    P:job:<id>                  hash: the record (strings; JSON for params/progress/problem)
    P:idx:<*|t<tenant>>:<*|status>  zsets by submission order (seq): listing, paging, counts
    P:leases                    zset: running jobs by lease expiry (recovery of lost workers)
    P:finished                  zset: finished jobs by finish time (TTL expiry)
    P:webhooks                  zset: finished jobs whose webhook is not delivered yet
    P:pending                   zset: requeued jobs waiting for their backoff (no RQ job yet)
    P:idem:<tenant>:<key>       string: job id of an idempotency key
    P:stats:finished, P:stats:duration   hashes: outcome counters, run-time histogram
    P:seq                       counter

Every state change is one Lua script, conditional on the expected status and, for the writes of
a run, on the run (``owner`` = worker name, ``attempts``): a run that was cancelled, timed out or
taken over cannot write, exactly as in the SQLite store. Only ids and small metadata are stored;
geometry lives in the blob store.
"""

from __future__ import annotations

import builtins
import json
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from service.jobs.admit import JobRow
from service.jobs.distributed import scripts
from service.jobs.errors import IdempotencyConflict
from service.jobs.metrics import DURATION_BUCKETS, bucket_index, cumulative
from service.jobs.progress import queued_progress
from service.jobs.queue import FINISHED, JobRecord, JobStatus

__all__ = ["RedisJobStore", "RunInfo"]

_NIL = "\x00"  # a NUL byte: "absent" in conditions, "delete" in sets
_MAX_PAGE = 2**31

_INT = ("input_bytes", "attempts", "max_attempts", "seq", "pid")
_FLOAT = ("created_at", "updated_at", "started_at", "finished_at", "lease_until", "run_seconds")
_JSON = ("params", "progress", "problem")


@dataclass(frozen=True)
class RunInfo:
    """What recovery and the worker need to know about a running job."""

    job_id: str
    owner: str | None
    attempts: int
    max_attempts: int
    lease_until: float | None


def _decode(raw: Mapping[bytes, bytes]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in raw.items():
        key, text = k.decode(), v.decode()
        if key in _INT:
            out[key] = int(text)
        elif key in _FLOAT:
            out[key] = float(text)
        elif key in _JSON:
            out[key] = json.loads(text)
        else:
            out[key] = text
    return out


def _encode(value: Any) -> str:
    if value is None:
        return _NIL
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, dict | list):
        return json.dumps(value, allow_nan=False)
    return str(value)


class RedisJobStore:
    """Job records of one queue in Redis.

    Parameters
    ----------
    redis : redis.Redis
        A connection (``decode_responses=False``, as RQ needs).
    prefix : str
        Key prefix (``geosmooth:<queue name>``).
    result_ttl : float or None
        Seconds finished jobs are kept (for ``expires_at``).
    """

    def __init__(self, redis: Any, prefix: str, result_ttl: float | None) -> None:
        self.redis = redis
        self.prefix = prefix
        self.result_ttl = result_ttl
        self._update = redis.register_script(scripts.UPDATE)
        self._claim = redis.register_script(scripts.CLAIM)
        self._delete = redis.register_script(scripts.DELETE)
        self._claim_webhook = redis.register_script(scripts.CLAIM_WEBHOOK)

    # -- keys ----------------------------------------------------------------------------
    def key(self, job_id: str) -> str:
        """The hash of one job."""
        return f"{self.prefix}:job:{job_id}"

    def index(self, tenant: str | None = None, status: str | None = None) -> str:
        """The sorted set of the jobs of ``tenant`` (``None``: all) in ``status`` (or any)."""
        who = "*" if tenant is None else f"t{tenant}"
        return f"{self.prefix}:idx:{who}:{status or '*'}"

    def _idem(self, tenant: str | None, key: str) -> str:
        return f"{self.prefix}:idem:{tenant or ''}:{key}"

    # -- records -------------------------------------------------------------------------
    def _record(self, data: dict[str, Any]) -> JobRecord:
        finished, ttl = data.get("finished_at"), self.result_ttl
        expires = None if finished is None or ttl is None else finished + ttl
        return JobRecord(
            id=data["id"],
            status=JobStatus(data["status"]),
            fmt=data["fmt"],
            filename=data.get("filename"),
            params=data["params"],
            input_bytes=data["input_bytes"],
            created_at=data["created_at"],
            updated_at=data["updated_at"],
            started_at=data.get("started_at"),
            finished_at=finished,
            expires_at=expires,
            weld=data.get("weld") == "1",
            tenant=data.get("tenant"),
            webhook_url=data.get("webhook_url"),
            attempts=data.get("attempts", 0),
            max_attempts=data["max_attempts"],
            progress=data.get("progress"),
            problem=data.get("problem"),
            run_seconds=data.get("run_seconds"),
            pid=data.get("pid"),
        )

    def raw(self, job_id: str) -> dict[str, Any] | None:
        """Every field of a job (``rq_job``, ``owner``, ``host``, ... included)."""
        data = self.redis.hgetall(self.key(job_id))
        return _decode(data) if data else None

    def get(self, job_id: str) -> JobRecord | None:
        """One job (without its report), or ``None``."""
        data = self.raw(job_id)
        return None if data is None else self._record(data)

    def insert(
        self, job: JobRow, rq_job: str, enqueue: Callable[[Any], None]
    ) -> tuple[JobRecord, bool]:
        """Add a ``queued`` job and, in the same transaction, ``enqueue(pipeline)`` its run as
        the RQ job ``rq_job``.

        Returns the record and whether it is new (an idempotent repeat returns the earlier job).

        Raises
        ------
        IdempotencyConflict
            The key was used for a different request.
        """
        idem = None
        if job.idempotency_key is not None:
            idem = self._idem(job.tenant, job.idempotency_key)
            if not self.redis.set(idem, job.job_id, nx=True):
                earlier = self._earlier(idem, job)
                if earlier is not None:
                    return earlier, False
        seq = int(self.redis.incr(f"{self.prefix}:seq"))
        now = time.time()
        fields = {
            "id": job.job_id, "status": JobStatus.QUEUED.value, "fmt": job.fmt,
            "filename": job.filename, "params": job.params, "input_bytes": job.input_bytes,
            "created_at": now, "updated_at": now, "attempts": 0,
            "max_attempts": job.max_attempts, "weld": job.weld, "tenant": job.tenant,
            "webhook_url": job.webhook_url, "request_hash": job.request_hash, "idem": idem,
            "seq": seq, "progress": queued_progress(), "rq_job": rq_job,
        }  # fmt: skip
        mapping = {k: _encode(v) for k, v in fields.items() if v is not None}
        with self.redis.pipeline(transaction=True) as pipe:
            pipe.multi()
            pipe.hset(self.key(job.job_id), mapping=mapping)
            for tenant in (None, job.tenant) if job.tenant is not None else (None,):
                pipe.zadd(self.index(tenant), {job.job_id: seq})
                pipe.zadd(self.index(tenant, JobStatus.QUEUED.value), {job.job_id: seq})
            enqueue(pipe)
            pipe.execute()
        rec = self.get(job.job_id)
        assert rec is not None
        return rec, True

    def _earlier(self, idem: str, job: JobRow) -> JobRecord | None:
        earlier_id = self.redis.get(idem)
        data = self.raw(earlier_id.decode()) if earlier_id else None
        if data is None:  # a submit that died before its record was written: take the key over
            self.redis.set(idem, job.job_id)
            return None
        IdempotencyConflict.check(data.get("request_hash"), job.request_hash,
                                  job.idempotency_key or "")  # fmt: skip
        return self._record(data)

    def list(
        self,
        offset: int = 0,
        limit: int = 50,
        status: JobStatus | None = None,
        tenant: str | None = None,
    ) -> tuple[builtins.list[JobRecord], int]:
        """A page of jobs, newest first, and the total count."""
        index = self.index(tenant, status.value if status else None)
        start = min(max(0, offset), _MAX_PAGE)
        stop = start + min(max(0, limit), _MAX_PAGE) - 1
        ids = self.redis.zrevrange(index, start, stop) if stop >= start else []
        with self.redis.pipeline(transaction=False) as pipe:
            pipe.zcard(index)
            for job_id in ids:
                pipe.hgetall(self.key(job_id.decode()))
            total, *rows = pipe.execute()
        return [self._record(_decode(r)) for r in rows if r], int(total)

    def counts(self) -> dict[str, int]:
        """Jobs per status."""
        with self.redis.pipeline(transaction=False) as pipe:
            for s in JobStatus:
                pipe.zcard(self.index(None, s.value))
            values = pipe.execute()
        return {s.value: int(n) for s, n in zip(JobStatus, values, strict=True)}

    # -- state changes -------------------------------------------------------------------
    def update(
        self,
        job_id: str,
        *,
        expect: tuple[JobStatus, ...] = (),
        when: Mapping[str, Any] | None = None,
        status: JobStatus | None = None,
        **fields: Any,
    ) -> JobStatus | None:
        """Change a job if it is in one of ``expect`` and its fields equal ``when``.

        ``when`` values of ``None`` mean "field absent"; ``fields`` of ``None`` are deleted.
        Returns its status before the change, ``None`` if a condition failed or it is unknown.
        """
        conditions = dict(when or {})
        args: builtins.list[Any] = [
            self.prefix, job_id, ",".join(s.value for s in expect),
            status.value if status else "", repr(time.time()), len(conditions),
        ]  # fmt: skip
        for name, value in conditions.items():
            args += [name, _encode(value)]
        args.append(len(fields))
        for name, value in fields.items():
            args += [name, _encode(value)]
        before = self._update(args=args)
        return JobStatus(before.decode()) if isinstance(before, bytes) else None

    def run_update(
        self, job_id: str, owner: str, attempt: int, status: JobStatus | None = None, **fields: Any
    ) -> bool:
        """Change a running job on behalf of its run ``(owner, attempt)``; ``False`` if the run
        lost the job."""
        when = {"owner": owner, "attempts": attempt}
        done = self.update(job_id, expect=(JobStatus.RUNNING,), when=when, status=status,
                           **fields)  # fmt: skip
        return done is not None

    def pending(self, now: float | None = None) -> builtins.list[str]:
        """Queued jobs without an RQ job (requeued, due by ``now``)."""
        high = repr(time.time() if now is None else now)
        due = self.redis.zrangebyscore(f"{self.prefix}:pending", "-inf", high)
        return [i.decode() for i in due]

    def claim(
        self, job_id: str, rq_job: str, owner: str, lease: float, pid: int, host: str
    ) -> int | None:
        """Start a run of a job queued as ``rq_job``; its attempt number, ``None`` if the job is
        not queued for that RQ job."""
        now = time.time()
        progress = json.dumps(queued_progress("reading"))
        attempt = self._claim(args=[self.prefix, job_id, owner, repr(now), repr(now + lease),
                                    pid, host, progress, rq_job])  # fmt: skip
        return int(attempt) or None

    def delete_finished(self, job_id: str) -> bool:
        """Delete a finished job's record; ``False`` if unknown or not finished."""
        return bool(self._delete(args=[self.prefix, job_id]))

    def claim_webhook(self, job_id: str, stale_after: float) -> bool:
        """Take the webhook delivery of a finished job (see the SQLite store)."""
        now = time.time()
        return bool(self._claim_webhook(args=[self.prefix, job_id, repr(now),
                                              repr(now - stale_after)]))  # fmt: skip

    def webhook_state(self, job_id: str, state: str) -> None:
        """``delivered`` or ``failed``."""
        self.update(job_id, webhook_state=state)
        self.redis.zrem(f"{self.prefix}:webhooks", job_id)

    def running(self, before: float | None = None) -> builtins.list[RunInfo]:
        """Running jobs (whose lease ends before ``before``, if given)."""
        high = "+inf" if before is None else repr(before)
        ids = [i.decode() for i in self.redis.zrangebyscore(f"{self.prefix}:leases", "-inf", high)]
        with self.redis.pipeline(transaction=False) as pipe:
            for job_id in ids:
                pipe.hmget(self.key(job_id), "owner", "attempts", "max_attempts", "lease_until")
            rows = pipe.execute()
        out = []
        for job_id, (owner, attempts, max_attempts, lease) in zip(ids, rows, strict=True):
            if attempts is None:
                continue
            out.append(RunInfo(job_id, owner.decode() if owner else None, int(attempts),
                               int(max_attempts), float(lease) if lease else None))  # fmt: skip
        return out

    def expired(self, now: float | None = None) -> builtins.list[str]:
        """Finished jobs older than ``result_ttl``."""
        if self.result_ttl is None:
            return []
        cutoff = (time.time() if now is None else now) - self.result_ttl
        old = self.redis.zrangebyscore(f"{self.prefix}:finished", "-inf", repr(cutoff))
        return [i.decode() for i in old]

    def webhooks_due(self, stale_after: float = 60.0) -> builtins.list[str]:
        """Finished jobs whose webhook is neither delivered nor given up, finished (or claimed)
        more than ``stale_after`` seconds ago (their deliverer died): ``P:webhooks``, a sorted
        set kept by the scripts, so the sweep's cost does not grow with the finished jobs."""
        high = repr(time.time() - stale_after)
        return [i.decode() for i in self.redis.zrangebyscore(f"{self.prefix}:webhooks", "-inf",
                                                                 high)]  # fmt: skip

    def ids(self) -> set[str]:
        """Every job id."""
        return {i.decode() for i in self.redis.zrange(self.index(), 0, -1)}

    # -- metrics -------------------------------------------------------------------------
    def observe(self, seconds: float) -> None:
        """Count a succeeded run in the shared run-time histogram."""
        with self.redis.pipeline(transaction=True) as pipe:
            pipe.hincrby(f"{self.prefix}:stats:duration", str(bucket_index(seconds)), 1)
            pipe.hincrbyfloat(f"{self.prefix}:stats:duration", "sum", seconds)
            pipe.execute()

    def histogram(self) -> dict[str, Any]:
        """The shared histogram and outcome counters (every worker, since the queue exists)."""
        raw = {k.decode(): v.decode() for k, v in
               self.redis.hgetall(f"{self.prefix}:stats:duration").items()}  # fmt: skip
        counts = [int(raw.get(str(i), 0)) for i in range(len(DURATION_BUCKETS) + 1)]
        buckets = cumulative(counts)
        finished = {k.decode(): int(v) for k, v in
                    self.redis.hgetall(f"{self.prefix}:stats:finished").items()}  # fmt: skip
        return {
            "finished_total": {s.value: finished.get(s.value, 0) for s in FINISHED},
            "duration_buckets": buckets,
            "duration_sum": float(raw.get("sum", 0.0)),
            "duration_count": int(buckets[-1][1]),
        }
