"""The compiled point–polygon kernels (leafsim.base.polykernels, behind geometry's
points_in_polygon and distance_to_polygon) against the numpy expressions they replaced: the same
arithmetic in the same order, so the results must be bit-identical, on vertices, on edges, on
horizontal and repeated edges too."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.paths import HANG_S
from leafsim.base.geometry import distance_to_polygon, points_in_polygon


def _inside_numpy(pts, poly):
    x0, y0 = poly[:, 0], poly[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    x, y = pts[:, 0:1], pts[:, 1:2]
    cond = (y0 > y) != (y1 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xi = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
    return (np.count_nonzero(cond & (x < xi), axis=1) % 2) == 1


def _distance_numpy(pts, poly):
    P, Q = poly, np.roll(poly, -1, axis=0)
    d = Q - P
    L2 = np.maximum((d * d).sum(1), 1e-30)
    x = pts[:, None, :]
    t = np.clip(((x - P) * d).sum(-1) / L2, 0, 1)
    proj = P + t[..., None] * d
    return np.sqrt(((x - proj) ** 2).sum(-1)).min(1)


def _polygon(rng, m, snap):
    ang = np.sort(rng.uniform(0.0, 2.0 * np.pi, m))
    r = rng.uniform(0.3, 1.0, m)
    poly = np.c_[r * np.cos(ang), r * np.sin(ang)]
    return np.round(poly * 20.0) / 20.0 if snap else poly  # snapped: horizontal and repeated vertices


@pytest.mark.parametrize("trial", range(12))
def test_bit_identical_to_numpy(trial):
    rng = np.random.default_rng(trial)
    poly = _polygon(rng, int(rng.integers(3, 300)), snap=trial % 3 == 0)
    pts = np.vstack([rng.uniform(-1.2, 1.2, (500, 2)), poly, 0.5 * (poly + np.roll(poly, -1, axis=0))])
    assert np.array_equal(points_in_polygon(pts, poly), _inside_numpy(pts, poly))
    assert np.array_equal(distance_to_polygon(pts, poly), _distance_numpy(pts, poly))


def test_shapes_and_known_values():
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    pts = [[0.5, 0.5], [2.0, 0.5], [0.5, -3.0], [0.25, 0.5]]
    assert points_in_polygon(pts, square).tolist() == [True, False, False, True]
    assert np.allclose(distance_to_polygon(pts, square), [0.5, 1.0, 3.0, 0.25])
    # one point as a flat list, no points, lists of lists, float32 input
    assert points_in_polygon([0.5, 0.5], square.tolist()).shape == (1,)
    assert distance_to_polygon(np.empty((0, 2)), square).shape == (0,)
    assert distance_to_polygon(np.array([[0.5, 2.0]], np.float32), square.astype(np.float32))[0] == pytest.approx(1.0)


@pytest.mark.parametrize("n", [1, 3, 4, 5, 40])
def test_few_and_many_points_agree_with_the_reference_at_nan_and_inf(n):
    """Both paths (numpy up to FEW_POINTS points, the compiled loops above) give the reference's
    bits, NaN and infinite coordinates included (NaN distance, outside)."""
    rng = np.random.default_rng(n)
    poly = _polygon(rng, 50, snap=False)
    pts = rng.uniform(-1.2, 1.2, (n, 2))
    pts[0] = [np.nan, 0.1]
    if n > 1:
        pts[1] = [np.inf, -np.inf]
    with np.errstate(invalid="ignore"):
        ref_in, ref_d = _inside_numpy(pts, poly), _distance_numpy(pts, poly)
    got_in, got_d = points_in_polygon(pts, poly), distance_to_polygon(pts, poly)
    assert np.array_equal(got_in, ref_in)
    assert np.array_equal(got_d, ref_d, equal_nan=True) and np.isnan(got_d[0])
    bad = poly.copy()
    bad[7] = np.nan  # a NaN vertex: NaN distances, as numpy's min gives
    with np.errstate(invalid="ignore"):
        assert np.array_equal(distance_to_polygon(pts[-1:].repeat(6, 0), bad), _distance_numpy(pts[-1:].repeat(6, 0), bad),
                              equal_nan=True)


def test_wrong_shapes_are_refused():
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    with pytest.raises(ValueError, match=r"shape \(n, 2\)"):
        points_in_polygon(np.zeros((10, 3)), square)
    with pytest.raises(ValueError, match=r"shape \(n, 2\)"):
        distance_to_polygon(np.zeros((10, 3)), square)
    with pytest.raises(ValueError, match=r"shape \(m, 2\)"):
        distance_to_polygon(np.zeros((10, 2)), square[:, 0])


def test_listing_the_species_loads_no_compiler():
    """`leafsim species` checks every outline (one-point queries): no numba for that."""
    import subprocess
    import sys

    code = ("import io, sys, contextlib\nfrom leafsim.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n    rc = main(['species'])\n"
            "print(rc, 'numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=HANG_S)
    assert out.stdout.split() == ["0", "False"], out.stdout + out.stderr
