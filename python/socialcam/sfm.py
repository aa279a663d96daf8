"""Structure from motion of a static scene through pycolmap (CPU), giving the camera poses
of social-camera frames in one world frame (the README's conventions).

>>> rec_dir = reconstruct_static("frames/", "work/sfm")        # doctest: +SKIP
>>> cams = Cameras.from_colmap(rec_dir)                          # doctest: +SKIP
"""

from __future__ import annotations

import io
import json
import os
import shutil
import sys
import time
import warnings
import zipfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np
import numpy.typing as npt

from socialcam._posetrack import _LK_VIDEO_RATE, KeyframeSelector
from socialcam._validate import (
    FloatArray,
    as_float_array,
    check_bool,
    check_choice,
    check_float,
    check_int,
    check_seed,
    readonly,
    readonly_fields,
)
from socialcam.camera import COLMAP_TO_OPENCV_PIXEL, Cameras
from socialcam.io import atomic_write_bytes, write_json

CameraModel = Literal["SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL", "OPENCV"]


def reconstruct_static(
    image_dir: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    *,
    camera_mode: Literal["single", "per_folder", "per_image"] = "single",
    camera_model: CameraModel = "SIMPLE_RADIAL",
    max_image_size: int = 1600,
    max_features: int = 4000,
    num_threads: int = -1,
    overwrite: bool = False,
    progress: Callable[[str], Any] | None = None,
) -> Path:
    """Runs incremental SfM on a folder of images and writes the largest model.

    Parameters
    ----------
    image_dir : folder of images (with ``camera_mode="per_folder"``, one sub-folder per
        social camera).
    out_dir : working folder; receives ``database.db`` and the model in ``sparse/``.
    camera_mode : ``"single"`` (one camera for all images: frames of one device — pycolmap's
        ``AUTO`` would give one camera per image), ``"per_folder"`` or
        ``"per_image"``.
    camera_model : COLMAP camera model for the intrinsics to estimate.
    max_image_size : images are downscaled to this size for SIFT; keypoints and intrinsics
        are reported at full resolution.
    max_features : SIFT features per image.
    num_threads : ``-1`` uses every core.
    overwrite : replace an existing ``out_dir``.
    progress : optional callback taking a stage name.

    Returns
    -------
    Path to the folder of the largest reconstruction, readable by
    :meth:`socialcam.Cameras.from_colmap`.

    Raises
    ------
    ValueError
        ``image_dir`` missing or without images, ``out_dir`` exists (without ``overwrite``).
    RuntimeError
        No model could be reconstructed.
    """
    try:
        import pycolmap
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise ImportError(
            "structure from motion needs pycolmap: pip install 'socialcam[sfm]'"
        ) from exc

    images = Path(image_dir)
    if not images.is_dir():
        raise ValueError(f"image_dir: {images} is not a folder")
    exts = {".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp"}
    if not any(p.suffix.lower() in exts for p in images.rglob("*")):
        raise ValueError(f"image_dir: no images in {images}")
    if max_image_size < 64:
        raise ValueError(f"max_image_size: must be at least 64, got {max_image_size}")
    overwrite = check_bool(overwrite, "overwrite")  # a truthy "no" must not delete out_dir
    out = Path(out_dir)
    if out.exists():
        if not overwrite:
            raise ValueError(f"out_dir: {out} exists (pass overwrite=True to replace it)")
        shutil.rmtree(out)
    out.mkdir(parents=True)
    db = out / "database.db"
    say = progress or (lambda _stage: None)
    modes = {
        "single": pycolmap.CameraMode.SINGLE,
        "per_folder": pycolmap.CameraMode.PER_FOLDER,
        "per_image": pycolmap.CameraMode.PER_IMAGE,
    }
    if camera_mode not in modes:
        raise ValueError(f"camera_mode: expected one of {sorted(modes)}, got {camera_mode!r}")
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = camera_model
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = num_threads
    extraction.max_image_size = max_image_size
    extraction.sift.max_num_features = max_features
    say("features")
    pycolmap.extract_features(
        db,
        images,
        camera_mode=modes[camera_mode],
        reader_options=reader,
        extraction_options=extraction,
        device=pycolmap.Device.cpu,
    )
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = num_threads
    say("matching")
    pycolmap.match_exhaustive(db, matching_options=matching, device=pycolmap.Device.cpu)
    say("mapping")
    sparse = out / "sparse"
    sparse.mkdir()
    models = pycolmap.incremental_mapping(db, images, sparse)
    if not models:
        raise RuntimeError("structure from motion registered no model (too few matches?)")
    best = max(models, key=lambda k: models[k].num_reg_images())
    return sparse / str(best)


# =====================================================================================
# Videos → camera poses of every output frame (issue 9; thesis App. A).
# =====================================================================================

VideoCameraModel = Literal[
    "SIMPLE_PINHOLE",
    "PINHOLE",
    "SIMPLE_RADIAL",
    "RADIAL",
    "OPENCV",
    "SIMPLE_RADIAL_FISHEYE",
    "RADIAL_FISHEYE",
    "OPENCV_FISHEYE",
]


@dataclass(frozen=True)
class VideoSfmOptions:
    """Options of :func:`reconstruct_videos` (each validated on construction).

    Attributes
    ----------
    fps : output rate: every video is posed at the frames nearest to ``k / fps`` s (local
        clock), Hz.
    keyframe_fps : least rate of the keyframes given to SIFT + incremental mapping, Hz;
        rounded so that every keyframe is an output frame (``fps / keyframe_fps`` an
        integer ≥ 1). Faster head motion adds keyframes (``keyframe_overlap``), and a clip
        gets at least ``MIN_KEYFRAMES`` (6).
    keyframe_overlap : a frame becomes a keyframe as soon as fewer than this fraction of the
        corners of the last keyframe can be followed into it (KLT, half resolution); 0 keeps
        the fixed rate ``keyframe_fps``.
    camera_model : COLMAP camera model of every wearer's lens (one camera per wearer).
    focal_prior : without given ``intrinsics``, the initial focal length as a fraction of
        the larger image side (refined by bundle adjustment). ``None``: 1.2 for the
        perspective models (COLMAP's default, a ~45° field) and 0.5 for the fisheye models
        (an equidistant lens with a ~110° field, as action cameras have). Fisheye models
        always start from this prior: COLMAP cannot recover a fisheye focal length from a
        pair of views and marks every pair without one as degenerate.
    max_features : SIFT features per keyframe.
    sequential_overlap : each keyframe is matched with this many following keyframes of
        the same video.
    cross_pairs : each keyframe is matched with its ``cross_pairs`` most similar keyframes in
        each other video, more in short clips (at least ``MIN_CROSS_PAIRS`` per pair of
        videos). Retrieval is by a TF-IDF bag of SIFT words computed here; the vocabulary
        tree of COLMAP is never used.
    same_lens : every wearer wears the same camera model: one set of intrinsics for all
        videos (COLMAP's single camera), estimated from all their keyframes together. On
        short clips a wearer's own estimate can run off (measured: +10.7 % focal length
        for one of four wearers of a rendered 3-s conversation circle, which bent the map
        by 3.6°; with one lens its rotations erred 0.19°). Only for cameras that are the
        same model: on the same rendered circles, whose wearers' focal lengths differ by
        up to ±3 %, it also made one map worse and let SfM join another wrongly
        (``benches/faces_run.out.txt``). The videos must share a frame size; given
        ``intrinsics`` must agree.
    global_mapping : use COLMAP's global mapper instead of the incremental one.
    refine_intrinsics : with given ``intrinsics``, let bundle adjustment refine them.
    min_inliers : fewest PnP inliers for a pose of a frame between keyframes.
    max_rms : largest reprojection RMS (pixels) of a trusted pose.
    ransac_px : PnP RANSAC threshold, pixels.
    max_split : a frame between two keyframes is posed from the tracks of each alone too; if
        the two centres differ by more than this (metres), it is dropped.
    max_split_turn : likewise for their rotations, radians (default 1°).
    max_jump : a frame between keyframes farther than this from the mean of its two
        neighbours is dropped, metres (a gross-error check: rendered and real heads move
        up to ~0.4 m from that mean at 10 fps). Without a metric scale, 0.2 of the median
        keyframe-to-point depth stands for ``max_jump`` (and ``max_split`` in proportion).
    max_turn : likewise for rotation, radians (default 30°).
    retry_min_inliers : keyframes that the first mapping pass leaves out get a second pass,
        which extends the map and registers an image from this many 2D–3D inliers (COLMAP's
        own bar, 30, holds in the first pass: it is made for photo collections, while a
        keyframe after a stretch of walking straight ahead can see fewer triangulated
        points). 0: no second pass.
    num_threads : threads for SIFT, matching and mapping. COLMAP's results depend on thread
        scheduling; with 1 thread the same inputs give bit-identical poses.
    seed : seeds the retrieval vocabulary, the mapper and the PnP RANSAC. COLMAP's two-view
        verification draws from each matching thread's own generator: one stream per
        thread, so reproducible with 1 thread. (Seeding it instead restarts every pair's
        RANSAC from one seed; on rendered 3-wearer × 4 s scenes that left 2 of 6 seeds with
        a map bent by a wrong focal length, 1–3° of rotation error.)
    """

    fps: float = 10.0
    keyframe_fps: float = 1.0
    keyframe_overlap: float = 0.5
    camera_model: VideoCameraModel = "SIMPLE_RADIAL"
    focal_prior: float | None = None
    max_features: int = 2048
    sequential_overlap: int = 3
    cross_pairs: int = 2
    same_lens: bool = False
    global_mapping: bool = False
    refine_intrinsics: bool = True
    min_inliers: int = 25
    max_rms: float = 2.0
    ransac_px: float = 2.0
    max_split: float = 0.03
    max_split_turn: float = 0.0175
    max_jump: float = 0.5
    max_turn: float = 0.524
    retry_min_inliers: int = 20
    num_threads: int = 2
    seed: int = 0

    def __post_init__(self) -> None:
        check_float(self.fps, "fps", min=0.0, min_exclusive=True, max=1000.0)
        check_float(self.keyframe_fps, "keyframe_fps", min=0.0, min_exclusive=True)
        if self.keyframe_fps > self.fps:
            raise ValueError(
                f"keyframe_fps: must not exceed fps ({self.fps}), got {self.keyframe_fps}"
            )
        check_float(self.keyframe_overlap, "keyframe_overlap", min=0.0, max=1.0)
        check_choice(self.camera_model, "camera_model", tuple(get_args(VideoCameraModel)))
        if self.focal_prior is not None:
            check_float(self.focal_prior, "focal_prior", min=0.05, max=20.0)
        check_int(self.max_features, "max_features", min=64, max=65536)
        check_int(self.sequential_overlap, "sequential_overlap", min=1, max=100)
        check_int(self.cross_pairs, "cross_pairs", min=0, max=100)
        check_int(self.min_inliers, "min_inliers", min=6)
        check_float(self.max_rms, "max_rms", min=0.0, min_exclusive=True)
        check_float(self.ransac_px, "ransac_px", min=0.0, min_exclusive=True)
        check_float(self.max_split, "max_split", min=0.0, min_exclusive=True)
        check_float(self.max_split_turn, "max_split_turn", min=0.0, min_exclusive=True)
        check_float(self.max_jump, "max_jump", min=0.0, min_exclusive=True)
        check_float(self.max_turn, "max_turn", min=0.0, min_exclusive=True, max=np.pi)
        check_int(self.retry_min_inliers, "retry_min_inliers", min=0)
        if 0 < self.retry_min_inliers < 6:
            raise ValueError(
                "retry_min_inliers: a pose needs at least 6 inliers (or 0 for no second "
                f"pass), got {self.retry_min_inliers}"
            )
        check_int(self.num_threads, "num_threads", min=1, max=1024)
        check_seed(self.seed)
        for name in ("same_lens", "global_mapping", "refine_intrinsics"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name}: expected True or False, got {getattr(self, name)!r}")

    @property
    def fisheye(self) -> bool:
        """Whether ``camera_model`` is a fisheye model."""
        return self.camera_model.endswith("FISHEYE")

    @property
    def focal_factor(self) -> float:
        """Initial focal length ÷ larger image side (``focal_prior`` or its default)."""
        if self.focal_prior is not None:
            return float(self.focal_prior)
        return 0.5 if self.fisheye else 1.2

    @property
    def keyframe_step(self) -> int:
        """Output frames per keyframe."""
        return max(1, round(self.fps / self.keyframe_fps))


