"""Webhooks: a signed POST of the finished job (``JobRecord.public_dict()``) to ``webhook_url``.

Signature (Stripe-style, so existing verification code carries over)::

    Geosmooth-Signature: t=<unix seconds>,v1=<hex HMAC-SHA256(secret, "<t>.<raw body>")>

with the secret of ``GEOSMOOTH_WEBHOOK_SECRET`` (no secret configured: no header). Verify it
on the receiving side with :func:`verify_signature` (docs/http-api.md shows the same ten lines
to copy).

SSRF guard: a target whose host resolves to a loopback, private, link-local, multicast, reserved
or unspecified address, or to an IPv6 address that embeds one (IPv4-mapped, -compatible,
-translated, 6to4, NAT64, Teredo: :func:`embedded_ipv4`), is refused (:func:`check_webhook_url`,
at submit and again at every delivery, after a new DNS resolution), unless
``GEOSMOOTH_WEBHOOK_ALLOW_PRIVATE=true``. A delivery connects to the address
that was checked (the ``Host`` header and TLS server name keep the URL's host), so a DNS answer
that changes between the check and the connection (DNS rebinding) cannot redirect it. Redirects
are not followed.

Bounded: a try ends after ``webhook_timeout`` seconds in all (a watchdog shuts its socket, so a
receiver that trickles its answer a byte at a time cannot hold a delivery thread), and reads at
most :data:`MAX_ANSWER` bytes of the answer's body (the status line and headers are bounded by
h11's 16 KiB); an answer that is longer, endless or unfinished at the deadline is a failed try.

Delivery: at least once, retried with exponential backoff (1, 2, 4, ... s, at most 60 s between
tries) on connection errors and non-2xx answers, ``webhook_max_attempts`` tries in all.
"""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import ipaddress
import json
import socket
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any
from urllib.parse import urlsplit, urlunsplit

import httpcore

from service.jobs.errors import WebhookUrlRejected

if TYPE_CHECKING:
    from service.settings import Settings

__all__ = [
    "SIGNATURE_HEADER",
    "Target",
    "check_webhook_url",
    "deliver",
    "embedded_ipv4",
    "sign",
    "verify_signature",
]

SIGNATURE_HEADER = "Geosmooth-Signature"
_MAX_URL = 2048
_MAX_BACKOFF = 60.0
#: Bytes of a receiver's answer body read at most (a longer answer is a failed try).
MAX_ANSWER = 4096


@dataclass(frozen=True)
class Target:
    """A checked webhook target: the URL and the address to connect to."""

    url: str
    host: str
    address: str
    port: int


_NAT64 = ipaddress.ip_network("64:ff9b::/96")  # RFC 6052 well-known prefix
_NAT64_LOCAL = ipaddress.ip_network("64:ff9b:1::/48")  # RFC 8215 local-use translation
_V4_COMPATIBLE = ipaddress.ip_network("::/96")  # RFC 4291 (deprecated) ::a.b.c.d
_V4_TRANSLATED = ipaddress.ip_network("::ffff:0:0:0/96")  # RFC 2765 ::ffff:0:a.b.c.d

IPAddress = ipaddress.IPv4Address | ipaddress.IPv6Address


def embedded_ipv4(address: IPAddress) -> list[ipaddress.IPv4Address]:
    """The IPv4 addresses an IPv6 address carries (they decide where a packet ends up).

    IPv4-mapped ``::ffff:0:0/96``, IPv4-compatible ``::/96``, IPv4-translated
    ``::ffff:0:0:0/96``, 6to4 ``2002::/16``, NAT64 ``64:ff9b::/96`` and ``64:ff9b:1::/48``
    (last 32 bits), Teredo ``2001::/32`` (server and de-obfuscated client).
    """
    if not isinstance(address, ipaddress.IPv6Address):
        return []
    low = ipaddress.IPv4Address(int(address) & 0xFFFFFFFF)
    found: list[ipaddress.IPv4Address] = []
    if address.ipv4_mapped is not None:
        found.append(address.ipv4_mapped)
    if address.sixtofour is not None:
        found.append(address.sixtofour)
    if address.teredo is not None:
        found.extend(address.teredo)
    nets = (_NAT64, _NAT64_LOCAL, _V4_TRANSLATED, _V4_COMPATIBLE)
    if any(address in net for net in nets) and int(address) > 1:
        found.append(low)
    return found


