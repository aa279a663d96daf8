"""Video input: any file FFmpeg decodes (through PyAV) or a folder of numbered frames.

Each video has its own *local* clock: container timestamps, with its first frame at 0
(variable frame rate is handled: the times come from the container, never from a nominal
rate). Frames are streamed — :meth:`Video.frames` decodes one frame at a time and never
holds the video in memory.

>>> with open_video("wearer0.mp4") as vid:            # doctest: +SKIP
...     print(vid.info.n_frames, vid.info.fps, vid.timestamps()[:3])
...     for fr in vid.frames(fps=10):                 # the frame nearest to 0, 0.1, 0.2, ... s
...         use(fr.index, fr.time, fr.image)          # image (H, W, 3) uint8 RGB
...     samples, rate = vid.audio()                   # mono float32, sample j at local j / rate

Errors are ``ValueError`` naming the file: not a video, no video stream, a folder without
images, a folder without ``fps``. A frame that cannot be decoded is skipped, counted in
:attr:`Video.n_corrupt` and reported with a :class:`CorruptFrameWarning`.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from socialcam._validate import FloatArray, check_bool, check_float

IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")


class CorruptFrameWarning(UserWarning):
    """A frame could not be decoded and was skipped."""


@dataclass(frozen=True)
class VideoInfo:
    """What a video is: ``name`` is the file stem (= the person's name), ``fps`` the
    nominal rate (``n_frames`` / span for variable-rate files), ``duration`` in seconds
    from the first frame to the end of the last."""

    path: Path
    name: str
    width: int
    height: int
    n_frames: int
    duration: float
    fps: float
    has_audio: bool
    audio_rate: int | None

    def to_dict(self) -> dict[str, Any]:
        d = dict(self.__dict__)
        d["path"] = str(self.path)
        return d


@dataclass(frozen=True)
class Frame:
    """One decoded frame: ``index`` in the video (0-based, decode order = time order),
    ``time`` on the video's local clock (s) and ``image`` ``(H, W, 3)`` uint8 RGB, or
    ``(H, W)`` uint8 when asked for gray."""

    index: int
    time: float
    image: npt.NDArray[np.uint8]


def _natural_key(p: Path) -> tuple[Any, ...]:
    return tuple(int(s) if s.isdigit() else s for s in re.split(r"(\d+)", p.name))


class Video:
    """An open video (use :func:`open_video`). A context manager; :meth:`close` frees the
    decoder."""

    def __init__(self, path: Path, *, fps: float | None = None) -> None:
        self._path = path
        self._container: Any = None
        self._files: list[Path] | None = None
        self._times: FloatArray | None = None
        self.n_corrupt = 0  # distinct frames found undecodable so far
        self._bad: set[int] = set()
        self._last_error = ""
        if path.is_dir():
            self._open_folder(path, fps)
        else:
            self._open_file(path)

    # ------------------------------------------------------------------ opening
    def _open_folder(self, path: Path, fps: float | None) -> None:
        files = sorted(
            (p for p in path.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS and p.is_file()),
            key=_natural_key,
        )
        if not files:
            raise ValueError(f"{path}: a folder with no images ({', '.join(IMAGE_EXTENSIONS)})")
        if fps is None:
            raise ValueError(f"fps: needed for the folder of frames {path}")
        rate = check_float(fps, "fps", min=0.0, min_exclusive=True)
        first = None
        for f in files:
            first = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
            if first is not None:
                break
        if first is None:
            raise ValueError(f"{path}: none of its {len(files)} images can be read")
        self._files = files
        self._times = np.arange(len(files)) / rate
        self.info = VideoInfo(
            path=path,
            name=path.name,
            width=int(first.shape[1]),
            height=int(first.shape[0]),
            n_frames=len(files),
            duration=len(files) / rate,
            fps=rate,
            has_audio=False,
            audio_rate=None,
        )

    def _open_file(self, path: Path) -> None:
        import av

        if not path.exists():
            raise ValueError(f"path: {path} does not exist")
        try:
            c = av.open(str(path))
        except (av.FFmpegError, UnicodeDecodeError, OSError) as exc:
            raise ValueError(f"{path}: not a video FFmpeg can read ({exc})") from None
        if not c.streams.video:
            c.close()
            raise ValueError(f"{path}: has no video stream")
        self._container = c
        vs = c.streams.video[0]
        vs.thread_type = "AUTO"
        times = self.timestamps()
        if len(times) == 0:
            self.close()
            raise ValueError(f"{path}: its video stream has no frames")
        aud = c.streams.audio[0] if c.streams.audio else None
        span = float(times[-1]) if len(times) > 1 else 0.0
        rate = float(vs.average_rate) if vs.average_rate else 0.0
        if len(times) > 1 and (rate <= 0 or not np.isfinite(rate)):
            rate = (len(times) - 1) / span
        step = float(np.median(np.diff(times))) if len(times) > 1 else (1 / rate if rate else 0.0)
        self.info = VideoInfo(
            path=path,
            name=path.stem,
            width=int(vs.codec_context.width),
            height=int(vs.codec_context.height),
            n_frames=len(times),
            duration=span + step,
            fps=rate,
            has_audio=aud is not None,
            audio_rate=int(aud.codec_context.sample_rate) if aud is not None else None,
        )

    # ------------------------------------------------------------------ basics
    def __enter__(self) -> Video:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        if self._container is not None:
            self._container.close()
            self._container = None

    def __repr__(self) -> str:
        i = self.info
        return f"Video({i.name!r}, {i.width}x{i.height}, {i.n_frames} frames, {i.fps:.3f} fps)"

    @property
    def path(self) -> Path:
        return self._path

    def _stream(self) -> Any:
        if self._container is None:
            raise ValueError(f"{self._path}: the video is closed")
        return self._container.streams.video[0]

    def _first_pts_time(self) -> float:
        self.timestamps()
        return self._t0

    # ------------------------------------------------------------------ timestamps
    def timestamps(self) -> FloatArray:
        """Frame times ``(F,)`` in seconds on the local clock (first frame at 0), from the
        container's presentation timestamps (variable frame rate kept as is)."""
        if self._times is not None:
            return self._times
        vs = self._stream()
        pts = []
        self._container.seek(0)
        for pkt in self._container.demux(vs):
            if pkt.pts is not None and pkt.size > 0:
                pts.append(pkt.pts)
        self._container.seek(0)
        p = np.unique(np.asarray(pts, dtype=np.int64))  # presentation order
        tb = float(vs.time_base)
        self._pts = p
        self._tb = tb
        self._t0 = float(p[0]) * tb if len(p) else 0.0
        self._times = (p - (p[0] if len(p) else 0)).astype(np.float64) * tb
        self._times.flags.writeable = False
        return self._times

    # ------------------------------------------------------------------ frames
    def _convert(self, frame: Any, gray: bool) -> npt.NDArray[np.uint8]:
        img = frame.to_ndarray(format="gray" if gray else "rgb24")
        return np.ascontiguousarray(img)

    def _decode(self, start_time: float) -> Iterator[tuple[int, Any]]:
        """Decoded frames ``(index, av frame)`` from the keyframe before ``start_time``."""
        import av

        vs = self._stream()
        self.timestamps()
        index_of = {int(p): i for i, p in enumerate(self._pts)}
        c = self._container
        if start_time > 0:
            target = round((start_time + self._t0) / self._tb)
            c.seek(target, stream=vs, backward=True, any_frame=False)
        else:
            c.seek(0)
        for pkt in c.demux(vs):
            try:
                frames = pkt.decode()
            except av.FFmpegError as exc:
                self._last_error = str(exc)
                continue
            for fr in frames:
                if fr.pts is None or int(fr.pts) not in index_of:
                    continue
                if getattr(fr, "is_corrupt", False):
                    self._last_error = "flagged corrupt by the decoder"
                    continue
                yield index_of[int(fr.pts)], fr

    def _corrupt(self, index: int, what: str) -> None:
        if index in self._bad:
            return
        self._bad.add(index)
        self.n_corrupt = len(self._bad)
        warnings.warn(
            f"{self._path}: skipped frame {index}, which cannot be decoded ({what})",
            CorruptFrameWarning,
            stacklevel=4,
        )

    def _folder_frame(self, i: int, gray: bool) -> npt.NDArray[np.uint8] | None:
        assert self._files is not None
        f = self._files[i]
        img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE if gray else cv2.IMREAD_COLOR)
        if img is None:
            self._corrupt(i, f"image {f.name} cannot be read")
            return None
        if not gray:
            img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
        return np.asarray(img, dtype=np.uint8)

    def frames(
        self,
        fps: float | None = None,
        *,
        start: float = 0.0,
        end: float | None = None,
        gray: bool = False,
        at: npt.ArrayLike | None = None,
    ) -> Iterator[Frame]:
        """Streams frames. With ``fps``, for each output time ``k / fps`` in ``[start,
        end)`` the frame nearest to it (a frame can repeat when ``fps`` exceeds the video's
        rate); with ``at`` (increasing local times, s), the frame nearest to each of them
        (``start``, ``end`` and ``fps`` ignored); without either, every frame with ``start
        ≤ time < end``. Only the frames yielded are converted to arrays. ``Frame.time`` is
        the frame's own timestamp. Undecodable frames are skipped (nothing is yielded for
        them), counted in :attr:`n_corrupt` and reported by a :class:`CorruptFrameWarning`."""
        gray = check_bool(gray, "gray")  # a truthy "no" gave gray frames
        times = self.timestamps()
        t0 = check_float(start, "start")
        t1 = float(times[-1]) + 1e-9 if end is None else check_float(end, "end")
        if at is not None:
            want_t = np.asarray(at, dtype=np.float64).reshape(-1)
            if not np.isfinite(want_t).all() or (np.diff(want_t) < 0).any():
                raise ValueError("at: expected increasing finite local times")
            wanted = _nearest(times, want_t)
        elif fps is None:
            wanted = np.nonzero((times >= t0) & (times < t1 if end is not None else True))[0]
        else:
            rate = check_float(fps, "fps", min=0.0, min_exclusive=True)
            k0 = int(np.ceil(t0 * rate - 1e-9))
            out_t = np.arange(k0, int(np.ceil(t1 * rate - 1e-9))) / rate
            out_t = out_t[(out_t >= t0 - 1e-9) & (out_t < t1)]
            if end is None:
                out_t = out_t[out_t <= times[-1] + 0.5 * _step(times)]
            wanted = _nearest(times, out_t)
        if len(wanted) == 0:
            return
        if self._files is not None:
            for i in wanted:
                img = self._folder_frame(int(i), gray)
                if img is None:
                    continue
                yield Frame(int(i), float(times[i]), img)
            return
        pos = 0
        for idx, fr in self._decode(float(times[wanted[0]])):
            while pos < len(wanted) and wanted[pos] < idx:
                # that frame could not be decoded: skipped (counted, warned)
                self._corrupt(int(wanted[pos]), self._last_error or "no picture")
                pos += 1
            while pos < len(wanted) and wanted[pos] == idx:
                yield Frame(idx, float(times[idx]), self._convert(fr, gray))
                pos += 1
            if pos >= len(wanted):
                return
        for w in wanted[pos:]:
            self._corrupt(int(w), self._last_error or "no picture")

    def frame_at(self, t: float, *, gray: bool = False) -> Frame:
        """The frame nearest to local time ``t``."""
        times = self.timestamps()
        tt = check_float(t, "t")
        i = int(_nearest(times, np.array([tt]))[0])
        for fr in self.frames(start=float(times[i]), end=float(times[i]) + 1e-6, gray=gray):
            return fr
        raise ValueError(f"{self._path}: the frame at t = {times[i]:.6f} s cannot be decoded")

    # ------------------------------------------------------------------ audio
    def audio(self) -> tuple[npt.NDArray[np.float32], int]:
        """The audio track as mono float32 samples (channels averaged) and its rate;
        sample ``j`` is at local time ``j / rate`` (the track is shifted by its container
        start time relative to the first video frame, padding with zeros or trimming).
        ValueError when the video has no audio."""
        import av

        if self._container is None or not self._container.streams.audio:
            raise ValueError(f"{self._path}: has no audio track")
        c = self._container
        a = c.streams.audio[0]
        rate = int(a.codec_context.sample_rate)
        res = av.AudioResampler(format="flt", layout="mono", rate=rate)
        chunks: list[npt.NDArray[np.float32]] = []
        first_t: float | None = None
        c.seek(0)
        try:
            for pkt in c.demux(a):
                try:
                    frames = pkt.decode()
                except av.FFmpegError:
                    continue
                for fr in frames:
                    if first_t is None and fr.pts is not None:
                        first_t = float(fr.pts * fr.time_base)
                    for r in res.resample(fr):
                        chunks.append(r.to_ndarray().reshape(-1).astype(np.float32))
            for r in res.resample(None):
                chunks.append(r.to_ndarray().reshape(-1).astype(np.float32))
        finally:
            c.seek(0)
        x = np.concatenate(chunks) if chunks else np.zeros(0, np.float32)
        shift = round(((first_t or 0.0) - self._first_pts_time()) * rate)
        if shift > 0:
            x = np.r_[np.zeros(shift, np.float32), x]
        elif shift < 0:
            x = x[-shift:]
        return x, rate


