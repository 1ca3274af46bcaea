"""Each species ages along its own trajectory (docs/method.md §7): the colours a photo species
takes while it dries, read off the view's per-particle colours (what the renderer draws), in
the compare metrics' colour classes."""

from __future__ import annotations

import numpy as np
import pytest

from leafsim.appearance.photo import species_photo_rgba
from leafsim.appearance.reflectance import linear_to_srgb
from leafsim.appearance.view import LeafView
from leafsim.compare.metrics import CLASSES, _lab, classify_lab
from leafsim.config.species import get_species
from leafsim.pipeline import build_leaf
from leafsim.sim.model import LAYER_T
from leafsim.sim.run import Run
from leafsim.sim.simulator import Simulator

COARSE = {"mesh.spacing": 0.04}


def _classes_while_drying(key: str, every: int = 150) -> list[np.ndarray]:
    """Area-weighted colour-class shares of the blade (layer T) every ``every`` frames until
    2 % of the water is left."""
    sp = get_species(key)
    params = sp.params.with_overrides(COARSE)
    _, _, model = build_leaf(sp, params, seed=0)
    sim = Simulator(model, params, effects=("osmosis", "colour"), seed=0)
    st = sim.state()
    view = LeafView(model, species_photo_rgba(sp, params), st.pigments.copy(), photo_tint=False, photo_colour=sp.photo_colour)
    area = model.particle_area[model.particle_layer == LAYER_T]
    w0 = float(model.particle_water0.sum())
    out = []
    run = Run(model, simulator=sim, state=st, name=key)

    def look(state):
        rgb, _ = view.colours(state, params)
        cls = classify_lab(_lab((linear_to_srgb(rgb) * 255).astype(np.uint8)[None])[0])
        out.append(np.bincount(cls, weights=area, minlength=len(CLASSES)) / area.sum())

    look(st)
    for _ in run.frames(until=lambda s: float(s.particle_water.sum()) <= 0.02 * w0):
        if run.state.frame % every == 0:
            look(run.state)
    look(run.state)
    return out


def _share(shares, name):
    return np.array([s[CLASSES.index(name)] for s in shares])


@pytest.mark.parametrize("key", ["grapevine", "oak", "aspen"])
def test_a_green_photo_never_turns_purple_or_red_unless_the_species_makes_anthocyanins(key):
    shares = _classes_while_drying(key)
    assert _share(shares, "green")[0] > 0.9  # the young leaf is the photo's green
    assert _share(shares, "purple").max() < 0.01
    assert _share(shares, "red").max() < 0.1  # these species make (almost) no anthocyanins
    # it turns: yellow (aspen, grapevine) or tan (oak, "yellow" and "orange" classes) first,
    # then brown; the dried leaf has no green left
    assert (_share(shares, "yellow") + _share(shares, "orange")).max() > 0.4
    assert _share(shares, "green")[-1] < 0.05
    assert _share(shares, "brown")[-1] + _share(shares, "yellow")[-1] > 0.8


def test_red_cultivar_turns_red():
    """A red-berried cultivar's leaves turn red to purplish red (anthocyanins): mostly red, a
    purple tinge at most on a few per cent of the blade (measured 5 % at its most)."""
    red = _classes_while_drying("grapevine_red")
    assert _share(red, "red").max() > 0.5 and _share(red, "purple").max() < 0.1


def test_photo_detail_follows_the_living_tissue():
    """The "detail" albedo's chroma (the photo's own fine hues): the young photo species' young
    leaf carries the photo's chromaticity at full weight; tissue that lost its chlorophyll
    carries none; a drawn species and a species photographed senescent carry no chroma."""

    sp = get_species("grapevine")
    params = sp.params.with_overrides(COARSE)
    _, _, model = build_leaf(sp, params, seed=0)
    sim = Simulator(model, params, effects=("osmosis", "colour"), seed=0)
    st = sim.state()
    view = LeafView(model, species_photo_rgba(sp, params), st.pigments.copy(), photo_tint=False, photo_colour=sp.photo_colour)
    c = view.chroma(st, params)
    nT = int((model.particle_layer == LAYER_T).sum())
    assert c.shape == (nT, 4) and np.isfinite(c).all()
    assert np.allclose(c[:, :3] @ np.array([0.2126, 0.7152, 0.0722]), 1.0, atol=1e-3)
    assert np.allclose(c[:, 3], 1.0)
    mesh = view.mesh(st, params)
    assert np.array_equal(mesh.chroma, c) and np.array_equal(view.update(st, params)["chroma"], c)
    dead = st.copy()
    dead.pigments.chlorophyll[:] = 0.5 * st.pigments.chlorophyll
    assert np.allclose(view.chroma(dead, params)[:, 3], 0.5)
    dead.pigments.chlorophyll[:] = 0.0
    assert np.allclose(view.chroma(dead, params)[:, 3], 0.0)
    assert view.chroma(st, params.with_overrides({"render.texture": False})) is None
    for key in ("maple", "hornbeam"):  # drawn; photographed senescent
        sp2 = get_species(key)
        p2 = sp2.params.with_overrides(COARSE)
        _, _, m2 = build_leaf(sp2, p2, seed=0)
        s2 = Simulator(m2, p2, effects=("colour",), seed=0).state()
        photo = species_photo_rgba(sp2, p2) if sp2.image is not None else None
        v2 = LeafView(m2, photo, s2.pigments.copy(), photo_tint=False, photo_colour=sp2.photo_colour)
        assert v2.chroma(s2, p2) is None and "chroma" not in v2.update(s2, p2)


def dataclasses_replace_none(state):
    import dataclasses

    return dataclasses.replace(state, pigments=None)


