"""Seeded scene simulator: cameras, moving points, people and their gaze, with the ground
truth beside the observations. Every function takes ``seed``; same seed, same scene.

Building blocks
---------------
- cameras: :func:`intrinsics`, :func:`look_at`, :func:`smooth_path`,
  :func:`random_photographers`, :func:`ring_rig`, :func:`walking_head`, :func:`head_mounted`
- points: :func:`random_points`, :func:`smooth_trajectories`
- observations: :func:`observe` → :class:`Observations` (pixel noise, missing data)
- people: :func:`wander`, :func:`looking_at` → :class:`People` (gaze model of Sec 3.1)
- a ready scene: :func:`multiview_scene`
- gaze calibration: :func:`fixation_segment` → :class:`FixationSegment` (Sec 3.2.1)
- social scenes with known joint attention: :func:`mocap_replica`, :func:`meeting`,
  :func:`party` → :class:`SocialScene`; :func:`mafia` → :class:`MafiaScene` (with
  inattentive players)
"""

from __future__ import annotations

from dataclasses import dataclass

from socialcam.camera import Cameras
from socialcam.synth.calibration import FixationSegment, fixation_segment
from socialcam.synth.cameras import (
    head_mounted,
    intrinsics,
    look_at,
    random_photographers,
    ring_rig,
    smooth_path,
    walking_head,
)
from socialcam.synth.mafia import MafiaScene, mafia
from socialcam.synth.observe import Observations, observe
from socialcam.synth.people import People, looking_at, primary_from_true, wander
from socialcam.synth.points import random_points, smooth_trajectories
from socialcam.synth.social import (
    SocialScene,
    marker_check,
    marker_check_family,
    meeting,
    mocap_replica,
    party,
)


@dataclass(frozen=True)
class MultiviewScene:
    """Static points seen by a rig of cameras: ``cameras`` (V views) and ``obs`` whose
    ``x`` is ``(N, V, 2)`` and ``points`` ``(N, 3)``."""

    cameras: Cameras
    obs: Observations


def multiview_scene(
    n_points: int = 1000,
    n_views: int = 4,
    *,
    noise_px: float = 1.0,
    missing: float = 0.0,
    seed: int = 0,
) -> MultiviewScene:
    """Random static points in a 2 m cube seen by a ring of ``n_views`` cameras 6 m away."""
    cams = ring_rig(n_views, seed=seed)
    pts = random_points(n_points, seed=seed + 1)
    obs = observe(pts, cams, noise_px=noise_px, missing=missing, seed=seed + 2)
    return MultiviewScene(cameras=cams, obs=obs)


__all__ = [
    "FixationSegment",
    "MafiaScene",
    "MultiviewScene",
    "Observations",
    "People",
    # social scenes (issue 5)
    "SocialScene",
    "fixation_segment",
    "head_mounted",
    "intrinsics",
    "look_at",
    "looking_at",
    "mafia",
    "marker_check",
    "marker_check_family",
    "meeting",
    "mocap_replica",
    "multiview_scene",
    "observe",
    "party",
    "primary_from_true",
    "random_photographers",
    "random_points",
    "ring_rig",
    "smooth_path",
    "smooth_trajectories",
    "walking_head",
    "wander",
]
