"""Pigment model of leaf colour (leafsim.sim.pigments): trajectories, patterns, palettes."""

from __future__ import annotations

import colorsys

import numpy as np
import pytest

from leafsim.appearance.reflectance import linear_to_srgb, pigments_to_rgb, tint_for_texture
from leafsim.config.params import PARAMS, ParamSet
from leafsim.measure.bench import bench_colour
from leafsim.sim.pigments import PALETTES, PigmentState, age_at, init_pigments, step_pigments


def _params(name: str | None = None, **extra) -> ParamSet:
    vals = dict(PALETTES[name]) if name else {}
    vals.update({f"colour.{k}": v for k, v in extra.items()})
    return ParamSet(vals)


def _hsv(rgb_linear: np.ndarray) -> tuple[float, float, float]:
    """Hue in degrees, saturation, value of a linear-RGB colour (via sRGB encoding)."""
    h, s, v = colorsys.rgb_to_hsv(*[float(x) for x in linear_to_srgb(rgb_linear)])
    return h * 360.0, s, v


def _age_on_tree(pig: PigmentState, p: ParamSet, age: float, steps: int = 100, dt: float = 0.05) -> None:
    w = np.ones(pig.n, np.float32)
    a0 = pig.age
    for s in range(1, steps + 1):
        step_pigments(pig, w, a0 + (age - a0) * s / steps, dt, p)


def test_params_declared_and_palettes_valid():
    for key in ("colour.onset", "colour.chlorophyll", "colour.chlorophyll_decay", "colour.water_sensitivity",
                "colour.carotenoid", "colour.carotenoid_decay", "colour.anthocyanin", "colour.anthocyanin_fade",
                "colour.browning", "colour.dry_threshold", "colour.dry_rate", "colour.vein_pallor",
                "colour.variation", "colour.age_rate", "colour.season"):
        assert PARAMS[key].group == "Colour" and not PARAMS[key].rebuild
    assert set(PALETTES) >= {"maple", "oak", "chestnut", "walnut", "pokeweed", "grapevine", "aspen", "hornbeam"}
    for name, pal in PALETTES.items():
        assert all(k.startswith("colour.") for k in pal), name
        ParamSet(pal)  # validates names and ranges


def test_monotone_trajectories_under_senescence_and_drying():
    p = _params("maple")
    n = 500
    rng = np.random.default_rng(0)
    pig = init_pigments(n, p, seed=3, rest_relative_mass=rng.uniform(0.1, 1.0, n))
    w = np.ones(n, np.float32)
    sink = rng.uniform(0.0, 0.02, n).astype(np.float32)
    age = 0.0
    prev = (pig.chlorophyll.copy(), pig.carotenoid.copy(), pig.browning.copy())
    for s in range(300):
        dt = float(rng.choice([0.002, 0.05, 1.0, 5.0]))  # tiny, small and large steps
        age += float(rng.uniform(0.0, 0.01))
        w = np.clip(w - sink * rng.uniform(0, 1, n).astype(np.float32), 0.0, 1.0)
        step_pigments(pig, w, age, dt, p)
        c, k, b = pig.chlorophyll, pig.carotenoid, pig.browning
        assert np.all(c <= prev[0]), f"chlorophyll increased at step {s}"
        assert np.all(k <= prev[1]), f"carotenoids increased at step {s}"
        assert np.all(b >= prev[2]), f"browning decreased at step {s}"
        assert np.all((c >= 0) & (b <= 1) & (pig.anthocyanin >= 0))
        prev = (c.copy(), k.copy(), b.copy())
    assert prev[0].max() < 0.5 and prev[2].min() > 0.0  # it really aged


def test_anthocyanin_peaks_then_fades():
    p = _params("maple")
    pig = init_pigments(1, p, seed=0)
    w = np.ones(1, np.float32)
    amounts = []
    for s in range(1, 301):
        step_pigments(pig, w, 3.0 * s / 300, 0.0, p)
        amounts.append(float(pig.anthocyanin[0]))
    a = np.array(amounts)
    peak = int(a.argmax())
    assert 0 < peak < len(a) - 1 and a[peak] > 0.3 and a[-1] < 0.5 * a[peak]
    assert a[0] < 0.01 * a[peak]  # none at the onset: made late in the breakdown
    # no anthocyanin species: colour carries none of it
    p0 = _params("chestnut")
    pig0 = init_pigments(1, p0, seed=0)
    ref = pig0.copy()
    step_pigments(pig0, w, 0.8, 0.0, p0)
    ref.chlorophyll[:], ref.carotenoid[:], ref.browning[:] = pig0.chlorophyll, pig0.carotenoid, pig0.browning
    np.testing.assert_allclose(pigments_to_rgb(pig0, p0), pigments_to_rgb(ref, p0), atol=1e-7)


