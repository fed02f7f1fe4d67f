"""Service settings, read from the environment (prefix ``GEOSMOOTH_``).

Shared by the HTTP service, the job queue backends and their workers (so a worker needs no
``service.api`` import). Each setting is one field: its env variable, default and bounds. The
fields live in two groups, composed here into the one :class:`Settings`: the job store and
queue (:mod:`service.settings.jobs`) and the HTTP API (:mod:`service.settings.http`).
"""

from __future__ import annotations

import os
from functools import lru_cache
from typing import Any, ClassVar

from pydantic import ValidationError
from pydantic_settings import SettingsConfigDict

from service.settings.http import HttpSettings
from service.settings.jobs import JobSettings

__all__ = ["ConfigError", "Settings", "default", "get_settings", "load_settings"]


class Settings(HttpSettings, JobSettings):
    """Configuration of the HTTP service.

    Every field can be set with an environment variable ``GEOSMOOTH_<NAME>``, e.g.
    ``GEOSMOOTH_DATA_DIR=/data`` or ``GEOSMOOTH_SYNC_MAX_POINTS=50000``. The job store's and
    queue's fields come first (:class:`~service.settings.jobs.JobSettings`), then the HTTP
    API's (:class:`~service.settings.http.HttpSettings`).
    """

    model_config = SettingsConfigDict(env_prefix="GEOSMOOTH_", extra="ignore")


def default(name: str) -> Any:
    """The default of setting ``name``: the one place a default is written (the embedded
    queue's keyword defaults and the API's documented models read it from here)."""
    return Settings.model_fields[name].get_default(call_default_factory=True)


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """Settings from the environment, read once per process (:class:`ConfigError` if invalid)."""
    return load_settings()


class ConfigError(Exception):
    """An invalid setting; the message names its environment variable (one line).

    Attributes
    ----------
    field : str
        The environment variable, e.g. ``GEOSMOOTH_WORKERS``.
    message : str
        ``GEOSMOOTH_WORKERS='abc': Input should be a valid integer ...``.
    """

    code: ClassVar[str] = "invalid-configuration"
    title: ClassVar[str] = "Invalid configuration"
    status: ClassVar[int] = 500
    exit_code: ClassVar[int] = 2  # see the CLI's table, service/exit_codes.py

    def __init__(self, message: str, *, field: str) -> None:
        super().__init__(message)
        self.message = message
        self.field = field

    def to_dict(self) -> dict[str, object]:
        """``{code, message, field}``."""
        return {"code": self.code, "message": self.message, "field": self.field}


def load_settings(**overrides: Any) -> Settings:
    """:class:`Settings` from the environment and ``overrides``.

    Raises
    ------
    ConfigError
        Naming the first invalid setting's environment variable and value.
    """
    try:
        return Settings(**overrides)
    except ValidationError as exc:
        err = exc.errors()[0]
        name = str(err["loc"][0]) if err.get("loc") else "settings"
        env = f"GEOSMOOTH_{name.upper()}"
        value = overrides.get(name, os.environ.get(env, err.get("input")))
        shown = "***" if "key" in name else repr(value)
        why = " ".join(str(err["msg"]).removeprefix("Value error, ").split())
        raise ConfigError(f"{env}={shown}: {why}", field=env) from None
