"""Trajectory reconstruction on real human motion: every joint/marker trajectory of each CMU
motion-capture trial in a folder (``*.bvh``, ``*.c3d``) is reconstructed from synthetic
"many photographers" cameras (one random photo per frame, 1 px noise, K by 5-fold cross
validation, refinement), and the mean relative error ``‖X − X̂‖ / ‖X‖`` per trial is printed
(lab coordinates, metres, z up), with the RMS error in millimetres.

    python benches/mocap_trajectory_report.py [--data FOLDER_OF_BVH_OR_C3D] [--step 4]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import socialcam as sc
from socialcam import synth
from socialcam.mocap import load_bvh, load_c3d

Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def load(path: Path) -> tuple[np.ndarray, float]:
    """``(F, J, 3)`` positions in metres (NaN gaps), z up, and the frame rate."""
    if path.suffix.lower() == ".bvh":
        m = load_bvh(path)
        return m.positions @ Y_UP_TO_Z_UP.T, m.fps
    c = load_c3d(path)
    return c.positions @ Y_UP_TO_Z_UP.T, c.fps


def report(path: Path, step: int, k_max: int, seeds: list[int]) -> dict[str, object]:
    pos, fps = load(path)
    pos = pos[::step]
    X = np.transpose(pos, (1, 0, 2))  # (J, F, 3)
    n, f = X.shape[:2]
    times = np.arange(f) * step / fps
    centre = np.nanmean(pos.reshape(-1, 3), axis=0)
    seen = ~np.isnan(X).any(-1)
    rels, rmss, ks, secs = [], [], [], []
    for seed in seeds:
        cams = synth.random_photographers(
            f, seed=seed, times=times, target=(centre[0], centre[1], 1.0)
        )
        obs = synth.observe(np.nan_to_num(X), cams, noise_px=1.0, seed=seed + 1)
        x = obs.x.copy()
        x[~seen] = np.nan
        t0 = time.perf_counter()
        b = sc.reconstruct_trajectories(x, cams, k_max=k_max)
        secs.append(time.perf_counter() - t0)
        ok = seen & b.ok[:, None]
        e = np.linalg.norm(b.points - X, axis=-1)[ok]
        rels.append(float((e / np.linalg.norm(X, axis=-1)[ok]).mean()))
        rmss.append(float(np.sqrt((e**2).mean())))
        ks.append(float(np.median(b.k[b.ok])))
        if not b.ok.all():
            print(f"  {path.name}: {int((~b.ok).sum())} trajectories failed")
    return {
        "trial": path.name,
        "trajectories": n,
        "frames": f,
        "fps": fps / step,
        "mean_relative_error": float(np.mean(rels)),
        "rms_error_mm": 1e3 * float(np.mean(rmss)),
        "median_k": float(np.median(ks)),
        "seconds": float(np.mean(secs)),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--data", type=Path, required=True, help="folder of *.bvh / *.c3d trials")
    ap.add_argument("--step", type=int, default=4, help="keep every n-th frame (120 → 30 Hz)")
    ap.add_argument("--k-max", type=int, default=80)
    ap.add_argument("--seeds", type=int, default=3, help="camera draws averaged per trial")
    ap.add_argument("--json", type=Path, help="also write the rows as JSON")
    args = ap.parse_args()
    files = sorted(p for p in args.data.iterdir() if p.suffix.lower() in (".bvh", ".c3d"))
    if not files:
        raise SystemExit(f"no .bvh/.c3d files in {args.data}")
    rows = [report(p, args.step, args.k_max, list(range(0, 10 * args.seeds, 10))) for p in files]
    print(
        f"{'trial':<22}{'traj':>6}{'frames':>8}{'Hz':>6}{'mean rel. err':>15}"
        f"{'RMS mm':>9}{'med K':>7}{'s':>7}"
    )
    for r in rows:
        print(
            f"{r['trial']:<22}{r['trajectories']:>6}{r['frames']:>8}{r['fps']:>6.0f}"
            f"{r['mean_relative_error']:>15.4%}{r['rms_error_mm']:>9.1f}{r['median_k']:>7.0f}"
            f"{r['seconds']:>7.2f}"
        )
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
