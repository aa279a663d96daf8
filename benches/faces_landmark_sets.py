"""Which FaceMesh landmarks tell a face's direction on the rendered circles (issue 11)?

Two questions about the faces the renderer draws (a photograph on the front of a head box),
asked of FaceMesh's full 478-point output on the same crops ``refine_landmarks`` uses:

1. **One view**: FaceMesh's own mesh carries a relative depth per point, so its face frame
   (eye corners 33 → 263 across, chin 152 → forehead 10 up, normal = across × up; weak
   perspective along the ray to the face) is a per-view head direction. Printed: its yaw
   against the true yaw of the view, by bands of the true yaw.
2. **Several views at one instant**: every point of a set triangulated (linear DLT over the
   views that see the face), the plane fitted through them, its normal against the true
   face normal; per set of points and by kind of instant (2 views one of them beyond 50°
   from the face's normal, other 2-view instants, 3 or more views). The library uses the
   first set (iris centres + mouth corners, with the nose tip for the shape).

Needs the renders of ``benches/faces_attention.py OUT SEED landmarks=facemesh`` (the folder
``OUT/circle<SEED>_1280``); FaceMesh is run again here (≈ 15 s per circle).
Run: python benches/faces_landmark_sets.py OUT SEED [SEED ...]
"""

from __future__ import annotations

import sys
import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from socialcam.faces import _facemesh, _facemesh_points, _frames_of
from socialcam.synth.evaluate import truth_detections
from socialcam.synth.render import load_truth

INNER = [33, 133, 362, 263, 468, 473, 61, 291, 0, 17, 6, 168, 70, 300, 105, 334]
SETS = {
    "iris+mouth (4)": [468, 473, 61, 291],
    "eye corners+mouth (6)": [33, 133, 362, 263, 61, 291],
    "inner (16)": INNER,
    "wide (24)": [*INNER, 10, 152, 50, 280, 234, 454, 127, 356],
    "all 468": list(range(468)),
}


def measure(folder: Path, seed: int) -> dict[str, np.ndarray]:
    """Per detection of the truth (the bench's boxes): FaceMesh's 478 points on the crop
    ``refine_landmarks`` uses (``x, y`` image pixels, ``z`` its relative depth), the ray to the
    face, the camera, and the true face."""
    truth = load_truth(folder)
    dets, cams = truth_detections(truth, scale=1.0, seed=seed)
    rows: dict[str, list[np.ndarray]] = defaultdict(list)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = _facemesh()
        for v, d in enumerate(dets):
            who = [(k, p) for k in range(len(truth.frame_times[v]))
                   for p in np.nonzero(truth.face_visible[v][k]
                                       & (truth.face_size[v][k] >= 12.0))[0]]  # fmt: skip
            images, _ = _frames_of(folder / f"wearer{v}.mp4")
            K = cams[v].K[0]
            for k, img in enumerate(images):
                for i in d.in_frame(k):
                    _, p = who[i]
                    pts = _facemesh_points(model, np.asarray(img), d.box[i])
                    if pts is None:
                        continue
                    b = d.box[i]
                    ray = np.linalg.solve(K, [b[0] + 0.5 * b[2], b[1] + 0.5 * b[3], 1.0])
                    rows["M"].append(pts)
                    rows["ray"].append(ray / np.linalg.norm(ray))
                    rows["K"].append(K)
                    rows["R"].append(truth.R[v][k])
                    rows["C"].append(truth.C[v][k])
                    rows["n"].append(truth.face_normal[v][k][p])
                    rows["centre"].append(truth.face_landmarks[v][k][p].mean(axis=0))
                    rows["kp"].append(np.array([k, p]))
        model.close()
    return {k: np.stack(x) for k, x in rows.items()}


def _unit(a: np.ndarray) -> np.ndarray:
    out: np.ndarray = a / np.linalg.norm(a, axis=-1, keepdims=True)
    return out


