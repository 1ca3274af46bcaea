"""Paths of the checkout the tests run in (docs, scripts, the validator)."""

from pathlib import Path

#: the repository root
REPO = Path(__file__).resolve().parents[2]
