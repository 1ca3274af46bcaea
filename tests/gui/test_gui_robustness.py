"""A hostile user at the window: every text and number the GUI takes (export folder, preset
JSON path, seed, the parameter sliders' typed values), every button that writes a file
("Export frame", "Record take", "Export mesh", "Save params") and a simulation that fails in
its worker thread.  Each bad input must end as one line in the status bar naming what was
wrong, with nothing written but a regular file, and the window must keep running and stay
usable (the same app is used afterwards).  Driven like tests/gui/test_app.py; every wait is
for progress (a frame reached, an error shown), never for a clock."""

from __future__ import annotations

import json
import os

# hard dependencies (pyproject.toml): a broken install must fail here, not skip the GUI tests
import imgui_bundle  # noqa: F401
import moderngl  # noqa: F401
import numpy as np
import pytest

from helpers.gui import wait_until
from leafsim.base.errors import LeafsimError
from leafsim.config.params import PARAMS

pytestmark = pytest.mark.usefixtures("xdisplay")

PLAY = "**/###play"
SMALL = {"mesh.spacing": 0.06}


def run_gui(test_fn, species="oak", overrides=SMALL, seed=0):
    """Run the app with ``test_fn(ctx, app)`` driving it; returns the app afterwards."""
    from imgui_bundle.immapp import testing

    from leafsim.gui.app import LeafApp, _configure_threads, without_test_time_limit
    from leafsim.interactive.session import Session

    _configure_threads()
    session = Session(species, overrides=overrides, seed=seed)
    app = LeafApp(session)
    rp = app.runner_params()
    without_test_time_limit(rp)
    testing.run(test_function=lambda ctx: test_fn(ctx, app), runner_params=rp, add_ons_params=app.addons())
    return app


def clear(app):
    for m in app.status.messages():
        app.status.clear(m.topic)


def errors(app) -> list[str]:
    return [m.text for m in app.status.messages() if m.level == "error"]


def one_line(text) -> bool:
    return bool(text) and "\n" not in text and "internal error" not in text and "Traceback" not in text


def still_usable(ctx, app, seen, key):
    """The window keeps drawing and the simulation still steps (Step button)."""
    s = app.session
    f0, g0 = app.gui_frames, s.frame
    ctx.item_click("**/Step")
    wait_until(ctx, lambda: s.frame > g0, 600)
    seen[key] = (app.gui_frames > f0, s.frame > g0)


# ------------------------------------------------------------------ export folder
def test_bad_export_folders_are_one_line_errors_for_every_export_button(tmp_path, monkeypatch):
    """Empty, a file, a link to a file, a broken link, a link loop, a path under a file, a path
    too long for the system, a NUL character, /proc: "Export frame", "Record take" and "Export
    mesh" each answer with one line naming the export folder; nothing is created; afterwards a
    good folder works.  (An empty field used to export into the working folder.)"""
    monkeypatch.chdir(tmp_path)  # whatever a relative or empty folder would reach is seen below
    afile = tmp_path / "a_file"
    afile.write_text("x")
    (tmp_path / "link_file").symlink_to(afile)
    (tmp_path / "broken").symlink_to(tmp_path / "nowhere")
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    before = sorted(p.name for p in tmp_path.iterdir())
    bad = {"empty": "", "file": str(afile), "link to a file": str(tmp_path / "link_file"),
           "broken link": str(tmp_path / "broken"), "link loop": str(tmp_path / "loop"),
           "under a file": str(afile / "sub"), "too long": str(tmp_path / ("x" * 5000)),
           "long name": str(tmp_path / ("y" * 300)), "NUL": str(tmp_path / "a\0b"), "/proc": "/proc"}
    good = tmp_path / "out"
    seen = {}

    def body(ctx, app):
        for name, value in bad.items():
            for button in ("Export frame", "###record", "Export mesh"):
                clear(app)
                if name in ("too long", "NUL"):
                    app.export_dir = value  # what the field holds (imgui cannot type a NUL)
                else:
                    ctx.item_input_value("**/export folder", value)
                ctx.item_click(f"**/{button}")
                wait_until(ctx, lambda: errors(app) or app.take is not None, 60)
                seen[(name, button)] = (errors(app), app.take is not None)
                if app.take is not None:
                    ctx.item_click("**/###record")
        seen["last bad"] = errors(app)
        ctx.item_input_value("**/export folder", str(good))  # (the last refusal is not dismissed: the export clears it)
        ctx.item_click("**/Export frame")
        wait_until(ctx, lambda: app.exported, 60)
        seen["after frame"] = errors(app)  # Export mesh's refusal went when the folder served another button
        ctx.item_click("**/Export mesh")
        ctx.yield_(2)
        seen["good"] = errors(app)
        still_usable(ctx, app, seen, "usable")

    run_gui(body)
    for (name, button), (errs, recording) in ((k, v) for k, v in seen.items() if isinstance(k, tuple)):
        assert len(errs) == 1 and one_line(errs[0]), f"{name} / {button}: {errs}"
        assert "export folder" in errs[0], f"{name} / {button}: {errs[0]}"
        assert not recording, f"{name} / {button}: recording started"
    assert "empty" in seen[("empty", "Export frame")][0][0]
    assert "broken symbolic link" in seen[("broken link", "Export frame")][0][0]
    assert len(seen["last bad"]) == 1 and seen["after frame"] == [] and seen["good"] == [] and seen["usable"] == (True, True)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(before + ["out"])
    assert len(list(good.glob("*.png"))) == 1 and len(list(good.glob("*.glb"))) == 1


