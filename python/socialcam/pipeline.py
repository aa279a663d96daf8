"""The video pipeline behind ``socialcam poses``: videos → synchronised camera poses.

A run folder (DESIGN.md, "A run folder") receives ``poses.csv``, ``sync.json``,
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
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from socialcam.io import atomic_write_bytes, write_json
from socialcam.sfm import (
    KnownDistance,
    VideoPosesWarning,
    VideoReconstruction,
    VideoSfmOptions,
    _options,
    _quat_wxyz,
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
    **overrides: Any,
) -> VideoReconstruction:
    """Camera poses of every video at ``fps`` on one clock, written to ``out_dir``.

    Writes ``poses.csv`` (``person,time,cx,cy,cz,qw,qx,qy,qz``), ``sync.json`` (offset,
    confidence and method per video), ``report.json`` (stage times, counts, per-frame
    quality summary, dropped frames with reasons, warnings) and ``cache/sfm``. A rerun with
    the same videos and options reloads the cached reconstruction instead of recomputing.
    Arguments as :func:`socialcam.sfm.reconstruct_videos`.
    """
    opts = _options(options, {**overrides, "fps": fps})
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
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
    key = _input_key(videos, settings)
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
    write_json(out / "report.json", report)
    return rec


def _at(seq: Any, i: int) -> Any:
    try:
        return seq[i]
    except (TypeError, IndexError, KeyError):
        return None
