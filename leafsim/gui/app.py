"""The interactive application: hello_imgui/immapp runner + moderngl leaf view + imgui panels.

* moderngl is attached to the runner's OpenGL context in ``callbacks.post_init``;
* the leaf is drawn by :class:`leafsim.render.Renderer` in ``callbacks.custom_background``
  (into the part of the window between the two panels, straight into the window's
  framebuffer at render scale 1);
* the panels (generated from :data:`leafsim.config.params.PARAMS`) and the fixed status bar are
  drawn in ``callbacks.show_gui`` by the panel objects of :mod:`leafsim.gui.panels`, each
  holding this app.

All state lives in a :class:`leafsim.interactive.session.Session`: builds run in a background
thread, the simulation in the session's worker thread (:mod:`leafsim.interactive.worker`); every frame the window
takes the worker's latest consistent snapshot and draws it, so the window never waits for a
step or a build.  Errors (unreadable photo, broken preset, unwritable export folder, a build
that fails, a diverged simulation) appear in the status bar at the bottom, which has a fixed
height, so no widget ever moves; the app keeps running.
"""

from __future__ import annotations

import math
import os
import sys
import time
from pathlib import Path

import cv2
import moderngl
import numpy as np
from imgui_bundle import hello_imgui, imgui, immapp

from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import not_an_input, write_png_atomic
from leafsim.base.resources import default_config
from leafsim.export.mesh import export_mesh
from leafsim.gui.exports import BackgroundJobs, ensure_folder, free_path, new_take, user_path
from leafsim.gui.fonts import load_ui_font
from leafsim.gui.layout import (BACKGROUND, DRY_UI_HZ, LEFT_W, MIN_WINDOW, OWN_RANGE, PANEL_BG, RIGHT_W, STATUS_H,
                                 fixed_flags, window_rects)
from leafsim.gui.panels.controls import ControlsPanel
from leafsim.gui.panels.stats import StatsPanel
from leafsim.gui.panels.status_bar import StatusBar
from leafsim.gui.panels.view import ViewOverlay
from leafsim.gui.photo import texcoord_affine
from leafsim.gui.status import Status
from leafsim.interactive.session import Session
from leafsim.render.camera import OrbitCamera
from leafsim.render.options import RenderOptions
from leafsim.render.renderer import Renderer

#: above this many triangles the view is drawn into a texture kept while nothing changes (a
#: large mesh costs more to draw than the texture costs to show; a small one is drawn straight
#: into the window every frame)
CACHE_TRIANGLES = 20000


def without_test_time_limit(runner_params) -> None:
    """Scripts and tests that drive the window with the ImGui test engine wait for progress
    (a frame reached, a build done), not for a clock: switch off the engine's watchdog, which
    otherwise kills a test after 60 s, a limit a first run's numba compile or a busy machine
    passes.  Call before ``immapp.testing.run``."""
    earlier = runner_params.callbacks.register_tests

    def register():
        if callable(earlier):
            earlier()
        io = imgui.test_engine.get_io(hello_imgui.get_imgui_test_engine())
        io.config_watchdog_warning = io.config_watchdog_kill_test = sys.float_info.max

    runner_params.callbacks.register_tests = register


def _configure_threads() -> None:
    """llvmpipe's render threads compete with the simulation worker on small machines: leave it
    a core (:mod:`leafsim.gui.threads`), and make numba's OpenMP workers sleep instead of
    spinning between parallel regions (measured: spinning workers starve llvmpipe).  Values
    already set in the environment win."""
    from leafsim.gui.threads import render_threads

    os.environ.setdefault("LP_NUM_THREADS", render_threads())
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")



def leaf_file_stem(session) -> str:
    """``leafsim_<species>_seed<seed>_f<frame>``: an exported frame's or mesh's name, after the
    leaf on screen (the built one: a species or seed waiting for Rebuild is not it yet)."""
    key = session.built_species or session.species_key
    seed = session.built_seed if session.built_seed is not None else session.seed
    return f"leafsim_{key}_seed{seed}_f{session.frame:06d}"


class _Shown(LeafsimError):
    """A refusal the status bar already shows under its own topic (``guard`` posts no second)."""

