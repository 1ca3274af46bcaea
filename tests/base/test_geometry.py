"""Resampling closed outlines: the vertices (tooth tips, notches) survive."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from leafsim.base.geometry import resample_closed, resample_closed_keeping


def _perimeter(p):
    return float(np.linalg.norm(np.diff(np.vstack([p, p[:1]]), axis=0), axis=1).sum())


def test_keeping_resample_keeps_every_vertex_and_splits_edges_evenly():
    saw = np.array([[0, 0], [1, 3], [2, 0], [3, 3], [4, 0], [4, -1], [0, -1.0]])
    q = resample_closed_keeping(saw, 40)
    assert q.shape == (40, 2)
    for v in saw:  # every vertex is one of the points
        assert np.min(np.linalg.norm(q - v, axis=1)) < 1e-12
    assert np.allclose(q[0], saw[0])
    assert abs(_perimeter(q) - _perimeter(saw)) < 1e-9  # no corner cut
    # equal arc length cuts the teeth's tips
    assert _perimeter(resample_closed(saw, 40)) < _perimeter(saw) - 0.1


@given(st.integers(3, 30), st.integers(0, 200), st.integers(0, 2**31 - 1))
def test_keeping_resample_has_n_points_in_order(m, extra, seed):
    rng = np.random.default_rng(seed)
    ang = (np.arange(m) + rng.uniform(0.0, 0.4, m)) * (2 * np.pi / m)  # gaps < π: star-shaped about 0
    poly = np.column_stack([np.cos(ang), np.sin(ang)]) * rng.uniform(0.5, 1.5, (m, 1))
    n = m + extra
    q = resample_closed_keeping(poly, n)
    assert q.shape == (n, 2) and np.all(np.isfinite(q))
    assert abs(_perimeter(q) - _perimeter(poly)) < 1e-9 * _perimeter(poly)
    # the points run around the polygon in order: their angles never step back
    a = np.unwrap(np.arctan2(q[:, 1], q[:, 0]))
    assert np.all(np.diff(a) > -1e-12)


def test_fewer_points_than_vertices_fall_back_to_equal_arc_length():
    poly = np.column_stack([np.cos(np.linspace(0, 6, 50)), np.sin(np.linspace(0, 6, 50))])
    assert np.allclose(resample_closed_keeping(poly, 20), resample_closed(poly, 20))
