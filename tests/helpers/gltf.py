"""Run the Khronos glTF-Validator (installed by scripts/setup.sh into .tools/) on a file."""

from __future__ import annotations

import json
import shutil
import subprocess

import pytest

from helpers.paths import HANG_S
from helpers.paths import REPO as ROOT

SCRIPT = ROOT / "tests" / "helpers" / "validate_gltf.js"
MODULE = ROOT / ".tools" / "node_modules" / "gltf-validator" / "package.json"


def validate(path) -> dict:
    """The validator's report of ``path`` (fails the test when the validator is missing)."""
    node = shutil.which("node")
    if node is None or not MODULE.exists():
        pytest.fail("the glTF-Validator is missing: run scripts/setup.sh (installs Node and .tools/node_modules/gltf-validator)")
    r = subprocess.run([node, str(SCRIPT), str(path)], capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def assert_clean(path) -> dict:
    """0 errors and 0 warnings (infos and hints allowed); returns the report."""
    rep = validate(path)
    issues = rep["issues"]
    bad = [m for m in issues["messages"] if m["severity"] <= 1]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, bad
    return rep
