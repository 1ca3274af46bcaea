"""The documented library API (``build_leaf``, ``Run``/``Stop``, ``export_mesh``, ``ParamSet``,
``get_species``) called as a careless script would: every wrong type or value is one
LeafsimError line naming the argument, never a numpy/numba traceback, a crash, a hang, NaN in
a file or a file of another leaf's geometry (docs/robustness.md)."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from helpers.paths import HANG_S
from leafsim.base.errors import LeafsimError
from leafsim.config.species import get_species
from leafsim.export.mesh import export_mesh
from leafsim.pipeline import build_leaf
from leafsim.sim.run import Run, Stop


@pytest.fixture(scope="module")
def oak():
    sp = get_species("oak")
    params = sp.params.with_overrides({"mesh.spacing": 0.06})
    model = build_leaf(sp, params, seed=0).model
    run = Run(model, params, seed=0)
    for _ in run.frames(Stop(frames=3)):
        pass
    return sp, params, model, run.state


@pytest.fixture(scope="module")
def other(oak):
    """A second, coarser build of the same species (another particle count)."""
    sp = oak[0]
    params = sp.params.with_overrides({"mesh.spacing": 0.08})
    model = build_leaf(sp, params, seed=1).model
    assert model.particle_count != oak[2].particle_count
    return model, Run(model, params, seed=0).state


def one_line(e) -> str:
    msg = str(e.value)
    assert "\n" not in msg
    return msg


# ------------------------------------------------------------------ seeds

@pytest.mark.parametrize("seed", [0.5, 1.0, "0", -1, np.int32(-5), 2**63, True, float("nan")])  # (None: the model's own)
def test_bad_seed_is_one_line(oak, seed):
    sp, params, model, _ = oak
    with pytest.raises(LeafsimError, match="seed") as e:
        Run(model, params, seed=seed)
    assert "2**63-1" in one_line(e)
    with pytest.raises(LeafsimError, match="seed"):
        build_leaf(sp, params, seed=seed)


def test_numpy_integer_seed_is_a_seed(oak):
    _, params, model, _ = oak
    assert Run(model, params, seed=np.int64(3)).sim.seed == 3


# ------------------------------------------------------------------ params and species

@pytest.mark.parametrize("params", [{"mesh.spacing": 0.06}, {}, "oak", None])
def test_params_that_are_not_a_param_set(oak, params):
    sp, _, model, _ = oak
    with pytest.raises(LeafsimError, match="params") as e:
        build_leaf(sp, params, seed=0)
    assert "with_overrides" in one_line(e)
    with pytest.raises(LeafsimError, match="params"):
        Run(model, params)


@pytest.mark.parametrize("overrides", [[("osmosis.every", 2)], "osmosis.every=2"])
def test_overrides_that_are_not_a_mapping(oak, overrides):
    with pytest.raises(LeafsimError, match="expected a mapping") as e:
        oak[1].with_overrides(overrides)
    one_line(e)


def test_species_that_is_not_a_species(oak):
    _, params, _, _ = oak
    with pytest.raises(LeafsimError, match="get_species"):
        build_leaf("oak", params, seed=0)
    with pytest.raises(LeafsimError, match="species name"):
        get_species(3)


def test_model_that_is_not_a_model(oak):
    sp, params, model, _ = oak
    leaf = build_leaf(sp, params, seed=0)
    with pytest.raises(LeafsimError, match=r"leaf\.model"):
        Run(leaf, params)


# ------------------------------------------------------------------ Stop

@pytest.mark.parametrize("kw, name", [
    ({"frames": float("nan")}, "frames"), ({"frames": float("inf")}, "frames"), ({"frames": -5}, "frames"),
    ({"frames": 2.5}, "frames"), ({"frames": "10"}, "frames"), ({"frames": True}, "frames"),
    ({"frames": 10**30}, "frames"), ({"water_left": float("nan")}, "water_left"), ({"water_left": 1.5}, "water_left"),
    ({"water_left": -0.1}, "water_left"), ({"water_left": "0.5"}, "water_left"), ({"season": float("nan")}, "season"),
    ({"season": -1}, "season"), ({"water_left": 0.02, "max_frames": float("nan")}, "max_frames"),
    ({"water_left": 0.02, "max_frames": -1}, "max_frames"), ({}, "no criterion"), ({"max_frames": 5}, "no criterion"),
])
def test_bad_stop_is_one_line(kw, name):
    with pytest.raises(LeafsimError, match=f"Stop: {name}") as e:
        Stop(**kw)
    one_line(e)


def test_good_stops_still_hold(oak):
    _, params, model, _ = oak
    assert Stop(frames=np.int64(4)).frames == 4
    assert Stop(water_left=0, max_frames=0).water_left == 0.0
    run = Run(model, params, seed=0)
    assert list(run.frames(Stop(water_left=1.0))) == []  # holds already: nothing runs


def test_stop_that_is_not_a_stop(oak):
    _, params, model, _ = oak
    with pytest.raises(LeafsimError, match="stop"):
        next(Run(model, params).frames("dry"))


def test_nan_frames_does_not_hang():
    """Stop(frames=nan) used to run for ever (no frame is >= NaN)."""
    code = textwrap.dedent("""
        from leafsim.base.errors import LeafsimError
        from leafsim.sim.run import Stop
        try:
            Stop(frames=float("nan"))
        except LeafsimError as e:
            print("refused:", e)
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=HANG_S)
    assert "refused: Stop: frames" in out.stdout, out.stderr


