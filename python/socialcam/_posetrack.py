"""Poses of the frames between keyframes: KLT tracks of map points + PnP (OpenCV).

The mapper poses the keyframes; every other output frame is posed from the map points that
the previous keyframe observes, followed frame to frame with pyramidal Lucas–Kanade (with a
forward–backward check), undistorted through the wearer's COLMAP camera, and passed to
``solvePnPRansac`` + Levenberg–Marquardt refinement in normalised coordinates. A frame whose
pose cannot be trusted is reported with a reason and no pose, never guessed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

#: Lucas–Kanade settings: 21-px window, 4 pyramid levels (motion up to ~150 px at 10 fps).
_LK = {
    "winSize": (21, 21),
    "maxLevel": 4,
    "criteria": (3, 30, 0.01),  # cv2.TERM_CRITERIA_EPS | COUNT, 30 iterations, 0.01 px
}


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


class KeyframeTracker:
    """Follows the map points of the last keyframe through the frames of one video.

    Parameters
    ----------
    camera : pycolmap.Camera of this wearer (intrinsics and distortion of the raw frames).
    min_inliers : fewest PnP inliers for a trusted pose.
    max_rms : largest inlier reprojection RMS (pixels) for a trusted pose.
    ransac_px : PnP RANSAC inlier threshold in pixels.
    fb_px : largest forward–backward KLT disagreement (pixels) for a track to survive.
    seed : seeds OpenCV's RANSAC.
    """

    def __init__(
        self,
        camera: Any,
        *,
        min_inliers: int,
        max_rms: float,
        ransac_px: float,
        fb_px: float,
        seed: int,
    ) -> None:
        self.camera = camera
        self.focal = float(np.mean(camera.calibration_matrix()[[0, 1], [0, 1]]))
        self.min_inliers = min_inliers
        self.max_rms = max_rms
        self.ransac_px = ransac_px
        self.fb_px = fb_px
        self.seed = seed
        self.prev: npt.NDArray[np.uint8] | None = None
        self.pts = np.zeros((0, 2), np.float32)  # tracked raw pixels (OpenCV convention)
        self.X = np.zeros((0, 3))  # their map points
        self.last_R: FloatArray | None = None
        self.last_t: FloatArray | None = None

    def reset(
        self,
        gray: npt.NDArray[np.uint8],
        px: FloatArray,
        X: FloatArray,
        R: FloatArray,
        t: FloatArray,
    ) -> None:
        """Starts new tracks at a registered keyframe: its observations ``px (N, 2)`` of map
        points ``X (N, 3)`` and its mapper pose."""
        self.prev = gray
        self.pts = np.ascontiguousarray(px, dtype=np.float32)
        self.X = np.asarray(X, dtype=np.float64)
        self.last_R, self.last_t = R, t

    def advance(self, gray: npt.NDArray[np.uint8]) -> None:
        """Moves the tracks into the next frame (no pose)."""
        import cv2

        if self.prev is None or len(self.pts) == 0 or gray.shape != self.prev.shape:
            self.pts = np.zeros((0, 2), np.float32)
            self.X = np.zeros((0, 3))
            self.prev = gray
            return
        p0 = self.pts.reshape(-1, 1, 2)
        p1, st1, _ = cv2.calcOpticalFlowPyrLK(self.prev, gray, p0, None, **_LK)
        p0b, st2, _ = cv2.calcOpticalFlowPyrLK(gray, self.prev, p1, None, **_LK)
        fb = np.linalg.norm((p0b - p0).reshape(-1, 2), axis=1)
        h, w = gray.shape
        q = p1.reshape(-1, 2)
        ok = (
            (st1.ravel() == 1)
            & (st2.ravel() == 1)
            & (fb < self.fb_px)
            & (q[:, 0] >= 0)
            & (q[:, 1] >= 0)
            & (q[:, 0] <= w - 1)
            & (q[:, 1] <= h - 1)
        )
        self.pts = np.ascontiguousarray(q[ok])
        self.X = self.X[ok]
        self.prev = gray

    def pose(self) -> FramePose:
        """PnP on the current tracks; ``reason`` says why a pose is refused."""
        import cv2

        n = len(self.pts)
        if n < self.min_inliers:
            return FramePose(None, None, float("nan"), 0, f"only {n} tracked map points")
        xn = undistort_to_normalised(self.camera, self.pts.astype(np.float64))
        cv2.setRNGSeed(self.seed)
        eye = np.eye(3)
        guess = self.last_R is not None and self.last_t is not None
        rvec0 = cv2.Rodrigues(self.last_R)[0] if guess else None
        tvec0 = self.last_t.reshape(3, 1).copy() if guess else None  # type: ignore[union-attr]
        ok, rvec, tvec, inl = cv2.solvePnPRansac(
            self.X,
            xn,
            eye,
            None,
            rvec=rvec0,
            tvec=tvec0,
            useExtrinsicGuess=bool(guess),
            iterationsCount=200,
            reprojectionError=self.ransac_px / self.focal,
            confidence=0.999,
            flags=cv2.SOLVEPNP_EPNP if not guess else cv2.SOLVEPNP_ITERATIVE,
        )
        if not ok or inl is None or len(inl) < self.min_inliers:
            k = 0 if inl is None else len(inl)
            return FramePose(None, None, float("nan"), k, f"PnP found only {k} inliers")
        idx = inl.ravel()
        rvec, tvec = cv2.solvePnPRefineLM(self.X[idx], xn[idx], eye, None, rvec, tvec)
        proj, _ = cv2.projectPoints(self.X[idx], rvec, tvec, eye, None)
        res = (proj.reshape(-1, 2) - xn[idx]) * self.focal
        rms = float(np.sqrt((res**2).sum(axis=1).mean()))
        R = cv2.Rodrigues(rvec)[0]
        t = tvec.ravel().astype(np.float64)
        # Drop tracks that PnP rejected: they are drifting or sit on a wrong map point.
        keep = np.zeros(n, bool)
        keep[idx] = True
        self.pts, self.X = self.pts[keep], self.X[keep]
        if rms > self.max_rms:
            return FramePose(None, None, rms, len(idx), f"reprojection RMS {rms:.2f} px")
        self.last_R, self.last_t = R, t
        return FramePose(R, t, rms, len(idx), "")
