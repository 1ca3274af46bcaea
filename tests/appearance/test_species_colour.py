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
