#!/usr/bin/env bash
# Proves the Docker image's build steps without a container engine (none runs in our CI):
#
# 1. base: a minimal Debian 12 root (debootstrap --variant=minbase), plus a stand-in for the
#    python:3.11-slim-bookworm base image: Debian's python3.11 + venv, and Python's C headers
#    unpacked WITHOUT their dependencies (the slim image has Python.h but no compiler, no
#    libc6-dev). Checked: no gcc, no libc6-dev in the base.
# 2. builder: a copy of the base runs `install-system-deps.sh --build` and
#    `docker-build-steps.sh deps` / `package`, the very commands of the Dockerfile's builder
#    stage (scikit-sparse is compiled against Debian's SuiteSparse here).
# 3. runtime: another copy of the base runs `install-system-deps.sh --runtime`, receives
#    /opt/geosmooth from the builder (as COPY --from=builder does), and runs the smoke test: the
#    service imports, the worker entry point answers --help, and a real smoothing job
#    factorizes with CHOLMOD on the runtime's OpenBLAS.
#
#   sudo scripts/check-image.sh            (root: debootstrap, chroot, mount)
# IMAGE_CHECK_DIR (default /tmp/geosmooth-image-check) keeps the base tarball between runs, so
# CI pays for debootstrap once per cache. Timings of each phase are printed at the end.
set -euo pipefail
SRC=$(cd "$(dirname "$0")/.." && pwd)
WORK=${IMAGE_CHECK_DIR:-/tmp/geosmooth-image-check}
MIRROR=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
BASE_TAR="$WORK/base-bookworm.tar"
declare -A SECONDS_OF=()
MOUNTS=()

