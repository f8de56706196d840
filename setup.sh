#!/usr/bin/env bash
# Set up twin on a fresh Debian machine with Python 3.11: the Debian packages its dependencies need,
# a virtual environment in .venv, and twin with every built-in backend (OMPL, CasADi, open3d, Ray,
# matplotlib) and the test tools.
# Safe to run again: it only installs what is missing.
set -euo pipefail
cd "$(dirname "$0")"

# libusb-1.0-0: open3d; libegl1 + libgl1-mesa-dri: PyBullet's headless EGL renderer; libgomp1: OpenMP.
debs=(libusb-1.0-0 libegl1 libgl1-mesa-dri libgomp1)
missing=()
for d in "${debs[@]}"; do dpkg -s "$d" >/dev/null 2>&1 || missing+=("$d"); done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing Debian packages: ${missing[*]}"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null 2>&1 || PY=python3
"$PY" -c 'import sys; assert sys.version_info[:2] >= (3, 11), "twin needs Python 3.11+"'
[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip 2>&1 | grep -v -i "warning" || true
.venv/bin/python -m pip install -q -e ".[all,test]" 2>&1 | grep -v -i "warning" || true
.venv/bin/python -c "import twin, pybullet, fcl, ruckig, toppra, ompl, casadi, open3d, ray, matplotlib" \
  || { echo "setup: install failed" >&2; exit 1; }
echo "setup: ready (.venv)"
