"""Resolution-independent probe metrics (the accuracy study's error measures)."""

import numpy as np
import pytest

from leafsim.config.species import get_species
from leafsim.pipeline import build_leaf
from leafsim.sim.metrics import Probe, field_errors


@pytest.fixture(scope="module")
def two_meshes():
    sp = get_species("oak")
    out = []
    for s in (0.06, 0.042):
        shape, _, model = build_leaf(sp, sp.params.with_overrides({"mesh.spacing": s}), 0)
        out.append(model)
    return Probe(shape), out


def test_same_leaf_on_two_meshes_agrees_at_rest(two_meshes):
    probe, (a, b) = two_meshes
    assert a.particle_count < b.particle_count
    e = field_errors(probe.fields(a, a.state()), probe.fields(b, b.state()), probe.length)
    assert e["position_rms"] < 2e-3 and e["height_rms"] == 0.0 and e["water_rms"] < 1e-12
    assert e["d_area_top"] < 0.01


def test_rigid_motion_is_no_error_in_own_frame(two_meshes):
    probe, (a, _) = two_meshes
    ref = probe.fields(a, a.state())
    st = a.state()
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    st.particle_q[:] = st.particle_q @ R.T + [0.2, -0.1, 0.0]
    e = field_errors(probe.fields(a, st), ref, probe.length)
    assert e["position_rms"] < 1e-12 and e["d_area_3d"] < 1e-12 and e["d_area_top"] < 0.01


def test_known_bend_is_measured(two_meshes):
    """Lift the blade by z = k y²: heights follow exactly, the top-down area shrinks less than
    the 3D area grows, margin lift = the highest margin point."""
    probe, (a, _) = two_meshes
    ref = probe.fields(a, a.state())
    st = a.state()
    L = probe.length
    st.particle_q[:, 2] += 0.3 * st.particle_q[:, 1] ** 2 / L
    f = probe.fields(a, st)
    ymax = probe.margin[:, 1].max()
    assert f["margin_lift"] == pytest.approx(0.3 * ymax ** 2 / L / L, rel=0.02)
    e = field_errors(f, ref, L)
    assert e["height_rms"] > 0.05 and f["area_3d"] > 1.0 and f["area_top"] == pytest.approx(1.0, abs=0.01)


def test_a_cached_embedding_serves_only_the_model_it_was_made_for(two_meshes):
    """A freed model's ``id`` is reused by a later one (CI once indexed a coarse oak's 600
    triangles with a fine oak's embedding): the cache must notice the entry is another model's."""
    import weakref

    from leafsim.sim.metrics import embed

    probe, (a, b) = two_meshes
    probe._emb[id(b)] = (weakref.ref(a), probe.embedding(a))  # as if ``a`` had died and ``b`` took its id
    got, want = probe.embedding(b), embed(b, probe.points)
    assert np.array_equal(got.tri, want.tri) and np.allclose(got.bary, want.bary)
    assert probe.fields(b, b.state())["q"].shape == (len(probe.points), 3)
