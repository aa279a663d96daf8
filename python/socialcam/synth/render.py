"""Rendered first-person videos with exact ground truth: the test bed of issue 9.

:func:`render_scene` renders ``n_wearers`` head-mounted cameras walking in a room whose
walls, floor, ceiling, boxes and pillars carry rich non-repetitive textures (procedural
dead-leaves images, optionally mixed with real photographs), writes one H.264 + AAC mp4
per wearer (PyAV) and the ground truth (``truth.npz`` + a readable ``truth.json``).

What is simulated (all seeded, all recorded in :class:`SceneTruth`):

- **Walking**: wearers walk around one closed loop (an ellipse around a central pillar) in
  the same direction with evenly spread phases, speeding up and slowing down, drifting in
  and out, with a 2 Hz head bob — smooth paths that never collide.
- **Gaze** (thesis Sec 3.1): every ~1–3 s a wearer looks at something else — one of the
  moving targets (small textured cubes), another wearer's head, or a random point on the
  walls ("around"). The true gaze ray goes from the eye centre ``p`` to the point of
  regard; the head (primary gaze ``v``) follows it with a rate-limited smooth pursuit
  (≤ 200°/s) and deviates from it by a smooth eye-in-head offset ``m(t)`` whose
  components have standard deviation ``h`` on the plane at unit distance (true gaze
  through ``v + m``).
- **Head-mounted camera**: fixed per wearer — the eye centre at ``eye_offset`` in the
  camera frame and the primary gaze along ``primary_dir`` in the camera frame (camera
  pitched a few degrees down from the gaze), so ``p = Rᵀ eye_offset + C`` and
  ``v = Rᵀ primary_dir`` (the calibration unknowns of Eq 3.1), plus a small head roll.
- **Calibration** (Sec 3.2.1, for issue 10): right after its video starts, each wearer
  stops, turns to a still point on the central pillar, steps to about 1.3 m from it and
  fixates it while moving back and forth (±0.45 m), side to side (±0.35 m) and up and
  down and rolling the head (±15°); the eye-in-head deviation is then fast jitter (3–12 Hz)
  of the same spread ``h`` and the head follows the point without lag
  (``calibration[v] = (t0, t1, point)`` on the true clock; the ``CALIB_*`` constants).
- **Clocks**: wearer ``v``'s first frame is at true time ``start[v]`` (different for
  each); frame ``k`` at ``start[v] + k / fps``. The common clock of the pipeline starts
  at the first frame of the first video: ``t_common = t_true - start[0]``.
- **Audio**: 48 kHz mono per wearer: independent pink background noise at a different
  gain per wearer, independent speech-like bursts, and claps at known true times (the
  same sound for everyone, at a different loudness per wearer). By default the sound
  reaches every wearer at the clap's true time (no propagation delay); pass
  ``sound_speed=343.0`` to delay it by the wearer's distance to the clap / speed.
- **Lens**: pinhole by default; ``distortion="radial"`` (OpenCV ``k1, k2``; COLMAP
  ``RADIAL``) or ``"fisheye"`` (OpenCV fisheye ``k1..k4``; COLMAP ``OPENCV_FISHEYE``),
  rendered by remapping a larger pinhole image.

Other wearers appear as textured boxes (torso and head); ``head_textures`` puts a given
image on the front of each head (a hook for faces in later issues).

Run ``python -m socialcam.synth.render --ship`` to regenerate the short scene shipped in
``socialcam/data/scene/``.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from socialcam._validate import FloatArray, check_choice, check_float, check_int, check_seed
from socialcam.camera import Cameras
from socialcam.synth.cameras import look_at
from socialcam.synth.raster import Plane, Renderer, _Batch, face
from socialcam.synth.texture import load_photos, photo_texture, procedural_texture

U8Image = npt.NDArray[np.uint8]
IntArray = npt.NDArray[np.int64]

AUDIO_RATE = 48000
N_SHELL = 6  # the first planes of a room are its walls, floor and ceiling (convex shell)
GRID_HZ = 240.0  # simulation grid of the motion (frames interpolate it)
PRE_ROLL = 2.0  # s simulated before true time 0, so that the first frames are settled
#: target codes in ``SceneTruth.target_of``: ``k ≥ 0`` moving target ``k``; ``AROUND``
#: a point on the walls; ``CALIBRATION`` the calibration point; ``HEAD - w`` wearer ``w``.
AROUND = -1
CALIBRATION = -2
HEAD = -10


# ----------------------------------------------------------------------------- truth
@dataclass(frozen=True)
class SceneTruth:
    """Ground truth of a rendered scene (``V`` wearers, ``F_v`` frames each).

    Attributes
    ----------
    names : (V,) video names (``wearer0``, ...), the file stems
    start : (V,) true time of each video's first frame, s
    fps : nominal frame rate
    size : (width, height) in pixels
    K : (V, 3, 3) intrinsics, pixel (0, 0) at the centre of the top-left pixel
    dist : per wearer ``{"model": "pinhole" | "radial" | "fisheye", "params": [...],
        "colmap_model": ..., "colmap_params": [...]}``. ``params`` are OpenCV
        coefficients: radial ``[k1, k2]`` (``cv2.projectPoints`` with ``(k1, k2, 0, 0)``),
        fisheye ``[k1, k2, k3, k4]`` (``cv2.fisheye``); ``colmap_params`` the full COLMAP
        camera parameters (``RADIAL``: f, cx, cy, k1, k2; ``OPENCV_FISHEYE``: fx, fy, cx,
        cy, k1..k4; ``PINHOLE``: fx, fy, cx, cy) in COLMAP's pixel convention (+0.5).
    frame_times : per wearer (F_v,) on the TRUE clock, s
    R : per wearer (F_v, 3, 3) world→camera rotations
    C : per wearer (F_v, 3) camera centres, metres
    eye_offset : (V, 3) eye centre in the camera frame, metres
    primary_dir : (V, 3) primary gaze direction in the camera frame (unit)
    h : (V,) eye-in-head spread: std of each component of ``m`` at unit distance
    eyes : per wearer (F_v, 3) eye centres ``p`` in the world
    gaze : per wearer (F_v, 3) primary gaze directions ``v`` in the world (unit)
    gaze_true : per wearer (F_v, 3) true gaze directions (unit, eye → regard)
    regard : per wearer (F_v, 3) points of regard
    target_of : per wearer (F_v,) what is looked at: ``k ≥ 0`` moving target ``k``,
        ``-1`` a point on the walls, ``-2`` the calibration point, ``-10 - w`` the head of
        person ``w`` (wearers ``0 … V - 1``, then the people without a camera)
    target_times : (T,) true times at which ``target_positions`` are sampled
    target_positions : (T, n_targets, 3) centres of the moving targets
    calibration : per wearer ``(t0, t1, point (3,))``, true clock
    claps : (n,) true times of the claps, s
    clap_position : (3,) where the claps happen
    sound_speed : m/s used for propagation delay, or ``None`` (no delay)
    audio_rate : Hz
    room : ``{"size": [W, D, H], "planes": [Plane.to_dict(), ...]}`` static surfaces
    seed : the scene seed
    n_people : people without a camera (persons ``V … V + n_people - 1``); 0 unless
        rendered with ``n_people``
    face_landmarks : with ``faces=True``, per wearer ``(F_v, P, 5, 3)`` world positions of
        the five face landmarks (``socialcam.faces.LANDMARKS`` order) of every person
        ``P = V + n_people`` at that wearer's frame times (the viewer's own face too,
        though it is not drawn); empty otherwise
    face_normal : per wearer ``(F_v, P, 3)`` unit normal of each face (the head direction
        the head is drawn with: turned and pitched)
    face_visible : per wearer ``(F_v, P)`` the face is drawn in that frame: all five
        landmarks inside the image, turned towards the camera by less than 75°, the ray
        to the face unobstructed, not the viewer's own face
    face_size : per wearer ``(F_v, P)`` frontal face size in pixels, ``f · 0.13 m / depth``
        (the side of the box a detector draws around a frontal face)
    face_regard : per wearer ``(F_v, P, 3)`` the point every person looks at (at that
        wearer's frame times): the eye centre of the person looked at, or a point that
        nobody else shares (code ``-1``)
    face_target : per wearer ``(F_v, P)`` what every person looks at, codes as in
        ``target_of`` (``-10 - q``: the head of person ``q``, wearers first)
    """

    names: tuple[str, ...]
    start: FloatArray
    fps: float
    size: tuple[int, int]
    K: FloatArray
    dist: tuple[dict[str, Any], ...]
    frame_times: tuple[FloatArray, ...]
    R: tuple[FloatArray, ...]
    C: tuple[FloatArray, ...]
    eye_offset: FloatArray
    primary_dir: FloatArray
    h: FloatArray
    eyes: tuple[FloatArray, ...]
    gaze: tuple[FloatArray, ...]
    gaze_true: tuple[FloatArray, ...]
    regard: tuple[FloatArray, ...]
    target_of: tuple[IntArray, ...]
    target_times: FloatArray
    target_positions: FloatArray
    calibration: tuple[tuple[float, float, FloatArray], ...]
    claps: FloatArray
    clap_position: FloatArray
    sound_speed: float | None
    audio_rate: int
    room: dict[str, Any]
    seed: int
    n_people: int = 0
    face_landmarks: tuple[FloatArray, ...] = ()
    face_normal: tuple[FloatArray, ...] = ()
    face_visible: tuple[npt.NDArray[np.bool_], ...] = ()
    face_size: tuple[FloatArray, ...] = ()
    face_regard: tuple[FloatArray, ...] = ()
    face_target: tuple[IntArray, ...] = ()

    @property
    def offsets(self) -> FloatArray:
        """Exact offsets ``start[v] - start[0]`` (common clock = local + offset)."""
        return self.start - self.start[0]

    def cameras(self, v: int) -> Cameras:
        """Wearer ``v``'s cameras with ``times`` on the COMMON clock (``t_true - start[0]``)."""
        return Cameras(self.K[v], self.R[v], self.C[v], self.frame_times[v] - self.start[0])

    def to_dict(self) -> dict[str, Any]:
        """Everything except the per-frame arrays (those are in ``truth.npz``)."""
        return {
            "names": list(self.names),
            "start": self.start.tolist(),
            "offsets": self.offsets.tolist(),
            "fps": self.fps,
            "size": list(self.size),
            "n_frames": [len(t) for t in self.frame_times],
            "K": self.K.tolist(),
            "dist": list(self.dist),
            "eye_offset": self.eye_offset.tolist(),
            "primary_dir": self.primary_dir.tolist(),
            "h": self.h.tolist(),
            "calibration": [
                {"t0": t0, "t1": t1, "point": p.tolist()} for t0, t1, p in self.calibration
            ],
            "claps": self.claps.tolist(),
            "clap_position": self.clap_position.tolist(),
            "sound_speed": self.sound_speed,
            "audio_rate": self.audio_rate,
            "room": self.room,
            "seed": self.seed,
            **({"n_people": self.n_people, "faces": True} if self.face_landmarks else {}),
            "clock": "true clock; common clock = true - start[0]; local = true - start[v]",
            "target_codes": {
                "k>=0": "moving target k",
                str(AROUND): "a point on the walls",
                str(CALIBRATION): "the calibration point",
                f"{HEAD}-w": "the head of person w (wearers first, then people)",
            },
        }


_PER_WEARER = ("frame_times", "R", "C", "eyes", "gaze", "gaze_true", "regard", "target_of")
_FACE_TRUTH = ("face_landmarks", "face_normal", "face_visible", "face_size")
_FACE_TRUTH_OPT = ("face_regard", "face_target")  # absent from scenes rendered before


def save_truth(truth: SceneTruth, path: str | Path) -> Path:
    """Writes ``truth.npz`` (all arrays) and ``truth.json`` (readable summary) atomically;
    returns the npz path."""
    path = Path(path)
    arrays: dict[str, np.ndarray] = {
        "start": truth.start,
        "K": truth.K,
        "eye_offset": truth.eye_offset,
        "primary_dir": truth.primary_dir,
        "h": truth.h,
        "target_times": truth.target_times,
        "target_positions": truth.target_positions,
        "claps": truth.claps,
        "clap_position": truth.clap_position,
        "meta": np.array(json.dumps(truth.to_dict())),
    }
    for name in _PER_WEARER + _FACE_TRUTH + _FACE_TRUTH_OPT:
        for v, a in enumerate(getattr(truth, name)):
            arrays[f"{name}_{v}"] = a
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez_compressed(tmp, **arrays)  # type: ignore[arg-type]
    os.replace(tmp, path)
    js = path.with_suffix(".json")
    tmpj = js.with_name(js.name + ".tmp")
    tmpj.write_text(json.dumps(truth.to_dict(), indent=1))
    os.replace(tmpj, js)
    return path


def load_truth(path: str | Path) -> SceneTruth:
    """Reads a ``truth.npz`` written by :func:`render_scene` (or its folder)."""
    p = Path(path)
    if p.is_dir():
        p = p / "truth.npz"
    try:
        z = np.load(p, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise ValueError(f"path: cannot read scene truth from {p} ({exc})") from None
    with z:
        meta = json.loads(str(z["meta"]))
        V = len(meta["names"])
        per = {name: tuple(z[f"{name}_{v}"] for v in range(V)) for name in _PER_WEARER}
        if meta.get("faces"):
            per |= {name: tuple(z[f"{name}_{v}"] for v in range(V)) for name in _FACE_TRUTH}
            per |= {
                name: tuple(z[f"{name}_{v}"] for v in range(V))
                for name in _FACE_TRUTH_OPT
                if f"{name}_0" in z
            }
        return SceneTruth(
            names=tuple(meta["names"]),
            start=z["start"],
            fps=float(meta["fps"]),
            size=(int(meta["size"][0]), int(meta["size"][1])),
            K=z["K"],
            dist=tuple(meta["dist"]),
            eye_offset=z["eye_offset"],
            primary_dir=z["primary_dir"],
            h=z["h"],
            target_times=z["target_times"],
            target_positions=z["target_positions"],
            calibration=tuple(
                (float(c["t0"]), float(c["t1"]), np.array(c["point"])) for c in meta["calibration"]
            ),
            claps=z["claps"],
            clap_position=z["clap_position"],
            sound_speed=meta["sound_speed"],
            audio_rate=int(meta["audio_rate"]),
            room=meta["room"],
            seed=int(meta["seed"]),
            n_people=int(meta.get("n_people", 0)),
            **per,  # type: ignore[arg-type]
        )


@dataclass(frozen=True)
class RenderedScene:
    """What :func:`render_scene` wrote: ``videos`` (``out_dir/<name>.mp4`` in order),
    ``truth_path`` (``out_dir/truth.npz``), the ``truth`` itself and the ``room`` (static
    planes with their textures, to check renders against)."""

    videos: tuple[Path, ...]
    truth_path: Path
    truth: SceneTruth
    room: Room
    render_seconds: float


# ----------------------------------------------------------------------------- room
@dataclass(frozen=True)
class Room:
    """Static surfaces: ``planes`` and their ``textures`` (RGB uint8), ``size (W, D, H)``
    (x ∈ [-W/2, W/2], y ∈ [-D/2, D/2], z ∈ [0, H], z up), the central ``pillar``
    half-width and the loop the wearers walk on (semi-axes ``loop``)."""

    size: tuple[float, float, float]
    planes: tuple[Plane, ...]
    textures: tuple[U8Image, ...]
    pillar: float
    loop: tuple[float, float]

    def to_dict(self) -> dict[str, Any]:
        return {
            "size": list(self.size),
            "pillar_half_width": self.pillar,
            "loop_semi_axes": list(self.loop),
            "planes": [p.to_dict() for p in self.planes],
        }


def _tex_size(width_m: float, height_m: float, texel: float) -> tuple[int, int]:
    m = 16
    return (
        max(m, round(height_m / texel / m) * m),
        max(m, round(width_m / texel / m) * m),
    )


def build_room(
    size: tuple[float, float, float] = (8.0, 6.0, 3.0),
    *,
    seed: int = 0,
    photos: Sequence[U8Image] | None = None,
    texel: float = 0.008,
) -> Room:
    """The room of a scene: walls, floor, ceiling, a central pillar, two corner pillars and
    boxes along the walls, each face with its own texture (``texel`` metres per texel on
    the large surfaces, half that on boxes)."""
    W, D, H = (float(s) for s in size)
    if W < 5.0 or D < 4.0 or H < 2.4:
        raise ValueError(f"room_size: at least 5 × 4 × 2.4 m, got {W} × {D} × {H}")
    rng = np.random.default_rng([check_seed(seed), 101])
    specs: list[tuple[str, FloatArray, FloatArray, float, float, FloatArray | None, float]] = []

    def add(name: str, c: Any, n: Any, w: float, h: float, right: Any = None, tx: float = texel):
        specs.append(
            (
                name,
                np.asarray(c, float),
                np.asarray(n, float),
                w,
                h,
                None if right is None else np.asarray(right, float),
                tx,
            )
        )

    add("wall+y", (0, D / 2, H / 2), (0, -1, 0), W, H)
    add("wall-y", (0, -D / 2, H / 2), (0, 1, 0), W, H)
    add("wall+x", (W / 2, 0, H / 2), (-1, 0, 0), D, H)
    add("wall-x", (-W / 2, 0, H / 2), (1, 0, 0), D, H)
    add("floor", (0, 0, 0), (0, 0, 1), W, D, (1, 0, 0), 1.25 * texel)
    add("ceiling", (0, 0, H), (0, 0, -1), W, D, (1, 0, 0), 1.5 * texel)

    def box(name: str, cx: float, cy: float, hx: float, hy: float, hz: float) -> None:
        for sx, n in ((1, (1, 0, 0)), (-1, (-1, 0, 0))):
            add(
                f"{name}{'+' if sx > 0 else '-'}x",
                (cx + sx * hx, cy, hz),
                n,
                2 * hy,
                2 * hz,
                tx=texel / 2,
            )
        for sy, n in ((1, (0, 1, 0)), (-1, (0, -1, 0))):
            add(
                f"{name}{'+' if sy > 0 else '-'}y",
                (cx, cy + sy * hy, hz),
                n,
                2 * hx,
                2 * hz,
                tx=texel / 2,
            )
        if hz * 2 < H - 1e-6:
            add(f"{name}.top", (cx, cy, 2 * hz), (0, 0, 1), 2 * hx, 2 * hy, (1, 0, 0), texel / 2)

    pillar = 0.25
    box("pillar", 0.0, 0.0, pillar, pillar, H / 2)
    for k, (sx, sy) in enumerate(((1, 1), (-1, -1))):
        box(f"cpillar{k}", sx * (W / 2 - 0.55), sy * (D / 2 - 0.55), 0.2, 0.2, H / 2)
    # boxes along the walls, one per wall stretch
    for k, (wall_axis, sgn) in enumerate(((1, 1), (1, -1), (0, 1), (0, -1), (1, 1), (1, -1))):
        depth = rng.uniform(0.25, 0.4)
        half_w = rng.uniform(0.3, 0.6)
        hz = rng.uniform(0.3, 0.9)
        if wall_axis == 1:  # along a y wall
            span = W / 2 - 1.3
            lo, hi = (-span, -0.4) if k < 4 else (0.4, span)
            cx = rng.uniform(lo + half_w, hi - half_w) if hi - lo > 2 * half_w else (lo + hi) / 2
            cy = sgn * (D / 2 - depth - 0.02)
            box(f"box{k}", cx, cy, half_w, depth, hz)
        else:
            span = D / 2 - 1.3
            cy = rng.uniform(-span + half_w, span - half_w) if span > half_w else 0.0
            cx = sgn * (W / 2 - depth - 0.02)
            box(f"box{k}", cx, cy, depth, half_w, hz)
    planes = []
    textures = []
    for i, (name, c, n, w, h, right, tx) in enumerate(specs):
        th, tw = _tex_size(w, h, tx)
        tseed = int(rng.integers(0, 2**31))
        if photos:
            tex = photo_texture(photos, th, tw, seed=tseed)
        else:
            tex = procedural_texture(th, tw, seed=tseed, palette=i % 6)
        planes.append(face(name, c, n, w, h, i, right))
        textures.append(tex)
    loop = (W / 2 - 1.9, D / 2 - 1.55)
    return Room((W, D, H), tuple(planes), tuple(textures), pillar, loop)


# ----------------------------------------------------------------------------- motion
def _smooth(rng: np.random.Generator, n: int, fmin: float, fmax: float) -> Callable[..., Any]:
    """A smooth zero-mean random signal of unit standard deviation: a sum of ``n``
    sinusoids with random frequencies in ``[fmin, fmax]`` Hz and phases."""
    f = rng.uniform(fmin, fmax, n)
    ph = rng.uniform(0, 2 * np.pi, n)
    a = np.sqrt(2.0 / n)

    def sig(t: npt.ArrayLike) -> FloatArray:
        tt = np.asarray(t, dtype=np.float64)[..., None]
        return np.asarray(a * np.sin(2 * np.pi * f * tt + ph).sum(axis=-1))

    return sig


def _rot_from_z(d: FloatArray) -> FloatArray:
    """The minimal rotation taking ``e_z`` to the unit vector ``d``."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, d)
    s, c = np.linalg.norm(axis), float(z @ d)
    if s < 1e-12:
        return np.eye(3)
    k = axis / s
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * Kx + (1 - c) * Kx @ Kx


@dataclass
class _Motion:
    """Everything that moves, on the simulation grid ``t`` (G,)."""

    t: FloatArray
    eyes: FloatArray  # (G, V, 3)
    head: FloatArray  # (G, V, 3) primary gaze v (world)
    regard: FloatArray  # (G, V, 3)
    code: IntArray  # (G, V)
    roll: FloatArray  # (G, V)
    body_yaw: FloatArray  # (G, V)
    targets: Callable[[npt.ArrayLike], FloatArray]  # t (...,) -> (..., n_targets, 3)
    people_eyes: FloatArray | None = None  # (G, Q, 3) people without a camera
    people_head: FloatArray | None = None  # (G, Q, 3) their head directions (unit)
    people_regard: FloatArray | None = None  # (G, Q, 3) what they look at
    people_code: IntArray | None = None  # (G, Q) target codes of what they look at

    def at(self, name: str, t: npt.ArrayLike) -> FloatArray:
        """Linear interpolation of a grid quantity at times ``t`` (...,)."""
        arr = getattr(self, name)
        tt = np.asarray(t, dtype=np.float64)
        x = (tt - self.t[0]) / (self.t[1] - self.t[0])
        i = np.clip(np.floor(x).astype(np.int64), 0, len(self.t) - 2)
        w = np.clip(x - i, 0.0, 1.0)
        w = w.reshape(w.shape + (1,) * (arr.ndim - 1))
        return np.asarray((1 - w) * arr[i] + w * arr[i + 1])

    def code_at(self, t: npt.ArrayLike, name: str = "code") -> IntArray:
        x = np.round((np.asarray(t, dtype=np.float64) - self.t[0]) / (self.t[1] - self.t[0]))
        arr: IntArray = getattr(self, name)
        return arr[np.clip(x.astype(np.int64), 0, len(self.t) - 1)]


#: range of motion of a calibration segment (thesis Sec 3.2.1 and 6.2: "move back and forth
#: and side to side at least three times" while fixating one point): amplitudes in metres of
#: the eye's side-to-side, back-and-forth (towards the point) and up-and-down motion, the
#: head's roll in degrees, the distance to the point the wearer steps to, how long before
#: the segment the wearer turns to the point (s) and the band (Hz) of the eye-in-head jitter
#: while fixating. The back and forth (about 0.85 to 1.8 m from the point) is what tells the
#: eye offset from the gaze direction in Eq 3.1; the roll turns the camera about the ray.
CALIB_SWAY, CALIB_DEPTH, CALIB_BOB = 0.35, 0.45, 0.08
CALIB_ROLL_DEG = 15.0
CALIB_DISTANCE = 1.3
CALIB_TURN = 1.5
CALIB_FAST = (3.0, 12.0)
#: range of the wearers' eye-in-head spread ``h`` (radians at unit distance, 0.9–2°: "the eye
#: orientation varies by a small degree" from the primary gaze, Sec 3.1)
H_RANGE = (0.015, 0.035)


def _ramp(tau: FloatArray, length: float, rise: float) -> FloatArray:
    """1 inside ``[0, length]`` except smooth (C¹) rises of ``rise`` s at both ends; 0 outside."""
    r = min(rise, length / 2)
    x = np.clip(np.minimum(tau, length - tau) / r, 0.0, 1.0)
    return np.asarray(x * x * (3 - 2 * x))


def _range_of_motion(
    tau: FloatArray, length: float, approach: float, rng: np.random.Generator
) -> FloatArray:
    """Eye displacement ``(n, 3)`` at times ``tau`` into a calibration segment, as (side to
    side, towards the point, up and down): ``approach`` metres closer, and about three
    periods of each motion (fewer in segments under 5 s: people do not sway faster than
    about 0.6 Hz), smoothly starting and stopping."""
    win = _ramp(tau, length, 0.6)
    f = rng.uniform(0.8, 1.2, 3) * np.array([3.0, 3.5, 2.5]) / max(length, 5.0)
    ph = rng.uniform(0, 2 * np.pi, 3)
    amp = np.array([CALIB_SWAY, CALIB_DEPTH, CALIB_BOB])
    d = amp * np.sin(2 * np.pi * f * tau[:, None] + ph)
    d[:, 1] -= approach
    return np.asarray(win[:, None] * d)


def _plan_motion(
    room: Room,
    n_wearers: int,
    t_end: float,
    calib: Sequence[tuple[float, float]],
    h: FloatArray,
    rng: np.random.Generator,
    n_targets: int,
) -> tuple[_Motion, FloatArray]:
    """Walking, gaze targets and head motion of every wearer on a ``GRID_HZ`` grid."""
    dt = 1.0 / GRID_HZ
    t = np.arange(-PRE_ROLL, t_end + 2 * dt, dt)
    G, V = len(t), n_wearers
    ax, ay = room.loop
    _W, _D, _H = room.size
    # --- walking: phase on the loop; frozen while calibrating
    walking = np.ones((G, V))
    for v, (c0, c1) in enumerate(calib):
        walking[(t >= c0) & (t < c1), v] = 0.0
    s = np.cumsum(walking, axis=0) * dt  # walking time
    speed = rng.uniform(0.45, 0.6)
    omega = speed / (0.5 * (ax + ay))
    spacing = 2 * np.pi / V
    amp = min(0.25, 0.2 * spacing)
    phase0 = rng.uniform(0, 2 * np.pi) + spacing * np.arange(V)
    eyes = np.empty((G, V, 3))
    eye_h = rng.uniform(1.55, 1.75, V)
    # the range of motion draws from its own stream: the rest of a scene does not depend on it
    rng_c = rng.spawn(1)[0]
    calib_pts = np.empty((V, 3))
    for v in range(V):
        mod = _smooth(rng, 3, 0.03, 0.1)
        rad = _smooth(rng, 3, 0.05, 0.15)
        phi = phase0[v] + omega * s[:, v] + amp * mod(s[:, v])
        rho = 1.0 + 0.08 * rad(s[:, v])
        x = ax * rho * np.cos(phi)
        y = ay * rho * np.sin(phi)
        step_hz = rng.uniform(1.8, 2.1)
        z = eye_h[v] + 0.02 * np.sin(2 * np.pi * step_hz * s[:, v])
        eyes[:, v] = np.c_[x, y, z]
        # calibration: fixate the pillar face towards the wearer and move (range of motion)
        c0, c1 = calib[v]
        i0 = int(np.clip(np.searchsorted(t, c0), 0, G - 1))
        pos = eyes[i0, v]
        axis = int(np.argmax(np.abs(pos[:2]) / np.array([ax, ay])))
        normal = np.zeros(3)
        normal[axis] = np.sign(pos[axis]) or 1.0
        along = float(np.clip(pos[1 - axis] * 0.3, -0.1, 0.1))
        calib_pts[v] = normal * room.pillar + np.array([0, 0, eye_h[v] - 0.05])
        calib_pts[v][1 - axis] = along
        inside = (t >= c0) & (t < c1)
        if inside.any():
            # step towards the point to about CALIB_DISTANCE, then move around there: back
            # and forth along the line to the point (not the pillar face's normal, which
            # from a corner of the loop runs nearly across that line: depth ratios down to
            # 1.1 and one wearer in 1920 whose Eq 3.1 was rightly refused)
            away = np.r_[(pos - calib_pts[v])[:2], 0.0]
            dist = float(np.linalg.norm(away))
            away = away / dist if dist > 1e-9 else normal
            approach = max(0.0, dist - CALIB_DISTANCE)
            eyes[inside, v] += _range_of_motion(
                t[inside] - c0, c1 - c0, approach, rng_c
            ) @ np.stack([np.cross([0.0, 0.0, 1.0], away), away, np.array([0.0, 0.0, 1.0])])
    vel = np.gradient(eyes[:, :, :2], dt, axis=0)
    body_yaw = np.unwrap(np.arctan2(vel[..., 1], vel[..., 0]), axis=0)
    # --- moving targets: Lissajous paths around the pillar
    targets = _plan_targets(rng, n_targets)
    tg = targets(t)  # (G, T, 3)
    # --- what each wearer looks at: segments of 1–3 s
    code = np.empty((G, V), np.int64)
    regard = np.empty((G, V, 3))
    for v in range(V):
        k = 0
        while k < G:
            n = int(rng.uniform(1.0, 3.0) * GRID_HZ)
            sl = slice(k, min(G, k + n))
            r = rng.uniform()
            others = [w for w in range(V) if w != v]
            if r < 0.35 and others:
                w = int(rng.choice(others))
                code[sl, v] = HEAD - w
                regard[sl, v] = eyes[sl, w]
            elif r < 0.7 and n_targets > 0:
                j = int(rng.integers(0, n_targets))
                code[sl, v] = j
                regard[sl, v] = tg[sl, j]
            else:
                code[sl, v] = AROUND
                regard[sl, v] = _wall_point(room, rng)
            k += n
        c0, c1 = calib[v]
        if c1 > c0:
            # the wearer turns to the point before the segment starts and holds it still
            # when the segment starts (the pursuit has settled)
            turn = (t >= c0 - CALIB_TURN) & (t < c1 + 0.3)
            code[turn, v] = CALIBRATION
            regard[turn, v] = calib_pts[v]
    head, roll = _pursue(t, eyes, regard, code, h, rng, calib, rng_c)
    return (
        _Motion(t, eyes, head, regard, code, roll, body_yaw, targets),
        calib_pts,
    )


def _plan_targets(rng: np.random.Generator, n_targets: int) -> Callable[..., FloatArray]:
    """Moving targets: Lissajous paths around the central pillar, ``t (...,) -> (..., n, 3)``."""
    tp = [
        (
            rng.uniform(0.55, 0.85),
            rng.uniform(0.1, 0.25),
            rng.uniform(0, 2 * np.pi),
            rng.uniform(1.0, 1.9),
            rng.uniform(0.1, 0.3),
            rng.uniform(0.1, 0.4),
        )
        for _ in range(n_targets)
    ]

    def targets(tt: npt.ArrayLike) -> FloatArray:
        ta = np.asarray(tt, dtype=np.float64)
        out = np.empty((*ta.shape, n_targets, 3))
        for k, (r, w, p0, zc, za, zf) in enumerate(tp):
            a = p0 + w * 2 * np.pi * ta * (1 if k % 2 == 0 else -1)
            out[..., k, 0] = r * np.cos(a)
            out[..., k, 1] = r * np.sin(a)
            out[..., k, 2] = zc + za * np.sin(2 * np.pi * zf * ta + p0)
        return out

    return targets


def _pursue(
    t: FloatArray,
    eyes: FloatArray,
    regard: FloatArray,
    code: IntArray,
    h: FloatArray,
    rng: np.random.Generator,
    calib: Sequence[tuple[float, float]] = (),
    rng_c: np.random.Generator | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Head directions ``(G, V, 3)`` and rolls ``(G, V)`` of people at ``eyes`` looking at
    ``regard`` (what, ``code``): a rate-limited smooth pursuit of the true gaze after a change
    of target (the head turns), tight tracking once the target is held, then the eye-in-head
    offset of spread ``h[v]`` and a small roll. During person ``v``'s calibration segment
    ``calib[v]`` (none for people past ``len(calib)``) the head holds the point and its
    deviation is the fast jitter drawn from ``rng_c``."""
    G, V = code.shape
    dt = 1.0 / GRID_HZ
    calib = [calib[v] if v < len(calib) else (-1.0, -1.0) for v in range(V)]
    rng_c = rng if rng_c is None else rng_c
    u = regard - eyes
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    # --- head: rate-limited smooth pursuit of the true gaze after a change of target (the
    # head turns), tight tracking once the target is held (then the primary gaze deviates
    # from the true gaze by the eye-in-head offset only)
    tau_turn, tau_hold, max_rate, settle = 0.1, 0.01, 3.5, 0.6
    # A new target is a change of code or a jump of the regarded point (two wall points in a
    # row keep the code): either starts a rate-limited turn.
    jump = np.linalg.norm(regard[1:] - regard[:-1], axis=-1) > 0.25
    switched = np.vstack([np.ones((1, V), bool), (code[1:] != code[:-1]) | jump])
    last = np.maximum.accumulate(np.where(switched, np.arange(G)[:, None], 0), axis=0)
    holding = (np.arange(G)[:, None] - last) * dt > settle
    a_turn, a_hold = 1 - np.exp(-dt / tau_turn), 1 - np.exp(-dt / tau_hold)
    track = np.empty_like(u)
    track[0] = u[0]
    for g in range(1, G):
        prev = track[g - 1]
        cosang = np.clip((prev * u[g]).sum(-1), -1.0, 1.0)
        ang = np.arccos(cosang)
        stepang = np.minimum(np.where(holding[g], ang * a_hold, ang * a_turn), max_rate * dt)
        perp = u[g] - cosang[:, None] * prev
        pn = np.linalg.norm(perp, axis=-1, keepdims=True)
        perp = np.where(pn > 1e-12, perp / np.maximum(pn, 1e-12), 0.0)
        track[g] = np.cos(stepang)[:, None] * prev + np.sin(stepang)[:, None] * perp
    for v, (c0, c1) in enumerate(calib):
        if c1 > c0:  # while fixating, the head's deviation from the point is m alone
            fix = _ramp(t - c0 + 0.3, c1 - c0 + 0.6, 0.3)[:, None]
            track[:, v] = (1 - fix) * track[:, v] + fix * u[:, v]
            track[:, v] /= np.linalg.norm(track[:, v], axis=-1, keepdims=True)
    e1 = np.cross(np.array([0.0, 0.0, 1.0]), track)
    e1 /= np.maximum(np.linalg.norm(e1, axis=-1, keepdims=True), 1e-12)
    e2 = np.cross(track, e1)
    head = np.empty_like(track)
    roll = np.empty((G, V))
    for v in range(V):
        m1 = h[v] * _smooth(rng, 4, 0.1, 0.6)(t)
        m2 = h[v] * _smooth(rng, 4, 0.1, 0.6)(t)
        roll[:, v] = np.radians(2.0) * _smooth(rng, 3, 0.05, 0.3)(t)
        c0, c1 = calib[v]
        if c1 > c0:
            # while fixating, the eye-in-head deviation is small jitter of the same spread
            # (saccade-free fixation, imperfect vestibulo-ocular reflex) and the head rolls
            fix1 = _ramp(t - c0 + 0.3, c1 - c0 + 0.6, 0.3)  # 1 on the whole segment
            m1 = (1 - fix1) * m1 + fix1 * h[v] * _smooth(rng_c, 8, *CALIB_FAST)(t)
            m2 = (1 - fix1) * m2 + fix1 * h[v] * _smooth(rng_c, 8, *CALIB_FAST)(t)
            f_roll, ph = rng_c.uniform(0.2, 0.3), rng_c.uniform(0, 2 * np.pi)
            roll[:, v] += fix1 * np.radians(CALIB_ROLL_DEG) * np.sin(2 * np.pi * f_roll * t + ph)
        hv = track[:, v] - m1[:, None] * e1[:, v] - m2[:, None] * e2[:, v]
        head[:, v] = hv / np.linalg.norm(hv, axis=-1, keepdims=True)
    return head, roll


def _wall_point(room: Room, rng: np.random.Generator) -> FloatArray:
    W, D, H = room.size
    side = int(rng.integers(0, 4))
    z = rng.uniform(0.4, H - 0.3)
    if side < 2:
        return np.array([rng.uniform(-W / 2 + 0.3, W / 2 - 0.3), (1 if side else -1) * D / 2, z])
    return np.array([(1 if side == 2 else -1) * W / 2, rng.uniform(-D / 2 + 0.3, D / 2 - 0.3), z])


def _camera_poses(
    motion: _Motion,
    v: int,
    times: FloatArray,
    R_cg: FloatArray,
    eye_offset: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """World→camera ``R (F,3,3)``, centres ``C (F,3)``, eyes and primary gaze at ``times``
    (the world's up is the image's up before the head's roll)."""
    p = motion.at("eyes", times)[:, v]
    hv = motion.at("head", times)[:, v]
    hv /= np.linalg.norm(hv, axis=-1, keepdims=True)
    roll = motion.at("roll", times)[:, v]
    Rg = look_at(p, p + hv)
    c, s = np.cos(roll), np.sin(roll)
    Rz = np.zeros((len(times), 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
    R = R_cg[None] @ Rz @ Rg
    C = p - np.einsum("fji,j->fi", R, eye_offset)
    return R, C, p, hv


# ----------------------------------------------------------------------------- people
HEAD_HALF = (0.1, 0.085, 0.125)  # head box half sizes: depth, width, height (metres)
FACE_WIDTH = 0.13  # metres: side of a detector's box around a frontal face


def _plan_people(room: Room, motion: _Motion, n_people: int, seed: int) -> None:
    """People without a camera (``motion.people_eyes``, ``people_head``): each stands
    outside the wearers' loop, sways a little and turns the head towards a wearer's head or
    the room centre, changing every 1.5–4 s (first-order pursuit, 0.3 s). Its own random
    stream, so scenes without people are unchanged."""
    rng = np.random.default_rng([seed, 31])
    t = motion.t
    G, Q, V = len(t), n_people, motion.eyes.shape[1]
    W, D, _H = room.size
    ax, ay = room.loop
    rx, ry = min(W / 2 - 0.75, 1.3 * ax), min(D / 2 - 0.8, 1.35 * ay)
    theta = rng.uniform(0, 2 * np.pi) + 2 * np.pi * (np.arange(Q) + rng.uniform(-0.2, 0.2, Q)) / Q
    eyes = np.empty((G, Q, 3))
    head = np.empty((G, Q, 3))
    regard = np.empty((G, Q, 3))
    codes = np.empty((G, Q), np.int64)
    dt = t[1] - t[0]
    for q in range(Q):
        sx, sy = _smooth(rng, 3, 0.05, 0.2), _smooth(rng, 3, 0.05, 0.2)
        base = np.array([rx * np.cos(theta[q]), ry * np.sin(theta[q]), rng.uniform(1.5, 1.75)])
        eyes[:, q] = base + 0.05 * np.c_[sx(t), sy(t), np.zeros(G)]
        look = np.empty((G, 3))
        k = 0
        while k < G:
            n = int(rng.uniform(1.5, 4.0) * GRID_HZ)
            sl = slice(k, min(G, k + n))
            w = int(rng.integers(0, V + 1))
            look[sl] = motion.eyes[sl, w] if w < V else np.array([0.0, 0.0, base[2]])
            codes[sl, q] = HEAD - w if w < V else AROUND
            k += n
        regard[:, q] = look
        d = look - eyes[:, q]
        yaw = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
        a = 1 - np.exp(-dt / 0.3)
        y = np.empty(G)
        y[0] = yaw[0]
        for g in range(1, G):
            y[g] = y[g - 1] + a * (yaw[g] - y[g - 1])
        head[:, q] = np.c_[np.cos(y), np.sin(y), np.zeros(G)]
    motion.people_eyes, motion.people_head = eyes, head
    motion.people_regard, motion.people_code = regard, codes


def _plan_circle(
    room: Room,
    n_wearers: int,
    n_people: int,
    t_end: float,
    h: FloatArray,
    rng: np.random.Generator,
    n_targets: int,
) -> _Motion:
    """A conversation circle: the wearers and the people without a camera stand on a
    circle (radius 1.0–1.4 m, larger for many people) in one half of the room, the central
    pillar outside it, mixed in a random order, swaying a little, and look at each other's
    heads. Every 2–5 s someone else speaks: the speaker looks at one listener after another
    (1–2.5 s each); each listener looks at the speaker (75 %) or at someone else, with its
    own reaction delay of 0–0.5 s. Heads follow by the pursuit of the walking scenes
    (eye-in-head spread ``h`` for the wearers, 0.03–0.07 for the others)."""
    dt = 1.0 / GRID_HZ
    t = np.arange(-PRE_ROLL, t_end + 2 * dt, dt)
    G, V, Q = len(t), n_wearers, n_people
    P = V + Q
    W, D, _H = room.size
    side = 1.0 if rng.uniform() < 0.5 else -1.0
    centre = np.array([side * W / 4, rng.uniform(-0.2, 0.2), 0.0])
    radius = min(max(rng.uniform(1.0, 1.4), 0.1 * P), W / 4 - 0.5, D / 2 - 1.0)
    theta = np.empty(P)
    theta[rng.permutation(P)] = (
        rng.uniform(0, 2 * np.pi) + 2 * np.pi * (np.arange(P) + rng.uniform(-0.2, 0.2, P)) / P
    )
    eyes = np.empty((G, P, 3))
    for p in range(P):
        sx, sy, sz = (_smooth(rng, 3, 0.05, 0.3) for _ in range(3))
        base = centre + np.array(
            [radius * np.cos(theta[p]), radius * np.sin(theta[p]), rng.uniform(1.55, 1.75)]
        )
        eyes[:, p] = base + np.c_[0.04 * sx(t), 0.04 * sy(t), 0.01 * sz(t)]
    # who speaks when, and whom everyone looks at
    code = np.empty((G, P), np.int64)
    k, speaker = 0, int(rng.integers(0, P))
    while k < G:
        n = int(rng.uniform(2.0, 5.0) * GRID_HZ)
        sl = slice(k, min(G, k + n))
        for p in range(P):
            others = [q for q in range(P) if q != p]
            if p == speaker:
                j = k
                while j < sl.stop:
                    m = int(rng.uniform(1.0, 2.5) * GRID_HZ)
                    code[j : min(sl.stop, j + m), p] = HEAD - int(rng.choice(others))
                    j += m
            else:
                code[sl, p] = HEAD - (speaker if rng.uniform() < 0.75 else int(rng.choice(others)))
        k += n
        speaker = int(rng.choice([q for q in range(P) if q != speaker] or [speaker]))
    for p in range(P):  # reaction delays
        lag = int(rng.uniform(0.0, 0.5) * GRID_HZ)
        if lag:
            code[lag:, p] = code[:-lag, p].copy()
    regard = eyes[np.arange(G)[:, None], HEAD - code]
    hh = np.r_[h, rng.uniform(0.03, 0.07, Q)]
    head, roll = _pursue(t, eyes, regard, code, hh, rng)
    to_c = centre[:2] - eyes[:, :V, :2]
    body_yaw = np.arctan2(to_c[..., 1], to_c[..., 0])
    return _Motion(
        t,
        eyes[:, :V],
        head[:, :V],
        regard[:, :V],
        code[:, :V],
        roll[:, :V],
        body_yaw,
        _plan_targets(rng, n_targets),
        people_eyes=eyes[:, V:],
        people_head=head[:, V:],
        people_regard=regard[:, V:],
        people_code=code[:, V:],
    )


def _persons(motion: _Motion, t: float) -> tuple[FloatArray, FloatArray]:
    """Eye centres ``(P, 3)`` and head directions ``(P, 3)`` of wearers then people."""
    eyes, head = motion.at("eyes", t), motion.at("head", t)
    if motion.people_eyes is not None:
        eyes = np.vstack([eyes, motion.at("people_eyes", t)])
        head = np.vstack([head, motion.at("people_head", t)])
    return eyes, head


def _regard_of_all(motion: _Motion, times: FloatArray) -> FloatArray:
    """What every person looks at ``(F, P, 3)`` at ``times`` (wearers, then people)."""
    reg = motion.at("regard", times)
    if motion.people_regard is not None:
        reg = np.concatenate([reg, motion.at("people_regard", times)], axis=1)
    return reg


def _codes_of_all(motion: _Motion, times: FloatArray) -> IntArray:
    """Target codes ``(F, P)`` of every person at ``times`` (wearers, then people)."""
    code = motion.code_at(times)
    if motion.people_code is not None:
        code = np.concatenate([code, motion.code_at(times, "people_code")], axis=1)
    return code


def _head_centre(
    eye: FloatArray, head_dir: FloatArray, pitch: bool = True, up: float = 0.04
) -> tuple[FloatArray, float, float]:
    """Centre of the head box, its yaw and its pitch (0 unless ``pitch``: the head box
    turns up and down with ``head_dir``) for a person with eye centre ``eye``; the box
    centre is ``up`` metres above the eye along the head's up axis."""
    hyaw = float(np.arctan2(head_dir[1], head_dir[0]))
    hpitch = float(np.arctan2(head_dir[2], np.hypot(head_dir[0], head_dir[1]))) if pitch else 0.0
    fwd, _side, up_axis = _box_axes(hyaw, hpitch)
    return eye - 0.05 * fwd + up * up_axis, hyaw, hpitch


def _eye_level(face_lm: Sequence[FloatArray], tex_shape: tuple[int, int]) -> FloatArray:
    """Per person, the ``up`` of :func:`_head_centre` that puts the eyes of the face
    photograph (texel landmarks ``face_lm[p] (5, 2)`` of a ``tex_shape`` image drawn over
    the front of the head box) at the height of the eye centre."""
    hz = HEAD_HALF[2]
    rows = np.array([0.5 * (lm[0, 1] + lm[1, 1]) for lm in face_lm])
    return (rows + 0.5) / tex_shape[0] * 2 * hz - hz


def _face_plane(eye: FloatArray, head_dir: FloatArray, up: float = 0.04) -> Plane:
    """The front of a head box (where the face photograph is drawn), pitched with the
    head."""
    hc, hyaw, hpitch = _head_centre(eye, head_dir, up=up)
    return _box_faces("head", hc, HEAD_HALF, hyaw, [0] * 5, hpitch)[0]


def _face_truth(
    motion: _Motion,
    times: FloatArray,
    face_lm: Sequence[FloatArray],
    tex_shape: tuple[int, int],
) -> tuple[FloatArray, FloatArray]:
    """World landmarks ``(F, P, 5, 3)`` and face normals ``(F, P, 3)`` at ``times``;
    ``face_lm[p]`` are person ``p``'s landmarks in texel coordinates ``(5, 2)``."""
    th, tw = tex_shape
    level = _eye_level(face_lm, tex_shape)
    out: list[FloatArray] = []
    normals: list[FloatArray] = []
    for t in times:
        eyes, head = _persons(motion, float(t))
        lms, ns = [], []
        for p in range(len(eyes)):
            pl = _face_plane(eyes[p], head[p], float(level[p]))
            xy = face_lm[p]
            lms.append(
                pl.point((xy[:, 0] + 0.5) * pl.size[0] / tw, (xy[:, 1] + 0.5) * pl.size[1] / th)
            )
            ns.append(pl.normal)
        out.append(np.stack(lms))
        normals.append(np.stack(ns))
    return np.stack(out), np.stack(normals)


def _blocked(planes: Sequence[Plane], C: FloatArray, X: FloatArray) -> bool:
    """Whether the segment from ``C`` to ``X`` crosses one of ``planes``."""
    if not planes:
        return False
    o = np.stack([p.origin for p in planes])
    u = np.stack([p.u for p in planes])
    v = np.stack([p.v for p in planes])
    n = np.stack([p.normal for p in planes])
    size = np.array([p.size for p in planes])
    d = X - C
    den = n @ d
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.einsum("ij,ij->i", n, o - C) / den
    ok = (np.abs(den) > 1e-12) & (s > 1e-6) & (s < 1 - 1e-6)
    P = C + s[:, None] * d
    a = np.einsum("ij,ij->i", P - o, u)
    b = np.einsum("ij,ij->i", P - o, v)
    ok &= (a >= 0) & (a <= size[:, 0]) & (b >= 0) & (b <= size[:, 1])
    return bool(ok.any())


def _face_visibility(
    lm: FloatArray,
    normal: FloatArray,
    K: FloatArray,
    R: FloatArray,
    C: FloatArray,
    size: tuple[int, int],
    planes: Sequence[Plane],
    viewer: int,
) -> tuple[npt.NDArray[np.bool_], FloatArray]:
    """Per person: drawn and visible in this view, and frontal face size in pixels."""
    P = lm.shape[0]
    vis = np.zeros(P, bool)
    fsize = np.full(P, np.nan)
    for p in range(P):
        Xc = (lm[p] - C) @ R.T
        centre = lm[p].mean(axis=0)
        depth = float(((centre - C) @ R.T)[2])
        if depth <= 0.05:
            continue
        fsize[p] = K[0, 0] * FACE_WIDTH / depth
        if p == viewer or (Xc[:, 2] <= 0.05).any():
            continue
        uv = Xc[:, :2] / Xc[:, 2:] * np.diag(K)[:2] + K[:2, 2]
        if (
            (uv < -0.5).any()
            or (uv[:, 0] > size[0] - 0.5).any()
            or (uv[:, 1] > size[1] - 0.5).any()
        ):
            continue
        to_cam = (C - centre) / np.linalg.norm(C - centre)
        if float(normal[p] @ to_cam) < np.cos(np.radians(75.0)):
            continue
        vis[p] = not _blocked(planes, C, centre + 0.01 * normal[p])
    return vis, fsize


def load_face_set() -> tuple[list[U8Image], list[FloatArray]]:
    """The shipped face photographs (``socialcam/data/faces``, provenance in its README) as
    RGB textures and their landmarks ``(5, 2)`` in texel coordinates."""
    import socialcam.data

    root = Path(socialcam.data.__file__).parent / "faces"
    meta = json.loads((root / "faces.json").read_text())
    images, marks = [], []
    for name, info in meta["faces"].items():
        img = cv2.imread(str(root / f"{name}.png"), cv2.IMREAD_COLOR)
        if img is None:
            raise ValueError(f"faces: cannot read {root / name}.png")
        images.append(np.ascontiguousarray(img[:, :, ::-1], dtype=np.uint8))
        marks.append(np.asarray(info["landmarks"], np.float64))
    return images, marks


def _person_faces(
    P: int, scales: Sequence[float] | None = None
) -> tuple[list[U8Image], list[FloatArray]]:
    """One face per person: the shipped photographs, mirrored every other round (a mirror
    image swaps the image-left/right landmarks back into order); with ``scales``, person
    ``p``'s photograph magnified by ``scales[p]`` about the texture's centre (its border
    pixels extend where it shrinks), and its landmarks with it."""
    images, marks = load_face_set()
    out_i, out_m = [], []
    for p in range(P):
        img, lm = images[p % len(images)], marks[p % len(images)]
        if (p // len(images)) % 2:
            img = np.ascontiguousarray(img[:, ::-1], dtype=np.uint8)
            lm = lm.copy()
            lm[:, 0] = img.shape[1] - 1 - lm[:, 0]
            lm = lm[[1, 0, 2, 4, 3]]
        a = 1.0 if scales is None else float(scales[p])
        if a != 1.0:
            c = np.array([(img.shape[1] - 1) / 2, (img.shape[0] - 1) / 2])
            M = np.array([[a, 0.0, (1 - a) * c[0]], [0.0, a, (1 - a) * c[1]]])
            warped = cv2.warpAffine(
                img, M, (img.shape[1], img.shape[0]), flags=cv2.INTER_LINEAR,
                borderMode=cv2.BORDER_REPLICATE,
            )  # fmt: skip
            img = np.ascontiguousarray(warped, dtype=np.uint8)
            lm = a * (lm - c) + c
        out_i.append(np.ascontiguousarray(img, dtype=np.uint8))
        out_m.append(lm)
    return out_i, out_m


# ----------------------------------------------------------------------------- bodies
def _box_axes(yaw: float, pitch: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Forward, left and up axes of a box turned by ``yaw`` about z, then ``pitch`` up."""
    cp, sp = np.cos(pitch), np.sin(pitch)
    fx = np.array([np.cos(yaw) * cp, np.sin(yaw) * cp, sp])
    fy = np.array([-np.sin(yaw), np.cos(yaw), 0.0])
    return fx, fy, np.cross(fx, fy)


def _box_faces(
    name: str,
    centre: FloatArray,
    half: tuple[float, float, float],
    yaw: float,
    textures: Sequence[int],
    pitch: float = 0.0,
) -> list[Plane]:
    """Five faces (front, back, left, right, top) of a box turned by ``yaw`` about z and
    tilted up by ``pitch``; ``textures`` gives one texture per face in that order (front =
    +x of the box)."""
    fx, fy, fz = _box_axes(yaw, pitch)
    hx, hy, hz = half
    return [
        face(f"{name}.front", centre + hx * fx, fx, 2 * hy, 2 * hz, textures[0]),
        face(f"{name}.back", centre - hx * fx, -fx, 2 * hy, 2 * hz, textures[1]),
        face(f"{name}.left", centre + hy * fy, fy, 2 * hx, 2 * hz, textures[2], right=-fx),
        face(f"{name}.right", centre - hy * fy, -fy, 2 * hx, 2 * hz, textures[3], right=fx),
        face(f"{name}.top", centre + hz * fz, fz, 2 * hx, 2 * hy, textures[4], right=fy),
    ]


def _dynamic_planes(
    motion: _Motion,
    t: float,
    viewer: int,
    body_tex: Sequence[Sequence[int]],
    head_tex: Sequence[Sequence[int]],
    target_tex: Sequence[Sequence[int]],
    bodies: bool,
    head_up: FloatArray | None = None,
) -> list[Plane]:
    """The moving planes at ``t`` seen by ``viewer``; ``head_up`` (per person, the ``up``
    of :func:`_head_centre`) draws the heads pitched with the head direction and at that
    height (faces scenes), ``None`` upright and 4 cm above the eyes."""
    out: list[Plane] = []
    eyes, head = _persons(motion, t)
    V = motion.eyes.shape[1]
    yaw = motion.at("body_yaw", t)
    if bodies:
        for w in range(eyes.shape[0]):
            if w == viewer:
                continue
            hc, hyaw, hpitch = (
                _head_centre(eyes[w], head[w], False)
                if head_up is None
                else _head_centre(eyes[w], head[w], True, float(head_up[w]))
            )
            out += _box_faces(f"head{w}", hc, HEAD_HALF, hyaw, head_tex[w], hpitch)
            bc = np.array([eyes[w, 0], eyes[w, 1], 0.5 * (eyes[w, 2] - 0.22)])
            byaw = float(yaw[w]) if w < V else hyaw
            out += _box_faces(
                f"body{w}", bc, (0.13, 0.22, 0.5 * (eyes[w, 2] - 0.22)), byaw, body_tex[w]
            )
    for k, p in enumerate(motion.targets(t)):
        out += _box_faces(f"target{k}", p, (0.09, 0.09, 0.09), 0.7 * k, target_tex[k])
    return out


# ----------------------------------------------------------------------------- audio
def _clap_wave(rng: np.random.Generator) -> Callable[[FloatArray], FloatArray]:
    """A clap as a continuous-time signal ``w(τ)`` (τ in s; 0 before the onset): damped
    partials 0.4–5 kHz under a 0.3 ms attack and ~6 ms decay, so it can be sampled at any
    fractional delay exactly."""
    n = 24
    f = rng.uniform(400.0, 5000.0, n)
    ph = rng.uniform(0, 2 * np.pi, n)
    a = rng.uniform(0.3, 1.0, n)
    decay = rng.uniform(0.004, 0.009)
    norm = 1.0 / (0.5 * a.sum())

    def w(tau: FloatArray) -> FloatArray:
        out = np.zeros_like(tau)
        on = tau >= 0
        x = tau[on]
        env = (1 - np.exp(-x / 0.0003)) * np.exp(-x / decay)
        out[on] = norm * env * (a * np.sin(2 * np.pi * f * x[:, None] + ph)).sum(axis=1)
        return out

    return w


def _pink(rng: np.random.Generator, n: int) -> FloatArray:
    spec = np.fft.rfft(rng.normal(size=n))
    fr = np.fft.rfftfreq(n, 1.0 / AUDIO_RATE)
    spec /= np.sqrt(np.maximum(fr, 20.0))
    x = np.fft.irfft(spec, n)
    return np.asarray(x / (x.std() + 1e-12))


def _audio(
    rng: np.random.Generator,
    n: int,
    start: float,
    gain: float,
    claps: FloatArray,
    clap_waves: Sequence[Callable[[FloatArray], FloatArray]],
    clap_gain: FloatArray,
    delays: FloatArray,
) -> npt.NDArray[np.float32]:
    """One wearer's track: ``n`` samples, sample ``j`` at true time ``start + j / rate``."""
    x = gain * _pink(rng, n)
    t = start + np.arange(n) / AUDIO_RATE
    # speech-like bursts heard by this wearer only
    for _ in range(int(n / AUDIO_RATE / 2) + 1):
        t0 = rng.uniform(0, n / AUDIO_RATE)
        length = rng.uniform(0.3, 1.0)
        i0, i1 = int(t0 * AUDIO_RATE), min(n, int((t0 + length) * AUDIO_RATE))
        if i1 <= i0:
            continue
        b = _pink(rng, i1 - i0)
        b = np.diff(np.r_[0.0, b])  # tilt towards speech band
        b /= b.std() + 1e-12
        tt = np.arange(i1 - i0) / AUDIO_RATE
        env = np.abs(np.sin(2 * np.pi * rng.uniform(3, 5) * tt)) * np.sin(np.pi * tt / length)
        x[i0:i1] += gain * rng.uniform(1.5, 3) * env * b
    for tc, wave, g, d in zip(claps, clap_waves, clap_gain, delays, strict=True):
        lo = max(0, int((tc + d - start) * AUDIO_RATE) - 2)
        hi = min(n, lo + int(0.08 * AUDIO_RATE))
        if hi > lo:
            x[lo:hi] += g * wave(t[lo:hi] - tc - d)
    return np.clip(x, -1.0, 1.0).astype(np.float32)


# ----------------------------------------------------------------------------- lens
def distort_radius(kind: str, params: Sequence[float], ru: FloatArray) -> FloatArray:
    """Distorted radius (normalised image plane) of undistorted radius ``ru``: OpenCV's
    ``radial`` model ``r (1 + k1 r² + k2 r⁴)`` or ``fisheye`` model ``θ (1 + k1 θ² + k2 θ⁴
    + k3 θ⁶ + k4 θ⁸)`` with ``θ = atan r``."""
    if kind == "radial":
        r2 = ru * ru
        return np.asarray(ru * (1 + params[0] * r2 + params[1] * r2 * r2))
    th = np.arctan(ru)
    t2 = th * th
    k1, k2, k3, k4 = params
    return np.asarray(th * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))))


def undistort_radius(kind: str, params: Sequence[float], rd: FloatArray) -> FloatArray:
    """Inverse of :func:`distort_radius` by Newton's method (monotone in the image)."""
    r = rd.copy()
    for _ in range(50):
        h = 1e-7
        fr = distort_radius(kind, params, r) - rd
        df = (distort_radius(kind, params, r + h) - distort_radius(kind, params, r - h)) / (2 * h)
        step = fr / np.where(np.abs(df) > 1e-9, df, 1e-9)
        r = np.maximum(r - step, 0.0)
        if np.abs(step).max() < 1e-13:
            break
    return r


def _lens(
    kind: str | None, width: int, height: int, rng: np.random.Generator
) -> tuple[
    FloatArray,
    dict[str, Any],
    FloatArray | None,
    tuple[npt.NDArray[np.float32], ...] | None,
    tuple[int, int],
]:
    """Intrinsics, distortion record, render intrinsics and remap tables for a lens.

    Returns ``K, dist, K_render, (map_x, map_y) or None, (render_w, render_h)``.
    """
    cx, cy = (width - 1) / 2, (height - 1) / 2
    if kind == "fisheye":
        f = 0.59 * width * rng.uniform(0.97, 1.03)
        params = [0.05 * rng.uniform(0.8, 1.2), 0.01 * rng.uniform(0.5, 1.5), 0.0, 0.0]
    else:
        f = width / 2 / np.tan(np.radians(37.5)) * rng.uniform(0.97, 1.03)
        params = [-0.12 * rng.uniform(0.8, 1.2), 0.01 * rng.uniform(0.5, 1.5)]
    K = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]])
    if kind is None:
        dist = {
            "model": "pinhole",
            "params": [],
            "colmap_model": "PINHOLE",
            "colmap_params": [f, f, cx + 0.5, cy + 0.5],
        }
        return K, dist, None, None, (width, height)
    xs, ys = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    xd = np.stack([(xs.ravel() - cx) / f, (ys.ravel() - cy) / f], axis=1)
    rd = np.linalg.norm(xd, axis=1)
    if kind == "radial":
        dist = {
            "model": "radial",
            "params": params,
            "colmap_model": "RADIAL",
            "colmap_params": [f, cx + 0.5, cy + 0.5, *params],
        }
    else:
        dist = {
            "model": "fisheye",
            "params": params,
            "colmap_model": "OPENCV_FISHEYE",
            "colmap_params": [f, f, cx + 0.5, cy + 0.5, *params],
        }
    ru = undistort_radius(kind, params, rd)
    scale = np.where(rd > 1e-12, ru / np.maximum(rd, 1e-12), 1.0)
    und = xd * scale[:, None]
    # pinhole canvas with the same focal length, large enough for every ray
    half_w = int(np.ceil(np.abs(und[:, 0]).max() * f)) + 2
    half_h = int(np.ceil(np.abs(und[:, 1]).max() * f)) + 2
    rw, rh = 2 * half_w + 1, 2 * half_h + 1
    Kr = np.array([[f, 0, half_w], [0, f, half_h], [0, 0, 1.0]])
    mx = (und[:, 0] * f + half_w).reshape(height, width).astype(np.float32)
    my = (und[:, 1] * f + half_h).reshape(height, width).astype(np.float32)
    return K, dist, Kr, (mx, my), (rw, rh)


# ----------------------------------------------------------------------------- writing
def _fps_fraction(fps: float) -> Fraction:
    return Fraction(fps).limit_denominator(1001)


def _yuv_frame(img: U8Image) -> Any:
    """An ``av.VideoFrame`` (yuv420p) of an RGB image with every byte defined.

    The RGB → YUV 4:2:0 conversion (BT.601, limited range) is done by OpenCV, and each
    plane's row padding is zeroed so that every byte the encoder's SIMD code may read is
    defined (determinism).
    """
    import av

    h, w = img.shape[:2]
    yuv = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2YUV_I420)
    planes = (
        yuv[:h],
        yuv[h : h + h // 4].reshape(h // 2, w // 2),
        yuv[h + h // 4 :].reshape(h // 2, w // 2),
    )
    vf = av.VideoFrame(w, h, "yuv420p")
    for plane, arr in zip(vf.planes, planes, strict=True):
        buf = np.zeros((plane.height, plane.line_size), np.uint8)
        buf[:, : arr.shape[1]] = arr
        plane.update(buf.tobytes())
    return vf


def _write_video(
    path: Path,
    frames: Callable[[], Any],
    n_frames: int,
    fps: float,
    width: int,
    height: int,
    audio: npt.NDArray[np.float32] | None,
    crf: int,
    preset: str = "veryfast",
) -> None:
    tmp = path.with_name(path.stem + ".tmp" + path.suffix)
    try:
        _encode(tmp, frames, fps, width, height, audio, crf, preset)
    except BaseException:  # Ctrl-C or an error: no half-written file is left behind
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, path)


def _encode(
    tmp: Path,
    frames: Callable[[], Any],
    fps: float,
    width: int,
    height: int,
    audio: npt.NDArray[np.float32] | None,
    crf: int,
    preset: str = "veryfast",
) -> None:
    import av

    rate = _fps_fraction(fps)
    with av.open(str(tmp), mode="w") as out:
        vs = out.add_stream("libx264", rate=rate)
        vs.width, vs.height = width, height
        vs.pix_fmt = "yuv420p"
        # mbtree off: with it, identical runs gave different files now and then on this
        # machine (x264's float SIMD; also gone with asm=0, which is 15× slower)
        vs.options = {"crf": str(crf), "preset": preset, "x264-params": "mbtree=0"}
        vs.codec_context.gop_size = 30
        vs.codec_context.time_base = 1 / rate
        aus = None
        if audio is not None:
            aus = out.add_stream("aac", rate=AUDIO_RATE)
            aus.layout = "mono"
            aus.bit_rate = 128000
            block = 1024
            for i in range(0, len(audio), block):
                chunk = audio[i : i + block]
                af = av.AudioFrame.from_ndarray(chunk[None, :], format="fltp", layout="mono")
                af.sample_rate = AUDIO_RATE
                af.pts = i
                af.time_base = Fraction(1, AUDIO_RATE)
                for pkt in aus.encode(af):
                    out.mux(pkt)
            for pkt in aus.encode(None):
                out.mux(pkt)
        for k, img in enumerate(frames()):
            vf = _yuv_frame(img)
            vf.pts = k
            vf.time_base = 1 / rate
            for pkt in vs.encode(vf):
                out.mux(pkt)
        for pkt in vs.encode(None):
            out.mux(pkt)


# ----------------------------------------------------------------------------- main
def render_scene(
    out_dir: str | Path,
    *,
    n_wearers: int = 4,
    duration: float = 20.0,
    fps: float = 30.0,
    size: tuple[int, int] = (640, 480),
    seed: int = 0,
    distortion: str | None = None,
    calibration: bool = True,
    audio: bool = True,
    progress: bool = True,
    room_size: tuple[float, float, float] = (8.0, 6.0, 3.0),
    photos: Sequence[str | Path] | None = None,
    head_textures: Sequence[U8Image] | None = None,
    bodies: bool = True,
    n_targets: int = 2,
    n_claps: int | None = None,
    sound_speed: float | None = None,
    start_spread: float | None = None,
    crf: int = 17,
    faces: bool = False,
    n_people: int = 0,
    arrangement: str = "loop",
    face_scales: Sequence[float] | None = None,
) -> RenderedScene:
    """Renders a scene of ``n_wearers`` head-mounted cameras (module docstring) into
    ``out_dir``: ``wearer<v>.mp4`` (H.264 + AAC, ``size = (width, height)``, ``fps``,
    ``duration`` seconds each) and ``truth.npz`` / ``truth.json``.

    Parameters beyond the issue-9 contract: ``room_size (W, D, H)`` metres; ``photos``
    (image files mixed into the textures; default: procedural textures only);
    ``head_textures`` (per wearer an RGB image for the front of the head); ``bodies``
    (draw other wearers); ``n_targets`` moving targets; ``n_claps`` (default one per 6 s,
    at least one); ``sound_speed`` (m/s; ``None`` = claps reach everyone at once);
    ``start_spread`` (s; default ``min(1, duration / 5)``: video starts are drawn in
    ``[0, start_spread]``); ``crf`` (x264 quality, lower = better); ``faces`` (a real face
    photograph on the front of every head, ``socialcam/data/faces``, with the 3D landmark
    truth ``face_*`` in :class:`SceneTruth`); ``n_people`` (people without a camera standing
    around the wearers' loop and looking at wearers; drawn when ``bodies``);
    ``arrangement``: ``"loop"`` (the wearers walk around the pillar, the module docstring)
    or ``"circle"`` (everyone stands in a conversation circle and looks at each other's
    heads, so that faces are seen by several cameras at once; no calibration segments);
    ``face_scales`` (with ``faces``: per person, wearers then people, a factor 0.7–1.3 on
    the size of its face photograph, whose eyes are ``socialcam.faces.INTEROCULAR`` apart
    at 1: people's faces differ; default 1 for everyone).

    Deterministic: same arguments, same files.
    """
    out = Path(out_dir)
    V = check_int(n_wearers, "n_wearers", min=1, max=8)
    dur = check_float(duration, "duration", min=0.2, max=600.0)  # audio is built in memory
    fps_ = check_float(fps, "fps", min=1.0, max=240.0)
    if not (isinstance(size, (tuple, list)) and len(size) == 2):
        raise ValueError(f"size: expected (width, height), got {size!r}")
    width = check_int(size[0], "size[0] (width)", min=32, max=4096)
    height = check_int(size[1], "size[1] (height)", min=32, max=4096)
    if width % 2 or height % 2:
        raise ValueError(f"size: width and height must be even for H.264, got {width}x{height}")
    seed_ = check_seed(seed)
    if distortion is not None:
        check_choice(distortion, "distortion", ("radial", "fisheye"))
    n_t = check_int(n_targets, "n_targets", min=0, max=8)
    if sound_speed is not None:
        check_float(sound_speed, "sound_speed", min=1.0)
    crf_ = check_int(crf, "crf", min=0, max=51)
    Q = check_int(n_people, "n_people", min=0, max=12)
    check_choice(arrangement, "arrangement", ("loop", "circle"))
    if arrangement == "circle" and calibration:
        raise ValueError("calibration: the circle arrangement has no calibration segments")
    fscales: list[float] | None = None
    if face_scales is not None:
        if not faces:
            raise ValueError("face_scales: only with faces=True")
        if isinstance(face_scales, (str, bytes)) or len(face_scales) != V + Q:
            raise ValueError(
                f"face_scales: expected {V + Q} factors (wearers then people), got {face_scales!r}"
            )
        fscales = [
            check_float(a, f"face_scales[{i}]", min=0.7, max=1.3) for i, a in enumerate(face_scales)
        ]
    if faces and head_textures is not None:
        raise ValueError("head_textures: give either head_textures or faces=True, not both")
    if (faces or Q) and not bodies:
        raise ValueError("bodies: faces and n_people draw heads and bodies; need bodies=True")
    F = round(dur * fps_)
    if F < 2:
        raise ValueError(f"duration: less than two frames at {fps_} fps")
    if V * F * width * height * 3 > 2**40:
        raise ValueError("duration: the scene is too large to render (over 1 TiB of pixels)")
    spread = (
        min(1.0, dur / 5)
        if start_spread is None
        else check_float(start_spread, "start_spread", min=0.0, max=dur / 2)
    )
    t_wall = time.perf_counter()
    rng = np.random.default_rng([seed_, 9])
    photos_ = load_photos([str(p) for p in photos]) if photos else None
    # texture detail follows the image resolution: 8 mm texels at 640 px wide
    texel = float(np.clip(0.008 * 640 / width, 0.004, 0.06))
    room = build_room(room_size, seed=seed_, photos=photos_, texel=texel)
    start = np.round(rng.uniform(0.0, spread, V), 6)
    start[rng.integers(0, V)] = 0.0 if V > 1 else start[0]
    t_end = float(start.max() + dur + 0.5)
    calib_len = min(6.0, 0.3 * dur)
    calib = [
        (
            float(start[v] + 0.1 * min(1.0, dur / 2)),
            float(start[v] + 0.1 * min(1.0, dur / 2) + calib_len),
        )
        if calibration
        else (-1.0, -1.0)
        for v in range(V)
    ]
    h = rng.uniform(*H_RANGE, V)
    if arrangement == "circle":
        motion, calib_pts = _plan_circle(room, V, Q, t_end, h, rng, n_t), np.zeros((V, 3))
    else:
        motion, calib_pts = _plan_motion(room, V, t_end, calib, h, rng, n_t)
        if Q:
            _plan_people(room, motion, Q, seed_)
    # per-wearer lens and camera-to-head transform
    eye_offset = np.c_[
        rng.uniform(-0.01, 0.01, V), rng.uniform(0.06, 0.09, V), rng.uniform(-0.05, -0.02, V)
    ]
    pd = np.c_[
        np.tan(np.radians(rng.uniform(-3, 3, V))),
        -np.tan(np.radians(rng.uniform(4, 12, V))),
        np.ones(V),
    ]
    primary_dir = pd / np.linalg.norm(pd, axis=1, keepdims=True)
    lenses = [_lens(distortion, width, height, rng) for _ in range(V)]
    # textures of the moving things
    tex = list(room.textures)

    def new_tex(h_: int, w_: int, pal: int) -> int:
        tex.append(procedural_texture(h_, w_, seed=int(rng.integers(0, 2**31)), palette=pal))
        return len(tex) - 1

    body_tex = [[new_tex(64, 64, w % 6)] * 5 for w in range(V)]
    head_tex = []
    for w in range(V):
        hair = new_tex(32, 32, 1)
        front = hair
        if head_textures is not None:
            if len(head_textures) != V:
                raise ValueError(f"head_textures: expected {V} images, got {len(head_textures)}")
            img = np.asarray(head_textures[w])
            if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
                raise ValueError("head_textures: expected RGB uint8 images (H, W, 3)")
            tex.append(
                np.asarray(cv2.resize(img, (64, 80), interpolation=cv2.INTER_AREA), np.uint8)
            )
            front = len(tex) - 1
        head_tex.append([front, hair, hair, hair, hair])
    target_tex = [[new_tex(32, 32, 3 + k % 3)] * 5 for k in range(n_t)]
    # people and faces draw from their own stream: scenes without them are unchanged
    rng_p = np.random.default_rng([seed_, 37])
    for q in range(Q):
        tex.append(procedural_texture(64, 64, seed=int(rng_p.integers(0, 2**31)), palette=q % 6))
        body_tex.append([len(tex) - 1] * 5)
        tex.append(procedural_texture(32, 32, seed=int(rng_p.integers(0, 2**31)), palette=1))
        head_tex.append([len(tex) - 1] * 5)
    face_lm: list[FloatArray] = []
    face_shape = (0, 0)
    head_up: FloatArray | None = None
    if faces:
        face_imgs, face_lm = _person_faces(V + Q, fscales)
        face_shape = face_imgs[0].shape[:2]
        for p_, img_ in enumerate(face_imgs):
            tex.append(img_)
            head_tex[p_] = [len(tex) - 1, *head_tex[p_][1:]]
        head_up = _eye_level(face_lm, face_shape)
    # clocks, claps and audio
    frame_times = [start[v] + np.arange(F) / fps_ for v in range(V)]
    lo, hi = float(start.max()), float(start.min() + F / fps_)
    nc = max(1, int(dur / 6)) if n_claps is None else check_int(n_claps, "n_claps", min=1, max=100)
    claps = np.sort(
        lo + (hi - lo) * (0.15 + 0.7 * (np.arange(nc) + rng.uniform(0.1, 0.9, nc)) / nc)
    )
    clap_pos = np.array([0.0, 0.0, 1.2]) + np.r_[rng.uniform(-0.5, 0.5, 2), 0.0]
    clap_waves = [_clap_wave(rng) for _ in range(nc)]
    names = tuple(f"wearer{v}" for v in range(V))
    out.mkdir(parents=True, exist_ok=True)
    videos = []
    truths: dict[str, list[Any]] = {k: [] for k in _PER_WEARER + _FACE_TRUTH + _FACE_TRUTH_OPT}
    total = V * F
    bar = None
    if progress:
        from tqdm.auto import tqdm  # type: ignore[import-untyped]

        bar = tqdm(total=total, desc="render", unit="frame")
    try:
        for v in range(V):
            K, _dist, Kr, maps, (rw, rh) = lenses[v]
            R_cg = _rot_from_z(primary_dir[v])
            times = frame_times[v]
            R, C, p, hv = _camera_poses(motion, v, times, R_cg, eye_offset[v])
            regard = motion.at("regard", times)[:, v]
            code = motion.code_at(times)[:, v]
            if calibration:
                code[(times >= calib[v][0]) & (times < calib[v][1])] = CALIBRATION
            ut = regard - p
            ut /= np.linalg.norm(ut, axis=1, keepdims=True)
            for k, a in (
                ("frame_times", times),
                ("R", R),
                ("C", C),
                ("eyes", p),
                ("gaze", hv),
                ("gaze_true", ut),
                ("regard", regard),
                ("target_of", code),
            ):
                truths[k].append(a)
            face_vis = np.zeros((F, V + Q), bool)
            face_px = np.zeros((F, V + Q))
            if faces:
                lm_v, n_v = _face_truth(motion, times, face_lm, face_shape)
                truths["face_landmarks"].append(lm_v)
                truths["face_normal"].append(n_v)
                truths["face_visible"].append(face_vis)
                truths["face_size"].append(face_px)
                truths["face_regard"].append(_regard_of_all(motion, times))
                truths["face_target"].append(_codes_of_all(motion, times))
            renderer = Renderer(K if Kr is None else Kr, rw, rh, tex)
            shell = renderer.prepare(room.planes[:N_SHELL], depth_test=False)
            static = renderer.prepare(room.planes[N_SHELL:])
            rng_a = np.random.default_rng([seed_, 17, v])
            track = None
            if audio:
                gain = float(np.exp(rng_a.uniform(np.log(0.003), np.log(0.04))))
                cg = rng_a.uniform(0.25, 0.9, nc)
                if sound_speed is None:
                    delays = np.zeros(nc)
                else:
                    pos_c = motion.at("eyes", claps)[:, v]
                    delays = np.linalg.norm(pos_c - clap_pos, axis=1) / sound_speed
                n_s = round(F / fps_ * AUDIO_RATE)
                track = _audio(rng_a, n_s, float(start[v]), gain, claps, clap_waves, cg, delays)

            def frames(
                v: int = v,
                R: FloatArray = R,
                C: FloatArray = C,
                times: FloatArray = times,
                renderer: Renderer = renderer,
                static: _Batch = static,
                shell: _Batch = shell,
                maps: Any = maps,
                face_vis: npt.NDArray[np.bool_] = face_vis,
                face_px: FloatArray = face_px,
            ) -> Any:
                K_v = lenses[v][0]
                for k in range(F):
                    dyn = _dynamic_planes(
                        motion,
                        float(times[k]),
                        v,
                        body_tex,
                        head_tex,
                        target_tex,
                        bodies,
                        head_up=head_up,
                    )
                    if faces:
                        face_vis[k], face_px[k] = _face_visibility(
                            truths["face_landmarks"][v][k],
                            truths["face_normal"][v][k],
                            K_v,
                            R[k],
                            C[k],
                            (width, height),
                            [*room.planes[N_SHELL:], *dyn],
                            v,
                        )
                    img = renderer.render(R[k], C[k], shell, static, renderer.prepare(dyn, 10.0))
                    if maps is not None:
                        img = cv2.remap(  # type: ignore[assignment]
                            img, maps[0], maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
                        )
                    if bar is not None:
                        bar.update(1)
                    yield img

            path = out / f"{names[v]}.mp4"
            _write_video(path, frames, F, fps_, width, height, track, crf_)
            videos.append(path)
    finally:
        if bar is not None:
            bar.close()
    truth = SceneTruth(
        names=names,
        start=start,
        fps=fps_,
        size=(width, height),
        K=np.stack([lens[0] for lens in lenses]),
        dist=tuple(lens[1] for lens in lenses),
        eye_offset=eye_offset,
        primary_dir=primary_dir,
        h=h,
        target_times=motion.t,
        target_positions=motion.targets(motion.t),
        calibration=tuple(
            (calib[v][0], calib[v][1], calib_pts[v]) for v in range(V) if calibration
        ),
        claps=claps if audio else np.zeros(0),
        clap_position=clap_pos,
        sound_speed=sound_speed,
        audio_rate=AUDIO_RATE,
        room=room.to_dict(),
        seed=seed_,
        n_people=Q,
        **{k: tuple(a) for k, a in truths.items()},  # type: ignore[arg-type]
    )
    truth_path = save_truth(truth, out / "truth.npz")
    return RenderedScene(tuple(videos), truth_path, truth, room, time.perf_counter() - t_wall)


def shipped_scene() -> Path:
    """The folder of the rendered scene shipped with socialcam (``SHIPPED_SCENE``: 4
    wearers × 8 s, 640×480, 30 fps): ``wearer0.mp4`` … ``wearer3.mp4``, ``truth.npz``,
    ``truth.json``. Regenerate with ``python -m socialcam.synth.render --ship``."""
    import socialcam.data

    return Path(socialcam.data.__file__).parent / "scene"


def _main(argv: Sequence[str] | None = None) -> int:
    import argparse
    import sys

    ap = argparse.ArgumentParser(prog="python -m socialcam.synth.render")
    ap.add_argument(
        "--ship", action="store_true", help="regenerate the scene shipped in socialcam/data/scene/"
    )
    ap.add_argument("--out", default=None, help="write the shipped scene there instead")
    args = ap.parse_args(argv)
    if args.ship:
        dest = shipped_scene() if args.out is None else Path(args.out)
        res = render_scene(dest, **SHIPPED_SCENE, progress=sys.stderr.isatty())
        print(f"wrote {len(res.videos)} videos to {dest} in {res.render_seconds:.1f} s")
    else:
        ap.print_help()
    return 0


#: the arguments of the shipped scene (``socialcam/data/scene``). The seed is the first from
#: 2026 whose truth holds at least 2 s of joint attention (group-frames at 10 Hz) and whose
#: four calibration segments determine Eq 3.1 on the true cameras (2026 has no joint
#: attention; 2032 has a wearer whose 2.4-s segment falls back).
SHIPPED_SCENE: dict[str, Any] = {
    "n_wearers": 4,
    "duration": 8.0,
    "fps": 30.0,
    "size": (640, 480),
    "seed": 2033,
    "crf": 26,
}


if __name__ == "__main__":
    raise SystemExit(_main())
