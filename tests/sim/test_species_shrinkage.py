"""How much a fully dried blade's tissue shrinks is a species trait (docs/method.md §6): the rest
state of the shrink effect with every particle's water gone, measured on the blade's own
triangles, follows Jeong's law for the species' σ and water fraction, and orders the kinds of
leaf as the shrinkage literature does (leathery least, herbaceous most)."""

import numpy as np
import pytest

from leafsim.config.species import get_species
from leafsim.pipeline import build_leaf
from leafsim.sim.effects.shrink import Shrink


def _heron(a, b, c):
    s = 0.5 * (a + b + c)
    return np.sqrt(np.maximum(s * (s - a) * (s - b) * (s - c), 0.0))


def dried_tissue_area(key: str) -> tuple[float, float, float, float]:
    """(area kept by the blade's triangles' rest state when bone dry, σ of the bottom surface
    springs, σ of the vein springs, water fraction) for species ``key`` on a coarse mesh."""
    sp = get_species(key)
    p = sp.params.with_overrides({"mesh.spacing": 0.035})
    model = build_leaf(sp, p, 0).model
    shrink = Shrink(model)
    shrink.configure(p)
    st = model.state()
    st.particle_water[:] = 0.0
    shrink.apply(st)
    tri = model.vol_springs
    # the blade's triangles: none of their three T particles on the stalk
    blade = (np.ones(len(tri), bool) if model.particle_petiole is None
             else ~model.particle_petiole[model.vol_idx[:, 1:]].any(1))
    rest0 = model.spring_rest0[tri[blade]]
    rest = st.spring_rest[tri[blade]]
    kept = _heron(*rest.T).sum() / _heron(*rest0.T).sum()
    return (float(kept), float(p["shrink.sigma_surface_bottom"]), float(p["shrink.sigma_vein"]),
            float(p["mass.water_fraction"]))


@pytest.fixture(scope="module")
def areas():
    return {k: dried_tissue_area(k) for k in ("oak", "chestnut", "maple", "hornbeam", "grapevine", "pokeweed")}


def test_dried_tissue_follows_the_shrink_law_of_its_species(areas):
    for key, (kept, sigma, sigma_vein, w) in areas.items():
        # between every spring shrinking as the lamina (σ w) and every one as a vein (σ_vein w):
        # vein springs are about a sixth of the layer's spring length and hold the triangles they border
        lamina, veins = (1.0 - sigma * w) ** 2, (1.0 - sigma_vein * w) ** 2
        assert lamina - 0.005 <= kept <= lamina + 0.5 * (veins - lamina), (key, kept, lamina, veins)


def test_kinds_of_leaf_shrink_as_the_literature_orders_them(areas):
    kept = {k: v[0] for k, v in areas.items()}
    leathery = min(kept["oak"], kept["chestnut"])
    thin = [kept[k] for k in ("maple", "hornbeam", "grapevine")]
    assert leathery > max(thin) and min(thin) > kept["pokeweed"], kept
    # a fully dried leathery blade loses under a tenth of its area, the herbaceous one over a fifth
    assert leathery > 0.90 and kept["pokeweed"] < 0.78, kept
    assert max(kept.values()) - min(kept.values()) > 0.15, kept