def test_export_folder_with_non_utf8_bytes_or_format_characters(tmp_path):
    """A folder whose name is not UTF-8 (as Path.cwd() gives it in such a folder: the field and
    the status bar could not be drawn, every frame an internal error) is shown escaped in the
    field and the status bar, and the export lands in it; printf's % in a name is just text."""
    folder = os.fsdecode(os.fsencode(str(tmp_path)) + b"/caf\xe9")
    percent = tmp_path / "%s%n%x"
    seen = {}

    def body(ctx, app):
        app.export_dir = folder
        ctx.mouse_move("**/export folder")  # its tooltip shows the path too
        ctx.yield_(3)
        seen["drawn"] = errors(app)
        ctx.item_click("**/Export frame")
        wait_until(ctx, lambda: app.exported, 60)
        ctx.mouse_move("**/copy path###copy")
        ctx.yield_(3)
        seen["after"] = errors(app)
        seen["msg"] = app.status.get("export").text
        ctx.item_input_value("**/export folder", str(percent))
        ctx.mouse_move("**/export folder")
        ctx.item_click("**/Export frame")
        wait_until(ctx, lambda: len(app.exported) >= 2, 60)
        ctx.mouse_move("**/copy path###copy")
        ctx.yield_(3)
        seen["percent"] = errors(app)

    run_gui(body)
    assert seen["drawn"] == [] and seen["after"] == [] and seen["percent"] == []
    assert "caf\\xe9" in seen["msg"]
    assert [p.suffix for p in (tmp_path / os.fsdecode(b"caf\xe9")).iterdir()] == [".png"]
    assert [p.suffix for p in percent.iterdir()] == [".png"]


# ------------------------------------------------------------------ seed
def test_seed_field_takes_every_valid_seed_and_names_bad_ones():
    """A seed beyond 32 bits (valid on the command line, up to 2**63-1) is shown and editable;
    a negative, non-numeric or too large one is an error naming the seed, the staged seed
    unchanged; a good one clears the error."""
    seen = {}

    def body(ctx, app):
        s = app.session
        ctx.yield_(3)
        seen["big"] = (errors(app), ctx.item_exists("//Controls/Export frame"))
        for text in ("-5", "1-2", "99999999999999999999", ""):
            clear(app)
            ctx.item_input_value("**/seed", text)
            ctx.yield_(2)
            seen[text] = (errors(app), s.seed)
        ctx.item_input_value("**/seed", "7")
        ctx.yield_(2)
        seen["good"] = (errors(app), s.seed, s.pending_rebuild)

    run_gui(body, seed=2**40)
    assert seen["big"] == ([], True)
    for text in ("-5", "1-2", "99999999999999999999", ""):
        errs, seed = seen[text]
        assert len(errs) == 1 and one_line(errs[0]) and "seed" in errs[0], (text, errs)
        assert seed == 2**40, text
    assert seen["good"] == ([], 7, True)


