"""The window's imgui panels (a mixin of :class:`leafsim.gui.app.LeafApp`).

A fixed layout: Controls on the left, Stats on the right, the 3-D view between them and one
status bar along the bottom.  The panels cannot be moved or resized, and everything that
comes and goes -- errors, build and "dry to end" progress, "saved ...", "recording ..." --
lives in the status bar, whose height never changes: no widget ever moves under the user's
mouse.  Parameter widgets are generated from :data:`leafsim.params.PARAMS`
(:mod:`leafsim.gui.widgets`).
"""

from __future__ import annotations

import time

import numpy as np

from ..view import PIGMENT_VIEWS

VIEWS = ("shaded", "wireframe", "particles", "springs", "mass", "water", *PIGMENT_VIEWS)
#: heat maps: (label of the colour bar, unit, scale applied to the field for the ticks)
HEAT_UNITS = {"mass": ("particle mass", "mg", 1.0), "water": ("water / initial water", "%", 100.0),
              **{p: (f"{p} / summer content", "%", 100.0) for p in PIGMENT_VIEWS}}
LEFT_W, RIGHT_W, STATUS_H = 380, 330, 34
#: albedo of photo species: pigment colour with the photo's detail, the photo tinted by the
#: pigment change, or the pigment colour alone
ALBEDOS = ("detail", "photo", "colours")
COMPARES = ("off", "overlay", "blink")
BACKGROUND = (0.80, 0.84, 0.88)
PANEL_BG = (0.11, 0.11, 0.12)


def _fixed_flags():
    from imgui_bundle import imgui

    return (imgui.WindowFlags_.no_move | imgui.WindowFlags_.no_resize | imgui.WindowFlags_.no_collapse
            | imgui.WindowFlags_.no_background | imgui.WindowFlags_.no_saved_settings)


def _tip(text: str) -> None:
    from imgui_bundle import imgui

    if imgui.is_item_hovered(imgui.HoveredFlags_.for_tooltip):
        imgui.set_tooltip(text)