@dataclass(frozen=True)
class KnownDistance:
    """A distance measured in the scene, fixing the metric scale: between the camera centre
    of ``person_a`` at time ``time_a`` and that of ``person_b`` at ``time_b`` (common clock,
    seconds; the nearest posed frame is used). Two wearers standing ``metres`` apart at one
    moment, or one wearer walking a measured baseline, are both of this form."""

    person_a: str
    time_a: float
    person_b: str
    time_b: float
    metres: float

    def __post_init__(self) -> None:
        check_float(self.time_a, "known_distance.time_a")
        check_float(self.time_b, "known_distance.time_b")
        check_float(self.metres, "known_distance.metres", min=0.0, min_exclusive=True)


@dataclass(frozen=True)
class FrameQuality:
    """Per output frame of one video: ``times (F,)`` common clock s, ``posed (F,)`` bool,
    ``keyframe (F,)`` bool, ``rms (F,)`` inlier reprojection RMS px (NaN when unposed),
    ``n_inliers (F,)``, ``reasons``: frame index → why it was dropped."""

    times: FloatArray
    posed: npt.NDArray[np.bool_]
    keyframe: npt.NDArray[np.bool_]
    rms: FloatArray
    n_inliers: npt.NDArray[np.int64]
    reasons: dict[int, str]

    def to_dict(self) -> dict[str, Any]:
        return {
            "n_frames": len(self.times),
            "n_posed": int(self.posed.sum()),
            "n_keyframes": int(self.keyframe.sum()),
            "median_rms": float(np.nanmedian(self.rms)) if self.posed.any() else None,
            "dropped": {str(k): v for k, v in sorted(self.reasons.items())},
        }


