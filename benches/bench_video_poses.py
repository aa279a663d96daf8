"""Issue-9 bench: videos → camera poses, against truth, beside the reference alternative.

For each seed: renders (or reuses) a scene of ``--wearers`` × ``--duration`` s at
``--size`` (the renderer's default scene), runs ``socialcam.poses`` at 10 fps, and prints
the registered fraction, centre / rotation errors after one similarity fit (per frame:
median, p95, max), synchronisation error, every stage's wall time, peak memory (RSS high
water mark of this process; with ``--tracemalloc`` also Python's own peak, which slows the
Python stages (every allocation is traced), so such a run's times are not the speed figure),
then the spread over seeds.

Reference: plain pycolmap incremental SfM over every output frame (10 fps) — SIFT on every
frame (pycolmap defaults), sequential matching (overlap 10, no loop detection: the
vocabulary tree would abort the process here) and incremental mapping. It runs on the
first ``--ref-seconds`` of every video and its cost is extrapolated linearly to the whole
scene (a lower bound: mapping grows faster than linearly with the number of images).

    python benches/bench_video_poses.py --seeds 0 1 2 --scenes /tmp/scenes
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

import socialcam as sc
from socialcam.sfm import KnownDistance, pose_errors


def _scene(root: Path, seed: int, args: argparse.Namespace):
    from socialcam.synth.render import load_truth, render_scene

    w, h = args.size
    lens = "" if args.lens == "pinhole" else f"_{args.lens}"
    d = root / f"w{args.wearers}_d{args.duration:g}_{w}x{h}_s{seed}{lens}"
    if (d / "truth.npz").is_file():
        truth = load_truth(d / "truth.npz")
        return [d / f"{n}.mp4" for n in truth.names], truth, 0.0
    t0 = time.perf_counter()
    s = render_scene(
        d,
        n_wearers=args.wearers,
        duration=args.duration,
        size=(w, h),
        seed=seed,
        distortion=None if args.lens == "pinhole" else args.lens,
        progress=False,
    )
    return list(s.videos), s.truth, time.perf_counter() - t0


def _known_distance(truth) -> KnownDistance:
    ca, cb = truth.cameras(0), truth.cameras(1 if len(truth.names) > 1 else 0)
    i = len(ca) // 3
    j = int(np.argmin(np.abs(cb.times - ca.times[i]))) if len(truth.names) > 1 else 2 * i
    return KnownDistance(
        truth.names[0],
        float(ca.times[i]),
        truth.names[1 if len(truth.names) > 1 else 0],
        float(cb.times[j]),
        float(np.linalg.norm(ca.C[i] - cb.C[j])),
    )


def _reference(videos, out: Path, seconds: float, fps: float, total_frames: int) -> dict:
    """Plain pycolmap SfM on every output frame of the first ``seconds`` of each video."""
    import cv2
    import pycolmap

    from socialcam.video import open_video

    img = out / "images"
    n = 0
    for p in videos:
        (img / p.stem).mkdir(parents=True)
        with open_video(p) as v:
            for k, fr in enumerate(v.frames(fps=fps, end=seconds)):
                cv2.imwrite(str(img / p.stem / f"{k:06d}.png"), fr.image[:, :, ::-1])
                n += 1
    db = out / "db.db"
    times = {}
    t0 = time.perf_counter()
    ext = pycolmap.FeatureExtractionOptions()
    ext.num_threads = 2
    pycolmap.extract_features(
        db,
        img,
        camera_mode=pycolmap.CameraMode.PER_FOLDER,
        extraction_options=ext,
        device=pycolmap.Device.cpu,
    )
    times["features"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    pairing = pycolmap.SequentialPairingOptions()
    pairing.overlap = 10
    pairing.quadratic_overlap = False
    pairing.loop_detection = False
    match = pycolmap.FeatureMatchingOptions()
    match.num_threads = 2
    pycolmap.match_sequential(
        db, pairing_options=pairing, matching_options=match, device=pycolmap.Device.cpu
    )
    times["matching"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    (out / "sparse").mkdir()
    opts = pycolmap.IncrementalPipelineOptions()
    opts.num_threads = 2
    models = pycolmap.incremental_mapping(db, img, out / "sparse", options=opts)
    times["mapping"] = time.perf_counter() - t0
    reg = max((m.num_reg_images() for m in models.values()), default=0)
    measured = sum(times.values())
    return {
        "frames": n,
        "registered": reg,
        "stage_seconds": times,
        "measured_seconds": measured,
        "extrapolated_seconds": measured * total_frames / max(n, 1),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--wearers", type=int, default=4)
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--size", type=int, nargs=2, default=[640, 480])
    ap.add_argument("--fps", type=float, default=10.0)
    ap.add_argument("--scenes", type=Path, default=Path(tempfile.gettempdir()) / "socialcam-scenes")
    ap.add_argument("--manual-sync", action="store_true", help="true offsets instead of audio")
    ap.add_argument("--ref-seconds", type=float, default=3.0)
    ap.add_argument("--no-reference", action="store_true")
    ap.add_argument(
        "--tracemalloc", action="store_true", help="also Python's peak memory (slows the run)"
    )
    ap.add_argument("--lens", choices=["pinhole", "radial", "fisheye"], default="pinhole")
    ap.add_argument("--camera-model", default=None, help="COLMAP model (default: SIMPLE_RADIAL)")
    args = ap.parse_args()
    args.size = tuple(args.size)
    rows = []
    ref = None
    for seed in args.seeds:
        videos, truth, t_render = _scene(args.scenes, seed, args)
        sync = None
        if args.manual_sync:
            sync = {n: float(truth.start[v] - truth.start[0]) for v, n in enumerate(truth.names)}
        out = Path(tempfile.mkdtemp(prefix=f"bench_poses_{seed}_"))
        if args.tracemalloc:
            tracemalloc.start()
        t0 = time.perf_counter()
        c0 = time.process_time()  # CPU of every thread of this process: load-independent
        rec = sc.poses(
            videos,
            out,
            fps=args.fps,
            sync=sync,
            known_distance=_known_distance(truth),
            progress=False,
            **({} if args.camera_model is None else {"camera_model": args.camera_model}),
        )
        wall = time.perf_counter() - t0
        cpu = time.process_time() - c0
        py_peak = float("nan")
        if args.tracemalloc:
            _, py_peak = tracemalloc.get_traced_memory()
            tracemalloc.stop()
        e = pose_errors(rec, {n: truth.cameras(v) for v, n in enumerate(truth.names)})
        d = rec.to_dict()
        sync_err = np.abs(rec.offsets - (truth.start - truth.start[0]))
        row = {
            "seed": seed,
            "render_s": t_render,
            "wall_s": wall,
            "cpu_s": cpu,
            "load_avg_1min": os.getloadavg()[0],
            "registered_fraction": d["registered_fraction"],
            "frames": d["n_frames"],
            "posed": d["n_posed"],
            "centre_median_mm": 1000 * float(np.median(e.centre)),
            "centre_p95_mm": 1000 * float(np.percentile(e.centre, 95)),
            "centre_max_mm": 1000 * float(e.centre.max()),
            "rotation_median_deg": float(np.degrees(np.median(e.rotation))),
            "rotation_max_deg": float(np.degrees(e.rotation.max())),
            "scale_error_pct": 100 * abs(e.scale - 1.0),
            "sync_max_error_ms": 1000 * float(sync_err.max()),
            "stages_s": d["timings"],
            "py_peak_mb": py_peak / 2**20,
            "rss_peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "warnings": d["warnings"],
            "counts": d["counts"],
        }
        rows.append(row)
        print(json.dumps(row, default=float), flush=True)
        if ref is None and not args.no_reference:
            rdir = Path(tempfile.mkdtemp(prefix="bench_poses_ref_"))
            ref = _reference(videos, rdir, args.ref_seconds, args.fps, d["n_frames"])
            shutil.rmtree(rdir, ignore_errors=True)
            print("reference", json.dumps(ref), flush=True)
        shutil.rmtree(out, ignore_errors=True)

    def spread(key: str) -> str:
        v = np.array([r[key] for r in rows], dtype=float)
        return f"{np.median(v):.3g} [{v.min():.3g}, {v.max():.3g}]"

    print(
        f"\n{len(rows)} seeds {args.seeds}, {args.wearers} wearers × {args.duration:g} s, "
        f"{args.size[0]}×{args.size[1]}, output {args.fps:g} fps — median [min, max]:"
    )
    for key in (
        "registered_fraction",
        "centre_median_mm",
        "centre_p95_mm",
        "centre_max_mm",
        "rotation_median_deg",
        "rotation_max_deg",
        "scale_error_pct",
        "sync_max_error_ms",
        "wall_s",
        "cpu_s",
        "load_avg_1min",
        "rss_peak_mb",
        "py_peak_mb",
    ):
        print(f"  {key:22s} {spread(key)}")
    stages = sorted({k for r in rows for k in r["stages_s"]}, key=list(rows[0]["stages_s"]).index)
    for k in stages:
        v = [r["stages_s"].get(k, 0.0) for r in rows]
        print(f"  stage {k:16s} {np.median(v):7.1f} s  [{min(v):.1f}, {max(v):.1f}]")
    if ref is not None:
        med = float(np.median([r["wall_s"] for r in rows]))
        print(
            f"  reference (plain pycolmap SfM on every {args.fps:g}-fps frame): "
            f"{ref['measured_seconds']:.1f} s measured on {ref['frames']} frames "
            f"(first {args.ref_seconds:g} s of each video, {ref['registered']} registered), "
            f"extrapolated linearly to {ref['extrapolated_seconds']:.0f} s for the scene; "
            f"ratio reference / socialcam = {ref['extrapolated_seconds'] / med:.1f}×"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
