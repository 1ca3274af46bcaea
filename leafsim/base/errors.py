"""The one error type users see: its message is a single line naming what and where."""


class LeafsimError(Exception):
    """Bad input (file, species, key, value). The CLI prints ``leafsim: <message>`` and exits 2."""


class LeafsimWarning(UserWarning):
    """Something a user should check, though it does not stop the work (a leaf's base guessed
    from its shape).  The CLI prints ``leafsim: warning: <message>`` once; a library caller sees
    Python's usual warning."""


class Diverged(LeafsimError):
    """The simulation blew up: NaN/Inf in the state, a kernel's arithmetic error, or the
    watchdog's runaway motion or energy (:mod:`leafsim.sim.watchdog`).  Also importable as
    ``leafsim.sim.run.Diverged``."""
