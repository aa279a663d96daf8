"""Synchronisation of social-camera videos from their audio (thesis Sec 6.2: "we
synchronize the cameras using audio signals, e.g., a clap").

The common clock starts at the first frame of the first video given:
``t_common = t_local + offsets[v]`` with ``offsets[0] = 0``.

Method, per pair of videos (the reference against each other video, and for three or more
videos every pair, so the offsets are checked for consistency and refined jointly):

1. **Onset envelopes** — the audio is high-passed (300 Hz), cut into 10 ms windows every
   2.5 ms, and the positive part of the frame-to-frame change of log-energy is kept
   (log-energy flux). A gain only adds a constant to the log-energy, so the envelope does
   not depend on a microphone's gain; each envelope is then standardised.
2. **Coarse lag** — cross-correlation of the two envelopes (FFT) over every lag; the peak
   gives the offset to one envelope step (2.5 ms).
3. **Sub-sample refinement** — cross-correlation of the raw band-passed signals within
   ±3 envelope steps of the coarse lag, and parabolic interpolation of its peak: a
   fraction of a sample (20 µs at 48 kHz).
4. **Confidence** in [0, 1] — the normalised correlation of the raw waveforms in short
   windows at the onsets that are strong in both tracks once aligned (the same clap
   recorded by two microphones has the same waveform; two different sounds do not),
   lowered when the envelope peak barely stands out from the next-best lag outside ±50 ms
   (``separation = 1 - second / first`` below 0.3). Measured on rendered scenes: 0.71–0.99
   for videos of one scene, 0.16–0.49 for unrelated ones; below ``min_confidence`` (0.6)
   the audio does not agree and :class:`SyncError` is raised, naming the video, instead
   of returning a wrong offset.

Manual offsets (``manual_offsets={name: seconds}``) override the audio; a video without an
audio track needs one.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy import signal  # type: ignore[import-untyped]

from socialcam._validate import FloatArray, as_float_array, check_float, check_int, readonly
from socialcam.video import Video, open_video

F32 = npt.NDArray[np.float32]

HOP_S = 0.0025
WIN_S = 0.010
REFINE_STEPS = 3
SEPARATION_S = 0.05
#: default ``min_confidence``: between the largest value measured for unrelated audio
#: (0.49) and the smallest for videos of one scene (0.71, over 11 rendered scenes)
MIN_CONFIDENCE = 0.6
MAX_RESIDUAL = 0.002  # s: pairwise offsets must agree with the joint solution
SEPARATION_OK = 0.3  # envelope peak separation above which it does not lower confidence


class SyncError(ValueError):
    """The videos cannot be synchronised from their audio (no audio, or audio that does not
    agree); the message names the video and says to pass ``manual_offsets``."""


@dataclass(frozen=True)
class SyncResult:
    """Offsets of each video on the common clock.

    Attributes
    ----------
    names : (V,) video names (file stems)
    offsets : (V,) seconds; ``t_common = t_local + offsets[v]``; ``offsets[0] == 0``
    confidence : (V,) in [0, 1]; 1 for the reference and for manual offsets
    method : per video ``"reference" | "audio" | "manual"``
    residual : (V,) seconds: the largest disagreement between the pairwise audio offsets
        involving the video and the final offsets (0 with fewer than three audio videos)
    """

    names: tuple[str, ...]
    offsets: FloatArray
    confidence: FloatArray
    method: tuple[str, ...]
    residual: FloatArray

    def to_dict(self) -> dict[str, Any]:
        return {
            "reference": self.names[0],
            "clock": "t_common = t_local + offset; the common clock starts at the first "
            "frame of the reference",
            "videos": [
                {
                    "name": n,
                    "offset": float(o),
                    "confidence": float(c),
                    "method": m,
                    "residual": float(r),
                }
                for n, o, c, m, r in zip(
                    self.names,
                    self.offsets,
                    self.confidence,
                    self.method,
                    self.residual,
                    strict=True,
                )
            ],
        }


@dataclass(frozen=True)
class _Track:
    name: str
    x: F32  # band-passed samples, local clock
    env: FloatArray  # standardised onset envelope
    rate: int


def onset_envelope(x: npt.ArrayLike, rate: int) -> FloatArray:
    """Gain-invariant onset strength of ``x`` (mono samples at ``rate`` Hz): standardised
    positive log-energy flux, one value every 2.5 ms (value ``i`` at ``i · 2.5 ms``)."""
    a = as_float_array(x, "x", (None,))
    rate = check_int(rate, "rate", min=1)
    hop = max(1, round(HOP_S * rate))
    win = max(hop, round(WIN_S * rate))
    n = (len(a) - win) // hop + 1
    if n < 4:
        return np.zeros(max(n, 0))
    sq = np.concatenate([[0.0], np.cumsum(a * a)])
    starts = np.arange(n) * hop
    e = (sq[starts + win] - sq[starts]) / win
    floor = max(np.median(e) * 1e-2, 1e-12)
    le = np.log(e + floor)
    flux = np.maximum(np.diff(le, prepend=le[0]), 0.0)
    # the window ending at the onset reacts over its length: centre the response
    flux = np.roll(flux, -round(0.5 * win / hop) + 1)
    s = flux.std()
    return (flux - flux.mean()) / s if s > 0 else flux * 0.0


def _bandpass(x: F32, rate: int) -> F32:
    hi = min(8000.0, 0.45 * rate)
    sos = signal.butter(4, [300.0, hi], btype="bandpass", fs=rate, output="sos")
    return np.asarray(signal.sosfiltfilt(sos, x.astype(np.float64)), dtype=np.float32)


def _track(name: str, x: F32, rate: int, to_rate: int) -> _Track:
    if rate != to_rate:
        g = np.gcd(rate, to_rate)
        x = signal.resample_poly(x.astype(np.float64), to_rate // g, rate // g).astype(np.float32)
    if len(x) < to_rate * 0.05:
        raise SyncError(f"{name}: its audio is too short to synchronise; pass manual_offsets")
    b = _bandpass(x, to_rate)
    return _Track(name, b, onset_envelope(b, to_rate), to_rate)


def _pair(ref: _Track, other: _Track) -> tuple[float, float]:
    """Offset (s) such that ``t_ref = t_other + offset`` and its confidence."""
    rate = ref.rate
    hop = max(1, round(HOP_S * rate))
    a, b = ref.env, other.env
    if len(a) < 4 or len(b) < 4 or not a.any() or not b.any():
        return 0.0, 0.0
    c = signal.correlate(a, b, mode="full", method="fft")
    lags = signal.correlation_lags(len(a), len(b), mode="full")
    # lags with at least 20 % overlap of the shorter track
    overlap = np.minimum(len(a), lags + len(b)) - np.maximum(0, lags)
    ok = overlap >= min(len(a), len(b)) * 0.2
    c = np.where(ok, c, -np.inf)
    i = int(np.argmax(c))
    first = float(c[i])
    sep = round(SEPARATION_S / HOP_S)
    mask = np.abs(np.arange(len(c)) - i) > sep
    second = float(np.max(c[mask & ok])) if (mask & ok).any() else 0.0
    separation = 0.0 if first <= 0 else float(np.clip(1.0 - max(second, 0.0) / first, 0.0, 1.0))
    env_lag = int(lags[i])
    coarse = env_lag * hop  # samples
    picks = _shared_onsets(a, b, env_lag, rate, hop)
    if not picks:
        return coarse / rate, 0.0
    # sub-sample refinement on the raw signals, restricted to the shared events:
    # r(l) = Σ x_w[n] y[n - l] with x windowed around the events (-5 ms, +40 ms)
    x, y = ref.x.astype(np.float64), other.x.astype(np.float64)
    xw = np.zeros_like(x)
    for p in picks:
        s0, s1 = max(0, p - int(0.005 * rate)), min(len(x), p + int(0.04 * rate))
        xw[s0:s1] = x[s0:s1]
    w = (REFINE_STEPS + 1) * hop
    r_full = signal.correlate(xw, y, mode="full", method="fft")
    r_lags = signal.correlation_lags(len(xw), len(y), mode="full")
    sel = (r_lags >= coarse - w) & (r_lags <= coarse + w)
    r = r_full[sel]
    ls = r_lags[sel]
    if len(r) == 0:
        return coarse / rate, 0.0
    j = int(np.argmax(r))
    frac = 0.0
    if 0 < j < len(r) - 1:
        den = r[j - 1] - 2 * r[j] + r[j + 1]
        if den < 0:
            frac = float(np.clip(0.5 * (r[j - 1] - r[j + 1]) / den, -0.5, 0.5))
    lag = float(ls[j]) + frac
    ncc = _event_ncc(x, y, int(ls[j]), picks, rate)
    # the waveform agreement decides; a barely distinguishable envelope peak lowers it
    return lag / rate, max(ncc, 0.0) * min(1.0, separation / SEPARATION_OK)


def _shared_onsets(
    env_x: FloatArray, env_y: FloatArray, env_lag: int, rate: int, hop: int
) -> list[int]:
    """Sample positions (in ``x``) of the onsets strong in both envelopes once aligned by
    ``env_lag``: at most five, 100 ms apart, each ≥ 3 standard deviations in both."""
    n = len(env_x)
    k = np.arange(n)
    kb = k - env_lag
    ok = (kb >= 0) & (kb < len(env_y))
    both = np.full(n, -np.inf)
    both[ok] = np.minimum(env_x[ok], env_y[kb[ok]])
    guard = int(0.1 * rate / hop)
    picks: list[int] = []
    for _ in range(5):
        i = int(np.argmax(both))
        if not np.isfinite(both[i]) or both[i] < 3.0:
            break
        both[max(0, i - guard) : i + guard] = -np.inf
        picks.append(i * hop)
    return sorted(picks)


def _event_ncc(x: FloatArray, y: FloatArray, lag: int, picks: list[int], rate: int) -> float:
    """Normalised correlation of ``x[n]`` and ``y[n - lag]`` in short windows (2 ms
    before to 15 ms after) at the shared onsets: the same clap recorded by two microphones
    has the same waveform, two different sounds do not. 0 when there is none."""
    pre, post = int(0.002 * rate), int(0.015 * rate)
    num = sxx = syy = 0.0
    for p in picks:
        s0, s1 = max(p - pre, lag, 0), min(p + post, len(x), len(y) + lag)
        if s1 - s0 < 8:
            continue
        a = x[s0:s1]
        b = y[s0 - lag : s1 - lag]
        num += float(a @ b)
        sxx += float(a @ a)
        syy += float(b @ b)
    if sxx <= 0 or syy <= 0:
        return 0.0
    return num / np.sqrt(sxx * syy)


def synchronize(
    videos: Sequence[str | Path | Video],
    *,
    manual_offsets: Mapping[str, float] | None = None,
    min_confidence: float = MIN_CONFIDENCE,
) -> SyncResult:
    """Offsets of ``videos`` on the common clock (the first video's first frame is 0).

    ``videos`` are paths or open :class:`~socialcam.video.Video`; a video's name is its
    file stem. ``manual_offsets`` maps names to offsets in seconds (``t_common = t_local +
    offset``) and overrides the audio. Raises :class:`SyncError` (a ``ValueError``) naming
    the video when its audio does not agree with the others (confidence below
    ``min_confidence``) or it has no audio and no manual offset.
    """
    if isinstance(videos, (str, Path, Video)) or len(videos) == 0:
        raise ValueError("videos: expected a non-empty sequence of videos")
    minc = check_float(min_confidence, "min_confidence", min=0.0, max=1.0)
    manual = dict(manual_offsets or {})
    opened: list[Video] = []
    vids: list[Video] = []
    try:
        for item in videos:
            if isinstance(item, Video):
                vids.append(item)
            else:
                vid = open_video(item)
                opened.append(vid)
                vids.append(vid)
        names = tuple(v.info.name for v in vids)
        if len(set(names)) != len(names):
            raise ValueError(f"videos: two videos share a name (file stem): {names}")
        for k, val in manual.items():
            if k not in names:
                raise ValueError(f"manual_offsets: {k!r} is not one of the videos {names}")
            check_float(val, f"manual_offsets[{k!r}]")
        if names[0] in manual and manual[names[0]] != 0:
            raise ValueError(
                f"manual_offsets: the reference {names[0]!r} (first video) has offset 0 by "
                "definition"
            )
        V = len(vids)
        offsets = np.zeros(V)
        conf = np.ones(V)
        method = ["reference"] + ["manual" if n in manual else "audio" for n in names[1:]]
        for v in range(1, V):
            if names[v] in manual:
                offsets[v] = float(manual[names[v]])
        need = [v for v in range(1, V) if method[v] == "audio"]
        residual = np.zeros(V)
        if need:
            for v in [0, *need]:
                if not vids[v].info.has_audio:
                    who = names[v]
                    what = (
                        "the reference (first video) has no audio track: pass manual_offsets "
                        "for every other video"
                        if v == 0
                        else "has no audio track: pass its offset, e.g. "
                        f"manual_offsets={{{who!r}: seconds}}"
                    )
                    raise SyncError(f"{who}: {what}")
            raw = {v: vids[v].audio() for v in [0, *need]}
            rate = raw[0][1]
            tracks = {v: _track(names[v], x, r, rate) for v, (x, r) in raw.items()}
            del raw
            offsets, conf, residual = _solve(tracks, need, offsets, conf, names, minc)
        offsets = offsets - offsets[0]
        return SyncResult(
            names=names,
            offsets=readonly(offsets),
            confidence=readonly(conf),
            method=tuple(method),
            residual=readonly(residual),
        )
    finally:
        for vid in opened:
            vid.close()


def _solve(
    tracks: dict[int, _Track],
    need: list[int],
    offsets: FloatArray,
    conf: FloatArray,
    names: tuple[str, ...],
    minc: float,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Pairwise offsets (reference and, with ≥ 3 audio videos, all pairs), then the least
    squares offsets over the confident pairs; SyncError for a video that does not agree."""
    ids = [0, *need]
    pairs: dict[tuple[int, int], tuple[float, float]] = {}
    for v in need:
        pairs[(0, v)] = _pair(tracks[0], tracks[v])
    if len(ids) >= 3:
        for a_i, a in enumerate(need):
            for b in need[a_i + 1 :]:
                pairs[(a, b)] = _pair(tracks[a], tracks[b])
    out = offsets.copy()
    cout = conf.copy()
    for v in need:
        best = max(c for (a, b), (_, c) in pairs.items() if v in (a, b))
        direct = pairs[(0, v)][1]
        cout[v] = direct
        if best < minc:
            raise SyncError(
                f"{names[v]}: its audio does not agree with the other videos (confidence "
                f"{best:.2f} < min_confidence {minc:.2f}); pass its offset with "
                f"manual_offsets={{{names[v]!r}: seconds}}"
            )
    # joint least squares: offset[b] - offset[a] = o_ab for every confident pair
    good = [(a, b, o, c) for (a, b), (o, c) in pairs.items() if c >= minc]
    col = {v: i for i, v in enumerate(need)}
    A = np.zeros((len(good), len(need)))
    y = np.zeros(len(good))
    w = np.zeros(len(good))
    for r, (a, b, o, c) in enumerate(good):
        if b in col:
            A[r, col[b]] += 1.0
        if a in col:
            A[r, col[a]] -= 1.0
        y[r] = o
        w[r] = c
    if np.linalg.matrix_rank(A) < len(need):
        lost = [names[v] for v in need if not A[:, col[v]].any()]
        raise SyncError(
            f"{', '.join(lost)}: cannot be placed on the common clock from the audio; pass "
            "manual_offsets"
        )
    sol, *_ = np.linalg.lstsq(A * w[:, None], y * w, rcond=None)
    for v in need:
        out[v] = sol[col[v]]
        if (0, v) in pairs and pairs[(0, v)][1] < minc:
            # placed through other videos only: confidence of its best pair
            cout[v] = max(c for (a, b), (_, c) in pairs.items() if v in (a, b))
    res = np.zeros(len(out))
    worst = (0.0, 0, 0)
    for a, b, o, _c in good:
        d = abs(out[b] - out[a] - o)
        res[a] = max(res[a], d)
        res[b] = max(res[b], d)
        worst = max(worst, (d, a, b))
    if worst[0] > MAX_RESIDUAL:
        d, a, b = worst
        raise SyncError(
            f"{names[a]}, {names[b]}: their audio offset disagrees by {1e3 * d:.1f} ms with "
            "the offsets through the other videos; pass manual_offsets for the one that is wrong"
        )
    return out, cout, res
