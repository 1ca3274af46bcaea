"""The interactive application: hello_imgui/immapp runner + moderngl leaf view + imgui panels.

* moderngl is attached to the runner's OpenGL context in ``callbacks.post_init``;
* the leaf is drawn by :class:`leafsim.render.Renderer` in ``callbacks.custom_background``
  (into the part of the window between the two panels);
* the panels (generated from :data:`leafsim.params.PARAMS`) are drawn in ``callbacks.show_gui``.

All state lives in a :class:`leafsim.session.Session`; builds run in a background thread and
are swapped in between frames, so the window never freezes.  Errors (unreadable photo, broken
preset, unwritable export folder, a build that fails) are shown as a red line in the
Controls panel and the app keeps running.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

from ..errors import LeafsimError

VIEWS = ("shaded", "wireframe", "particles", "springs", "mass", "water",
         "chlorophyll", "carotenoid", "anthocyanin", "browning")
LEFT_W, RIGHT_W = 380, 330
#: resolution factors of the 3-D view (llvmpipe's cost is per pixel)
SCALES = (0.35, 0.5, 0.75, 1.0)
#: albedo of photo species: pigment colour with the photo's detail, the photo tinted by the
#: pigment change, or the pigment colour alone
ALBEDOS = ("detail", "photo", "colours")
BACKGROUND = (0.80, 0.84, 0.88)


def moderngl_linear():
    import moderngl

    return moderngl.LINEAR


def _configure_threads() -> None:
    """llvmpipe's render threads compete with numba's on small machines: cap them, and make
    numba's OpenMP workers sleep instead of spinning between parallel regions (measured: spinning
    workers starve llvmpipe).  Values already set in the environment win."""
    os.environ.setdefault("LP_NUM_THREADS", "2" if (os.cpu_count() or 1) <= 2 else "4")
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


class LeafApp:
    """One window: a session, its renderer, camera and the UI state.

    Parameters
    ----------
    session : Session (may still be building).
    frames : run this many frames once the leaf is built, then exit (scripted runs).
    play : start playing.
    window_size : (w, h) pixels.
    """

    def __init__(self, session, frames: int | None = None, play: bool = False, window_size=(1280, 800),
                 title: str = "leafsim"):
        from ..render.camera import OrbitCamera

        self.session = session
        self.frames = frames
        self.playing = bool(play or frames is not None)
        self.window_size = tuple(int(v) for v in window_size)
        self.title = title
        self.steps_per_frame = 1
        self.view = "shaded"
        self.export_dir = str(Path.cwd() / "frames")
        self.preset_path = str(Path.cwd() / "leafsim_params.json")
        self.record_every = 1
        self.recording = False
        self.recorded = 0
        self.error: str | None = None
        self.info: str = ""
        self.exit_code = 0
        self.camera = OrbitCamera()
        self.ctx = None
        self.renderer = None
        self.rendered_gen = -1
        self.rendered_tex = None
        self.framed_species = None
        self.photo_tex = None
        self.photo_gen = -1
        self.export_fbo = None
        self.requests: list[tuple[str, object]] = []
        self.gui_frames = 0
        self.leaf_frames = 0
        self.t_start = time.perf_counter()
        self.t_first_frame: float | None = None
        self.t_first_leaf: float | None = None
        self.frame_ms: list[float] = []
        self._t_last = None
        self.leaf_rect_px = (LEFT_W, 0, max(self.window_size[0] - LEFT_W - RIGHT_W, 64), self.window_size[1])
        self.dirty = True
        self.exported: list[str] = []
        self.timing: dict[str, float] = {}
        #: (opt-in, LEAFSIM_SIM_THREAD=1; measured no gain on a busy 2-core llvmpipe machine)
        #: opt-in (LEAFSIM_SIM_THREAD=1): step the simulation in a worker thread while imgui
        #: renders and llvmpipe swaps (the C++ frame loop releases the GIL); it only runs between
        #: the end of show_gui and the start of the next frame's custom_background.  Measured on
        #: a busy 2-core llvmpipe machine: no gain (the step slows 2-3x from contention).
        self.threaded = os.environ.get("LEAFSIM_SIM_THREAD", "0") == "1"
        self._worker = None
        self._worker_exc = None
        self._worker_ms = 0.0
        self.msaa = int(os.environ.get("LEAFSIM_MSAA", "0"))
        self.render_scale = float(os.environ.get("LEAFSIM_RENDER_SCALE", "0.75"))
        #: on a software rasteriser start with a cheaper view (ground/shadows off, half size)
        self.auto_quality = "LEAFSIM_RENDER_SCALE" not in os.environ
        self.software_gl = False
        self.show_ground = True
        self.albedo = "detail"
        self.shadows = True
        self.view_fbo = self.view_tex = self.view_depth = None
        self._view_key = None
        self.uploads = 0

    # ------------------------------------------------------------------ runner wiring
    def runner_params(self):
        from imgui_bundle import hello_imgui

        rp = hello_imgui.RunnerParams()
        rp.app_window_params.window_title = self.title
        rp.app_window_params.window_geometry.size = self.window_size
        rp.imgui_window_params.default_imgui_window_type = hello_imgui.DefaultImGuiWindowType.no_default_window
        rp.fps_idling.enable_idling = False
        rp.ini_disable = True
        # llvmpipe: 8x MSAA on the window (hello_imgui's default) costs ~5x per frame;
        # the leaf is anti-aliased by its own renderer settings instead
        rp.renderer_backend_options.open_gl_options.anti_aliasing_samples = self.msaa
        rp.callbacks.post_init = self.post_init
        rp.callbacks.before_exit = self.before_exit
        rp.callbacks.custom_background = self.custom_background
        rp.callbacks.show_gui = self.show_gui
        return rp

    @staticmethod
    def addons():
        from imgui_bundle import immapp

        return immapp.AddOnsParams(with_implot=True)

    def post_init(self) -> None:
        import moderngl

        from ..render.renderer import Renderer

        self.ctx = moderngl.create_context()
        self.renderer = Renderer(self.ctx)
        gl = str(self.ctx.info.get("GL_RENDERER", "")).lower()
        self.software_gl = any(k in gl for k in ("llvmpipe", "softpipe", "swrast"))
        if self.software_gl and self.auto_quality:
            # measured under llvmpipe (428x600 view): ground + its shadow ~65 ms, blade ~27 ms;
            # both scale with pixels.  Hardware GL keeps the full picture.
            self.show_ground = self.shadows = False
            self.render_scale = 0.5

    def before_exit(self) -> None:
        try:
            self._join_step()
        except Exception:
            pass
        for o in (self.photo_tex, self.export_fbo, self.view_fbo, self.view_tex, self.view_depth):
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
    def fail(self, msg: str) -> None:
        self.error = msg

    def _guard(self, fn, *args):
        try:
            return fn(*args)
        except LeafsimError as e:
            self.fail(str(e))
        except Exception as e:  # the GUI must survive anything
            if os.environ.get("LEAFSIM_DEBUG"):
                raise
            self.fail(f"internal error: {type(e).__name__}: {e}")
        return None

    # ------------------------------------------------------------------ per frame (GL)
    def render_options(self):
        from ..render.options import RenderOptions

        p = self.session.params
        view = self.view
        opts = RenderOptions(view=view, translucency=float(p["render.translucency"]) * 1.8,
                             specular=float(p["render.specular"]), veins=p["render.vein_alpha"] > 0.02,
                             background=BACKGROUND, shadow_size=1024, ground=self.show_ground,
                             shadows=self.shadows)
        if view == "water" or view in ("chlorophyll", "carotenoid", "anthocyanin", "browning"):
            opts.scalar_range = (0.0, 1.0)
        if self.session.use_texture():
            opts.albedo = {"detail": "detail", "photo": "texture", "colours": "colours"}[self.albedo]
        return opts

    def custom_background(self) -> None:
        now = time.perf_counter()
        if self._t_last is not None:
            self.frame_ms.append((now - self._t_last) * 1e3)
            del self.frame_ms[:-240]
        self._t_last = now
        if self.t_first_frame is None:
            self.t_first_frame = now
        self.gui_frames += 1
        self._guard(self._frame)

    def _step(self) -> None:
        s = self.session
        t0 = time.perf_counter()
        try:
            s.step(self.steps_per_frame)
        except BaseException as e:  # re-raised on the main thread by _join_step
            self._worker_exc = e
        self._worker_ms = (time.perf_counter() - t0) * 1e3

    def _start_step(self) -> None:
        import threading

        s = self.session
        if self._worker is None and s.ready and self.playing and s.sim_error is None and not s.building:
            self._frame_before = s.frame
            self._worker = threading.Thread(target=self._step, name="leafsim-step", daemon=True)
            self._worker.start()

    def _join_step(self) -> None:
        """Wait for the background step (if any) and take its result."""
        w = self._worker
        if w is None:
            return
        w.join()
        self._worker = None
        exc, self._worker_exc = self._worker_exc, None
        self._stepped(self._frame_before)
        if exc is not None:
            raise exc

    def _stepped(self, before: int) -> None:
        s = self.session
        if s.frame != before:
            self.dirty = True
            if self.recording and s.frame % max(self.record_every, 1) == 0:
                self.requests.append(("record", None))
        if s.sim_error and self.error is None:
            self.fail(s.sim_error)
            self.playing = False

    def _frame(self) -> None:
        """One frame: take the state stepped while the last frame was presented, upload and
        draw it (llvmpipe rasterises the view in its own threads once its framebuffer is
        unbound); the next step starts when the panels are done (:meth:`show_gui`), or here
        right after the draw when ``threaded`` is off.  The picture lags the simulation by
        one frame."""
        s = self.session
        t0 = time.perf_counter()
        self._join_step()
        if s.poll():
            self.dirty = True
        if s.build_error and self.error != s.build_error:
            self.fail(s.build_error)
            s.build_error = None
            if self.frames is not None:
                self.exit_code = 2
                self._exit()
        fb = self.ctx.detect_framebuffer()
        if s.ready:
            self._sync_renderer()
            while self.requests:
                kind, arg = self.requests.pop(0)
                self._guard(self._export, kind, arg)
        t1 = time.perf_counter()
        self._draw_screen(fb)
        t2 = time.perf_counter()
        if not self.threaded and s.ready and self.playing and s.sim_error is None:
            before = s.frame
            s.step(self.steps_per_frame)
            self._worker_ms = (time.perf_counter() - t2) * 1e3
            self._stepped(before)
        self.timing = {"upload": (t1 - t0) * 1e3, "draw": (t2 - t1) * 1e3, "step": self._worker_ms}
        if s.ready:
            self.leaf_frames += 1
            if self.t_first_leaf is None:
                self.t_first_leaf = time.perf_counter()
            if self.frames is not None and self.leaf_frames >= self.frames:
                self._exit()

    def _exit(self) -> None:
        from imgui_bundle import hello_imgui

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
        if self.photo_gen != s.generation:
            self._make_photo_texture()

    def frame_leaf(self) -> None:
        """Aim the camera at the leaf (apex up on screen, seen from above at 55°)."""
        r = self.renderer
        if r is None or r.mesh is None:
            return
        self.camera.yaw, self.camera.pitch = -90.0, 55.0
        pts = np.stack([r.lo, r.hi])
        self.camera.frame_bounds(pts, margin=1.05)

    def _make_photo_texture(self) -> None:
        import cv2

        s = self.session
        if self.photo_tex is not None:
            self.photo_tex.release()
            self.photo_tex = None
        self.photo_gen = s.generation
        if s.photo_rgba is None:
            return
        img = s.photo_rgba
        h, w = img.shape[:2]
        f = min(1.0, 512.0 / max(h, w))
        if f < 1.0:
            img = cv2.resize(img, (max(1, int(w * f)), max(1, int(h * f))), interpolation=cv2.INTER_AREA)
        rgba = img.copy()
        rgba[:, :, 3] = 255  # show the whole photo, background included
        self.photo_tex = self.ctx.texture((rgba.shape[1], rgba.shape[0]), 4, np.ascontiguousarray(rgba).tobytes())

    def _draw_screen(self, fb) -> None:
        """Clear the window and render the leaf into the view texture (drawn by imgui in the
        leaf area, scaled by ``render_scale``: llvmpipe's cost is per pixel)."""
        from imgui_bundle import imgui

        io = imgui.get_io()
        sx, sy = io.display_framebuffer_scale.x, io.display_framebuffer_scale.y
        W, H = int(io.display_size.x * sx), int(io.display_size.y * sy)
        fb.use()
        fb.viewport = (0, 0, W, H)
        fb.clear(*BACKGROUND, 1.0, depth=1.0)
        if not self.session.ready or self.renderer is None or self.renderer.mesh is None:
            return
        _, _, w, h = self.leaf_rect_px
        w = max(int(w * sx * self.render_scale), 16)
        h = max(int(h * sy * self.render_scale), 16)
        if self.view_fbo is None or self.view_fbo.size != (w, h):
            for o in (self.view_fbo, self.view_tex, self.view_depth):
                if o is not None:
                    o.release()
            self.view_tex = self.ctx.texture((w, h), 4)
            self.view_tex.filter = (moderngl_linear(), moderngl_linear())
            self.view_depth = self.ctx.depth_renderbuffer((w, h))
            self.view_fbo = self.ctx.framebuffer(self.view_tex, self.view_depth)
            self._view_key = None
        opts = self.render_options()
        cam = self.camera
        key = (w, h, cam.yaw, cam.pitch, cam.distance, tuple(cam.target), repr(opts), self.uploads)
        if key != self._view_key:  # nothing changed (paused, camera still): keep the last image
            self.renderer.render(cam, w, h, opts, framebuffer=self.view_fbo)
            self._view_key = key
        fb.use()
        fb.viewport = (0, 0, W, H)

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
        folder = Path(self.export_dir).expanduser()
        if not folder.is_dir():
            what = "is not a folder" if folder.exists() else "does not exist"
            raise LeafsimError(f"export folder {folder} {what}")
        if not os.access(folder, os.W_OK | os.X_OK):
            raise LeafsimError(f"export folder {folder} is not writable")
        return folder

    def _export(self, kind: str, arg) -> None:
        from ..render.offscreen import write_png_atomic
        from ..session import public_mode

        s = self.session
        try:
            folder = self._export_folder()
        except LeafsimError:
            self.recording = False
            raise
        if kind == "frame":
            path = folder / f"leafsim_{s.species_key}_seed{s.seed}_f{s.frame:06d}.png"
        else:
            path = folder / f"seq_{s.species_key}_{self.recorded:05d}.png"
        try:
            write_png_atomic(self.leaf_image(), path)
            os.chmod(path, public_mode())
        except OSError as e:
            self.recording = False
            raise LeafsimError(f"cannot write {path}: {e.strerror or e}") from None
        except LeafsimError:
            self.recording = False
            raise
        self.exported.append(str(path))
        if kind == "record":
            self.recorded += 1
            self.info = f"recording: {self.recorded} frames -> {folder}"
        else:
            self.info = f"exported {path}"

    def request_export(self) -> None:
        self.requests.append(("frame", None))

    def start_recording(self) -> None:
        try:
            self._export_folder()
        except LeafsimError as e:
            self.fail(str(e))
            return
        self.recording = True
        self.recorded = 0
        self.requests.append(("record", None))

    # ------------------------------------------------------------------ actions
    def save_preset(self) -> None:
        p = self.session.save_params(self.preset_path)
        self.info = f"saved {p}"

    def load_preset(self) -> None:
        self.session.load_params(self.preset_path, rebuild=True)
        self.dirty = True
        self.info = f"loaded {self.preset_path}"

    def set_params(self, changes: dict) -> None:
        self.session.set_params(self.session.params.with_overrides(changes))
        self.dirty = True

    # ------------------------------------------------------------------ GUI
    def show_gui(self) -> None:
        self._guard(self._gui)
        if self.threaded and not (self.frames is not None and self.leaf_frames >= self.frames):
            self._guard(self._start_step)

    def _gui(self) -> None:
        from imgui_bundle import imgui

        io = imgui.get_io()
        W, H = io.display_size.x, io.display_size.y
        imgui.set_next_window_pos((0, 0), imgui.Cond_.first_use_ever)
        imgui.set_next_window_size((LEFT_W, H), imgui.Cond_.first_use_ever)
        left = right = None
        if imgui.begin("Controls", None, imgui.WindowFlags_.no_collapse):
            self._controls()
            left = imgui.get_window_pos().x + imgui.get_window_size().x
        imgui.end()
        imgui.set_next_window_pos((W - RIGHT_W, 0), imgui.Cond_.first_use_ever)
        imgui.set_next_window_size((RIGHT_W, H), imgui.Cond_.first_use_ever)
        if imgui.begin("Stats", None, imgui.WindowFlags_.no_collapse):
            self._stats()
            right = imgui.get_window_pos().x
        imgui.end()
        x0 = left if left is not None and left < W * 0.6 else 0
        x1 = right if right is not None and right > x0 + 64 else W
        self.leaf_rect_px = (x0, 0, max(x1 - x0, 64), H)
        self._overlay(x0, x1, H)
        self._mouse(io)

    def _overlay(self, x0, x1, H) -> None:
        from imgui_bundle import imgui

        s = self.session
        dl = imgui.get_background_draw_list()
        if s.ready and self.view_tex is not None:
            dl.add_image(imgui.ImTextureRef(self.view_tex.glo), (x0, 0), (x1, H), (0, 1), (1, 0))
        if s.building:
            msg = f"building {s.species_key}: {s.progress_text} ({100 * s.progress:.0f} %)"
            dl.add_text((x0 + 12, 12), imgui.get_color_u32((0.1, 0.1, 0.1, 1.0)), msg)
        if s.ready:
            txt = f"{s.species.name}  frame {s.frame}  t = {s.time:.3f} s  water {100 * s.water_fraction():.1f} %"
            dl.add_text((x0 + 12, H - 24), imgui.get_color_u32((0.1, 0.1, 0.1, 1.0)), txt)

    def _mouse(self, io) -> None:
        from imgui_bundle import imgui

        if io.want_capture_mouse or self.renderer is None:
            return
        x0, _, w, h = self.leaf_rect_px
        dx, dy = io.mouse_delta.x, io.mouse_delta.y
        if imgui.is_mouse_down(imgui.MouseButton_.left) and (dx or dy):
            self.camera.drag(dx, dy)
        if (imgui.is_mouse_down(imgui.MouseButton_.right) or imgui.is_mouse_down(imgui.MouseButton_.middle)) and (dx or dy):
            self.camera.pan(dx, dy, h)
        if io.mouse_wheel:
            self.camera.zoom(io.mouse_wheel)

    def _controls(self) -> None:
        from imgui_bundle import imgui

        from ..session import species_keys
        from .widgets import params_panel

        s = self.session
        imgui.push_item_width(-175)
        if self.error:
            imgui.push_style_color(imgui.Col_.text, (0.9, 0.1, 0.1, 1.0))
            imgui.text_wrapped(f"Error: {self.error}")
            imgui.pop_style_color()
            if imgui.small_button("Dismiss"):
                self.error = None
            imgui.separator()
        # --- species / seed / rebuild
        keys = self._species_keys = getattr(self, "_species_keys", None) or species_keys(s.config)
        idx = keys.index(s.species_key) if s.species_key in keys else 0
        ch, i = imgui.combo("species", idx, keys)
        if ch and keys[i] != s.species_key:
            s.set_species(keys[i])
        ch, seed = imgui.input_int("seed", s.seed)
        if ch and seed >= 0:
            s.set_seed(seed)
        pending = s.pending_rebuild and not s.building
        if pending:
            imgui.push_style_color(imgui.Col_.button, (0.85, 0.45, 0.05, 1.0))
            imgui.push_style_color(imgui.Col_.button_hovered, (0.95, 0.55, 0.1, 1.0))
        if imgui.button("Rebuild"):
            s.apply_rebuild()
        if pending:
            imgui.pop_style_color(2)
            imgui.same_line()
            imgui.text_colored((0.85, 0.45, 0.05, 1.0), "changes staged")
        if s.building:
            imgui.progress_bar(max(s.progress, 0.01), (-1, 0), s.progress_text)
        # --- playback
        imgui.separator()
        if imgui.button("Pause" if self.playing else "Play"):
            self.playing = not self.playing
        imgui.same_line()
        if imgui.button("Step"):
            if s.ready:
                s.step(self.steps_per_frame)
                self.dirty = True
        imgui.same_line()
        if imgui.button("Reset"):
            s.reset()
            self.dirty = True
            if self.error and self.error.startswith("simulation diverged"):
                self.error = None
        imgui.same_line()
        if imgui.button("Frame view"):
            self.frame_leaf()
        _, self.steps_per_frame = imgui.slider_int("steps per frame", self.steps_per_frame, 1, 50)
        vi = VIEWS.index(self.view)
        ch, vi = imgui.combo("view", vi, list(VIEWS))
        if ch:
            self.view = VIEWS[vi]
        _, self.show_ground = imgui.checkbox("ground", self.show_ground)
        imgui.same_line()
        _, self.shadows = imgui.checkbox("shadows", self.shadows)
        imgui.same_line()
        imgui.set_next_item_width(90)
        si = min(range(len(SCALES)), key=lambda k: abs(SCALES[k] - self.render_scale))
        ch, si = imgui.combo("render scale", si, [f"{v:g}x" for v in SCALES])
        if ch:
            self.render_scale = SCALES[si]
        ai = ALBEDOS.index(self.albedo)
        ch, ai = imgui.combo("photo albedo", ai, list(ALBEDOS))
        if ch:
            self.albedo = ALBEDOS[ai]
            self.dirty = True
        # --- export
        if imgui.collapsing_header("Export & presets", imgui.TreeNodeFlags_.default_open):
            _, self.export_dir = imgui.input_text("export folder", self.export_dir)
            if imgui.button("Export frame"):
                self.request_export()
            imgui.same_line()
            if imgui.button("Stop recording" if self.recording else "Record sequence"):
                if self.recording:
                    self.recording = False
                    self.info = f"recorded {self.recorded} frames"
                else:
                    self.start_recording()
            imgui.same_line()
            imgui.set_next_item_width(60)
            _, self.record_every = imgui.input_int("every", self.record_every, 0)
            self.record_every = max(1, self.record_every)
            _, self.preset_path = imgui.input_text("preset JSON", self.preset_path)
            if imgui.button("Save params"):
                self._guard(self.save_preset)
            imgui.same_line()
            if imgui.button("Load params"):
                self._guard(self.load_preset)
            if self.info:
                imgui.text_disabled(self.info)
        # --- parameters (generated from the declaration)
        imgui.separator()
        imgui.text("Parameters (hover for help; orange = staged until Rebuild)")
        changes = params_panel(s.params, s.built_params)
        if changes:
            self._guard(self.set_params, changes)
        imgui.pop_item_width()

    def _stats(self) -> None:
        from imgui_bundle import imgui, implot

        s = self.session
        ft = self.frame_ms[-60:]
        fps = 1000.0 / (sum(ft) / len(ft)) if ft else 0.0
        imgui.text(f"{fps:5.1f} fps  ({imgui.get_io().framerate:5.1f} imgui)")
        if not s.ready:
            imgui.text("building the first leaf ...")
            return
        c = s.counts()
        imgui.text(f"frame {s.frame}   t = {s.time:.3f} s   {'playing' if self.playing else 'paused'}")
        imgui.text(f"particles {c['particles']} (T {c['particles_T']}, V {c['particles_V']})")
        imgui.text(f"springs {c['springs']} (T {c['springs_T']}, V {c['springs_V']}, link {c['springs_link']})")
        imgui.text(f"triangles {c['triangles']}   hinges {c['hinges']}")
        ms = s.last_ms
        tot = sum(ms.values())
        imgui.text(f"ms per stage (total {tot:.2f}):")
        imgui.text_wrapped("   " + "   ".join(f"{k} {v:.2f}" for k, v in ms.items()))
        if self.timing:
            imgui.text_disabled("frame: " + "  ".join(f"{k} {v:.1f}" for k, v in self.timing.items()) + " ms")
        h = s.history
        imgui.text(f"water {s.total_water():.4g} mg ({100 * s.water_fraction():.1f} %)")
        if h["residual"]:
            imgui.text(f"residual {h['residual'][-1]:.3g}   kinetic {h['kinetic'][-1]:.3g} J")
            imgui.text(f"PBD iterations {h['iterations'][-1]}")
        x = np.asarray(h["frame"], np.float64)
        pw = imgui.get_content_region_avail().x
        fit = implot.AxisFlags_.auto_fit
        if len(x) > 0:
            if implot.begin_plot("water", (pw, 150)):
                implot.setup_axes("frame", "water / initial", fit, 0)
                implot.setup_axis_limits(implot.ImAxis_.y1, 0.0, 1.05, imgui.Cond_.once)
                implot.setup_legend(implot.Location_.north_east)
                implot.plot_line("total", x, np.asarray(h["water"], np.float64))
                for key, label in (("water_T", "bottom T"), ("water_V", "top V")):
                    v = np.asarray(h[key], np.float64)
                    implot.plot_line(label, x, v / max(v[0], 1e-300))
                implot.end_plot()
            if implot.begin_plot("constraint residual", (pw, 150)):
                implot.setup_axes("frame", "log10 max |C|/l", fit, fit)
                implot.setup_legend(implot.Location_.south_east)
                r = np.nan_to_num(np.asarray(h["residual"], np.float64), nan=1.0)
                ok = r > 0  # the fresh leaf (frame 0) has none
                implot.plot_line("residual", np.ascontiguousarray(x[ok]), np.log10(r[ok]))
                implot.end_plot()
        imgui.separator()
        imgui.text("Photo")
        if self.photo_tex is not None:
            tw, th = self.photo_tex.size
            f = min(pw / tw, max(imgui.get_content_region_avail().y - 4.0, 100.0) / th)
            imgui.image(imgui.ImTextureRef(self.photo_tex.glo), (tw * f, th * f))
        elif s.photo_error:
            imgui.text_colored((0.9, 0.1, 0.1, 1.0), f"photo unreadable: {s.photo_error}")
        else:
            imgui.text_disabled("no photo (drawn outline species)")


def run_app(species=None, config=None, seed: int = 0, overrides=None, frames=None, screenshot=None,
            play: bool = False) -> int:
    """Run the GUI; returns the exit code.

    ``frames``: run that many frames after the leaf is built (playing), then exit;
    ``screenshot``: write the final window (PNG, atomically) when exiting.
    """
    _configure_threads()
    from ..session import Session

    if frames is not None and frames < 0:
        raise LeafsimError(f"--frames {frames}: expected a non-negative number of frames")
    if screenshot is not None:
        folder = Path(screenshot).parent if str(Path(screenshot).parent) else Path(".")
        if not folder.is_dir():
            raise LeafsimError(f"--screenshot {screenshot}: folder {folder} does not exist")
    session = Session(species, config, seed, overrides, build=False)
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise LeafsimError("gui: no display (DISPLAY is not set); run it on a desktop or under "
                           "xvfb-run -a -s '-screen 0 1280x800x24' leafsim gui ...")
    session.rebuild_async()
    app = LeafApp(session, frames=frames, play=play)
    from imgui_bundle import hello_imgui, immapp

    immapp.run(app.runner_params(), app.addons())
    if screenshot is not None:
        from ..render.offscreen import write_png_atomic

        img = hello_imgui.final_app_window_screenshot()
        if img is None or getattr(img, "size", 0) == 0:
            raise LeafsimError("--screenshot: the window produced no frame")
        img = np.asarray(img)
        write_png_atomic(np.ascontiguousarray(img[:, :, :3]), screenshot)
        from ..session import public_mode

        os.chmod(screenshot, public_mode())
    return app.exit_code
