"""The sub-grid mottle (``colour.mottle``): its field and the optical depths the renderer draws it
from.  The pixels are tested in tests/render/test_renderer.py."""

import numpy as np
import pytest

from leafsim.appearance.mottle import TEXELS_PER_LENGTH, leaf_offset, mottle_field, mottle_scale
from leafsim.appearance.reflectance import BASE_REFLECTANCE, mottle_depths, pigments_to_rgb
from leafsim.config.params import ParamSet
from leafsim.sim.pigments import init_pigments


def test_field_is_uniform_zero_mean_periodic_and_seeded():
    f = mottle_field(256, seed=3)
    assert f.dtype == np.float32 and f.shape == (256, 256)
    assert f.min() >= -1.0 and f.max() <= 1.0
    assert abs(float(f.mean(dtype=np.float64))) < 1e-6
    # rank-mapped: uniform on [-1, 1] (each tenth of the range holds a tenth of the texels)
    counts = np.histogram(f, bins=10, range=(-1, 1))[0] / f.size
    assert np.abs(counts - 0.1).max() < 1e-3
    # correlation 1/e at the correlation length (Gaussian filter), gone by three lengths
    lag = int(TEXELS_PER_LENGTH)
    rho = [float(np.mean(f * np.roll(f, k, axis)) / np.mean(f * f)) for k in (lag, 3 * lag) for axis in (0, 1)]
    assert all(0.25 < r < 0.45 for r in rho[:2]), rho
    assert all(abs(r) < 0.1 for r in rho[2:]), rho
    # periodic: the step across the wrap is no larger than a step inside
    inside = np.abs(np.diff(f, axis=0)).mean()
    assert np.abs(f[0] - f[-1]).mean() < 1.3 * inside
    assert np.array_equal(mottle_field(256, seed=3), f)
    assert not np.array_equal(mottle_field(256, seed=4), f)


def test_scale_and_leaf_offsets():
    # texture coordinates per metre: one correlation length spans TEXELS_PER_LENGTH texels
    assert mottle_scale(0.0006, 1024) * 0.0006 * 1024 == pytest.approx(TEXELS_PER_LENGTH)
    assert np.array_equal(leaf_offset(7), leaf_offset(7))
    assert not np.array_equal(leaf_offset(7), leaf_offset(8))


def _pigments(n=64, seed=0):
    p = ParamSet()
    pig = init_pigments(n, p, seed=seed, rest_relative_mass=np.linspace(0.0, 1.0, n))
    rng = np.random.default_rng(seed)
    pig.chlorophyll[:] = rng.uniform(0, 1, n)
    pig.carotenoid[:] = rng.uniform(0.3, 1, n)
    pig.browning[:] = rng.uniform(0, 1, n)
    pig.necrosis[:] = rng.uniform(0, 0.5, n)
    pig.anthocyanin[:] = rng.uniform(0, 0.5, n)
    return p, pig


def test_depths_reproduce_the_reflectance_and_their_gradient():
    p, pig = _pigments()
    p = p.with_overrides({"colour.anthocyanin": 1.0})
    d = mottle_depths(pig, p)
    assert d.shape == (pig.n, 7) and np.all(np.isfinite(d))
    # surface + base·exp(−x) is the particle's colour
    np.testing.assert_allclose(d[:, 3:4] + BASE_REFLECTANCE * np.exp(-d[:, :3]), pigments_to_rgb(pig, p), rtol=2e-4, atol=1e-6)
    # the gradient: every reaction's progress moved by a·n·p(1 − p), here n = ±ε (central difference)
    a, eps = float(p["colour.mottle"]), 1e-3

    def moved(n):
        q = pig.copy()
        c, k, b, m = (np.clip(getattr(pig, x), 0, 1) for x in ("chlorophyll", "carotenoid", "browning", "necrosis"))
        q.chlorophyll = (pig.chlorophyll - a * n * c * (1 - c)).astype(np.float32)
        q.carotenoid = (pig.carotenoid - a * n * k * (1 - k)).astype(np.float32)
        q.browning = (pig.browning + a * n * b * (1 - b)).astype(np.float32)
        q.necrosis = (pig.necrosis + a * n * m * (1 - m)).astype(np.float32)
        return mottle_depths(q, p)[:, :3].astype(np.float64)

    np.testing.assert_allclose((moved(eps) - moved(-eps)) / (2 * eps), d[:, 4:], rtol=2e-2, atol=2e-3)


def test_fresh_and_finished_tissue_and_zero_amount_are_uniform():
    p, pig = _pigments()
    fresh = init_pigments(pig.n, p, seed=0)
    assert np.all(mottle_depths(fresh, p)[:, 4:] == 0.0)
    done = pig.copy()
    done.chlorophyll[:] = 0.0
    done.carotenoid[:] = 0.0
    done.browning[:] = 1.0
    done.necrosis[:] = 1.0
    assert np.all(mottle_depths(done, p)[:, 4:] == 0.0)
    off = mottle_depths(pig, p.with_overrides({"colour.mottle": 0.0}))
    assert np.all(off[:, 4:] == 0.0)
    np.testing.assert_array_equal(off[:, :4], mottle_depths(pig, p)[:, :4])
    # half-turned tissue is mottled: where n > 0 it holds less chlorophyll, which absorbs red
    # and blue most, so those bands' depths fall (the fleck is yellower)
    mid = pig.copy()
    mid.chlorophyll[:], mid.carotenoid[:], mid.browning[:], mid.necrosis[:] = 0.5, 1.0, 0.0, 0.0
    g = mottle_depths(mid, p)[:, 4:]
    assert np.all(g[:, 0] < 0) and np.all(g[:, 2] < 0)


def test_the_pigment_amounts_keep_their_mean():
    """Over the field, p + a·n·p(1 − p) has the mean p (n has mean 0 and stays in [−1, 1], so
    every local progress stays in [0, 1])."""
    f = mottle_field(256, seed=5).astype(np.float64)
    for prog in (0.1, 0.5, 0.9):
        local = prog + 1.0 * f * prog * (1 - prog)
        assert local.min() >= 0.0 and local.max() <= 1.0
        assert abs(local.mean() - prog) < 1e-9
