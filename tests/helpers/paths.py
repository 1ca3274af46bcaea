"""Paths of the checkout the tests run in (docs, scripts, the validator), and how long a test
may wait on a subprocess before it counts as hung."""

from pathlib import Path

#: the repository root
REPO = Path(__file__).resolve().parents[2]
#: a subprocess that has not finished after this long is hung (a bound against hangs, never a
#: speed requirement: the suite must pass on a machine kept busy by other work)
HANG_S = 1800.0
