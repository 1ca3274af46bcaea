"""GUI tests with the Dear ImGui test engine (``imgui_bundle.immapp.testing``) under Xvfb.

Each test launches the real application (hello_imgui runner, moderngl renderer, panels
generated from the parameter declaration) on the small oak leaf and drives it by widget
labels; the ``xdisplay`` fixture (conftest) provides an X server.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

# hard dependencies (pyproject.toml): a broken install must fail here, not skip the GUI tests
import imgui_bundle  # noqa: F401
import moderngl  # noqa: F401
import numpy as np
import pytest

from helpers.gui import wait_until
from helpers.paths import HANG_S
from helpers.paths import REPO as ROOT
from leafsim.base.errors import LeafsimError
from leafsim.config.params import GROUPS, PARAMS

pytestmark = pytest.mark.usefixtures("xdisplay")


def run_gui(test_fn, species="oak", overrides=None, play=False, window_size=(1280, 800)):
    """Run the app with ``test_fn(ctx, app)`` driving it; returns the app afterwards."""
    from imgui_bundle.immapp import testing

    from leafsim.gui.app import LeafApp, _configure_threads, without_test_time_limit
    from leafsim.interactive.session import Session

    _configure_threads()
    session = Session(species, overrides=overrides)
    app = LeafApp(session, play=play, window_size=window_size)
    # under llvmpipe the app starts with a cheap view (half size, no ground): fast test frames
    rp = app.runner_params()
    without_test_time_limit(rp)  # the tests wait for progress; a busy machine may take minutes
    testing.run(test_function=lambda ctx: test_fn(ctx, app), runner_params=rp, add_ons_params=app.addons())
    return app


PLAY = "**/###play"
DISMISS = "**/###dismiss"


def ref(name):
    from leafsim.gui.widgets import widget_ref

    return widget_ref(name)


def test_live_slider_changes_params_and_keeps_state():
    seen = {}

    def body(ctx, app):
        s = app.session
        ctx.item_click("**/Step")
        ctx.item_click("**/Step")
        wait_until(ctx, lambda: s.frame == 2, 300)  # steps run in the worker
        ctx.yield_(3)
        frame, gen = s.frame, s.generation
        water = s.state.particle_water.copy()
        ctx.item_open("**/###group Osmosis")
        ctx.item_input_value(ref("osmosis.evaporation_top"), 2.5)
        ctx.yield_(2)
        seen.update(frame=frame, frame_after=s.frame, gen=gen, gen_after=s.generation,
                    value=s.params["osmosis.evaporation_top"], sim_value=s.simulator.params["osmosis.evaporation_top"],
                    pending=s.pending_rebuild, same_water=bool(np.array_equal(water, s.state.particle_water)))

    run_gui(body)
    assert seen["frame"] == 2 and seen["frame_after"] == 2
    assert seen["gen"] == seen["gen_after"]
    assert seen["value"] == pytest.approx(2.5, rel=1e-5)
    assert seen["sim_value"] == pytest.approx(2.5, rel=1e-5)
    assert seen["pending"] is False and seen["same_water"]


def test_rebuild_slider_and_button():
    seen = {}

    def body(ctx, app):
        s = app.session
        seen["n0"], seen["gen0"] = s.model.particle_count, s.generation
        ctx.item_open("**/###group Mesh")
        ctx.item_input_value(ref("mesh.spacing"), 0.05)
        ctx.yield_(2)
        seen["pending"] = s.pending_rebuild
        seen["n_staged"] = s.model.particle_count
        ctx.item_click("**/Rebuild")
        seen["building"] = s.building
        frames0 = app.gui_frames
        wait_until(ctx, lambda: not s.building and s.generation > seen["gen0"])
        seen["frames_during_build"] = app.gui_frames - frames0
        ctx.yield_(2)
        seen["n1"], seen["gen1"], seen["pending_after"] = s.model.particle_count, s.generation, s.pending_rebuild
        seen["rendered_gen"] = app.rendered_gen

    run_gui(body)
    assert seen["pending"] is True and seen["n_staged"] == seen["n0"]
    assert seen["building"] is True
    assert seen["frames_during_build"] >= 2  # the window kept drawing while building
    assert seen["gen1"] == seen["gen0"] + 1 and seen["n1"] < seen["n0"]
    assert seen["pending_after"] is False and seen["rendered_gen"] == seen["gen1"]


def test_play_advances_and_dries():
    seen = {}

    def body(ctx, app):
        s = app.session
        w0 = s.total_water()
        ctx.item_click(PLAY)
        wait_until(ctx, lambda: s.frame >= 15, 600)
        ctx.item_click(PLAY)  # Pause
        ctx.yield_(2)
        seen.update(frame=s.frame, w0=w0, w1=s.total_water(), playing=app.playing)
        # orbit camera: left-drag over the leaf view (not over a panel) rotates, wheel zooms
        cam = app.camera
        yaw, dist = cam.yaw, cam.distance
        ctx.mouse_move_to_pos((640, 420))
        ctx.mouse_down(0)
        ctx.mouse_move_to_pos((700, 440))
        ctx.mouse_up(0)
        ctx.mouse_wheel_y(2.0)
        ctx.yield_(2)
        seen.update(yaw_changed=cam.yaw != yaw, zoomed=cam.distance < dist)
        # the same drag over the Controls panel leaves the camera alone
        yaw = cam.yaw
        ctx.mouse_move_to_pos((150, 700))
        ctx.mouse_down(0)
        ctx.mouse_move_to_pos((250, 720))
        ctx.mouse_up(0)
        ctx.yield_(2)
        seen["panel_drag_kept"] = cam.yaw == yaw

    run_gui(body)
    assert seen["frame"] >= 15 and seen["playing"] is False
    assert seen["w1"] < seen["w0"]
    assert seen["yaw_changed"] and seen["zoomed"] and seen["panel_drag_kept"]


def test_exports_create_the_folder_and_never_overwrite(tmp_path):
    """The first Export frame creates the missing folder (and says so); each recorded take is
    a new numbered folder; the same frame exported twice gives two files; the status bar shows
    the full path and no stale text after Stop."""
    import cv2

    out = tmp_path / "new" / "frames"
    seen = {}

    def body(ctx, app):
        s = app.session
        ctx.item_input_value("**/export folder", str(out))
        ctx.yield_(1)
        ctx.item_click("**/Export frame")
        wait_until(ctx, lambda: app.exported, 60)
        seen["folder_msg"] = [m.text for m in app.status.messages() if m.topic == "folder"]
        seen["export_msg"] = app.status.get("export")
        ctx.item_click("**/Export frame")  # same frame again: a second file, not an overwrite
        wait_until(ctx, lambda: len(app.exported) >= 2, 60)
        for take in range(2):
            ctx.item_click("**/###record")  # Record take
            ctx.item_click(PLAY)
            wait_until(ctx, lambda: app.recorded >= 3, 600)
            ctx.item_click("**/###record")  # Stop recording
            ctx.item_click(PLAY)
            ctx.yield_(2)
            seen[f"after_stop_{take}"] = app.status.get("record").text
            seen[f"recorded_{take}"] = app.recorded
        ctx.yield_(2)
        seen["frames_after"] = s.frame

    app = run_gui(body)
    assert app.error is None
    assert seen["folder_msg"] and str(out) in seen["folder_msg"][0] and "created" in seen["folder_msg"][0]
    assert seen["export_msg"].path and str(out) in seen["export_msg"].path
    singles = sorted(out.glob("leafsim_oak_*.png"))
    assert len(singles) == 2 and singles[0].stem + "_2" == singles[1].stem
    takes = sorted(p.name for p in out.iterdir() if p.is_dir())
    assert takes == ["take_001", "take_002"]
    for k, t in enumerate(takes):
        files = sorted((out / t).iterdir())
        assert len(files) == seen[f"recorded_{k}"] >= 3
        assert files[0].name == "frame_00000.png"
        assert seen[f"after_stop_{k}"].startswith("recorded ") and str(out / t) in seen[f"after_stop_{k}"]
    assert not [f for f in out.rglob(".*")]  # no temp files left
    img = cv2.imread(str(singles[0]))[:, :, ::-1].astype(int)
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    leaf = (g > r + 15) & (g > b + 25)
    assert leaf.mean() > 0.03, f"only {leaf.mean():.3%} leaf-green pixels"


@pytest.mark.parametrize("dry", [False, True])
def test_a_take_holds_every_nth_simulation_frame(tmp_path, dry):
    """A take "every 2" while the leaf plays (or dries to the end) writes simulation frames
    f0, f0 + 2, f0 + 4, ...: the worker waits at each until it is written (it recorded whichever
    snapshot was published: every 1 gave frames 0, 3, 8, 12, 31, ...)."""
    seen = {}

    def body(ctx, app):
        s = app.session
        ctx.item_input_value("**/export folder", str(tmp_path))
        app.record_every = 2
        ctx.item_click("**/###record")  # Record take
        ctx.item_click("**/###dry" if dry else PLAY)
        wait_until(ctx, lambda: app.recorded >= 8, 600)
        ctx.item_click("**/###record")  # Stop recording
        seen["frames"] = list(app.recorded_frames)
        f = s.frame
        wait_until(ctx, lambda: s.playback.take_snapshot() or s.frame > f + 20, 600)  # it plays on, unheld
        seen["after"] = s.frame - f

    app = run_gui(body, overrides={"mesh.spacing": 0.05})
    assert app.error is None
    fr = seen["frames"]
    assert len(fr) >= 8 and all(b - a == 2 for a, b in zip(fr, fr[1:])), fr
    assert len(sorted((tmp_path / "take_001").iterdir())) == len(fr)
    assert seen["after"] > 0


def test_export_mesh_button_writes_a_glb(tmp_path):
    """"Export mesh" writes the leaf on screen as a binary glTF into the export folder (created
    when missing) on a thread of its own, a second click a second file (even while the first is
    being written); trimesh loads it with the blade's counts, its
    blade coloured by the baked texture (the window's albedo, sub-grid mottle and photo detail
    included), and so are the veins over oak's photo (the window draws the photo under them)."""
    import json
    import struct

    import trimesh

    out = tmp_path / "meshes"
    seen = {}

    def body(ctx, app):
        ctx.item_input_value("**/export folder", str(out))
        ctx.yield_(1)
        # two presses in a row: each bakes on its own thread while the window keeps drawing,
        # and the second picks another name while the first file is still being written
        ctx.item_click("**/Export mesh")
        seen["first"] = app.status.get("mesh").text
        ctx.yield_(1)
        ctx.item_click("**/Export mesh")
        app.jobs.join()
        ctx.yield_(2)
        seen["msg"] = app.status.get("mesh")
        seen["nT"] = int((app.session.model.particle_layer == 0).sum())

    app = run_gui(body)
    assert app.error is None
    files = sorted(out.glob("leafsim_oak_seed*_f*.glb"))
    assert len(files) == 2 and files[0].stem + "_2" == files[1].stem
    assert seen["first"].startswith(("exporting mesh", "exported mesh"))
    assert seen["msg"].path and str(out) in str(seen["msg"].path) and seen["msg"].text.startswith("exported mesh")
    scene = trimesh.load(files[0])
    blade = max(scene.geometry.values(), key=lambda g: len(g.faces))
    # the stalk is a mesh of its own (its colour per vertex: its texture coordinates lie on the
    # blade's midrib), cut from the blade's shell: the two together are closed
    leaf = trimesh.util.concatenate([blade, scene.geometry["stalk"]])
    leaf.merge_vertices(merge_tex=True, merge_norm=True)
    assert leaf.is_watertight and not blade.is_watertight and len(leaf.vertices) >= 2 * seen["nT"]
    data = files[0].read_bytes()
    doc = json.loads(data[20:20 + struct.unpack("<I", data[12:16])[0]])
    assert [im["name"] for im in doc["images"]] == ["baked"]
    prims = {m["name"]: m["primitives"][0]["attributes"] for m in doc["meshes"]}
    assert "COLOR_0" not in prims["blade"] and "COLOR_0" not in prims["veins"] and "COLOR_0" in prims["stalk"]
    mats = [doc["materials"][m["primitives"][0]["material"]] for m in doc["meshes"] if m["name"] != "stalk"]
    assert all(m["pbrMetallicRoughness"].get("baseColorTexture") == {"index": 0} for m in mats)


