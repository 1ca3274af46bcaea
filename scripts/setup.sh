#!/usr/bin/env bash
# Set up leafsim on a fresh Debian/Ubuntu machine: the system libraries Debian must provide
# (Mesa EGL/GL for offscreen rendering, Xvfb for GUI tests, Node.js + npm for the glTF
# validator when no node is on PATH), a virtual environment .venv installed from this
# project's own pyproject.toml, and the Khronos glTF-Validator (npm) in .tools/ (the export
# tests run it).  Safe to run again: it only installs what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

DEB_PKGS="libegl1 libegl-mesa0 libgl1-mesa-dri libgles2 libglx-mesa0 xvfb xauth"
missing=""
for p in $DEB_PKGS; do
  dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"
done
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
  missing="$missing nodejs npm"
fi
if [ -n "$missing" ]; then
  SUDO=""
  [ "$(id -u)" = 0 ] || SUDO="sudo"
  echo "setup: installing Debian packages:$missing"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq $missing >/dev/null
fi

PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv"
  "$PY" -m venv .venv
fi
stamp=.venv/.leafsim-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  echo "setup: installing leafsim and its dependencies into .venv"
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q -e ".[test]"
  touch "$stamp"
fi
GLTF_VALIDATOR="gltf-validator@2.0.0-dev.3.10"
if [ ! -f .tools/node_modules/gltf-validator/package.json ]; then
  echo "setup: installing the Khronos glTF-Validator ($GLTF_VALIDATOR) into .tools/"
  mkdir -p .tools
  npm install --prefix .tools --no-audit --no-fund --silent "$GLTF_VALIDATOR" >/dev/null
fi
# compile the numba kernels now (cached per source version under ~/.cache/leafsim), so the
# first window or command does not spend a minute on it (they would, announced:
# leafsim/interactive/warmup.py); nothing to do when this version's are cached already
.venv/bin/python -c "from leafsim.interactive.warmup import warm_up_cli; warm_up_cli()"
echo "setup: ready (.venv/bin/leafsim)"