# ------------------------------------------------------------------ Run with a state

def _mod(state, **kw):
    return dataclasses.replace(state.copy(), **kw)


def _crash_free(code: str) -> subprocess.CompletedProcess:
    """Run ``code`` (after building the coarse oak as M, P, S, M2, S2) in a child: a state that
    reaches the kernels unchecked aborts the interpreter (double free, segfault)."""
    head = textwrap.dedent("""
        import dataclasses
        import numpy as np
        from leafsim.base.errors import LeafsimError
        from leafsim.config.species import get_species
        from leafsim.pipeline import build_leaf
        from leafsim.sim.run import Run, Stop
        sp = get_species("oak")
        P = sp.params.with_overrides({"mesh.spacing": 0.06})
        M = build_leaf(sp, P, seed=0).model
        S = Run(M, P).state
        P2 = sp.params.with_overrides({"mesh.spacing": 0.08})
        M2 = build_leaf(sp, P2, seed=1).model
        S2 = Run(M2, P2).state
    """)
    return subprocess.run([sys.executable, "-c", head + textwrap.dedent(code)], capture_output=True, text=True, timeout=HANG_S)


def test_state_of_another_model_does_not_crash():
    out = _crash_free("""
        for name, st in [("other model", S2.copy()),
                         ("short q", dataclasses.replace(S.copy(), particle_q=S.particle_q[:-5].copy())),
                         ("empty vol_rest", dataclasses.replace(S.copy(), vol_rest=np.zeros(0)))]:
            try:
                run = Run(M, P, state=st)
                for _ in run.frames(Stop(frames=3)):
                    pass
                print(name, "ran")
            except LeafsimError as e:
                print(name, "refused:", e)
    """)
    assert out.returncode == 0, out.stderr[-500:]
    assert out.stdout.count("refused: Run: state ") == 3 and "other model refused: Run: state is a state of another model" in out.stdout, out.stdout