@dataclass(frozen=True)
class VideoReconstruction:
    """Camera poses of every output frame of every video, in one metric, gravity-aligned
    world frame (z up; origin on the floor below the first wearer's mean position when the
    floor was found, else at that position).

    Attributes
    ----------
    names : person names (video file stems), in the order given.
    cameras : person → :class:`~socialcam.Cameras` of its posed frames, ``times`` on the
        common clock; ``K`` is the pinhole part of the lens and
        ``Cameras.undistort_points`` maps raw pixels to it. Wearers that could not be placed
        are absent.
    quality : person → :class:`FrameQuality` (every output frame, posed or not).
    points : ``(M, 3)`` static map points, metres. colors : ``(M, 3)`` uint8 RGB.
    offsets : ``(V,)`` s, ``t_common = t_local + offsets[v]``.
    sync : the synchronisation result as a dict (offsets, confidence, method).
    scale : metres per map unit (NaN when no scale was given: the map's own units).
    unplaced : persons with no pose in the largest model.
    timings : stage → wall seconds. warnings : what a user should know.
    out_dir : where it is saved (``load`` reads it back).
    """

    names: tuple[str, ...]
    cameras: dict[str, Cameras]
    quality: dict[str, FrameQuality]
    points: FloatArray
    colors: npt.NDArray[np.uint8]
    offsets: FloatArray
    sync: dict[str, Any]
    scale: float
    unplaced: tuple[str, ...]
    timings: dict[str, float]
    warnings: tuple[str, ...]
    counts: dict[str, Any]
    out_dir: Path

    def __post_init__(self) -> None:
        # The per-frame quality is filled in place while the poses are checked; the result
        # hands it out read-only, like every other result array.
        for q in self.quality.values():
            readonly_fields(q)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able summary (no per-frame poses)."""
        n = sum(len(q.times) for q in self.quality.values())
        posed = sum(int(q.posed.sum()) for q in self.quality.values())
        return {
            "names": list(self.names),
            "registered_fraction": posed / n if n else 0.0,
            "n_frames": n,
            "n_posed": posed,
            "n_points": len(self.points),
            "scale": self.scale,
            "offsets": self.offsets.tolist(),
            "sync": self.sync,
            "unplaced": list(self.unplaced),
            "timings": dict(self.timings),
            "warnings": list(self.warnings),
            "counts": dict(self.counts),
            "quality": {k: q.to_dict() for k, q in self.quality.items()},
        }

    def save(self) -> Path:
        """Writes ``reconstruction.npz`` + ``reconstruction.json`` into ``out_dir``."""
        arrays: dict[str, np.ndarray] = {
            "points": self.points,
            "colors": self.colors,
            "offsets": self.offsets,
        }
        for i, name in enumerate(self.names):
            q = self.quality[name]
            for k in ("times", "posed", "keyframe", "rms", "n_inliers"):
                arrays[f"{i}_{k}"] = getattr(q, k)
            if name in self.cameras:
                c = self.cameras[name]
                arrays[f"{i}_R"], arrays[f"{i}_C"], arrays[f"{i}_K"] = c.R, c.C, c.K
        buf = io.BytesIO()
        np.savez(buf, **arrays)  # type: ignore[arg-type]
        atomic_write_bytes(self.out_dir / "reconstruction.npz", buf.getvalue())
        meta = self.to_dict()
        meta["reasons"] = {
            name: {str(k): v for k, v in self.quality[name].reasons.items()} for name in self.names
        }
        write_json(self.out_dir / "reconstruction.json", meta)
        return self.out_dir

    @classmethod
    def load(cls, out_dir: str | os.PathLike[str]) -> VideoReconstruction:
        """Reads what :meth:`save` (and :func:`reconstruct_videos`) wrote; nothing is
        recomputed. The lens of each wearer comes from the COLMAP model in ``model/``."""
        import pycolmap

        out = Path(out_dir)
        meta_p, npz_p = out / "reconstruction.json", out / "reconstruction.npz"
        if not meta_p.is_file() or not npz_p.is_file():
            raise ValueError(f"out_dir: {out} holds no saved video reconstruction")
        try:
            meta = json.loads(meta_p.read_text())
            if not isinstance(meta, dict) or not isinstance(meta.get("names"), list):
                raise ValueError("no list of names")
        except ValueError as exc:  # json's errors are ValueErrors too
            raise ValueError(f"out_dir: {meta_p} is damaged ({exc})") from None
        lenses: dict[str, Any] = {}
        if (out / "model").is_dir():
            rec = pycolmap.Reconstruction(str(out / "model"))
            for img in rec.images.values():
                lenses.setdefault(img.name.split("/")[0], rec.cameras[img.camera_id])
        try:
            return cls._from_saved(meta, npz_p, lenses, out)
        except (OSError, EOFError, KeyError, TypeError, zipfile.BadZipFile) as exc:
            raise ValueError(f"out_dir: {npz_p} does not match {meta_p} or is damaged "
                             f"({type(exc).__name__}: {exc})") from None  # fmt: skip

    @classmethod
    def _from_saved(
        cls, meta: dict[str, Any], npz_p: Path, lenses: dict[str, Any], out: Path
    ) -> VideoReconstruction:
        """The reconstruction from its saved arrays and metadata (:meth:`load`)."""
        cameras: dict[str, Cameras] = {}
        quality: dict[str, FrameQuality] = {}
        with open(npz_p, "rb") as fh, np.load(fh) as z:  # fh closed when np.load fails
            names = tuple(meta["names"])
            for i, name in enumerate(names):
                q = {k: z[f"{i}_{k}"] for k in ("times", "posed", "keyframe", "rms", "n_inliers")}
                reasons = {int(k): v for k, v in meta["reasons"][name].items()}
                quality[name] = FrameQuality(reasons=reasons, **q)
                if f"{i}_R" in z:
                    cam = Cameras(z[f"{i}_K"], z[f"{i}_R"], z[f"{i}_C"], q["times"][q["posed"]])
                    if name in lenses:
                        cam._colmap = [lenses[name]] * len(cam)
                    cameras[name] = cam
            points, colors, offsets = z["points"], z["colors"], z["offsets"]
        return cls(
            names=names,
            cameras=cameras,
            quality=quality,
            points=readonly(points),
            colors=readonly(colors),
            offsets=readonly(offsets),
            sync=meta["sync"],
            scale=float("nan") if meta["scale"] is None else float(meta["scale"]),
            unplaced=tuple(meta["unplaced"]),
            timings=meta["timings"],
            warnings=tuple(meta["warnings"]),
            counts=meta["counts"],
            out_dir=out,
        )


def _silence_glog() -> None:
    """COLMAP logs thousands of lines through glog (measured with pycolmap 3.11): keep
    warnings and errors."""
    import pycolmap

    logging = getattr(pycolmap, "logging", None)
    if logging is not None:
        for attr, value in (("minloglevel", 2), ("stderrthreshold", 2), ("verbose_level", 0)):
            if hasattr(logging, attr):
                setattr(logging, attr, value)
    os.environ.setdefault("GLOG_minloglevel", "2")


def _options(options: VideoSfmOptions | None, overrides: dict[str, Any]) -> VideoSfmOptions:
    base = VideoSfmOptions() if options is None else options
    if not isinstance(base, VideoSfmOptions):
        raise ValueError(f"options: expected VideoSfmOptions, got {type(base).__name__}")
    names = {f.name for f in fields(VideoSfmOptions)}
    for k in overrides:
        if k not in names:
            raise ValueError(f"{k}: not an option of reconstruct_videos ({sorted(names)})")
    return replace(base, **overrides) if overrides else base


def _resolve_sync(vids: list[Any], sync: Any) -> tuple[FloatArray, dict[str, Any]]:
    """Offsets ``(V,)`` on the common clock (``offsets[0] == 0``) and their description."""
    names = [v.info.name for v in vids]
    if sync is None:
        if len(vids) == 1:
            return np.zeros(1), {
                "names": names,
                "offsets": [0.0],
                "confidence": [1.0],
                "method": ["reference"],
            }
        silent = [str(v.info.path) for v in vids if not v.info.has_audio]
        if silent:
            raise ValueError(
                f"sync: {', '.join(silent)} has no audio track, so the videos cannot be "
                "synchronised from sound; pass manual offsets, e.g. "
                "sync={'" + names[0] + "': 0.0, ...} (seconds added to each video's local "
                "clock)"
            )
        from socialcam.sync import synchronize

        res = synchronize(vids)
    elif isinstance(sync, Mapping):
        given = {str(k): float(v) for k, v in sync.items()}
        unknown = sorted(set(given) - set(names))
        if unknown:
            raise ValueError(f"sync: no video named {unknown} (names are {names})")
        if set(given) >= set(names):
            off = np.array([given[n] for n in names]) - given[names[0]]
            return off, {
                "names": names,
                "offsets": off.tolist(),
                "confidence": [1.0] * len(names),
                "method": ["reference"] + ["manual"] * (len(names) - 1),
            }
        from socialcam.sync import synchronize

        res = synchronize(vids, manual_offsets=given)
    elif hasattr(sync, "offsets") and hasattr(sync, "names"):
        res = sync
    else:
        raise ValueError(
            f"sync: expected None, a SyncResult or a mapping name → offset, got {type(sync).__name__}"
        )
    if tuple(res.names) != tuple(names):
        raise ValueError(f"sync: names {list(res.names)} do not match the videos {names}")
    off = np.asarray(res.offsets, dtype=np.float64)
    n = len(names)
    conf = getattr(res, "confidence", None)
    method = getattr(res, "method", None)
    d = {
        "names": names,
        "offsets": off.tolist(),
        "confidence": [None] * n if conf is None else [float(c) for c in conf],
        "method": [None] * n if method is None else [str(m) for m in method],
    }
    return off, d


_PINHOLE_PARAMS = {
    # COLMAP parameter order; "f" = mean focal, "fx", "fy", "cx", "cy", then distortion.
    "SIMPLE_PINHOLE": ("f", "cx", "cy"),
    "PINHOLE": ("fx", "fy", "cx", "cy"),
    "SIMPLE_RADIAL": ("f", "cx", "cy"),
    "RADIAL": ("f", "cx", "cy"),
    "OPENCV": ("fx", "fy", "cx", "cy"),
    "SIMPLE_RADIAL_FISHEYE": ("f", "cx", "cy"),
    "RADIAL_FISHEYE": ("f", "cx", "cy"),
    "OPENCV_FISHEYE": ("fx", "fy", "cx", "cy"),
}
_N_DIST = {
    "SIMPLE_PINHOLE": 0,
    "PINHOLE": 0,
    "SIMPLE_RADIAL": 1,
    "RADIAL": 2,
    "OPENCV": 4,
    "SIMPLE_RADIAL_FISHEYE": 1,
    "RADIAL_FISHEYE": 2,
    "OPENCV_FISHEYE": 4,
}


def _colmap_params(model: str, K: FloatArray, dist: Sequence[float], who: str) -> list[float]:
    """COLMAP parameters of ``model`` from an OpenCV-convention ``K`` and the distortion
    coefficients in COLMAP order (SIMPLE_RADIAL: k; RADIAL: k1 k2; OPENCV: k1 k2 p1 p2;
    OPENCV_FISHEYE: k1..k4)."""
    if len(dist) != _N_DIST[model]:
        raise ValueError(
            f"intrinsics: {who}: {model} takes {_N_DIST[model]} distortion coefficients, "
            f"got {len(dist)}"
        )
    vals = {
        "f": (K[0, 0] + K[1, 1]) / 2,
        "fx": K[0, 0],
        "fy": K[1, 1],
        "cx": K[0, 2] - COLMAP_TO_OPENCV_PIXEL,
        "cy": K[1, 2] - COLMAP_TO_OPENCV_PIXEL,
    }
    return [float(vals[k]) for k in _PINHOLE_PARAMS[model]] + [float(d) for d in dist]


def _resolve_intrinsics(intrinsics: Any, names: list[str], model: str) -> dict[str, list[float]]:
    """``intrinsics`` (None, a sequence per video or a mapping name → ``(K, dist)``) as
    COLMAP parameters per person."""
    if intrinsics is None:
        return {}
    if isinstance(intrinsics, Mapping):
        unknown = sorted(set(map(str, intrinsics)) - set(names))
        if unknown:
            raise ValueError(f"intrinsics: no video named {unknown} (names are {names})")
        items = {str(k): v for k, v in intrinsics.items()}
    else:
        seq = list(intrinsics)
        if len(seq) != len(names):
            raise ValueError(f"intrinsics: expected {len(names)} entries, got {len(seq)}")
        items = dict(zip(names, seq, strict=True))
    out = {}
    for name, value in items.items():
        if value is None:
            continue
        try:
            K, dist = value
        except (TypeError, ValueError):
            raise ValueError(f"intrinsics: {name}: expected a pair (K, dist)") from None
        Km = as_float_array(K, f"intrinsics[{name}].K", (3, 3))
        d = as_float_array(dist, f"intrinsics[{name}].dist", (None,))
        if Km[0, 0] <= 0 or Km[1, 1] <= 0:
            raise ValueError(f"intrinsics: {name}: focal lengths must be positive")
        out[name] = _colmap_params(model, Km, list(d), name)
    return out


def _retrieval_pairs(
    db_path: Path,
    by_video: list[list[tuple[int, str]]],
    overlap: int,
    cross: int,
    seed: int,
) -> list[tuple[str, str]]:
    """Keyframe pairs to match: ``overlap`` following keyframes in the same video, and the
    ``cross`` most similar keyframes in each other video by a TF-IDF bag of SIFT words
    (a small vocabulary k-means'd here from the keyframes' own descriptors)."""
    import cv2
    import pycolmap

    pairs: set[tuple[str, str]] = set()
    for kfs in by_video:
        for i in range(len(kfs)):
            for j in range(i + 1, min(len(kfs), i + 1 + overlap)):
                pairs.add((kfs[i][1], kfs[j][1]))
    if cross == 0 or len(by_video) < 2:
        return sorted(pairs)
    flat = [(v, iid, name) for v, kfs in enumerate(by_video) for iid, name in kfs]
    db = pycolmap.Database.open(str(db_path))
    try:
        desc = [_descriptors(db.read_descriptors(iid)) for _, iid, _ in flat]
    finally:
        db.close()
    rng = np.random.default_rng(seed)
    pool = np.concatenate([d for d in desc if len(d)]) if any(len(d) for d in desc) else None
    if pool is None or len(pool) < 512:
        return sorted(pairs)
    sample = pool[rng.choice(len(pool), size=min(len(pool), 10000), replace=False)]
    n_words = 200
    cv2.setRNGSeed(seed)
    _, _, centres = cv2.kmeans(  # type: ignore[call-overload]
        sample,
        n_words,
        None,
        (cv2.TERM_CRITERIA_MAX_ITER | cv2.TERM_CRITERIA_EPS, 6, 1.0),
        1,
        cv2.KMEANS_PP_CENTERS,
    )
    c2 = (centres**2).sum(axis=1)
    hist = np.zeros((len(flat), n_words))
    for i, d in enumerate(desc):
        if len(d):
            words = np.argmin(c2[None, :] - 2.0 * d @ centres.T, axis=1)
            hist[i] = np.bincount(words, minlength=n_words)
    df = (hist > 0).sum(axis=0)
    idf = np.log(len(flat) / np.maximum(df, 1))
    tf = hist / np.maximum(hist.sum(axis=1, keepdims=True), 1)
    vec = tf * idf
    vec /= np.maximum(np.linalg.norm(vec, axis=1, keepdims=True), 1e-12)
    sim = vec @ vec.T
    video = np.array([v for v, _, _ in flat])
    # a short clip has few keyframes: each of them gets more cross pairs, so that every
    # pair of videos is tried on at least MIN_CROSS_PAIRS keyframe pairs each way
    per_video = [max(cross, -(-MIN_CROSS_PAIRS // max(1, len(k)))) for k in by_video]
    for i in range(len(flat)):
        for other in range(len(by_video)):
            if other == video[i]:
                continue
            s = np.where(video == other, sim[i], -np.inf)
            for j in np.argsort(-s, kind="stable")[: per_video[video[i]]]:
                if np.isfinite(s[j]):
                    a, b = sorted((flat[i][2], flat[j][2]))
                    pairs.add((a, b))
    return sorted(pairs)


def _descriptors(d: Any) -> npt.NDArray[np.float32]:
    """A keyframe's SIFT descriptors ``(N, 128)`` as float32 (pycolmap 4 wraps them)."""
    raw = d.data if hasattr(d, "data") else d
    return np.ascontiguousarray(np.asarray(raw), dtype=np.float32).reshape(-1, 128)


def _gravity_rotation(up: FloatArray) -> FloatArray:
    """Rotation taking the unit vector ``up`` to +z (the smallest such rotation)."""
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(up, z)
    c = float(up @ z)
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1 + c)


