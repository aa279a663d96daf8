"""A simulated game of *Mafia* (thesis Sec 7.4.2, Fig 7.3b/7.4b): players seated around a
table interrogate one suspect at a time, so the group's attention (one social charge) sits
at the suspect's face and moves when the suspect changes; now and then one or two players
stop paying attention and look elsewhere — the anomalies to detect.

Primary gaze is drawn from the gaze model of Sec 3.1 (:func:`socialcam.synth.looking_at`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from socialcam._validate import FloatArray, check_seed
from socialcam.synth.people import looking_at

IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True)
class MafiaScene:
    """``F`` frames of ``P`` players.

    Attributes
    ----------
    times : (F,) seconds
    eyes : (F, P, 3) eye centres, metres
    gaze : (F, P, 3) primary gaze directions (unit), what head-mounted cameras measure
    gaze_true : (F, P, 3) true gaze directions (unit)
    h : (P,) gaze-model bandwidths
    ids : (P,) person ids
    faces : (F, P, 3) the point others look at on each player (10 cm in front of the eyes)
    suspect : (F,) the player being interrogated
    accuser : (F,) the player the suspect answers (looks at)
    inattentive : (F, P) bool, players not paying attention (the true anomalies)
    """

    times: FloatArray
    eyes: FloatArray
    gaze: FloatArray
    gaze_true: FloatArray
    h: FloatArray
    ids: IntArray
    faces: FloatArray
    suspect: IntArray
    accuser: IntArray
    inattentive: npt.NDArray[np.bool_]

    @property
    def n_frames(self) -> int:
        return int(self.eyes.shape[0])

    def ray_frames(self) -> list[tuple[FloatArray, FloatArray, FloatArray, IntArray]]:
        """Per frame ``(p, v, h, ids)``, the input of :meth:`socialcam.GazeField.fit`."""
        return [(self.eyes[f], self.gaze[f], self.h, self.ids) for f in range(self.n_frames)]

    def to_dict(self) -> dict[str, Any]:
        return {k: np.asarray(getattr(self, k)).tolist() for k in self.__dataclass_fields__}


def mafia(
    n_frames: int = 200,
    n_players: int = 8,
    *,
    h: float = 0.08,
    fps: float = 10.0,
    turn: tuple[int, int] = (25, 50),
    lapse: tuple[int, int] = (10, 30),
    lapse_rate: float = 0.04,
    max_inattentive: int = 2,
    seed: int = 0,
) -> MafiaScene:
    """Players seated on a circle of radius 1.1 m, eyes 1.15–1.3 m high with a little sway.

    The suspect changes every ``turn`` frames (uniform range); everyone else looks at the
    suspect's face and the suspect at the accuser. In each frame an attentive player who
    is neither suspect nor accuser starts a lapse with probability ``lapse_rate`` (while
    fewer than ``max_inattentive`` players are lapsing), lasting ``lapse`` frames: the
    player then looks at a random point 3 m away in a random, mostly horizontal direction
    (out of the window, at the wall); a lapse that happens to point at the suspect cannot
    be told from attention.
    """
    s = check_seed(seed)
    rng = np.random.default_rng(s)
    F, P = int(n_frames), int(n_players)
    if F < 1 or P < 4:
        raise ValueError("n_frames >= 1 and n_players >= 4 are required")
    ang = 2 * np.pi * np.arange(P) / P + rng.uniform(-0.1, 0.1, P)
    seat = np.c_[1.1 * np.cos(ang), 1.1 * np.sin(ang)]
    eyes = np.empty((F, P, 3))
    eyes[..., :2] = seat[None]
    eyes[..., 2] = rng.uniform(1.15, 1.3, P)[None]
    # Smooth sway of a few centimetres.
    t = np.arange(F) / fps
    for k in range(3):
        ph = rng.uniform(0, 2 * np.pi, P)
        fr = rng.uniform(0.05, 0.2, P)
        eyes[..., k] += 0.03 * np.sin(2 * np.pi * fr[None] * t[:, None] + ph[None])
    inward = -np.c_[np.cos(ang), np.sin(ang), np.zeros(P)]
    faces = eyes + 0.1 * inward[None]

    suspect = np.empty(F, dtype=np.int64)
    accuser = np.empty(F, dtype=np.int64)
    f = 0
    cur = int(rng.integers(P))
    while f < F:
        d = int(rng.integers(turn[0], turn[1] + 1))
        acc = int(rng.choice([j for j in range(P) if j != cur]))
        suspect[f : f + d] = cur
        accuser[f : f + d] = acc
        f += d
        cur = int(rng.choice([j for j in range(P) if j != cur]))

    inattentive = np.zeros((F, P), dtype=bool)
    left = np.zeros(P, dtype=np.int64)
    for f in range(F):
        left = np.maximum(left - 1, 0)
        left[[suspect[f], accuser[f]]] = 0
        for j in rng.permutation(P):
            if (
                left[j] == 0
                and j not in (suspect[f], accuser[f])
                and (left > 0).sum() < max_inattentive
            ):
                if rng.uniform() < lapse_rate:
                    left[j] = int(rng.integers(lapse[0], lapse[1] + 1))
        inattentive[f] = left > 0

    attention = np.where(inattentive, -1, suspect[:, None]).astype(np.int64)
    attention[np.arange(F), suspect] = accuser
    people = looking_at(eyes, faces, attention, h=h, times=t, seed=s + 1)
    return MafiaScene(
        times=people.times,
        eyes=people.eyes,
        gaze=people.gaze,
        gaze_true=people.gaze_true,
        h=people.h,
        ids=people.ids,
        faces=faces,
        suspect=suspect,
        accuser=accuser,
        inattentive=inattentive,
    )