class LeafApp:
    """One window: a session, its renderer, camera and the UI state.

    Parameters
    ----------
    session : Session (may still be building).
    frames : simulate to this frame as fast as possible, draw it, then exit (scripted runs:
        the simulation is bit-identical on any machine, the picture nearly so).
    window_frames : exit after this many window frames drawn with the leaf (playing; timing).
    play : start playing.
    window_size : (w, h) pixels.
    """

    def __init__(self, session, frames: int | None = None, play: bool = False, window_size=(1280, 800),
                 title: str = "leafsim", window_frames: int | None = None, until_dry: bool = False):
        self.session = session
        self.frames = frames
        self.window_frames = window_frames
        self.until_dry = bool(until_dry)
        self._dry_posted: str | None = None  # the "Dry to end" stall last put in the status bar
        # no smaller than the panels and a usable view between them (at 640 x 400 the stats panel
        # covered the controls and the leaf; at 800 x 600 the view was 90 px wide)
        self.window_size = tuple(max(int(v), lo) for v, lo in zip(window_size, MIN_WINDOW))
        self.title = title
        self.view = "shaded"
        # relative to the folder the app was started in: short enough to read in the field
        self.export_dir = "frames"
        self.preset_path = "leafsim_params.json"
        self.record_every = 1
        self.take: Path | None = None     # folder of the take being recorded
        self.recorded = 0
        self.recorded_frames: list[int] = []  # the simulation frame of each file of the take
        self._last_recorded_frame = -1
        self._hold_n = 1  # the worker waits at every this many frames while a take is recorded
        self.status = Status()
        self.exit_code = 0
        self.fatal: str | None = None  # why a scripted run (--frames) failed, for stderr
        self.camera = OrbitCamera()
        self.ctx = self.renderer = None
        self.rendered_gen = -1
        self.rendered_tex = None
        self.framed_species = None
        self.followed = None  # the leaf's centre the camera last followed (free scene)
        self.photo_tex = self.photo_tex_masked = None
        self.photo_gen = -1
        self.photo_affine = None
        self.export_fbo = None
        self.requests: list[tuple[str, object]] = []
        self.jobs = BackgroundJobs()  # mesh exports, each on its own thread
        self.mesh_paths: set = set()  # the files they are writing (a second press picks another name)
        self.gui_frames = self.leaf_frames = 0
        self.t_start = time.perf_counter()
        self.t_first_frame: float | None = None
        self.t_first_leaf: float | None = None
        self.frame_ms: list[float] = []
        self._paced_before = False
        self._t_last = None
        self.leaf_rect_px = (LEFT_W, 0, max(self.window_size[0] - LEFT_W - RIGHT_W, 64), self.window_size[1] - STATUS_H)
        self.dirty = True
        self.exported: list[str] = []
        self.timing: dict[str, float] = {}
        self.msaa = int(os.environ.get("LEAFSIM_MSAA", "0"))
        # full quality by default (1x, ground and soft shadow): affordable on llvmpipe since the
        # ground shadow became one mask fetch (see Renderer._ground_shadow_pass)
        self.render_scale = float(os.environ.get("LEAFSIM_RENDER_SCALE", "1.0"))
        self.software_gl = False
        self.show_ground = self.shadows = True
        #: the leaf shading itself (a shadow-map pass + 4 taps per blade pixel, ~12 ms per frame
        #: under llvmpipe at 1x): on with hardware GL, a checkbox away on a software rasteriser
        self.self_shadow = True
        self.albedo = "detail"
        self.heat_fit = True         # heat maps over the field's own range (else 0..1 / full)
        self.photo_compare = "off"   # "off", "overlay", "blink" (photo over the 3-D view)
        self.photo_alpha = 0.5
        self.speed_fast = True       # simulation as fast as possible (else self.speed)
        self.speed = 0.05            # simulated seconds per wall second
        self.view_fbo = self.view_tex = self.view_depth = None
        self.view_direct = False
        self._view_key = None
        self.uploads = 0
        self.controls, self.stats = ControlsPanel(self), StatsPanel(self)
        self.status_bar, self.overlay = StatusBar(self), ViewOverlay(self)
        session.playback.start_worker()
        session.playback.set_speed(None)
        if until_dry:
            session.playback.dry_to_end(True)
        elif frames is not None:
            session.playback.play_until(frames)
        elif play or window_frames is not None:
            session.playback.play(True)

    @property
    def playing(self) -> bool:
        return self.session.playback.playing

    # ------------------------------------------------------------------ runner wiring
    def runner_params(self):
        rp = hello_imgui.RunnerParams()
        rp.app_window_params.window_title = self.title
        rp.app_window_params.window_geometry.size = self.window_size
        rp.imgui_window_params.default_imgui_window_type = hello_imgui.DefaultImGuiWindowType.no_default_window
        rp.fps_idling.enable_idling = False
        rp.ini_disable = True
        # llvmpipe: 8x MSAA on the window (hello_imgui's default) costs ~5x per frame;
        # the leaf is anti-aliased by its own renderer settings instead
        rp.renderer_backend_options.open_gl_options.anti_aliasing_samples = self.msaa
        rp.callbacks.load_additional_fonts = load_ui_font
        rp.callbacks.post_init = self.post_init
        rp.callbacks.before_exit = self.before_exit
        rp.callbacks.custom_background = self.custom_background
        rp.callbacks.show_gui = self.show_gui
        return rp

    @staticmethod
    def addons():
        return immapp.AddOnsParams(with_implot=True)

    def post_init(self) -> None:
        _limit_window_size()
        self.ctx = moderngl.create_context()
        self.renderer = Renderer(self.ctx)
        gl = str(self.ctx.info.get("GL_RENDERER", "")).lower()
        self.software_gl = any(k in gl for k in ("llvmpipe", "softpipe", "swrast"))
        if self.software_gl and "LEAFSIM_SELF_SHADOW" not in os.environ:
            self.self_shadow = False
        # slider values are drawn centred under the grab: a see-through, narrow grab keeps them legible
        style = imgui.get_style()
        style.grab_min_size = 6.0
        for col, alpha in ((imgui.Col_.slider_grab, 0.45), (imgui.Col_.slider_grab_active, 0.6)):
            r, g, b, _ = style.color_(col)
            style.set_color_(col, imgui.ImVec4(r, g, b, alpha))

    def before_exit(self) -> None:
        self.jobs.join()  # a mesh still being written is finished, not cut short
        self.session.close()
        for o in (self.photo_tex, self.photo_tex_masked, self.export_fbo, self.view_fbo, self.view_tex, self.view_depth):
            if o is not None:
                try:
                    o.release()
                except Exception:
                    pass
        if self.renderer is not None:
            try:
                self.renderer.release()
            except Exception:
                pass
        self.renderer = None

    # ------------------------------------------------------------------ errors
    def fail(self, msg: str, topic: str = "app") -> None:
        self.status.error(topic, msg)

    @property
    def error(self) -> str | None:
        """The newest error shown in the status bar (None when there is none)."""
        return self.status.error_text

    def guard(self, fn, *args, topic: str = "app"):
        try:
            return fn(*args)
        except _Shown:  # already in the status bar under its own topic
            pass
        except LeafsimError as e:
            self.fail(str(e), topic)
        except Exception as e:  # the GUI must survive anything
            if os.environ.get("LEAFSIM_DEBUG"):
                raise
            self.fail(f"internal error: {type(e).__name__}: {e}", topic)
        return None

    # ------------------------------------------------------------------ per frame (GL)
    def render_options(self):
        p = self.session.params
        opts = RenderOptions.of_params(p, view=self.view, background=BACKGROUND, shadow_size=1024, ground=self.show_ground,
                                       shadows=self.shadows or self.self_shadow, self_shadow=self.self_shadow)
        opts.ground_shadow = self.shadows  # "shadows": the soft shadow on the ground
        if not self.heat_fit and self.view not in OWN_RANGE:
            opts.scalar_range = (0.0, 1.0)
        if self.session.use_texture():
            opts.albedo = {"detail": "detail", "photo": "texture", "colours": "colours"}[self.albedo]
        return opts

    def custom_background(self) -> None:
        self._pace()
        now = time.perf_counter()
        if self._t_last is not None:
            self.frame_ms.append((now - self._t_last) * 1e3)
            del self.frame_ms[:-600]
        if self.paced != self._paced_before:  # the frame rate of one pace only (after "Dry to end": the window's own)
            self.frame_ms.clear()
            self._paced_before = self.paced
        self._t_last = now
        if self.t_first_frame is None:
            self.t_first_frame = now
        self.gui_frames += 1
        self.guard(self._frame)

    @property
    def paced(self) -> bool:
        """The window draws at most ``DRY_UI_HZ`` frames per second ("Dry to end" runs; a take
        draws every frame)."""
        return self.session.playback.drying and self.take is None

    def _pace(self) -> None:
        """While "Dry to end" runs, draw at most ``DRY_UI_HZ`` frames per second: with a CPU
        rasteriser (llvmpipe) every frame drawn is CPU time the drying does not get."""
        if self._t_last is not None and self.paced:
            wait = 1.0 / DRY_UI_HZ - (time.perf_counter() - self._t_last)
            if wait > 0.0:
                time.sleep(wait)

    # ------------------------------------------------------------------ panels (imgui)
    def show_gui(self) -> None:
        self.guard(self._gui)

    def panel_rects(self):
        _, _, left, right, bar = window_rects()
        return left, right, bar

    def _window(self, name: str, rect, draw) -> None:
        x, y, w, h = rect
        imgui.set_next_window_pos((x, y), imgui.Cond_.always)
        imgui.set_next_window_size((w, h), imgui.Cond_.always)
        extra = imgui.WindowFlags_.no_title_bar | imgui.WindowFlags_.no_scrollbar if name == "Status" else 0
        if imgui.begin(name, None, fixed_flags() | extra):
            self.guard(draw)
        imgui.end()

    def _gui(self) -> None:
        W, H, left, right, bar = window_rects()
        self._window("Controls", left, self.controls.draw)
        self._window("Stats", right, self.stats.draw)
        self._window("Status", bar, self.status_bar.draw)
        self.leaf_rect_px = (LEFT_W, 0, max(W - LEFT_W - RIGHT_W, 64), max(H - STATUS_H, 64))
        self.overlay.draw()
        self.overlay.mouse(imgui.get_io())

    # ------------------------------------------------------------------ session news
    def _take_session(self) -> None:
        """Swap in a finished build and the worker's latest snapshot; route their news (and
        the finished background exports') to the status bar."""
        for tag, result, error in self.jobs.finished():
            if error is not None:
                self.fail(error, tag)
            else:
                path, tri = result
                self.status.info(tag, f"exported mesh {path} ({tri} triangles)", path=path)
        s = self.session
        if s.poll():
            self.dirty = True
            self.status.clear("build")
        if s.build_error:
            self.fail(s.build_error, "build")
            if self.scripted:  # a script gets the reason on stderr (run_app prints it), not a window
                self.fatal = s.build_error
                self.exit_code = 2
                self._exit()
            s.build_error = None
        if self.take is not None and max(self.record_every, 1) != self._hold_n:  # "every" changed mid-take
            self._hold_n = max(self.record_every, 1)
            s.playback.hold_every(self._hold_n)
        if s.playback.take_snapshot():
            self.dirty = True
            if self.take is not None and s.frame >= self._last_recorded_frame + max(self.record_every, 1):
                self.requests.append(("record", None))
        pb = s.playback
        if pb.dry_stalled and pb.dry_stalled != self._dry_posted:  # once per stall: dismissable
            stalled = self._dry_posted = pb.dry_stalled
            self.status.error("dry", stalled, holds=lambda: pb.dry_stalled == stalled)
            if self.until_dry:  # the dry leaf asked for will never come
                self.fatal = stalled
                self.exit_code = 2
                self._exit()
        if pb.sim_error and self.status.get("sim") is None:
            self.status.error("sim", pb.sim_error, holds=lambda: pb.sim_error is not None)
            if self.frames is not None or self.until_dry:  # the frame asked for will never come
                self.fatal = pb.sim_error
                self.exit_code = 2
                self._exit()
            if self.take is not None:
                self.stop_recording()

    def _frame(self) -> None:
        """One frame: take the session's news, upload the snapshot if it is new, draw."""
        s = self.session
        t0 = time.perf_counter()
        self._take_session()
        fb = self.ctx.detect_framebuffer()
        if s.ready:
            self._sync_renderer()
            while self.requests:
                kind, arg = self.requests.pop(0)
                self.guard(self._export, kind, arg, topic="export")
        t1 = time.perf_counter()
        self._draw_screen(fb)
        t2 = time.perf_counter()
        self.timing = {"upload": (t1 - t0) * 1e3, "draw": (t2 - t1) * 1e3}
        if s.ready:
            self.leaf_frames += 1
            if self.t_first_leaf is None:
                self.t_first_leaf = time.perf_counter()
            pb = s.playback
            if ((self.frames is not None and not self.until_dry and s.frame >= self.frames)
                    or (self.until_dry and pb.dry_done and not pb.drying and s.frame == pb.worker.run.state.frame)
                    or (self.window_frames is not None and self.leaf_frames >= self.window_frames)):
                self._exit()

    @property
    def scripted(self) -> bool:
        """Run by a script (``--frames`` / ``--until dry`` / ``--window-frames``): exits by itself."""
        return self.frames is not None or self.window_frames is not None or self.until_dry

    def _exit(self) -> None:
        hello_imgui.get_runner_params().app_shall_exit = True

    def _sync_renderer(self) -> None:
        s = self.session
        tex = s.use_texture()
        s.photo_tint = self.albedo == "photo"
        if self.rendered_gen != s.generation or self.rendered_tex != tex:
            self.renderer.populate(s.render_mesh())
            if self.framed_species != s.species_key:  # keep the user's view across rebuilds
                self.frame_leaf()
            self.rendered_gen, self.rendered_tex = s.generation, tex
            self.framed_species = s.species_key
            self.dirty = False
            self.uploads += 1
        elif self.dirty:
            self.renderer.update(**s.render_update())
            self.dirty = False
            self.uploads += 1
            self.follow_leaf()
        if self.photo_gen != s.generation:
            self._make_photo_texture()

    def frame_leaf(self) -> None:
        """Aim the camera at the leaf (apex up on screen, seen from above at 55°)."""
        r = self.renderer
        if r is None or r.mesh is None:
            return
        self.camera.yaw, self.camera.pitch = -90.0, 55.0
        pts = np.stack([r.lo, r.hi])
        _, _, w, h = self.leaf_rect_px
        # the leaf's bounding sphere fits the vertical field of view, and the horizontal one in a
        # view narrower than tall (1024 × 768 leaves 264 px between the panels: maple's lobes
        # were cut off on both sides)
        half_v = math.radians(self.camera.fov) / 2.0
        half_h = math.atan(min(float(w) / max(float(h), 1.0), 1.0) * math.tan(half_v))
        self.camera.frame_bounds(pts, margin=1.05 * math.sin(half_v) / math.sin(half_h))
        self.followed = r.center.copy()

    def follow_leaf(self) -> None:
        """The free scene's leaf falls for ever (at about 1.6 m/s, dynamics.air_damping) and the
        hanging scene's swings down below its stalk within a fraction of a second: there the
        camera moves with the leaf's centre, keeping the user's angle and zoom."""
        r = self.renderer
        if r is None or r.mesh is None:
            return
        if self.session.params["dynamics.scene"] in ("free", "hanging") and self.followed is not None:
            self.camera.target = np.asarray(self.camera.target, dtype=np.float64) + (r.center - self.followed)
        self.followed = r.center.copy()

    def _make_photo_texture(self) -> None:
        """The photo as two textures: whole (side panel) and leaf-masked (overlay); and the
        affine that maps model xy to its texture coordinates."""
        s = self.session
        for t in (self.photo_tex, self.photo_tex_masked):
            if t is not None:
                t.release()
        self.photo_tex = self.photo_tex_masked = self.photo_affine = None
        self.photo_gen = s.generation
        if s.photo_rgba is None or s.model is None:
            return
        img = s.photo_rgba
        h, w = img.shape[:2]
        f = min(1.0, 512.0 / max(h, w))
        if f < 1.0:
            img = cv2.resize(img, (max(1, int(w * f)), max(1, int(h * f))), interpolation=cv2.INTER_AREA)
        # the side panel: the photo's leaf on the window's grey (its background pixels hold the
        # cleaned fill colour under alpha 0: shown opaque, hornbeam sat on a mustard rectangle
        # that hid its outline, oak on a black one)
        a = img[:, :, 3:4].astype(np.float32) / 255.0
        grey = np.array([255.0 * c for c in BACKGROUND[:3]], np.float32)
        whole = np.empty_like(img)
        whole[:, :, :3] = np.clip(img[:, :, :3].astype(np.float32) * a + grey * (1.0 - a) + 0.5, 0, 255).astype(np.uint8)
        whole[:, :, 3] = 255
        for name, rgba in (("photo_tex", whole), ("photo_tex_masked", img)):
            t = self.ctx.texture((rgba.shape[1], rgba.shape[0]), 4, np.ascontiguousarray(rgba).tobytes())
            t.repeat_x = t.repeat_y = False
            setattr(self, name, t)
        T = s.model.blade_T  # the petiole's texture coordinates sit on the midrib, off this map
        self.photo_affine = texcoord_affine(s.model.particle_rest[T][:, :2], s.model.particle_texcoord[T])
        self.photo_z = float(s.model.particle_rest[T][:, 2].mean())

    def view_proj(self) -> np.ndarray:
        _, _, w, h = self.leaf_rect_px
        return self.camera.proj(max(w, 1) / max(h, 1)) @ self.camera.view()

    def _clear_panels(self, fb, W: int, H: int, sy: float, sx: float) -> None:
        """Fill the panels' and status bar's rectangles with their background colour by a
        scissored clear (the panels are drawn without an imgui background: a blended fill
        of a third of the window was ~5 ms per frame under llvmpipe)."""
        for x, y, w, h in self.panel_rects():
            fb.clear(*PANEL_BG, 1.0, depth=1.0,
                     viewport=(int(x * sx), int(H - (y + h) * sy), max(int(w * sx), 1), max(int(h * sy), 1)))

    def _draw_screen(self, fb) -> None:
        """Clear the window and draw the leaf: at render scale 1 straight into the window's
        framebuffer, else into a smaller texture that imgui draws scaled (llvmpipe's cost is per
        pixel)."""
        io = imgui.get_io()
        sx, sy = io.display_framebuffer_scale.x, io.display_framebuffer_scale.y
        W, H = int(io.display_size.x * sx), int(io.display_size.y * sy)
        fb.use()
        fb.viewport = (0, 0, W, H)
        self._clear_panels(fb, W, H, sy, sx)  # the panels, the bar and the view tile the window
        x0, y0, w, h = self.leaf_rect_px
        direct = self.renderer is not None and self.renderer.mesh is not None and self.render_scale >= 1.0 \
            and len(self.renderer.tri) <= CACHE_TRIANGLES
        if not self.session.ready or not direct:
            fb.clear(*BACKGROUND, 1.0, depth=1.0, viewport=(int(x0 * sx), H - int((y0 + h) * sy), int(w * sx), int(h * sy)))
        if not self.session.ready or self.renderer is None or self.renderer.mesh is None:
            return
        opts = self.render_options()
        cam = self.camera
        if direct:
            self.view_direct = True
            vw, vh = max(int(w * sx), 16), max(int(h * sy), 16)
            self.renderer.render(cam, vw, vh, opts, framebuffer=fb, viewport=(int(x0 * sx), H - int(y0 * sy) - vh, vw, vh))
        else:
            self.view_direct = False
            self._draw_scaled(cam, opts, max(int(w * sx * self.render_scale), 16), max(int(h * sy * self.render_scale), 16))
        fb.use()
        fb.viewport = (0, 0, W, H)

    def _draw_scaled(self, cam, opts, w: int, h: int) -> None:
        if self.view_fbo is None or self.view_fbo.size != (w, h):
            for o in (self.view_fbo, self.view_tex, self.view_depth):
                if o is not None:
                    o.release()
            self.view_tex = self.ctx.texture((w, h), 4)
            self.view_tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
            self.view_depth = self.ctx.depth_renderbuffer((w, h))
            self.view_fbo = self.ctx.framebuffer(self.view_tex, self.view_depth)
            self._view_key = None
        key = (w, h, cam.yaw, cam.pitch, cam.distance, tuple(cam.target), repr(opts), self.uploads)
        if key != self._view_key:  # nothing changed (paused, camera still): keep the last image
            self.renderer.render(cam, w, h, opts, framebuffer=self.view_fbo)
            self._view_key = key

    # ------------------------------------------------------------------ export
    def leaf_image(self) -> np.ndarray:
        """The leaf view alone, rendered offscreen at the view's size: (H, W, 3) uint8 RGB."""
        x, y, w, h = self.leaf_rect_px
        w, h = max(int(w), 16), max(int(h), 16)
        if self.export_fbo is None or self.export_fbo.size != (w, h):
            if self.export_fbo is not None:
                self.export_fbo.release()
            self.export_fbo = self.ctx.simple_framebuffer((w, h))
        self.renderer.render(self.camera, w, h, self.render_options(), framebuffer=self.export_fbo)
        data = self.export_fbo.read(components=3, alignment=1)
        return np.ascontiguousarray(np.frombuffer(data, np.uint8).reshape(h, w, 3)[::-1])

    def _export_folder(self) -> Path:
        """The export folder, created when missing (the status bar says so).  A folder it
        refuses is an error of the topic "folder", cleared once a folder is usable (it stayed
        after the folder was corrected)."""
        try:
            folder, created = ensure_folder(self.export_dir)
        except LeafsimError as e:
            self.fail(str(e), "folder")
            raise _Shown(str(e)) from None
        self.status.clear("folder", "error")
        if created:
            self.status.info("folder", f"created export folder {folder}", path=folder)
        return folder

    def _write_png(self, path: Path) -> None:
        write_png_atomic(path, self.leaf_image(), rgb=True)
        self.exported.append(str(path))

    def _export(self, kind: str, arg) -> None:
        s = self.session
        if kind == "frame":
            folder = self._export_folder()
            path = free_path(folder, leaf_file_stem(s))
            self._write_png(path)
            self.status.info("export", f"exported frame {s.frame} to {path}", path=path)
            return
        if self.take is None:  # a record request that arrived after Stop
            return
        try:
            self._write_png(self.take / f"frame_{self.recorded:05d}.png")
        except LeafsimError:
            self.stop_recording(failed=True)
            raise
        self.recorded += 1
        self.recorded_frames.append(s.frame)
        self._last_recorded_frame = s.frame
        s.playback.release_hold()  # the worker waited at this frame: on to the next
        take = self.take
        self.status.info("record", f"recording {take.name}: {self.recorded} frames to {take}", path=take,
                         holds=lambda: self.take is take)

    def request_export(self) -> None:
        self.requests.append(("frame", None))

    def start_recording(self) -> None:
        """A new numbered take folder; frames are written while the leaf changes."""
        try:
            self.take = new_take(self._export_folder())
        except _Shown:
            return
        except LeafsimError as e:
            self.fail(str(e), "record")
            return
        self.status.clear("record")
        self.recorded = 0
        self.recorded_frames = []
        self._last_recorded_frame = -1
        self._hold_n = max(self.record_every, 1)
        self.session.playback.hold_every(self._hold_n)  # playing waits at every n-th frame for it
        self.requests.append(("record", None))

    def stop_recording(self, failed: bool = False) -> None:
        take, self.take = self.take, None
        self.session.playback.hold_every(None)
        if take is not None and not failed:
            self.status.info("record", f"recorded {self.recorded} frames in {take}", path=take)

    # ------------------------------------------------------------------ actions
    def export_mesh(self) -> Path:
        """The current snapshot as ``leafsim_<species>_seed<seed>_f<frame>.glb`` in the export folder
        (:func:`leaf_file_stem`)."""
        s = self.session
        if s.state is not None and not np.isfinite(s.state.particle_q).all():
            raise LeafsimError(f"Export mesh: the simulation diverged (positions NaN/Inf at frame {s.frame}); "
                               "expected a finite leaf: press Reset")
        path = free_path(self._export_folder(), leaf_file_stem(s), ".glb", self.mesh_paths)  # (as Export frame's PNG)
        # the blade's colour baked as the window draws it (sub-grid mottle, the photo's detail):
        # about a second of work, on a thread of its own with its own view of the leaf (the
        # window's view keeps drawing), from a copy of the state on screen
        from leafsim.appearance.view import LeafView

        v = s.view
        view = LeafView(s.model, v.photo_rgba, v.pigments0, photo_tint=v.photo_tint, photo_colour=v.photo_colour,
                        blade_only=v.blade_only)
        model, state, params = s.model, s.state.copy(), s.sim_params
        albedo = {"detail": "detail", "photo": "texture", "colours": "colours"}[self.albedo]
        self.mesh_paths.add(path)

        def work():
            try:
                rep = export_mesh(model, state, path, params=params, view=view, veins=True, texture="baked", albedo=albedo)
            finally:
                self.mesh_paths.discard(path)
            return path, sum(m["triangles"] for m in rep["meshes"].values())

        self.jobs.start("mesh", work)
        self.status.info("mesh", f"exporting mesh {path} (baking its colour) …", path=path,
                         holds=lambda: bool(self.jobs.pending("mesh")))
        return path

    def save_preset(self) -> None:
        """Save params: a regular file is replaced (atomically), anything else refused; never
        the species' config or photo it was built from."""
        path = user_path(self.preset_path, "preset JSON", "JSON file")
        sp = self.session.species
        not_an_input(path, (sp.config or default_config(), sp.image), "preset JSON")
        existed = Path(path).is_file()
        p = self.session.save_params(path)
        self.status.info("preset", f"{'replaced the parameters in' if existed else 'saved parameters to'} {p}", path=p)

    def load_preset(self) -> None:
        path = user_path(self.preset_path, "preset JSON", "JSON file")
        self.session.load_params(path, rebuild=True)
        self.dirty = True
        self.status.clear("params", "error")  # every value is a valid one now
        self.status.info("preset", f"loaded {path}", path=path)

    def set_params(self, changes: dict) -> None:
        """Stage or apply the panel's changes; a refused value is an error of the topic
        "params" until a change is accepted (it stayed after the value was corrected)."""
        try:
            self.session.set_params(self.session.params.with_overrides(changes))
        except LeafsimError as e:
            self.fail(str(e), "params")
            raise _Shown(str(e)) from None
        self.status.clear("params", "error")
        self.dirty = True

    def switch_species(self, key: str) -> None:
        res = self.session.set_species(key)
        kept, reset = res["kept"], res["reset"]
        if not (kept or reset):  # only while the new leaf builds (it stayed 30 s after)
            s = self.session
            self.status.info("species", f"switching to {key}", holds=lambda: s.building and s.species_key == key)
            return
        text = f"switched to {key}"
        if kept:
            text += f"; kept your {len(kept)} change(s): {', '.join(kept)}"
        if reset:
            text += f"; reset to {key}'s values: {', '.join(reset)}"
        self.status.info("species", text, seconds=30.0)

    def species_defaults(self) -> None:
        names = self.session.species_defaults()
        self.dirty = True
        self.status.clear("params", "error")  # every value is a valid one now
        what = ", ".join(names) if names else "nothing was changed"
        self.status.info("species", f"{self.session.species.name} defaults restored ({what})", seconds=30.0)