def test_a_state_swapped_in_after_the_run_was_made_does_not_crash():
    """run.state is a plain attribute (``leafsim run`` sets it after a resume) and Simulator.step
    is public: a state of another model, or an array cut short, given either way reached the
    kernels (exit 139, or a heap corruption abort; an audit's finding)."""
    out = _crash_free("""
        from leafsim.sim.simulator import Simulator
        def swapped():
            run = Run(M, P)
            run.state = S2.copy()
            for _ in run.frames(Stop(frames=3)):
                pass
        def stepped():
            Simulator(M, P).step(S2.copy())
        def cut():
            st = dataclasses.replace(S.copy(), particle_q=S.particle_q[:31].copy())
            Simulator(M, P, watchdog=False).step(st)
        def cut_pigments():
            st = Simulator(M, P).state()
            pig = dataclasses.replace(st.pigments, chlorophyll=st.pigments.chlorophyll[:10].copy())
            Simulator(M, P).step(dataclasses.replace(st, pigments=pig))
        for name, f in [("swapped", swapped), ("stepped", stepped), ("cut", cut), ("cut pigments", cut_pigments)]:
            try:
                f()
                print(name, "ran")
            except LeafsimError as e:
                print(name, "refused:", e)
    """)
    assert out.returncode == 0, out.stderr[-500:]
    lines = out.stdout.strip().splitlines()
    assert [ln.split(" refused: ")[0] for ln in lines] == ["swapped", "stepped", "cut", "cut pigments"], out.stdout
    assert "Run.frames: state is a state of another model" in lines[0] and "Simulator.step: state is a state of another model" in lines[1]
    assert "pigment array chlorophyll" in lines[3]


def test_a_state_edited_between_runs_is_checked_again(oak):
    """Run.frames checks run.state as it stands: water put in by hand, or a NaN, is refused
    naming the array (the NaN was reported as the simulation's own divergence)."""
    _, params, model, state = oak
    run = Run(model, params, state=state.copy())
    run.state.particle_water[:] *= 5
    with pytest.raises(LeafsimError, match="Run.frames: state array particle_water holds more water") as e:
        next(run.frames(Stop(frames=state.frame + 2)))
    one_line(e)
    run = Run(model, params, state=state.copy())
    run.state.particle_q[0, 0] = np.nan
    with pytest.raises(LeafsimError, match="Run.frames: state array particle_q holds NaN"):
        next(run.frames(Stop(frames=state.frame + 2)))


@pytest.mark.parametrize("params", [{"osmosis.diffusion": 1e-5}, None])
def test_a_simulator_s_params_must_be_a_param_set(oak, params):
    from leafsim.sim.simulator import Simulator

    with pytest.raises(LeafsimError, match="Simulator: params .* expected a ParamSet") as e:
        Simulator(oak[2], params)
    one_line(e)


@pytest.mark.parametrize("field, value", [
    ("particle_water", lambda s: np.full_like(s.particle_water, np.nan)),
    ("particle_water", lambda s: -s.particle_water),
    ("particle_q", lambda s: s.particle_q.astype(np.float32)),
    ("particle_q", lambda s: s.particle_q.tolist()),
    ("hinge_rest", lambda s: np.zeros(len(s.hinge_rest) + 100)),
    ("scalars", lambda s: np.zeros(1)),
    ("scalars", lambda s: np.array([np.nan, 3.0, 0.0])),
])
def test_bad_state_is_refused_before_the_kernels(oak, field, value):
    _, params, model, state = oak
    with pytest.raises(LeafsimError, match=f"Run: state array {field}") as e:
        Run(model, params, state=_mod(state, **{field: value(state)}))
    one_line(e)


def test_bad_pigments_are_refused(oak):
    _, params, model, state = oak
    pig = dataclasses.replace(state.pigments, chlorophyll=np.full_like(state.pigments.chlorophyll, np.nan))
    with pytest.raises(LeafsimError, match="chlorophyll"):
        Run(model, params, state=_mod(state, pigments=pig))
    with pytest.raises(LeafsimError, match="expected a leafsim.sim.model.State"):
        Run(model, params, state={"particle_q": state.particle_q})


def test_effects_as_one_string(oak):
    _, params, model, _ = oak
    with pytest.raises(LeafsimError, match=r"\['osmosis'\]"):
        Run(model, params, effects="osmosis")


def test_simulator_of_another_model(oak, other):
    from leafsim.sim.simulator import Simulator

    _, params, model, _ = oak
    with pytest.raises(LeafsimError, match="simulator"):
        Run(other[0], simulator=Simulator(model, params))


def test_a_good_state_still_runs(oak):
    _, params, model, state = oak
    run = Run(model, params, state=state.copy())
    for _ in run.frames(Stop(frames=state.frame + 2)):
        pass
    assert run.state.frame == state.frame + 2 and run.finite()
    Run(model, params, state=model.state())  # a fresh state without pigments is a state


