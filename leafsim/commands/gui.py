"""``leafsim gui`` (and plain ``leafsim``): the interactive application."""

from __future__ import annotations

from leafsim.base.errors import LeafsimError
from leafsim.commands.common import overrides, png_output


def cmd_gui(args):
    if args.until is not None and args.until.strip().lower() != "dry":
        raise LeafsimError(f"--until {args.until!r}: the window takes --until dry (the 'Dry to end' button)")
    until_dry = args.until is not None
    if args.screenshot and args.frames is None and args.window_frames is None and not until_dry:
        raise LeafsimError("--screenshot needs --frames N, --until dry or --window-frames N")
    png_output("--screenshot", args.screenshot)
    from leafsim.gui.app import run_app  # imgui and OpenGL load only when the window opens

    return run_app(species=args.species, config=args.config, seed=args.seed, overrides=overrides(args),
                   frames=args.frames, screenshot=args.screenshot, play=args.play,
                   window_frames=args.window_frames, until_dry=until_dry)
