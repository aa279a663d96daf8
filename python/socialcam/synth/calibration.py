"""Range-of-motion segments for ego-motion gaze calibration (thesis Sec 3.2.1), with truth."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from socialcam._validate import FloatArray, as_float_array, check_float, check_int, check_seed
from socialcam.camera import Cameras
from socialcam.synth.cameras import intrinsics
from socialcam.synth.people import primary_from_true


@dataclass(frozen=True)
class FixationSegment:
    """A wearer fixating ``target`` while moving: the head camera poses ``cameras`` and the
    truth of the gaze model in the camera frame (``eye`` offset, primary ``direction``,
    spread ``h``) and the eye centres ``eyes (F, 3)`` in the world."""

    cameras: Cameras
    eye: FloatArray
    direction: FloatArray
    h: float
    target: FloatArray
    eyes: FloatArray

    @property
    def eye_normal(self) -> FloatArray:
        """The observable part of the eye offset, normal to the gaze direction."""
        e, d = self.eye, self.direction
        return e - float(e @ d) * d


def fixation_segment(
    n_frames: int = 300,
    *,
    h: float = 0.01,
    eye: npt.ArrayLike = (0.01, 0.08, -0.06),
    direction: npt.ArrayLike = (0.05, 0.08, 1.0),
    target: npt.ArrayLike = (0.2, -0.1, 1.2),
    sway: float = 0.3,
    depth_swing: float = 0.4,
    roll_deg: float = 15.0,
    fps: float = 30.0,
    seed: int = 0,
) -> FixationSegment:
    """A range-of-motion segment: the eye moves ``±sway`` m side to side (and half of it up
    and down) and ``±depth_swing`` m back and forth around the origin while fixating
    ``target``; the head rolls up to ``±roll_deg``; the primary gaze ray misses the target by
    the Sec 3.1 deviation ``m ~ N(0, h² I₂)``. ``eye`` and ``direction`` are the camera-frame
    truth (camera looks along +z, x right, y down)."""
    n = check_int(n_frames, "n_frames", min=5, max=10_000_000)
    h = check_float(h, "h", min=0.0)
    sway = check_float(sway, "sway", min=0.0)
    depth_swing = check_float(depth_swing, "depth_swing", min=0.0)
    roll = np.radians(check_float(roll_deg, "roll_deg", min=0.0, max=90.0))
    fps = check_float(fps, "fps", min=0.0, min_exclusive=True)
    rng = np.random.default_rng(check_seed(seed))
    e = as_float_array(eye, "eye", (3,))
    d = as_float_array(direction, "direction", (3,))
    if np.linalg.norm(d) == 0:
        raise ValueError("direction: must be non-zero")
    d = d / np.linalg.norm(d)
    y = as_float_array(target, "target", (3,))
    t = np.arange(n) / n * 2.0 * np.pi
    eyes = np.stack(
        [sway * np.sin(t), 0.5 * sway * np.sin(2 * t), -depth_swing * np.cos(2 * t)], axis=1
    )
    to_target = y - eyes
    if np.any(np.linalg.norm(to_target, axis=1) < 1e-6):
        raise ValueError("target: the eye passes through the target")
    u = to_target / np.linalg.norm(to_target, axis=1, keepdims=True)
    w = primary_from_true(u, h, rng) if h > 0 else u
    # scipy is imported here, not at the top: `import socialcam` stays light.
    from scipy.spatial.transform import Rotation  # type: ignore[import-untyped]

    R = np.empty((n, 3, 3))
    C = np.empty((n, 3))
    for i in range(n):
        # World-from-camera rotation M with M d = w_i, then a roll about w_i.
        align, _ = Rotation.align_vectors(w[i][None], d[None])
        spin = Rotation.from_rotvec(w[i] * rng.uniform(-roll, roll))
        M = (spin * align).as_matrix()
        R[i] = M.T
        C[i] = eyes[i] - M @ e
    cams = Cameras(intrinsics(), R, C, times=np.arange(n) / fps)
    return FixationSegment(cameras=cams, eye=e, direction=d, h=h, target=y, eyes=eyes)