def test_drawn_veins_take_the_vein_tissues_own_colour():
    """A drawn vein is vein tissue (docs/method.md §7): the pigment model's colour at m̂ = 1,
    paler green than the lamina while fresh (``colour.vein_pallor``), paler than the browned
    lamina when dried (``colour.vein_browning``), and the lamina's colour when both are 0."""
    sp = get_species("maple")
    params = sp.params.with_overrides(COARSE)
    _, _, model = build_leaf(sp, params, seed=0)
    sim = Simulator(model, params, effects=("osmosis", "colour"), seed=0)
    st = sim.state()
    view = LeafView(model, None, photo_tint=False)
    lum = np.float32([0.2126, 0.7152, 0.0722])
    lamina = np.asarray(st.pigments.vein)[view.T] < 0.05  # the thinnest lamina
    fresh_blade, _ = view.colours(st, params)
    fresh_vein = view.vein_colours(st, params)
    assert fresh_vein.shape == fresh_blade.shape and np.isfinite(fresh_vein).all()
    assert (fresh_vein @ lum)[lamina].mean() > 1.1 * (fresh_blade @ lum)[lamina].mean()  # paler
    assert np.median(fresh_vein[:, 1] / fresh_vein[:, 0]) > 1.2  # still green
    run = Run(model, simulator=sim, state=st, name="maple")
    w0 = float(model.particle_water0.sum())
    for _ in run.frames(until=lambda s: float(s.particle_water.sum()) <= 0.02 * w0):
        pass
    dry_blade, _ = view.colours(run.state, params)
    dry_vein = view.vein_colours(run.state, params)
    assert params["colour.vein_browning"] > 0
    assert (dry_vein @ lum)[lamina].mean() > 1.05 * (dry_blade @ lum)[lamina].mean()  # browned less
    same = params.with_overrides({"colour.vein_pallor": 0.0, "colour.vein_browning": 0.0})
    np.testing.assert_allclose(view.vein_colours(run.state, same), view.colours(run.state, same)[0][:, :3], rtol=1e-6)
    # a photo species: the photo's colour at the vein, changed as pure vein tissue differs from
    # the particle's own (the renderer's photo albedos draw the photo's veins instead)
    photo = get_species("oak")
    p_oak = photo.params.with_overrides(COARSE)
    _, _, m_oak = build_leaf(photo, p_oak, seed=0)
    st_oak = Simulator(m_oak, p_oak, effects=("colour",), seed=0).state()
    v_oak = LeafView(m_oak, species_photo_rgba(photo, p_oak), st_oak.pigments.copy(), photo_colour=photo.photo_colour)
    blade_oak = v_oak.colours(st_oak, p_oak)[0]
    vein_oak = v_oak.vein_colours(st_oak, p_oak)
    lam = np.asarray(st_oak.pigments.vein)[v_oak.T] < 0.05
    assert (vein_oak @ lum)[lam].mean() > 1.1 * (blade_oak @ lum)[lam].mean()
    flat = p_oak.with_overrides({"colour.vein_pallor": 0.0, "colour.vein_browning": 0.0})
    np.testing.assert_allclose(v_oak.vein_colours(st_oak, flat), v_oak.colours(st_oak, flat)[0], rtol=1e-5)
    assert v_oak.vein_colours(dataclasses_replace_none(st_oak), p_oak) is None  # no pigments


def test_a_lesion_dead_in_the_young_photo_keeps_its_colour_as_the_leaf_dries(tmp_path):
    """A brown lesion on a green photo is tissue dead already: as the blade around it loses its
    chlorophyll and browns, the lesion keeps its photo colour (it used to take the surrounding
    tissue's dried colour and vanish, its edge alone left darker), in the vertex colours, the
    texture's tint; the green tissue around it changes.  The detail albedo lays no photo hue on
    it (its weight is the chlorophyll kept, 0 there as around it): the photo's pixels at the
    lesion's edge are half green, and with the hue kept they drew a green ring round it."""
    import json

    import cv2

    from helpers import leafimg
    from leafsim.config.species import load_library

    img, _ = leafimg.photo(600)
    base, _, _ = leafimg.petiole_line(600)
    centre = (int(base[0] + 40), int(0.45 * 600))
    cv2.circle(img, centre, 28, (30, 60, 110), -1)  # BGR: a brown lesion
    cv2.imwrite(str(tmp_path / "lesion.png"), img)
    (tmp_path / "leaves.json").write_text(json.dumps({"species": {"l": {"image": "lesion.png", "length_m": 0.08}}}))
    sp = load_library(tmp_path / "leaves.json")["l"]
    params = sp.params.with_overrides({"mesh.spacing": 0.02})
    _, _, model = build_leaf(sp, params, seed=0)
    st = Simulator(model, params, effects=("colour",), seed=0).state()
    view = LeafView(model, species_photo_rgba(sp, params), st.pigments.copy(), photo_colour=True)
    dead = view.dead_in_photo()
    lesion, green = dead > 0.99, dead == 0.0
    assert lesion.sum() >= 5 and green.sum() > 20 * lesion.sum()
    young, tint0 = view.colours(st, params)
    aged = st.copy()
    aged.pigments.chlorophyll[:] = 0.0
    aged.pigments.browning[:] = 1.0
    old, tint = view.colours(aged, params)
    assert np.allclose(old[lesion], young[lesion], rtol=1e-5) and np.allclose(tint[lesion], 1.0)
    assert np.abs(old[green] - young[green]).max(axis=1).min() > 0.01  # the rest changed
    assert np.allclose(view.chroma(aged, params)[:, 3], 0.0)