# ------------------------------------------------------------------ export_mesh

def test_export_states_of_another_model(oak, other, tmp_path):
    sp, params, model, state = oak
    m2, s2 = other
    for states in ([s2], [state, s2]):
        with pytest.raises(LeafsimError, match="export: state") as e:
            export_mesh(model, states, tmp_path / "a.glb", params=params)
        one_line(e)
    # the other way round the indices fit, and the file was another leaf's geometry
    with pytest.raises(LeafsimError, match="export: state 0 is a state of another model"):
        export_mesh(m2, [state], tmp_path / "b.glb", params=params)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("field, value", [
    ("particle_q", lambda s: np.full_like(s.particle_q, np.nan)),
    ("particle_water", lambda s: np.full_like(s.particle_water, np.nan)),
])
def test_export_refuses_nan(oak, tmp_path, field, value):
    _, params, model, state = oak
    with pytest.raises(LeafsimError, match=f"{field} holds NaN"):
        export_mesh(model, [_mod(state, **{field: value(state)})], tmp_path / "nan.glb", params=params)
    assert not (tmp_path / "nan.glb").exists()


def test_export_bad_arguments(oak, other, tmp_path):
    from leafsim.appearance.view import LeafView

    _, params, model, state = oak
    out = tmp_path / "x.glb"
    cases = [
        (dict(states=None), "states"),
        (dict(params={"render.texture": True}), "params"),
        (dict(view=LeafView(other[0])), "view"),
        (dict(view=np.zeros((4, 4, 4), np.uint8)), "view"),
        (dict(view=LeafView(model, np.zeros((3, 3)))), "photo"),
        (dict(states=[state, state.copy()], times=[0.0]), "times"),
        (dict(states=[state, state.copy()], times=[0.0, float("nan")]), "times"),
        (dict(states=[state, state.copy()], times="ab"), "times"),
        (dict(states=[{"a": 1}]), "State"),
        (dict(path=None), "path"),
        # API words, not the CLI's flags (a format that does not exist was told to name the file .fbx)
        (dict(format="fbx"), r"format 'fbx': unknown mesh format \(expected one of"),
        (dict(format="obj"), r"the name says glb, format says obj"),
        (dict(texture="photo"), r"needs the leaf's photo in the view: view=LeafView.of_species"),
        (dict(texture="baked", states=[state, state.copy()]), r"export one state, or texture='colours'"),
    ]
    for kw, what in cases:
        kw = {"states": [state], "params": params, "path": out, **kw}
        with pytest.raises(LeafsimError, match=what) as e:
            export_mesh(model, kw.pop("states"), kw.pop("path"), **kw)
        one_line(e)
    assert not out.exists()


def test_export_good_calls_still_write(oak, tmp_path):
    _, params, model, state = oak
    export_mesh(model, state, tmp_path / "a.glb", params=params)
    export_mesh(model, [state, state.copy()], tmp_path / "b.glb", params=params, times=[0.0, 1.0])
    export_mesh(model, [model.state()], tmp_path / "c.glb")  # fresh state, default params and view
    assert {p.name for p in tmp_path.iterdir()} == {"a.glb", "b.glb", "c.glb"}


