"""Token buckets of the rate limits: per process, or shared by every API replica through Redis.

A bucket holds at most ``burst`` tokens and refills at ``rate`` tokens per second; a request
takes one (:meth:`Buckets.take` answers 0, or the seconds until a token is back: the
``Retry-After`` of a 429). :func:`buckets_for` picks the store from the settings:

* embedded deployment (``GEOSMOOTH_QUEUE=local``): :class:`MemoryBuckets`, in the API process
  (one process serves the API);
* distributed deployment (``GEOSMOOTH_QUEUE=rq``): :class:`RedisBuckets` in the deployment's
  Redis (``GEOSMOOTH_REDIS_URL``), so N API replicas share one limit instead of allowing N
  times it. One Lua script reads, refills and takes atomically on Redis's own clock (the
  replicas' clocks do not matter); a bucket's key expires once it would be full again. When
  Redis cannot be reached the request is let through (logged): the queue answers 503 for
  what needs Redis, and a rate limit is no reason to refuse the rest.
"""

from __future__ import annotations

import logging
import time
from collections import OrderedDict
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from service.settings import Settings

__all__ = ["Buckets", "MemoryBuckets", "RedisBuckets", "buckets_for"]

log = logging.getLogger("geosmooth.api")


class Buckets(Protocol):
    """A store of token buckets by key."""

    async def peek(self, key: str, rate: float, burst: int) -> float:
        """The tokens ``key`` has now (``burst`` for an unknown key); takes none."""
        ...

    async def take(self, key: str, rate: float, burst: int) -> float:
        """Take one token; 0 if granted, else the seconds until one is available."""
        ...


class MemoryBuckets:
    """Token buckets in this process (at most ``max_keys``, least recently used dropped)."""

    def __init__(self, max_keys: int = 10_000) -> None:
        self.max_keys = max_keys
        self._buckets: OrderedDict[str, tuple[float, float]] = OrderedDict()

    def peek_at(self, key: str, rate: float, burst: int, now: float) -> float:
        tokens, last = self._buckets.get(key, (float(burst), now))
        return min(float(burst), tokens + (now - last) * rate)

    def take_at(self, key: str, rate: float, burst: int, now: float) -> float:
        tokens, last = self._buckets.pop(key, (float(burst), now))
        tokens = min(float(burst), tokens + (now - last) * rate)
        wait = 0.0
        if tokens >= 1.0:
            tokens -= 1.0
        else:
            wait = (1.0 - tokens) / rate
        self._buckets[key] = (tokens, now)
        while len(self._buckets) > self.max_keys:
            self._buckets.popitem(last=False)
        return wait

    async def peek(self, key: str, rate: float, burst: int) -> float:
        return self.peek_at(key, rate, burst, time.monotonic())

    async def take(self, key: str, rate: float, burst: int) -> float:
        return self.take_at(key, rate, burst, time.monotonic())


# KEYS[1]: the bucket (a hash: tokens, last). ARGV: rate, burst, 1 to take a token / 0 to peek.
# Answers the wait (take) or the tokens (peek) as a string (Lua numbers would be truncated).
_SCRIPT = """
local t = redis.call('TIME')
local now = tonumber(t[1]) + tonumber(t[2]) / 1000000
local rate = tonumber(ARGV[1])
local burst = tonumber(ARGV[2])
local state = redis.call('HMGET', KEYS[1], 'tokens', 'last')
local tokens = tonumber(state[1]) or burst
local last = tonumber(state[2]) or now
tokens = math.min(burst, tokens + math.max(0, now - last) * rate)
if ARGV[3] == '0' then
  return tostring(tokens)
end
local wait = 0
if tokens >= 1 then
  tokens = tokens - 1
else
  wait = (1 - tokens) / rate
end
redis.call('HSET', KEYS[1], 'tokens', tostring(tokens), 'last', tostring(now))
redis.call('PEXPIRE', KEYS[1], math.ceil((burst - tokens) / rate * 1000) + 1000)
return tostring(wait)
"""

#: Seconds between two warnings that Redis cannot be reached.
_WARN_EVERY = 10.0


class RedisBuckets:
    """Token buckets in Redis under ``prefix`` (shared by every process that uses the same
    Redis and prefix). The client is created on first use, in the event loop that uses it."""

    def __init__(self, url: str, prefix: str, timeout: float = 2.0) -> None:
        self.url = url
        self.prefix = prefix
        self.timeout = timeout
        self._client: Any = None
        self._script: Any = None
        self._warned = -_WARN_EVERY

    def _run(self) -> Any:
        if self._script is None:
            from redis.asyncio import Redis

            self._client = Redis.from_url(
                self.url, socket_timeout=self.timeout, socket_connect_timeout=self.timeout
            )
            self._script = self._client.register_script(_SCRIPT)
        return self._script

    async def _call(self, key: str, rate: float, burst: int, take: bool) -> float | None:
        from redis.exceptions import RedisError

        try:
            answer = await self._run()(
                keys=[self.prefix + key], args=[repr(float(rate)), int(burst), int(take)]
            )
        except (RedisError, OSError) as exc:
            now = time.monotonic()
            if now - self._warned >= _WARN_EVERY:
                self._warned = now
                log.warning("rate limit store unreachable; requests are let through: %s", exc)
            return None
        return float(answer)

    async def peek(self, key: str, rate: float, burst: int) -> float:
        tokens = await self._call(key, rate, burst, take=False)
        return float(burst) if tokens is None else tokens

    async def take(self, key: str, rate: float, burst: int) -> float:
        wait = await self._call(key, rate, burst, take=True)
        return 0.0 if wait is None else wait

    async def aclose(self) -> None:
        if self._client is not None:
            await self._client.aclose()
            self._client = self._script = None


def buckets_for(settings: Settings, purpose: str) -> Buckets:
    """The store of one kind of bucket (``purpose``: ``requests``, ``auth-failures``): in Redis
    for the distributed deployment, in this process for the embedded one."""
    if settings.queue == "rq":
        return RedisBuckets(settings.redis_url, f"{settings.rq_queue_name}:ratelimit:{purpose}:")
    return MemoryBuckets()
