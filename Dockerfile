# syntax=docker/dockerfile:1
# geosmooth HTTP service (and, with GEOSMOOTH_QUEUE=rq, its distributed workers).
#   docker build -t geosmooth .
#   docker run -p 127.0.0.1:8000:8000 -v geosmooth-data:/data geosmooth
#   docker compose --profile distributed up --scale worker=4      (see docker-compose.yml)
# Base: Debian 12 (bookworm); SuiteSparse 5.12 (libcholmod3) matches scikit-sparse 0.4.16.
# No container engine runs in CI: scripts/check-image.sh runs these same steps (the install
# script's --build/--runtime modes, scripts/docker-build-steps.sh) in debootstrapped Debian 12
# roots; see the README's Docker section for what that proves and what it does not.

ARG PYTHON_IMAGE=python:3.11-slim-bookworm

# ---------------------------------------------------------------------------- builder
FROM ${PYTHON_IMAGE} AS builder

ENV PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PIP_NO_CACHE_DIR=1 \
    PYTHONDONTWRITEBYTECODE=1

WORKDIR /src
# The one place that installs Debian packages (also used by make and CI): gcc, libc6-dev and
# SuiteSparse's headers to compile scikit-sparse.
COPY scripts/install-system-deps.sh scripts/docker-build-steps.sh scripts/
RUN scripts/install-system-deps.sh --build \
    && rm -rf /var/lib/apt/lists/*

# Dependencies first (this layer stays cached while only the sources change; scikit-sparse is
# compiled here against Debian's SuiteSparse), then the package itself.
COPY pyproject.toml README.md ./
# The pure-Python client (a dependency of the server package, not on PyPI) is installed first.
COPY clients/python/ clients/python/
RUN scripts/docker-build-steps.sh deps
COPY service/ service/
COPY geosmooth/ geosmooth/
RUN scripts/docker-build-steps.sh package

# ---------------------------------------------------------------------------- runtime
FROM ${PYTHON_IMAGE} AS runtime

LABEL org.opencontainers.image.title="geosmooth" \
      org.opencontainers.image.description="Smoothing of meshes, polylines and point clouds over HTTP" \
      org.opencontainers.image.licenses="BSD-3-Clause"

COPY scripts/install-system-deps.sh /tmp/install-system-deps.sh
RUN /tmp/install-system-deps.sh --runtime \
    && rm -rf /var/lib/apt/lists/* /tmp/install-system-deps.sh

COPY --from=builder /opt/geosmooth /opt/geosmooth

RUN groupadd --system --gid 10001 geosmooth \
    && useradd --system --uid 10001 --gid geosmooth --home-dir /data --no-create-home \
       --shell /usr/sbin/nologin geosmooth \
    && mkdir -p /data \
    && chown geosmooth:geosmooth /data

# BLAS threads per job: GEOSMOOTH_THREADS_PER_JOB (default cores / GEOSMOOTH_WORKERS), set by
# the queue in each job process (threadpoolctl); no OPENBLAS_NUM_THREADS here, it would cap them.
ENV PATH=/opt/geosmooth/bin:$PATH \
    PYTHONUNBUFFERED=1 \
    PYTHONDONTWRITEBYTECODE=1 \
    GEOSMOOTH_DATA_DIR=/data \
    GEOSMOOTH_PORT=8000

USER geosmooth
WORKDIR /data
VOLUME ["/data"]
EXPOSE 8000

# No curl in slim images: probe /healthz with the venv's Python, on GEOSMOOTH_PORT.
HEALTHCHECK --interval=30s --timeout=5s --start-period=20s --retries=3 \
    CMD ["python", "-c", "import os, sys, urllib.request; url = 'http://127.0.0.1:%s/healthz' % os.environ.get('GEOSMOOTH_PORT', '8000'); sys.exit(0 if urllib.request.urlopen(url, timeout=4).status == 200 else 1)"]

# SIGTERM (docker stop) shuts down gracefully: running jobs are put back in the queue (the API
# with the embedded queue, and `geosmooth worker` alike).
STOPSIGNAL SIGTERM
CMD ["sh", "-c", "exec geosmooth serve --host 0.0.0.0 --port \"$GEOSMOOTH_PORT\" --data-dir /data"]