def test_run_continues_a_crumpled_or_strongly_curled_state(oak):
    """``Run(state=...)`` checks a state as a checkpoint's, and the simulator's own states must
    pass: a crumpled leaf folds some of its springs below 0.2 × their rest lengths (the thesis
    preset's ball: up to 1.1 %; 4 % here), and a strong bilayer's hinge_plastic (the largest angle
    a hinge asked for; its rest angle is clamped) passes 2π (6.1 rad on oak with
    shrink.sigma_surface_top 0.8).  A collapsed array (every spring crushed), half the leaf
    collapsed to a point and a scrambled array (most springs torn) are still refused."""
    from leafsim.sim.checkpoint import check_state

    sp, params, model, state = oak
    st = state.copy()
    ij = model.spring_ij
    fold = np.arange(0, len(ij), 25)  # 4 % of the springs folded to a tenth of their length
    a, b = ij[fold, 0], ij[fold, 1]
    st.particle_q[b] = st.particle_q[a] + 0.1 * (st.particle_q[b] - st.particle_q[a])
    st.hinge_plastic[:] = 6.1
    check_state(st, model, "crumpled")
    Run(model, params, seed=0, state=st)  # accepted
    bad = state.copy()
    bad.particle_q[:] = 0.0
    with pytest.raises(LeafsimError, match="does not form this leaf"):
        check_state(bad, model, "collapsed")
    bad = state.copy()
    half = bad.particle_q[:, 0] < np.median(bad.particle_q[:, 0])
    bad.particle_q[half] = bad.particle_q[half].mean(axis=0)
    with pytest.raises(LeafsimError, match="does not form this leaf"):
        check_state(bad, model, "half collapsed")
    bad = state.copy()
    bad.particle_q[:] = bad.particle_q + np.random.default_rng(0).normal(0.0, 0.05, bad.particle_q.shape)
    with pytest.raises(LeafsimError, match="does not form this leaf"):
        check_state(bad, model, "scrambled")
    bad = state.copy()
    bad.hinge_plastic[0] = 1e300
    with pytest.raises(LeafsimError, match="hinge_plastic"):
        check_state(bad, model, "garbage")


# ------------------------------------------------------------------ save_checkpoint

def test_save_checkpoint_refuses_foreign_or_nan_states(oak, other, tmp_path):
    """A state that no load could resume (another leaf's arrays, NaN) is refused before a byte
    is written, so the last good checkpoint at that path stays as it was."""
    from leafsim.sim.checkpoint import load_checkpoint, save_checkpoint

    _, params, model, state = oak
    ck = tmp_path / "checkpoint.npz"
    meta = {"species": "oak"}
    save_checkpoint(ck, model, state, meta)
    good = ck.read_bytes()
    bad_states = [other[1], _mod(state, particle_q=np.full_like(state.particle_q, np.nan)),
                  _mod(state, particle_water=np.where(np.arange(state.particle_water.size) == 3, np.inf, state.particle_water))]
    for bad in bad_states:
        with pytest.raises(LeafsimError, match=r"checkpoint .*the state to save (array particle_(q|water)|is a state of another model)") as e:
            save_checkpoint(ck, model, bad, meta)
        one_line(e)
        assert ck.read_bytes() == good
    assert load_checkpoint(ck, model, meta).frame == state.frame


def test_save_checkpoint_checks_the_drying_path_mesh_state_too(tmp_path):
    """With the drying path (the default mesh) the state carries the path mesh's state: NaN
    there, or none at all, is refused before writing, as a load would refuse it."""
    from leafsim.sim.checkpoint import load_checkpoint, save_checkpoint

    sp = get_species("oak")
    params = sp.params
    model = build_leaf(sp, params, seed=0).model
    assert model.path is not None
    state = Run(model, params, seed=0).state
    ck = tmp_path / "checkpoint.npz"
    save_checkpoint(ck, model, state, {"species": "oak"})
    good = ck.read_bytes()
    nan_path = state.copy()
    nan_path.path.particle_q[:] = np.nan
    for bad, what in ((nan_path, r"\(drying-path mesh\) array particle_q holds NaN"),
                      (dataclasses.replace(state.copy(), path=None), "has no drying-path mesh state")):
        with pytest.raises(LeafsimError, match=what) as e:
            save_checkpoint(ck, model, bad, {"species": "oak"})
        one_line(e)
        assert ck.read_bytes() == good
    assert load_checkpoint(ck, model, {"species": "oak"}).path is not None


