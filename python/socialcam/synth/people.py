"""People in a scene: eye positions, head poses (primary gaze) and gaze targets.

The gaze model is thesis Sec 3.1: the true gaze ray passes through ``v + m`` where ``v`` is
the primary gaze direction (the head's, what a social camera measures), and ``m`` lies on
the plane normal to ``v`` at unit distance with ``m₁, m₂ ~ N(0, h²)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from socialcam._validate import FloatArray, as_float_array, check_seed


def primary_from_true(
    true_dirs: npt.ArrayLike, h: npt.ArrayLike, rng: np.random.Generator
) -> FloatArray:
    """Draws primary gaze directions ``(..., 3)`` whose gaze-model offset to the true unit
    directions ``true_dirs (..., 3)`` is exactly ``m ~ N(0, h² I₂)`` (Sec 3.1).

    With ``δ = atan(|m|)`` and ``w`` a uniformly random unit vector normal to ``u``,
    ``v = cos δ · u − sin δ · w`` puts ``u`` at offset ``tan δ = |m|`` from ``v`` on the
    plane at unit distance, in an isotropic direction.
    """
    u = np.asarray(true_dirs, dtype=np.float64)
    u = u / np.linalg.norm(u, axis=-1, keepdims=True)
    hh = np.broadcast_to(np.asarray(h, dtype=np.float64), u.shape[:-1])
    m = rng.normal(size=(*u.shape[:-1], 2)) * hh[..., None]
    delta = np.arctan(np.linalg.norm(m, axis=-1))
    a = np.where(np.abs(u[..., 0:1]) < 0.9, np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
    e1 = np.cross(u, a)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(u, e1)
    phi = rng.uniform(0, 2 * np.pi, u.shape[:-1])
    w = np.cos(phi)[..., None] * e1 + np.sin(phi)[..., None] * e2
    v = np.cos(delta)[..., None] * u - np.sin(delta)[..., None] * w
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@dataclass(frozen=True)
class People:
    """A simulated group over ``F`` frames and ``P`` people.

    Attributes
    ----------
    times : (F,) seconds
    eyes : (F, P, 3) eye centres ``p`` in metres
    gaze : (F, P, 3) primary gaze directions ``v`` (unit; what a social camera measures)
    gaze_true : (F, P, 3) true gaze directions (unit, towards ``regard``)
    regard : (F, P, 3) points of regard (the attended target)
    attention : (F, P) index into ``targets`` of each person's target, -1 for none
    targets : (F, T, 3) target positions
    h : (P,) gaze-model bandwidths (std of eye-in-head deviation at unit distance)
    ids : (P,) person ids
    """

    times: FloatArray
    eyes: FloatArray
    gaze: FloatArray
    gaze_true: FloatArray
    regard: FloatArray
    attention: npt.NDArray[np.int64]
    targets: FloatArray
    h: FloatArray
    ids: npt.NDArray[np.int64]

    def rays(self, frame: int) -> tuple[FloatArray, FloatArray, FloatArray, npt.NDArray[np.int64]]:
        """Gaze rays of one frame: ``p (P,3)``, ``v (P,3)``, ``h (P,)``, ``ids (P,)``."""
        return self.eyes[frame], self.gaze[frame], self.h, self.ids

    def to_dict(self) -> dict[str, Any]:
        return {k: np.asarray(getattr(self, k)).tolist() for k in self.__dataclass_fields__}


def wander(
    n_frames: int,
    n_people: int,
    *,
    seed: int = 0,
    room: tuple[npt.ArrayLike, npt.ArrayLike] = ((-4.0, -4.0), (4.0, 4.0)),
    fps: float = 10.0,
    speed: float = 0.4,
    eye_height: tuple[float, float] = (1.5, 1.8),
) -> FloatArray:
    """Eye positions ``(F, P, 3)`` of people strolling smoothly inside the floor rectangle
    ``room = ((xmin, ymin), (xmax, ymax))`` at about ``speed`` m/s: a random walk with
    inertia that turns back at the walls."""
    rng = np.random.default_rng(check_seed(seed))
    lo = as_float_array(room[0], "room[0]", (2,))
    hi = as_float_array(room[1], "room[1]", (2,))
    if (hi <= lo).any():
        raise ValueError("room: need xmin < xmax and ymin < ymax")
    dt = 1.0 / fps
    pos = np.empty((n_frames, n_people, 2))
    pos[0] = lo + (hi - lo) * rng.uniform(0.1, 0.9, (n_people, 2))
    heading = rng.uniform(0, 2 * np.pi, n_people)
    for f in range(1, n_frames):
        heading += rng.normal(0.0, 0.3, n_people) * np.sqrt(dt)
        step = speed * dt * np.c_[np.cos(heading), np.sin(heading)]
        nxt = pos[f - 1] + step
        out = (nxt < lo + 0.2) | (nxt > hi - 0.2)
        if out.any():
            bounce = out.any(axis=1)
            heading[bounce] += np.pi
            nxt[bounce] = pos[f - 1, bounce]
        pos[f] = nxt
    z = rng.uniform(*eye_height, n_people)
    return np.concatenate([pos, np.broadcast_to(z, (n_frames, n_people))[..., None]], axis=2)


def looking_at(
    eyes: npt.ArrayLike,
    targets: npt.ArrayLike,
    attention: npt.ArrayLike,
    *,
    h: npt.ArrayLike = 0.1,
    times: npt.ArrayLike | None = None,
    seed: int = 0,
    idle_distance: float = 3.0,
) -> People:
    """People at ``eyes (F, P, 3)`` looking at ``targets`` (``(T, 3)`` static or
    ``(F, T, 3)`` moving) as chosen by ``attention (F, P)`` (index of the target, or -1 for
    no shared target: the person looks at a random point ``idle_distance`` metres away,
    drawn once per run of idle frames). Primary gaze directions are drawn from the gaze
    model with bandwidth ``h`` (float or ``(P,)``)."""
    rng = np.random.default_rng(check_seed(seed))
    E = as_float_array(eyes, "eyes", (None, None, 3))
    F, P, _ = E.shape
    T = as_float_array(targets, "targets")
    if T.ndim == 2 and T.shape[1] == 3:
        T = np.broadcast_to(T, (F, *T.shape)).copy()
    if T.ndim != 3 or T.shape[0] != F or T.shape[2] != 3:
        raise ValueError(f"targets: expected shape (T, 3) or ({F}, T, 3), got {T.shape}")
    A = np.asarray(attention)
    if A.shape != (F, P) or not np.issubdtype(A.dtype, np.integer):
        raise ValueError(
            f"attention: expected an integer array of shape ({F}, {P}), got {A.shape} {A.dtype}"
        )
    if (A >= T.shape[1]).any() or (A < -1).any():
        raise ValueError(f"attention: entries must be -1 or in [0, {T.shape[1]})")
    hh = np.broadcast_to(as_float_array(h, "h"), (P,)).copy()
    if (hh <= 0).any():
        raise ValueError("h: must be positive")
    regard = np.empty_like(E)
    idle_dir = rng.normal(size=(P, 3))
    for f in range(F):
        for p in range(P):
            a = A[f, p]
            if a >= 0:
                regard[f, p] = T[f, a]
            else:
                if f == 0 or A[f - 1, p] >= 0:
                    d = rng.normal(size=3)
                    d[2] *= 0.2
                    idle_dir[p] = d / np.linalg.norm(d)
                regard[f, p] = E[f, p] + idle_distance * idle_dir[p]
    u = regard - E
    n = np.linalg.norm(u, axis=-1, keepdims=True)
    if (n < 1e-9).any():
        raise ValueError("targets: a person's eyes coincide with their target")
    u /= n
    v = primary_from_true(u, hh[None, :], rng)
    t = np.arange(F, dtype=np.float64) if times is None else as_float_array(times, "times", (F,))
    return People(
        times=t,
        eyes=E,
        gaze=v,
        gaze_true=u,
        regard=regard,
        attention=A.astype(np.int64),
        targets=T,
        h=hh,
        ids=np.arange(P, dtype=np.int64),
    )
