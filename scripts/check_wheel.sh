#!/usr/bin/env bash
# Build the wheel, install it into a fresh virtual environment outside the checkout and run it
# there from an empty folder: what a user gets from `pip install leafsim` must find its species,
# shaders and configs without this source tree.
set -euo pipefail
cd "$(dirname "$0")/.."
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
PY=${PYTHON:-python3}
echo "check_wheel: building the wheel"
.venv/bin/python -m pip wheel -q --no-deps -w "$work/dist" . >/dev/null
wheel=$(ls "$work"/dist/leafsim-*.whl)
echo "check_wheel: installing $(basename "$wheel") into a fresh venv"
"$PY" -m venv "$work/venv"
"$work/venv/bin/python" -m pip install -q "$wheel" >/dev/null
mkdir "$work/run" && cd "$work/run"
L="$work/venv/bin/leafsim"
"$work/venv/bin/python" - <<'PY'
import leafsim, pathlib, sys
here = pathlib.Path(leafsim.__file__).resolve()
assert "site-packages" in here.parts, f"leafsim imported from {here}, not from the installed wheel"
for kind in ("configs", "images", "shaders"):
    assert (here.parent / "data" / kind).is_dir(), f"the wheel lacks leafsim/data/{kind}"
print("check_wheel: leafsim from", here.parent)
PY
"$L" --version
"$L" species | head -3
"$L" run --species maple --quality draft --frames 5 --json > run.json
"$work/venv/bin/python" -c "import json; r = json.load(open('run.json')); assert r['frame'] == 5 and not r['nan'], r; print('check_wheel: run', r['frame'], 'frames,', r['particles'], 'particles')"
"$L" export --species oak --out oak.glb --json > export.json
test -s oak.glb
echo "check_wheel: export $(stat -c %s oak.glb) bytes; the installed wheel works outside the checkout"
