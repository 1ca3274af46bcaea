"""leafsim — procedural leaves and a physically based simulation of how they age."""

from pathlib import Path

__version__ = "0.1.0"

#: Repository root (configs/, images/, shaders/ live here).
ROOT = Path(__file__).resolve().parent.parent
