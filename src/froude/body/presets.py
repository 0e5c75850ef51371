"""Where the shipped character presets live, and their names (no NumPy: the CLI lists them in --help)."""
from __future__ import annotations

from pathlib import Path

PRESET_DIR = Path(__file__).parents[1] / "data" / "characters"


def list_presets() -> list[str]:
    """Names of the shipped presets."""
    return sorted(p.stem for p in PRESET_DIR.glob("*.yaml"))


#: What froude supports for a character, checked wherever a character is described (CLI options, YAML
#: files, the Python API): stature [m], mass [kg], and the bone length factors of a body part.
HEIGHT_RANGE_M = (0.3, 10.0)
MASS_RANGE_KG = (1.0, 5000.0)
PART_SCALE_RANGE = (0.2, 5.0)
