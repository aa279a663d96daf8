"""Seeded camera paths: smooth and slow, random "many photographers", static rigs and
head-mounted cameras on a walking wearer."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from socialcam._validate import FloatArray, as_float_array, check_seed
from socialcam.camera import Cameras

UP = np.array([0.0, 0.0, 1.0])  # world z is up in every synthetic scene


def intrinsics(width: int = 1280, height: int = 720, fov_deg: float = 60.0) -> FloatArray:
    """A pinhole ``K (3, 3)`` with square pixels, principal point at the image centre
    (OpenCV convention) and horizontal field of view ``fov_deg``."""
    if width <= 0 or height <= 0:
        raise ValueError(f"width/height: must be positive, got {width}x{height}")
    if not 0.0 < fov_deg < 180.0:
        raise ValueError(f"fov_deg: must be in (0, 180), got {fov_deg}")
    f = 0.5 * width / np.tan(np.radians(fov_deg) / 2)
    return np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1.0]])


def look_at(centres: npt.ArrayLike, targets: npt.ArrayLike, up: npt.ArrayLike = UP) -> FloatArray:
    """World→camera rotations ``(F, 3, 3)`` for cameras at ``centres (F, 3)`` looking at
    ``targets (F, 3)`` or ``(3,)``, with image "up" towards ``up`` (OpenCV axes: x right,
    y down, z forward)."""
    C = as_float_array(centres, "centres", (None, 3))
    T = np.broadcast_to(as_float_array(targets, "targets"), C.shape)
    z = T - C
    n = np.linalg.norm(z, axis=1, keepdims=True)
    if (n <= 1e-12).any():
        raise ValueError("targets: a camera centre coincides with its target")
    z = z / n
    up_ = np.broadcast_to(as_float_array(up, "up"), C.shape)
    x = np.cross(-up_, z)  # image y points down (y ≈ -up) and x = y × z points right
    bad = np.linalg.norm(x, axis=1) < 1e-9
    if bad.any():  # looking straight up or down: pick any perpendicular
        x[bad] = np.cross(z[bad], np.array([1.0, 0.0, 0.0]))
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)


def _times(n: int, fps: float, times: npt.ArrayLike | None) -> FloatArray:
    if times is not None:
        return as_float_array(times, "times", (n,))
    if fps <= 0:
        raise ValueError(f"fps: must be positive, got {fps}")
    return np.arange(n) / fps


def smooth_path(
    n: int,
    *,
    seed: int = 0,
    target: npt.ArrayLike = (0.0, 0.0, 1.0),
    radius: float = 6.0,
    height: float = 1.6,
    arc_deg: float = 30.0,
    fps: float = 30.0,
    times: npt.ArrayLike | None = None,
    K: npt.ArrayLike | None = None,
) -> Cameras:
    """One camera moving slowly and smoothly along an arc of ``arc_deg`` degrees around
    ``target``, always looking at it. This is the hard case for trajectory reconstruction
    (low reconstructability, thesis Fig 5.7a)."""
    rng = np.random.default_rng(check_seed(seed))
    tgt = as_float_array(target, "target", (3,))
    a0 = rng.uniform(0, 2 * np.pi)
    a = a0 + np.radians(arc_deg) * np.linspace(0.0, 1.0, n)
    C = np.c_[tgt[0] + radius * np.cos(a), tgt[1] + radius * np.sin(a), np.full(n, height)]
    C[:, 2] += 0.05 * np.sin(np.linspace(0, np.pi, n))
    return Cameras(intrinsics() if K is None else K, look_at(C, tgt), C, _times(n, fps, times))


def random_photographers(
    n: int,
    *,
    seed: int = 0,
    target: npt.ArrayLike = (0.0, 0.0, 1.0),
    radius: tuple[float, float] = (4.0, 9.0),
    height: tuple[float, float] = (1.4, 1.9),
    aim_jitter: float = 0.3,
    fps: float = 30.0,
    times: npt.ArrayLike | None = None,
    K: npt.ArrayLike | None = None,
) -> Cameras:
    """``n`` photos by many independent photographers standing around ``target``: each
    frame is taken from a random place (random azimuth, distance in ``radius``, height in
    ``height``), aimed at ``target`` ± ``aim_jitter`` metres. Their centres form a random,
    non-smooth camera "trajectory" (thesis Sec 5.3.3)."""
    rng = np.random.default_rng(check_seed(seed))
    tgt = as_float_array(target, "target", (3,))
    az = rng.uniform(0, 2 * np.pi, n)
    r = rng.uniform(*radius, n)
    C = np.c_[tgt[0] + r * np.cos(az), tgt[1] + r * np.sin(az), rng.uniform(*height, n)]
    aim = tgt + rng.normal(0.0, aim_jitter, (n, 3))
    return Cameras(intrinsics() if K is None else K, look_at(C, aim), C, _times(n, fps, times))


def ring_rig(
    n_views: int,
    *,
    seed: int = 0,
    target: npt.ArrayLike = (0.0, 0.0, 1.0),
    radius: float = 6.0,
    height: float = 2.0,
    K: npt.ArrayLike | None = None,
) -> Cameras:
    """``n_views`` static cameras spread around ``target`` at roughly equal angles (with a
    seeded random offset and jitter), all looking at it — a multi-view capture rig."""
    if n_views < 1:
        raise ValueError(f"n_views: must be positive, got {n_views}")
    rng = np.random.default_rng(check_seed(seed))
    tgt = as_float_array(target, "target", (3,))
    az = rng.uniform(0, 2 * np.pi) + 2 * np.pi * np.arange(n_views) / n_views
    az += rng.uniform(-0.2, 0.2, n_views)
    r = radius * rng.uniform(0.85, 1.15, n_views)
    C = np.c_[
        tgt[0] + r * np.cos(az), tgt[1] + r * np.sin(az), height + rng.uniform(-0.3, 0.3, n_views)
    ]
    return Cameras(intrinsics() if K is None else K, look_at(C, tgt), C)


def walking_head(
    n: int,
    *,
    seed: int = 0,
    start: npt.ArrayLike = (-4.0, -1.0),
    heading_deg: float = 20.0,
    speed: float = 1.3,
    eye_height: float = 1.65,
    fps: float = 30.0,
) -> tuple[FloatArray, FloatArray]:
    """A walking wearer's head: positions ``(n, 3)`` and unit facing directions ``(n, 3)``,
    with a step-frequency vertical bob (≈ 2 Hz, 3 cm), lateral sway and slow seeded head
    turns of up to ±25°."""
    rng = np.random.default_rng(check_seed(seed))
    t = np.arange(n) / fps
    h = np.radians(heading_deg)
    fwd = np.array([np.cos(h), np.sin(h), 0.0])
    side = np.array([-fwd[1], fwd[0], 0.0])
    s0 = as_float_array(start, "start", (2,))
    step_hz = rng.uniform(1.8, 2.1)
    pos = np.c_[s0[0] + 0 * t, s0[1] + 0 * t, np.full(n, eye_height)]
    pos += np.outer(speed * t, fwd)
    pos += np.outer(0.02 * np.sin(np.pi * step_hz * t), side)
    pos[:, 2] += 0.03 * np.sin(2 * np.pi * step_hz * t)
    ph = rng.uniform(0, 2 * np.pi, 2)
    yaw = np.radians(25.0) * np.sin(2 * np.pi * 0.15 * t + ph[0])
    pitch = np.radians(8.0) * np.sin(2 * np.pi * 0.1 * t + ph[1]) - np.radians(5.0)
    d = np.c_[np.cos(h + yaw) * np.cos(pitch), np.sin(h + yaw) * np.cos(pitch), np.sin(pitch)]
    return pos, d / np.linalg.norm(d, axis=1, keepdims=True)


def head_mounted(
    head_positions: npt.ArrayLike,
    head_directions: npt.ArrayLike,
    *,
    offset: npt.ArrayLike = (0.08, 0.0, 0.05),
    fps: float = 30.0,
    times: npt.ArrayLike | None = None,
    K: npt.ArrayLike | None = None,
) -> Cameras:
    """Cameras rigidly mounted on heads: frame ``f`` sits at ``head_positions[f]`` plus
    ``offset`` given in the head frame (forward, left, up) and looks along
    ``head_directions[f]``."""
    P = as_float_array(head_positions, "head_positions", (None, 3))
    n = P.shape[0]
    D = as_float_array(head_directions, "head_directions", (n, 3))
    nd = np.linalg.norm(D, axis=1, keepdims=True)
    if (nd < 1e-12).any():
        raise ValueError("head_directions: contains a zero vector")
    D = D / nd
    o = as_float_array(offset, "offset", (3,))
    left = np.cross(UP, D)
    left /= np.maximum(np.linalg.norm(left, axis=1, keepdims=True), 1e-12)
    up = np.cross(D, left)
    C = P + o[0] * D + o[1] * left + o[2] * up
    return Cameras(intrinsics() if K is None else K, look_at(C, C + D), C, _times(n, fps, times))