def _camera_up(R: FloatArray) -> FloatArray:
    """World "up" (unit) seen by head cameras ``R (N, 3, 3)`` (world→camera).

    People nod and look down far more than they tilt their head sideways, so the mean
    camera "up" (−y) leans towards where they looked (6–8° on 4-s rendered clips), while the
    camera x axes stay nearly horizontal: up is the direction most nearly perpendicular to
    all of them (the least eigenvector of Σ x xᵀ), signed like the mean −y. When the x axes
    span too narrow a range of headings for that to be defined, the mean −y is used."""
    minus_y = -R[:, 1, :].mean(axis=0)
    minus_y /= np.linalg.norm(minus_y)
    x = R[:, 0, :]
    w, vecs = np.linalg.eigh(x.T @ x / len(x))
    # w[0] ≈ 0 (roll noise) and w[1] ≳ sin² of the heading spread: well defined when the
    # headings spread over more than ~25° (w[1] > 0.05) and w[0] is clearly smaller.
    if w[1] < 0.05 or w[0] > 0.25 * w[1]:
        return np.asarray(minus_y)
    up = vecs[:, 0] * np.sign(vecs[:, 0] @ minus_y)
    return np.asarray(up)


def _floor_height(points: FloatArray, cam_heights: FloatArray, seed: int) -> float | None:
    """Height (along +z) of the floor: the densest horizontal layer of map points well below
    every camera, or ``None`` when there are too few points there."""
    if len(points) == 0 or len(cam_heights) == 0:
        return None
    lowest_cam = float(np.min(cam_heights))
    spread = float(np.ptp(cam_heights)) + 1e-9
    h = points[:, 2]
    # the lowest map points, robustly: a few badly triangulated points far below the floor
    # (seen: 6 m below on a 4-s clip) must not move the search window off the floor
    low = float(np.percentile(h, 1.0))
    below = h[(h < lowest_cam - 0.5 * (np.median(cam_heights) - low)) & (h >= low)]
    if len(below) < 30:
        return None
    # Densest thin slab (width 2 % of the camera-to-lowest-point range).
    width = max(0.02 * (lowest_cam - low), 1e-3 * spread)
    hs = np.sort(below)
    counts = np.searchsorted(hs, hs + width) - np.arange(len(hs))
    k = int(np.argmax(counts))
    if counts[k] < 30:
        return None
    slab = hs[k : k + counts[k]]
    return float(np.median(slab))


def _quat_wxyz(R: FloatArray) -> FloatArray:
    """Unit quaternions ``(N, 4)`` (w, x, y, z; w ≥ 0) of rotations ``(N, 3, 3)``."""
    from scipy.spatial.transform import Rotation  # type: ignore[import-untyped]

    q = Rotation.from_matrix(R).as_quat()  # x, y, z, w
    q = np.c_[q[:, 3], q[:, :3]]
    q[q[:, 0] < 0] *= -1
    return q


def _neighbour_outliers(
    idx: npt.NDArray[np.int64], C: FloatArray, R: FloatArray, jump: float, turn: float
) -> npt.NDArray[np.bool_]:
    """Posed frames (output indices ``idx``, centres ``C (N, 3)``, rotations ``R (N, 3, 3)``)
    that disagree with both temporal neighbours: centre farther than ``jump`` from the mean
    of the previous and next posed frames, or rotation more than ``turn`` radians from
    their mean; frames at the ends compare with the one neighbour they have (``2 jump``).
    Worst first: the frame that breaks its limits by the largest factor is dropped, and the
    others are judged again without it, so that one gross outlier (a keyframe registered
    1 m off, rendered seed 484) does not take its good neighbours with it."""
    n = len(idx)
    bad = np.zeros(n, bool)
    if n < 3:
        return bad
    live = list(range(n))

    def excess(a: int) -> float:
        """By what factor ``live[a]`` breaks its limits (≤ 1: it does not)."""
        i = live[a]
        nb = [
            live[b]
            for b in (a - 1, a + 1)
            if 0 <= b < len(live) and abs(int(idx[live[b]]) - int(idx[i])) <= 2
        ]
        if not nb:
            return 0.0
        c_ref = C[nb].mean(axis=0)
        u, _, vt = np.linalg.svd(R[nb].sum(axis=0))
        ang = np.arccos(np.clip((np.trace(R[i] @ (u @ vt).T) - 1) / 2, -1.0, 1.0))
        k = 1.0 if len(nb) == 2 else 2.0
        return float(max(np.linalg.norm(C[i] - c_ref) / (k * jump), ang / (k * turn)))

    ratio = [excess(a) for a in range(n)]
    while len(live) >= 3:
        worst = int(np.argmax(ratio))
        if ratio[worst] <= 1.0:
            break
        bad[live.pop(worst)] = True
        del ratio[worst]
        for a in (worst - 1, worst):  # only its two neighbours' neighbours changed
            if 0 <= a < len(live):
                ratio[a] = excess(a)
    return bad


def _check_video_args(
    videos: object,
    out_dir: object = "",
    sync: object = None,
    intrinsics: object = None,
    known_distance: object = None,
    eye_height: object = None,
    progress: object = True,
) -> tuple[list[str | os.PathLike[str]], KnownDistance | None, float | None]:
    """The arguments :func:`reconstruct_videos`, :func:`socialcam.poses` and
    :func:`socialcam.run` share, checked before any file is opened or written: ``videos``
    as a list of existing paths, ``known_distance`` as a :class:`KnownDistance` and
    ``eye_height`` as a float; the others by type. A ``ValueError`` names the argument."""
    if isinstance(videos, (str, os.PathLike)) or not isinstance(videos, Sequence):
        raise ValueError("videos: expected a sequence of video paths")
    if len(videos) == 0:
        raise ValueError("videos: no video given")
    for p in videos:
        if not isinstance(p, (str, os.PathLike)):
            raise ValueError(f"videos: expected paths, got {p!r}")
        if not os.path.exists(p):
            raise ValueError(f"videos: {p} does not exist")
    if not isinstance(out_dir, (str, os.PathLike)):
        raise ValueError(f"out_dir: expected a path, got {type(out_dir).__name__}")
    if not (sync is None or isinstance(sync, Mapping) or hasattr(sync, "offsets")):
        raise ValueError(
            f"sync: expected None, a SyncResult or a mapping name → offset, got {type(sync).__name__}"
        )
    if not (
        intrinsics is None
        or isinstance(intrinsics, Mapping)
        or (isinstance(intrinsics, Sequence) and not isinstance(intrinsics, (str, bytes)))
    ):
        raise ValueError(
            "intrinsics: expected None, one (K, dist) per video or a mapping name → (K, dist), "
            f"got {type(intrinsics).__name__}"
        )
    if known_distance is not None and not isinstance(known_distance, KnownDistance):
        try:
            known_distance = KnownDistance(*known_distance)  # type: ignore[misc]
        except TypeError:
            raise ValueError(
                "known_distance: expected KnownDistance(person_a, time_a, person_b, time_b, metres)"
            ) from None
    if eye_height is not None:
        eye_height = check_float(eye_height, "eye_height", min=0.0, min_exclusive=True)
    check_bool(progress, "progress")
    return list(videos), known_distance, eye_height  # type: ignore[return-value]


