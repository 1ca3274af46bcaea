"""Session: the GUI's core (no OpenGL, no imgui)."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from leafsim.base.errors import LeafsimError
from leafsim.config.params import PARAMS
from leafsim.interactive.session import Session


@pytest.fixture(scope="module")
def built():
    return Session("oak", seed=0)


@pytest.fixture()
def s(built):
    built.reset()
    return built


def test_no_gl_imports():
    import ast

    import leafsim.interactive.session

    tree = ast.parse(open(leafsim.interactive.session.__file__).read())
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            names.add(node.module or "")
    bad = {n for n in names if n.split(".")[0] in ("moderngl", "imgui_bundle", "glfw", "OpenGL")}
    assert not bad and not any("render.renderer" in n or n.startswith("gui") for n in names), names


def test_build_and_step(s):
    c = s.counts()
    assert c["particles"] == s.model.particle_count > 100
    assert s.frame == 0 and s.water_fraction() == pytest.approx(1.0)
    ms = s.step(5)
    assert s.frame == 5
    assert set(ms) >= {"osmosis", "shrink", "dynamics", "colour"}
    assert s.water_fraction() < 1.0
    h = s.playback.history
    assert len(h["frame"]) == 2 and h["frame"][-1] == 5  # initial record + one per step() call
    assert np.isfinite(h["residual"][-1]) and h["kinetic"][-1] >= 0
    blade = float(s.state.particle_water[s.model.blade_particles].sum())  # the history plots the blade's
    assert h["water_T"][-1] + h["water_V"][-1] == pytest.approx(blade) and blade < s.total_water()
    # the margin band dries first (its thin boundary layer): below the interior, around the blade
    assert h["water_margin"][0] == pytest.approx(1.0) and h["water_interior"][0] == pytest.approx(1.0)
    assert h["water_margin"][-1] < h["water"][-1] < h["water_interior"][-1] < 1.0


def test_live_param_applies_at_once_and_keeps_state(s):
    s.step(3)
    gen, frame, water = s.generation, s.frame, s.state.particle_water.copy()
    pending = s.set_params({"osmosis.evaporation_top": 5.0})
    assert pending is False and not s.pending_rebuild
    assert s.params["osmosis.evaporation_top"] == 5.0
    assert s.simulator.params["osmosis.evaporation_top"] == 5.0
    assert s.generation == gen and s.frame == frame
    np.testing.assert_array_equal(s.state.particle_water, water)
    s.set_params({"osmosis.evaporation_top": PARAMS["osmosis.evaporation_top"].default})


def test_effect_toggle_is_live(s):
    s.set_params({"effects.osmosis": False})
    assert s.simulator.effects["osmosis"] is False
    w = s.total_water()
    ms = s.step(2)
    assert "osmosis" not in ms and s.total_water() == pytest.approx(w)
    s.set_params({"effects.osmosis": True})


def test_rebuild_param_is_staged_until_apply():
    s = Session("oak")
    n0, gen = s.model.particle_count, s.generation
    s.step(2)
    assert s.set_params({"mesh.spacing": 0.05}) is True
    assert s.pending_rebuild and s.model.particle_count == n0 and s.frame == 2
    s.apply_rebuild()
    assert s.building
    # the old model keeps running while the new one builds
    s.step(1)
    assert s.wait(120)
    assert not s.pending_rebuild and s.generation == gen + 1
    assert s.model.particle_count < n0 and s.frame == 0
    assert s.progress == 1.0 and s.progress_text.startswith("built")


def test_rebuild_async_progress_and_superseding():
    s = Session("oak", build=False)
    assert not s.ready
    seen = []
    s.rebuild_async()
    s.set_params({"mesh.spacing": 0.045})
    s.rebuild_async()  # supersedes the first build
    t0 = time.time()
    while s.building and time.time() - t0 < 120:
        seen.append((s.progress, s.progress_text))
        s.poll()
        time.sleep(0.01)
    s.poll()
    assert s.ready and s.build_error is None
    assert s.built_params["mesh.spacing"] == 0.045 and s.generation == 1
    assert all(0.0 <= p <= 1.0 for p, _ in seen)
    assert any(t for _, t in seen)


def test_build_error_keeps_old_model(monkeypatch, s):
    import leafsim.pipeline as leaf

    model = s.model

    def boom(*a, **k):
        raise LeafsimError("images/x.png: cannot read image (corrupt data)")

    monkeypatch.setattr(leaf, "leaf_shape", boom)
    s.rebuild_async()
    assert not s.wait(60)
    assert "cannot read image" in s.build_error
    assert s.model is model
    s.step(1)
    assert s.frame == 1


def test_reset(s):
    s.step(4)
    s.reset()
    assert s.frame == 0 and s.water_fraction() == pytest.approx(1.0)
    np.testing.assert_allclose(s.state.particle_q, s.model.particle_rest)


def test_seed_and_species_changes_need_rebuild(s):
    seed = s.seed
    assert not s.pending_rebuild
    assert s.set_seed(seed + 1) is True and s.pending_rebuild
    s.set_seed(seed)
    assert not s.pending_rebuild
    built, model = s.built_species, s.model
    assert built == s.species_key == "oak"
    try:
        s.set_species("maple", rebuild=False)  # staged: the oak stays on screen
        assert s.species_key == "maple" and s.pending_rebuild and s.model is model and not s.building
        # the species alone needs a rebuild, even with the built parameters in place
        s.set_params(s.built_params)
        assert not s.params.rebuild_differs(s.built_params) and s.seed == s.built_seed and s.pending_rebuild
        s.set_species(built, rebuild=False)
        assert s.species_key == built and not s.pending_rebuild
    finally:
        if s.species_key != built:
            s.set_species(built, rebuild=False)
        s.set_params(s.species.params)
    assert s.model is model and not s.pending_rebuild


def test_save_load_roundtrip(s, tmp_path):
    s.set_params({"osmosis.evaporation_top": 3.5, "veins.main.kappa": 7.0})
    path = tmp_path / "p.json"
    s.save_params(path)
    doc = json.loads(path.read_text())
    assert doc["species"] == "oak" and doc["params"]["osmosis.evaporation_top"] == 3.5
    assert [p.name for p in tmp_path.iterdir()] == ["p.json"]
    s.set_params({"osmosis.evaporation_top": 0.014, "veins.main.kappa": PARAMS["veins.main.kappa"].default})
    assert s.load_params(path) is True  # kappa is a rebuild parameter: staged
    assert s.params["osmosis.evaporation_top"] == 3.5 and s.simulator.params["osmosis.evaporation_top"] == 3.5
    assert s.params["veins.main.kappa"] == 7.0 and s.pending_rebuild
    s.set_params(s.built_params.with_overrides({"osmosis.evaporation_top": 0.014}))
    assert not s.pending_rebuild


def test_load_plain_object(s, tmp_path):
    p = tmp_path / "plain.json"
    p.write_text(json.dumps({"osmosis": {"diffusion": 0.01}}))
    s.load_params(p)
    assert s.params["osmosis.diffusion"] == 0.01
    s.set_params({"osmosis.diffusion": s.built_params["osmosis.diffusion"]})


@pytest.mark.parametrize("text,needle", [
    ("{not json", "malformed JSON"),
    ('{"params": {"osmosis.nope": 1}}', "unknown parameter 'osmosis.nope'"),
    ('{"osmosis.evaporation_top": -0.21}', "out of range"),
    ('{"params": {}, "extra": 1}', "unknown key 'extra'"),
    ('[1, 2]', "expected a JSON object"),
    ('{"params": {}, "species": "nosuch"}', "unknown species"),
])
def test_broken_preset_leaves_session_unchanged(s, tmp_path, text, needle):
    p = tmp_path / "bad.json"
    p.write_text(text)
    before = (s.params, s.seed, s.species_key, s.generation, s.frame)
    with pytest.raises(LeafsimError, match=needle.replace("(", r"\(")):
        s.load_params(p)
    assert (s.params, s.seed, s.species_key, s.generation, s.frame) == before


def test_save_to_missing_folder_fails_cleanly(s, tmp_path):
    with pytest.raises(LeafsimError, match="does not exist"):
        s.save_params(tmp_path / "nope" / "p.json")
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(LeafsimError):
        s.save_params(f / "p.json")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_render_mesh(s):
    from leafsim.appearance.mesh import validate_mesh

    s.step(2)
    m = s.render_mesh()
    validate_mesh(m)
    nT = int((s.model.particle_layer == 0).sum())
    assert m.positions.shape == (nT, 3) and m.top_positions.shape == (s.model.particle_count - nT, 3)
    assert m.triangles.shape == (s.model.tri_count, 3)
    assert m.springs.shape == (s.model.spring_count, 2)
    assert set(np.unique(m.spring_kind)) == {0, 1, 2, 3}
    assert set(m.scalars) == {"mass", "water", "chlorophyll", "carotenoid", "anthocyanin", "browning", "necrosis", "crinkle"}
    assert m.texture_rgba is not None and m.texture_rgba.shape[2] == 4  # oak has a photo
    assert m.tint is not None and m.vein_lines
    u = s.render_update()
    assert u["positions"].shape == (nT, 3) and u["colours"].shape == (nT, 3)


def test_render_mesh_drawn_species():
    s = Session("maple", overrides={"mesh.spacing": 0.06})
    m = s.render_mesh()
    assert m.texture_rgba is None and m.tint is None and s.photo_rgba is None
    assert np.all((m.colours > 0) & (m.colours < 1))
