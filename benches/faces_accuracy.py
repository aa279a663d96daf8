"""Accuracy of socialcam.faces on rendered scenes against simulator truth (issue 11).

For each seed: render 4 wearers + 3 people without cameras (2 s, 15 fps, 1280×960, faces
on every head), detect faces in every video, reconstruct with the true camera poses and
report: detection rate of visible faces ≥ 12 px, false detections surviving association,
association accuracy, median 3D landmark error and median gaze error against the head
direction the faces are drawn with. Slow (≈ 3 min per seed on a loaded 2-core machine).

Run: python benches/faces_accuracy.py OUT_DIR [seed ...]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from socialcam.faces import detect_faces, reconstruct_faces
from socialcam.synth.render import render_scene


def evaluate(out: Path, seed: int) -> dict[str, float]:
    scene = render_scene(out / f"seed{seed}", n_wearers=4, duration=2.0, fps=15.0,
                         size=(1280, 960), seed=seed, faces=True, n_people=3, audio=False,
                         calibration=False, start_spread=0.0, progress=False)  # fmt: skip
    tr = scene.truth
    V = len(tr.names)
    dets = [detect_faces(p) for p in scene.videos]
    match, hit, visible, unmatched = [], 0, 0, 0
    for v in range(V):
        d, K = dets[v], tr.K[v]
        m = np.full(len(d), -1)
        for k in range(d.n_frames):
            X = tr.face_landmarks[v][k]
            Xc = np.einsum("ij,pkj->pki", tr.R[v][k], X - tr.C[v][k])
            uv = Xc[..., :2] / Xc[..., 2:] * np.diag(K)[:2] + K[:2, 2]
            ids = d.in_frame(k)
            for i in ids:
                e = np.linalg.norm(d.landmarks[i] - uv, axis=-1).mean(-1)
                e[Xc[:, :, 2].min(1) <= 0] = np.inf
                e[v] = np.inf
                p = int(np.argmin(e))
                if e[p] < 0.25 * d.box[i, 2:].max():
                    m[i] = p
                else:
                    unmatched += 1
            for p in np.nonzero(tr.face_visible[v][k] & (tr.face_size[v][k] >= 12))[0]:
                visible += 1
                hit += int(any(m[i] == p for i in ids))
        match.append(m)
    f3 = reconstruct_faces(dets, [tr.cameras(v) for v in range(V)])
    right = wrong = false = 0
    err, gerr = [], []
    for j, pid in enumerate(f3.person):
        who = [match[v][i] for v in range(V) for i in np.nonzero(f3.detection_person[v] == j)[0]]
        false += sum(w < 0 for w in who)
        who = [w for w in who if w >= 0]
        if not who:
            continue
        vals, cnt = np.unique(who, return_counts=True)
        owner = pid if pid < V else vals[np.argmax(cnt)]
        right += sum(w == owner for w in who)
        wrong += sum(w != owner for w in who)
        for t in np.nonzero(np.isfinite(f3.landmarks[:, j, 0, 0]))[0]:
            err.append(
                np.linalg.norm(f3.landmarks[t, j] - tr.face_landmarks[0][t][owner], axis=-1).mean()
            )
            c = np.clip(f3.v[t, j] @ tr.face_normal[0][t][owner], -1, 1)
            gerr.append(np.degrees(np.arccos(c)))
    n_det = sum(len(d) for d in dets)
    return {
        "detected": hit / max(visible, 1),
        "false_surviving": false / max(n_det, 1),
        "association": right / max(right + wrong, 1),
        "assigned": (right + wrong) / max(n_det, 1),
        "landmark_mm": 1000 * float(np.median(err)) if err else np.nan,
        "gaze_deg": float(np.median(gerr)) if gerr else np.nan,
        "face_instants": len(err),
    }


def main(argv: list[str]) -> None:
    out = Path(argv[0])
    for s in [int(a) for a in argv[1:]] or [1, 2, 3]:
        r = evaluate(out, s)
        print(f"seed {s}: " + ", ".join(f"{k} {v:.3f}" for k, v in r.items()))


if __name__ == "__main__":
    main(sys.argv[1:])