phase() { SECONDS_OF[$1]=$(( $(date +%s) - $2 )); }
cleanup() {
  local m
  for (( i=${#MOUNTS[@]}-1; i>=0; i-- )); do m=${MOUNTS[$i]}; umount -l "$m" 2>/dev/null || true; done
}
trap cleanup EXIT

in_root() {  # in_root ROOT COMMAND...: run in a chroot with /proc, /dev and DNS
  local root=$1; shift
  if ! mountpoint -q "$root/proc"; then
    mount -t proc proc "$root/proc"; MOUNTS+=("$root/proc")
    mount --bind /dev "$root/dev"; MOUNTS+=("$root/dev")
  fi
  cp /etc/resolv.conf "$root/etc/resolv.conf"
  chroot "$root" /usr/bin/env -i PATH=/usr/local/bin:/usr/bin:/bin:/usr/sbin:/sbin HOME=/root \
    LANG=C.UTF-8 DEBIAN_FRONTEND=noninteractive PIP_CERT=/etc/ssl/certs/ca-certificates.crt "$@"
}

fresh_root() {  # fresh_root NAME: a new copy of the base
  local root="$WORK/$1"
  rm -rf "$root"; mkdir -p "$root"
  tar -C "$root" -xf "$BASE_TAR"
  echo "$root"
}

make_base() {
  local t0; t0=$(date +%s)
  local root="$WORK/base"
  rm -rf "$root"
  debootstrap --variant=minbase bookworm "$root" "$MIRROR" >"$WORK/debootstrap.log" 2>&1
  in_root "$root" apt-get update -qq
  in_root "$root" apt-get install -y -qq --no-install-recommends python3.11 python3.11-venv \
    ca-certificates >/dev/null
  # Trust the CAs the host trusts on top of Debian's (a TLS-intercepting proxy in CI): what a
  # docker build behind that proxy needs too. pip uses the system bundle (PIP_CERT above).
  if compgen -G "/usr/local/share/ca-certificates/*.crt" >/dev/null; then
    cp /usr/local/share/ca-certificates/*.crt "$root/usr/local/share/ca-certificates/"
    in_root "$root" update-ca-certificates >/dev/null
  fi
  # Python.h and friends, without libpython3.11-dev's dependencies (zlib1g-dev -> libc6-dev):
  in_root "$root" sh -c 'cd /tmp && apt-get download -qq libpython3.11-dev \
    && dpkg-deb -x libpython3.11-dev_*.deb / && rm -f libpython3.11-dev_*.deb'
  in_root "$root" ln -sf /usr/bin/python3.11 /usr/local/bin/python
  in_root "$root" ln -sf /usr/bin/python3.11 /usr/local/bin/python3
  in_root "$root" sh -c 'rm -rf /var/lib/apt/lists/* /var/cache/apt/archives/*.deb'
  cleanup; MOUNTS=()
  tar -C "$root" -cf "$BASE_TAR" .
  rm -rf "$root"
  phase base "$t0"
}

mkdir -p "$WORK"
if [[ ! -s "$BASE_TAR" ]]; then make_base; else SECONDS_OF[base]=0; fi

# -- builder -------------------------------------------------------------------------------
t0=$(date +%s)
BUILD=$(fresh_root builder)
for tool in gcc cc; do
  if chroot "$BUILD" sh -c "command -v $tool" >/dev/null; then echo "base has $tool" >&2; exit 1; fi
done
if chroot "$BUILD" dpkg-query -W libc6-dev >/dev/null 2>&1; then echo "base has libc6-dev" >&2; exit 1; fi
mkdir -p "$BUILD/src"
tar -C "$SRC" -cf - pyproject.toml README.md scripts service geosmooth clients/python \
  | tar -C "$BUILD/src" -xf -
in_root "$BUILD" sh -c 'cd /src && scripts/install-system-deps.sh --build && rm -rf /var/lib/apt/lists/*'
in_root "$BUILD" sh -c 'cd /src && PYTHON=python scripts/docker-build-steps.sh deps'
in_root "$BUILD" sh -c 'cd /src && PYTHON=python scripts/docker-build-steps.sh package'
cleanup; MOUNTS=()
phase builder "$t0"

# -- runtime -------------------------------------------------------------------------------
t0=$(date +%s)
RUN=$(fresh_root runtime)
cp "$SRC/scripts/install-system-deps.sh" "$RUN/tmp/"
in_root "$RUN" sh -c '/tmp/install-system-deps.sh --runtime && rm -rf /var/lib/apt/lists/* /tmp/install-system-deps.sh'
if chroot "$RUN" sh -c 'command -v gcc' >/dev/null; then echo "runtime has gcc" >&2; exit 1; fi
cp -a "$BUILD/opt/geosmooth" "$RUN/opt/geosmooth"
cp "$SRC/service/samples/"* "$RUN/tmp/" 2>/dev/null || true
in_root "$RUN" /opt/geosmooth/bin/python - <<'EOF'
import pathlib, subprocess, sys
import sksparse.cholmod, service.api.app, service.jobs.distributed.worker, rq, boto3  # noqa: F401
import geosmooth, geosmooth_client  # noqa: F401
import numpy as np
from service.core.geometry import Geometry
from service.core.params import SmoothingParams
from service.core import smooth

rng = np.random.default_rng(0)
t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
ring = Geometry(np.c_[np.cos(t), np.sin(t), np.zeros(400)] + rng.normal(0, 0.01, (400, 3)),
                edges=np.c_[np.arange(400), (np.arange(400) + 1) % 400])
result = smooth(ring, SmoothingParams(tau=0.01, solver="cholmod"))
report = result.report()
assert abs(report["phi"] - 0.01) / 0.01 <= 1e-3, report
help_text = subprocess.run([sys.executable, "-m", "service.jobs.distributed.worker", "--help"],
                           capture_output=True, text=True, check=True).stdout
assert "geosmooth worker" in help_text
print("runtime smoke test: CHOLMOD solve ok, phi =", report["phi"])
EOF
cleanup; MOUNTS=()
phase runtime "$t0"

rm -rf "$BUILD" "$RUN"
echo "check-image: base ${SECONDS_OF[base]} s (0: cached), builder ${SECONDS_OF[builder]} s, runtime ${SECONDS_OF[runtime]} s"
