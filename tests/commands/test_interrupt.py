"""Runs that survive interruption (issue 9, point 6): statistics streamed frame by frame,
atomic checkpoints, ``--resume`` bit-identical to an uninterrupted run, SIGINT/SIGTERM end with
one line and 128 + signal — tested with real signals sent to a real ``leafsim run`` process."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from helpers.paths import HANG_S
from leafsim.cli import main

N = 200  # frames of the reference run (a few ms each at this mesh size)
BASE = ["run", "--species", "oak", "--set", "mesh.spacing=0.05", "--checkpoint-every", "7"]


def _stats(path):
    lines = [json.loads(x) for x in path.read_text().splitlines()]
    for x in lines:
        x.pop("ms")  # wall-clock timings are the only thing that may differ
    return lines


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """An uninterrupted run of N frames (in-process): its final state and statistics."""
    d = tmp_path_factory.mktemp("ref")
    assert main(BASE + ["--frames", str(N), "--out", str(d / "out"), "--stats", str(d / "s.jsonl"), "--json"]) == 0
    return np.load(d / "out" / "final.npz"), _stats(d / "s.jsonl")


def _start_and_signal(tmp_path, sig, min_lines=20, fresh_compile=False, extra=()):
    """Start a long run, wait until it has streamed ``min_lines`` frames, send ``sig``.
    ``fresh_compile``: the run compiles every kernel itself (an empty numba cache) while this
    process uses cached ones — the first run on a new machine against a later resume, which
    once differed in the 17th digit (fast-math reassociation depends on what LLVM inlined)."""
    out, stats = tmp_path / "out", tmp_path / "s.jsonl"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba")) if fresh_compile else None
    proc = subprocess.Popen([sys.executable, "-m", "leafsim", *BASE, "--frames", "1000000", "--out", str(out),
                             "--stats", str(stats), *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    # wait for progress (frames streamed), not for a clock: a fresh numba compile on a busy
    # machine may take minutes; only a run that makes no progress at all for HANG_S fails
    t0 = time.monotonic()
    while proc.poll() is None:
        if stats.exists() and stats.read_text().count("\n") >= min_lines:
            break
        if time.monotonic() - t0 > HANG_S:
            proc.kill()
            pytest.fail(f"the run streamed no {min_lines} frames in {HANG_S:.0f} s: hung")
        time.sleep(0.005)
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(sig)
    so, se = proc.communicate(timeout=HANG_S)
    return proc.returncode, so, se, out, stats


def _resume_to_n(out, stats, capsys):
    capsys.readouterr()
    assert main(BASE + ["--frames", str(N), "--out", str(out), "--stats", str(stats), "--resume", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["frame"] == N and 0 < rep["resumed_from"] < N
    # this invocation's seconds, and with the interrupted one's before it (kept in the checkpoint)
    assert rep["sim_s_total"] > rep["sim_s"] > 0
    return np.load(out / "final.npz"), _stats(stats)


def _assert_same(run, reference):
    (final, stats), (ref_final, ref_stats) = run, reference
    for k in ("particle_q", "particle_qd", "particle_water", "spring_rest"):
        assert np.array_equal(final[k], ref_final[k]), k  # bit-identical, not merely close
    assert stats == ref_stats


@pytest.mark.slow
def test_sigkill_then_resume_is_bit_identical(tmp_path, reference, capsys):
    code, so, se, out, stats = _start_and_signal(tmp_path, signal.SIGKILL, fresh_compile=True)
    assert code == -signal.SIGKILL
    assert not (out / "final.npz").exists()
    # every streamed line is a whole frame; the checkpoint is from a multiple of 7
    lines = [json.loads(x) for x in stats.read_text().splitlines()]
    assert len(lines) >= 20 and [x["frame"] for x in lines] == list(range(1, len(lines) + 1))
    meta = json.loads(str(np.load(out / "checkpoint.npz")["meta"]))
    assert meta["frame"] % 7 == 0 and 0 < meta["frame"] <= len(lines) < N
    _assert_same(_resume_to_n(out, stats, capsys), reference)
    assert not [p.name for p in out.iterdir() if p.name.endswith(".tmp")]  # a kill mid-write is cleaned up


@pytest.mark.parametrize("sig,code,as_json", [(signal.SIGTERM, 143, False), (signal.SIGINT, 130, True)])
def test_sigterm_and_sigint_stop_cleanly_and_resume(tmp_path, reference, capsys, sig, code, as_json):
    rc, so, se, out, stats = _start_and_signal(tmp_path, sig, extra=["--json"] if as_json else [])
    assert se.count("\n") == 1 and "Traceback" not in se, se
    name = signal.Signals(sig).name
    assert se.startswith("leafsim: interrupted at frame ") and f"(by {name})" in se and "--resume" in se
    # the frame in progress was finished and checkpointed: nothing computed is lost
    frame = int(se.split("interrupted at frame ")[1].split()[0])
    if as_json:  # --json still prints its one object, saying where the run stopped
        rep = json.loads(so)
        assert rc == code and rep["interrupted"] == name and rep["frame"] == frame == rep["frames"]
    else:
        assert rc == code and so == ""
    assert json.loads(str(np.load(out / "checkpoint.npz")["meta"]))["frame"] == frame
    assert stats.read_text().count("\n") == frame
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]
    if sig == signal.SIGTERM:  # (SIGINT takes the same path; one resume suffices)
        _assert_same(_resume_to_n(out, stats, capsys), reference)


def test_resume_continues_a_finished_run(tmp_path, reference, capsys):
    """The final checkpoint lets a finished run be extended: N/2 then N equals N."""
    out, stats = tmp_path / "out", tmp_path / "s.jsonl"
    assert main(BASE + ["--frames", str(N // 2), "--out", str(out), "--stats", str(stats)]) == 0
    _assert_same(_resume_to_n(out, stats, capsys), reference)


def test_resume_refuses_a_statistics_file_with_a_gap(tmp_path, capsys):
    """A stats file is continued on --resume only when it reaches the checkpoint: a resumed run
    without --stats in between left it at frame N/2 while the run went on, and the next resume
    with --stats appended from later on, without a word (frames missing in the middle)."""
    out, stats = tmp_path / "out", tmp_path / "s.jsonl"
    assert main(BASE + ["--frames", str(N // 2), "--out", str(out), "--stats", str(stats)]) == 0
    assert main(BASE + ["--frames", str(N // 2 + 3), "--out", str(out), "--resume"]) == 0
    before = stats.read_bytes()
    capsys.readouterr()
    assert main(BASE + ["--frames", str(N), "--out", str(out), "--stats", str(stats), "--resume"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"frames {N // 2 + 1}–{N // 2 + 3} are missing" in err and str(stats) in err
    assert stats.read_bytes() == before


def test_a_run_stopped_before_its_first_frame_leaves_the_old_statistics(tmp_path, capsys, monkeypatch):
    """--stats replaces its file at the run's first line, not when the run starts: a signal
    during the frame-0 picture left an empty file where the last run's statistics had been.
    A run that ends normally without a frame (--frames 0) still leaves its (empty) file."""
    import leafsim.commands.run as cr

    stats = tmp_path / "s.jsonl"
    stats.write_text('{"frame": 1}\n{"frame": 2}\n')

    def interrupted(*a, **k):
        os.kill(os.getpid(), signal.SIGINT)
        raise AssertionError("SIGINT did not interrupt")

    monkeypatch.setattr(cr.FrameWriter, "write", interrupted)
    assert main(BASE + ["--frames", "50", "--every", "5", "--out", str(tmp_path / "o"), "--stats", str(stats)]) == 130
    assert stats.read_text() == '{"frame": 1}\n{"frame": 2}\n'
    monkeypatch.undo()
    capsys.readouterr()
    assert main(BASE[:5] + ["--frames", "0", "--stats", str(stats)]) == 0, capsys.readouterr().err
    assert stats.exists() and stats.read_text() == ""
    capsys.readouterr()


def test_sigterm_during_the_build(capsys, monkeypatch):
    import leafsim.commands.shape

    def build_leaf(*a, **k):
        os.kill(os.getpid(), signal.SIGTERM)
        raise AssertionError("SIGTERM did not interrupt")

    monkeypatch.setattr(leafsim.commands.shape, "build_leaf", build_leaf)
    assert main(["build", "--species", "oak"]) == 143
    out, err = capsys.readouterr()
    assert out == "" and err == "leafsim: interrupted (by SIGTERM)\n"


@pytest.mark.parametrize("module,argv", [
    ("leafsim.commands.export", ["export", "--species", "oak", "--frames", "5", "--out", "X.glb"]),
    ("leafsim.compare.run", ["compare", "--species", "oak", "--stage", "dried"]),
])
def test_an_interrupted_command_still_prints_its_json_object(tmp_path, capsys, monkeypatch, module, argv):
    """``--json`` prints exactly one JSON object, an interrupted command's too: export and
    compare printed nothing when stopped (only ``run`` did)."""
    import importlib

    mod = importlib.import_module(module)

    def build_leaf(*a, **k):
        os.kill(os.getpid(), signal.SIGTERM)
        raise AssertionError("SIGTERM did not interrupt")

    monkeypatch.setattr(mod, "build_leaf", build_leaf)
    monkeypatch.chdir(tmp_path)
    assert main(argv + ["--json"]) == 143
    out, err = capsys.readouterr()
    rep = json.loads(out)
    assert rep["interrupted"] == "SIGTERM" and rep["command"] == argv[0] and out.count("\n") == 1
    last = err.strip().splitlines()[-1]  # (a first run says first that it compiles the kernels)
    assert last.startswith("leafsim: interrupted") and "(by SIGTERM)" in last
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv,needle", [
    (["--resume"], "--resume needs --out"),
    (["--checkpoint-every", "5"], "--checkpoint-every needs --out"),
    (["--checkpoint-every", "-1", "--out", "OUT"], "--checkpoint-every -1"),
    (["--resume", "--out", "OUT"], "no checkpoint at"),
])
def test_bad_checkpoint_options(capsys, tmp_path, argv, needle):
    argv = [a.replace("OUT", str(tmp_path / "o")) for a in argv]
    assert main(["run", "--species", "oak", "--frames", "3", *argv]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and needle in err


def test_resume_with_other_settings_refused(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(BASE + ["--frames", "7", "--out", str(out)]) == 0
    capsys.readouterr()
    for extra, needle in ((["--seed", "3"], "made with seed 0, this run has 3"),
                          (["--set", "osmosis.evaporation_top=0.5"], "parameter 'osmosis.evaporation_top' = 0.014, this run has 0.5"),
                          (["--species", "maple"], "made with species 'oak', this run has 'maple'")):
        assert main(BASE + ["--frames", "20", "--out", str(out), "--resume", *extra]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and needle in err, err


def test_corrupt_checkpoint(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "checkpoint.npz").write_bytes(b"PK\x03\x04 not a zip")
    assert main(BASE + ["--frames", "20", "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot read checkpoint" in err


def test_resume_from_a_checkpoint_written_before_the_weather_clock(tmp_path, reference, capsys):
    """Checkpoints from before the state carried the weather clock (two scalars) still resume,
    bit-identically."""
    out, stats = tmp_path / "out", tmp_path / "s.jsonl"
    assert main(BASE + ["--frames", str(N // 2), "--out", str(out), "--stats", str(stats)]) == 0
    ck = out / "checkpoint.npz"
    data = dict(np.load(ck))
    assert data["state_scalars"].shape == (3,)
    data["state_scalars"] = data["state_scalars"][:2]
    with open(ck, "wb") as f:
        np.savez(f, **data)
    _assert_same(_resume_to_n(out, stats, capsys), reference)


def test_weather_clock_survives_resume(tmp_path, capsys):
    weather = ["--set", "environment.drive=weather", "--set", "environment.time_warp=50000"]
    out = tmp_path / "out"
    assert main(BASE + weather + ["--frames", str(N // 2), "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(BASE + weather + ["--frames", str(N), "--out", str(out), "--resume", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["weather_hours"] == pytest.approx(N * 0.002 * 50000 / 3600, abs=1e-4)  # reported to 4 decimals
    assert rep["time_s"] == pytest.approx(N * 0.002, rel=1e-9)  # the simulated clock, through the resume too


def test_resume_from_a_checkpoint_older_than_a_parameter(tmp_path, reference, capsys):
    """A checkpoint written before a parameter existed resumes (bit-identically) when this run
    keeps that parameter at its default, the behaviour the checkpoint ran with; any other value
    is refused."""
    import json as _json

    out, stats = tmp_path / "out", tmp_path / "s.jsonl"
    assert main(BASE + ["--frames", str(N // 2), "--out", str(out), "--stats", str(stats)]) == 0
    ck = out / "checkpoint.npz"
    data = dict(np.load(ck))
    meta = _json.loads(str(data["meta"]))
    for k in ("dynamics.integrator", "dynamics.sun_courant", "material.turgor_pressure"):
        del meta["params"][k]
    data["meta"] = np.array(_json.dumps(meta, sort_keys=True))
    with open(ck, "wb") as f:
        np.savez(f, **data)
    capsys.readouterr()
    assert main(BASE + ["--frames", "120", "--out", str(out), "--resume", "--set", "dynamics.integrator=sun"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "parameter 'dynamics.integrator' = None, this run has 'sun'" in err, err
    _assert_same(_resume_to_n(out, stats, capsys), reference)


def test_a_nan_frame_keeps_the_last_good_checkpoint(tmp_path, monkeypatch, capsys):
    """A frame that produces NaN ends the run with one line and leaves the last good
    checkpoint (frame 6 of --checkpoint-every 3) for --resume: no NaN checkpoint, no final.npz."""
    from leafsim.sim import run as run_mod

    step = run_mod.Run.step

    def poisoned(self):
        out = step(self)
        if self.state.frame == 8:
            self.state.particle_q[5, 0] = np.nan
        return out

    monkeypatch.setattr(run_mod.Run, "step", poisoned)
    out = tmp_path / "out"
    assert main(BASE[:-2] + ["--checkpoint-every", "3", "--frames", "12", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "NaN at frame 8" in err
    ck = np.load(out / "checkpoint.npz")
    assert json.loads(str(ck["meta"]))["frame"] == 6 and np.isfinite(ck["state_particle_q"]).all()
    assert not (out / "final.npz").exists()


def test_stats_at_the_out_folder_is_refused_before_the_folder_is_made(tmp_path, capsys):
    """``--out D --stats D`` is one line and leaves nothing (the folder was made, then the
    statistics could not be written into a folder)."""
    d = tmp_path / "SX"
    assert main(["run", "--species", "oak", "--frames", "2", "--out", str(d), "--stats", str(d)]) == 2
    err = capsys.readouterr().err
    assert "that is the --out folder" in err and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("scene", ["ground", "free", "hanging"])
def test_a_run_that_went_nan_is_reported_as_such_in_every_scene(scene):
    """A falling or hanging leaf is measured in its own frame (a rigid fit): with NaN positions
    that fit failed with an internal error before the report's NaN check could say what
    happened (a review's finding)."""
    import types

    from leafsim.base.errors import LeafsimError
    from leafsim.commands.run import run_report
    from leafsim.config.species import get_species
    from leafsim.pipeline import build_leaf
    from leafsim.sim.run import Run

    sp = get_species("maple")
    p = sp.params.with_overrides({"mesh.spacing": 0.08, "dynamics.scene": scene})
    run = Run(build_leaf(sp, p, 0).model, p, seed=0)
    run.state.particle_q[3] = np.nan
    args = types.SimpleNamespace(seed=0, until=None)
    with pytest.raises(LeafsimError, match="produced NaN"):
        run_report(sp, p, args, run, [{"nan": True, "ms": {"a": 1.0}}], 0, 0.0, 0.0, None)
    rep = run_report(sp, p, args, run, [{"nan": True, "ms": {"a": 1.0}}], 0, 0.0, 0.0, None, check_nan=False)
    assert rep["nan"] is True  # the interrupted path's report, NaN and all


def test_a_checkpoints_earlier_seconds_are_read_only_when_they_are_seconds():
    from leafsim.commands.run import _prior_seconds

    assert _prior_seconds({"sim_s_total": 12.5}) == 12.5 and _prior_seconds({"sim_s_total": 0}) == 0.0
    for bad in ({}, {"sim_s_total": None}, {"sim_s_total": "x"}, {"sim_s_total": float("nan")},
                {"sim_s_total": -1.0}, {"sim_s_total": True}):
        assert _prior_seconds(bad) is None  # an older version's checkpoint, or a damaged one: unknown