@pytest.mark.parametrize("name", ["maple", "oak", "pokeweed"])
def test_constant_without_water_loss_or_senescence(name):
    # age constant (mid-season) and water_rel = 1: the colour must not move
    p = _params(name)
    pig = init_pigments(300, p, seed=1)
    w = np.ones(300, np.float32)
    step_pigments(pig, w, 0.55, 0.1, p)
    rgb0 = pigments_to_rgb(pig, p)
    for _ in range(200):
        step_pigments(pig, w, 0.55, 0.1, p)
    np.testing.assert_allclose(pigments_to_rgb(pig, p), rgb0, atol=1e-6, rtol=0)
    # age_rate = 0: the season clock stands still however long the leaf lies there
    p2 = _params(name, age_rate=0.0, season=0.4)
    pig2 = init_pigments(300, p2, seed=1)
    step_pigments(pig2, w, age_at(0.0, p2), 0.0, p2)
    rgb1 = pigments_to_rgb(pig2, p2)
    for i in range(1, 201):
        step_pigments(pig2, w, age_at(i * 0.5, p2), 0.5, p2)
    np.testing.assert_allclose(pigments_to_rgb(pig2, p2), rgb1, atol=1e-6, rtol=0)


def test_margin_turns_before_veins_from_water_field_only():
    p = _params("chestnut")
    n = 400
    margin = np.arange(n) < n // 2  # first half: margin / intercostal particles, rest: veins
    pig = init_pigments(n, p, seed=2)  # uniform mass: pattern can only come from water
    rgb_young = pigments_to_rgb(pig, p)
    w_end = np.where(margin, 0.45, 0.95).astype(np.float32)
    steps = 200
    for s in range(1, steps + 1):
        f = s / steps
        w = (1.0 - f * (1.0 - w_end)).astype(np.float32)
        step_pigments(pig, w, 0.5 * f, 0.01, p)  # mid-senescence
    rgb = pigments_to_rgb(pig, p)
    dist = np.linalg.norm(linear_to_srgb(rgb) - linear_to_srgb(rgb_young), axis=1)
    assert dist[margin].min() > dist[~margin].max() + 0.05
    assert pig.chlorophyll[margin].max() < pig.chlorophyll[~margin].min()
    # the veins are still greener (hue) than the margin
    assert _hsv(rgb[~margin].mean(0))[0] > _hsv(rgb[margin].mean(0))[0] + 10


def test_uniform_water_gives_uniform_colour():
    p = _params("maple")
    n = 600
    pig = init_pigments(n, p, seed=4, rest_relative_mass=np.full(n, 0.7))
    for s in range(1, 101):
        w = np.full(n, 1.0 - 0.008 * s, np.float32)
        step_pigments(pig, w, 0.01 * s, 0.05, p)
    rgb = pigments_to_rgb(pig, p)
    assert np.ptp(rgb, axis=0).max() == 0.0


def test_vein_mass_makes_veins_paler_but_same_trend():
    p = _params()
    m = np.array([0.1, 0.1, 1.0, 1.0])
    pig = init_pigments(4, p, seed=0, rest_relative_mass=m)
    np.testing.assert_array_equal(pig.vein, [0, 0, 1, 1])
    rgb = pigments_to_rgb(pig, p)
    assert rgb[2].sum() > rgb[0].sum()  # less chlorophyll → lighter
    np.testing.assert_array_equal(rgb[0], rgb[1])
    # the pallor acts live at colour time
    p_none = p.with_overrides({"colour.vein_pallor": 0.0})
    rgb0 = pigments_to_rgb(pig, p_none)
    np.testing.assert_allclose(rgb0[2], rgb0[0], rtol=1e-6)
    # veins age the same way as the lamina under the same water (pattern comes from water only)
    step_pigments(pig, np.ones(4, np.float32), 0.7, 0.0, p)
    assert pig.chlorophyll[0] == pig.chlorophyll[2]
    with pytest.raises(ValueError):
        init_pigments(4, p, 0, rest_relative_mass=np.ones(3))


