"""Simulated photo collections of a moving person (issue 11 step 5, thesis Sec 5.3.2): several
photographers at random places around a motion-capture clip take photos at random moments,
and a detector-like 2D pose model reports the body joints in each photo — with pixel noise,
missed joints, left/right swaps and, in some photos, a second person. Everything is seeded.

The detections stand in for a real pose model (no images are rendered); the true 3D joints,
the true identity of every detection and the true swaps are returned for evaluation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from socialcam._validate import FloatArray, check_float, check_int, check_seed
from socialcam.camera import Cameras
from socialcam.synth.cameras import look_at

#: a COCO-like joint set of a 2D pose model, as CMU BVH joint names, and its left/right pairs
BODY_JOINTS = (
    "Head",
    "LeftShoulder",
    "RightShoulder",
    "LeftElbow",
    "RightElbow",
    "LeftWrist",
    "RightWrist",
    "LeftHip",
    "RightHip",
    "LeftKnee",
    "RightKnee",
    "LeftAnkle",
    "RightAnkle",
)
BODY_PAIRS = ((1, 2), (3, 4), (5, 6), (7, 8), (9, 10), (11, 12))
#: lines between joints of :data:`BODY_JOINTS` that draw a skeleton (head to shoulders, arms,
#: trunk, legs), e.g. for :func:`socialcam.viz.plot_body`
BODY_BONES = ((0, 1), (0, 2), (1, 2), (1, 3), (3, 5), (2, 4), (4, 6), (1, 7), (2, 8), (7, 8),
              (7, 9), (9, 11), (8, 10), (10, 12))  # fmt: skip
#: CMU BVH files are Y-up; ours are Z-up (x, y, z) ← (x, −z, y)
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@dataclass(frozen=True)
class PhotoCollection:
    """Photos of a moving person and the 2D joints a pose model reports in them.

    Attributes
    ----------
    cameras : ``F`` photo cameras with capture ``times`` (s, one clock)
    detections : per photo ``(n_f, J, 2)`` pixels of every person found (NaN = joint missed),
        in the detector's (arbitrary) order
    size : image (width, height), pixels
    points : ``(F, J, 3)`` true joints of the photographed person at the photo times, metres
    who : per photo ``(n_f,)`` true person of each detection (0 = the photographed person)
    swapped : ``(F, P)`` true left/right swaps of the photographed person's pairs
    photographer : ``(F,)`` index of the photographer of each photo
    """

    cameras: Cameras
    detections: tuple[FloatArray, ...]
    size: tuple[int, int]
    points: FloatArray
    who: tuple[npt.NDArray[np.int64], ...]
    swapped: npt.NDArray[np.bool_]
    photographer: npt.NDArray[np.int64]


def _joints(positions: FloatArray, names: list[str]) -> FloatArray:
    idx = [names.index(n) for n in BODY_JOINTS]
    return np.einsum("ij,tpj->tpi", Y_UP_TO_Z_UP, positions[:, idx])


def photo_collection(
    positions: npt.ArrayLike,
    names: list[str],
    fps: float,
    *,
    other: npt.ArrayLike | None = None,
    n_photographers: int = 6,
    n_photos: int = 60,
    size: tuple[int, int] = (1280, 960),
    focal: float = 1000.0,
    distance: tuple[float, float] = (3.5, 6.0),
    noise: float = 3.0,
    miss: float = 0.05,
    swap: float = 0.05,
    pair_swap: float = 0.03,
    second: float = 0.3,
    seed: int = 0,
) -> PhotoCollection:
    """Photos of the BVH motion ``positions (T, joints, 3)`` (Y-up, metres, frame rate
    ``fps``; joint ``names``) by ``n_photographers`` standing at random places
    ``distance`` metres from the middle of the path (eye height 1.5–1.8 m), each turning
    to the person at each of its photos; ``n_photos`` in all at uniformly random moments.

    The pose model: each joint of :data:`BODY_JOINTS` with Gaussian pixel noise ``noise``
    (px per coordinate), missed with probability ``miss`` (or when outside the image);
    with probability ``swap`` per photo all left/right pairs exchanged (a body seen from
    the wrong side) and, independently, each pair exchanged with probability
    ``pair_swap`` (defaults: 7.8 % of the pairs inverted, near the 5–8 % of keypoints a
    COCO keypoint benchmark analysis counts as left/right inversions, Ronchi & Perona
    2017);
    with probability ``second`` a second person (``other``: another BVH clip of the same
    joints, placed 1.2–2 m to the side) detected too when in view.
    """
    rng = np.random.default_rng(check_seed(seed))
    pos = np.asarray(positions, np.float64)
    fps_ = check_float(fps, "fps", min=0.0, min_exclusive=True)
    n_cam = check_int(n_photographers, "n_photographers", min=2)
    F = check_int(n_photos, "n_photos", min=n_cam)
    for name, val in (("miss", miss), ("swap", swap), ("pair_swap", pair_swap), ("second", second)):
        check_float(val, name, min=0.0, max=1.0)
    check_float(noise, "noise", min=0.0)
    W, H = size
    X = _joints(pos, names)  # (T, J, 3)
    X[..., :2] -= X[0, 0, :2]  # the path starts above the origin
    X[..., 2] -= X[..., 2].min()  # the feet on the floor
    T = len(X)
    times_all = np.arange(T) / fps_
    Y = None
    if other is not None:
        Y = _joints(np.asarray(other, np.float64)[:T], names)
        Y[..., 2] -= Y[..., 2].min()
        mid_x, mid_y = X[:, 0].mean(0), Y[:, 0].mean(0)
        side = rng.uniform(1.2, 2.0) * rng.choice([-1.0, 1.0])
        Y[..., :2] += (mid_x - mid_y)[:2] + np.array([0.0, side])
    centre = X[:, 0].mean(0)
    ang = (
        rng.uniform(0, 2 * np.pi)
        + 2 * np.pi * (np.arange(n_cam) + rng.uniform(-0.3, 0.3, n_cam)) / n_cam
    )
    rad = rng.uniform(*distance, n_cam)
    Cph = np.c_[
        centre[0] + rad * np.cos(ang), centre[1] + rad * np.sin(ang), rng.uniform(1.5, 1.8, n_cam)
    ]
    ph = np.sort(rng.integers(0, n_cam, F))
    ph[:n_cam] = np.arange(n_cam)  # everyone takes at least one photo
    ph = np.sort(ph)
    t = np.sort(rng.uniform(0, times_all[-1], F))
    rng.shuffle(t)
    k = np.clip(np.round(t * fps_).astype(int), 0, T - 1)
    t = times_all[k]
    C = Cph[ph]
    aim = X[k, 0] + rng.normal(scale=0.2, size=(F, 3))
    R = look_at(C, aim)
    K = np.array([[focal, 0.0, (W - 1) / 2], [0.0, focal, (H - 1) / 2], [0.0, 0.0, 1.0]])
    cams = Cameras(np.tile(K, (F, 1, 1)), R, C, t)

    def project(P: FloatArray, f: int) -> FloatArray:
        Pc = (P - C[f]) @ R[f].T
        uv = Pc[:, :2] / Pc[:, 2:] * focal + K[:2, 2]
        uv = uv + rng.normal(scale=noise, size=uv.shape)
        out = (
            (Pc[:, 2] <= 0.1)
            | (uv[:, 0] < 0)
            | (uv[:, 0] > W - 1)
            | (uv[:, 1] < 0)
            | (uv[:, 1] > H - 1)
        )
        uv[out | (rng.uniform(size=len(P)) < miss)] = np.nan
        return uv

    dets, who = [], []
    swapped = np.zeros((F, len(BODY_PAIRS)), bool)
    for f in range(F):
        uv = project(X[k[f]], f)
        swapped[f] = rng.uniform() < swap
        swapped[f] ^= rng.uniform(size=len(BODY_PAIRS)) < pair_swap
        for p, (a, b) in enumerate(BODY_PAIRS):
            if swapped[f, p]:
                uv[[a, b]] = uv[[b, a]]
        people, ids = [uv], [0]
        if Y is not None and rng.uniform() < second:
            u2 = project(Y[k[f]], f)
            if np.isfinite(u2).all(axis=1).sum() >= 4:
                people.append(u2)
                ids.append(1)
        order = rng.permutation(len(people))
        dets.append(np.stack([people[i] for i in order]))
        who.append(np.array([ids[i] for i in order], np.int64))
    return PhotoCollection(
        cameras=cams,
        detections=tuple(dets),
        size=(W, H),
        points=X[k],
        who=tuple(who),
        swapped=swapped,
        photographer=ph.astype(np.int64),
    )
