"""``shrink.patchiness``: the blade's tissue shrinks unevenly, by a seeded smooth field of the
rest position (docs/method.md §4).  Off by default; on, every spring's σ and every hinge's
bilayer curl are × (1 + a z) with z of zero mean and unit spread over the blade, the stalk
uniform, the same field on every mesh of the leaf and a new one for every seed."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from leafsim.config.species import get_species
from leafsim.pipeline import build_leaf
from leafsim.sim.effects.shrink import Shrink
from leafsim.sim.model import SPRING_SURFACE, SPRING_VEIN
from leafsim.sim.simulator import Simulator
from leafsim.sim.veinframe import hinge_alignment


def _factors(spacing: float, patchiness: float, seed: int = 0, size: float = 0.01):
    """(model, σ factor per spring, curl factor per hinge) of maple at ``spacing``."""
    sp = get_species("maple")
    p = sp.params.with_overrides({"mesh.spacing": spacing})
    model = build_leaf(sp, p, 0).model
    base = Shrink(model)
    base.configure(p)
    sh = Shrink(model)
    sh.configure(p.with_overrides({"shrink.patchiness": patchiness, "shrink.patch_size": size}), seed)
    fs = np.divide(sh.sigma, base.sigma, out=np.ones_like(sh.sigma), where=base.sigma > 0)
    fh = np.divide(sh.hinge_curl, base.hinge_curl, out=np.ones_like(sh.hinge_curl), where=base.hinge_curl > 0)
    return model, fs, fh


def _mid(model, idx):
    return 0.5 * (model.particle_rest[idx[:, 0], :2] + model.particle_rest[idx[:, 1], :2])


@pytest.fixture(scope="module")
def coarse():
    return _factors(0.035, 0.8)


def test_off_by_default_changes_nothing():
    sp = get_species("maple")
    p = sp.params.with_overrides({"mesh.spacing": 0.035})
    assert p["shrink.patchiness"] == 0.0
    model = build_leaf(sp, p, 0).model
    sh = Shrink(model)
    sh.configure(p, seed=3)
    t = model.spring_type
    want = np.where(t == SPRING_SURFACE, p["shrink.sigma_surface_bottom"], np.where(t == SPRING_VEIN, p["shrink.sigma_vein"], 0.0))
    assert np.array_equal(sh.sigma, want)
    curl = np.where(model.hinge_vein, 0.0, 1.0 + p["shrink.curl_anisotropy"] * hinge_alignment(model))
    assert np.array_equal(sh.hinge_curl, curl)


def test_the_simulator_and_its_drying_path_shrink_with_the_leafs_seed():
    sp = get_species("maple")
    p = sp.params.with_overrides({"shrink.patchiness": 0.8})  # the default mesh: it has a drying path
    model = build_leaf(sp, p, 0).model
    assert model.path is not None
    sims = [Simulator(model, p, seed=s) for s in (0, 1)]
    assert not np.array_equal(sims[0]._shrink.sigma, sims[1]._shrink.sigma)
    for sim in sims:  # the coarse mesh of the drying path: the same seed, so the same patches
        assert sim._path is not None and sim._path.sim.seed == sim.seed
    assert not np.array_equal(sims[0]._path.sim._shrink.sigma, sims[1]._path.sim._shrink.sigma)
    # one effect reconfigured with another seed takes the new field (the cache is per seed)
    sh = Shrink(model)
    sh.configure(p, seed=0)
    first = sh.sigma.copy()
    sh.configure(p, seed=1)
    assert np.array_equal(sh.sigma, sims[1]._shrink.sigma) and not np.array_equal(sh.sigma, first)


def test_the_field_has_the_asked_spread_on_the_blade_and_none_on_the_stalk(coarse):
    model, fs, fh = coarse
    ij = model.spring_ij
    surface = model.spring_type == SPRING_SURFACE
    blade = surface & ~model.particle_petiole[ij].any(1)
    on_stalk = model.particle_petiole[ij].all(1)
    assert np.all(fs[on_stalk] == 1.0)
    # mean one, spread about a (a mean of two nearby points' z is a little narrower than z)
    assert abs(fs[blade].mean() - 1.0) < 0.08, fs[blade].mean()
    assert 0.55 < fs[blade].std() < 0.85, fs[blade].std()
    assert fs.min() >= 0.0 and fh.min() >= 0.0
    # the curl follows the same field: a hinge's factor is its shared edge's spring's (hinges
    # that bend a vein lengthwise have no curl to scale)
    h = model.hinge_idx
    edge = {tuple(sorted(e)): k for k, e in enumerate(ij.tolist())}
    pairs = [(k, edge[tuple(sorted((a, b)))]) for k, (a, b) in enumerate(h[:, 2:].tolist())
             if tuple(sorted((a, b))) in edge and blade[edge[tuple(sorted((a, b)))]] and not model.hinge_vein[k]]
    hk, sk = np.array(pairs).T
    assert np.allclose(fh[hk], fs[sk])


def test_every_mesh_of_the_leaf_shrinks_with_the_same_patches(coarse):
    ma, fa, _ = coarse
    mb, fb, _ = _factors(0.025, 0.8)
    sa = (ma.spring_type == SPRING_SURFACE) & ~ma.particle_petiole[ma.spring_ij].any(1)
    sb = (mb.spring_type == SPRING_SURFACE) & ~mb.particle_petiole[mb.spring_ij].any(1)
    d, k = cKDTree(_mid(ma, ma.spring_ij[sa])).query(_mid(mb, mb.spring_ij[sb]))
    assert np.corrcoef(fb[sb], fa[sa][k])[0, 1] > 0.9


def test_a_seed_is_a_new_field_and_the_same_seed_the_same(coarse):
    model, f0, _ = coarse
    _, f0b, _ = _factors(0.035, 0.8, seed=0)
    _, f1, _ = _factors(0.035, 0.8, seed=1)
    blade = (model.spring_type == SPRING_SURFACE) & ~model.particle_petiole[model.spring_ij].any(1)
    assert np.array_equal(f0, f0b)
    assert abs(np.corrcoef(f0[blade], f1[blade])[0, 1]) < 0.5