# ------------------------------------------------------------------ presets
def test_preset_save_and_load_refuse_bad_paths_and_files(tmp_path):
    """Save params: empty path, NUL, a folder, a link (live or broken), a missing folder are one
    line each and write nothing; an existing regular file is replaced (documented: the atomic
    writer replaces a writable regular file).  Load params: missing, a folder, malformed,
    unknown keys, wrong types, out of range, NaN, Infinity, a huge file, a seed beyond 2**63-1,
    each one line naming the file, the session unchanged; a valid one with a 64-bit seed loads
    and the panel stays drawn."""
    target = tmp_path / "target.json"
    target.write_text("keep me")
    (tmp_path / "link.json").symlink_to(target)
    (tmp_path / "broken.json").symlink_to(tmp_path / "nowhere.json")
    existing = tmp_path / "existing.json"
    existing.write_text("{}")
    (tmp_path / "dir").mkdir()
    huge = tmp_path / "huge.json"
    with open(huge, "wb") as f:
        f.truncate(40 * 2**20)
    loads = {"missing": tmp_path / "missing.json", "folder": tmp_path / "dir",
             "malformed": '{"params": {"osmosis.evaporation_top": 0.07,, }',
             "unknown": {"params": {"osmosis.nope": 1}}, "extra key": {"params": {}, "extra": 1},
             "wrong type": {"osmosis.evaporation_top": "abc"}, "out of range": {"osmosis.evaporation_top": -3},
             "NaN": '{"osmosis.evaporation_top": NaN}', "Infinity": '{"params": {"dynamics.dt": Infinity}}',
             "huge": huge, "seed too big": {"params": {}, "seed": 10**30}, "seed negative": {"params": {}, "seed": -1},
             "species": {"params": {}, "species": "nosuch"}, "not an object": [1, 2]}
    paths = {}
    for k, v in loads.items():
        if isinstance(v, os.PathLike):
            paths[k] = str(v)
            continue
        p = tmp_path / f"load_{len(paths)}.json"
        p.write_text(v if isinstance(v, str) else json.dumps(v))
        paths[k] = str(p)
    saves = {"empty": "", "NUL": str(tmp_path / "a\0b.json"), "folder": str(tmp_path / "dir"),
             "link": str(tmp_path / "link.json"), "broken link": str(tmp_path / "broken.json"),
             "missing folder": str(tmp_path / "no" / "p.json")}
    good = tmp_path / "good.json"
    good.write_text(json.dumps({"params": {"osmosis.evaporation_top": 0.5}, "seed": 2**40, "species": "oak"}))
    seen = {}

    def body(ctx, app):
        s = app.session
        before = (s.params, s.seed, s.species_key)
        for k, v in list(saves.items()) + [(("load", k), v) for k, v in paths.items()]:
            clear(app)
            if k in ("NUL",):
                app.preset_path = v
            else:
                ctx.item_input_value("**/preset JSON", v)
            ctx.item_click("**/Load params" if isinstance(k, tuple) else "**/Save params")
            ctx.yield_(2)
            seen[k] = errors(app)
        seen["unchanged"] = (s.params, s.seed, s.species_key) == before
        clear(app)
        ctx.item_input_value("**/preset JSON", str(existing))
        ctx.item_click("**/Save params")
        ctx.yield_(2)
        seen["existing"] = errors(app)
        seen["existing status"] = [m.text for m in app.status.messages() if m.topic == "preset"]
        clear(app)
        ctx.item_input_value("**/preset JSON", str(tmp_path / "fresh.json"))
        ctx.item_click("**/Save params")
        ctx.yield_(2)
        seen["fresh status"] = [m.text for m in app.status.messages() if m.topic == "preset"]
        ctx.item_input_value("**/preset JSON", str(good))
        ctx.item_click("**/Load params")
        ctx.yield_(3)
        seen["good"] = (errors(app), s.seed, s.params["osmosis.evaporation_top"], ctx.item_exists("//Controls/Export frame"))
        still_usable(ctx, app, seen, "usable")

    run_gui(body)
    for k in list(saves) + [("load", k) for k in paths]:
        errs = seen[k]
        assert len(errs) == 1 and one_line(errs[0]), f"{k}: {errs}"
    for k in ("empty", "NUL"):
        assert "preset JSON" in seen[k][0], seen[k]
    assert "symbolic link" in seen["link"][0] and "broken symbolic link" in seen["broken link"][0]
    assert "seed" in seen[("load", "seed too big")][0] and "2**63-1" in seen[("load", "seed too big")][0]
    assert "MiB" in seen[("load", "huge")][0]
    for k in ("NaN", "Infinity"):
        assert "finite" in seen[("load", k)][0]
    assert seen["unchanged"]
    assert target.read_text() == "keep me" and (tmp_path / "broken.json").is_symlink()
    assert not (tmp_path / "nowhere.json").exists() and not (tmp_path / "no").exists()
    assert seen["existing"] == [] and json.loads(existing.read_text())["species"] == "oak"
    # replacing a preset is said, not silent (docs/gui.md)
    assert len(seen["existing status"]) == 1 and seen["existing status"][0].startswith("replaced the parameters in")
    assert len(seen["fresh status"]) == 1 and seen["fresh status"][0].startswith("saved parameters to")
    errs, seed, evap, drawn = seen["good"]
    assert errs == [] and seed == 2**40 and evap == pytest.approx(0.5) and drawn
    assert seen["usable"] == (True, True)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporaries left


