"""Ego-motion gaze: calibrate the primary gaze ray of a camera wearer (thesis Sec 3.1–3.2.1).

A head-mounted camera is rigid with the head but its centre is not the centre of the eyes,
and its optical axis is not the primary gaze direction. During a *range-of-motion* segment
the wearer fixates one still point while moving the head (side to side *and* back and forth);
Eq 3.1 then recovers the eye centre ``p`` and primary direction ``v`` in the camera frame and
the eye-in-head spread ``h``. :meth:`GazeCalibration.rays` turns every camera pose of the
wearer into a primary gaze ray in the world.

What the data determine: sliding the eye centre along its own gaze direction leaves every
ray unchanged, so only the part of ``p`` normal to ``v`` is observable. The reported ``p`` is
the point of the primary ray closest to the camera centre (``p · v = 0``); compare offsets with
``p_true − (p_true · v) v``. The offset and the direction are told apart by the change of
fixation depth during the segment: a segment without back-and-forth motion gives large
``p_std``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from socialcam import _core
from socialcam._validate import FloatArray, check_float, check_int, check_rounding, readonly
from socialcam.camera import Cameras
from socialcam.errors import DegenerateError

__all__ = ["DEFAULT_H", "GazeCalibration", "calibrate_gaze"]

#: Eye-in-head spread assumed without a calibration segment (≈ 3°; Sec 3.1 reports the
#: eye orientation deviating "by a small degree" from the head while fixating).
DEFAULT_H = 0.05

#: Largest ``lambda_axis`` (1/m² per frame; a prior of σ = 1 mm on the eye's position along
#: its ray). Stronger priors stiffen the solve until Levenberg–Marquardt stalls (1e7: the
#: iteration cap; 1e300: no step at all, the start returned as converged).
MAX_LAMBDA_AXIS = 1e6

#: Least head motion (m, the centres' largest range along an axis) a calibration segment
#: needs. The eye's offset is seen only through the head's motion, which the thesis takes
#: side to side and back and forth by decimetres; at a micrometre the start came back.
MIN_HEAD_MOTION = 1e-3


@dataclass(frozen=True)
class GazeCalibration:
    """The primary gaze ray of one wearer in its camera frame (Eq 3.1), with uncertainty.

    Attributes
    ----------
    p : (3,) eye centre in the camera frame, metres (the point of the ray closest to the
        camera centre).
    v : (3,) unit primary gaze direction in the camera frame.
    h : eye-in-head spread: std of each coordinate of the deviation on the plane at unit
        distance (Sec 3.1), radians for small angles.
    y : (3,) the fixated point in the world frame, metres (``NaN`` without calibration).
    p_std, y_std : (3,) standard errors, metres.
    v_std : standard error of the direction, radians.
    h_rel_std : relative standard error of ``h``.
    residuals : (F,) deviation of each frame of the segment at the solution, radians.
    iterations, converged : Levenberg–Marquardt diagnostics.
    calibrated : False for the optical-axis default (:meth:`optical_axis`).
    """

    p: FloatArray
    v: FloatArray
    h: float
    y: FloatArray
    p_std: FloatArray
    v_std: float
    y_std: FloatArray
    h_rel_std: float
    residuals: FloatArray
    iterations: int
    converged: bool
    calibrated: bool = True

    @classmethod
    def optical_axis(cls, h: float = DEFAULT_H) -> GazeCalibration:
        """No calibration: the gaze ray is the camera's optical axis with spread ``h``."""
        h = check_float(h, "h", min=0.0, min_exclusive=True)
        nan3 = readonly(np.full(3, np.nan))
        return cls(
            p=readonly(np.zeros(3)),
            v=readonly(np.array([0.0, 0.0, 1.0])),
            h=h,
            y=nan3,
            p_std=nan3,
            v_std=float("nan"),
            y_std=nan3,
            h_rel_std=float("nan"),
            residuals=readonly(np.zeros(0)),
            iterations=0,
            converged=True,
            calibrated=False,
        )

    @property
    def v_error_bound_deg(self) -> float:
        """Three standard errors of ``v``, in degrees (for reports)."""
        return float(np.degrees(3.0 * self.v_std))

    def rays(self, cameras: Cameras) -> tuple[FloatArray, FloatArray, FloatArray]:
        """World primary gaze rays of the wearer at each camera pose.

        Returns ``p (F, 3)`` eye centres (metres), ``v (F, 3)`` unit directions and
        ``h (F,)`` spreads: ``p_i = R_iᵀ p + C_i``, ``v_i = R_iᵀ v``.
        """
        if not isinstance(cameras, Cameras):
            raise ValueError(f"cameras: expected a socialcam.Cameras, got {type(cameras).__name__}")
        p, v = _core.gaze_rays(cameras.R, cameras.C, self.p, self.v)
        h = np.full(len(cameras), self.h)
        return readonly(p), readonly(v), readonly(h)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> GazeCalibration:
        """The inverse of :meth:`to_dict` (``None`` entries of arrays read as NaN)."""
        if not isinstance(d, dict):
            raise ValueError(f"d: expected a dict from to_dict(), got {type(d).__name__}")
        missing = [k for k in cls.__dataclass_fields__ if k not in d]
        if missing:
            raise ValueError(f"d: not a GazeCalibration record, missing {missing}")
        kw: dict[str, Any] = {}
        for k in cls.__dataclass_fields__:
            val = d[k]
            if isinstance(val, list):
                kw[k] = readonly(np.array([np.nan if x is None else x for x in val], float))
            elif k in ("h", "v_std", "h_rel_std"):
                kw[k] = float("nan") if val is None else float(val)
            else:
                kw[k] = val
        return cls(**kw)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for k in self.__dataclass_fields__:
            val = getattr(self, k)
            out[k] = val.tolist() if isinstance(val, np.ndarray) else val
        return out