def reconstruct_videos(
    videos: Sequence[str | os.PathLike[str]],
    *,
    out_dir: str | os.PathLike[str],
    sync: Any = None,
    intrinsics: Any = None,
    known_distance: KnownDistance | tuple[str, float, str, float, float] | None = None,
    eye_height: float | None = None,
    options: VideoSfmOptions | None = None,
    progress: bool = True,
    **overrides: Any,
) -> VideoReconstruction:
    """Camera poses of every output frame of social-camera videos, on one clock, in one
    metric, gravity-aligned world frame (thesis App. A).

    Keyframes (``keyframe_fps``) go through SIFT, sequential matching inside each video,
    matching across videos between retrieved similar keyframes, and incremental mapping
    (pycolmap, CPU; one camera model per wearer). Every output frame (``fps``) between
    keyframes is then posed by tracking the previous keyframe's map points (KLT) and PnP;
    a frame whose pose cannot be trusted (too few inliers, reprojection RMS above
    ``max_rms``, disagreement with its neighbours) is dropped with its reason.

    Parameters
    ----------
    videos : video files (or folders of numbered frames); the file stem names the person.
    out_dir : working folder (keyframes, COLMAP database and model, our npz/json). Its saved
        result is reloaded by :meth:`VideoReconstruction.load`.
    sync : ``None`` (synchronise from the audio; one video needs none), a
        ``socialcam.sync.SyncResult``, or a mapping person → offset in seconds
        (``t_common = t_local + offset``; missing persons are synchronised from audio).
    intrinsics : ``None`` (self-calibrate), or per video (sequence, or mapping person →)
        ``(K (3, 3) OpenCV pixels, dist)`` with ``dist`` the distortion coefficients of
        ``camera_model`` in COLMAP order. Refined by bundle adjustment unless
        ``refine_intrinsics=False``; a warning says when they look wrong.
    known_distance : a :class:`KnownDistance` (or its 5 fields as a tuple) fixing the scale.
    eye_height : mean height of the cameras above the floor, metres (the floor is the
        densest horizontal layer of map points below the cameras). Ignored with
        ``known_distance``. Without either, the map's own (arbitrary) unit is kept.
    options, **overrides : :class:`VideoSfmOptions` and field overrides (``fps``,
        ``keyframe_fps``, ``camera_model``, ``global_mapping``, ``seed``, ...).
    progress : show progress bars on stderr.

    Returns
    -------
    VideoReconstruction
        Saved in ``out_dir`` (``model/`` COLMAP model in the world frame,
        ``reconstruction.npz``, ``reconstruction.json``).

    Raises
    ------
    ValueError
        A file that is not a video, videos without audio and no manual offsets, bad
        options, no model at all — naming the file or argument and what to do.
    """
    import pycolmap
    from tqdm import tqdm  # type: ignore[import-untyped]

    from socialcam.video import open_video

    opts = _options(options, overrides)
    videos, known_distance, eye_height = _check_video_args(
        videos, out_dir, sync, intrinsics, known_distance, eye_height, progress
    )
    _silence_glog()
    timings: dict[str, float] = {}
    warns: list[str] = []
    clock = time.perf_counter()

    def lap(stage: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        timings[stage] = timings.get(stage, 0.0) + now - clock
        clock = now

    vids = [open_video(Path(p)) for p in videos]
    names = [v.info.name for v in vids]
    if len(set(names)) != len(names):
        raise ValueError(f"videos: two videos share a file stem (person name): {names}")
    if known_distance is not None:
        for who in (known_distance.person_a, known_distance.person_b):
            if who not in names:
                raise ValueError(f"known_distance: no video named {who!r} (names are {names})")
    own_k = _resolve_intrinsics(intrinsics, names, opts.camera_model)
    if opts.same_lens:
        sizes = {(v.info.width, v.info.height) for v in vids}
        if len(sizes) > 1:
            raise ValueError(f"same_lens: the videos differ in frame size {sorted(sizes)}")
        if len({tuple(np.round(k, 6)) for k in own_k.values()}) > 1:
            raise ValueError("same_lens: the given intrinsics differ between videos")
    offsets, sync_info = _resolve_sync(vids, sync)
    for name, conf in zip(names, sync_info.get("confidence", []), strict=False):
        if conf is not None and float(conf) < 0.5:
            warns.append(f"{name}: synchronisation confidence {float(conf):.2f} is low")
    lap("sync")

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    kf_root = out / "keyframes"
    if kf_root.exists():
        shutil.rmtree(kf_root)
    step = opts.keyframe_step
    local_times: list[list[float]] = []
    kf_names: list[list[str]] = []
    bar = tqdm(total=len(vids), desc="keyframes", unit="video", disable=not progress)

    cache_root = out / "frames"
    if cache_root.exists():
        shutil.rmtree(cache_root)
    cache_root.mkdir()
    # The grey output frames are kept on disk for the posing pass (which then decodes
    # nothing) when the whole scene needs at most FRAME_CACHE_BYTES.
    cache_bytes = sum(
        vid.info.width * vid.info.height * (int(vid.info.duration * opts.fps) + 1) for vid in vids
    )
    caches: list[_FrameCache | None] = [
        _FrameCache(cache_root / f"{n}.gray") if cache_bytes <= FRAME_CACHE_BYTES else None
        for n in names
    ]

    def keyframes_of(v: int) -> tuple[list[float], list[str], str]:
        person, vid, cache = names[v], vids[v], caches[v]
        (kf_root / person).mkdir(parents=True)
        times: list[float] = []
        kfs: list[str] = []
        problem = ""
        # a short clip still gets MIN_KEYFRAMES keyframes (few views cannot join a model)
        n_out = max(1, int(vid.info.duration * opts.fps))
        select = KeyframeSelector(opts.keyframe_overlap, min(step, max(1, n_out // MIN_KEYFRAMES)))
        try:
            for k, fr in enumerate(_decoded(vid, opts.fps, gray=False)):
                if isinstance(fr, Exception):  # a decoder error ends this video, not the run
                    problem = (
                        f"{vid.info.path}: decoding stopped after {len(times)} output frames "
                        f"({type(fr).__name__}: {fr}); later frames are not posed"
                    )
                    break
                times.append(float(fr.time))
                gray = _gray(fr.image) if _usable(fr.image) else None
                if cache is not None:
                    cache.write(gray)
                if gray is not None and select(gray):
                    kf_name = f"{person}/{k:06d}.png"
                    _write_png(kf_root / kf_name, fr.image)
                    kfs.append(kf_name)
        finally:
            if cache is not None:
                cache.close()
        bar.update(1)
        return times, kfs, problem

    # One video per thread (decoding, KLT and PNG writing release the GIL); in video order.
    with ThreadPoolExecutor(max_workers=max(1, min(opts.num_threads, len(vids)))) as pool:
        for times, kfs, problem in pool.map(keyframes_of, range(len(vids))):
            local_times.append(times)
            kf_names.append(kfs)
            if problem:
                warns.append(problem)
    bar.close()
    lap("decode keyframes")

    db_path = out / "database.db"
    if db_path.exists():
        db_path.unlink()
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = opts.camera_model
    reader.default_focal_length_factor = opts.focal_factor
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = opts.num_threads
    extraction.sift.max_num_features = opts.max_features
    # No upsampled first octave: 3–4× less SIFT time on 640×480 frames for the same pose
    # accuracy (measured on rendered scenes); the keypoints it adds are the smallest scales.
    extraction.sift.first_octave = 0
    with _quiet(progress, "SIFT on keyframes"):
        pycolmap.extract_features(
            db_path,
            kf_root,
            camera_mode=(
                pycolmap.CameraMode.SINGLE if opts.same_lens else pycolmap.CameraMode.PER_FOLDER
            ),
            reader_options=reader,
            extraction_options=extraction,
            device=pycolmap.Device.cpu,
        )
    db = pycolmap.Database.open(str(db_path))
    try:
        images = {img.name: img for img in db.read_all_images()}
        # Given intrinsics replace the reader's guess; a fisheye lens (or a focal_prior the
        # user gave) starts from a focal length that the two-view verification trusts.
        trust_prior = opts.fisheye or opts.focal_prior is not None
        done: set[int] = set()
        for img in images.values():
            person = img.name.split("/")[0]
            if img.camera_id in done or not (person in own_k or trust_prior):
                continue
            cam = db.read_camera(img.camera_id)
            if person in own_k:
                cam.params = own_k[person]
            cam.has_prior_focal_length = True
            db.update_camera(cam)
            done.add(img.camera_id)
    finally:
        db.close()
    lap("features")

    by_video = [[(images[n].image_id, n) for n in kfs if n in images] for kfs in kf_names]
    # COLMAP's RANSAC draws from a process-wide generator seeded from the clock unless set.
    if hasattr(pycolmap, "set_random_seed"):
        pycolmap.set_random_seed(opts.seed)
    pairs = _retrieval_pairs(
        db_path, by_video, opts.sequential_overlap, opts.cross_pairs, opts.seed
    )
    pair_file = out / "pairs.txt"
    pair_file.write_text("".join(f"{a} {b}\n" for a, b in pairs))
    lap("retrieval")
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = opts.num_threads
    pairing = pycolmap.ImportedPairingOptions()
    pairing.match_list_path = str(pair_file)
    with _quiet(progress, f"matching {len(pairs)} keyframe pairs"):
        pycolmap.match_image_pairs(
            db_path,
            matching_options=matching,
            pairing_options=pairing,
            device=pycolmap.Device.cpu,
        )
    lap("matching")

    sparse = out / "sparse"
    if sparse.exists():
        shutil.rmtree(sparse)
    sparse.mkdir()
    with _quiet(progress, "mapping keyframes"):
        models = _map(
            db_path,
            kf_root,
            sparse,
            opts,
            fixed=bool(own_k) and not opts.refine_intrinsics,
            given=bool(own_k),
        )
    if not models:
        raise ValueError(
            "videos: no 3D model could be built from the keyframes (too little texture or "
            "overlap); try a higher keyframe_fps or more max_features"
        )
    best = max(models, key=lambda k: models[k].num_reg_images())
    rec = models[best]
    lap("mapping")

    # ---- which wearers are in the model, and their lenses
    # A registered keyframe must observe enough map points: pycolmap can leave an image
    # "registered" with no observation and a pose far away (seen: 300 units off).
    reg = {
        img.name: img
        for img in rec.images.values()
        if img.has_pose and img.num_points3D >= opts.min_inliers
    }
    n_bad_kf = sum(1 for img in rec.images.values() if img.has_pose) - len(reg)
    lens: dict[str, Any] = {}
    for img in reg.values():
        lens.setdefault(img.name.split("/")[0], rec.cameras[img.camera_id])
    unplaced = tuple(n for n in names if n not in lens)
    for n in unplaced:
        others = [
            k
            for k in models
            if k != best and any(i.name.startswith(n + "/") for i in models[k].images.values())
        ]
        where = " (it forms a separate model: it shares no view with the others)" if others else ""
        warns.append(
            f"{n}: could not be placed in the largest model{where}; its frames are not posed"
        )
    for n, params in own_k.items():
        if n in lens:
            f0 = params[0]
            f1 = float(lens[n].params[0])
            if abs(f1 - f0) > 0.05 * f0:
                warns.append(
                    f"{n}: the given intrinsics look wrong (focal {f0:.1f} px, the videos "
                    f"say {f1:.1f} px); the poses are not to be trusted: rerun with "
                    "intrinsics=None to self-calibrate"
                    if opts.refine_intrinsics
                    else f"{n}: the given intrinsics look wrong (focal {f0:.1f} px)"
                )
    if own_k and not opts.refine_intrinsics:
        err = float(rec.compute_mean_reprojection_error())
        if err > 1.0:
            warns.append(
                f"mean keyframe reprojection error {err:.2f} px with the given (fixed) "
                "intrinsics: they may be wrong; rerun with refine_intrinsics=True"
            )

    # ---- every output frame: keyframes from the mapper, the rest by KLT + PnP
    quality: dict[str, FrameQuality] = {}
    raw_R: dict[str, FloatArray] = {}
    raw_t: dict[str, FloatArray] = {}
    splits: dict[str, FloatArray] = {}
    total = sum(len(t) for n, t in zip(names, local_times, strict=True) if n in lens)
    bar = tqdm(total=total, desc="posing frames", unit="frame", disable=not progress)

    def pose_one(v: int) -> tuple[FloatArray, FloatArray, FloatArray, FrameQuality, str]:
        name, vid = names[v], vids[v]
        F = len(local_times[v])
        Rs = np.full((F, 3, 3), np.nan)
        ts = np.full((F, 3), np.nan)
        rms = np.full(F, np.nan)
        n_inl = np.zeros(F, np.int64)
        is_kf = np.zeros(F, bool)
        reasons: dict[int, str] = {}
        split = np.full((F, 2), np.nan)
        problem = ""
        if name not in lens:
            reasons = dict.fromkeys(range(F), "wearer not placed in the model")
        else:
            problem = _pose_video(
                vid if caches[v] is None else caches[v],
                name,
                F,
                rec,
                reg,
                lens[name],
                opts,
                bar,
                Rs,
                ts,
                rms,
                n_inl,
                is_kf,
                reasons,
                split,
            )
        q = FrameQuality(
            times=readonly(np.asarray(local_times[v], dtype=np.float64) + offsets[v]),
            posed=np.isfinite(Rs[:, 0, 0]),
            keyframe=is_kf,
            rms=rms,
            n_inliers=n_inl,
            reasons=reasons,
        )
        return Rs, ts, split, q, problem

    # One video per thread: OpenCV's tracking and PnP release the GIL. Results are
    # gathered in video order, so the outcome does not depend on the scheduling.
    with ThreadPoolExecutor(max_workers=max(1, min(opts.num_threads, len(vids)))) as pool:
        posed_videos = list(pool.map(pose_one, range(len(vids))))
    for name, (Rs, ts, split, q, problem) in zip(names, posed_videos, strict=True):
        if problem:
            warns.append(problem)
        raw_R[name], raw_t[name], splits[name], quality[name] = Rs, ts, split, q
    bar.close()
    for vid in vids:
        if hasattr(vid, "close"):
            vid.close()
    shutil.rmtree(cache_root, ignore_errors=True)
    lap("posing frames")

    cent: dict[str, FloatArray] = {
        name: -np.einsum("fji,fj->fi", np.nan_to_num(raw_R[name]), np.nan_to_num(raw_t[name]))
        for name in lens
    }

    # ---- world frame: gravity from the cameras' horizontal x axes, metric scale
    kf_R = np.array(
        [
            (
                img.cam_from_world() if callable(img.cam_from_world) else img.cam_from_world
            ).rotation.matrix()
            for img in reg.values()
        ]
    )
    G = _gravity_rotation(_camera_up(kf_R))
    ids = sorted(rec.points3D)
    pts_m = np.array([rec.points3D[i].xyz for i in ids]).reshape(-1, 3)
    cols = np.array([rec.points3D[i].color for i in ids], dtype=np.uint8).reshape(-1, 3)
    kf_C = np.array([img.projection_center() for img in reg.values()])
    first = next(n for n in names if n in lens)
    first_C = np.array(
        [img.projection_center() for img in reg.values() if img.name.startswith(first + "/")]
    )
    g_pts = pts_m @ G.T
    g_cams = kf_C @ G.T
    floor = _floor_height(g_pts, g_cams[:, 2], opts.seed)
    scale = float("nan")
    if known_distance is not None:
        ca = _centre_at(known_distance.person_a, known_distance.time_a, quality, cent, opts.fps)
        cb = _centre_at(known_distance.person_b, known_distance.time_b, quality, cent, opts.fps)
        d = float(np.linalg.norm(ca - cb))
        if d <= 0:
            raise ValueError("known_distance: the two camera centres coincide in the map")
        scale = known_distance.metres / d
    elif eye_height is not None:
        if floor is None:
            warns.append(
                "eye_height: no floor found among the map points; the map's own unit is kept (give known_distance instead)"
            )
        else:
            scale = eye_height / float(np.mean(g_cams[:, 2]) - floor)
    else:
        warns.append("no known_distance or eye_height: poses are in the map's own unit, not metres")
    s = 1.0 if not np.isfinite(scale) else scale

    # ---- neighbour check: a frame between keyframes whose pose jumps away from both its
    # neighbours (more than max_jump metres, or 2 % of the median keyframe-to-point depth
    # without a metric scale; or more than max_turn) is dropped.
    if np.isfinite(scale):
        jump = opts.max_jump / s
    else:
        depth = [
            np.median(
                np.linalg.norm(_keyframe_observations(rec, im)[1] - im.projection_center(), axis=1)
            )
            for im in list(reg.values())[:: max(1, len(reg) // 20)]
        ]
        jump = 0.2 * float(np.median(depth))
    for name in lens:
        q = quality[name]
        sp = splits[name]
        with np.errstate(invalid="ignore"):
            split_bad = q.posed & (
                (sp[:, 0] > jump * opts.max_split / opts.max_jump)
                | (sp[:, 1] > opts.max_split_turn)
            )
        for k in map(int, np.flatnonzero(split_bad)):
            q.reasons[int(k)] = (
                f"the tracks of the keyframes before and after disagree ({sp[k, 0] * s:.3g} "
                f"{'m' if np.isfinite(scale) else 'map units'}, {np.degrees(sp[k, 1]):.2f}°)"
            )
            q.posed[k] = False
            q.rms[k] = np.nan
        idx = np.flatnonzero(q.posed)
        # keyframes too: pycolmap can register one with hundreds of inliers far from where
        # the frames around it are (rendered seed 484: 391 inliers, 1.04 m off)
        bad = _neighbour_outliers(idx, cent[name][idx], raw_R[name][idx], jump, opts.max_turn)
        for k in idx[bad]:
            q.reasons[int(k)] = "jumps away from both neighbours"
            q.posed[k] = False
            q.rms[k] = np.nan
    origin = (first_C @ G.T).mean(axis=0)
    if floor is not None:
        origin[2] = floor
    # X_world = s G X_map + t
    tvec = -s * origin
    world_pts = s * g_pts + tvec

    cameras: dict[str, Cameras] = {}
    for name in lens:
        q = quality[name]
        idx = np.flatnonzero(q.posed)
        Rw = raw_R[name][idx] @ G.T
        Cw = s * cent[name][idx] @ G.T + tvec
        K = np.asarray(lens[name].calibration_matrix(), dtype=np.float64).copy()
        K[0, 2] += COLMAP_TO_OPENCV_PIXEL
        K[1, 2] += COLMAP_TO_OPENCV_PIXEL
        posed_cams = Cameras(K, Rw, Cw, q.times[idx])
        posed_cams._colmap = [lens[name]] * len(idx)
        cameras[name] = posed_cams
    sim = pycolmap.Sim3d(s, pycolmap.Rotation3d(G), tvec)
    rec.transform(sim)
    model_dir = out / "model"
    if model_dir.exists():
        shutil.rmtree(model_dir)
    model_dir.mkdir()
    rec.write(str(model_dir))
    lap("world frame")

    n_frames = sum(len(q.times) for q in quality.values())
    n_posed = sum(int(q.posed.sum()) for q in quality.values())
    counts = {
        "keyframes": sum(len(k) for k in kf_names),
        "registered_keyframes": len(reg),
        "keyframes_rejected": n_bad_kf,
        "pairs": len(pairs),
        "models": len(models),
        "points": len(world_pts),
        "frames": n_frames,
        "posed": n_posed,
        "keyframe_rms": float(rec.compute_mean_reprojection_error()),
        "floor_found": floor is not None,
        "focal": {n: float(lens[n].params[0]) for n in lens},
    }
    if n_frames and n_posed / n_frames < 0.9:
        warns.append(
            f"only {n_posed} of {n_frames} frames posed ({100 * n_posed / n_frames:.1f} %)"
        )
    result = VideoReconstruction(
        names=tuple(names),
        cameras=cameras,
        quality=quality,
        points=readonly(world_pts),
        colors=readonly(cols),
        offsets=readonly(np.asarray(offsets, dtype=np.float64)),
        sync=sync_info,
        scale=scale,
        unplaced=unplaced,
        timings=timings,
        warnings=tuple(warns),
        counts=counts,
        out_dir=out,
    )
    result.save()
    for w in warns:
        warnings.warn(w, VideoPosesWarning, stacklevel=2)
    return result


class VideoPosesWarning(UserWarning):
    """Something a user of :func:`reconstruct_videos` should know (low confidence, dropped
    wearers, wrong intrinsics, no scale)."""


def _decoded(vid: Any, fps: float, *, gray: bool) -> Iterator[Any]:
    """The frames of ``vid`` at ``fps``; a decoder exception is yielded (and ends the
    stream) instead of raised, so that one broken file does not end the run."""
    it = iter(vid.frames(fps=fps, gray=gray))
    while True:
        try:
            fr = next(it)
        except StopIteration:
            return
        except Exception as exc:
            yield exc
            return
        yield fr


#: largest total size of the grey output frames kept on disk between the keyframe pass
#: and the posing pass (above it, the videos are decoded twice instead)
FRAME_CACHE_BYTES = 4 * 2**30


class _FrameCache:
    """Grey frames written once, in order, to a raw file, then read back one at a time
    (never all in memory); ``None`` stands for an unreadable frame."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._file: Any = open(path, "wb")
        self._shapes: list[tuple[int, int] | None] = []

    def write(self, gray: npt.NDArray[np.uint8] | None) -> None:
        if gray is None:
            self._shapes.append(None)
            return
        self._file.write(np.ascontiguousarray(gray, dtype=np.uint8).tobytes())
        self._shapes.append((gray.shape[0], gray.shape[1]))

    def close(self) -> None:
        self._file.close()

    def frames(self) -> Iterator[npt.NDArray[np.uint8] | None]:
        with open(self.path, "rb") as f:
            for shape in self._shapes:
                if shape is None:
                    yield None
                    continue
                buf = bytearray(shape[0] * shape[1])
                f.readinto(buf)
                yield np.frombuffer(buf, dtype=np.uint8).reshape(shape)


def _usable(img: Any) -> bool:
    return (
        isinstance(img, np.ndarray)
        and img.ndim in (2, 3)
        and img.size > 0
        and img.dtype == np.uint8
    )


def _gray(image: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
    import cv2

    if image.ndim == 2:
        return image
    return np.asarray(cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY))


def _write_png(path: Path, image: npt.NDArray[np.uint8]) -> None:
    import cv2

    bgr = image[:, :, ::-1] if image.ndim == 3 else image
    if not cv2.imwrite(str(path), np.ascontiguousarray(bgr)):
        raise OSError(f"cannot write keyframe {path}")


class _quiet:
    """A one-line progress note around a pycolmap stage (which prints nothing itself)."""

    def __init__(self, progress: bool, what: str) -> None:
        self.progress, self.what = progress, what

    def __enter__(self) -> None:
        if self.progress:
            print(f"{self.what} ...", file=sys.stderr, flush=True)

    def __exit__(self, *exc: object) -> None:
        return None


def _map(
    db_path: Path,
    kf_root: Path,
    sparse: Path,
    opts: VideoSfmOptions,
    *,
    fixed: bool,
    given: bool = False,
) -> dict[int, Any]:
    import pycolmap

    if opts.global_mapping:
        g = pycolmap.GlobalPipelineOptions()
        for path in ("mapper.global_positioning.use_gpu", "mapper.bundle_adjustment.ceres.use_gpu"):
            obj = g
            *head, last = path.split(".")
            try:
                for h in head:
                    obj = getattr(obj, h)
                setattr(obj, last, False)
            except AttributeError:
                pass
        if hasattr(g, "num_threads"):
            g.num_threads = opts.num_threads
        if hasattr(g, "random_seed"):
            g.random_seed = opts.seed
        return dict(pycolmap.global_mapping(db_path, kf_root, sparse, options=g))
    inc = pycolmap.IncrementalPipelineOptions()
    inc.num_threads = opts.num_threads
    # A global bundle adjustment each time the model grows by half (COLMAP: 10 %): a third
    # less mapping time on video keyframes, same poses (measured on rendered scenes; the
    # final global adjustment is always run).
    inc.ba_global_frames_ratio = 1.5
    inc.ba_global_points_ratio = 1.5
    # One refinement round per bundle adjustment (COLMAP: 2 local, 5 global) and global
    # adjustments without the points that add no new view: 40 % less mapping time on
    # video keyframes for the same keyframe reprojection error (measured on rendered
    # scenes; the frames between keyframes are posed by PnP afterwards anyway).
    # Given intrinsics that are refined keep COLMAP's 5 global rounds: a wrong focal length
    # moves back towards the truth only over several rounds (1 round left it 25 % off).
    inc.ba_local_max_refinements = 1
    inc.ba_global_max_refinements = 5 if given and not fixed else 1
    inc.mapper.ba_global_ignore_redundant_points3D = True
    if hasattr(inc, "random_seed"):
        inc.random_seed = opts.seed
    if fixed:
        inc.ba_refine_focal_length = False
        inc.ba_refine_principal_point = False
        inc.ba_refine_extra_params = False
    models = dict(pycolmap.incremental_mapping(db_path, kf_root, sparse, options=inc))
    if not models or opts.retry_min_inliers == 0:
        return models
    best = max(models, key=lambda k: models[k].num_reg_images())
    db = pycolmap.Database.open(str(db_path))
    try:
        n_images = db.num_images()
    finally:
        db.close()
    if models[best].num_reg_images() >= n_images:
        return models
    # A second chance for the keyframes the first pass left out: the map as it stands,
    # extended with a lower bar for registering an image. The frames around such a keyframe
    # still pass the per-frame checks (split, jump) afterwards. On rendered 3-wearer × 6 s
    # scenes (benches/sfm_second_pass.py) it placed the keyframes left out in 3 runs of 4
    # (135 → 180 frames posed), changed nothing where all were placed, and at 15 inliers
    # instead of 20 once registered a keyframe 0.33 m off.
    inc.mapper.abs_pose_min_num_inliers = opts.retry_min_inliers
    more = sparse.parent / (sparse.name + "_more")
    if more.exists():
        shutil.rmtree(more)
    more.mkdir()
    extended = dict(
        pycolmap.incremental_mapping(
            db_path, kf_root, more, options=inc, input_path=str(sparse / str(best))
        )
    )
    if extended:
        ext = max(extended.values(), key=lambda r: r.num_reg_images())
        if ext.num_reg_images() > models[best].num_reg_images():
            models[best] = ext
    return models


def _pose_video(
    vid: Any,
    name: str,
    F: int,
    rec: Any,
    reg: dict[str, Any],
    lens: Any,
    opts: VideoSfmOptions,
    bar: Any,
    Rs: FloatArray,
    ts: FloatArray,
    rms: FloatArray,
    n_inl: npt.NDArray[np.int64],
    is_kf: npt.NDArray[np.bool_],
    reasons: dict[int, str],
    split: FloatArray,
    lk: dict[str, Any] | None = None,
) -> str:
    """Poses the output frames of one video (``vid``, or its grey frames kept by a
    :class:`_FrameCache`; fills the arrays in place): registered
    keyframes from the model; the frames between two keyframes from the map points of both,
    tracked forward from the one before and backward from the one after, then PnP; with
    both, ``split (F, 2)`` receives the distance (map units) and angle (radians) between the
    poses from each side's tracks alone. Holds at
    most one keyframe interval of grey frames. ``lk``: the Lucas–Kanade settings (default
    those of the output rate). Returns a warning ('' if none)."""
    from socialcam._posetrack import solve_pnp, track

    kf: tuple[Any, FloatArray, FloatArray, FloatArray, FloatArray] | None
    kf = None  # the last registered keyframe: gray, px, X, R, t
    pending: list[tuple[int, Any]] = []

    def flush(nxt: tuple[Any, ...] | None) -> None:
        if not pending:
            return
        grays = [g for _, g in pending]
        fwd = track(kf[0], kf[1], kf[2], grays, fb_px=1.0, lk=lk) if kf is not None else None
        bwd = (
            track(nxt[0], nxt[1], nxt[2], grays[::-1], fb_px=1.0, lk=lk)[::-1]
            if nxt is not None
            else None
        )
        for j, (k, _) in enumerate(pending):
            parts = [p[j] for p in (fwd, bwd) if p is not None]
            px = np.concatenate([p[0] for p in parts])
            X = np.concatenate([p[1] for p in parts])
            # The nearer keyframe's pose starts the PnP iterations.
            near = kf if (nxt is None or (kf is not None and j < len(pending) / 2)) else nxt
            assert near is not None
            fp = solve_pnp(
                lens,
                px,
                X,
                (near[3], near[4]),
                min_inliers=opts.min_inliers,
                max_rms=opts.max_rms,
                ransac_px=opts.ransac_px,
                seed=opts.seed,
            )
            if fp.R is None or fp.t is None:
                reasons[k] = fp.reason
                continue
            Rs[k], ts[k], rms[k], n_inl[k] = fp.R, fp.t, fp.rms, fp.n_inliers
            if len(parts) == 2:
                # Two independent poses, from the tracks of each keyframe: their
                # disagreement is measured here and judged once the scale is known.
                one = [
                    solve_pnp(
                        lens,
                        p[0],
                        p[1],
                        (fp.R, fp.t),
                        min_inliers=opts.min_inliers,
                        max_rms=opts.max_rms,
                        ransac_px=opts.ransac_px,
                        seed=opts.seed,
                    )
                    for p in parts
                ]
                a, b = one
                if a.R is not None and b.R is not None and a.t is not None and b.t is not None:
                    split[k, 0] = np.linalg.norm(a.R.T @ a.t - b.R.T @ b.t)
                    cosang = (np.trace(a.R @ b.R.T) - 1) / 2
                    split[k, 1] = np.arccos(np.clip(cosang, -1.0, 1.0))
        pending.clear()

    message = ""
    frames = vid.frames() if isinstance(vid, _FrameCache) else _decoded(vid, opts.fps, gray=True)
    for k, fr in enumerate(frames):
        if isinstance(fr, Exception):  # a decoder error: what was posed stays
            message = (
                f"{vid.info.path}: decoding failed while posing after {k} output frames "
                f"({type(fr).__name__}: {fr}); later frames are not posed"
            )
            break
        if k >= F:
            break
        bar.update(1)
        gray = None if fr is None else np.ascontiguousarray(getattr(fr, "image", fr))
        if gray is None or not _usable(gray):
            reasons[k] = "unreadable frame"
            continue
        im = reg.get(f"{name}/{k:06d}.png")
        if im is None:
            pending.append((k, gray))
            continue
        pose = im.cam_from_world() if callable(im.cam_from_world) else im.cam_from_world
        R = np.asarray(pose.rotation.matrix(), dtype=np.float64)
        t = np.asarray(pose.translation, dtype=np.float64)
        px, X, r = _keyframe_observations(rec, im)
        keep = spread_subset(px, gray.shape, TRACKED_POINTS)
        nxt = (gray, px[keep], X[keep], R, t)
        flush(nxt)
        kf = nxt
        Rs[k], ts[k], rms[k], n_inl[k], is_kf[k] = R, t, r, len(px), True
    flush(None)
    for k in range(F):
        if np.isnan(Rs[k, 0, 0]) and k not in reasons:
            reasons[k] = "frame not decoded"
    return message


#: fewest cross-video keyframe pairs tried between two videos, each way (short clips get
#: more than ``cross_pairs`` per keyframe)
MIN_CROSS_PAIRS = 30

#: fewest keyframes per video (the keyframe interval shrinks for short clips)
MIN_KEYFRAMES = 6

#: map points of a keyframe followed into the frames around it: more add little to a
#: PnP pose and cost tracking time in proportion
TRACKED_POINTS = 250


def spread_subset(px: FloatArray, shape: tuple[int, ...], n: int) -> npt.NDArray[np.int64]:
    """Indices of at most ``n`` of the pixels ``px (N, 2)`` spread evenly over an image of
    ``shape``: an 8 × 6 grid, taken round-robin over its cells in the given order."""
    if len(px) <= n:
        return np.arange(len(px))
    h, w = shape[:2]
    cell = np.clip((px[:, 0] * 8 // max(w, 1)), 0, 7) + 8 * np.clip(px[:, 1] * 6 // max(h, 1), 0, 5)
    cell = cell.astype(np.int64)
    # rank of each point within its cell (stable: first come, first ranked)
    order = np.argsort(cell, kind="stable")
    first = np.searchsorted(cell[order], cell[order])
    rank = np.empty(len(px), np.int64)
    rank[order] = np.arange(len(px)) - first
    return np.sort(np.lexsort((np.arange(len(px)), rank))[:n])


def _keyframe_observations(rec: Any, image: Any) -> tuple[FloatArray, FloatArray, float]:
    """Raw pixels (OpenCV convention) ``(N, 2)`` and map points ``(N, 3)`` a registered
    keyframe observes, and their reprojection RMS in pixels."""
    px, X, err = [], [], []
    for p in image.points2D:
        if p.has_point3D():
            px.append(np.asarray(p.xy, dtype=np.float64) + COLMAP_TO_OPENCV_PIXEL)
            pt = rec.points3D[p.point3D_id]
            X.append(pt.xyz)
            err.append(pt.error)
    if not px:
        return np.zeros((0, 2)), np.zeros((0, 3)), float("nan")
    return np.array(px), np.array(X), float(np.sqrt(np.mean(np.square(err))))


def _centre_at(
    person: str,
    t: float,
    quality: dict[str, FrameQuality],
    centres: dict[str, FloatArray],
    fps: float,
) -> FloatArray:
    """Camera centre of ``person`` at common time ``t``: the posed frame at ``t`` (within
    half a frame), else linearly interpolated between the posed frames around ``t`` when
    both lie within 0.5 s."""
    q = quality.get(person)
    if q is None or person not in centres or not q.posed.any():
        raise ValueError(f"known_distance: {person} has no posed frame")
    idx = np.flatnonzero(q.posed)
    ts = q.times[idx]
    k = int(np.argmin(np.abs(ts - t)))
    if abs(ts[k] - t) <= 0.5 / fps:
        return centres[person][idx[k]]
    before, after = idx[ts <= t], idx[ts > t]
    if len(before) and len(after):
        i, j = before[-1], after[0]
        if t - q.times[i] <= 0.5 and q.times[j] - t <= 0.5:
            w = (t - q.times[i]) / (q.times[j] - q.times[i])
            return (1 - w) * centres[person][i] + w * centres[person][j]
    raise ValueError(
        f"known_distance: {person} has no posed frame near t={t} s; give a time at which "
        "that camera is posed"
    )


@dataclass(frozen=True)
class PoseErrors:
    """Posed frames against ground truth after one similarity fit of all camera centres.

    ``centre (N,)`` metres (in the truth's unit) and ``rotation (N,)`` radians, per posed
    frame (every wearer, in ``names`` order); ``person (N,)`` index into ``names``;
    ``scale`` the fitted truth-per-estimate scale; ``n_truth`` frames the truth has at the
    output times (posed or not).
    """

    names: tuple[str, ...]
    person: npt.NDArray[np.int64]
    centre: FloatArray
    rotation: FloatArray
    scale: float

    def __post_init__(self) -> None:
        readonly_fields(self)

    def to_dict(self) -> dict[str, Any]:
        return {
            "n": len(self.centre),
            "centre_median_m": float(np.median(self.centre)),
            "centre_p95_m": float(np.percentile(self.centre, 95)),
            "centre_max_m": float(self.centre.max()),
            "rotation_median_deg": float(np.degrees(np.median(self.rotation))),
            "rotation_max_deg": float(np.degrees(self.rotation.max())),
            "scale": self.scale,
        }


def pose_errors(
    rec: VideoReconstruction, truth: Mapping[str, Cameras], *, time_tol: float = 1e-3
) -> PoseErrors:
    """Compares the posed frames of ``rec`` with true cameras (person → ``Cameras`` with
    ``times`` on the common clock): each posed frame is matched to the true frame nearest
    in time (within ``time_tol`` s), then one similarity (Umeyama, :func:`align_similarity`)
    maps every estimated centre onto the truth."""
    from socialcam.geometry import align_similarity

    est_C, true_C, est_R, true_R, who = [], [], [], [], []
    for i, name in enumerate(rec.names):
        cam = rec.cameras.get(name)
        if cam is None or len(cam) == 0 or name not in truth:
            continue
        tc = truth[name]
        if tc.times is None or cam.times is None:
            raise ValueError(f"truth: {name} has no times")
        order = np.argsort(tc.times)
        ts = tc.times[order]
        j = np.clip(np.searchsorted(ts, cam.times), 1, len(ts) - 1)
        j = np.where(np.abs(ts[j - 1] - cam.times) < np.abs(ts[j] - cam.times), j - 1, j)
        gap = np.abs(ts[j] - cam.times)
        if gap.max() > time_tol:
            raise ValueError(
                f"truth: {name} has no true frame within {time_tol} s of t={cam.times[np.argmax(gap)]:.4f}"
            )
        k = order[j]
        est_C.append(cam.C)
        true_C.append(tc.C[k])
        est_R.append(cam.R)
        true_R.append(tc.R[k])
        who.append(np.full(len(cam), i))
    if not est_C:
        raise ValueError("rec: no posed frame to compare")
    E, T = np.concatenate(est_C), np.concatenate(true_C)
    s, Rs, t = align_similarity(E, T)
    centre = np.linalg.norm(s * E @ Rs.T + t - T, axis=1)
    # Estimated world→camera R_e, aligned world: R_e Rsᵀ.
    Ra = np.concatenate(est_R) @ Rs.T
    cosang = (np.einsum("nij,nij->n", Ra, np.concatenate(true_R)) - 1) / 2
    rot = np.arccos(np.clip(cosang, -1.0, 1.0))
    return PoseErrors(tuple(rec.names), np.concatenate(who), centre, rot, float(s))


class _Window:
    """Every frame of an opened video with local time in ``[start, end]``, as the stream
    :func:`_pose_video` reads (it asks for frames at a rate; the window ignores it)."""

    def __init__(self, vid: Any, start: float, end: float) -> None:
        self.vid, self.start, self.end, self.info = vid, start, end, vid.info

    def frames(self, fps: float | None = None, *, gray: bool = False) -> Iterator[Any]:
        return iter(self.vid.frames(start=self.start, end=self.end, gray=gray))


def pose_segment(
    rec: VideoReconstruction,
    video: str | os.PathLike[str],
    t0: float,
    t1: float,
    *,
    options: VideoSfmOptions | None = None,
    **overrides: Any,
) -> Cameras:
    """Camera poses of EVERY frame of ``video`` (the video's own rate, not ``fps``) whose
    time on the common clock lies in ``[t0, t1]``, in the world frame of ``rec`` (a saved
    :func:`reconstruct_videos` result of the same videos).

    The frames are registered against the existing map exactly as the output frames
    between keyframes are: KLT tracks of the map points that the registered keyframes
    around them observe, PnP, and the same checks (``min_inliers``, ``max_rms``, the
    forward/backward ``max_split`` and the neighbour ``max_jump`` / ``max_turn``, in metres
    when ``rec`` is metric, else relative to the map's depth). Nothing is mapped anew, so
    the cost is that of tracking the segment's frames: meant for short segments that need
    every frame, such as the gaze calibration of Eq 3.1, whose 3-12 Hz head jitter a
    10 Hz sampling aliases.

    Parameters
    ----------
    rec : the reconstruction (its ``out_dir`` must hold the ``model/`` it saved).
    video : the video of one person of ``rec`` (its file stem names the person).
    t0, t1 : the segment, seconds on the common clock, ``t0 < t1``.
    options, **overrides : :class:`VideoSfmOptions` (those of ``rec``), field overrides.

    Returns
    -------
    Cameras
        The posed frames of the segment (unposed frames are left out), ``times`` on the
        common clock; possibly empty.

    Raises
    ------
    ValueError
        A video of no person of ``rec``, a bad segment, a ``rec`` without its saved model.
    """
    from socialcam.video import open_video

    opts = _options(options, overrides)
    a = check_float(t0, "t0")
    b = check_float(t1, "t1")
    if not b > a:
        raise ValueError(f"t1: must exceed t0 ({a}), got {b}")
    name = Path(video).stem
    if name not in rec.names:
        raise ValueError(f"video: {name} is not one of the persons {list(rec.names)}")
    model_dir = rec.out_dir / "model"
    if not (model_dir / "images.bin").is_file() and not (model_dir / "images.txt").is_file():
        raise ValueError(f"rec: {rec.out_dir} holds no saved model (model/)")
    offset = float(rec.offsets[rec.names.index(name)])
    vid = open_video(Path(video))
    try:
        return _pose_window(rec, vid, name, a - offset, b - offset, offset, opts, model_dir)
    finally:
        if hasattr(vid, "close"):
            vid.close()


def _pose_window(
    rec: VideoReconstruction,
    vid: Any,
    name: str,
    lo: float,
    hi: float,
    offset: float,
    opts: VideoSfmOptions,
    model_dir: Path,
) -> Cameras:
    """:func:`pose_segment` on the opened ``vid`` of ``name``, local times ``[lo, hi]``."""
    import pycolmap

    q = rec.quality[name]
    model = pycolmap.Reconstruction(str(model_dir))
    kf_time: dict[float, Any] = {}
    lens = None
    for img in model.images.values():
        person, _, stem = img.name.partition("/")
        if person != name or not img.has_pose or img.num_points3D < opts.min_inliers:
            continue
        k = int(Path(stem).stem)
        if k < len(q.times):
            kf_time[float(q.times[k]) - offset] = img
            lens = model.cameras[img.camera_id]
    times = vid.timestamps()
    empty = Cameras(np.eye(3), np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros(0))
    if lens is None or len(times) == 0:
        return empty
    # from the last keyframe at or before the segment to the first at or after it
    before = [t for t in kf_time if t <= lo]
    after = [t for t in kf_time if t >= hi]
    start = max(before) if before else lo
    end = min(after) if after else hi
    window = np.flatnonzero((times >= start - 1e-6) & (times <= end + 1e-6))
    if len(window) == 0:
        return empty
    wt = times[window]
    reg_w: dict[str, Any] = {}
    half = 0.5 * float(np.median(np.diff(times))) if len(times) > 1 else 1.0
    for t, img in kf_time.items():
        j = int(np.argmin(np.abs(wt - t)))
        if abs(wt[j] - t) <= half:
            reg_w[f"{name}/{j:06d}.png"] = img
    F = len(window)
    Rs, ts = np.full((F, 3, 3), np.nan), np.full((F, 3), np.nan)
    rms, n_inl = np.full(F, np.nan), np.zeros(F, np.int64)
    is_kf, split = np.zeros(F, bool), np.full((F, 2), np.nan)
    reasons: dict[int, str] = {}

    class _NoBar:
        def update(self, n: int) -> None:
            return None

    src = _Window(vid, float(wt[0]) - 1e-6, float(wt[-1]) + 1e-6)
    _pose_video(
        src, name, F, model, reg_w, lens, opts, _NoBar(), Rs, ts, rms, n_inl, is_kf, reasons,
        split, _LK_VIDEO_RATE,
    )  # fmt: skip
    posed = np.isfinite(Rs[:, 0, 0])
    C = -np.einsum("fji,fj->fi", np.nan_to_num(Rs), np.nan_to_num(ts))
    if np.isfinite(rec.scale):
        jump = opts.max_jump
    else:  # the map's unit: 0.2 of the median keyframe-to-point depth, as reconstruct_videos
        depth = [
            np.median(
                np.linalg.norm(
                    _keyframe_observations(model, im)[1] - im.projection_center(), axis=1
                )
            )
            for im in reg_w.values()
        ] or [1.0]
        jump = 0.2 * float(np.median(depth))
    with np.errstate(invalid="ignore"):
        posed &= ~(
            (split[:, 0] > jump * opts.max_split / opts.max_jump)
            | (split[:, 1] > opts.max_split_turn)
        )
    idx = np.flatnonzero(posed)
    bad = _neighbour_outliers(idx, C[idx], Rs[idx], jump, opts.max_turn) & ~is_kf[idx]
    posed[idx[bad]] = False
    keep = posed & (wt >= lo - 1e-6) & (wt <= hi + 1e-6)
    if not keep.any():
        return empty
    K = np.asarray(lens.calibration_matrix(), dtype=np.float64).copy()
    K[0, 2] += COLMAP_TO_OPENCV_PIXEL
    K[1, 2] += COLMAP_TO_OPENCV_PIXEL
    cams = Cameras(K, Rs[keep], C[keep], wt[keep] + offset)
    cams._colmap = [lens] * int(keep.sum())
    return cams