def test_a_run_takes_the_seed_its_model_was_built_with():
    """``build_leaf(sp, p, 3)`` then ``Run(model, p)`` is ``leafsim run --seed 3``: the simulator's
    seed (colour variation, shrinkage field) defaulted to 0 whatever seed built the model."""
    sp = get_species("oak")
    p = sp.params.with_overrides({"mesh.spacing": 0.06, "shrink.patchiness": 1.0})
    model = build_leaf(sp, p, seed=3).model
    assert model.seed == 3 and (model.path is None or model.path.seed == 3)
    a, b, c = Run(model, p), Run(model, p, seed=3), Run(model, p, seed=0)
    assert a.sim.seed == 3
    for r in (a, b, c):
        for _ in r.frames(Stop(frames=5)):
            pass
    assert np.array_equal(a.state.particle_q, b.state.particle_q)
    assert not np.array_equal(a.state.particle_q, c.state.particle_q)  # the seeded shrinkage field


def test_a_state_without_pigments_is_refused_while_colour_is_on(oak):
    """Model.state() makes a state without pigments: with effects.colour on, the leaf stayed
    green without a word and a season stop ran 2000 frames before giving up."""
    _, params, model, _ = oak
    run = Run(model, params, state=model.state())
    with pytest.raises(LeafsimError, match="no pigments, yet effects.colour is on") as e:
        next(run.frames(Stop(frames=2)))
    one_line(e)
    run = Run(model, params.with_overrides({"effects.colour": False}), state=model.state())
    for _ in run.frames(Stop(frames=2)):
        pass


def test_an_edited_species_length_is_named(oak):
    sp = oak[0]
    for bad in (float("nan"), 0.0):
        with pytest.raises(LeafsimError, match="key 'length_m'") as e:
            build_leaf(dataclasses.replace(sp, length_m=bad), oak[1], seed=0)
        one_line(e)


def test_a_parameter_the_model_is_built_from_is_refused_at_run_time(oak):
    """A sweep of a rebuild parameter (mass, mesh, veins ...) over one model ran the same leaf
    every time without a word: Run names the parameter and says to build again; live
    parameters and the size guards (limits.*) still go."""
    _, params, model, _ = oak
    with pytest.raises(LeafsimError, match=r"mass.lma = 0.05 \(built with 0.08\).*build it again") as e:
        Run(model, params.with_overrides({"mass.lma": 0.05}))
    one_line(e)
    Run(model, params.with_overrides({"osmosis.every": 2, "limits.max_particles": 10_000}))


def test_a_simulator_refuses_a_parameter_the_model_is_built_from(oak):
    """Simulator(...) and set_params(...) took a changed rebuild parameter (mass.lma,
    veins.main.kappa, mesh.spacing) without a word and ignored it (30 frames bit-identical):
    refused as Run refuses it; live parameters still go, live."""
    from leafsim.sim.simulator import Simulator

    _, params, model, _ = oak
    with pytest.raises(LeafsimError, match=r"^Simulator: params set veins.main.kappa = 9.0 \(built with") as e:
        Simulator(model, params.with_overrides({"veins.main.kappa": 9.0}))
    one_line(e)
    sim = Simulator(model, params)
    with pytest.raises(LeafsimError, match=r"^Simulator.set_params: params set mesh.spacing = 0.05 \(built with 0.06\)") as e:
        sim.set_params(params.with_overrides({"mesh.spacing": 0.05}))
    one_line(e)
    assert sim.params is params  # the refused set changed nothing
    sim.set_params(params.with_overrides({"osmosis.every": 2}))
    assert sim.osmosis_every == 2


def test_a_run_s_own_state_is_not_checked_again_between_calls():
    """Run.frames checks in full only a state it did not step to itself: a free leaf that has
    fallen farther than the loaded-state bound (100 leaf lengths) was refused on the next call
    of a chunked run; dynamics.path = own at run time is obeyed, not refused as a build value."""
    sp = get_species("oak")
    p = sp.params.with_overrides({"mesh.spacing": 0.06, "dynamics.scene": "free"})
    model = build_leaf(sp, p, seed=0).model
    run = Run(model, p)
    for _ in run.frames(Stop(frames=2)):
        pass
    run.state.particle_q[:, 2] -= 1000.0 * model.length  # (as if it had fallen that far)
    for _ in run.frames(Stop(frames=4)):
        pass
    assert run.state.frame == 4
    built = build_leaf(sp, sp.params, seed=0).model
    assert built.path is not None
    Run(built, sp.params.with_overrides({"dynamics.path": "own"}))


