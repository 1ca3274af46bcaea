"""The package's stage folders import only downwards, form no import circle, and keep OpenGL
and imgui out of the core (tests/helpers/layers.py states the contract)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

import leafsim
from helpers import layers

ROOT = Path(leafsim.__file__).resolve().parent


def test_every_module_belongs_to_a_stage():
    assert layers.unknown_stages(ROOT) == []


def test_imports_point_down_the_stage_order():
    assert layers.upward(ROOT) == []


def test_no_import_circles():
    assert layers.circles(ROOT) == []


def test_no_opengl_or_imgui_in_the_core():
    assert layers.gl_outside(ROOT) == []


@pytest.fixture
def copy(tmp_path) -> Path:
    dst = tmp_path / "leafsim"
    shutil.copytree(ROOT, dst, ignore=shutil.ignore_patterns("__pycache__", "*.ttf"))
    return dst


def test_the_contract_catches_an_upward_import(copy):
    """The check itself: a deliberate import from the simulation up into the GUI is caught."""
    f = copy / "sim" / "run.py"
    f.write_text(f.read_text() + "\n\ndef _bad():\n    from leafsim.gui.app import LeafApp  # noqa: F401\n")
    found = layers.upward(copy)
    assert len(found) == 1 and "leafsim.sim.run (stage sim) imports leafsim.gui.app (stage gui)" in found[0]


def test_the_contract_catches_a_circle_and_gl_in_the_core(copy):
    (copy / "base" / "geometry.py").write_text((copy / "base" / "geometry.py").read_text()
                                               + "\nfrom leafsim.base import fileio  # noqa: F401,E402\n")
    (copy / "base" / "fileio.py").write_text((copy / "base" / "fileio.py").read_text()
                                             + "\nfrom leafsim.base import geometry  # noqa: F401,E402\nimport moderngl  # noqa: F401,E402\n")
    assert ["leafsim.base.fileio", "leafsim.base.geometry"] in layers.circles(copy)
    assert any("leafsim.base.fileio imports moderngl" in x for x in layers.gl_outside(copy))


def test_sibling_stages_do_not_import_each_other(copy):
    f = copy / "scene" / "run.py"
    f.write_text(f.read_text() + "\nfrom leafsim.compare import metrics  # noqa: F401,E402\n")
    assert any("imports leafsim.compare.metrics (stage compare)" in x for x in layers.upward(copy))


def test_the_architecture_page_shows_the_contract():
    """docs/architecture.md's table lists the stages row by row as the contract orders them."""
    from helpers.paths import REPO

    text = (REPO / "docs" / "architecture.md").read_text(encoding="utf-8")
    rows = [line.split("|")[1:3] for line in text.splitlines() if line.startswith("| ") and "`" in line.split("|")[2]]
    found = [(int(r.strip()), s.strip().strip("`").rstrip("/").removesuffix(".py")) for r, s in rows if r.strip().isdigit()]
    expected = [(i + 1, stage) for i, row in enumerate(layers.LAYERS) for stage in row if stage != "__main__"]
    assert found == expected
