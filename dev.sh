#!/usr/bin/env bash
# The project's one set-up script: installs the system packages and a virtual environment,
# then runs the demo or the tests. Safe to re-run: each step is skipped when already done.
#   bash dev.sh demo     install everything, run the built-in default scene
#   bash dev.sh test     install everything, run ruff and the whole test suite (what CI runs)
#   bash dev.sh test --quick   the same without the tests marked slow (pytest -m "not slow")
#   bash dev.sh install  install only
set -euo pipefail
cd "$(dirname "$0")"
VENV=${VENV:-.venv}
PYTHON=${PYTHON:-python3}
# open3d needs libusb at import time; libgomp for its threads; pyvista's off-screen 3D views
# render through Mesa EGL (libegl1, libegl-mesa0, libgl1-mesa-dri), vtk links libGL and libXrender.
APT_PACKAGES="libusb-1.0-0 libgomp1 libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri libxrender1"
# the tests alone also need a headless browser: report.html is opened in it (not for the demo)
APT_PACKAGES_TEST="chromium"

log() { printf '[dev.sh %(%H:%M:%S)T] %s\n' -1 "$*"; }

install_system() {
  local missing="" p
  for p in $APT_PACKAGES; do
    dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"
  done
  command -v "$PYTHON" >/dev/null 2>&1 || missing="$missing python3"
  if command -v "$PYTHON" >/dev/null 2>&1 && ! "$PYTHON" -c 'import ensurepip, venv' 2>/dev/null; then
    missing="$missing python3-venv"
  fi
  if [ -n "$missing" ]; then
    local sudo=""
    [ "$(id -u)" = 0 ] || sudo=sudo
    log "installing system packages:$missing"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends $missing >/dev/null
  else
    log "system packages present: $APT_PACKAGES"
  fi
}

install_python() {
  local stamp
  stamp="$VENV/.installed-$(sha1sum pyproject.toml | cut -c1-12)"
  if [ -f "$stamp" ]; then
    log "virtual environment $VENV up to date"
    return
  fi
  log "creating $VENV and installing the project (about 1-2 minutes the first time)"
  "$PYTHON" -m venv "$VENV"
  "$VENV/bin/python" -m pip install -q --upgrade pip
  "$VENV/bin/python" -m pip install -q -e '.[dev]'
  touch "$stamp"
}

cmd=${1:-test}
[ $# -gt 0 ] && shift
if [ "$cmd" = test ]; then APT_PACKAGES="$APT_PACKAGES $APT_PACKAGES_TEST"; fi
install_system
install_python
export MPLBACKEND=Agg
case "$cmd" in
  install) ;;
  demo)
    log "running the default scene"
    "$VENV/bin/bathy" run --out out/default --overwrite
    ;;
  test)
    log "ruff"
    "$VENV/bin/ruff" check .
    "$VENV/bin/ruff" format --check .
    select=()
    if [ "${1:-}" = "--quick" ]; then
      shift
      select=(-m "not slow")  # the slow and statistical tests are left to the full run
    fi
    # one test file per worker, a worker per core (pytest-xdist): a file's module fixtures
    # (the CI suite subset, simulated surveys) are made once
    log "pytest -n auto --dist loadfile ${select[*]}"
    "$VENV/bin/python" -m pytest -n auto --dist loadfile "${select[@]}" "$@"
    ;;
  *)
    echo "usage: bash dev.sh demo|test [--quick]|install" >&2
    exit 2
    ;;
esac
