"""Turning ground truth into observations: projection, pixel noise, missing data."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from socialcam._validate import FloatArray, as_float_array, check_seed
from socialcam.camera import Cameras


@dataclass(frozen=True)
class Observations:
    """Pixel observations beside the ground truth that made them.

    Attributes
    ----------
    x : ndarray, shape (N, F, 2)
        Noisy pixels; NaN rows are missing (dropped, behind the camera, or off the image).
    x_clean : ndarray, shape (N, F, 2)
        Noise-free projections (NaN only behind the camera).
    points : ndarray, shape (N, F, 3) or (N, 3)
        The ground-truth 3D points.
    noise_px : float
        Standard deviation of the Gaussian pixel noise added to each coordinate.
    """

    x: FloatArray
    x_clean: FloatArray
    points: FloatArray
    noise_px: float

    @property
    def missing(self) -> npt.NDArray[np.bool_]:
        """``(N, F)`` true where the observation is missing."""
        return np.asarray(np.isnan(self.x).any(axis=-1), dtype=bool)

    def to_dict(self) -> dict[str, Any]:
        return {"x": self.x.tolist(), "points": self.points.tolist(), "noise_px": self.noise_px}


def observe(
    points: npt.ArrayLike,
    cameras: Cameras,
    *,
    noise_px: float = 0.0,
    missing: float = 0.0,
    image_size: tuple[int, int] | None = None,
    seed: int = 0,
) -> Observations:
    """Projects ground truth into cameras and corrupts it.

    Parameters
    ----------
    points : array_like, shape (N, 3) or (N, F, 3)
        Static points, seen by every camera (``F = len(cameras)`` views), or moving points,
        seen at frame ``f`` by camera ``f``.
    cameras : Cameras
    noise_px : float
        Gaussian noise (pixels, per coordinate).
    missing : float
        Fraction of observations dropped uniformly at random, in ``[0, 1)``.
    image_size : (width, height), optional
        If given, projections outside the image are missing too.
    seed : int

    Returns
    -------
    Observations
        ``x`` has shape ``(N, F, 2)``.
    """
    rng = np.random.default_rng(check_seed(seed))
    X = as_float_array(points, "points")
    if noise_px < 0 or not np.isfinite(noise_px):
        raise ValueError(f"noise_px: must be a non-negative number, got {noise_px}")
    if not 0.0 <= missing < 1.0:
        raise ValueError(f"missing: must be in [0, 1), got {missing}")
    f = len(cameras)
    if X.ndim == 2 and X.shape[1] == 3:
        px, depth = cameras.project(X, return_depth=True)
        clean = np.transpose(px, (1, 0, 2)).copy()
        clean[depth.T <= 0] = np.nan
    elif X.ndim == 3 and X.shape[1:] == (f, 3):
        clean = cameras.project_trajectory(X)
    else:
        raise ValueError(f"points: expected shape (N, 3) or (N, {f}, 3), got {X.shape}")
    x = clean + rng.normal(0.0, noise_px, clean.shape) if noise_px > 0 else clean.copy()
    drop = rng.random(x.shape[:2]) < missing
    if image_size is not None:
        w, h = image_size
        off = (
            (clean[..., 0] < -0.5)
            | (clean[..., 0] > w - 0.5)
            | (clean[..., 1] < -0.5)
            | (clean[..., 1] > h - 0.5)
        )
        drop |= off
    x[drop] = np.nan
    return Observations(x=x, x_clean=clean, points=X, noise_px=float(noise_px))
