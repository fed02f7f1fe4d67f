"""API keys, tenants and the bounds that apply to each key.

Keys come from ``GEOSMOOTH_API_KEYS`` (comma separated, every key gets the default bounds) and
from ``GEOSMOOTH_API_KEYS_FILE``: one key per line as the sha256 hex digest of the key, then
optionally a name and per-key bounds, e.g.::

    # sha256(key), then an optional name and bounds
    9f86d081884c7d659a2feaa0c55ad015a3bf4f1b2b0b822cd15d6c15b0f00a08 ci-bot max_points=5000000

A request names its key with ``Authorization: Bearer <key>`` or ``X-API-Key: <key>``. The
tenant of a key is the first 16 hex digits of its sha256 digest: jobs belong to their tenant
and every other tenant gets 404 for them. Without any key configured there is no
authentication: every request is the anonymous principal (tenant ``None``) and rate limits
are kept per client address.
"""

from __future__ import annotations

import hashlib
import hmac
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from service.api.http.bounds import BoundError, Limits
from service.settings import ConfigError, Settings

__all__ = ["KeyRing", "Limits", "Principal", "key_digest", "presented_key", "tenant_of"]

_HEX = frozenset("0123456789abcdef")


@dataclass(frozen=True)
class Principal:
    """Who sent a request.

    Attributes
    ----------
    tenant : str or None
        Owner id of the key (``None``: authentication is off).
    name : str or None
        The key's name from the keys file, if any (logged, never answered).
    limits : Limits
        The key's bounds.
    bucket : str
        Rate-limit bucket: ``key:<tenant>``, or ``addr:<client address>`` without keys.
    """

    tenant: str | None
    name: str | None
    limits: Limits
    bucket: str


def key_digest(key: str) -> str:
    """sha256 hex digest of a key (what the keys file stores)."""
    return hashlib.sha256(key.encode("utf-8")).hexdigest()


def tenant_of(digest: str) -> str:
    """Tenant id of a key: the first 16 hex digits of its digest."""
    return digest[:16]


def presented_key(headers: Mapping[str, str]) -> str | None:
    """The key a request presents (``Authorization: Bearer`` first, then ``X-API-Key``)."""
    auth = headers.get("authorization")
    if auth:
        scheme, _, token = auth.strip().partition(" ")
        if scheme.lower() == "bearer" and token.strip():
            return token.strip()
    key = headers.get("x-api-key")
    return key.strip() if key and key.strip() else None


_FILE_ENV = "GEOSMOOTH_API_KEYS_FILE"


def _file_entries(path: Path, defaults: Limits) -> dict[str, tuple[str | None, Limits]]:
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else "unreadable"
        message = f"{_FILE_ENV}: cannot read the keys file ({why})"
        raise ConfigError(message, field=_FILE_ENV) from None
    out: dict[str, tuple[str | None, Limits]] = {}
    for number, line in enumerate(lines, 1):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        where = f"{_FILE_ENV} line {number}"
        digest = words[0].lower()
        if len(digest) != 64 or not set(digest) <= _HEX:
            raise ConfigError(f"{where}: expected a sha256 hex digest first", field=_FILE_ENV)
        name = next((w for w in words[1:] if "=" not in w), None)
        bounds = dict(w.split("=", 1) for w in words[1:] if "=" in w)
        try:
            out[digest] = (name, defaults.with_overrides(bounds))
        except BoundError as exc:
            raise ConfigError(f"{where}: {exc}", field=_FILE_ENV) from None
    return out


class KeyRing:
    """The configured API keys (by digest) and their bounds.

    Parameters
    ----------
    entries : mapping
        sha256 hex digest -> (name, limits).
    defaults : Limits
        Bounds of anonymous requests (no keys configured).
    """

    def __init__(self, entries: Mapping[str, tuple[str | None, Limits]], defaults: Limits) -> None:
        self._entries = dict(entries)
        self.defaults = defaults

    @classmethod
    def from_settings(cls, settings: Settings) -> KeyRing:
        """Keys of ``GEOSMOOTH_API_KEYS`` and ``GEOSMOOTH_API_KEYS_FILE``."""
        defaults = Limits.from_settings(settings)
        entries: dict[str, tuple[str | None, Limits]] = {}
        if settings.api_keys_file is not None:
            entries.update(_file_entries(Path(settings.api_keys_file), defaults))
        raw = settings.api_keys.get_secret_value() if settings.api_keys else ""
        for key in (k.strip() for k in raw.split(",")):
            if key:
                entries.setdefault(key_digest(key), (None, defaults))
        return cls(entries, defaults)

    @property
    def enabled(self) -> bool:
        """Whether requests must present a key."""
        return bool(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def anonymous(self, client: str | None) -> Principal:
        """The principal of a request when authentication is off."""
        return Principal(None, None, self.defaults, f"addr:{client or '-'}")

    def authenticate(self, key: str) -> Principal | None:
        """The principal of ``key``, ``None`` if it is not a configured key."""
        digest = key_digest(key)
        for known, (name, limits) in self._entries.items():
            if hmac.compare_digest(known, digest):
                tenant = tenant_of(digest)
                return Principal(tenant, name, limits, f"key:{tenant}")
        return None