def test_typed_slider_values_stay_in_range_and_finite():
    """Ctrl+click on a slider lets the user type any text: "nan", "inf", "-1e9", "abc" never
    reach the parameters as a non-finite or out-of-range value; the speed and photo opacity
    sliders likewise."""
    name = "osmosis.evaporation_top"
    p = PARAMS[name]
    seen = {}

    def body(ctx, app):
        from leafsim.gui.widgets import widget_ref

        s = app.session
        ctx.item_open("**/###group Osmosis")
        for text in ("nan", "inf", "-inf", "-1e9", "1e999", "abc"):
            clear(app)
            ctx.item_input_value(widget_ref(name), text)
            ctx.yield_(2)
            seen[text] = (s.params[name], s.simulator.params[name], errors(app))
        ctx.item_input_value(widget_ref(name), "nan")  # refused; then a good value clears the error
        ctx.yield_(2)
        seen["refused"] = errors(app)
        ctx.item_input_value(widget_ref(name), str(0.5 * (p.lo + p.hi)))
        ctx.yield_(2)
        seen["accepted"] = errors(app)
        ctx.item_close("**/###group Osmosis")
        ctx.item_click("**/as fast as possible")
        for text in ("nan", "inf"):
            ctx.item_input_value("**/###speed", text)
            ctx.item_input_value("**/###photo alpha", text)
            ctx.yield_(2)
            seen[("speed", text)] = (app.speed, app.photo_alpha, s.playback.worker.speed, errors(app))

    run_gui(body)
    for text in ("nan", "inf", "-inf", "-1e9", "1e999", "abc"):
        v, sim_v, errs = seen[text]
        assert np.isfinite(v) and p.lo <= v <= p.hi and v == sim_v, (text, v)
        assert errs == [] or (len(errs) == 1 and one_line(errs[0]) and name in errs[0]), (text, errs)
    assert len(seen["refused"]) == 1 and name in seen["refused"][0], seen  # "nan" is refused here ...
    assert seen["accepted"] == [], seen  # ... and the refusal went with the next accepted value (it stayed)
    for text in ("nan", "inf"):
        speed, alpha, worker_speed, errs = seen[("speed", text)]
        assert np.isfinite(speed) and 0.001 <= speed <= 2.0 and 0.0 <= alpha <= 1.0, (text, speed, alpha)
        assert np.isfinite(worker_speed) and errs == [], (text, worker_speed, errs)