def one_view(z: dict[str, np.ndarray]) -> None:
    M, R, n = z["M"], z["R"], z["n"]
    # x, y, z: the crop's frame up to scale and shift (-z = a frontal face), which weak
    # perspective turns with the ray to the face
    nm = _unit(np.cross(M[:, 263] - M[:, 33], M[:, 10] - M[:, 152]))
    zc = np.array([0.0, 0.0, 1.0])
    axis = np.cross(zc, z["ray"])
    sin = np.linalg.norm(axis, axis=1)
    angle = np.arctan2(sin, z["ray"] @ zc)
    turn = Rotation.from_rotvec(axis * (angle / np.where(sin > 0, sin, 1.0))[:, None])
    world = np.einsum("nji,nj->ni", R, turn.apply(nm))
    across = _unit(np.cross([0.0, 0.0, 1.0], n))
    to_cam = _unit(z["C"] - z["centre"])
    yaw = np.degrees(np.arctan2((to_cam * across).sum(1), (to_cam * n).sum(1)))
    est = np.degrees(np.arctan2((world * across).sum(1), (world * n).sum(1)))
    # est is the estimated normal's yaw in the face frame: 0 = right; the view's yaw says
    # where the camera is, so an estimate that follows the camera is biased by +yaw
    print("  one view, FaceMesh's own mesh: yaw error towards the camera, by |true yaw|")
    for lo, hi in [(0, 15), (15, 30), (30, 45), (45, 55), (55, 65), (65, 90)]:
        s = (np.abs(yaw) >= lo) & (np.abs(yaw) < hi)
        if s.sum() >= 3:
            e = est[s] * np.sign(yaw[s])
            print(
                f"    {lo:2d}-{hi:2d} deg  n {s.sum():4d}  median {np.median(e):+6.2f}  sd {e.std():5.2f}"
            )


def views_together(z: dict[str, np.ndarray]) -> None:
    xy, K, R, C, n = z["M"][:, :, :2], z["K"], z["R"], z["C"], z["n"]
    groups: dict[tuple[int, int], list[int]] = defaultdict(list)
    for i, (k, p) in enumerate(z["kp"]):
        groups[(int(k), int(p))].append(i)
    P = np.stack([K[i] @ np.hstack([R[i], -(R[i] @ C[i])[:, None]]) for i in range(len(K))])
    errs: dict[tuple[str, str], list[float]] = defaultdict(list)
    for rows in groups.values():
        if len(rows) < 2:
            continue
        off = [np.degrees(np.arccos(np.clip(_unit(C[r] - z["centre"][r]) @ n[r], -1, 1)))
               for r in rows]  # fmt: skip
        kind = (
            "3+ views" if len(rows) > 2 else ("2 views, one > 50" if max(off) > 50 else "2 views")
        )
        for name, idx in SETS.items():
            A = np.concatenate([xy[r][idx, 0, None, None] * P[r][None, 2] - P[r][None, 0]
                                for r in rows], axis=1)  # fmt: skip
            B = np.concatenate([xy[r][idx, 1, None, None] * P[r][None, 2] - P[r][None, 1]
                                for r in rows], axis=1)  # fmt: skip
            H = np.concatenate([A, B], axis=1)  # (points, 2 views, 4)
            X = np.linalg.svd(H)[2][:, -1]
            X = X[:, :3] / X[:, 3:]
            c = X.mean(axis=0)
            nn = np.linalg.svd(X - c)[2][-1]
            nn = nn if nn @ (C[rows[0]] - c) > 0 else -nn
            errs[(kind, name)].append(float(np.degrees(np.arccos(np.clip(nn @ n[rows[0]], -1, 1)))))
    print("  views together: the plane through the triangulated points, normal error (deg)")
    for kind in ("2 views, one > 50", "2 views", "3+ views"):
        for name in SETS:
            e = np.array(errs[(kind, name)])
            if len(e):
                print(f"    {kind:18s} {name:22s} n {len(e):4d}  median {np.median(e):5.2f}"
                      f"  p90 {np.percentile(e, 90):5.2f}")  # fmt: skip


def main(argv: list[str]) -> None:
    out = Path(argv[0])
    for seed in [int(a) for a in argv[1:]]:
        folder = out / f"circle{seed}_1280"
        if not (folder / "truth.npz").exists():
            raise SystemExit(f"{folder}: no render; run benches/faces_attention.py {out} {seed} "
                             "landmarks=facemesh first")  # fmt: skip
        z = measure(folder, seed)
        print(f"circle {seed}: {len(z['M'])} faces measured by FaceMesh")
        one_view(z)
        views_together(z)


if __name__ == "__main__":
    main(sys.argv[1:])