def test_layout_does_not_move_when_messages_appear(tmp_path):
    """Widget rectangles are the same with and without an error, a build in progress, an info
    message and a recording (everything transient lives in the fixed status bar)."""
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    refs = [f"//Controls/{r}" for r in ("###play", "Step", "seed", "Rebuild", "export folder", "Export frame",
                                        "preset JSON", "Load params", "###render scale", "###group Effects",
                                        "###effects.osmosis", "Reset", "###dry", "every")]
    seen = {}

    def rects(ctx):
        out = {}
        for r in refs:
            info = ctx.item_info(r)
            out[r] = (round(info.rect_full.min.x), round(info.rect_full.min.y), round(info.rect_full.max.x),
                      round(info.rect_full.max.y))
        return out

    def body(ctx, app):
        s = app.session
        ctx.yield_(3)
        seen["before"] = rects(ctx)
        ctx.item_input_value("**/export folder", str(blocker))
        ctx.item_click("**/Export frame")
        ctx.yield_(3)
        seen["error"] = app.error
        seen["with_error"] = rects(ctx)
        ctx.item_open("**/###group Mesh")
        ctx.item_input_value(ref("mesh.spacing"), 0.05)
        ctx.item_close("**/###group Mesh")
        ctx.item_click("**/Rebuild")
        ctx.yield_(2)
        seen["building"] = s.building
        seen["while_building"] = rects(ctx)
        wait_until(ctx, lambda: not s.building, 600)
        ctx.item_input_value("**/export folder", str(tmp_path / "f"))
        ctx.item_click("**/###record")
        ctx.item_click(PLAY)
        ctx.yield_(3)
        seen["while_recording"] = rects(ctx)  # playing too: "Pause", "Stop recording"
        seen["error_while_recording"] = app.error  # the folder works now: its refusal went
        ctx.item_click(PLAY)
        ctx.item_click("**/###record")
        ctx.yield_(2)
        seen["after"] = rects(ctx)
        seen["error_after"] = app.error

    run_gui(body)
    assert seen["error"] and "not a folder" in seen["error"] and seen["building"]
    for k in ("with_error", "while_building", "while_recording", "after"):
        moved = {r: (seen["before"][r], seen[k][r]) for r in refs if seen["before"][r] != seen[k][r]}
        assert not moved, f"{k}: {moved}"
    assert seen["error_while_recording"] is None and seen["error_after"] is None


