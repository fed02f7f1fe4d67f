#!/usr/bin/env bash
# The one place that installs Debian packages for geosmooth.
# Used by the Makefile (make setup / run / test), .ci/run and the Dockerfile, so CI exercises the
# same install path as the Docker image. Idempotent: does nothing when everything is present.
#
#   scripts/install-system-deps.sh            runtime + build packages (SuiteSparse, OpenBLAS, venv),
#                                             plus what the tests start (chromium, redis-server) and
#                                             scripts/check-image.sh uses (debootstrap)
#   scripts/install-system-deps.sh --build    only what compiling scikit-sparse needs (Docker builder,
#                                             whose Python is the image's own, not Debian's)
#   scripts/install-system-deps.sh --runtime  only what the running service needs (Docker final stage)
#   scripts/install-system-deps.sh --bench    also what the peer libraries of benchmarks/ need
set -euo pipefail

# gcc with --no-install-recommends does not pull libc6-dev (crt1.o, libc headers): name it.
build_pkgs=(libsuitesparse-dev libopenblas0-pthread gcc libc6-dev)
python_pkgs=(python3-dev python3-venv)  # Debian's python3 needs these for venv + C extensions
runtime_pkgs=(libcholmod3 libopenblas0-pthread)
# tests/web drive chromium with Playwright and Firefox ESR over WebDriver BiDi on an Xvfb display
# (WebGL: Mesa's software rasterizer); no browser is ever downloaded (fonts: screenshots);
# tests/jobs start a real redis-server; scripts/check-image.sh builds Debian 12 roots; the
# Ctrl-C tests read a socket's acknowledged bytes with `ss` (iproute2); tests/docs run the
# documentation's curl recipes; tests/io read every output back with Open3D (libusb, libgl1,
# libgomp1 are what its wheel loads).
test_pkgs=(chromium firefox-esr xvfb libgl1-mesa-dri fonts-dejavu-core redis-server debootstrap
           iproute2 curl libusb-1.0-0 libgl1 libgomp1)
pkgs=("${build_pkgs[@]}" "${python_pkgs[@]}")
bench_pkgs=(libusb-1.0-0 libgl1 libgomp1)
case "${1:-}" in
  --build) pkgs=("${build_pkgs[@]}") ;;
  --runtime) pkgs=("${runtime_pkgs[@]}") ;;
  --bench) pkgs+=("${bench_pkgs[@]}") ;;
  --test|"") pkgs+=("${test_pkgs[@]}") ;;
  *) echo "usage: $0 [--build|--runtime|--bench|--test]" >&2; exit 2 ;;
esac

missing=()
for p in "${pkgs[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
if [[ ${#missing[@]} -eq 0 ]]; then
  exit 0
fi

SUDO=""
if [[ "$(id -u)" != "0" ]]; then
  if command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
    echo "install-system-deps: need root (or sudo) to install: ${missing[*]}" >&2; exit 1
  fi
fi
echo "install-system-deps: installing ${missing[*]}" >&2
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
# Make sure the BLAS alternative points at OpenBLAS (reference BLAS is 5-8x slower for CHOLMOD).
if command -v update-alternatives >/dev/null 2>&1; then
  for alt in $(update-alternatives --get-selections 2>/dev/null | awk '/^lib(blas|lapack)\.so\.3-/ {print $1}'); do
    target=$(update-alternatives --list "$alt" 2>/dev/null | grep -m1 openblas-pthread || true)
    if [[ -n "$target" ]]; then $SUDO update-alternatives --set "$alt" "$target" >/dev/null; fi
  done
fi
