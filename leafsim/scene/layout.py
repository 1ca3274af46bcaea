"""Where a scene writes each leaf: ``OUT/leaves/NAME/``."""

from __future__ import annotations

from pathlib import Path


def leaf_dir(out: Path, name: str) -> Path:
    return Path(out) / "leaves" / name
