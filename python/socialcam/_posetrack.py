"""Poses of the frames between keyframes: KLT tracks of map points + PnP (OpenCV).

The mapper poses the keyframes; every other output frame is posed from the map points that
the keyframes before and after it observe, followed frame to frame with pyramidal
Lucas–Kanade (forward from the previous keyframe, backward from the next; with a
forward–backward check), undistorted through the wearer's COLMAP camera, and passed to
``solvePnPRansac`` + Levenberg–Marquardt refinement in normalised coordinates. A frame whose
pose cannot be trusted is reported with a reason and no pose, never guessed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

#: Lucas–Kanade settings: 21-px window, 4 pyramid levels (motion up to ~150 px at 10 fps).
_LK: dict[str, Any] = {
    "winSize": (21, 21),
    "maxLevel": 4,
    "criteria": (3, 30, 0.01),  # cv2.TERM_CRITERIA_EPS | COUNT, 30 iterations, 0.01 px
}

#: the same between the frames of a video at its own rate (``sfm.pose_segment``): the
#: motion between two 30-fps frames is a third of that at 10 fps, and an 11-px window
#: tracked the calibration segments of rendered scenes as well (seed 1: the same 723
#: frames posed, Eq 3.1 the same to 0.01° and 0.1 cm) at 54 % of the CPU time. The
#: pyramid stays: 2 levels lost a third of the frames of fast head turns.
_LK_VIDEO_RATE: dict[str, Any] = {**_LK, "winSize": (11, 11)}


@dataclass
class FramePose:
    """Pose of one frame, or the reason it has none."""

    R: FloatArray | None  # (3, 3) world→camera (map frame)
    t: FloatArray | None  # (3,) so that x_cam = R X + t
    rms: float  # reprojection RMS of the inliers, pixels (NaN if none)
    n_inliers: int
    reason: str  # "" when posed


def undistort_to_normalised(camera: Any, px: FloatArray) -> FloatArray:
    """Raw OpenCV-convention pixels ``(N, 2)`` → normalised pinhole coordinates ``(N, 2)``
    through the COLMAP camera model (pixel centre shift +0.5 applied here, once)."""
    if len(px) == 0:
        return np.zeros((0, 2))
    n = np.asarray(camera.cam_from_img(np.ascontiguousarray(px + 0.5)), dtype=np.float64)
    if n.shape[1] == 3:
        n = n[:, :2] / n[:, 2:3]
    return n


def follow(
    prev: npt.NDArray[np.uint8],
    cur: npt.NDArray[np.uint8],
    pts: npt.NDArray[np.float32],
    lk: dict[str, Any],
    fb_px: float,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_]]:
    """One pyramidal Lucas–Kanade step of ``pts (N, 1, 2)`` from ``prev`` to ``cur``: the
    new positions and which of them to keep (found both ways, back within ``fb_px``
    pixels of where they started, inside ``cur``)."""
    import cv2

    p1, st1, _ = cv2.calcOpticalFlowPyrLK(prev, cur, pts, None, **lk)  # type: ignore[call-overload]
    p0b, st2, _ = cv2.calcOpticalFlowPyrLK(cur, prev, p1, None, **lk)  # type: ignore[call-overload]
    fb = np.linalg.norm((p0b - pts).reshape(-1, 2), axis=1)
    h, w = cur.shape[:2]
    q = p1.reshape(-1, 2)
    ok = (
        (st1.ravel() == 1)
        & (st2.ravel() == 1)
        & (fb < fb_px)
        & (q[:, 0] >= 0)
        & (q[:, 1] >= 0)
        & (q[:, 0] <= w - 1)
        & (q[:, 1] <= h - 1)
    )
    return p1, ok


def track(
    start: npt.NDArray[np.uint8],
    px: FloatArray,
    X: FloatArray,
    frames: list[npt.NDArray[np.uint8]],
    *,
    fb_px: float,
    lk: dict[str, Any] | None = None,
) -> list[tuple[FloatArray, FloatArray]]:
    """Follows the pixels ``px (N, 2)`` of map points ``X (N, 3)`` from frame ``start``
    through grey ``frames`` in order (pyramidal Lucas–Kanade with a forward–backward check of ``fb_px`` pixels); returns, per frame, the surviving pixels
    and their map points. ``lk``: Lucas–Kanade settings (default ``_LK``)."""

    out: list[tuple[FloatArray, FloatArray]] = []
    prev = start
    pts = np.ascontiguousarray(px, dtype=np.float32).reshape(-1, 1, 2)
    Xs = np.asarray(X, dtype=np.float64)
    for cur in frames:
        if len(pts) == 0 or cur.shape != prev.shape:
            pts, Xs = np.zeros((0, 1, 2), np.float32), np.zeros((0, 3))
            out.append((np.zeros((0, 2)), Xs))
            prev = cur
            continue
        p1, ok = follow(prev, cur, pts, _LK if lk is None else lk, fb_px)
        pts, Xs = np.ascontiguousarray(p1[ok]), Xs[ok]
        out.append((pts.reshape(-1, 2).astype(np.float64), Xs))
        prev = cur
    return out


def solve_pnp(
    camera: Any,
    px: FloatArray,
    X: FloatArray,
    guess: tuple[FloatArray, FloatArray] | None,
    *,
    min_inliers: int,
    max_rms: float,
    ransac_px: float,
    seed: int,
) -> FramePose:
    """Pose from raw pixels ``px (N, 2)`` of map points ``X (N, 3)``: undistortion through
    the COLMAP ``camera``, RANSAC PnP (threshold ``ransac_px``) from the ``guess``
    ``(R, t)``, Levenberg–Marquardt on the inliers. ``reason`` says why a pose is refused
    (fewer than ``min_inliers`` inliers, RMS above ``max_rms`` pixels)."""
    import cv2

    n = len(px)
    if n < min_inliers:
        return FramePose(None, None, float("nan"), 0, f"only {n} tracked map points")
    focal = float(np.mean(np.asarray(camera.calibration_matrix())[[0, 1], [0, 1]]))
    xn = undistort_to_normalised(camera, px)
    cv2.setRNGSeed(seed)
    eye = np.eye(3)
    if guess is not None:
        rvec0, tvec0 = cv2.Rodrigues(guess[0])[0], guess[1].reshape(3, 1).copy()
    else:
        rvec0, tvec0 = None, None
    ok, rvec, tvec, inl = cv2.solvePnPRansac(
        X,
        xn,
        eye,
        None,
        rvec=rvec0,
        tvec=tvec0,
        useExtrinsicGuess=guess is not None,
        iterationsCount=100,
        reprojectionError=ransac_px / focal,
        confidence=0.999,
        flags=cv2.SOLVEPNP_ITERATIVE if guess is not None else cv2.SOLVEPNP_EPNP,
    )
    if not ok or inl is None or len(inl) < min_inliers:
        k = 0 if inl is None else len(inl)
        return FramePose(None, None, float("nan"), k, f"PnP found only {k} inliers")
    idx = inl.ravel()
    rvec, tvec = cv2.solvePnPRefineLM(X[idx], xn[idx], eye, None, rvec, tvec)
    proj, _ = cv2.projectPoints(X[idx], rvec, tvec, eye, None)
    res = (proj.reshape(-1, 2) - xn[idx]) * focal
    rms = float(np.sqrt((res**2).sum(axis=1).mean()))
    if rms > max_rms:
        return FramePose(None, None, rms, len(idx), f"reprojection RMS {rms:.2f} px")
    R = np.asarray(cv2.Rodrigues(rvec)[0], dtype=np.float64)
    return FramePose(R, np.asarray(tvec, dtype=np.float64).ravel(), rms, len(idx), "")


class KeyframeSelector:
    """Chooses keyframes from the image motion, as visual odometry does.

    Corners found in the last keyframe (half resolution, Shi–Tomasi) are followed frame to
    frame with pyramidal Lucas–Kanade and a forward–backward check; a frame becomes a
    keyframe when fewer than ``min_overlap`` of them survive (the view has moved on: a
    head turn, a cut, a corrupt frame) or ``max_step`` frames after the last keyframe. Fast
    head turns thus get dense keyframes, which SIFT can register, and the frames between two
    keyframes always share most of their view with both — what KLT + PnP needs.
    ``min_overlap = 0`` gives a keyframe every ``max_step`` frames.
    """

    #: corners per keyframe, their minimum spacing (half-resolution pixels)
    CORNERS, SPACING = 300, 6
    _LK: ClassVar[dict[str, Any]] = {"winSize": (15, 15), "maxLevel": 3, "criteria": (3, 20, 0.03)}

    def __init__(self, min_overlap: float, max_step: int) -> None:
        self.min_overlap, self.max_step = float(min_overlap), int(max_step)
        self._prev: npt.NDArray[np.uint8] | None = None
        self._pts = np.zeros((0, 1, 2), np.float32)
        self._n0 = 0
        self._since = 0

    def __call__(self, gray: npt.NDArray[np.uint8]) -> bool:
        """Whether this frame (grey, full resolution; frames in order) is a keyframe."""
        import cv2

        small = np.asarray(cv2.pyrDown(gray), dtype=np.uint8)
        new = (
            self._prev is None
            or self._since + 1 >= self.max_step
            or small.shape != self._prev.shape
        )
        if not new and self.min_overlap > 0 and self._prev is not None:
            if len(self._pts):
                p1, ok = follow(self._prev, small, self._pts, self._LK, 0.5)
                self._pts = np.ascontiguousarray(p1[ok])
            new = len(self._pts) < self.min_overlap * self._n0
        self._prev = small
        if new:
            c = cv2.goodFeaturesToTrack(small, self.CORNERS, 0.01, self.SPACING)
            self._pts = np.zeros((0, 1, 2), np.float32) if c is None else c.astype(np.float32)
            self._n0 = len(self._pts)
            self._since = 0
        else:
            self._since += 1
        return new