#: the autumn colour on the tree (season 0.9) the literature gives each species (HSV hue in
#: degrees of sRGB): Norway maple clear yellow to orange, oak tan (yellow-brown) to russet, aspen/hornbeam
#: golden yellow, a white grapevine yellow, pokeweed purple-red (docs/method.md §9)
PALETTE_HUES = {
    "maple": lambda h, s, v: 28 <= h <= 60 and v > 0.6,
    "chestnut": lambda h, s, v: 35 <= h <= 65,
    "oak": lambda h, s, v: 20 <= h <= 50 and v < 0.62 and s < 0.7,
    "pokeweed": lambda h, s, v: h > 300 or h < 20,
    "aspen": lambda h, s, v: 35 <= h <= 65 and v > 0.7,
    "hornbeam": lambda h, s, v: 30 <= h <= 60,
    "grapevine": lambda h, s, v: 38 <= h <= 65 and v > 0.6,
    "walnut": lambda h, s, v: 30 <= h <= 60,
}


@pytest.mark.parametrize("name", sorted(PALETTE_HUES))
def test_palettes_young_green_and_autumn_hue(name):
    p = _params(name)
    pig = init_pigments(64, p, seed=7)
    h, s, v = _hsv(pigments_to_rgb(pig, p).mean(0))
    assert 70 <= h <= 160 and s < 0.75, (name, h, s, v)  # green, not over-saturated
    _age_on_tree(pig, p, 0.9)
    h, s, v = _hsv(pigments_to_rgb(pig, p).mean(0))
    assert PALETTE_HUES[name](h, s, v), (name, h, s, v)
    # dried at the end: brown — yellow-brown for the golden species (little tannin,
    # colour.brown_level), russet to dark brown for oak and walnut — darker than the autumn
    # peak, and a colour, not grey
    for _ in range(40):
        step_pigments(pig, np.zeros(pig.n, np.float32), 1.0, 0.5, p)
    h2, s2, v2 = _hsv(pigments_to_rgb(pig, p).mean(0))
    assert (h2 < 50 or h2 > 340) and v2 < v + 1e-6 and v2 < 0.75 and s2 > 0.3, (name, h2, s2, v2)
    if p["colour.brown_level"] >= 1.0:
        assert v2 < 0.6, (name, v2)


def test_seed_determinism_and_variation():
    p = _params("maple")
    w = np.linspace(0.3, 1.0, 50).astype(np.float32)

    def run(seed):
        pig = init_pigments(50, p, seed=seed)
        for s in range(1, 51):
            step_pigments(pig, w, 0.014 * s, 0.02, p)
        return pigments_to_rgb(pig, p)

    np.testing.assert_array_equal(run(11), run(11))
    assert np.abs(run(11) - run(12)).max() > 1e-3
    p0 = _params("maple", variation=0.0)
    a, b = init_pigments(5, p0, seed=1), init_pigments(5, p0, seed=2)
    np.testing.assert_array_equal(a.leaf, b.leaf)


def test_large_step_matches_small_steps():
    p = _params("maple")
    n = 20
    w = np.linspace(0.3, 1.0, n).astype(np.float32)
    big, small = init_pigments(n, p, seed=5), init_pigments(n, p, seed=5)
    step_pigments(big, w, 0.8, 4.0, p)  # one jump (sub-stepped inside)
    for s in range(1, 2001):
        step_pigments(small, w, 0.8 * s / 2000, 4.0 / 2000, p)
    np.testing.assert_allclose(pigments_to_rgb(big, p), pigments_to_rgb(small, p), atol=0.01)


