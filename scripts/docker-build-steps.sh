#!/usr/bin/env bash
# The Python half of the Docker image's builder stage, run from the source directory:
#   scripts/docker-build-steps.sh deps      venv + third-party dependencies (a cached layer)
#   scripts/docker-build-steps.sh package   the geosmooth package itself + an import check
# The Dockerfile RUNs this script, and scripts/check-image.sh runs it in a debootstrapped
# Debian 12 root: the proof executes the very commands of the image build.
set -euo pipefail
VENV=${GEOSMOOTH_VENV:-/opt/geosmooth}
PYTHON=${PYTHON:-python3}
PIP=("$VENV/bin/pip" install --no-cache-dir --disable-pip-version-check -q)
case "${1:-}" in
  deps)
    "$PYTHON" -m venv "$VENV"
    "${PIP[@]}" --upgrade pip setuptools wheel
    "${PIP[@]}" ./clients/python  # geosmooth-client: a dependency, not on PyPI
    # runtime dependencies + the distributed backend (rq, redis, boto3), from pyproject.toml
    "$VENV/bin/python" -c 'import tomllib; p = tomllib.load(open("pyproject.toml", "rb"))["project"]; print("\n".join(p["dependencies"] + p["optional-dependencies"]["distributed"]))' \
      | grep -v '^geosmooth-client' > /tmp/requirements.txt
    "${PIP[@]}" -r /tmp/requirements.txt
    ;;
  package)
    "${PIP[@]}" --no-deps .
    "$VENV/bin/python" -c "import sksparse.cholmod, service.api.app, service.cli, service.jobs.distributed.worker, rq, boto3, geosmooth, geosmooth_client"
    ;;
  *) echo "usage: $0 deps|package" >&2; exit 2 ;;
esac