def test_every_declared_parameter_has_a_widget():
    from leafsim.gui import widgets

    seen = {}

    def body(ctx, app):
        for g in GROUPS:
            ctx.item_open(f"**/###group {g}")
        ctx.yield_(2)
        widgets.reset_drawn()
        ctx.yield_(1)
        seen["drawn"] = set(widgets.DRAWN)

    run_gui(body)
    missing = set(PARAMS) - seen["drawn"]
    assert not missing, f"parameters without a widget: {sorted(missing)}"
    assert seen["drawn"] == set(PARAMS)


def test_param_widget_kinds():
    """param_widget returns valid values for each kind (no window needed for the logic)."""
    from leafsim.gui.widgets import widget_label

    assert widget_label(PARAMS["osmosis.evaporation_top"]) == "evaporation_top [kg/(m²·s)]###osmosis.evaporation_top"
    assert widget_label(PARAMS["effects.pbd"]) == "pbd###effects.pbd"


def test_errors_are_shown_and_app_keeps_running(tmp_path, monkeypatch):
    bad = tmp_path / "broken.json"
    bad.write_text('{"params": {"osmosis.evaporation_top": 0.07,, }')
    unknown = tmp_path / "unknown.json"
    unknown.write_text(json.dumps({"params": {"osmosis.nope": 1}}))
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    seen = {}

    def body(ctx, app):
        s = app.session
        params0 = s.params
        ctx.item_input_value("**/preset JSON", str(bad))
        ctx.item_click("**/Load params")
        ctx.yield_(2)
        seen["err_json"] = app.error
        seen["params_same"] = s.params is params0
        ctx.item_click(DISMISS)
        ctx.item_input_value("**/preset JSON", str(unknown))
        ctx.item_click("**/Load params")
        ctx.yield_(2)
        seen["err_unknown"] = app.error
        ctx.item_click(DISMISS)
        ctx.item_input_value("**/export folder", str(blocker / "sub"))
        ctx.item_click("**/Export frame")
        ctx.yield_(3)
        seen["err_export"] = app.error
        ctx.item_click(DISMISS)
        ctx.item_input_value("**/export folder", str(blocker))
        ctx.item_click("**/###record")
        ctx.yield_(2)
        seen["err_record"] = app.error
        seen["recording"] = app.take is not None
        ctx.item_click(DISMISS)
        # an unreadable photo during a rebuild: error shown, the old leaf stays
        import leafsim.pipeline as leaf

        def unreadable(*a, **k):
            raise LeafsimError("images/quercus_01.png: cannot read image (corrupt data)")

        monkeypatch.setattr(leaf, "leaf_shape", unreadable)
        gen = s.generation
        ctx.item_click("**/Rebuild")
        wait_until(ctx, lambda: app.error is not None, 300)
        monkeypatch.undo()
        seen["err_photo"] = app.error
        seen["gen_kept"] = s.generation == gen and s.ready
        f0 = app.gui_frames
        ctx.item_click(PLAY)
        wait_until(ctx, lambda: s.frame >= 3, 300)
        seen["frames"] = app.gui_frames - f0
        seen["sim_frame"] = s.frame

    run_gui(body)
    assert "broken.json" in seen["err_json"] and "malformed JSON" in seen["err_json"]
    assert seen["params_same"]
    assert "unknown parameter 'osmosis.nope'" in seen["err_unknown"]
    assert seen["err_export"] and "a_file" in seen["err_export"]
    assert seen["err_record"] and "not a folder" in seen["err_record"] and seen["recording"] is False
    assert "cannot read image" in seen["err_photo"] and seen["gen_kept"]
    assert seen["frames"] > 0 and seen["sim_frame"] >= 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file", "broken.json", "unknown.json"]


