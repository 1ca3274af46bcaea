"""The sub-grid mottle (``colour.mottle``): its field and the optical depths the renderer draws it
from.  The pixels are tested in tests/render/test_renderer.py."""

import numpy as np
import pytest

from leafsim.appearance.mottle import TEXELS_PER_LENGTH, leaf_offset, mottle_field, mottle_levels, mottle_scale
from leafsim.appearance.reflectance import (ABSORPTION, BASE_REFLECTANCE, MOTTLE_COLUMNS, mottle_pigments, mottle_ratio,
                                            pigments_to_rgb)
from leafsim.config.params import ParamSet
from leafsim.sim.pigments import init_pigments


def test_field_is_uniform_zero_mean_periodic_and_seeded():
    f = mottle_field(256, seed=3)
    assert f.dtype == np.float32 and f.shape == (256, 256)
    assert f.min() == -255 / 256 and f.max() == 255 / 256
    assert float(f.mean(dtype=np.float64)) == 0.0
    # rank-mapped: every one of the 256 levels on the same number of texels
    k = mottle_levels(256, seed=3)
    assert k.dtype == np.uint8 and np.all(np.bincount(k.ravel(), minlength=256) == 256)
    np.testing.assert_array_equal(f, (2.0 * k + 1) / 256 - 1)
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
    p = ParamSet().with_overrides({"colour.anthocyanin": 1.0})
    pig = init_pigments(n, p, seed=seed, rest_relative_mass=np.linspace(0.0, 1.0, n))
    rng = np.random.default_rng(seed)
    pig.chlorophyll[:] = rng.uniform(0, 1, n)
    pig.carotenoid[:] = rng.uniform(0.3, 1, n)
    pig.browning[:] = rng.uniform(0, 1, n)
    pig.necrosis[:] = rng.uniform(0, 0.5, n)
    pig.anthocyanin[:] = rng.uniform(0, 0.5, n)
    return p, pig


def _moved(pig, a, n):
    """The pigments with every reaction's progress moved by a·n·p(1 − p)."""
    q = pig.copy()
    c, k, b, m = (getattr(pig, x).astype(np.float64) for x in ("chlorophyll", "carotenoid", "browning", "necrosis"))
    q.chlorophyll = (c - a * n * c * (1 - c)).astype(np.float32)
    q.carotenoid = (k - a * n * k * (1 - k)).astype(np.float32)
    q.browning = (b + a * n * b * (1 - b)).astype(np.float32)
    q.necrosis = (m + a * n * m * (1 - m)).astype(np.float32)
    return q


@pytest.mark.parametrize("contents", [None, (1.7, 0.9, 0.02)])
def test_the_rows_reproduce_the_reflectance_and_the_moved_pigments(contents):
    """The renderer's formula (mottle_ratio, the shader's in float64) at field value n is the
    reflectance of the pigments moved by a·n·p(1 − p) over the unmoved one, for the palette's
    contents and a photo's fitted ones."""
    p, pig = _pigments()
    m = mottle_pigments(pig, p, contents)
    assert m.shape == (pig.n, len(MOTTLE_COLUMNS)) and np.all(np.isfinite(m))
    rgb = pigments_to_rgb(pig, p, contents).astype(np.float64)
    x = m[:, [0, 1, 2, 3, 8]].astype(np.float64) @ ABSORPTION.astype(np.float64)
    np.testing.assert_allclose(m[:, 9:10] + BASE_REFLECTANCE * np.exp(-np.maximum(x, 0)), rgb, rtol=1e-4, atol=1e-6)
    a = float(p["colour.mottle"])
    assert 0 < a <= 1
    for n in (-1.0, -0.3, 0.5, 1.0):
        want = pigments_to_rgb(_moved(pig, a, n), p, contents).astype(np.float64) / rgb
        np.testing.assert_allclose(mottle_ratio(m, np.full(pig.n, n), a), want, rtol=1e-4)
    assert np.all(mottle_ratio(m, np.zeros(pig.n), a) == 1.0)


def test_fresh_and_finished_tissue_stay_uniform():
    p, pig = _pigments()
    a = float(p["colour.mottle"])
    fresh = init_pigments(pig.n, p, seed=0)
    assert np.all(mottle_ratio(mottle_pigments(fresh, p), np.ones(pig.n), a) == 1.0)
    done = pig.copy()
    done.chlorophyll[:] = 0.0
    done.carotenoid[:] = 0.0
    done.browning[:] = 1.0
    done.necrosis[:] = 1.0
    assert np.all(mottle_ratio(mottle_pigments(done, p), -np.ones(pig.n), a) == 1.0)
    # half-turned tissue: where n > 0 it holds less chlorophyll, which absorbs red and blue
    # most, so the fleck is lighter in red and blue, and it is darker where n < 0
    mid = init_pigments(pig.n, p, seed=0)
    mid.chlorophyll[:] = 0.5
    r = mottle_ratio(mottle_pigments(mid, p), np.ones(pig.n), a)
    assert np.all(r[:, 0] > 1.05) and np.all(r[:, 2] > 1.0)
    assert np.all(mottle_ratio(mottle_pigments(mid, p), -np.ones(pig.n), a)[:, 0] < 0.97)


@pytest.mark.parametrize("species", ["oak", "maple"])
def test_the_view_gives_the_renderer_its_pigments(species):
    """LeafView's rows are the blade's (layer T) pigments with the contents its colours use: a
    photo species' fitted ones (oak), the palette's (maple); the mesh and the per-frame update
    carry them with the field's size, amount and the tissue's sample positions."""
    from leafsim.interactive.session import Session

    s = Session(species, overrides={"mesh.spacing": 0.04, "effects.pbd": False, "effects.shrink": False,
                                    "colour.age_rate": 0.3}, build=True)
    s.step(200)
    view, params, state = s.view, s.sim_params, s.state
    rows, size, amount = view.mottle(state, params)
    contents = view.photo_contents(params) if species == "oak" else None
    assert (species == "oak") == view.photo_colour
    rgb = pigments_to_rgb(state.pigments, params, contents)[view.T].astype(np.float64)
    x = rows[:, [0, 1, 2, 3, 8]].astype(np.float64) @ ABSORPTION.astype(np.float64)
    np.testing.assert_allclose(rows[:, 9:10] + BASE_REFLECTANCE * np.exp(-np.maximum(x, 0)), rgb, rtol=1e-4, atol=1e-6)
    assert size == params["colour.mottle_size"] and amount == params["colour.mottle"]
    mesh = view.mesh(state, params)
    np.testing.assert_array_equal(mesh.mottle, rows)
    assert mesh.mottle_rest.shape == (len(view.T), 2) and (mesh.mottle_size, mesh.mottle_amount) == (size, amount)
    # the rest positions (plus the leaf's offset), not the current ones: the flecks ride on the tissue
    np.testing.assert_allclose(mesh.mottle_rest - s.model.particle_rest[view.T][:, :2],
                               np.broadcast_to(leaf_offset(state.pigments.seed), (len(view.T), 2)), atol=1e-6)
    up = view.update(state, params)
    np.testing.assert_array_equal(up["mottle"], rows)
    assert up["mottle_size"] == size and up["mottle_amount"] == amount
