"""Where a leaf turns first (leafsim.sim.senescence): the seeded senescence field, its pattern on
the blade (margin first, green islands along the veins, patches, spots) and what it does to the
pigments."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from helpers.synthetic import ellipse_shape, synthetic_veins
from leafsim.blade.build import build_blade
from leafsim.config.params import ParamSet
from leafsim.sim.model import LAYER_T
from leafsim.sim.pigments import PALETTES
from leafsim.sim.senescence import _vein_distance, random_field, senescence_field
from leafsim.sim.simulator import Simulator

PATTERN = {"colour.patchiness": 0.6, "colour.patch_size": 0.01, "colour.margin_first": 2.0, "colour.margin_width": 0.003,
           "colour.vein_islands": 0.7, "colour.island_width": 0.002}


def _model(spacing=0.04, seed=2):
    s = ellipse_shape()
    return build_blade(s, synthetic_veins(s), ParamSet({"mesh.spacing": spacing}), seed=seed)


@pytest.fixture(scope="module")
def model():
    return _model()


def test_uniform_without_parameters(model):
    rate, spot = senescence_field(model, ParamSet({}), seed=0)
    assert rate.dtype == np.float32 and rate.shape == (model.particle_count,)
    assert np.all(rate == 1.0) and np.all(spot == 0.0)


def test_seeded_and_a_function_of_position(model):
    p = ParamSet(PATTERN)
    a, _ = senescence_field(model, p, seed=5)
    b, _ = senescence_field(model, p, seed=5)
    c, _ = senescence_field(model, p, seed=6)
    np.testing.assert_array_equal(a, b)
    assert np.corrcoef(np.log(a), np.log(c))[0, 1] < 0.9  # another seed, other patches
    # the same field on a mesh √2 finer: at the coarse particles' places the finer mesh's nearest
    # particles (within a fraction of the spacing) carry nearly the same rate
    fine = _model(spacing=0.04 / np.sqrt(2))
    f, _ = senescence_field(fine, p, seed=5)
    d, j = cKDTree(fine.particle_rest[:, :2]).query(model.particle_rest[:, :2])
    close = d < 0.25 * fine.spacing
    assert close.sum() > 20
    assert np.corrcoef(np.log(a[close]), np.log(f[j[close]]))[0, 1] > 0.9


def test_margin_first_and_green_islands_along_the_veins(model):
    T = model.particle_layer == LAYER_T
    p = ParamSet({**PATTERN, "colour.patchiness": 0.0})
    rate, _ = senescence_field(model, p, seed=1)
    d_vein = _vein_distance(model, model.particle_rest[:, :2])
    edge = T & (model.particle_margin_distance < 0.5 * model.spacing) & (d_vein > 0.006)
    inner = T & (model.particle_margin_distance > 0.01) & (d_vein > 0.006)
    on_vein = T & (d_vein < 0.0005) & (model.particle_margin_distance > 0.005)
    assert edge.sum() > 5 and inner.sum() > 5 and on_vein.sum() > 5
    assert rate[edge].min() > 2.0 * rate[inner].max() * 0.99  # the margin turns first
    assert rate[on_vein].max() < 0.5 * rate[inner].min()      # the tissue along the veins last


def test_patch_field_is_normalised():
    xy = np.random.default_rng(0).uniform(0, 0.1, (4000, 2))
    z = random_field(xy, np.ones(len(xy)), 0.01, [3, 4])
    assert abs(z.mean()) < 1e-9 and abs(z.std() - 1.0) < 1e-9


def test_spots_count_and_they_die_dark(model):
    T = model.particle_layer == LAYER_T
    area = float(model.particle_area[T].sum())
    p = ParamSet({"colour.spots": 40.0 / area, "colour.spot_radius": 0.002})
    rate, spot = senescence_field(model, p, seed=3)
    inside = spot > 0.99
    # the seeded Poisson count of spots of ≈ 2 mm: their cores cover a share of the blade near
    # 40 π r² / area (overlaps and the margin take a little)
    share = float(model.particle_area[T & inside].sum()) / area
    assert 0.3 * 40 * np.pi * 0.002 ** 2 / area < share < 1.5 * 40 * np.pi * 0.002 ** 2 / area
    assert rate[inside].min() > 1.5  # the lesion and its halo turn early
    # drying: the spots' tissue dies green (necrosis), the rest of the blade senesces first
    params = ParamSet({**PALETTES["hornbeam"], **{k: v for k, v in p.items() if k.startswith("colour.spot")},
                       "mesh.spacing": 0.04})
    sim = Simulator(model, params, effects=("osmosis", "colour"), seed=3)
    st = sim.state()
    w0 = float(model.particle_water0.sum())
    while float(st.particle_water.sum()) > 0.02 * w0:
        sim.step(st)
    nec = st.pigments.necrosis
    assert np.isfinite(nec).all()
    assert nec[T & inside].mean() > 0.5 and nec[T & (spot == 0)].mean() < 0.5 * nec[T & inside].mean()


def test_field_changes_the_colour_order_not_conservation(model):
    """With the pattern, the margin's chlorophyll goes before the veins' at the same water; the
    pigments stay in their ranges."""
    params = ParamSet({**PALETTES["maple"], "mesh.spacing": 0.04, "osmosis.patchiness": 0.0})
    sim = Simulator(model, params, effects=("osmosis", "colour"), seed=0)
    st = sim.state()
    w0 = float(model.particle_water0.sum())
    while float(st.particle_water.sum()) > 0.7 * w0:
        sim.step(st)
    pig = st.pigments
    T = model.particle_layer == LAYER_T
    d_vein = _vein_distance(model, model.particle_rest[:, :2])
    edge = T & (model.particle_margin_distance < 0.5 * model.spacing)
    veins = T & (d_vein < 0.0005) & (model.particle_margin_distance > 0.005)
    assert pig.chlorophyll[edge].mean() < pig.chlorophyll[veins].mean() - 0.1
    for name in ("chlorophyll", "carotenoid", "browning", "necrosis"):
        a = getattr(pig, name)
        assert np.isfinite(a).all() and a.min() >= 0.0 and a.max() <= 1.0 + 1e-6, name


def test_only_the_fast_turning_particles_are_sub_stepped(model):
    """A patterned blade sub-steps only the particles whose exponent needs it (the field sorted
    by rate); the result agrees with sub-stepping the whole blade to the scheme's accuracy (no
    exponent above 0.1 per step: the anthocyanin made from the chlorophyll lost, the one
    coupling, differs by 2 % of its amount, every other pigment by < 0.5 %)."""
    from leafsim.sim.effects.colour import Colour
    from leafsim.sim.pigments import age_at, init_pigments, step_pigments

    params = ParamSet({**PALETTES["maple"], "mesh.spacing": 0.04})
    col = Colour(model)
    col.configure(params)
    six = col.field(0)
    assert len(six) == 6 and np.all(np.diff(six[5]) <= 0)
    n = model.particle_count
    a, b = init_pigments(n, params, seed=0), init_pigments(n, params, seed=0)
    rng = np.random.default_rng(1)
    w = np.ones(n, np.float32)
    for s in range(200):
        w = np.clip(w - rng.uniform(0, 0.006, n).astype(np.float32), 0, 1)
        step_pigments(a, w, age_at(s * 0.02, params), 0.02, params, six)
        step_pigments(b, w, age_at(s * 0.02, params), 0.02, params, six[:4])
    for name in ("chlorophyll", "carotenoid", "anthocyanin", "browning", "necrosis"):
        x, y = getattr(a, name), getattr(b, name)
        tol = 0.03 * float(np.abs(y).max()) if name == "anthocyanin" else 5e-3
        assert np.isfinite(x).all() and np.abs(x - y).max() < tol, name
    assert a.chlorophyll.max() < 0.9  # it aged
