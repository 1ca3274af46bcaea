"""imgui widgets generated from the parameter declaration (:data:`leafsim.config.params.PARAMS`).

Every parameter gets one widget whose kind follows the declaration: float → slider (log scale
where declared) with the unit in the label and the help text as tooltip, int → integer
slider, bool → checkbox, choice → combo.  The visible label is the last name component plus
the unit; the imgui ID is the full dotted name (``"evaporation_top [kg/(m²·s)]###osmosis.evaporation_top"``), so
tests and scripts can address a widget as ``"**/###osmosis.evaporation_top"``.
"""

from __future__ import annotations

from typing import Any

from imgui_bundle import imgui

from leafsim.config.params import GROUPS, PARAMS, Param, ParamSet

#: names of the parameter widgets drawn since the last :func:`reset_drawn` (tests use it to
#: check that every declared parameter has a widget)
DRAWN: set[str] = set()
STAGED_COLOUR = (1.0, 0.78, 0.25, 1.0)


#: the tooltip's note on a parameter that does not act now
IDLE_NOTE_COLOUR = (0.95, 0.6, 0.2, 1.0)


def reset_drawn() -> None:
    DRAWN.clear()


#: narrowest parameter widget [px] when a group's labels are long
MIN_WIDGET_PX = 110.0


def widget_label(p: Param) -> str:
    """Visible label (short name + unit) with the dotted name as the imgui ID."""
    short = p.name.split(".", 1)[1] if "." in p.name else p.name
    unit = f" [{p.unit}]" if p.unit else ""
    return f"{short}{unit}###{p.name}"


def widget_ref(name: str) -> str:
    """Test-engine reference of a parameter's widget (searched in any window)."""
    return f"**/###{name}"


def _tooltip(p: Param, idle: bool = False) -> None:
    if imgui.is_item_hovered(imgui.HoveredFlags_.for_tooltip):
        imgui.begin_tooltip()
        imgui.push_text_wrap_pos(imgui.get_font_size() * 28.0)
        imgui.text_unformatted(p.name)
        if idle:
            imgui.text_colored(IDLE_NOTE_COLOUR, f"Unused now: acts only with {p.only_text()}")
        imgui.text_unformatted(p.help)
        imgui.text_disabled(f"{p.describe()}; default {p.default}; {'needs Rebuild' if p.rebuild else 'applies live'}")
        imgui.pop_text_wrap_pos()
        imgui.end_tooltip()


def param_widget(p: Param, value: Any, idle: bool = False) -> tuple[bool, Any]:
    """Draw the widget of one declared parameter; returns ``(changed, new_value)``.  ``idle``:
    the parameter does not act under the current values (:meth:`Param.applies`): its tooltip
    says so (it stays editable, to be set before it acts).

    The new value is always valid for the declaration (clamped to [lo, hi]; float sliders
    round to float32, so a value that was not changed is returned unchanged).
    """
    DRAWN.add(p.name)
    label = widget_label(p)
    changed, new = False, value
    if p.kind == "float":
        flags = imgui.SliderFlags_.always_clamp
        if p.log:
            flags |= imgui.SliderFlags_.logarithmic
        changed, v = imgui.slider_float(label, float(value), float(p.lo), float(p.hi), "%.4g", flags)
        if changed:
            new = min(max(float(v), float(p.lo)), float(p.hi))
    elif p.kind == "int":
        changed, v = imgui.slider_int(label, int(value), int(p.lo), int(p.hi), "%d", imgui.SliderFlags_.always_clamp)
        if changed:
            new = min(max(int(v), int(p.lo)), int(p.hi))
    elif p.kind == "bool":
        changed, v = imgui.checkbox(label, bool(value))
        if changed:
            new = bool(v)
    elif p.kind == "choice":
        idx = p.choices.index(value) if value in p.choices else 0
        changed, i = imgui.combo(label, idx, list(p.choices))
        if changed:
            new = p.choices[i]
    else:  # pragma: no cover - the declaration has only these kinds
        imgui.text(f"{p.name}: unsupported kind {p.kind}")
    _tooltip(p, idle)
    if changed and new == value:
        changed = False
    return changed, new


def group_params(group: str) -> list[Param]:
    return [p for p in PARAMS.values() if p.group == group]


def params_panel(params: ParamSet, built: ParamSet | None = None, open_groups: tuple[str, ...] = ("Effects",),
                 groups: list[str] | None = None) -> dict[str, Any]:
    """Collapsing header per group (in declaration order) with every parameter's widget.

    Parameters
    ----------
    params : values shown.
    built : values of the current model; rebuild parameters that differ from it are drawn
        highlighted (staged until Rebuild).
    open_groups : groups open the first time.
    Returns the changed values ``{name: value}`` of this frame (empty when nothing changed).
    """
    changes: dict[str, Any] = {}
    for g in groups or GROUPS:
        plist = group_params(g)
        rebuild = all(p.rebuild for p in plist)
        imgui.set_next_item_open(g in open_groups, imgui.Cond_.once)
        if not imgui.collapsing_header(f"{g}{'  (rebuild)' if rebuild else ''}###group {g}"):
            continue
        # every label of the group whole beside its widget ("evaporation_bottom [kg/(m²·s)]" was
        # cut at the panel's edge); the widgets keep at least MIN_WIDGET_PX
        label_px = max(imgui.calc_text_size(widget_label(p).split("###")[0]).x for p in plist)
        gap = imgui.get_style().item_inner_spacing.x + 2.0
        imgui.push_item_width(max(imgui.get_content_region_avail().x - label_px - gap, MIN_WIDGET_PX))
        for p in plist:
            staged = p.rebuild and built is not None and params[p.name] != built[p.name]
            # dimmed while it does not act (the weather's temperature under the rates drive
            # looked as live as the rates themselves)
            idle = not p.applies(params)
            if staged or idle:
                imgui.push_style_color(imgui.Col_.text, STAGED_COLOUR if staged else imgui.get_style_color_vec4(imgui.Col_.text_disabled))
            ch, v = param_widget(p, params[p.name], idle)
            if staged or idle:
                imgui.pop_style_color()
            if ch:
                changes[p.name] = v
        imgui.pop_item_width()
    return changes
