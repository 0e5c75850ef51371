"""The embedded sample clip (real CMU motion capture, see data/ACKNOWLEDGEMENT.md)."""
from __future__ import annotations

from importlib import resources
from pathlib import Path

#: File name of the default sample: CMU subject 09, trial 01, a steady run at about 3.5 m/s.
SAMPLE_RUN = "09_01.bvh"


def sample_path(name: str = SAMPLE_RUN) -> Path:
    """Path of an embedded sample clip."""
    return Path(str(resources.files("froude") / "data" / name))
