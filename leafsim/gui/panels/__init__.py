"""The window's panels, each an object holding the app it draws for (composition, not a
mixin): :class:`~leafsim.gui.panels.controls.ControlsPanel` (left),
:class:`~leafsim.gui.panels.stats.StatsPanel` (right), :class:`~leafsim.gui.panels.status_bar.StatusBar`
(bottom) and :class:`~leafsim.gui.panels.view.ViewOverlay` (over the 3-D view: photo compare,
colour bar, caption, mouse)."""