def _step(times: FloatArray) -> float:
    return float(np.median(np.diff(times))) if len(times) > 1 else 1.0


def _nearest(times: FloatArray, t: FloatArray) -> npt.NDArray[np.int64]:
    """Index of the nearest entry of the sorted ``times`` for each of ``t`` (ties → earlier)."""
    j = np.clip(np.searchsorted(times, t), 1, max(1, len(times) - 1))
    if len(times) == 1:
        return np.zeros(len(t), np.int64)
    left = times[j - 1]
    right = times[j]
    return np.where(np.abs(t - left) <= np.abs(right - t), j - 1, j).astype(np.int64)


def open_video(path: str | Path, *, fps: float | None = None) -> Video:
    """Opens a video file (mp4, mov, mkv, ... anything FFmpeg decodes) or a folder of
    numbered images (then ``fps`` is required). ValueError naming the file when it is not
    a video, has no video stream, or is a folder without images."""
    if not isinstance(path, (str, Path)):
        raise ValueError(f"path: expected a file or folder path, got {type(path).__name__}")
    p = Path(path)
    if not p.exists():
        raise ValueError(f"path: {p} does not exist")
    if p.is_file() and fps is not None:
        check_float(fps, "fps", min=0.0, min_exclusive=True)
    return Video(p, fps=fps)