def test_a_run_that_blows_up_raises_diverged(oak):
    """A leaf kicked to 10³⁰ m/s mid-run: the watchdog's runaway-motion error is a ``Diverged``
    (a LeafsimError), as docs/api.md promises, so ``except Diverged`` catches every blow-up."""
    from leafsim.sim.run import Diverged

    sp, params, model, _ = oak
    run = Run(model, params, seed=0)
    with pytest.raises(Diverged) as e:
        for _ in run.frames(Stop(frames=400)):
            if run.state.frame == 10:
                run.state.particle_qd[100, 2] = 1e30
    assert isinstance(e.value, LeafsimError) and "simulation unstable" in one_line(e)


def test_a_state_of_another_build_of_the_same_size_is_refused(tmp_path):
    """Two oaks of one draft config and two seeds have arrays of the same shapes, so the shapes
    cannot tell their states apart: measured on the other model the fold read −37.7° (3.7°),
    and an export put one leaf's positions on the other's triangles.  Each state names its
    model (``State.model_key``, the model's fingerprint): a state of the other build is refused
    by Run, Simulator.step, export and leaf_measures, in one line; a copy keeps the name."""
    from leafsim.config.presets import quality_overrides
    from leafsim.sim import leaf_measures
    from leafsim.sim.simulator import Simulator

    sp = get_species("oak")
    p = sp.params.with_overrides(quality_overrides("draft"))

    def shapes(model):  # every array of its fresh state
        return tuple((k, v.shape) for k, v in sorted(vars(model.state()).items()) if isinstance(v, np.ndarray))

    seen = {}
    for seed in range(60):  # the first two seeds whose builds have arrays of the same shapes
        m = build_leaf(sp, p, seed=seed).model  # (a seed moves the surface particles; 4 and 14 today)
        if shapes(m) in seen:
            a, b = seen[shapes(m)], m
            break
        seen[shapes(m)] = m
    else:
        pytest.fail("no two of 60 seeds build a draft oak of the same size")
    st = Run(a, p).state
    assert st.particle_q.shape == b.particle_rest.shape and st.spring_rest.shape == b.spring_rest0.shape
    assert a.fingerprint != b.fingerprint and st.copy().model_key == a.fingerprint
    for call in (lambda: Run(b, p, state=st.copy()), lambda: Simulator(b, p).step(st.copy()),
                 lambda: export_mesh(b, st, tmp_path / "never.glb", params=p), lambda: leaf_measures(b, st, p)):
        with pytest.raises(LeafsimError, match="state of another model") as e:
            call()
        one_line(e)
    leaf_measures(a, st, p)  # its own model's: fine


def test_a_drying_path_the_model_was_not_built_with_is_refused(oak):
    """``dynamics.path`` builds the drying-path mesh: a model built without it and run with the
    default (draft) path ran its own mesh throughout, 5× slower, and one built with the draft
    path run with ``fine`` ran the draft mesh with fine's solver settings, without a word.  Both
    are refused naming the parameter; ``own`` on a model with a path mesh leaves it unused."""
    sp = get_species("oak")
    own = build_leaf(sp, sp.params.with_overrides({"dynamics.path": "own"}), seed=3).model
    with pytest.raises(LeafsimError, match="dynamics.path = 'draft', but the model was built with 'own'") as e:
        Run(own, sp.params)
    one_line(e)
    built = build_leaf(sp, sp.params, seed=3).model
    assert built.path is not None
    with pytest.raises(LeafsimError, match="dynamics.path = 'fine'.*built with 'draft'"):
        Run(built, sp.params.with_overrides({"dynamics.path": "fine"}))
    Run(built, sp.params.with_overrides({"dynamics.path": "own"}))
    Run(built, sp.params)


