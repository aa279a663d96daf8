"""Scores a ``socialcam run`` on a rendered scene against the scene's truth (issue 10).

:func:`run_vs_truth` measures

- **calibration**: per wearer the angle between the calibrated primary direction ``v`` and
  the truth, the distance between the calibrated eye centre ``p`` (scaled to metres by the
  similarity that maps the estimated camera centres onto the true ones) and the observable
  part of the true eye offset (normal to ``v``, see :mod:`socialcam.gaze`), and ``h`` over
  the true spread;
- **joint attention**: at every output time, the groups of ≥ 2 wearers whose truth says they
  look at the same thing (a moving target or a wearer's head) and have been doing so for at
  least ``settle`` seconds; a group is *found* when a charge (mapped into the truth frame)
  with at least two of its members lies within ``radius`` metres of the target; the error is
  that charge's distance to the target;
- **reference**: the same calibration, gaze and charge stages on the TRUE cameras at the
  same output times (:func:`socialcam.pipeline.gaze_and_charges`), so that the joint
  attention error of the run can be compared with what perfect poses give (the ratio).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from socialcam._validate import FloatArray
from socialcam.charges import Charge
from socialcam.geometry import align_similarity
from socialcam.synth.render import AROUND, CALIBRATION, SceneTruth

__all__ = ["joint_attention", "run_vs_truth", "truth_segments"]


def truth_segments(truth: SceneTruth) -> dict[str, tuple[float, float]]:
    """The rendered calibration segments on the common clock (``socialcam run --calibration``)."""
    return {
        n: (t0 - float(truth.start[0]), t1 - float(truth.start[0]))
        for n, (t0, t1, _) in zip(truth.names, truth.calibration, strict=False)
    }


def _angle_deg(a: FloatArray, b: FloatArray) -> float:
    c = float(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b)))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def _truth_at(truth: SceneTruth, v: int, times: FloatArray) -> tuple[Any, FloatArray]:
    """Index of the true frame nearest to each common-clock time (−1 beyond half a frame)
    and how long the wearer has been looking at the same thing there (s)."""
    ft = truth.frame_times[v] - truth.start[0]
    j = np.clip(np.searchsorted(ft, times), 1, len(ft) - 1)
    j = np.where(np.abs(ft[j - 1] - times) < np.abs(ft[j] - times), j - 1, j)
    j = np.where(np.abs(ft[j] - times) <= 0.5 / truth.fps + 1e-9, j, -1)
    code = truth.target_of[v]
    change = np.r_[0, np.flatnonzero(code[1:] != code[:-1]) + 1]
    since = np.empty(len(code))
    for a, b in zip(change, [*change[1:], len(code)], strict=True):
        since[a:b] = ft[a:b] - ft[a]
    return j, np.where(j >= 0, since[np.maximum(j, 0)], np.nan)


def joint_attention(
    truth: SceneTruth,
    names: Sequence[str],
    times: FloatArray,
    charges: Sequence[Sequence[Charge]],
    to_truth: Any = None,
    *,
    radius: float = 0.5,
    settle: float = 0.6,
    max_deviation: float = 3.0,
) -> dict[str, Any]:
    """Joint-attention figures of ``charges`` (ids index ``names``) at ``times`` (common
    clock); ``to_truth(X (N, 3)) -> (N, 3)`` maps charge positions into the truth frame.

    A wearer looks at a target at a time when its truth says so for at least ``settle``
    seconds and its head has turned there: the primary gaze is within ``max_deviation``
    spreads ``h`` of the true gaze (Sec 3.1; beyond 3 h is a 1 % tail of the model, in
    practice a head still turning towards the target). ``false_fraction``: the charges none
    of whose two members look at one thing (settled or not)."""
    idx = {n: truth.names.index(n) for n in names if n in truth.names}
    at = {n: _truth_at(truth, v, times) for n, v in idx.items()}

    def code_now(n: str, k: int) -> int | None:
        """What ``n`` looks at at output time ``k`` (None: unknown, a wall or calibrating)."""
        if n not in at or at[n][0][k] < 0:
            return None
        code = int(truth.target_of[idx[n]][at[n][0][k]])
        return None if code in (AROUND, CALIBRATION) else code

    errors: list[float] = []
    n_groups = n_found = n_charges = n_false = 0
    for k in range(len(times)):
        groups: dict[int, list[int]] = {}
        for i, n in enumerate(names):
            if n not in at:
                continue
            j, since = at[n][0][k], at[n][1][k]
            if j < 0 or not since >= settle:
                continue
            v = idx[n]
            if _angle_deg(truth.gaze[v][j], truth.gaze_true[v][j]) > np.degrees(
                np.arctan(max_deviation * truth.h[v])
            ):
                continue
            code = int(truth.target_of[v][j])
            if code in (AROUND, CALIBRATION):
                continue
            groups.setdefault(code, []).append(i)
        pos = [
            c.position[None] if to_truth is None else to_truth(c.position[None]) for c in charges[k]
        ]
        for members in groups.values():
            if len(members) < 2:
                continue
            n_groups += 1
            first = names[members[0]]
            target = truth.regard[idx[first]][at[first][0][k]]
            best = np.inf
            for i, c in enumerate(charges[k]):
                if len(set(c.members.tolist()) & set(members)) < 2:
                    continue
                best = min(best, float(np.linalg.norm(pos[i][0] - target)))
            if best <= radius:
                n_found += 1
                errors.append(best)
        for c in charges[k]:  # false: no two members look at one thing (settled or not)
            codes = [code_now(names[m], k) for m in c.members.tolist() if m < len(names)]
            shared = [x for x in codes if x is not None and codes.count(x) >= 2]
            n_charges += 1
            n_false += not shared
    e = np.array(errors)
    return {
        "charges": n_charges,
        "false_charges": n_false,
        "false_fraction": n_false / n_charges if n_charges else float("nan"),
        "groups": n_groups,
        "found": n_found,
        "found_fraction": n_found / n_groups if n_groups else float("nan"),
        "error_median_m": float(np.median(e)) if len(e) else float("nan"),
        "error_mean_m": float(e.mean()) if len(e) else float("nan"),
        "error_p90_m": float(np.percentile(e, 90)) if len(e) else float("nan"),
    }


def _alignment(rec: Any, truth: SceneTruth) -> tuple[float, FloatArray, FloatArray]:
    """Similarity ``x_truth ≈ s R x + t`` of the estimated camera centres onto the true ones
    (true centres interpolated to the posed times)."""
    E, T = [], []
    for n, cam in rec.cameras.items():
        if len(cam) == 0 or n not in truth.names:
            continue
        tc = truth.cameras(truth.names.index(n))
        assert cam.times is not None and tc.times is not None
        T.append(np.stack([np.interp(cam.times, tc.times, tc.C[:, d]) for d in range(3)], 1))
        E.append(cam.C)
    s, R, t = align_similarity(np.concatenate(E), np.concatenate(T))
    return s, R, t


def run_vs_truth(
    result: Any,
    truth: SceneTruth,
    *,
    reference: bool = True,
    radius: float = 0.5,
    settle: float = 0.6,
    max_deviation: float = 3.0,
) -> dict[str, Any]:
    """Accuracy of a :class:`socialcam.pipeline.RunResult` against the rendered ``truth``
    (module docs). Returns a JSON-able dict: ``alignment``, ``calibration`` (per wearer
    ``v_error_deg``, ``p_error_m``, ``h_ratio``, ``calibrated``), ``joint_attention``, and
    with ``reference`` ``joint_attention_true_cameras`` and ``error_ratio``."""
    from socialcam.pipeline import RunOptions, gaze_and_charges

    rec = result.reconstruction
    names = list(rec.names)
    s, R, t = _alignment(rec, truth)

    def to_truth(X: FloatArray) -> FloatArray:
        return np.asarray(s * X @ R.T + t)

    cal = _calibration_errors(result.calibrations, truth, s)
    out: dict[str, Any] = {
        "alignment": {"scale": s},
        "calibration": cal,
        "joint_attention": joint_attention(
            truth,
            names,
            result.times,
            result.charges,
            to_truth,
            radius=radius,
            settle=settle,
            max_deviation=max_deviation,
        ),
    }
    if reference:
        opts = RunOptions(**{k: v for k, v in result.report["options"].items()})
        true_cams = {n: truth.cameras(truth.names.index(n)) for n in names}
        cals, times, _frames, charges = gaze_and_charges(
            true_cams,
            names,
            calibration={k: tuple(v) for k, v in result.report["inputs"]["calibration"].items()},
            times=result.times,
            options=opts,
        )
        out["calibration_true_cameras"] = _calibration_errors(cals, truth, 1.0)
        ref = joint_attention(
            truth, names, times, charges, radius=radius, settle=settle, max_deviation=max_deviation
        )
        out["joint_attention_true_cameras"] = ref
        a, b = out["joint_attention"]["error_median_m"], ref["error_median_m"]
        out["error_ratio"] = a / b if b > 0 else float("nan")
    return out


def _calibration_errors(
    calibrations: Mapping[str, Any], truth: SceneTruth, scale: float
) -> dict[str, dict[str, Any]]:
    out = {}
    for n, c in calibrations.items():
        v = truth.names.index(n)
        vt, pt = truth.primary_dir[v], truth.eye_offset[v]
        pn = pt - pt.dot(vt) * vt
        out[n] = {
            "calibrated": bool(c.calibrated),
            "v_error_deg": _angle_deg(c.v, vt),
            "p_error_m": float(np.linalg.norm(scale * c.p - pn)),
            "h_ratio": float(c.h / truth.h[v]),
        }
    return out
