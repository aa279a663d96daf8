"""Small sample data shipped with socialcam (provenance in ``README.md`` beside it)."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path


def sample_bvh() -> Path:
    """Path of a 2 s excerpt of real human walking (CMU subject 131, 120 Hz, BVH)."""
    return Path(str(files(__name__) / "cmu_131_01_walk240.bvh"))
