"""The Stats panel: frame rate, simulation rate, counts, timings per stage, water, live plots
of water and constraint residual, and the species photo turned as the leaf is shown."""

from __future__ import annotations

import numpy as np
from imgui_bundle import imgui, implot

from leafsim.gui.layout import DRY_UI_HZ
from leafsim.gui.photo import UV_CORNERS, leaf_axes, panel_quad, screen_rotation
from leafsim.sim.environment import clock_text

#: the photo's least height as a share of the panel's width, and at most [px]
PHOTO_MIN, PHOTO_MAX = 0.75, 260.0



def grams(g: float) -> str:
    """A mass in grams, 3 digits, in mg below 0.1 g and µg below 0.1 mg ("0.0001238 g" ran past
    the panel's edge)."""
    if abs(g) >= 0.1 or g == 0.0:
        return f"{g:.3g} g"
    return f"{1e3 * g:.3g} mg" if abs(g) >= 1e-4 else f"{1e6 * g:.3g} µg"

class StatsPanel:
    def __init__(self, app):
        self.app = app
        self._axes_key = None
        self._axes_val = None
        self.photo_size = None  # (w, h) px the photo was last drawn at

    def _axes(self):
        """Where the leaf's rest x and y point now (its blade's best-fit rotation), per snapshot."""
        s = self.app.session
        st, m = s.state, s.model
        if st is None or m is None or st.particle_q.shape != m.particle_rest.shape:
            return None
        key = (id(st), st.frame)
        if key != self._axes_key:
            b = m.blade_particles
            self._axes_key, self._axes_val = key, leaf_axes(m.particle_rest[b], st.particle_q[b])
        return self._axes_val

    def draw(self) -> None:
        app = self.app
        s, pb = app.session, app.session.playback
        ft = np.asarray(app.frame_ms[-120:])
        fps = 1000.0 / ft.mean() if ft.size else 0.0
        p90 = float(np.percentile(ft, 90)) if ft.size else 0.0
        if app.paced:  # drawn slowly on purpose: the CPU goes to the drying
            imgui.text(f"{fps:5.1f} fps   (at most {DRY_UI_HZ:g} while drying to the end)")
        elif ft.size < 2:  # the pace just changed ("Dry to end" ended): no frame rate of its own yet
            imgui.text("    - fps   (measuring)")
        else:
            imgui.text(f"{fps:5.1f} fps   frame p90 {p90:5.1f} ms")
        imgui.text(f"simulation {pb.sim_rate:6.3g} sim s / wall s")
        if s.params["environment.drive"] == "weather":  # the weather clock runs time_warp × faster
            imgui.text(f"weather    {pb.sim_rate * s.params['environment.time_warp'] / 3600:6.3g} h / wall s")
        if not s.ready:
            imgui.text("building the first leaf ...")
            if s.building and s.progress_text:
                imgui.text_wrapped(s.progress_text)  # the first run of a version: the kernels compiling
            return
        c = s.counts()
        imgui.text(f"frame {s.frame}   {clock_text(s.state, s.params)}   {'playing' if pb.playing else 'paused'}")
        imgui.text(f"particles {c['particles']} (T {c['particles_T']}, V {c['particles_V']})")
        imgui.text(f"springs {c['springs']}   triangles {c['triangles']}   hinges {c['hinges']}")
        ms = pb.last_ms
        if ms:
            # CPU ms of the worker thread (Simulator.step): time waiting for the GIL while this
            # thread draws is not in it (wall-clock stages read "shrink 29 ms" for a 0.2 ms kernel)
            imgui.text(f"step {sum(ms.values()):.2f} ms CPU:")  # the stages wrap to the panel's width
            imgui.same_line()
            imgui.text_wrapped(", ".join(f"{k} {v:.1f}" for k, v in ms.items()))  # whole names ("watc" was the watchdog)
        else:  # (it read "step 0.00 ms:" before the first step)
            imgui.text_disabled("step: none yet")
        if app.timing:
            imgui.text_disabled("frame: " + "  ".join(f"{k} {v:.1f}" for k, v in app.timing.items()) + " ms")
        h = pb.history
        # the blade's water and share, the stalk's apart (one total beside the blade's share misread)
        w, b = s.state.particle_water, s.model.blade_particles
        stalk = 1e3 * float(w[~b].sum())
        imgui.text(f"water: blade {grams(1e3 * float(w[b].sum()))} ({100 * s.water_fraction():.1f} %)"
                   + (f", stalk {grams(stalk)}" if (~b).any() else ""))
        if h["residual"]:
            imgui.text(f"residual {h['residual'][-1]:.3g}   kinetic {h['kinetic'][-1]:.3g} J")
        self.plots()
        self.photo()

    def plots(self) -> None:
        h = self.app.session.playback.history
        x = np.asarray(h["frame"], np.float64)
        if len(x) == 0:
            return
        step = max(1, len(x) // 300)  # ≤ 300 points per line: llvmpipe pays per triangle
        sl = slice(None, None, step)
        x = np.ascontiguousarray(x[sl])
        pw = imgui.get_content_region_avail().x
        # the axes are set to this frame's data every frame: implot's auto-fit takes the extents
        # of the frame before, and at "Dry to end"'s 3 redraws a second the curves ended hundreds
        # of frames short of the text above them.  A fresh leaf (one record, after a reset or a
        # species switch) shows frames 0..10
        x_lo, x_hi = (float(x[0]), max(float(x[-1]), float(x[0]) + 1.0)) if len(x) > 1 else (0.0, 10.0)
        if implot.begin_plot("water / initial", (pw, 170)):
            implot.setup_axes("frame", "", 0, 0)
            implot.setup_axis_limits(implot.ImAxis_.x1, x_lo, x_hi, imgui.Cond_.always)
            implot.setup_axis_limits(implot.ImAxis_.y1, 0.0, 1.05, imgui.Cond_.once)
            # below the plot, in a row: inside, it covered the curves and was cut at the edge
            implot.setup_legend(implot.Location_.south, implot.LegendFlags_.outside | implot.LegendFlags_.horizontal)
            implot.plot_line("blade", x, np.ascontiguousarray(np.asarray(h["water"], np.float64)[sl]))
            # where the blade dries first: the margin band against the interior (docs/method.md
            # §3); the two layers only when they part (through-thickness flow off), since with it
            # on they lie on the blade's curve
            for key, label in (("water_margin", "margin"), ("water_interior", "interior")):
                implot.plot_line(label, x, np.ascontiguousarray(np.asarray(h[key], np.float64)[sl]))
            T, V = np.asarray(h["water_T"], np.float64), np.asarray(h["water_V"], np.float64)
            t, v = T / max(T[0], 1e-300), V / max(V[0], 1e-300)
            if np.nanmax(np.abs(t - v)) > 0.05:
                for label, y in (("T", t), ("V", v)):
                    implot.plot_line(label, x, np.ascontiguousarray(y[sl]))
            implot.end_plot()
        r = np.nan_to_num(np.asarray(h["residual"], np.float64), nan=1.0)[sl]
        ok = (r > 0) & np.isfinite(r)  # the fresh leaf (frame 0) has none
        lr = np.log10(r[ok])
        y_lo, y_hi = (float(lr.min()), float(lr.max())) if lr.size else (-3.0, 0.0)
        pad = max(0.05 * (y_hi - y_lo), 0.1)
        if implot.begin_plot("log10 max |C| / l (constraint residual)", (pw, 130), implot.Flags_.no_legend):
            implot.setup_axes("frame", "", 0, 0)
            implot.setup_axis_limits(implot.ImAxis_.x1, x_lo, x_hi, imgui.Cond_.always)
            implot.setup_axis_limits(implot.ImAxis_.y1, y_lo - pad, y_hi + pad, imgui.Cond_.always)
            implot.plot_line("residual", np.ascontiguousarray(x[ok]), lr)
            implot.end_plot()

    def photo(self) -> None:
        """The photo turned as the leaf appears on screen (base→apex as shown)."""
        app = self.app
        s = app.session
        imgui.separator()
        imgui.text("Photo (turned as the leaf is shown)")
        if app.photo_tex is None or app.photo_affine is None:
            if s.photo_error:
                imgui.text_colored((0.9, 0.3, 0.3, 1.0), f"photo unreadable: {s.photo_error}")
            else:
                imgui.text_disabled("no photo (drawn outline species)")
            return
        avail = imgui.get_content_region_avail()
        # the rest of the panel, but at least PHOTO_MIN of its width (≤ PHOTO_MAX px) tall: in a
        # short window the panel scrolls to it (at 1024 × 700 it was an 80 px stamp)
        size = (avail.x, max(avail.y - 4.0, min(PHOTO_MIN * avail.x, PHOTO_MAX)))
        self.photo_size = size
        p0 = imgui.get_cursor_screen_pos()
        r = app.renderer
        R = screen_rotation(app.view_proj(), app.leaf_rect_px, r.center, max(r.radius, 1e-4), self._axes())
        quad, _ = panel_quad(app.photo_affine, R, (p0.x, p0.y, size[0], size[1]))
        dl = imgui.get_window_draw_list()
        dl.add_image_quad(imgui.ImTextureRef(app.photo_tex.glo), *[tuple(map(float, q)) for q in quad],
                          *[tuple(map(float, c)) for c in UV_CORNERS])
        imgui.dummy(size)
