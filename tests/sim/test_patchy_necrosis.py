"""A leaf whose water no longer moves between its patches dries in patches, and its colour
follows (docs/method.md, "Herbarium green"): with herbarium green on (``colour.reaction_water``),
tissue that dies fast keeps its chlorophyll and tissue that lingers wet after death turns it into
dark pheophytin.  A low water diffusivity keeps the hydraulic patch field's contrast, so the
dried blade splits into green and dark tissue; the default diffusivity evens the drying out and
the whole blade ends at one olive mixture.  Runs ``aspen_senescent``'s outline on a coarse mesh
with osmosis and colour only (no mechanics), its colour settings pinned here so that a later
change to the species entry does not change what this checks."""

import numpy as np
import pytest

from leafsim.config.species import get_species
from leafsim.pipeline import build_leaf
from leafsim.sim.simulator import Simulator

#: the run stops at this share of the water left (as "Dry to end" does)
DRY_LEFT = 0.02
#: the settings under test (aspen_senescent's when this was written)
SETTINGS = {"mesh.spacing": 0.035, "colour.onset": 1.0, "colour.dry_rate": 0.7, "colour.reaction_water": 0.6,
            "osmosis.patchiness": 0.8}


def dried_pigments(diffusion: float):
    """(chlorophyll, necrosis, area) of the blade's particles, dried to ``DRY_LEFT`` with
    ``osmosis.diffusion`` = ``diffusion``."""
    sp = get_species("aspen_senescent")
    p = sp.params.with_overrides({**SETTINGS, "osmosis.diffusion": diffusion})
    model = build_leaf(sp, p, 0).model
    sim = Simulator(model, p, effects=("osmosis", "colour"), seed=0)
    st = sim.state()
    for _ in range(20000):  # progress, not a clock: every step loses water
        if model.water_fraction(st.particle_water) <= DRY_LEFT:
            break
        sim.step(st)
    assert model.water_fraction(st.particle_water) <= DRY_LEFT, "the leaf did not dry"
    blade = model.blade_T
    return (st.pigments.chlorophyll[blade].astype(float), st.pigments.necrosis[blade].astype(float),
            model.particle_area[blade].astype(float))


@pytest.fixture(scope="module")
def runs():
    return {d: dried_pigments(d) for d in (1e-6, 1e-5)}


def _shares(run):
    """Area shares of the blade that kept over half its chlorophyll, and that is over 60 % necrotic."""
    chl, nec, area = run
    return float(area[chl > 0.5].sum() / area.sum()), float(area[nec > 0.6].sum() / area.sum())


def test_dried_blade_splits_into_green_and_dark_tissue_only_when_water_stays_put(runs):
    for chl, nec, _ in runs.values():
        assert np.isfinite(chl).all() and np.isfinite(nec).all()
    green, dark = _shares(runs[1e-6])
    assert green > 0.2 and dark > 0.2, (green, dark)
    green, dark = _shares(runs[1e-5])
    assert green < 0.05 and dark < 0.05, (green, dark)


def test_fast_diffusion_evens_the_necrosis_out(runs):
    spread = {d: np.subtract(*np.percentile(nec, [95, 5])) for d, (_, nec, _) in runs.items()}
    assert spread[1e-6] > 1.5 * spread[1e-5], spread