class Panels:
    """imgui drawing of :class:`LeafApp` (uses its session, status, camera, renderer)."""

    # ------------------------------------------------------------------ layout
    def layout(self):
        """(W, H, left rect, right rect, status rect) in window pixels."""
        from imgui_bundle import imgui

        io = imgui.get_io()
        W, H = io.display_size.x, io.display_size.y
        top = H - STATUS_H
        return W, H, (0, 0, LEFT_W, top), (W - RIGHT_W, 0, RIGHT_W, top), (0, top, W, STATUS_H)

    def panel_rects(self):
        _, _, left, right, bar = self.layout()
        return left, right, bar

    def show_gui(self) -> None:
        self._guard(self._gui)

    def _window(self, name: str, rect, draw) -> None:
        from imgui_bundle import imgui

        x, y, w, h = rect
        imgui.set_next_window_pos((x, y), imgui.Cond_.always)
        imgui.set_next_window_size((w, h), imgui.Cond_.always)
        extra = imgui.WindowFlags_.no_title_bar | imgui.WindowFlags_.no_scrollbar if name == "Status" else 0
        if imgui.begin(name, None, _fixed_flags() | extra):
            self._guard(draw)
        imgui.end()

    def _gui(self) -> None:
        from imgui_bundle import imgui

        W, H, left, right, bar = self.layout()
        self._window("Controls", left, self._controls)
        self._window("Stats", right, self._stats)
        self._window("Status", bar, self._status_bar)
        self.leaf_rect_px = (LEFT_W, 0, max(W - LEFT_W - RIGHT_W, 64), max(H - STATUS_H, 64))
        self._overlay()
        self._mouse(imgui.get_io())

    # ------------------------------------------------------------------ status bar
    def _status_bar(self) -> None:
        from imgui_bundle import imgui

        s = self.session
        msgs = self.status.messages()
        avail = imgui.get_content_region_avail().x
        x_left = imgui.get_cursor_screen_pos().x
        prog_w = 300.0
        m = msgs[0] if msgs else None
        if m is not None:
            colour = (0.95, 0.35, 0.3, 1.0) if m.level == "error" else (0.85, 0.85, 0.85, 1.0)
            if m.level == "error":
                if imgui.small_button("x###dismiss"):
                    self.status.clear(m.topic)
                _tip("Dismiss this message")
                imgui.same_line()
            if m.path:
                if imgui.small_button("copy path###copy"):
                    imgui.set_clipboard_text(m.path)
                _tip(f"Copy {m.path}")
                imgui.same_line()
            more = f"  (+{len(msgs) - 1})" if len(msgs) > 1 else ""
            imgui.push_style_color(imgui.Col_.text, colour)
            x_end = x_left + avail - prog_w - 12  # long text is cut here (full text: tooltip)
            imgui.push_clip_rect(imgui.get_cursor_screen_pos(), (x_end, 1e5), True)
            imgui.text_unformatted(("Error: " if m.level == "error" else "") + m.text + more)
            imgui.pop_clip_rect()
            imgui.pop_style_color()
            if imgui.is_item_hovered():
                imgui.set_tooltip("\n".join(("Error: " if x.level == "error" else "") + x.text for x in msgs))
        imgui.same_line(avail - prog_w)
        self._progress(prog_w)

    def _progress(self, width: float) -> None:
        from imgui_bundle import imgui

        s = self.session
        if s.building:
            frac, text = max(s.progress, 0.01), f"building {s.species_key}: {s.progress_text}"
        elif s.drying:
            frac, text = max(s.dry_progress(), 0.01), f"drying to the end: {100 * s.dry_progress():.0f} %"
        elif s.ready:
            state = "playing" if s.playing else "paused"
            frac, text = 0.0, f"{state}  {s.sim_rate:.3g} sim s / s"
        else:
            frac, text = 0.0, "starting"
        imgui.progress_bar(frac, (width, 0), text)
        if s.drying:
            _tip("Fast-forward until 2 % of the water is left; press Stop drying to cancel")

    # ------------------------------------------------------------------ overlay on the 3-D view
    def _overlay(self) -> None:
        from imgui_bundle import imgui

        s = self.session
        x0, y0, w, h = self.leaf_rect_px
        dl = imgui.get_background_draw_list()
        if s.ready and self.view_tex is not None and not self.view_direct:
            dl.add_image(imgui.ImTextureRef(self.view_tex.glo), (x0, y0), (x0 + w, y0 + h), (0, 1), (1, 0))
        if s.ready:
            self._photo_overlay(dl)
            sp = s.shown_species  # the leaf on screen: the old species while a switch builds
            txt = f"{sp.name}  frame {s.frame}  t = {s.time:.3f} s  water {100 * s.water_fraction():.1f} %"
            dl.add_text((x0 + 12, y0 + h - 24), imgui.get_color_u32((0.1, 0.1, 0.1, 1.0)), txt)
            if self.view in HEAT_UNITS and self.renderer is not None and self.renderer.mesh is not None:
                self._legend(dl, x0 + w - 70, y0 + 44, h * 0.33)

    def _legend(self, dl, x: float, y: float, height: float) -> None:
        """Colour bar of the heat map with its range, ticks and unit."""
        from imgui_bundle import imgui

        from ..render.colormaps import colormap

        label, unit, k = HEAT_UNITS[self.view]
        opts = self.render_options()
        lo, hi = self.renderer.scalar_range(opts)
        n = 32
        for i in range(n):  # top = high
            c0 = colormap(opts.colormap, 1.0 - i / n)
            c1 = colormap(opts.colormap, 1.0 - (i + 1) / n)
            y_a, y_b = y + height * i / n, y + height * (i + 1) / n
            u0 = imgui.get_color_u32((*c0, 1.0))
            u1 = imgui.get_color_u32((*c1, 1.0))
            dl.add_rect_filled_multi_color((x, y_a), (x + 18, y_b), u0, u0, u1, u1)
        ink = imgui.get_color_u32((0.1, 0.1, 0.1, 1.0))
        dl.add_rect((x, y), (x + 18, y + height), ink)
        for t in np.linspace(0.0, 1.0, 5):
            v = (lo + (hi - lo) * t) * k
            ty = y + height * (1.0 - t)
            dl.add_line((x + 18, ty), (x + 23, ty), ink)
            dl.add_text((x + 26, ty - 7), ink, f"{v:.3g}")
        tw = imgui.calc_text_size(label).x
        dl.add_text((x + 60 - tw, y - 36), ink, label)
        dl.add_text((x, y - 20), ink, f"[{unit}]")
        if not opts.scalar_range:
            note = "2nd..98th pct"
            dl.add_text((x + 60 - imgui.calc_text_size(note).x, y + height + 8), ink, note)

    def _photo_overlay(self, dl) -> None:
        """The photo projected onto the leaf's rest place (overlay or blink compare)."""
        from imgui_bundle import imgui

        from .photo import overlay_grid

        if self.photo_compare == "off" or self.photo_tex_masked is None or self.photo_affine is None:
            return
        if self.photo_compare == "blink" and int(time.monotonic() / 0.6) % 2 == 0:
            return
        alpha = 1.0 if self.photo_compare == "blink" else float(self.photo_alpha)
        pts, uv = overlay_grid(self.photo_affine, self.photo_z, self.view_proj(), self.leaf_rect_px)
        col = imgui.get_color_u32((1.0, 1.0, 1.0, alpha))
        ref = imgui.ImTextureRef(self.photo_tex_masked.glo)
        n = pts.shape[0] - 1
        for i in range(n):
            for j in range(n):
                q = [pts[i, j], pts[i, j + 1], pts[i + 1, j + 1], pts[i + 1, j]]
                t = [uv[i, j], uv[i, j + 1], uv[i + 1, j + 1], uv[i + 1, j]]
                dl.add_image_quad(ref, *[tuple(map(float, p)) for p in q], *[tuple(map(float, c)) for c in t], col)

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

    # ------------------------------------------------------------------ Controls
    def _controls(self) -> None:
        from imgui_bundle import imgui

        from .widgets import params_panel

        imgui.push_item_width(-175)
        self._species_rows()
        imgui.separator()
        self._playback_rows()
        self._view_rows()
        if imgui.collapsing_header("Export & presets", imgui.TreeNodeFlags_.default_open):
            self._export_rows()
        imgui.separator()
        imgui.text("Parameters (hover: help; orange: staged)")
        s = self.session
        changes = params_panel(s.params, s.built_params)
        if changes:
            self._guard(self.set_params, changes)
        imgui.pop_item_width()

    def _species_rows(self) -> None:
        from imgui_bundle import imgui

        from ..session import species_keys

        s = self.session
        keys = self._species_keys = getattr(self, "_species_keys", None) or species_keys(s.config)
        idx = keys.index(s.species_key) if s.species_key in keys else 0
        imgui.set_next_item_width(150)
        ch, i = imgui.combo("species", idx, keys)
        if ch and keys[i] != s.species_key:
            self._guard(self.switch_species, keys[i], topic="species")
        imgui.same_line()
        if imgui.button("species defaults"):
            self._guard(self.species_defaults, topic="species")
        _tip("Every parameter back to this species' own values (your changes and --set overrides dropped)")
        ch, seed = imgui.input_int("seed", s.seed)
        if ch and seed >= 0:
            s.set_seed(seed)
        self._quality_row()
        pending = s.pending_rebuild and not s.building
        if pending:
            imgui.push_style_color(imgui.Col_.button, (0.85, 0.45, 0.05, 1.0))
            imgui.push_style_color(imgui.Col_.button_hovered, (0.95, 0.55, 0.1, 1.0))
        if imgui.button("Rebuild"):
            s.apply_rebuild()
        if pending:
            imgui.pop_style_color(2)
        imgui.same_line()
        imgui.text_colored((0.85, 0.45, 0.05, 1.0), "changes staged" if pending else "")

    def _quality_row(self) -> None:
        """Quality levels from the accuracy study's front; the tooltip shows each one's measured
        error against the converged reference and its cost."""
        from imgui_bundle import imgui

        from ..params import ParamSet
        from ..sim.presets import quality_of, quality_table

        table = self._quality = getattr(self, "_quality", None) or quality_table()
        names = ["custom"] + list(table)
        now = quality_of(self.session.params) or "custom"
        imgui.set_next_item_width(150)
        ch, i = imgui.combo("quality", names.index(now), names)
        if ch and names[i] != "custom":
            self._guard(self.set_params, table[names[i]]["settings"], topic="quality")
        lines = []
        for k, v in table.items():
            m = v["measured"]
            lines.append(f"{k}{' (default)' if k == quality_of(ParamSet()) else ''}: " + (f"worst error {100 * m['worst_rel']:.0f} % of the reference, "
                                     f"{m['ms_per_sim_s']:.0f} ms per simulated second" if m else "not measured"))
        _tip("Mesh and solver settings from the accuracy study (docs/accuracy.md); measured on maple:\n" + "\n".join(lines))

    def _playback_rows(self) -> None:
        from imgui_bundle import imgui

        s = self.session
        # buttons whose label toggles have a fixed width: nothing after them moves
        if imgui.button("Pause###play" if s.playing and not s.drying else "Play###play", (52, 0)):
            s.play(not s.playing)
        imgui.same_line()
        if imgui.button("Step"):
            s.request_steps(1)
        imgui.same_line()
        if imgui.button("Reset"):
            s.reset(wait=False)  # the worker makes the fresh leaf; the next snapshot shows it
            self.dirty = True
        imgui.same_line()
        if imgui.button("Frame view"):
            self.frame_leaf()
        imgui.same_line()
        if imgui.button("Stop drying###dry" if s.drying else "Dry to end###dry", (96, 0)):
            s.dry_to_end(not s.drying)
        _tip("Fast-forward (as fast as possible) until 2 % of the water is left, then pause")
        ch, self.speed_fast = imgui.checkbox("as fast as possible", self.speed_fast)
        imgui.same_line()
        imgui.begin_disabled(self.speed_fast)
        imgui.set_next_item_width(110)
        ch2, self.speed = imgui.slider_float("sim s / s###speed", self.speed, 0.001, 2.0, "%.3g",
                                             imgui.SliderFlags_.logarithmic | imgui.SliderFlags_.always_clamp)
        imgui.end_disabled()
        _tip("Simulated seconds per wall-clock second (a full drying is a few simulated seconds)")
        if ch or ch2:
            s.set_speed(None if self.speed_fast else self.speed)

    def _view_rows(self) -> None:
        from imgui_bundle import imgui

        from .app import SCALES

        vi = VIEWS.index(self.view)
        ch, vi = imgui.combo("view", vi, list(VIEWS))
        if ch:
            self.view = VIEWS[vi]
        _, self.show_ground = imgui.checkbox("ground", self.show_ground)
        imgui.same_line()
        _, self.shadows = imgui.checkbox("shadows", self.shadows)
        _tip("The leaf's soft shadow on the ground")
        imgui.same_line()
        _, self.self_shadow = imgui.checkbox("self", self.self_shadow)
        _tip("The leaf shading itself where it curls (costs ~12 ms per frame on a software rasteriser at 1x)")
        imgui.same_line()
        imgui.set_next_item_width(70)
        si = min(range(len(SCALES)), key=lambda k: abs(SCALES[k] - self.render_scale))
        ch, si = imgui.combo("scale###render scale", si, [f"{v:g}x" for v in SCALES])
        _tip("Render scale of the 3-D view (a software rasteriser pays per pixel)")
        if ch:
            self.render_scale = SCALES[si]
        _, self.heat_fit = imgui.checkbox("heat map: fit range to the data", self.heat_fit)
        _tip("Colour the heat maps over the field's own 2nd..98th percentile (on) or over 0..100 % (off)")
        ai = ALBEDOS.index(self.albedo)
        ch, ai = imgui.combo("photo albedo", ai, list(ALBEDOS))
        if ch:
            self.albedo = ALBEDOS[ai]
            self.dirty = True
        imgui.set_next_item_width(90)
        ci = COMPARES.index(self.photo_compare)
        ch, ci = imgui.combo("photo compare", ci, list(COMPARES))
        if ch:
            self.photo_compare = COMPARES[ci]
        _tip("Show the species photo over the leaf where the fresh leaf lay: overlay (opacity) or blink")
        imgui.same_line()
        imgui.set_next_item_width(-1)
        _, self.photo_alpha = imgui.slider_float("###photo alpha", self.photo_alpha, 0.0, 1.0, "opacity %.2f")

    def _export_rows(self) -> None:
        from imgui_bundle import imgui

        _, self.export_dir = imgui.input_text("export folder", self.export_dir)
        _tip(f"{self.export_dir}\n(created when missing; every recorded take gets its own take_NNN folder)")
        if imgui.button("Export frame"):
            self.request_export()
        imgui.same_line()
        if imgui.button("Stop recording###record" if self.take is not None else "Record take###record", (118, 0)):
            if self.take is not None:
                self.stop_recording()
            else:
                self.start_recording()
        imgui.same_line()
        imgui.set_next_item_width(60)
        _, self.record_every = imgui.input_int("every", self.record_every, 0)
        _tip("Record a frame every this many simulation frames")
        self.record_every = max(1, self.record_every)
        _, self.preset_path = imgui.input_text("preset JSON", self.preset_path)
        _tip(self.preset_path)
        if imgui.button("Save params"):
            self._guard(self.save_preset, topic="preset")
        imgui.same_line()
        if imgui.button("Load params"):
            self._guard(self.load_preset, topic="preset")
        imgui.same_line()
        self._export_mesh_button()

    def _export_mesh_button(self) -> None:
        """"Export mesh": the leaf on screen as a binary glTF (both layers as a closed shell,
        veins, pigment colours) into the export folder, never overwriting."""
        from imgui_bundle import imgui

        imgui.begin_disabled(not self.session.ready)
        if imgui.button("Export mesh"):
            self._guard(self.export_mesh, topic="mesh")
        imgui.end_disabled()
        _tip("Write the leaf on screen as a glTF 2.0 binary (.glb: closed two-layer shell, veins, pigment colours)")

    # ------------------------------------------------------------------ Stats
    def _stats(self) -> None:
        from imgui_bundle import imgui

        s = self.session
        ft = np.asarray(self.frame_ms[-120:])
        fps = 1000.0 / ft.mean() if ft.size else 0.0
        p90 = float(np.percentile(ft, 90)) if ft.size else 0.0
        imgui.text(f"{fps:5.1f} fps   frame p90 {p90:5.1f} ms")
        imgui.text(f"simulation {s.sim_rate:6.3g} sim s / wall s")
        if not s.ready:
            imgui.text("building the first leaf ...")
            return
        c = s.counts()
        imgui.text(f"frame {s.frame}   t = {s.time:.3f} s   {'playing' if s.playing else 'paused'}")
        imgui.text(f"particles {c['particles']} (T {c['particles_T']}, V {c['particles_V']})")
        imgui.text(f"springs {c['springs']}   triangles {c['triangles']}   hinges {c['hinges']}")
        ms = s.last_ms
        imgui.text(f"step ms (total {sum(ms.values()):.2f}): " + " ".join(f"{k[:4]} {v:.1f}" for k, v in ms.items()))
        if self.timing:
            imgui.text_disabled("frame: " + "  ".join(f"{k} {v:.1f}" for k, v in self.timing.items()) + " ms")
        h = s.history
        imgui.text(f"water {1e3 * s.total_water():.4g} g ({100 * s.water_fraction():.1f} %)")  # kg in the model
        if h["residual"]:
            imgui.text(f"residual {h['residual'][-1]:.3g}   kinetic {h['kinetic'][-1]:.3g} J")
        self._plots()
        self._photo_panel()

    def _plots(self) -> None:
        from imgui_bundle import imgui, implot

        h = self.session.history
        x = np.asarray(h["frame"], np.float64)
        if len(x) == 0:
            return
        step = max(1, len(x) // 300)  # ≤ 300 points per line: llvmpipe pays per triangle
        sl = slice(None, None, step)
        x = np.ascontiguousarray(x[sl])
        pw = imgui.get_content_region_avail().x
        fit = implot.AxisFlags_.auto_fit
        if implot.begin_plot("water", (pw, 140)):
            implot.setup_axes("frame", "water / initial", fit, 0)
            implot.setup_axis_limits(implot.ImAxis_.y1, 0.0, 1.05, imgui.Cond_.once)
            implot.setup_legend(implot.Location_.north_east)
            implot.plot_line("total", x, np.ascontiguousarray(np.asarray(h["water"], np.float64)[sl]))
            for key, label in (("water_T", "bottom T"), ("water_V", "top V")):
                v = np.asarray(h[key], np.float64)
                implot.plot_line(label, x, np.ascontiguousarray(v[sl] / max(v[0], 1e-300)))
            implot.end_plot()
        if implot.begin_plot("constraint residual", (pw, 120)):
            implot.setup_axes("frame", "log10 max |C|/l", fit, fit)
            r = np.nan_to_num(np.asarray(h["residual"], np.float64), nan=1.0)[sl]
            ok = r > 0  # the fresh leaf (frame 0) has none
            implot.plot_line("residual", np.ascontiguousarray(x[ok]), np.log10(r[ok]))
            implot.end_plot()

    def _photo_panel(self) -> None:
        """The photo turned as the leaf appears on screen (base→apex as shown)."""
        from imgui_bundle import imgui

        from .photo import panel_quad, screen_rotation

        s = self.session
        imgui.separator()
        imgui.text("Photo (turned as the leaf is shown)")
        if self.photo_tex is None or self.photo_affine is None:
            if s.photo_error:
                imgui.text_colored((0.9, 0.3, 0.3, 1.0), f"photo unreadable: {s.photo_error}")
            else:
                imgui.text_disabled("no photo (drawn outline species)")
            return
        avail = imgui.get_content_region_avail()
        size = (avail.x, max(avail.y - 4.0, 80.0))
        p0 = imgui.get_cursor_screen_pos()
        r = self.renderer
        R = screen_rotation(self.view_proj(), self.leaf_rect_px, r.center, max(r.radius, 1e-4))
        quad, _ = panel_quad(self.photo_affine, R, (p0.x, p0.y, size[0], size[1]))
        from .photo import UV_CORNERS

        dl = imgui.get_window_draw_list()
        dl.add_image_quad(imgui.ImTextureRef(self.photo_tex.glo), *[tuple(map(float, q)) for q in quad],
                          *[tuple(map(float, c)) for c in UV_CORNERS])
        imgui.dummy(size)
