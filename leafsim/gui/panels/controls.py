"""The Controls panel: species, seed, quality and Rebuild; playback (play, step, reset, dry to
end, speed); view options; export and presets; every parameter as a widget generated from the
one declaration (:mod:`leafsim.gui.widgets`)."""

from __future__ import annotations

import math

from imgui_bundle import imgui

from leafsim.base.errors import LeafsimError
from leafsim.config.params import ParamSet
from leafsim.config.presets import quality_lines, quality_of, quality_table
from leafsim.gui.layout import ALBEDOS, COMPARES, SCALES, VIEWS, tip
from leafsim.gui.status import printable
from leafsim.gui.widgets import STAGED_COLOUR, params_panel
from leafsim.config.params import check_seed
from leafsim.interactive.session import species_keys
from leafsim.sim.effects.dynamics import unmeasured_substeps


def path_field(label: str, value: str) -> str:
    """A text field holding a path: shown drawable (bytes that are not UTF-8 as ``\\xNN``)
    and replaced only when the user edits it (an untouched path keeps its real bytes)."""
    ch, text = imgui.input_text(label, printable(value))
    return text if ch else value


def finite_or(new: float, old: float) -> float:
    """``new`` unless the user typed something that is not a finite number into a slider."""
    return float(new) if math.isfinite(new) else old


