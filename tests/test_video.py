"""Video input: files FFmpeg decodes (PyAV), folders of numbered frames, container
timestamps, streaming at a chosen rate, audio, and clear errors."""

from __future__ import annotations

import warnings
from fractions import Fraction
from pathlib import Path

import av
import cv2
import numpy as np
import pytest

from socialcam.video import CorruptFrameWarning, open_video

W, H = 64, 48


def frame_image(k: int) -> np.ndarray:
    """A frame whose mean grey level encodes its index (robust to compression)."""
    img = np.full((H, W, 3), 20 + 7 * (k % 30), np.uint8)
    img[:8, :8] = 255  # a corner mark
    return img


def decoded_index(img: np.ndarray) -> int:
    return round((float(img[16:, 16:].mean()) - 20) / 7)


def write_video(
    path: Path,
    times: np.ndarray,
    *,
    codec: str = "libx264",
    audio: np.ndarray | None = None,
    rate: int = 48000,
    time_base: Fraction = Fraction(1, 1000),
) -> Path:
    """Frames at arbitrary ``times`` (s; variable frame rate) + optional mono audio."""
    with av.open(str(path), mode="w") as out:
        vs = out.add_stream(codec, rate=30)
        vs.width, vs.height, vs.pix_fmt = W, H, "yuv420p"
        vs.codec_context.time_base = time_base
        if codec == "libx265":
            vs.options = {"x265-params": "log-level=error"}
        if audio is not None:
            aus = out.add_stream("aac", rate=rate)
            aus.layout = "mono"
            for i in range(0, len(audio), 1024):
                af = av.AudioFrame.from_ndarray(
                    audio[None, i : i + 1024].astype(np.float32), format="fltp", layout="mono"
                )
                af.sample_rate, af.pts, af.time_base = rate, i, Fraction(1, rate)
                for p in aus.encode(af):
                    out.mux(p)
            for p in aus.encode(None):
                out.mux(p)
        for k, t in enumerate(times):
            vf = av.VideoFrame.from_ndarray(frame_image(k), format="rgb24")
            vf.pts = round(t / time_base)
            vf.time_base = time_base
            for p in vs.encode(vf):
                out.mux(p)
        for p in vs.encode(None):
            out.mux(p)
    return path


@pytest.fixture(scope="module")
def cfr(tmp_path_factory) -> Path:
    return write_video(
        tmp_path_factory.mktemp("v") / "cam_a.mp4", np.arange(45) / 30.0, time_base=Fraction(1, 30)
    )


def test_constant_rate_round_trip(cfr):
    with open_video(cfr) as v:
        i = v.info
        assert (i.name, i.width, i.height, i.n_frames) == ("cam_a", W, H, 45)
        assert i.fps == pytest.approx(30.0) and i.duration == pytest.approx(1.5)
        assert not i.has_audio and i.audio_rate is None
        np.testing.assert_allclose(v.timestamps(), np.arange(45) / 30.0, atol=1e-9)
        frames = list(v.frames())
        assert [f.index for f in frames] == list(range(45))
        assert [decoded_index(f.image) for f in frames] == [k % 30 for k in range(45)]
        assert frames[0].image.shape == (H, W, 3) and frames[0].image.dtype == np.uint8
        gray = next(v.frames(gray=True)).image
        assert gray.shape == (H, W)
        with pytest.raises(ValueError, match=r"^gray: expected a bool"):  # "no" gave gray
            next(v.frames(gray="no"))  # type: ignore[arg-type]
        with pytest.raises(ValueError, match=r"^gray: expected a bool"):
            v.frame_at(0.0, gray=1)  # type: ignore[arg-type]


def test_streaming_at_10_fps_gives_the_nearest_frames(cfr):
    with open_video(cfr) as v:
        got = list(v.frames(fps=10))
        assert [f.index for f in got] == [0, 3, 6, 9, 12, 15, 18, 21, 24, 27, 30, 33, 36, 39, 42]
        np.testing.assert_allclose([f.time for f in got], np.arange(15) / 10, atol=1e-9)
        assert [decoded_index(f.image) for f in got] == [k % 30 for k in range(0, 45, 3)]
        # a window and a rate above the video's: frames repeat, times stay the frames' own
        sub = list(v.frames(fps=50, start=0.5, end=0.6))  # 0.5, 0.52, ..., 0.58 s
        assert [f.index for f in sub] == [15, 16, 16, 17, 17]
        assert next(iter(v.frames(fps=10, start=1.0, end=1.2))).index == 30
        assert v.frame_at(0.52).index == 16 and decoded_index(v.frame_at(0.52).image) == 16
        assert v.frame_at(99.0).index == 44
        # given local times (the overlays' common-clock grid minus an offset): the nearest
        # frame to each, repeats kept, decoded once
        at = [0.41, 0.45, 0.46, 0.47, 1.2]
        assert [f.index for f in v.frames(at=at)] == [12, 13, 14, 14, 36]
        assert [decoded_index(f.image) for f in v.frames(at=at)] == [12, 13, 14, 14, 6]
        with pytest.raises(ValueError, match="at"):
            list(v.frames(at=[0.5, 0.1]))
        # what the overlay videos and the .rrd frames stream: (index into the times, image),
        # times beyond the video skipped
        from socialcam.pipeline import frames_at

        got = [(j, decoded_index(img)) for j, img in frames_at(v, np.array([-1, 0.41, 0.47, 9]))]
        assert got == [(1, 12), (2, 14)]


