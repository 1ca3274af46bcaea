import json

import numpy as np
import pytest

from helpers.paths import HANG_S
from helpers.synthetic import ellipse_shape, synthetic_veins
from leafsim.base.errors import LeafsimError
from leafsim.blade.build import build_blade
from leafsim.config.params import ParamSet
from leafsim.sim.model import LAYER_T, LAYER_V
from leafsim.sim.run import run_headless
from leafsim.sim.shape import save_npz, shape_metrics
from leafsim.sim.simulator import Simulator

COARSE = {"mesh.spacing": 0.05}


@pytest.fixture(scope="module")
def model():
    s = ellipse_shape()
    return build_blade(s, synthetic_veins(s), ParamSet(COARSE), seed=2)


def _params(**kw):
    d = dict(COARSE)
    d.update({k.replace("__", "."): v for k, v in kw.items()})
    return ParamSet(d)


def test_water_nonnegative_and_never_increases(model):
    p = _params(osmosis__evaporation_top=2.8, osmosis__evaporation_bottom=1.75, osmosis__diffusion=1e-3)
    sim = Simulator(model, p, effects=("osmosis",))
    st = model.state()
    prev = st.particle_water.sum()
    for _ in range(150):
        sim.step(st)
        assert st.particle_water.min() >= 0.0
        tot = st.particle_water.sum()
        assert tot <= prev * (1 + 1e-12)
        prev = tot
    assert prev < 1e-9 * model.particle_water0.sum() + 1e-12  # fully dried in a few frames


@pytest.mark.parametrize("through", [False, True])
@pytest.mark.parametrize("solver", ["direct", "cg", "jacobi"])
def test_water_conserved_without_loss(model, solver, through):
    """No evaporation: water is conserved to round-off — per layer when the layers are separate
    (Jeong), in total when water also crosses the thickness (and then the layers equalise)."""
    p = _params(osmosis__evaporation_top=0, osmosis__evaporation_bottom=0, osmosis__diffusion=1e-2, osmosis__solver=solver,
                osmosis__through_thickness=through)
    sim = Simulator(model, p, effects=("osmosis",))
    st = model.state()
    rng = np.random.default_rng(0)
    st.particle_water[:] *= rng.uniform(0.2, 1.8, model.particle_count)  # non-uniform start
    tot0 = {l: st.particle_water[model.particle_layer == l].sum() for l in (LAYER_T, LAYER_V)}
    c0 = st.particle_water / model.particle_cytosol
    for _ in range(1000 if solver == "direct" else 200):
        sim.step(st)
    if through:  # Jacobi converges slowly on the stiff through-thickness coupling (2000-sweep cap)
        assert st.particle_water.sum() == pytest.approx(sum(tot0.values()), rel=1e-4 if solver == "jacobi" else 1e-6)
    else:
        for l in (LAYER_T, LAYER_V):
            assert st.particle_water[model.particle_layer == l].sum() == pytest.approx(tot0[l], rel=1e-6)
    # diffusion evens out the concentration: to a thousandth of its starting spread (1e-4 at most
    # after these frames), within each layer when they are separate (their totals differ, so
    # their levels do), over both when water crosses the thickness
    c = st.particle_water / model.particle_cytosol
    for part in ([model.particle_layer >= 0] if through else [model.particle_layer == l for l in (LAYER_T, LAYER_V)]):
        assert part.sum() > 100 and c0[part].std() > 0.5
        assert c[part].std() < 1e-3 * c0[part].std(), (c0[part].std(), c[part].std())
    if through:  # and the layers reach the same concentration
        cT, cV = (c[model.particle_layer == l].mean() for l in (LAYER_T, LAYER_V))
        assert abs(cT - cV) < 1e-3 * cT


def test_solvers_agree(model):
    out = []
    for solver in ("direct", "cg"):
        p = _params(osmosis__solver=solver, osmosis__tolerance=1e-12, osmosis__diffusion=1e-3)
        sim = Simulator(model, p, effects=("osmosis",))
        st = model.state()
        st.particle_water[:] *= np.linspace(0.5, 1.5, model.particle_count)
        for _ in range(50):
            sim.step(st)
        out.append(st.particle_water.copy())
    assert np.allclose(out[0], out[1], rtol=1e-7, atol=1e-12)


def test_leaf_at_rest_stays_put(model):
    p = _params(osmosis__evaporation_top=0, osmosis__evaporation_bottom=0, dynamics__gravity=0.0)
    sim = Simulator(model, p)
    st = model.state()
    for _ in range(500):
        sim.step(st)
    drift = np.linalg.norm(st.particle_q - model.particle_rest, axis=1).max()
    assert drift < 1e-6 * model.length


def test_rest_lengths_within_bounds(model):
    p = _params(osmosis__evaporation_top=0.35, osmosis__evaporation_bottom=0.35, shrink__sigma_surface_top=3.0, shrink__l_min=0.3)
    sim = Simulator(model, p, effects=("osmosis", "shrink"))
    st = model.state()
    l0 = model.spring_rest0
    for _ in range(100):
        sim.step(st)
        assert (st.spring_rest >= 0.3 * l0 * (1 - 1e-12)).all() and (st.spring_rest <= l0 * (1 + 1e-12)).all()
    assert (st.spring_rest < l0).any()


