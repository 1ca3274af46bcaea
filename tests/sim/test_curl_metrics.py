"""Dried-shape measures (leafsim.sim.curl) on shapes whose answer is known: a flat blade, a
sinusoidal wrinkle, a V fold along the midrib, a margin rolled up."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.synthetic import ellipse_shape, synthetic_veins
from leafsim.blade.build import build_blade
from leafsim.config.params import ParamSet
from leafsim.sim.curl import dried_shape, margin_roll, midrib_fold, wrinkles
from leafsim.sim.model import LAYER_T
from leafsim.veins.graph import MAIN, Vein, VeinGraph


@pytest.fixture(scope="module", params=[0.03, 0.02])
def model(request):
    s = ellipse_shape()
    return build_blade(s, synthetic_veins(s), ParamSet({"mesh.spacing": request.param}), seed=1)


def _with_z(model, z):
    q = model.particle_rest.copy()
    q[:, 2] = q[:, 2] + z(q[:, 0], q[:, 1])
    return q


def test_flat_blade_is_flat(model):
    q = model.particle_rest
    r = margin_roll(model, q)
    assert r["margin_roll_deg"] < 1.0 and abs(midrib_fold(model, q)) < 1.0
    w = wrinkles(model, q)
    assert w["wrinkle_rms_L"] < 1e-4 and w["wrinkle_wavelength_L"] is None


def test_sinusoidal_wrinkle_amplitude_and_wavelength(model):
    L = float(np.ptp(model.particle_rest[:, 1]))
    lam, amp = 0.12 * L, 0.004 * L  # 4 and 6 elements per wavelength on the two meshes
    q = _with_z(model, lambda x, y: amp * np.sin(2 * np.pi * x / lam))
    w = wrinkles(model, q)
    assert w["wrinkle_wavelength_L"] == pytest.approx(lam / L, rel=0.15)
    # the RMS is the mesh's own piecewise-linear surface's: a coarse mesh flattens the crests
    assert 0.65 * amp / np.sqrt(2) / L < w["wrinkle_rms_L"] < 1.05 * amp / np.sqrt(2) / L
    # a smooth bowl of the same height has (almost) no wrinkle
    bowl = _with_z(model, lambda x, y: 0.3 * ((x / L) ** 2 + ((y - 0.5 * L) / L) ** 2) * L)
    assert wrinkles(model, bowl)["wrinkle_rms_L"] < 0.1 * w["wrinkle_rms_L"]


@pytest.mark.parametrize("angle", [30.0, 90.0, -40.0])
def test_v_fold_along_the_midrib(model, angle):
    """The halves turned about the midrib by ±angle/2, lengths kept: + a valley (the halves
    rise), − a ridge."""
    q = model.particle_rest.copy()
    c, s = np.cos(np.radians(0.5 * angle)), np.sin(np.radians(0.5 * angle))
    x = q[:, 0]
    q[:, 0], q[:, 2] = np.abs(x) * c * np.sign(x), np.abs(x) * s
    assert midrib_fold(model, q) == pytest.approx(angle, abs=3.0)


def test_a_boat_or_a_lengthwise_curl_is_no_fold(model):
    """A blade bent end to end (a boat: each half curled along its length, as sweet chestnut
    dries) is not V-shaped across its midrib. The angle between the two halves' best-fit planes,
    the measure of before, read 90-180 degrees for such a curl: the plane of a half curled along
    its length is ill-defined."""
    L = float(np.ptp(model.particle_rest[:, 1]))
    for k in (2.0, 5.0, 8.0):  # curvature × L: up to a half-turn over the length
        R = L / k
        q = model.particle_rest.copy()
        y = q[:, 1] - 0.5 * L
        q[:, 1], q[:, 2] = R * np.sin(y / R), R * (1.0 - np.cos(y / R))  # rolled up, lengths kept
        assert abs(midrib_fold(model, q)) < 1.0, k
    # a V across the same curl is still read
    q = model.particle_rest.copy()
    x, y = q[:, 0], q[:, 1] - 0.5 * L
    c, s = np.cos(np.radians(20.0)), np.sin(np.radians(20.0))
    R = L / 3.0
    q[:, 0], h = x * c, np.abs(x) * s  # a 40° V ...
    q[:, 1], q[:, 2] = (R - h) * np.sin(y / R), R - (R - h) * np.cos(y / R)  # ... rolled up along y
    assert midrib_fold(model, q) == pytest.approx(40.0, abs=4.0)


def test_a_twist_about_the_midrib_is_no_fold(model):
    """The blade twisted about its midrib (each cross-section turned by an angle that grows
    along the length, ±19° at the ends of the measured span): no V across the midrib."""
    L = float(np.ptp(model.particle_rest[:, 1]))
    q = model.particle_rest.copy()
    q[:, 2] = q[:, 0] * (q[:, 1] - 0.5 * L) / L
    assert abs(midrib_fold(model, q)) < 1.0


@pytest.mark.parametrize("angle", [10.0, 30.0])
def test_a_v_across_a_curved_midrib(angle):
    """A midrib that bends sideways (0.06 L off the axis at mid-length, as traced midribs do):
    the halves turned up about the midrib itself read the V's angle within 1 % (taken along the
    strips' centroids instead of the midrib's own particles, the direction the normals are seen
    along leant sideways and read it 2.2 % low here, 1-11 % low on the species' leaves)."""
    s = ellipse_shape()
    L = s.length
    y = np.linspace(0.0, 0.97 * L, 60)
    curve = np.column_stack([0.06 * L * np.sin(np.pi * y / L), y])
    mid = Vein(order=MAIN, points=curve, widths=np.linspace(0.012 * L, 0.003 * L, len(y)))
    model = build_blade(s, VeinGraph(veins=[mid]), ParamSet({"mesh.spacing": 0.02}), seed=1)
    dense_y = np.linspace(0.0, 0.97 * L, 4000)
    dense = np.column_stack([0.06 * L * np.sin(np.pi * dense_y / L), dense_y])
    r = model.particle_rest[:, :2]
    d = np.min(np.linalg.norm(r[:, None, :] - dense[None], axis=2), axis=1)  # distance to the midrib
    q = model.particle_rest.copy()
    q[:, 2] = d * np.tan(np.radians(0.5 * angle))  # a V about the midrib (lengths across it × 1/cos)
    assert midrib_fold(model, q) == pytest.approx(angle, abs=0.01 * angle)


def test_rolled_margin(model):
    """The band within 15 % of the half-width of the margin bent up by 90°: the margin's
    normals lie in the plane."""
    q = model.particle_rest.copy()
    x = q[:, 0]
    w = float(np.abs(x).max())
    band = 0.85 * w
    out = np.abs(x) > band
    d = np.abs(x[out]) - band
    q[out, 0] = np.sign(x[out]) * band
    q[out, 2] = d  # turned straight up
    r = margin_roll(model, q)
    side = np.abs(model.particle_rest[model.contour_particles, 0]) > band + 0.2 * (w - band)
    assert side.mean() > 0.3
    assert r["margin_roll_p90_deg"] > 70.0
    d = dried_shape(model, model.state())
    assert set(d) >= {"margin_roll_deg", "midrib_fold_deg", "wrinkle_rms_L", "wrinkle_wavelength_L"}
    assert (model.particle_layer == LAYER_T).sum() > 100