def _limit_window_size() -> None:
    """Ask the window manager to keep the window at least :data:`MIN_WINDOW` (a hint: a desktop's
    window manager applies it to resizing, a bare X server ignores it)."""
    try:
        import glfw
        from imgui_bundle import glfw_utils

        glfw.set_window_size_limits(glfw_utils.glfw_window_hello_imgui(), *MIN_WINDOW, glfw.DONT_CARE, glfw.DONT_CARE)
    except Exception:  # noqa: BLE001 - a hint; no window manager, no GLFW window (tests), nothing lost
        pass


def _check_display() -> None:
    """One line instead of the window runner's C++ assert and abort (exit 134) when the display
    cannot be opened (DISPLAY names no running X server, a refused connection)."""
    import glfw

    before = glfw.ERROR_REPORTING
    glfw.ERROR_REPORTING = "ignore"  # its error callback would print a second, raw message
    try:
        ok = glfw.init()
        if ok:
            glfw.terminate()  # the window runner initialises GLFW itself
    finally:
        glfw.ERROR_REPORTING = before
    if not ok:
        shown = os.environ.get("WAYLAND_DISPLAY") or os.environ.get("DISPLAY")
        raise LeafsimError(f"gui: cannot open display {shown!r} (no X server there, or it refused the connection); "
                           "run it on a desktop or under xvfb-run -a -s '-screen 0 1280x800x24' leafsim gui ...")