def _refused_one(address: IPAddress) -> bool:
    return (
        address.is_loopback
        or address.is_private
        or address.is_link_local
        or address.is_multicast
        or address.is_reserved
        or address.is_unspecified
        or not address.is_global
    )


def _refused(address: IPAddress) -> bool:
    """Non-public, or carrying a non-public IPv4 address (6to4, NAT64, Teredo, mapped ...)."""
    return _refused_one(address) or any(_refused_one(v4) for v4 in embedded_ipv4(address))


def check_webhook_url(url: str, settings: Settings) -> Target:
    """Check a webhook URL (scheme, host, resolved addresses); the target to connect to.

    Raises
    ------
    WebhookUrlRejected
        A URL that is not ``http(s)://host[:port]/...``, whose host does not resolve, or that
        resolves to a refused address (unless ``settings.webhook_allow_private``).
    """
    if not isinstance(url, str) or len(url) > _MAX_URL:
        raise WebhookUrlRejected("webhook_url must be an http(s) URL", field="webhook_url")
    parts = urlsplit(url)
    try:
        port = parts.port or (443 if parts.scheme == "https" else 80)
    except ValueError:
        raise WebhookUrlRejected("webhook_url has an invalid port", field="webhook_url") from None
    if parts.scheme not in ("http", "https") or not parts.hostname or parts.username:
        raise WebhookUrlRejected(
            "webhook_url must be an http(s) URL with a host and no credentials",
            field="webhook_url",
        )
    host = parts.hostname
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError):
        raise WebhookUrlRejected(
            f"the host of webhook_url ({host}) does not resolve", field="webhook_url"
        ) from None
    addresses = [ipaddress.ip_address(str(info[4][0]).split("%", 1)[0]) for info in infos]
    if not settings.webhook_allow_private:
        bad = [a for a in addresses if _refused(a)]
        if bad:
            raise WebhookUrlRejected(
                f"webhook_url resolves to a non-public address ({bad[0]}); set"
                " GEOSMOOTH_WEBHOOK_ALLOW_PRIVATE=true to allow it",
                field="webhook_url",
            )
    return Target(url=url, host=host, address=str(addresses[0]), port=port)


def sign(secret: str, body: bytes, timestamp: int | None = None) -> str:
    """The ``Geosmooth-Signature`` header value for ``body``."""
    t = int(time.time()) if timestamp is None else int(timestamp)
    mac = hmac.new(secret.encode(), f"{t}.".encode() + body, hashlib.sha256).hexdigest()
    return f"t={t},v1={mac}"


def verify_signature(
    secret: str, body: bytes, header: str, tolerance: float = 300.0, now: float | None = None
) -> bool:
    """Whether ``header`` signs ``body`` with ``secret`` within ``tolerance`` seconds.

    The receiving side's check (docs/http-api.md has a dependency-free copy of it).
    """
    fields = dict(part.split("=", 1) for part in header.split(",") if "=" in part)
    try:
        t = int(fields["t"])
    except (KeyError, ValueError):
        return False
    expected = hmac.new(secret.encode(), f"{t}.".encode() + body, hashlib.sha256).hexdigest()
    fresh = abs((time.time() if now is None else now) - t) <= tolerance
    return fresh and hmac.compare_digest(expected, fields.get("v1", ""))


