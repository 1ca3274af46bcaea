"""``leafsim gui`` (and plain ``leafsim``): the interactive application."""

from __future__ import annotations

from leafsim.base.errors import LeafsimError
from leafsim.commands.common import overrides, png_output, species_inputs
from leafsim.config.species import DEFAULT_SPECIES, get_species
from leafsim.sim.run import MAX_RUN_FRAMES


def cmd_gui(args):
    if args.until is not None and args.until.strip().lower() != "dry":
        raise LeafsimError(f"--until {args.until!r}: the window takes --until dry (the 'Dry to end' button)")
    until_dry = args.until is not None
    if args.screenshot and args.frames is None and args.window_frames is None and not until_dry:
        raise LeafsimError("--screenshot needs --frames N, --until dry or --window-frames N")
    if args.frames is not None and not 0 <= args.frames <= MAX_RUN_FRAMES:
        raise LeafsimError(f"--frames {args.frames}: expected a number of frames from 0 to {MAX_RUN_FRAMES}")
    if args.screenshot:  # never over the photo or config the window reads
        sp = get_species(DEFAULT_SPECIES if args.species is None else args.species, args.config)
        png_output("--screenshot", args.screenshot, species_inputs(sp))
    from leafsim.interactive.warmup import MESSAGE, is_warm

    if not is_warm():  # the window shows the compile in its status bar; a terminal sat silent for a minute
        import sys

        print(f"leafsim: {MESSAGE}; the window opens meanwhile and shows its progress", file=sys.stderr, flush=True)
    from leafsim.gui.app import run_app  # imgui and OpenGL load only when the window opens

    return run_app(species=args.species, config=args.config, seed=args.seed, overrides=overrides(args),
                   frames=args.frames, screenshot=args.screenshot, play=args.play,
                   window_frames=args.window_frames, until_dry=until_dry)