def run_app(species=None, config=None, seed: int = 0, overrides=None, frames=None, screenshot=None,
            play: bool = False, window_frames=None, until_dry: bool = False) -> int:
    """Run the GUI; returns the exit code.

    ``frames``: simulate to that frame, draw it, then exit; ``until_dry``: the same at the "Dry to
    end" threshold (2 % of the water); ``window_frames``: exit after that
    many window frames with the leaf (playing); ``screenshot``: write the final window (PNG,
    atomically) when exiting.
    """
    _configure_threads()
    for name, v in (("--frames", frames), ("--window-frames", window_frames)):
        if v is not None and v < 0:
            raise LeafsimError(f"{name} {v}: expected a non-negative number of frames")
    if screenshot is not None:
        folder = Path(screenshot).parent if str(Path(screenshot).parent) else Path(".")
        if not folder.is_dir():
            raise LeafsimError(f"--screenshot {screenshot}: folder {folder} does not exist")
    session = Session(species, config, seed, overrides, build=False)
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise LeafsimError("gui: no display (DISPLAY is not set); run it on a desktop or under "
                           "xvfb-run -a -s '-screen 0 1280x800x24' leafsim gui ...")
    _check_display()
    session.rebuild_async()
    app = LeafApp(session, frames=frames, play=play, window_frames=window_frames, until_dry=until_dry)
    immapp.run(app.runner_params(), app.addons())
    if app.fatal is not None:
        raise LeafsimError(app.fatal)  # one line on stderr, exit 2
    if screenshot is not None:
        img = hello_imgui.final_app_window_screenshot()
        if img is None or getattr(img, "size", 0) == 0:
            raise LeafsimError("--screenshot: the window produced no frame")
        write_png_atomic(screenshot, np.ascontiguousarray(np.asarray(img)[:, :, :3]), rgb=True)
    return app.exit_code