def test_variable_frame_rate_uses_container_timestamps(tmp_path):
    rng = np.random.default_rng(0)
    times = np.round(np.cumsum(np.r_[0.0, rng.uniform(0.02, 0.07, 39)]), 3)  # ms time base
    path = write_video(tmp_path / "vfr.mp4", times)
    with open_video(path) as v:
        np.testing.assert_allclose(v.timestamps(), times - times[0], atol=1e-9)
        got = list(v.frames(fps=10))
        out_t = np.arange(len(got)) / 10
        want = np.abs(times[None, :] - out_t[:, None]).argmin(axis=1)
        assert [f.index for f in got] == list(want)
        assert [decoded_index(f.image) for f in got] == [k % 30 for k in want]


def test_hevc_and_mov(tmp_path):
    hevc = write_video(
        tmp_path / "h.mp4", np.arange(10) / 25.0, codec="libx265", time_base=Fraction(1, 25)
    )
    mov = write_video(tmp_path / "m.mov", np.arange(10) / 25.0, time_base=Fraction(1, 25))
    for p in (hevc, mov):
        with open_video(p) as v:
            assert v.info.n_frames == 10
            assert [decoded_index(f.image) for f in v.frames()] == list(range(10))


def test_audio_track_is_on_the_local_clock(tmp_path):
    rate = 48000
    x = np.zeros(rate, np.float32)
    click = 0.4123  # s
    i0 = round(click * rate)
    x[i0 : i0 + 48] = np.sin(np.arange(48) * 0.9) * 0.8
    path = write_video(tmp_path / "aud.mp4", np.arange(30) / 30.0, audio=x)
    with open_video(path) as v:
        assert v.info.has_audio and v.info.audio_rate == rate
        y, r = v.audio()
        assert r == rate and y.dtype == np.float32 and y.ndim == 1
        c = np.correlate(y[:rate], x[i0 - 100 : i0 + 200], mode="valid")
        found = (np.argmax(c) + 100) / rate
        assert abs(found - click) < 0.0005  # AAC priming compensated (measured: exact)


def test_folder_of_numbered_frames(tmp_path):
    d = tmp_path / "frames"
    d.mkdir()
    for k in (1, 2, 10, 11):  # natural order: 1, 2, 10, 11
        cv2.imwrite(str(d / f"frame_{k}.png"), frame_image(k))
    (d / "notes.txt").write_text("not an image")
    with open_video(d, fps=5) as v:
        assert v.info.n_frames == 4 and v.info.name == "frames"
        np.testing.assert_allclose(v.timestamps(), [0, 0.2, 0.4, 0.6])
        assert [decoded_index(f.image) for f in v.frames()] == [1, 2, 10, 11]
        with pytest.raises(ValueError, match="no audio"):
            v.audio()
    with pytest.raises(ValueError, match="fps"):
        open_video(d)
    (d / "frame_12.png").write_bytes(b"garbage")
    with open_video(d, fps=5) as v, pytest.warns(CorruptFrameWarning, match="frame_12"):
        got = [f.index for f in v.frames()]
    assert got == [0, 1, 2, 3] and v.n_corrupt == 1


def test_not_a_video_and_other_bad_input(tmp_path):
    txt = tmp_path / "notes.mp4"
    txt.write_text("hello, I am not a video\n" * 50)
    with pytest.raises(ValueError, match=r"notes\.mp4"):
        open_video(txt)
    with pytest.raises(ValueError, match="does not exist"):
        open_video(tmp_path / "missing.mp4")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="no images"):
        open_video(empty, fps=30)
    # audio only: no video stream
    m4a = tmp_path / "voice.m4a"
    with av.open(str(m4a), "w") as out:
        s = out.add_stream("aac", rate=48000)
        s.layout = "mono"
        af = av.AudioFrame.from_ndarray(
            np.zeros((1, 1024), np.float32), format="fltp", layout="mono"
        )
        af.sample_rate = 48000
        for p in s.encode(af):
            out.mux(p)
        for p in s.encode(None):
            out.mux(p)
    with pytest.raises(ValueError, match=r"voice.m4a.*no video stream"):
        open_video(m4a)
    with pytest.raises(ValueError, match="path"):
        open_video(3)  # type: ignore[arg-type]


def test_corrupt_file_is_read_without_crashing(tmp_path, cfr):
    data = bytearray(cfr.read_bytes())
    # overwrite a stretch in the middle of the media data (mdat box) with garbage
    rng = np.random.default_rng(1)
    m = data.find(b"mdat")
    size = int.from_bytes(data[m - 4 : m], "big")
    mid = m + size // 2
    data[mid : mid + 300] = rng.integers(0, 256, 300, dtype=np.uint8).tobytes()
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(bytes(data))
    with open_video(bad) as v, warnings.catch_warnings():
        warnings.simplefilter("ignore", CorruptFrameWarning)
        got = list(v.frames())
        # every frame either decodes or is skipped and counted; never a crash
        # (measured: 24 decoded + 21 skipped)
        assert len(got) + v.n_corrupt == 45 and v.n_corrupt > 0
        assert len({f.index for f in got}) == len(got)
    truncated = tmp_path / "cut.mp4"
    truncated.write_bytes(cfr.read_bytes()[: m + size // 2])  # the index (moov) is lost
    with pytest.raises(ValueError, match=r"cut\.mp4"):
        open_video(truncated)
