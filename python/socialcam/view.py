"""``socialcam view DIR``: a run folder as a rerun recording (``.rrd``, the optional
``rerun`` extra: ``pip install socialcam[rerun]``; open it with ``rerun FILE.rrd``).

The recording has one timeline, ``time`` (the common clock, seconds): the static map
points; every wearer's camera (pose and pinhole, with its video frame at the output rate);
the primary gaze rays; the social charges with their confidence ellipsoids, coloured by
track, and the tracks as lines.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

#: Length of the drawn gaze arrows, metres.
RAY_LENGTH = 2.0


def _import_rerun() -> Any:
    try:
        import rerun as rr
    except ImportError:
        raise ValueError(
            "rerun: the rerun-sdk package is not installed: pip install 'socialcam[rerun]'"
        ) from None
    return rr


def write_rrd(
    run_dir: str | os.PathLike[str],
    path: str | os.PathLike[str] | None = None,
    *,
    frames: bool = True,
    jpeg_quality: int = 75,
) -> Path:
    """Writes the rerun recording of the run folder ``run_dir`` (what :func:`socialcam.
    pipeline.run` wrote) to ``path`` (default ``run_dir/run.rrd``) and returns the path.
    ``frames``: include the video frames (JPEG at ``jpeg_quality``).

    Raises ``ValueError`` when rerun-sdk is missing or ``run_dir`` holds no finished run.
    """
    from socialcam._validate import check_bool
    from socialcam.pipeline import _charge_from_dict, _track_from_dict, load_poses

    frames = check_bool(frames, "frames")

    rr = _import_rerun()
    out = Path(run_dir)
    need = [out / "cache" / s for s in ("sfm", "gaze", "charges", "tracks")]
    if not all((d / "key.txt").is_file() for d in need):
        raise ValueError(f"run_dir: {out} holds no finished socialcam run (run it first)")
    rec = load_poses(out)
    with np.load(out / "cache" / "gaze" / "gaze.npz") as z:
        gz = {k: z[k] for k in z.files}
    times = gz["times"]
    charges = [
        [_charge_from_dict(c) for c in cs]
        for cs in json.loads((out / "cache" / "charges" / "charges.json").read_text())
    ]
    tracks = [
        _track_from_dict(d)
        for d in json.loads((out / "cache" / "tracks" / "tracks.json").read_text())
    ]
    manifest = json.loads((out / "run.json").read_text()) if (out / "run.json").is_file() else {}
    videos = dict(zip(manifest.get("names", []), manifest.get("videos", []), strict=False))
    dest = Path(path) if path is not None else out / "run.rrd"
    stream = rr.RecordingStream("socialcam")
    stream.save(str(dest.with_name(dest.name + ".tmp")))
    palette = np.array(
        [[230, 25, 75], [60, 180, 75], [255, 225, 25], [0, 130, 200], [245, 130, 48],
         [145, 30, 180], [70, 240, 240], [240, 50, 230]], dtype=np.uint8,
    )  # fmt: skip
    track_of = {
        (int(f), hash(p.tobytes())): tr.id
        for tr in tracks
        for f, p in zip(tr.frames, tr.positions, strict=True)
    }
    # static: map, tracks
    stream.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    if len(rec.points):
        stream.log("world/map", rr.Points3D(rec.points, colors=rec.colors, radii=0.01), static=True)
    for tr in tracks:
        stream.log(
            f"world/tracks/{tr.id}",
            rr.LineStrips3D([tr.positions], colors=palette[tr.id % len(palette)], radii=0.01),
            static=True,
        )
    # cameras (every posed frame) and their images at the output times
    for i, n in enumerate(rec.names):
        cams = rec.cameras.get(n)
        if cams is None or len(cams) == 0:
            continue
        assert cams.times is not None
        w, h = _resolution(cams.K[0])
        for k in range(len(cams)):
            stream.set_time("time", duration=float(cams.times[k]))
            stream.log(
                f"world/{n}",
                rr.Transform3D(translation=cams.C[k], mat3x3=cams.R[k].T),
            )
        stream.log(
            f"world/{n}",
            rr.Pinhole(image_from_camera=cams.K[0], resolution=[w, h], camera_xyz=rr.ViewCoordinates.RDF),
            static=True,
        )  # fmt: skip
        if frames and n in videos and os.path.exists(videos[n]):
            _log_frames(
                stream, rr, f"world/{n}", videos[n], float(rec.offsets[i]), times, jpeg_quality
            )
    # gaze rays and charges per output time
    names = list(rec.names)
    for k, t in enumerate(times):
        stream.set_time("time", duration=float(t))
        P, V, labels = [], [], []
        for n in names:
            if f"{n}.p" in gz and np.isfinite(gz[f"{n}.p"][k]).all():
                P.append(gz[f"{n}.p"][k])
                V.append(RAY_LENGTH * gz[f"{n}.v"][k])
                labels.append(n)
        stream.log("world/gaze", rr.Arrows3D(origins=P, vectors=V, labels=labels))
        cs = charges[k]
        tid = [track_of.get((k, hash(c.position.tobytes())), -1) for c in cs]
        col = [
            palette[t_ % len(palette)] if t_ >= 0 else np.array([160, 160, 160], np.uint8)
            for t_ in tid
        ]
        quats = [_quat_xyzw(c.region_axes) for c in cs]
        stream.log(
            "world/charges",
            rr.Ellipsoids3D(
                centers=[c.region_centre for c in cs],
                half_sizes=[np.minimum(c.region_radii, 2.0) for c in cs],
                quaternions=quats,
                colors=col,
                labels=[f"#{t_} " + ",".join(names[int(m)] for m in c.members) for t_, c in zip(tid, cs, strict=True)],
            ),
        )  # fmt: skip
    stream.flush()
    stream.disconnect()
    os.replace(dest.with_name(dest.name + ".tmp"), dest)
    return dest


def _resolution(K: np.ndarray) -> tuple[int, int]:
    # principal point at the image centre (pixel (0, 0) at the centre of the top-left pixel)
    return round(2 * K[0, 2] + 1), round(2 * K[1, 2] + 1)


def _quat_xyzw(axes: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation  # type: ignore[import-untyped,unused-ignore]

    M = np.asarray(axes, dtype=float)
    if np.linalg.det(M) < 0:
        M = M * np.array([1.0, 1.0, -1.0])
    return np.asarray(Rotation.from_matrix(M).as_quat())


def _log_frames(
    stream: Any, rr: Any, entity: str, video: str, offset: float, times: np.ndarray, quality: int
) -> None:
    from socialcam.pipeline import frames_at
    from socialcam.video import open_video

    with open_video(Path(video)) as vid:
        for j, image in frames_at(vid, times - offset):
            stream.set_time("time", duration=float(times[j]))
            stream.log(entity, rr.Image(image).compress(jpeg_quality=quality))
