"""The one error type users see: its message is a single line naming what and where."""


class LeafsimError(Exception):
    """Bad input (file, species, key, value). The CLI prints ``leafsim: <message>`` and exits 2."""