def calibrate_gaze(
    cameras: Cameras,
    *,
    lambda_c: float = 1e-4,
    lambda_axis: float = 100.0,
    max_iter: int = 200,
    tol: float = 1e-12,
) -> GazeCalibration:
    """Calibrates a wearer's primary gaze ray from a fixation segment (Eq 3.1).

    Parameters
    ----------
    cameras : the wearer's camera poses during the segment (at least 5 frames) while the
        wearer fixates one still point and moves the head side to side and back and forth.
    lambda_c : λ_c of Eq 3.1, weight of ``‖p‖²`` per frame (1/m²).
    lambda_axis : weight per frame of ``(p · v)²``, which fixes the unobservable position of
        the eye along its own ray (module docs); at most ``MAX_LAMBDA_AXIS``.
    max_iter, tol : Levenberg–Marquardt cap and relative cost tolerance.

    Raises
    ------
    ValueError
        Fewer than 5 frames, non-finite poses, bad options; centres so far from the origin
        that float64 rounds them by more than a thousandth of the head's motion.
    socialcam.DegenerateError
        The head did not move (parallel optical axes, or centres within ``MIN_HEAD_MOTION``)
        or the axes do not converge in front of the cameras.
    """
    if not isinstance(cameras, Cameras):
        raise ValueError(f"cameras: expected a socialcam.Cameras, got {type(cameras).__name__}")
    lambda_c = check_float(lambda_c, "lambda_c", min=0.0)
    lambda_axis = check_float(lambda_axis, "lambda_axis", min=0.0, max=MAX_LAMBDA_AXIS)
    max_iter = check_int(max_iter, "max_iter", min=1, max=1_000_000)
    tol = check_float(tol, "tol", min=0.0)
    # solved about the centres' mean (the fixation point y moves back): far from the
    # origin (1e6 m) the head's centimetres of motion were lost and the start returned
    moved = float(np.ptp(cameras.C, axis=0).max()) if len(cameras) else 0.0
    check_rounding(cameras.C, "cameras.C", "the head's motion", moved)
    if len(cameras) >= 5 and moved < MIN_HEAD_MOTION:
        raise DegenerateError(
            f"cameras.C: the head moved {moved:.3g} m; calibration needs it to move side to "
            f"side and back and forth (at least {MIN_HEAD_MOTION:g} m, decimetres at best)"
        )
    origin = cameras.C.mean(axis=0) if len(cameras) else np.zeros(3)
    d = _core.calibrate_gaze(
        cameras.R, np.ascontiguousarray(cameras.C - origin), lambda_c, lambda_axis, max_iter, tol
    )
    return GazeCalibration(
        p=readonly(np.asarray(d["p"])),
        v=readonly(np.asarray(d["v"])),
        h=float(d["h"]),
        y=readonly(np.asarray(d["y"]) + origin),
        p_std=readonly(np.asarray(d["p_std"])),
        v_std=float(d["v_std"]),
        y_std=readonly(np.asarray(d["y_std"])),
        h_rel_std=float(d["h_rel_std"]),
        residuals=readonly(np.asarray(d["residuals"])),
        iterations=int(d["iterations"]),
        converged=bool(d["converged"]),
    )
