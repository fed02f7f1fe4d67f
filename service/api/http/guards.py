"""Request guards (pure ASGI middleware), outermost first in the app:

1. :class:`InFlightLimit`: at most ``max_requests_in_flight`` requests at once (503 +
   ``Retry-After``); health probes are never refused.
2. :class:`HostGuard`: the ``Host`` header must be on the allow-list (default: the bound address
   and localhost), so a DNS-rebinding page cannot reach a local instance (400).
3. (CORS, when configured: Starlette's middleware.)
4. :class:`OriginGuard`: a state-changing request (POST, PUT, PATCH, DELETE) from another
   origin's page is refused unless it carries an API key (403): no cross-site form post can
   submit, cancel or delete a job.
5. :class:`AuthGate`: ``/v1/*`` requires a valid key when keys are configured (401), then the
   key's token bucket (429 + ``Retry-After``); a client address that sent more than
   ``auth_failure_burst`` wrong keys (refilled at ``auth_failure_rate``/s) gets 429 +
   ``Retry-After`` for every ``/v1`` request until its allowance is back; the
   :class:`~service.api.http.auth.Principal` is left in ``scope["state"]["principal"]`` for the
   routes and the body limit. Both buckets live in a :class:`~service.api.http.ratelimit.Buckets`
   store: per process in the embedded deployment, in Redis (shared by every API replica) in the
   distributed one (:func:`~service.api.http.ratelimit.buckets_for`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from urllib.parse import urlsplit

from starlette.datastructures import Headers
from starlette.types import ASGIApp, Receive, Scope, Send

from service.api.errors import ApiProblem
from service.api.http.auth import KeyRing, Principal, presented_key
from service.api.http.ratelimit import Buckets, MemoryBuckets
from service.api.problems import problem_response

__all__ = [
    "AuthGate",
    "HostGuard",
    "InFlightLimit",
    "OriginGuard",
    "allowed_hosts",
]

_UNSAFE = frozenset({"POST", "PUT", "PATCH", "DELETE"})
_PROBES = frozenset({"/healthz", "/readyz"})
_WILDCARD_BINDS = frozenset({"", "0.0.0.0", "::", "[::]"})


async def _refuse(problem: ApiProblem, scope: Scope, receive: Receive, send: Send) -> None:
    await problem_response(problem, scope.get("path"))(scope, receive, send)


def allowed_hosts(setting: str, bound: str) -> list[str]:
    """The Host allow-list: the setting, or the bound address plus localhost (``*`` for any)."""
    given = [h.strip().lower() for h in setting.split(",") if h.strip()]
    if given:
        return given
    if bound.strip().lower() in _WILDCARD_BINDS:
        return ["*"]
    return sorted({bound.strip("[]").lower(), "localhost", "127.0.0.1", "::1"})


def _host_name(host: str) -> str:
    """``example.org:8000`` -> ``example.org``; ``[::1]:8000`` -> ``::1``."""
    host = host.strip().lower()
    if host.startswith("["):
        return host[1 : host.find("]")] if "]" in host else host
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


class InFlightLimit:
    """503 problem + ``Retry-After`` beyond ``limit`` concurrent requests (probes exempt)."""

    def __init__(self, app: ASGIApp, limit: int) -> None:
        self.app = app
        self.limit = limit
        self.active = 0

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["path"] in _PROBES:
            await self.app(scope, receive, send)
            return
        if self.active >= self.limit:
            problem = ApiProblem(
                503,
                f"the server is handling {self.limit} requests; retry shortly",
                code="overloaded",
                headers={"Retry-After": "1"},
            )
            await _refuse(problem, scope, receive, send)
            return
        self.active += 1
        try:
            await self.app(scope, receive, send)
        finally:
            self.active -= 1


#: Largest request header accepted (all fields); more is a 431 problem.
MAX_HEADER_BYTES = 16 * 1024


class HostGuard:
    """400 problem unless the ``Host`` header is allowed (``*``, exact or ``*.domain``); 431
    for a header larger than :data:`MAX_HEADER_BYTES` (h11 only bounds incomplete headers).
    """

    def __init__(self, app: ASGIApp, hosts: Iterable[str]) -> None:
        self.app = app
        self.hosts = [h.lower() for h in hosts]
        self.any = "*" in self.hosts

    def allowed(self, host: str | None) -> bool:
        if self.any or host is None:  # no Host at all: not a browser, not rebinding
            return True
        name = _host_name(host)
        return any(name == h or (h.startswith("*.") and name.endswith(h[1:])) for h in self.hosts)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and _header_bytes(scope) > MAX_HEADER_BYTES:
            problem = ApiProblem(
                431,
                f"the request header exceeds {MAX_HEADER_BYTES} bytes",
                code="header-too-large",
                headers={"Connection": "close"},
            )
            await _refuse(problem, scope, receive, send)
            return
        if scope["type"] == "http" and not self.allowed(Headers(scope=scope).get("host")):
            problem = ApiProblem(
                400,
                "the Host header names a host this server does not answer for",
                code="host-not-allowed",
                field="Host",
            )
            await _refuse(problem, scope, receive, send)
            return
        await self.app(scope, receive, send)


def _header_bytes(scope: Scope) -> int:
    line = len(scope.get("raw_path") or b"") + len(scope.get("query_string") or b"")
    return line + sum(len(k) + len(v) + 4 for k, v in scope.get("headers", ()))


def _origin_of(url: str) -> str | None:
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError:
        return None
    if not parts.scheme or not parts.hostname:
        return None
    default = {"http": 80, "https": 443}.get(parts.scheme)
    host = f"[{parts.hostname}]" if ":" in parts.hostname else parts.hostname
    return f"{host}:{port or default}"


class OriginGuard:
    """403 problem for a keyless state-changing request from another origin's page."""

    def __init__(self, app: ASGIApp, trusted_origins: Iterable[str] = ()) -> None:
        self.app = app
        self.trusted = {o.strip().rstrip("/").lower() for o in trusted_origins if o.strip()}

    def cross_origin(self, headers: Headers, scheme: str) -> bool:
        origin = headers.get("origin")
        if origin is not None:
            origin = origin.strip().rstrip("/").lower()
            if origin in self.trusted:
                return False
            host = headers.get("host", "")
            same = _origin_of(f"{scheme}://{host}")
            return origin == "null" or same is None or _origin_of(origin) != same
        return headers.get("sec-fetch-site", "").lower() in ("cross-site", "same-site")

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and scope["method"] in _UNSAFE:
            headers = Headers(scope=scope)
            if presented_key(headers) is None and self.cross_origin(headers, scope["scheme"]):
                problem = ApiProblem(
                    403,
                    "state-changing requests from another origin need an API key",
                    code="cross-origin-refused",
                    field="Origin",
                )
                await _refuse(problem, scope, receive, send)
                return
        await self.app(scope, receive, send)