def test_cli_gui_screenshot(tmp_path, xdisplay):
    out = tmp_path / "shot.png"
    env = {**os.environ, "DISPLAY": xdisplay}
    r = subprocess.run([sys.executable, "-m", "leafsim", "gui", "--species", "oak", "--frames", "30",
                        "--screenshot", str(out)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 0, r.stderr[-2000:]
    import cv2

    img = cv2.imread(str(out))
    assert img is not None and img.shape[0] >= 400 and img.shape[1] >= 600
    assert [p.name for p in tmp_path.iterdir()] == ["shot.png"]


@pytest.mark.parametrize("frames", [0, 12])
def test_gui_frames_counts_simulation_frames(frames):
    """``gui --frames N`` simulates to frame N exactly, draws it and exits by itself, however
    fast the machine draws windows (it used to count window frames: 300 gave simulation frame
    0, 83 or 471)."""
    from imgui_bundle import immapp

    from leafsim.gui.app import LeafApp, _configure_threads
    from leafsim.interactive.session import Session

    _configure_threads()
    session = Session("oak", overrides={"mesh.spacing": 0.06}, build=False)
    session.rebuild_async()
    app = LeafApp(session, frames=frames)
    immapp.run(app.runner_params(), app.addons())
    assert app.exit_code == 0 and session.frame == frames and app.leaf_frames >= 1


def test_the_camera_follows_a_leaf_falling_in_the_free_scene():
    """The free scene's leaf falls at its real speed (selective mass scaling): the camera keeps
    it in view, moving with its centre."""
    from imgui_bundle import immapp

    from leafsim.gui.app import LeafApp, _configure_threads
    from leafsim.interactive.session import Session

    _configure_threads()
    session = Session("oak", overrides={"mesh.spacing": 0.06, "dynamics.scene": "free"}, build=False)
    session.rebuild_async()
    app = LeafApp(session, frames=100)
    immapp.run(app.runner_params(), app.addons())
    assert app.exit_code == 0 and session.frame == 100
    centre = app.followed  # the leaf's centre as last drawn
    assert centre[2] < -0.05  # 0.2 s of falling: over 5 cm, not the 2 mm of the scaled inertia
    assert np.allclose(app.camera.target, centre, atol=1e-9)


def _until_dry(evaporation: float):
    """``gui --until dry`` on a coarse oak evaporating at ``evaporation`` kg/(m²·s) from both
    faces: (the app after it exited, its session)."""
    from imgui_bundle import immapp

    from leafsim.gui.app import LeafApp, _configure_threads
    from leafsim.interactive.session import Session

    _configure_threads()
    session = Session("oak", overrides={"mesh.spacing": 0.06, "osmosis.evaporation_top": evaporation,
                                        "osmosis.evaporation_bottom": evaporation}, build=False)
    session.rebuild_async()
    app = LeafApp(session, until_dry=True)
    immapp.run(app.runner_params(), app.addons())
    return app, session


def test_gui_until_dry_ends_at_the_dry_frame():
    """``gui --until dry`` runs "Dry to end", draws the dry leaf and exits by itself."""
    from leafsim.sim.run import DRY_END_FRACTION

    app, session = _until_dry(50.0)
    assert app.exit_code == 0 and session.frame > 0
    assert session.water_fraction() <= DRY_END_FRACTION + 1e-9
    assert session.frame == session.playback.worker.run.state.frame  # the drawn frame is the last one


def test_gui_until_dry_of_a_leaf_that_cannot_dry_exits_with_the_reason(monkeypatch):
    """No evaporation: "Dry to end" gives up once the water has not fallen for STALL_FRAMES
    frames (it ran for ever, silent); the window shows why, and ``--until dry`` exits 2 with it."""
    from leafsim.interactive import worker as wmod

    monkeypatch.setattr(wmod, "STALL_FRAMES", 30)
    app, session = _until_dry(0.0)
    assert app.exit_code == 2 and "has not fallen in 30 frames" in app.fatal
    assert app.status.get("dry").level == "error" and session.water_fraction() > 0.99


def test_cli_gui_build_error_is_one_line_on_stderr(tmp_path, xdisplay):
    """A scripted window whose leaf cannot be built exits 2 with the reason on stderr (it used to
    exit 2 silently, the window showing 'building the first leaf ...')."""
    env = {**os.environ, "DISPLAY": xdisplay}
    r = subprocess.run([sys.executable, "-m", "leafsim", "gui", "--species", "oak", "--set", "limits.max_particles=1000",
                        "--frames", "5", "--screenshot", str(tmp_path / "x.png")], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.startswith("leafsim: ") and "limits.max_particles" in r.stderr and r.stderr.count("\n") == 1
    assert not (tmp_path / "x.png").exists()


def test_a_reduced_render_scale_draws_the_leaf_in_its_own_colours(tmp_path, xdisplay):
    """The half-size view (drawn as a texture over the window) shows the leaf as the full-size one
    does: its veins had left the texture's alpha below 1 (blended like the colour), and the
    window's grey showed through them, pale and dashed (the leaf's pixels 6 levels bluer on
    average; now within 1)."""
    import cv2

    shots = {}
    for scale in ("1.0", "0.5"):
        out = tmp_path / f"s{scale}.png"
        env = {**os.environ, "DISPLAY": xdisplay, "LEAFSIM_RENDER_SCALE": scale}
        r = subprocess.run([sys.executable, "-m", "leafsim", "gui", "--species", "maple", "--frames", "20",
                            "--screenshot", str(out)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=HANG_S)
        assert r.returncode == 0, r.stderr[-2000:]
        img = cv2.imread(str(out)).astype(int)[:, 390:940]  # the view between the panels
        leaf = (img[..., 1] - img[..., 2]) > 20
        assert leaf.mean() > 0.05
        shots[scale] = img[leaf].mean(axis=0)
    assert np.abs(shots["0.5"] - shots["1.0"]).max() < 2.5, shots  # 6.0 levels of blue before


def test_cli_gui_unreachable_display_is_one_line(tmp_path):
    """A DISPLAY with no X server behind it: one line and exit 2 (the window runner used to
    abort with a C++ assert, exit 134, before any window)."""
    free = next(n for n in range(250, 400) if not Path(f"/tmp/.X11-unix/X{n}").exists() and not Path(f"/tmp/.X{n}-lock").exists())
    env = {**os.environ, "DISPLAY": f":{free}"}
    env.pop("WAYLAND_DISPLAY", None)
    r = subprocess.run([sys.executable, "-m", "leafsim", "gui", "--species", "oak", "--frames", "1",
                        "--screenshot", str(tmp_path / "x.png")], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 2, r.stderr[-2000:]
    assert r.stderr.startswith("leafsim: gui: cannot open display") and r.stderr.count("\n") == 1
    assert not (tmp_path / "x.png").exists()


def test_cli_gui_screenshot_bad_folder(tmp_path, xdisplay):
    env = {**os.environ, "DISPLAY": xdisplay}
    r = subprocess.run([sys.executable, "-m", "leafsim", "gui", "--species", "oak", "--frames", "2",
                        "--screenshot", str(tmp_path / "no" / "x.png")], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 2 and "does not exist" in r.stderr and "Traceback" not in r.stderr


def test_loaded_font_has_every_glyph():
    """The font the window actually draws with is the bundled one and has a glyph for every
    character of the declared labels, units and help texts."""
    from leafsim.gui.fonts import ui_strings

    chars = sorted({c for s in ui_strings() for c in s if ord(c) >= 0x20})
    seen = {}

    def body(ctx, app):
        from imgui_bundle import imgui

        font = imgui.get_font()
        seen["name"] = font.get_debug_name()
        seen["missing"] = [c for c in chars if not font.is_glyph_in_font(ord(c))]
        seen["cjk"] = font.is_glyph_in_font(0x4E00)

    run_gui(body)
    assert "DejaVuSans" in seen["name"]
    assert seen["missing"] == [] and seen["cjk"] is False


def test_species_switch_keeps_changes_and_names_the_reset_ones():
    seen = {}

    def body(ctx, app):
        s = app.session
        ctx.item_open("**/###group Osmosis")
        ctx.item_input_value(ref("osmosis.evaporation_top"), 0.9)
        ctx.item_close("**/###group Osmosis")
        ctx.item_close("**/###group Effects")  # bring the Colour group into view
        ctx.item_open("**/###group Colour")
        ctx.scroll_to_bottom("//Controls")
        ctx.yield_(2)
        ctx.item_input_value(ref("colour.browning"), 7.5)   # oak sets its own browning
        ctx.scroll_to_top("//Controls")
        ctx.yield_(2)
        app.switch_species("maple")  # what picking maple in the species combo calls
        ctx.yield_(1)
        # while maple builds, the overlay names the leaf on screen: still oak
        seen["building"] = s.building
        seen["shown"] = s.shown_species.key
        seen["key"] = s.species_key
        seen["msg"] = app.status.get("species").text
        wait_until(ctx, lambda: not s.building, 900)
        ctx.yield_(2)
        seen["shown_after"] = s.shown_species.key
        seen["evaporation_top"] = s.params["osmosis.evaporation_top"]
        seen["browning"] = s.params["colour.browning"]
        seen["maple_browning"] = s.species.params["colour.browning"]
        ctx.item_click("//Controls/species defaults")
        ctx.yield_(2)
        seen["defaults"] = s.params["osmosis.evaporation_top"]
        seen["defaults_msg"] = app.status.get("species").text

    run_gui(body)
    assert seen["building"] and seen["shown"] == "oak" and seen["key"] == "maple"
    assert "osmosis.evaporation_top" in seen["msg"] and "kept" in seen["msg"]
    assert "colour.browning" in seen["msg"] and "reset" in seen["msg"]
    assert seen["shown_after"] == "maple"
    assert seen["evaporation_top"] == pytest.approx(0.9, rel=1e-5)
    assert seen["browning"] == seen["maple_browning"] != pytest.approx(7.5)
    assert seen["defaults"] == PARAMS["osmosis.evaporation_top"].default and "osmosis.evaporation_top" in seen["defaults_msg"]


def test_random_sliders_rebuilds_and_species_switches_while_playing():
    """Stress: N random live-parameter changes (every live float/int/bool/choice slider, any
    value in its range), rebuilds and species switches in the middle of builds, all while
    playing: no exception, no NaN in what is drawn, the window keeps drawing."""
    import random

    from leafsim.interactive.session import species_keys

    rng = random.Random(1234)
    live = [p for p in PARAMS.values() if not p.rebuild and p.group not in ("Effects",)
            and p.name not in ("dynamics.dt", "dynamics.substeps", "dynamics.iterations", "osmosis.solver")]
    keys = [k for k in species_keys() if k in ("oak", "maple", "aspen", "hornbeam")]
    seen = {"errors": [], "nan": 0, "nan_unreported": 0, "actions": 0}

    def value(p):
        if p.kind == "bool":
            return rng.random() < 0.5
        if p.kind == "choice":
            return rng.choice(p.choices)
        lo, hi = float(p.lo), float(p.hi)
        if p.log and lo > 0:
            v = math.exp(rng.uniform(math.log(lo), math.log(hi)))
        else:
            v = rng.uniform(lo, hi)
        return int(round(v)) if p.kind == "int" else v

    def body(ctx, app):
        s = app.session
        ctx.item_click(PLAY)
        for k in range(60):
            r = rng.random()
            if r < 0.75:
                p = rng.choice(live)
                app.set_params({p.name: value(p)})  # what a slider does, any value in range
            elif r < 0.85:
                s.set_params({"mesh.spacing": rng.uniform(0.04, 0.08)})
                ctx.item_click("**/Rebuild")
            else:
                app.switch_species(rng.choice(keys))  # often while a build is running
            seen["actions"] += 1
            ctx.yield_(rng.randint(1, 4))
            if s.ready and s.state is not None and not np.isfinite(s.state.particle_q).all():
                seen["nan"] += 1  # extreme values may diverge, but never silently
                seen["nan_unreported"] += s.playback.sim_error is None
                ctx.item_click("**/Reset")
            errs = [m.text for m in app.status.messages() if m.level == "error"]
            seen["errors"] += [e for e in errs if "internal error" in e or "Traceback" in e]
        wait_until(ctx, lambda: not s.building, 900)
        f0, g0 = app.gui_frames, s.frame
        if not s.playback.playing:
            ctx.item_click(PLAY)
        wait_until(ctx, lambda: s.frame > g0 + 2, 600)
        seen["frames"] = app.gui_frames - f0
        seen["sim_advanced"] = s.frame > g0 or s.playback.sim_error is not None
        seen["finite"] = bool(np.isfinite(s.state.particle_q).all()) or s.playback.sim_error is not None
        seen["rendered"] = app.rendered_gen == s.generation

    run_gui(body, species="oak", overrides={"mesh.spacing": 0.06})
    assert seen["actions"] == 60
    assert seen["errors"] == [] and seen["nan_unreported"] == 0
    assert seen["frames"] > 0 and seen["sim_advanced"] and seen["finite"] and seen["rendered"]



def test_the_heat_maps_colour_bar_sits_on_a_card():
    """The heat map's colour bar, ticks and label are drawn on a light card: where a wide leaf
    reached under them (maple's right lobe, zoomed in) the numbers were unreadable."""
    from imgui_bundle import hello_imgui

    from leafsim.gui.panels.view import LEGEND_CARD

    seen = {}

    def body(ctx, app):
        s = app.session
        wait_until(ctx, lambda: s.ready and app.renderer is not None and app.renderer.mesh is not None, 600)
        app.view = "water"
        app.camera.zoom(8.0)  # the leaf fills the view and runs under the bar
        ctx.yield_(4)
        seen["rect"] = app.leaf_rect_px

    run_gui(body, species="maple")
    img = np.asarray(hello_imgui.final_app_window_screenshot())[:, :, :3].astype(float)
    x0, y0, w, h = (int(round(v)) for v in seen["rect"])
    x, y, height = x0 + w - 70, y0 + 44, h * 0.33
    card = img[int(y + 0.25 * height):int(y + 0.75 * height), x - 8:x - 2].reshape(-1, 3)  # left of the bar
    under = img[int(y + height + 40):int(y + height + 60), x - 8:x - 2].reshape(-1, 3)  # just below the card
    ground = img[y0 + h - 40, x0 + w - 12]  # the view's lower right corner: no leaf there
    assert (np.abs(under - ground).max(axis=1) > 30).mean() > 0.5  # the leaf reaches the card
    a, c = LEGEND_CARD[3], 255.0 * np.array(LEGEND_CARD[:3])
    # whatever lies under it, the card's pixels are within (1 − alpha) of its colour
    assert np.abs(card - c).max() <= (1 - a) * 255 + 2, card.mean(axis=0)


def test_the_quality_tooltip_is_wrapped_inside_the_window():
    """The quality levels' tooltip (four long lines: each level's error and CPU on three
    species) is wrapped: unwrapped it was 1274 px wide, the whole 1280 px window."""
    from imgui_bundle import imgui

    seen = {}

    def body(ctx, app):
        wait_until(ctx, lambda: app.session.ready, 600)
        ctx.mouse_move_to_pos((100, 89))  # the quality combo
        ctx.yield_(5)
        ctx.sleep(1.5)  # the hover delay
        ctx.yield_(3)
        w = imgui.internal.find_window_by_name("##Tooltip_00")
        seen.update(found=w is not None and w.was_active, width=w.size.x if w else 0,
                    font=imgui.get_font_size(), display=imgui.get_io().display_size.x)

    run_gui(body, species="maple")
    assert seen["found"], "no tooltip over the quality combo"
    assert seen["width"] <= 48 * seen["font"] and seen["width"] < 0.6 * seen["display"], seen


def test_the_photo_keeps_its_size_in_a_short_window():
    """The stats panel's photo is at least three quarters of the panel's width tall: in a
    1024 x 700 window the plots above it left it an 80 px stamp; the panel scrolls to it now.
    In the default window it takes the rest of the panel, as before."""
    from leafsim.gui.panels.stats import PHOTO_MAX, PHOTO_MIN

    seen = {}

    def body(ctx, app):
        wait_until(ctx, lambda: app.session.ready and app.stats.photo_size is not None)
        ctx.yield_(2)
        seen["size"] = app.stats.photo_size

    for window in ((1024, 700), (1280, 800)):
        run_gui(body, window_size=window)
        w, h = seen["size"]
        assert w > 200 and h >= min(PHOTO_MIN * w, PHOTO_MAX) - 0.5, (window, w, h)
