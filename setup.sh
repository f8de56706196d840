#!/usr/bin/env bash
# Set up twin on a fresh Debian machine with Python 3.11: the Debian packages its dependencies need,
# a virtual environment in .venv, and twin with every built-in backend (OMPL, CasADi, open3d, Ray,
# matplotlib) and the test tools.
# Safe to run again: it only installs what is missing (or what differs from the pinned versions).
#
# Versions: by default every package is installed at the version constraints.txt pins (what CI passed
# with), so two machines set up a month apart run the same code. TWIN_RESOLVE=latest ./setup.sh resolves
# the newest releases instead (to try them, or where a pin has no build for the platform).
set -euo pipefail
cd "$(dirname "$0")"
case "${TWIN_RESOLVE:-locked}" in
  locked) pins=(-c constraints.txt) ;;  # also moves an installed package back to its pin
  latest) pins=(--upgrade --upgrade-strategy eager) ;;  # also moves installed packages to the newest
  *) echo "setup: TWIN_RESOLVE must be 'locked' (the default: constraints.txt) or 'latest', got '$TWIN_RESOLVE'" >&2
     exit 2 ;;
esac

# Run a command with its output kept aside: nothing shows when it succeeds (pip's and setuptools' notices, the
# fragments of a build's warning boxes, "debconf: delaying package configuration ..."); when it fails, its
# errors (from the first line that says error, else its last 20 lines) and where the whole output is.
quietly() {  # quietly WHAT COMMAND...
  local what=$1 log; shift
  log=$(mktemp "${TMPDIR:-/tmp}/twin-setup.XXXXXX")
  if "$@" >"$log" 2>&1; then rm -f "$log"; return 0; fi
  local first; first=$(grep -n -i -m 1 -E '^error\b' "$log" | cut -d: -f1)
  if [ -n "$first" ]; then tail -n "+$first" "$log"; else tail -n 20 "$log"; fi >&2
  echo "setup: $what failed (its whole output: $log)" >&2
  return 1
}

# libusb-1.0-0: open3d; libegl1 + libgl1-mesa-dri: PyBullet's headless EGL renderer; libgomp1: OpenMP.
debs=(libusb-1.0-0 libegl1 libgl1-mesa-dri libgomp1)
missing=()
for d in "${debs[@]}"; do dpkg -s "$d" >/dev/null 2>&1 || missing+=("$d"); done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing Debian packages: ${missing[*]}"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  quietly "apt-get update" $SUDO apt-get update -qq
  quietly "apt-get install ${missing[*]}" \
    $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null 2>&1 || PY=python3
"$PY" -c 'import sys; assert sys.version_info[:2] >= (3, 11), "twin needs Python 3.11+"'
[ -x .venv/bin/python ] || "$PY" -m venv .venv
pip_install() {  # pip's output shown only when it fails; its failure ends the setup with a hint
  if ! quietly "pip install $*" .venv/bin/python -m pip install -q "$@" "${pins[@]}"; then
    [ "${TWIN_RESOLVE:-locked}" = locked ] && echo "setup: constraints.txt pins the versions CI runs (Linux x86_64, Python 3.11);" \
      "TWIN_RESOLVE=latest ./setup.sh resolves the newest releases instead" >&2
    exit 1
  fi
}
pip_install --upgrade pip
echo "setup: installing twin and its backends into .venv (pip; minutes the first time)"
pip_install -e ".[all,test]"
quietly "the import check (twin and its backends)" \
  .venv/bin/python -c "import twin, pybullet, fcl, ruckig, toppra, ompl, casadi, open3d, ray, matplotlib" || exit 1
# Rerun (recordings, twin[viz]) sends usage statistics unless told not to; this turns them off for this user
# (`.venv/bin/rerun analytics enable` turns them back on)
quietly "rerun analytics disable" .venv/bin/rerun analytics disable || exit 1
echo "setup: ready (.venv, versions: ${TWIN_RESOLVE:-locked})"