class _Deadline(httpcore.SyncBackend):
    """Sockets that are shut down when the try's total deadline passes (whatever they wait on:
    the connection, the TLS handshake, a status line or a body sent a byte at a time)."""

    def __init__(self) -> None:
        self._sockets: list[socket.socket] = []
        self._lock = threading.Lock()
        self._expired = False

    def connect_tcp(self, host: str, port: int, timeout: float | None = None,
                    local_address: str | None = None,
                    socket_options: Any = None) -> httpcore.NetworkStream:  # fmt: skip
        stream = super().connect_tcp(host, port, timeout, local_address, socket_options)
        with self._lock:
            self._sockets.append(stream.get_extra_info("socket"))
            if self._expired:
                self._shut()
        return stream

    def expire(self) -> None:
        with self._lock:
            self._expired = True
            self._shut()

    def _shut(self) -> None:
        for sock in self._sockets:
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)


def _post(target: Target, body: bytes, headers: dict[str, str], timeout: float) -> int:
    """POST to the checked address (Host and TLS server name from the URL); the status.

    The whole try (connection, TLS, request, status line, headers, answer body) ends within
    ``timeout`` seconds, and at most :data:`MAX_ANSWER` bytes of the answer's body are read: a
    longer, endless or unfinished answer raises :class:`WebhookAnswerRefused` (a failed try).
    """
    parts = urlsplit(target.url)
    literal = f"[{target.address}]" if ":" in target.address else target.address
    direct = urlunsplit((parts.scheme, f"{literal}:{target.port}", parts.path or "/",
                         parts.query, ""))  # fmt: skip
    extensions: dict[str, Any] = {"timeout": dict.fromkeys(("connect", "read", "write",
                                                            "pool"), timeout)}  # fmt: skip
    if parts.scheme == "https":
        extensions["sni_hostname"] = target.host
    backend = _Deadline()
    timer = threading.Timer(timeout, backend.expire)
    timer.daemon = True
    timer.start()
    try:
        with (
            httpcore.ConnectionPool(network_backend=backend, max_connections=1) as pool,
            pool.stream(
                "POST",
                direct,
                content=body,
                extensions=extensions,
                headers=[*headers.items(), ("Host", parts.netloc.rpartition("@")[2]),
                         ("Connection", "close")],
            ) as response,  # fmt: skip
        ):
            read = 0
            for chunk in response.iter_stream():
                read += len(chunk)
                if read > MAX_ANSWER:
                    raise WebhookAnswerRefused(f"answer body over {MAX_ANSWER} bytes")
            return response.status
    finally:
        timer.cancel()


class WebhookAnswerRefused(Exception):
    """The receiver's answer was longer than :data:`MAX_ANSWER` bytes (a failed try)."""


def deliver(
    url: str,
    payload: dict[str, Any],
    settings: Settings,
    *,
    stop: threading.Event | None = None,
) -> tuple[bool, int]:
    """POST ``payload`` to ``url`` until a 2xx answer or ``webhook_max_attempts`` tries.

    ``stop``: set it to abandon the retries (checked between tries).

    Returns
    -------
    delivered : bool
    tries : int
    """
    body = json.dumps(payload, separators=(",", ":"), allow_nan=False).encode()
    tries = 0
    for tries in range(1, settings.webhook_max_attempts + 1):
        if tries > 1:
            delay = min(_MAX_BACKOFF, settings.webhook_backoff * 2 ** (tries - 2))
            if (stop or threading.Event()).wait(delay) or (stop and stop.is_set()):
                return False, tries - 1
        headers = {"Content-Type": "application/json", "User-Agent": "geosmooth-webhook"}
        secret = settings.webhook_secret.get_secret_value() if settings.webhook_secret else ""
        if secret:
            headers[SIGNATURE_HEADER] = sign(secret, body)
        try:
            target = check_webhook_url(url, settings)
            status = _post(target, body, headers, settings.webhook_timeout)
        except WebhookUrlRejected:
            return False, tries  # refused now (e.g. DNS changed): trying again will not help
        except Exception:  # connection refused, timeout, TLS: retried
            continue
        if 200 <= status < 300:
            return True, tries
    return False, tries