class AuthGate:
    """Authenticate ``/v1/*`` requests (401) and apply the key's rate limit (429)."""

    def __init__(
        self,
        app: ASGIApp,
        keys: KeyRing,
        buckets: Buckets | None = None,
        failure_burst: int = 20,
        failure_rate: float = 0.2,
        failures: Buckets | None = None,
    ) -> None:
        self.app = app
        self.keys = keys
        self.buckets = buckets or MemoryBuckets()
        self.failures = failures or MemoryBuckets()
        self.failure_burst = failure_burst
        self.failure_rate = failure_rate

    async def _guessing(self, client: str | None) -> ApiProblem | None:
        """429 for a client address whose wrong keys used up its allowance (its next wrong key
        would take a token it does not have): every ``/v1`` request of it waits, a valid key's
        too, so the answers tell a guesser nothing."""
        key = f"addr:{client}"
        tokens = await self.failures.peek(key, self.failure_rate, self.failure_burst)
        if tokens >= 1.0:
            return None
        wait = math.ceil((1.0 - tokens) / self.failure_rate)
        return ApiProblem(
            429,
            "too many requests with a wrong API key from this address",
            code="too-many-auth-failures",
            headers={"Retry-After": str(wait)},
            retry_after=wait,
        )

    def _principal(self, scope: Scope) -> Principal | ApiProblem:
        key = presented_key(Headers(scope=scope))
        client = (scope.get("client") or (None,))[0]
        if not self.keys.enabled:
            return self.keys.anonymous(client)
        if key is None:
            return ApiProblem(
                401,
                "an API key is required: Authorization: Bearer <key> or X-API-Key",
                code="unauthorized",
                headers={"WWW-Authenticate": 'Bearer realm="geosmooth"'},
            )
        principal = self.keys.authenticate(key)
        if principal is None:
            return ApiProblem(
                401,
                "the API key is not valid",
                code="invalid-api-key",
                headers={"WWW-Authenticate": 'Bearer realm="geosmooth", error="invalid_token"'},
            )
        return principal

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        gated = scope["path"].startswith("/v1/") or scope["path"] == "/v1"
        client = (scope.get("client") or (None,))[0]
        if gated and self.keys.enabled:
            blocked = await self._guessing(client)
            if blocked is not None:
                await _refuse(blocked, scope, receive, send)
                return
        principal = self._principal(scope)
        if isinstance(principal, ApiProblem):
            if gated:
                if principal.code == "invalid-api-key":
                    await self.failures.take(
                        f"addr:{client}", self.failure_rate, self.failure_burst
                    )
                await _refuse(principal, scope, receive, send)
                return
            principal = self.keys.anonymous((scope.get("client") or (None,))[0])
        scope.setdefault("state", {})["principal"] = principal
        if gated:
            limits = principal.limits
            wait = await self.buckets.take(principal.bucket, limits.rate_limit, limits.rate_burst)
            if wait > 0:
                problem = ApiProblem(
                    429,
                    f"rate limit of {limits.rate_limit:g} requests/s exceeded",
                    code="rate-limited",
                    headers={"Retry-After": str(math.ceil(wait))},
                    retry_after=math.ceil(wait),
                )
                await _refuse(problem, scope, receive, send)
                return
        await self.app(scope, receive, send)