# ------------------------------------------------------------------ the simulation worker
def test_a_failing_simulation_is_one_line_and_the_window_keeps_running(tmp_path, monkeypatch):
    """The watchdog stopping a runaway, the worker failing to apply parameters (which used to
    end its thread silently: "playing", nothing moving, no message), a multi-line exception
    text: each one line in the status bar; "Export mesh" of a diverged leaf is refused (it
    wrote a glTF full of NaN); Reset brings the leaf back and it plays again."""
    seen = {}

    def body(ctx, app):
        s = app.session
        pb = s.playback
        ctx.item_click("**/Step")
        wait_until(ctx, lambda: s.frame >= 1, 600)
        # a runaway the watchdog stops: 5 m/s of jitter in a paused leaf, then steps
        w = pb.worker
        with w._step_lock:
            w.run.state.particle_qd[:] = np.random.default_rng(0).normal(0, 5.0, w.run.state.particle_qd.shape)
        ctx.item_click(PLAY)
        wait_until(ctx, lambda: app.status.get("sim") is not None, 900)
        seen["watchdog"] = errors(app)
        seen["playing_after_error"] = pb.playing and pb.sim_error is None
        ctx.item_click("**/Reset")
        wait_until(ctx, lambda: pb.sim_error is None and app.status.get("sim") is None, 600)
        # the worker cannot apply new parameters
        w = pb.worker

        def boom(params):
            raise RuntimeError("factorisation failed\nsecond line of the reason")

        monkeypatch.setattr(w.simulator, "set_params", boom)
        if not pb.playing:
            ctx.item_click(PLAY)
        with w._step_lock:  # handed over while the worker holds no step: it applies them itself
            w._params = s.sim_params
        wait_until(ctx, lambda: app.status.get("sim") is not None, 900)
        seen["set_params"] = errors(app)
        seen["thread_alive"] = w.running
        monkeypatch.undo()
        ctx.item_click("**/Reset")
        wait_until(ctx, lambda: pb.sim_error is None and app.status.get("sim") is None, 600)
        # a diverged leaf: the mesh export is refused
        with w._step_lock:
            w.run.state.particle_q[3] = np.nan
        if not pb.playing:
            ctx.item_click(PLAY)
        wait_until(ctx, lambda: app.status.get("sim") is not None, 900)
        clear(app)
        app.export_dir = str(tmp_path / "out")
        ctx.item_click("**/Export mesh")
        ctx.yield_(2)
        seen["mesh"] = app.status.get("mesh")
        ctx.item_click("**/Reset")
        wait_until(ctx, lambda: pb.sim_error is None and app.status.get("sim") is None, 600)
        if not pb.playing:
            ctx.item_click(PLAY)
        g0 = s.frame
        wait_until(ctx, lambda: s.frame >= g0 + 3, 900)
        seen["plays_again"] = s.frame >= g0 + 3 and pb.sim_error is None

    run_gui(body)
    errs = seen["watchdog"]
    assert len(errs) == 1 and one_line(errs[0]) and "unstable" in errs[0], errs
    assert not seen["playing_after_error"]
    errs = seen["set_params"]
    assert len(errs) == 1 and one_line(errs[0]) and "factorisation failed" in errs[0], errs
    assert seen["thread_alive"]
    msg = seen["mesh"]
    assert msg is not None and msg.level == "error" and one_line(msg.text) and "diverged" in msg.text, msg
    assert not (tmp_path / "out").exists() or not list((tmp_path / "out").glob("*.glb"))
    assert seen["plays_again"]


def test_a_multi_line_build_error_is_one_line(monkeypatch):
    """A build failing with a multi-line reason (numba's errors are) is shown on one line."""
    import leafsim.pipeline as leaf

    seen = {}

    def body(ctx, app):
        s = app.session

        def broken(*a, **k):
            raise LeafsimError("first line\n  second line\n\nthird")

        monkeypatch.setattr(leaf, "leaf_shape", broken)
        ctx.item_click("**/Rebuild")
        wait_until(ctx, lambda: errors(app), 600)
        monkeypatch.undo()
        seen["errs"] = errors(app)
        seen["ready"] = s.ready

    run_gui(body)
    assert seen["errs"] and one_line(seen["errs"][0]) and "third" in seen["errs"][0], seen["errs"]
    assert seen["ready"]