def test_disabled_effects_leave_state_untouched(model):
    p = _params(osmosis__evaporation_top=0.14)
    st = model.state()
    Simulator(model, p, effects=("shrink", "pbd", "gravity", "ground")).step(st)
    assert np.array_equal(st.particle_water, model.particle_water0)  # osmosis off
    st = model.state()
    st.particle_water[:] *= 0.5
    Simulator(model, p, effects=("osmosis", "pbd", "gravity")).step(st)
    assert np.array_equal(st.spring_rest, model.spring_rest0)  # shrink off
    st = model.state()
    st.particle_water[:] *= 0.5
    ms = Simulator(model, p, effects=("osmosis", "shrink")).step(st)
    assert np.array_equal(st.particle_q, model.particle_rest) and not st.particle_qd.any()  # dynamics off
    assert set(ms) == {"osmosis", "shrink"}
    with pytest.raises(LeafsimError):
        Simulator(model, p, effects=("osmosis", "warp_drive"))


def _cup(model, st):
    T = model.particle_layer == LAYER_T
    q = st.particle_q
    return np.median(q[model.contour_particles, 2]) - np.median(q[T, 2])


@pytest.mark.parametrize("top,bottom,sign", [(0.14, 0.035, +1), (0.035, 0.14, -1)])
def test_top_drying_faster_curls_margin_up(model, top, bottom, sign):
    """Sign test (free, no gravity, equal σ in both layers, Jeong's separate layers): the
    faster-drying side is concave."""
    p = _params(osmosis__evaporation_top=top, osmosis__evaporation_bottom=bottom, dynamics__gravity=0.0, dynamics__scene="free",
                shrink__sigma_surface_top=0.15, shrink__sigma_surface_bottom=0.15, dynamics__dt=0.01,
                osmosis__through_thickness=False)
    st, stats = run_headless(model, p, 80)
    assert not stats[-1]["nan"]
    assert sign * _cup(model, st) > 0.01 * model.length


@pytest.mark.parametrize("top,bottom,sign", [(0.2, 0.12, +1), (0.12, 0.2, -1)])
def test_layer_that_shrinks_more_is_concave(model, top, bottom, sign):
    """Linked layers (water crosses the thickness, both dry alike): the curl's sign follows σ."""
    p = _params(osmosis__evaporation_top=0.1, osmosis__evaporation_bottom=0.1, dynamics__gravity=0.0, dynamics__scene="free",
                shrink__sigma_surface_top=top, shrink__sigma_surface_bottom=bottom, dynamics__dt=0.01)
    st, stats = run_headless(model, p, 80)
    assert not stats[-1]["nan"]
    assert sign * _cup(model, st) > 0.01 * model.length


def test_live_param_change(model):
    p = _params()
    sim = Simulator(model, p)
    st = model.state()
    sim.step(st)
    w1 = st.particle_water.sum()
    sim.set_params(p.with_overrides({"osmosis.evaporation_top": 0, "osmosis.evaporation_bottom": 0, "effects.osmosis": True}))
    sim.step(st)
    assert st.particle_water.sum() == pytest.approx(w1, rel=1e-9)
    sim.set_params(p.with_overrides({"effects.pbd": False, "effects.gravity": False}))
    q = st.particle_q.copy()
    sim.step(st)
    assert np.array_equal(q, st.particle_q)


def test_run_headless_stats_and_npz(model, tmp_path):
    p = _params()
    path = tmp_path / "stats.jsonl"
    st, stats = run_headless(model, p, 5, stats_path=path)
    assert len(stats) == 5
    rows = [json.loads(l) for l in path.read_text().splitlines()]
    assert rows[-1]["frame"] == 5
    for k in ("water_T", "water_V", "residual", "kinetic", "nan", "ms", "iterations"):
        assert k in rows[0]
    assert set(rows[0]["ms"]) >= {"osmosis", "shrink", "dynamics"}
    out = tmp_path / "leaf.npz"
    save_npz(out, model, st)
    z = np.load(out)
    assert np.array_equal(z["particle_q"], st.particle_q)
    assert not [f for f in tmp_path.iterdir() if f.name.startswith(".tmp")]
    with pytest.raises(LeafsimError):
        save_npz(tmp_path / "missing_dir" / "x.npz", model, st)
    m = shape_metrics(model, st)
    assert m["area_ratio"] == pytest.approx(1.0, abs=0.05) and m["inverted"] == 0


