#!/usr/bin/env bash
# Set up leafsim on a fresh Debian/Ubuntu machine: a Python >= 3.11, the system libraries
# Debian must provide (Mesa EGL/GL for offscreen rendering, Xvfb for GUI tests, the venv
# module), a virtual environment .venv installed from this project's own pyproject.toml, and
# the Khronos glTF-Validator (npm, with Node.js when no node is on PATH) in .tools/ for the
# export tests.  Safe to run again: it only installs what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

SUDO=""
[ "$(id -u)" = 0 ] || SUDO="sudo"
apt_install() {  # apt_install PKG...: install Debian packages (quietly)
  echo "setup: installing Debian packages: $*"
  $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "$@" >/dev/null
}

# a Python the project supports (pyproject.toml: requires-python >= 3.11)
PY=${PYTHON:-}
if [ -z "$PY" ]; then
  for cand in python3 python3.13 python3.12 python3.11; do
    if command -v "$cand" >/dev/null 2>&1 && "$cand" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
      PY=$cand; break
    fi
  done
fi
if [ -z "$PY" ] || ! "$PY" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
  tried=${PY:-python3}
  echo "setup: leafsim needs Python >= 3.11 ($tried is $("$tried" --version 2>&1 | head -1 || true)); install python3.11 or newer, or set PYTHON=/path/to/python3.11" >&2
  exit 1
fi

# what Debian must provide: Mesa EGL/GL (offscreen rendering), Xvfb (GUI tests), and the venv
# module (Debian and Ubuntu ship it apart from Python: python3.X-venv)
DEB_PKGS="libegl1 libegl-mesa0 libgl1-mesa-dri libgles2 libglx-mesa0 xvfb xauth"
missing=""
for p in $DEB_PKGS; do
  dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"
done
venv_ok() { [ -x .venv/bin/python ] && .venv/bin/python -m pip --version >/dev/null 2>&1; }
if ! venv_ok && ! "$PY" -c 'import ensurepip, venv' >/dev/null 2>&1; then
  missing="$missing $("$PY" -c 'import sys; print(f"python{sys.version_info[0]}.{sys.version_info[1]}-venv")')"
fi
if [ -n "$missing" ]; then
  # shellcheck disable=SC2086
  apt_install $missing
fi

if ! venv_ok; then
  # a .venv without pip is what a `python3 -m venv` leaves behind when the venv module was
  # missing: make it again
  [ -e .venv ] && { echo "setup: .venv has no pip; making it again"; rm -rf .venv; }
  echo "setup: creating .venv with $PY"
  "$PY" -m venv .venv
  rm -f .venv/.leafsim-installed
fi
stamp=.venv/.leafsim-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  echo "setup: installing leafsim and its dependencies into .venv"
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q -e ".[test]"
  touch "$stamp"
fi
# the Khronos glTF-Validator (npm) for the export tests; the app does not need it, so a machine
# without Node.js or the npm registry still gets a working app (the export tests then fail,
# naming the missing validator)
GLTF_VALIDATOR="gltf-validator@2.0.0-dev.3.10"
if [ ! -f .tools/node_modules/gltf-validator/package.json ]; then
  if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
    apt_install nodejs npm || echo "setup: warning: could not install Node.js and npm; the glTF export tests need them" >&2
  fi
  if command -v npm >/dev/null 2>&1; then
    echo "setup: installing the Khronos glTF-Validator ($GLTF_VALIDATOR) into .tools/"
    mkdir -p .tools
    npm install --prefix .tools --no-audit --no-fund --silent "$GLTF_VALIDATOR" >/dev/null \
      || echo "setup: warning: could not install $GLTF_VALIDATOR from npm; the glTF export tests need it" >&2
  fi
fi
# compile the numba kernels now (cached per source version under ~/.cache/leafsim), so the
# first window or command does not spend a minute on it (they would, announced:
# leafsim/interactive/warmup.py); nothing to do when this version's are cached already
.venv/bin/python -c "from leafsim.interactive.warmup import warm_up_cli; warm_up_cli()"
echo "setup: ready (.venv/bin/leafsim)"
