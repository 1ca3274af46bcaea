"""The one error type users see: its message is a single line naming what and where."""


class LeafsimError(Exception):
    """Bad input (file, species, key, value). The CLI prints ``leafsim: <message>`` and exits 2."""


class Diverged(LeafsimError):
    """The simulation blew up: NaN/Inf in the state, a kernel's arithmetic error, or the
    watchdog's runaway motion or energy (:mod:`leafsim.sim.watchdog`).  Also importable as
    ``leafsim.sim.run.Diverged``."""
