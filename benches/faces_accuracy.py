"""Accuracy of socialcam.faces on rendered scenes against simulator truth (issue 11).

For each seed: render 4 wearers + 3 people without cameras (2 s, 15 fps, 1280×960, faces
on every head; ``arrangement`` "loop" = walking wearers, "circle" = a conversation circle),
detect faces in every video (MTCNN), reconstruct with the true camera poses and report
(``socialcam.synth.evaluate.faces_vs_truth``): detection rate of visible faces ≥ 12 px,
false detections surviving association, association accuracy, median 3D landmark error
and median gaze error against the face normal the faces are drawn with; on circles also
joint attention from the exo rays against the wearers' ego rays
(``face_joint_attention``; ``ja_matched_ratio``: the same wearers' exo and ego rays on the
same groups). Slow (≈ 8 min per seed on a loaded 2-core machine). With ``anchors=0``
every face goes through RANSAC and tracks (no wearer's camera anchors its face: static or
unknown cameras).

Run: python benches/faces_accuracy.py OUT_DIR loop|circle [seed ...] [anchors=0]
"""

from __future__ import annotations

import sys
from pathlib import Path

from socialcam.faces import detect_faces, reconstruct_faces
from socialcam.synth.evaluate import face_joint_attention, faces_vs_truth
from socialcam.synth.render import render_scene


def evaluate(out: Path, arrangement: str, seed: int, anchors: bool = True) -> dict[str, float]:
    scene = render_scene(out / f"{arrangement}{seed}", n_wearers=4, duration=2.0, fps=15.0,
                         size=(1280, 960), seed=seed, faces=True, n_people=3, audio=False,
                         calibration=False, start_spread=0.0, progress=False,
                         arrangement=arrangement)  # fmt: skip
    tr = scene.truth
    dets = [detect_faces(p) for p in scene.videos]
    cams = [tr.cameras(v) for v in range(len(tr.names))]
    f3 = reconstruct_faces(dets, cams, anchors=anchors)
    r = faces_vs_truth(tr, dets, f3)
    ja = face_joint_attention(tr, f3, r["owner"])
    keys = ("detected", "false_surviving", "association", "assigned", "landmark_mm", "gaze_deg")
    out_ = {k: float(r[k]) for k in keys} | {"face_instants": float(r["face_instants"])}
    plain = faces_vs_truth(tr, dets, reconstruct_faces(dets, cams, anchors=anchors, rigid=False))
    return out_ | {
        "ja_exo_m": ja["exo"]["error_median_m"],
        "ja_ego_m": ja["ego"]["error_median_m"],
        "ja_matched_ratio": ja["matched"]["ratio"],
        "landmark_mm_not_rigid": float(plain["landmark_mm"]),
        "gaze_deg_not_rigid": float(plain["gaze_deg"]),
    }


def main(argv: list[str]) -> None:
    out, arrangement = Path(argv[0]), argv[1]
    anchors = "anchors=0" not in argv[2:]
    for s in [int(a) for a in argv[2:] if "=" not in a] or [1, 2, 3]:
        r = evaluate(out, arrangement, s, anchors)
        print(f"{arrangement} seed {s}: " + ", ".join(f"{k} {v:.3f}" for k, v in r.items()))


if __name__ == "__main__":
    main(sys.argv[1:])