def test_drying_leaf_on_ground_curls():
    """Defaults (ground scene, g = 9.81) on a coarse mesh: the dried leaf's margin is lifted
    ≥ 10 % of its length and it keeps 70–95 % of its 3D area."""
    s = ellipse_shape()
    p = ParamSet({"mesh.spacing": 0.045})  # everything else default (Δt 0.002 s, 5 × 2 iterations)
    m = build_blade(s, synthetic_veins(s), p, seed=1)
    assert p["dynamics.scene"] == "ground" and p["dynamics.gravity"] == pytest.approx(9.81)
    st, stats = run_headless(m, p, 3500)
    met = shape_metrics(m, st)
    assert met["water_fraction_left"] < 0.01
    assert met["margin_lift"] >= 0.10, met
    assert 0.70 <= met["area_ratio"] <= 0.95, met
    assert met["inverted"] == 0
    assert st.particle_q[:, 2].min() >= -1e-9


def test_simulator_runs_colour_itself(model):
    """One Simulator runs every effect, colour included: no GUI session needed; a state it makes
    carries pigments, a disabled colour effect leaves them untouched, snapshots copy them."""
    p = _params(colour__age_rate=2.0, osmosis__evaporation_top=0.14)
    sim = Simulator(model, p, seed=3)
    st = sim.state()
    assert st.pigments is not None and st.pigments.n == model.particle_count
    snap = st.copy()
    for _ in range(20):
        ms = sim.step(st)
    assert "colour" in ms
    assert st.pigments.chlorophyll.mean() < snap.pigments.chlorophyll.mean()  # aged
    np.testing.assert_array_equal(snap.pigments.chlorophyll, 1.0)  # the snapshot did not move
    off = Simulator(model, p.with_overrides({"effects.colour": False}), seed=3)
    st2 = off.state()
    chl = st2.pigments.chlorophyll.copy()
    for _ in range(20):
        ms = off.step(st2)
    assert "colour" not in ms
    np.testing.assert_array_equal(st2.pigments.chlorophyll, chl)
    # same seed, same leaf: two simulators give identical pigments
    a, b = Simulator(model, p, seed=5).state(), Simulator(model, p, seed=5).state()
    np.testing.assert_array_equal(a.pigments.leaf, b.pigments.leaf)


def test_cli_run_does_not_use_the_gui_session(tmp_path):
    import subprocess
    import sys

    code = ("import sys; from leafsim.cli import main; rc = main(['run', '--species', 'oak', '--frames', '3', "
            "'--set', 'mesh.spacing=0.08', '--json']); "
            "sys.stderr.write('SESSION' if 'leafsim.interactive.session' in sys.modules else 'OK'); sys.exit(rc)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 0, r.stderr
    assert r.stderr.endswith("OK"), r.stderr
    assert json.loads(r.stdout)["frames"] == 3


def test_the_stats_residual_is_the_mesh_that_carried_the_mechanics():
    """While a drying path carries the mechanics the residual is its mesh's (the solver's); the
    own mesh's springs only take the prolongation's positions. After the hand-over it is the
    own mesh's."""
    from leafsim.config.species import get_species
    from leafsim.pipeline import build_leaf
    from leafsim.sim.kernels.pbd import residual
    from leafsim.sim.stats import frame_stats

    sp = get_species("oak")
    params = sp.params  # the default mesh, finer than its drying path's
    m = build_leaf(sp, params, 0).model
    sim = Simulator(m, params, seed=0)
    st = sim.state()
    for _ in range(3):
        ms = sim.step(st)
    assert sim.on_path and sim.mechanics_mesh == 1
    row = frame_stats(m, st, ms, sim)
    assert row["residual"] == residual(st.path.particle_q, m.path.spring_ij, st.path.spring_rest)
    assert row["residual"] != residual(st.particle_q, m.spring_ij, st.spring_rest)
    sim.set_params(params.with_overrides({"dynamics.handover": 1.0}))  # the own mesh takes over now
    ms = sim.step(st)
    assert not sim.on_path and frame_stats(m, st, ms, sim)["residual"] == residual(st.particle_q, m.spring_ij, st.spring_rest)


def test_stage_timings_are_the_stepping_threads_cpu_time(model):
    """The stage timings are CPU time of the stepping thread, so a stage that waits for the GIL
    (the window's UI thread drawing in Python) does not count the wait: the GUI's stats read
    "shrink 29 ms" for a 0.2 ms kernel when they were wall time.  With another thread spinning
    in Python, the stages of 30 frames sum to no more than the thread's own CPU time over them
    (wall-clock stages exceed it: each return from a GIL-free kernel waits for the spinner)."""
    import threading
    import time

    p = _params(osmosis__evaporation_top=2.8, colour__age_rate=2.0)
    sim = Simulator(model, p, seed=1)
    st = sim.state()
    sim.step(st)  # compiled and warm
    stop = threading.Event()

    def spin():
        x = 0
        while not stop.is_set():
            x += 1

    t = threading.Thread(target=spin, daemon=True)
    t.start()
    try:
        c0 = time.thread_time()
        total = sum(sum(sim.step(st).values()) for _ in range(30))
        cpu_ms = (time.thread_time() - c0) * 1e3
    finally:
        stop.set()
        t.join()
    assert 0.0 < total <= cpu_ms + 1e-6
