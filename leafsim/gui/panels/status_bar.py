"""The status bar: the newest message (errors first, with dismiss and copy-path buttons; the
full text in a tooltip) and the progress of a build or of "dry to end"."""

from __future__ import annotations

from imgui_bundle import imgui

from leafsim.gui.layout import tip
from leafsim.gui.status import printable
from leafsim.interactive.builder import WARM_TEXT
from leafsim.interactive.eta import duration


#: width of the progress bar on the right [px]
PROGRESS_W = 300.0


class StatusBar:
    def __init__(self, app):
        self.app = app

    def draw(self) -> None:
        status = self.app.status
        msgs = status.messages()
        avail = imgui.get_content_region_avail().x
        x_left = imgui.get_cursor_screen_pos().x
        m = msgs[0] if msgs else None
        if m is not None:
            colour = (0.95, 0.35, 0.3, 1.0) if m.level == "error" else (0.85, 0.85, 0.85, 1.0)
            if m.level == "error":
                if imgui.small_button("x###dismiss"):
                    status.clear(m.topic)
                tip("Dismiss this message")
                imgui.same_line()
            if m.path:
                if imgui.small_button("copy path###copy"):
                    imgui.set_clipboard_text(printable(m.path))
                tip(f"Copy {m.path}")
                imgui.same_line()
            more = f"  (+{len(msgs) - 1})" if len(msgs) > 1 else ""
            imgui.push_style_color(imgui.Col_.text, colour)
            x_end = x_left + avail - PROGRESS_W - 12  # long text is cut here (full text: tooltip)
            full = ("Error: " if m.level == "error" else "") + m.text
            room = x_end - imgui.get_cursor_screen_pos().x - imgui.calc_text_size(more).x
            # cut with an ellipsis (it stopped mid-word at the progress bar, as if that were all)
            imgui.text_unformatted(fit_text(full, max(room, 40.0), imgui.calc_text_size) + more)
            imgui.pop_style_color()
            if imgui.is_item_hovered():
                imgui.set_tooltip("\n".join(("Error: " if x.level == "error" else "") + x.text for x in msgs))
        imgui.same_line(avail - PROGRESS_W)
        self.progress(PROGRESS_W)

    def progress(self, width: float) -> None:
        s = self.app.session
        pb = s.playback
        compiling = s.building and s.progress_text.startswith(WARM_TEXT)
        if compiling:  # the first build of a version: the bar is too narrow for "building …: " too
            frac, text = 0.0, s.progress_text.replace(WARM_TEXT, "compiling kernels")
        elif s.building:
            frac, text = max(s.progress, 0.01), f"building {s.species_key}: {s.progress_text}"
        elif pb.warming_up:
            frac, text = 0.0, "first step: compiling kernels"
        elif pb.drying:
            frac, text = max(pb.dry_progress(), 0.01), f"drying to the end: {100 * pb.dry_progress():.0f} %"
            left = pb.dry_time_left()
            if left is not None:
                text += f", {duration(left)} left"
        elif s.ready:
            state = "playing" if pb.playing else "paused"
            frac, text = 0.0, f"{state}  {pb.sim_rate:.3g} sim s / s"
        else:
            frac, text = 0.0, "starting"
        # a build's stage before its species when both do not fit ("building grapevine: veins:
        # growing the ven..." hid the stage waited on; the species is the one being switched to)
        short = s.progress_text if s.building and not compiling else text
        shown = text if imgui.calc_text_size(text).x <= width - 10.0 else fit_text(short, width - 10.0, imgui.calc_text_size)
        imgui.progress_bar(frac, (width, 0), shown)
        if shown != text and imgui.is_item_hovered():
            imgui.set_tooltip(text)
        if compiling:
            tip("The first run of a leafsim version compiles the simulation kernels (20 s to about a minute on a small "
                "machine; scripts/setup.sh does it during set-up); they are kept for later runs")
        elif pb.warming_up:
            tip("The first step of a first run compiles the simulation kernels (about a minute on a small machine); "
                "they are kept for later runs")
        elif pb.drying:
            tip("Fast-forward until 2 % of the water is left; press Stop drying to cancel. The time left is "
                "estimated from the pace since the press, and in the drying's tail from how fast the water "
                "has been falling")


def fit_text(text: str, width: float, measure) -> str:
    """``text`` cut at its end with an ellipsis to fit ``width`` pixels (``measure(s).x``): the
    progress bar centres its text, so a long one lost its start ("e: particles, Delaunay/...",
    the species and stage unreadable)."""
    if measure(text).x <= width:
        return text
    lo, hi = 0, len(text)
    while lo < hi:  # the longest start that fits with the ellipsis
        mid = (lo + hi + 1) // 2
        if measure(text[:mid].rstrip() + "...").x <= width:
            lo = mid
        else:
            hi = mid - 1
    return text[:lo].rstrip() + "..."