class ControlsPanel:
    def __init__(self, app):
        self.app = app
        self._species_keys: list[str] | None = None
        self._quality: dict | None = None
        self._seed_text, self._seed_shown = "", None

    def draw(self) -> None:
        app = self.app
        imgui.push_item_width(-175)
        self.species_rows()
        imgui.separator()
        self.playback_rows()
        self.view_rows()
        if imgui.collapsing_header("Export & presets", imgui.TreeNodeFlags_.default_open):
            self.export_rows()
        imgui.separator()
        imgui.text("Parameters (hover: help; orange: staged)")
        s = app.session
        changes = params_panel(s.params, s.built_params)
        if changes:
            app.guard(app.set_params, changes)
        imgui.pop_item_width()

    def species_rows(self) -> None:
        app = self.app
        s = app.session
        keys = self._species_keys = self._species_keys or species_keys(s.config)
        idx = keys.index(s.species_key) if s.species_key in keys else 0
        imgui.set_next_item_width(150)
        ch, i = imgui.combo("species", idx, keys)
        if ch and keys[i] != s.species_key:
            app.guard(app.switch_species, keys[i], topic="species")
        imgui.same_line()
        if imgui.button("species defaults"):
            app.guard(app.species_defaults, topic="species")
        tip("Every parameter back to this species' own values (your changes and --set overrides dropped)")
        self.seed_row()
        self.quality_row()
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

    def seed_row(self) -> None:
        """The seed as text: any seed the command line takes (up to 2**63-1, beyond an int
        field's 32 bits); what is not one is an error in the status bar, the staged seed kept."""
        app = self.app
        s = app.session
        if self._seed_shown != s.seed:  # changed elsewhere (a loaded preset)
            self._seed_text, self._seed_shown = str(s.seed), s.seed
        staged = s.built_seed is not None and s.seed != s.built_seed  # orange until Rebuild, as a staged slider
        if staged:
            imgui.push_style_color(imgui.Col_.text, STAGED_COLOUR)
        ch, text = imgui.input_text("seed", self._seed_text, imgui.InputTextFlags_.chars_decimal)
        if staged:
            imgui.pop_style_color()
        if not ch:
            return
        self._seed_text = text
        try:
            digits = text.strip().isascii() and text.strip().isdigit() and len(text.strip()) <= 30  # int() refuses > 4300
            s.set_seed(check_seed(int(text.strip()) if digits else text.strip(), "seed field"))
        except LeafsimError as e:
            app.fail(str(e), "seed")
            return
        self._seed_shown = s.seed
        app.status.clear("seed")

    def quality_row(self) -> None:
        """Quality levels from the accuracy study's front; the tooltip shows each one's measured
        error against the converged reference and its cost."""
        app = self.app
        table = self._quality = self._quality or quality_table()
        names = ["custom"] + list(table)
        now = quality_of(app.session.params) or "custom"
        imgui.set_next_item_width(150)
        ch, i = imgui.combo("quality", names.index(now), names)
        if ch and names[i] != "custom":
            app.guard(app.set_params, table[names[i]]["settings"], topic="quality")
        lines = quality_lines(table, quality_of(ParamSet()))
        tip("Mesh and solver settings, measured against each species' converged limit (docs/accuracy.md):\n"
            + "\n".join(lines))
        coarse = unmeasured_substeps(app.session.params)
        if coarse:  # (a leaf at dynamics.substeps 1 dried flat, and nothing said why)
            imgui.same_line()
            imgui.text_colored((0.95, 0.55, 0.1, 1.0), "substeps too coarse")
            tip(coarse.replace(": ", ":\n", 1))

    def playback_rows(self) -> None:
        app = self.app
        s = app.session
        pb = s.playback
        # buttons whose label toggles have a fixed width: nothing after them moves
        if imgui.button("Pause###play" if pb.playing and not pb.drying else "Play###play", (52, 0)):
            pb.play(not pb.playing)
        imgui.same_line()
        if imgui.button("Step"):
            pb.request_steps(1)
        imgui.same_line()
        if imgui.button("Reset"):
            s.reset(wait=False)  # the worker makes the fresh leaf; the next snapshot shows it
            app.dirty = True
        imgui.same_line()
        if imgui.button("Frame view"):
            app.frame_leaf()
        imgui.same_line()
        if imgui.button("Stop drying###dry" if pb.drying else "Dry to end###dry", (96, 0)):
            pb.dry_to_end(not pb.drying)
        tip("Fast-forward (as fast as possible) until 2 % of the water is left, then pause")
        ch, app.speed_fast = imgui.checkbox("as fast as possible", app.speed_fast)
        imgui.same_line()
        imgui.begin_disabled(app.speed_fast)
        imgui.set_next_item_width(110)
        ch2, speed = imgui.slider_float("sim s / s###speed", app.speed, 0.001, 2.0, "%.3g",
                                        imgui.SliderFlags_.logarithmic | imgui.SliderFlags_.always_clamp)
        app.speed = finite_or(speed, app.speed)
        imgui.end_disabled()
        tip("Simulated seconds per wall-clock second (a full drying is a few simulated seconds)")
        if ch or ch2:
            pb.set_speed(None if app.speed_fast else app.speed)

    def view_rows(self) -> None:
        app = self.app
        vi = VIEWS.index(app.view)
        ch, vi = imgui.combo("view", vi, list(VIEWS))
        if ch:
            app.view = VIEWS[vi]
        _, app.show_ground = imgui.checkbox("ground", app.show_ground)
        imgui.same_line()
        _, app.shadows = imgui.checkbox("shadows", app.shadows)
        tip("The leaf's soft shadow on the ground")
        imgui.same_line()
        _, app.self_shadow = imgui.checkbox("self", app.self_shadow)
        tip("The leaf shading itself where it curls (costs ~12 ms per frame on a software rasteriser at 1x)")
        imgui.same_line()
        imgui.set_next_item_width(70)
        si = min(range(len(SCALES)), key=lambda k: abs(SCALES[k] - app.render_scale))
        ch, si = imgui.combo("scale###render scale", si, [f"{v:g}x" for v in SCALES])
        tip("Render scale of the 3-D view (a software rasteriser pays per pixel)")
        if ch:
            app.render_scale = SCALES[si]
        _, app.heat_fit = imgui.checkbox("heat map: fit range to the data", app.heat_fit)
        tip("Colour the heat maps over the field's own 2nd..98th percentile (on) or over 0..100 % (off)")
        # a drawn species has no photo: the photo's controls are greyed out and say why (they were
        # live and did nothing)
        no_photo = app.session.ready and app.session.photo_rgba is None
        why = "\n(this species has no photo: its outline is drawn)" if no_photo else ""
        imgui.begin_disabled(no_photo)
        ai = ALBEDOS.index(app.albedo)
        ch, ai = imgui.combo("photo albedo", ai, list(ALBEDOS))
        if ch:
            app.albedo = ALBEDOS[ai]
            app.dirty = True
        _disabled_tip("The blade's colour from the species photo: detail (its fine hues on living tissue), the photo "
                      "itself, or the pigment colours alone" + why)
        imgui.set_next_item_width(90)
        ci = COMPARES.index(app.photo_compare)
        ch, ci = imgui.combo("photo compare", ci, list(COMPARES))
        if ch:
            app.photo_compare = COMPARES[ci]
        _disabled_tip("Show the species photo over the leaf where the fresh leaf lay: overlay (opacity) or blink" + why)
        imgui.same_line()
        imgui.set_next_item_width(-1)
        _, alpha = imgui.slider_float("###photo alpha", app.photo_alpha, 0.0, 1.0, "opacity %.2f",
                                      imgui.SliderFlags_.always_clamp)
        app.photo_alpha = finite_or(alpha, app.photo_alpha)
        imgui.end_disabled()

    def export_rows(self) -> None:
        app = self.app
        app.export_dir = path_field("export folder", app.export_dir)
        tip(f"{app.export_dir}\n(created when missing; every recorded take gets its own take_NNN folder)")
        if imgui.button("Export frame"):
            app.request_export()
        imgui.same_line()
        if imgui.button("Stop recording###record" if app.take is not None else "Record take###record", (118, 0)):
            if app.take is not None:
                app.stop_recording()
            else:
                app.start_recording()
        imgui.same_line()
        imgui.set_next_item_width(60)
        _, app.record_every = imgui.input_int("every", app.record_every, 0)
        tip("Record a frame every this many simulation frames")
        app.record_every = max(1, app.record_every)
        app.preset_path = path_field("preset JSON", app.preset_path)
        tip(app.preset_path)
        if imgui.button("Save params"):
            app.guard(app.save_preset, topic="preset")
        imgui.same_line()
        if imgui.button("Load params"):
            app.guard(app.load_preset, topic="preset")
        imgui.same_line()
        self.export_mesh_button()

    def export_mesh_button(self) -> None:
        """"Export mesh": the leaf on screen as a binary glTF (both layers as a closed shell,
        veins, its colour as the window draws it baked into a texture) into the export folder,
        never overwriting."""
        app = self.app
        imgui.begin_disabled(not app.session.ready)
        if imgui.button("Export mesh"):
            app.guard(app.export_mesh, topic="mesh")
        imgui.end_disabled()
        tip("Write the leaf on screen as a glTF 2.0 binary (.glb: closed two-layer shell, veins, and its colour as "
            "drawn here, the fine flecks and the photo's detail included, baked into a texture any glTF viewer shows)")


def _disabled_tip(text: str) -> None:
    """A tooltip that also shows over a greyed-out item."""
    if imgui.is_item_hovered(imgui.HoveredFlags_.for_tooltip | imgui.HoveredFlags_.allow_when_disabled):
        imgui.set_tooltip(text)
