"""The deployment files agree with the code: compose services, settings names, entry points.

(The image's build steps themselves are proven by scripts/check-image.sh in CI.)
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

from service.settings import Settings
from tests.jobs.jobs_helpers import REPO

COMPOSE = Path(REPO) / "docker-compose.yml"
COMPOSE_S3 = Path(REPO) / "docker-compose.s3.yml"


def _load(path: Path) -> dict[str, Any]:
    return yaml.safe_load(path.read_text())  # type: ignore[no-any-return]


def _geosmooth_env(services: dict[str, Any]) -> set[str]:
    names = set()
    for service in services.values():
        names |= {k for k in (service.get("environment") or {}) if k.startswith("GEOSMOOTH_")}
    return names


def test_compose_profiles_embedded_and_distributed() -> None:
    services = _load(COMPOSE)["services"]
    profiles = {name: tuple(s.get("profiles") or ()) for name, s in services.items()}
    assert profiles == {"geosmooth": ("embedded",), "redis": ("distributed",),
                        "api": ("distributed",), "worker": ("distributed",)}  # fmt: skip
    dotenv = (Path(REPO) / ".env.example").read_text()
    assert re.search(r"^COMPOSE_PROFILES=embedded$", dotenv, re.M)
    worker, api = services["worker"], services["api"]
    assert "ports" not in worker  # scalable: --scale worker=N needs no host port
    assert worker["environment"]["GEOSMOOTH_QUEUE"] == api["environment"]["GEOSMOOTH_QUEUE"] == "rq"
    assert worker["volumes"] == api["volumes"]  # the shared blob directory
    redis_cmd = " ".join(services["redis"]["command"])
    assert "--appendonly yes" in redis_cmd and "--appendfsync always" in redis_cmd
    for name in ("api", "worker"):
        assert services[name]["depends_on"]["redis"]["condition"] == "service_healthy"


def test_every_setting_named_in_the_deployment_exists() -> None:
    fields = {f"GEOSMOOTH_{name.upper()}" for name in Settings.model_fields}
    named = _geosmooth_env(_load(COMPOSE)["services"])
    named |= _geosmooth_env(_load(COMPOSE_S3)["services"])
    assert named and named <= fields, named - fields


def test_the_worker_command_of_the_compose_file_runs() -> None:
    command = _load(COMPOSE)["services"]["worker"]["command"]
    assert command == ["geosmooth", "worker"]
    done = subprocess.run([sys.executable, "-m", "service.cli", "worker", "--help"],
                          capture_output=True, text=True, cwd=REPO)  # fmt: skip
    assert done.returncode == 0 and "geosmooth worker" in done.stdout and "--burst" in done.stdout
    local = subprocess.run([sys.executable, "-m", "service.cli", "worker"], capture_output=True,
                           text=True, cwd=REPO, env={"PATH": "/usr/bin:/bin",
                                                     "PYTHONPATH": str(REPO)})  # fmt: skip
    assert local.returncode == 2 and "GEOSMOOTH_QUEUE=rq" in local.stderr


def test_the_dockerfile_builds_with_the_scripts_the_image_check_runs() -> None:
    dockerfile = (Path(REPO) / "Dockerfile").read_text()
    assert "install-system-deps.sh --build" in dockerfile
    assert "install-system-deps.sh --runtime" in dockerfile
    assert dockerfile.count("scripts/docker-build-steps.sh") >= 2
    check = (Path(REPO) / "scripts" / "check-image.sh").read_text()
    for step in ("--build", "--runtime", "docker-build-steps.sh deps",
                 "docker-build-steps.sh package"):  # fmt: skip
        assert step in check
    install = (Path(REPO) / "scripts" / "install-system-deps.sh").read_text()
    build = re.search(r"^build_pkgs=\((.*)\)", install, re.M)
    assert build and "libc6-dev" in build.group(1).split()  # gcc --no-install-recommends lacks it


def _compose_value(value: str, env: dict[str, str]) -> str:
    """``${NAME:-default}`` as docker compose resolves it from ``env``."""
    return re.sub(r"\$\{(\w+):-([^}]*)\}", lambda m: env.get(m[1]) or m[2], str(value))


def _starts(environment: dict[str, str], host: str) -> None:
    """The checks ``geosmooth serve --host HOST`` runs before it binds (raises if refused)."""
    from service.api.http.auth import KeyRing
    from service.api.server import check_bind
    from service.settings import load_settings

    fields = {k.removeprefix("GEOSMOOTH_").lower(): v for k, v in environment.items()
              if k.startswith("GEOSMOOTH_") and v != ""}  # fmt: skip
    settings = load_settings(**fields)
    check_bind(host, KeyRing.from_settings(settings).enabled, settings.insecure_no_auth)


def test_the_image_serves_0000_only_with_keys_or_the_explicit_opt_out() -> None:
    from service.api.server import InsecureBind

    cmd = (Path(REPO) / "Dockerfile").read_text().rsplit("CMD", 1)[1]
    assert "--host 0.0.0.0" in cmd
    with pytest.raises(InsecureBind, match="GEOSMOOTH_API_KEYS"):
        _starts({}, "0.0.0.0")  # docker run without keys: refused, exit status 2
    _starts({"GEOSMOOTH_API_KEYS": "k1,k2"}, "0.0.0.0")
    services = _load(COMPOSE)["services"]
    for name in ("geosmooth", "api"):  # `docker compose up` with an empty environment starts
        env = {k: _compose_value(v, {}) for k, v in services[name]["environment"].items()}
        assert env["GEOSMOOTH_INSECURE_NO_AUTH"] == "true"
        _starts(env, "0.0.0.0")
        assert all(p.startswith("127.0.0.1:") for p in services[name]["ports"])  # loopback only
        keyed = {k: _compose_value(v, {"GEOSMOOTH_API_KEYS": "k"}) for k, v in
                 services[name]["environment"].items()}  # fmt: skip
        assert keyed["GEOSMOOTH_API_KEYS"] == "k"