def test_texture_tint():
    p = _params("aspen")
    pig0 = init_pigments(10, p, seed=0)
    pig = pig0.copy()
    np.testing.assert_allclose(tint_for_texture(pig, pig0, p), 1.0, atol=1e-6)
    _age_on_tree(pig, p, 0.9, steps=20)
    tint = tint_for_texture(pig, pig0, p)
    assert tint.shape == (10, 3) and tint.dtype == np.float32
    assert tint[:, 0].min() > 3.0  # red rises when green turns yellow
    np.testing.assert_allclose(pigments_to_rgb(pig0, p) * tint, pigments_to_rgb(pig, p), rtol=1e-5)
    assert pig0.chlorophyll[0] == 1.0  # copy() is deep


def test_bad_and_edge_inputs():
    p = _params()
    pig = init_pigments(4, p, seed=0)
    step_pigments(pig, np.array([np.nan, 2.0, -1.0, 0.5]), 0.5, 1.0, p)  # NaN → dry, clipped
    assert np.all(np.isfinite(pig.chlorophyll)) and np.all(np.isfinite(pig.browning))
    assert pig.chlorophyll[0] == pytest.approx(pig.chlorophyll[2])  # NaN treated like no water
    with pytest.raises(ValueError):
        step_pigments(pig, np.ones(3), 0.6, 0.1, p)
    empty = init_pigments(0, p, seed=0)
    step_pigments(empty, np.ones(0, np.float32), 1.0, 1.0, p)
    assert pigments_to_rgb(empty, p).shape == (0, 3)
    # the clock going backwards ages nothing
    pig = init_pigments(3, p, seed=0)
    step_pigments(pig, np.ones(3, np.float32), 0.8, 0.0, p)
    c = pig.chlorophyll.copy()
    step_pigments(pig, np.ones(3, np.float32), 0.5, 0.0, p)
    step_pigments(pig, np.ones(3, np.float32), 0.8, 0.0, p)
    np.testing.assert_array_equal(pig.chlorophyll, c)


def test_colour_bench_measures():
    """`bench_colour` reports a duration (how fast is `leafsim bench`'s business, not a test's)."""
    us = bench_colour(n=5700, steps=20)
    assert isinstance(us, float) and np.isfinite(us) and us > 0


def _dry_through(p: ParamSet, seconds: float, steps: int = 400, hold: float = 5.0):
    """One particle that dies green (no senescence: age stays 0) as its water falls linearly
    from 1 to 0 over ``seconds``, then stays dry for ``hold`` seconds."""
    pig = init_pigments(1, p, seed=0)
    w = np.ones(1, np.float32)
    for s in range(1, steps + 1):
        w[0] = 1.0 - s / steps
        step_pigments(pig, w, 0.0, seconds / steps, p)
    for _ in range(50):
        step_pigments(pig, w, 0.0, hold / 50, p)
    return pig


def test_reaction_water_keeps_fast_dried_tissue_green():
    """Herbarium green: the reactions of dead tissue run on its water, so tissue that passes the
    dying range fast keeps chlorophyll it had; dryness no longer drives a bone-dry particle (only
    the season would, and it stays before the onset here); 0 = the old model."""
    base = dict(onset=1.5, drought=0.0, dry_rate=2.0)
    limited = _params(reaction_water=0.35, **base)
    fast, slow = _dry_through(limited, 0.5), _dry_through(limited, 8.0)
    assert fast.chlorophyll[0] > 0.3 and slow.chlorophyll[0] < 0.05, (fast.chlorophyll, slow.chlorophyll)
    assert fast.necrosis[0] < slow.necrosis[0]
    # chlorophyll + necrosis is conserved (dying converts one into the other)
    for pig in (fast, slow):
        assert pig.chlorophyll[0] + pig.necrosis[0] == pytest.approx(1.0, abs=1e-5)
    # without the limit the dead tissue converts everything, however fast it dried
    unlimited = _dry_through(_params(reaction_water=0.0, **base), 0.5)
    assert unlimited.chlorophyll[0] < 1e-3
    # bone-dry tissue before the season's onset does not change at all, however long it waits
    pig = init_pigments(1, limited, seed=0)
    before = (pig.chlorophyll.copy(), pig.browning.copy(), pig.necrosis.copy())
    for _ in range(20):
        step_pigments(pig, np.zeros(1, np.float32), 0.0, 10.0, limited)
    assert np.array_equal(pig.chlorophyll, before[0]) and np.array_equal(pig.necrosis, before[2])
    assert np.array_equal(pig.browning, before[1])
