"""A leaf whose veins no longer spread water dries in patches, and its colour follows
(docs/method.md, "Herbarium green"): with herbarium green on (``colour.reaction_water``), tissue
that dies fast keeps its chlorophyll and tissue that lingers wet after death turns it into dark
pheophytin.  Slow water diffusion through the blade keeps the patch field's contrast, so the
dried blade splits into green and dark tissue; fast diffusion evens the drying out and the
whole blade ends at one olive mixture.  Runs ``aspen_senescent`` (the species that sets this)
on a coarse mesh with osmosis and colour only (no mechanics)."""

import numpy as np
import pytest

from leafsim.config.species import get_species
from leafsim.pipeline import build_leaf
from leafsim.sim.simulator import Simulator

#: the run stops at this share of the water left (as "Dry to end" does)
DRY_LEFT = 0.02


def dried_pigments(diffusion: float):
    """(chlorophyll, necrosis) of the blade's particles of ``aspen_senescent`` dried to
    ``DRY_LEFT`` with ``osmosis.diffusion`` = ``diffusion``."""
    sp = get_species("aspen_senescent")
    p = sp.params.with_overrides({"mesh.spacing": 0.035, "osmosis.diffusion": diffusion})
    model = build_leaf(sp, p, 0).model
    sim = Simulator(model, p, effects=("osmosis", "colour"), seed=0)
    st = sim.state()
    for _ in range(20000):  # progress, not a clock: every step loses water
        if model.water_fraction(st.particle_water) <= DRY_LEFT:
            break
        sim.step(st)
    assert model.water_fraction(st.particle_water) <= DRY_LEFT, "the leaf did not dry"
    blade = model.blade_T
    return st.pigments.chlorophyll[blade].astype(float), st.pigments.necrosis[blade].astype(float)


@pytest.fixture(scope="module")
def runs():
    return {d: dried_pigments(d) for d in (1e-6, 1e-5)}


def test_dried_blade_keeps_green_and_dark_tissue_when_water_stays_put(runs):
    chl, nec = runs[1e-6]
    assert np.isfinite(chl).all() and np.isfinite(nec).all()
    # dying converts chlorophyll into necrosis, breakdown removes it: never more than there was
    assert (chl >= 0).all() and (nec >= 0).all() and (chl + nec).max() <= 1.0 + 1e-5
    green, dark = (chl > 0.5).mean(), (nec > 0.6).mean()
    assert green > 0.1 and dark > 0.1, (green, dark)


def test_fast_diffusion_evens_the_necrosis_out(runs):
    spread = {d: np.subtract(*np.percentile(nec, [95, 5])) for d, (_, nec) in runs.items()}
    assert spread[1e-6] > 1.5 * spread[1e-5], spread