def test_read_only_arrays_are_refused_before_anything_moves(oak):
    """A state whose velocities are a read-only broadcast ("start at rest") met a numba typing
    error after the osmosis had already moved its water: now refused, naming the array, with
    the state untouched."""
    from leafsim.sim.simulator import Simulator

    _, params, model, state = oak
    st = dataclasses.replace(state.copy(), particle_qd=np.broadcast_to(0.0, state.particle_qd.shape))
    with pytest.raises(LeafsimError, match="particle_qd is read-only") as e:
        Run(model, params, state=st)
    one_line(e)
    water = st.particle_water.copy()
    with pytest.raises(LeafsimError, match="particle_qd is read-only"):
        Simulator(model, params).step(st)
    assert np.array_equal(st.particle_water, water) and st.frame == state.frame
    st = state.copy()
    st.pigments.chlorophyll.flags.writeable = False
    with pytest.raises(LeafsimError, match="pigment array chlorophyll is read-only"):
        Simulator(model, params).step(st)


def test_a_run_s_own_state_edited_between_calls_is_checked(oak):
    """The state a run stepped to, edited in place before the next ``frames`` call (State is
    frozen, its arrays are not): water × 5 was taken as found, and a NaN was reported as the
    simulation's own divergence.  Both refused, naming the array; ``until`` that is not a
    function is named too."""
    _, params, model, state = oak
    run = Run(model, params, state=state.copy())
    for _ in run.frames(Stop(frames=state.frame + 1)):
        pass
    run.state.particle_water[:] *= 5
    with pytest.raises(LeafsimError, match="particle_water holds more water than the fresh leaf") as e:
        next(run.frames(Stop(frames=state.frame + 3)))
    one_line(e)
    run.state.particle_water[:] /= 5
    run.state.particle_q[3, 1] = np.nan
    with pytest.raises(LeafsimError, match="particle_q holds NaN"):
        next(run.frames(Stop(frames=state.frame + 3)))
    with pytest.raises(LeafsimError, match="until 5: expected a function"):
        next(run.frames(Stop(frames=state.frame + 3), until=5))


def test_a_simulator_stepping_nan_water_raises_diverged(oak):
    """Simulator.step called directly on water holding NaN: the shrink's ZeroDivisionError came out
    bare; it is a Diverged, as from Run."""
    from leafsim.sim.run import Diverged
    from leafsim.sim.simulator import Simulator

    _, params, model, state = oak
    st = state.copy()
    st.particle_water[:] = np.nan
    with pytest.raises(Diverged):
        Simulator(model, params).step(st)


def test_measures_views_and_exports_check_their_arguments(oak, other, tmp_path):
    """leaf_measures, LeafView.of_species and export_mesh as a careless script calls them: one
    line each, naming what is wrong; a state holding NaN gives every measure, as None."""
    from leafsim.appearance.view import LeafView
    from leafsim.sim import leaf_measures

    sp, params, model, state = oak
    maple = get_species("maple").params
    cases = [(lambda: leaf_measures(build_leaf(sp, params, seed=0), state, params), "expected a Model"),
             (lambda: leaf_measures(model, state, None), "params"),
             (lambda: leaf_measures(other[0], state, params), "state of another model"),
             (lambda: leaf_measures(model, state, maple), "which the model is built from"),
             (lambda: LeafView.of_species("oak", model, params), "expected a Species"),
             (lambda: LeafView.of_species(sp, build_leaf(sp, params, seed=0), params), "expected a Model"),
             (lambda: export_mesh(model, state, tmp_path / "a.glb", params=maple), "which the model is built from"),
             (lambda: export_mesh(model, state, tmp_path / "b.glb", params=params, extras={"a": float("nan")}),
              "extras: expected JSON values"),
             (lambda: export_mesh(model, state, tmp_path / "c.glb", params=params, extras={"a": object()}),
              "extras: expected JSON values")]
    for call, words in cases:
        with pytest.raises(LeafsimError, match=words) as e:
            call()
        one_line(e)
    assert not list(tmp_path.iterdir())
    good = leaf_measures(model, state, params)
    st = state.copy()
    st.particle_q[0, 0] = np.nan
    bad = leaf_measures(model, st, params)
    assert set(bad) == set(good) and bad["shape_midrib_fold_deg"] is None and good["shape_midrib_fold_deg"] is not None
