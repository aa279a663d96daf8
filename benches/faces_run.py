"""Faces of everyone in view through the user's chain (issue 11: "3D landmark error ≤ 3 cm
with poses from SfM"): a rendered conversation circle (4 wearers + 2 people without a
camera, 3 s at 10 fps, 1280×960, no audio: manual zero offsets) → ``socialcam run`` (poses
by SfM on one thread, repeatable; metric scale from the wearers' mean camera height, as a user would measure it) →
``pipeline.faces`` (MTCNN on every posed frame, undistorted with the estimated lens,
``reconstruct_faces``) → scored against the renderer's truth
(``synth.evaluate.faces_vs_truth``, the SfM world mapped onto the truth by the similarity of
the camera centres, and by the similarity of the camera poses: orientations and centres). The same detections with the true poses of the same frames give the
"true poses" row. Prints per seed: posed fraction, detected, false surviving, association,
landmark error (mm), gaze error (deg), face-instants, wearers anchored; both rows.

Scale from faces (session 35): a run whose SfM found no floor has no metric scale; then
``pipeline.faces(..., interocular=INTEROCULAR)`` takes it from the faces' eyes
(``faces.scale_from_faces``), and the seed is scored. On every seed the row "scale" also
gives the error of that face scale against the truth (for runs with a metric scale: on the
same detections with the poses put back in map units) next to the eye-height scale's. With
``face_spread=X`` the people's faces differ in size (``render_scene(face_scales=...)``, eye
distances 63 mm × N(1, X), seeded per scene; adults: X ≈ 0.06), so the face scale meets
people's real differences; without, every face is drawn 63 mm. ``duration=S`` renders
S-second clips instead of 3 (session 35: do the SfM misses of 3-s clips of a circle, where
cameras across the circle share no view, hold on longer clips?). ``calibrated=1`` gives the run
each wearer's lens (the renderer's K, no distortion) and keeps it fixed
(``refine_intrinsics=False``), as a user who calibrated the head cameras would (session 36:
are the 3-s misses SfM's self-calibration, a map bent by a wrong focal length?).
``same_lens=1`` runs SfM with one lens estimated from all videos (``same_lens``; the
renderer's wearers' focal lengths differ by up to ±3 %, more than same-model cameras do).

Session 38: ``pipeline.faces`` repairs a wrong join it finds (``faces.repair_joins``); the
poses scored and aligned to the truth are then the cameras the faces were reconstructed with
(``VideoFaces.cameras``), and a line gives the repair (``repair=0``: as before, no repair).

Run: python benches/faces_run.py OUT_DIR [seed ...] [face_spread=X] [duration=S] [calibrated=1] [same_lens=1] [repair=0]
"""

from __future__ import annotations

import dataclasses
import sys
import warnings
from pathlib import Path

import numpy as np

from socialcam import Cameras
from socialcam.faces import INTEROCULAR, FaceDetections, reconstruct_faces, scale_from_faces
from socialcam.pipeline import RunWarning, faces, run
from socialcam.sfm import VideoReconstruction
from socialcam.synth.evaluate import _alignment, faces_vs_truth
from socialcam.synth.render import render_scene


def _on_video_frames(dets, posed_times, truth_times):
    """The detections of the posed frames renumbered to the video's frames (what the truth
    matcher indexes)."""
    k = np.array([int(np.argmin(np.abs(truth_times - t))) for t in posed_times])
    return dataclasses.replace(dets, frame=k[dets.frame], n_frames=len(truth_times))


def _on_truth_cameras(tr, used, dets, faces3d):
    """The detections and faces of the cameras ``used`` (those SfM placed, a subset of the
    truth's) put on the truth's cameras for ``faces_vs_truth``: no detections for the
    others, the wearers' person ids renumbered to the truth's camera indices."""
    names = list(tr.names)
    if list(used) == names:
        return dets, faces3d
    V, U = len(names), len(used)
    full, dp = [], []
    for v, n in enumerate(names):
        if n in used:
            full.append(dets[used.index(n)])
            dp.append(faces3d.detection_person[used.index(n)])
        else:
            full.append(FaceDetections(
                frame=np.zeros(0, np.int64), box=np.zeros((0, 4)), confidence=np.zeros(0),
                landmarks=np.zeros((0, 5, 2)), n_frames=len(tr.cameras(v)), size=dets[0].size,
                landmark_source=dets[0].landmark_source))  # fmt: skip
            dp.append(np.zeros(0, np.int64))
    person = np.array([names.index(used[p]) if p < U else p - U + V for p in faces3d.person])
    return full, dataclasses.replace(faces3d, person=person, detection_person=tuple(dp))


def evaluate(
    out: Path,
    seed: int,
    face_spread: float = 0.0,
    duration: float = 3.0,
    calibrated: bool = False,
    same_lens: bool = False,
    repair: bool = True,
) -> None:
    factors = None
    tag = ""
    if face_spread > 0:
        rng = np.random.default_rng([seed, 35])
        factors = np.clip(rng.normal(1.0, face_spread, 6), 0.7, 1.3).tolist()
        tag = f"_fs{face_spread:g}"
    if duration != 3.0:
        tag += f"_d{duration:g}"
    scene = render_scene(out / f"scene{seed}{tag}", n_wearers=4, n_people=2, duration=duration,
                         fps=10.0, size=(1280, 960), seed=seed, faces=True,
                         arrangement="circle", audio=False, calibration=False,
                         start_spread=0.0, progress=False, face_scales=factors)  # fmt: skip
    tr = scene.truth
    names = list(tr.names)
    eye = float(np.mean([tr.C[v][:, 2].mean() for v in range(len(names))]))
    folder = out / f"run{seed}{tag}{'_cal' if calibrated else ''}{'_same' if same_lens else ''}"
    lens: dict[str, object] = {"same_lens": True} if same_lens else {}
    if calibrated:  # the renderer's lens (pinhole), fixed in bundle adjustment
        lens.update(intrinsics={n: (tr.K[v], [0.0]) for v, n in enumerate(names)},
                    refine_intrinsics=False)  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RunWarning)  # no calibration segment: optical axis
        res = run(
            scene.videos,
            folder,
            sync=dict.fromkeys(names, 0.0),
            eye_height=eye,
            overwrite=True,
            progress=False,
            plots=False,
            overlays=False,
            num_threads=1,
            **lens,
        )  # fmt: skip  (one thread: the same poses on every run)
    try:  # a run without a metric scale takes it from the faces' eyes
        vf, report = faces(folder, progress=False, interocular=INTEROCULAR, repair=repair)
    except ValueError as exc:  # e.g. no face to measure: said, next seed
        print(f"{seed} posed {res.report['poses']['registered_fraction']:.3f}: not scored ({exc}; "
              f"run warnings: {res.report['poses']['warnings']})", flush=True)  # fmt: skip
        return
    rec = VideoReconstruction.load(folder / "cache" / "sfm")
    used = list(vf.names)
    if vf.scale is not None:  # the faces' scale: the world is the map times it
        rec = dataclasses.replace(
            rec,
            cameras={n: Cameras(c.K, c.R, c.C * vf.scale.metres_per_unit, c.times)
                     for n, c in rec.cameras.items()},
            points=rec.points * vf.scale.metres_per_unit,
        )  # fmt: skip
    pc = report["pose_check"]
    if "wrong_pairs_before_repair" in pc:  # the faces' repair of a wrong join
        print(f"{seed} wrong pairs {pc['wrong_pairs_before_repair']}: repaired "
              f"{[(r['wearers'], round(r['turn_deg'], 1), r['refined_by_faces']) for r in pc['repaired']]}"
              f", unplaced {pc['unplaced']}, still wrong {pc.get('wrong_pairs', [])}", flush=True)  # fmt: skip
    if vf.cameras is not None:  # the cameras the faces were reconstructed with (repaired)
        rec = dataclasses.replace(rec, cameras={**rec.cameras, **vf.cameras})
    truth_cams = {n: tr.cameras(names.index(n)) for n in used}
    A, B, RA, RB = [], [], [], []
    for n in used:
        for tt, c, r in zip(rec.cameras[n].times, rec.cameras[n].C, rec.cameras[n].R,
                            strict=True):  # fmt: skip
            k = int(np.argmin(np.abs(truth_cams[n].times - tt)))
            A.append(c)
            B.append(truth_cams[n].C[k])
            RA.append(r)
            RB.append(truth_cams[n].R[k])
    A_, B_ = np.array(A), np.array(B)
    s, R, t = _alignment(rec, tr)  # the camera centres alone, as run_vs_truth maps runs
    # the cameras' orientations too: centres near one plane (a circle at eye height) leave
    # the tilt of a centres-only similarity loose by ~1.5° (measured), which alone moves a
    # face 1 m from the middle by ~2.5 cm
    U, _sv, Vt = np.linalg.svd(sum(rb.T @ ra for ra, rb in zip(RA, RB, strict=True)))
    Rp = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    a0, b0 = A_ - A_.mean(0), B_ - B_.mean(0)
    sp = float(np.sum((a0 @ Rp.T) * b0) / np.sum(a0**2))
    tp = B_.mean(0) - sp * Rp @ A_.mean(0)
    rot = [np.degrees(np.arccos(np.clip((np.trace(ra @ Rp.T @ rb.T) - 1) / 2, -1, 1)))
           for ra, rb in zip(RA, RB, strict=True)]  # fmt: skip
    cen = np.linalg.norm(sp * A_ @ Rp.T + tp - B_, axis=1)
    print(f"{seed} poses after the pose alignment: centres {1e3 * np.median(cen):.0f} mm, "
          f"rotations {np.median(rot):.2f} deg median (centres-only alignment: centres "
          f"{1e3 * np.median(np.linalg.norm(s * A_ @ R.T + t - B_, axis=1)):.0f} mm)")  # fmt: skip

    # the face scale against the truth: truth metres per map unit = sp × (metres per map unit
    # of the world the faces were reconstructed in)
    if vf.scale is not None:
        fs, unit, how = vf.scale, vf.scale.metres_per_unit, "faces (no floor)"
    else:
        unit, how = rec.scale, "eye height"
        fs, _ = scale_from_faces(
            list(vf.detections),
            [Cameras(rec.cameras[n].K, rec.cameras[n].R, rec.cameras[n].C / unit,
                     rec.cameras[n].times) for n in used],
            interocular=INTEROCULAR,
        )  # fmt: skip
    true_unit = sp * unit
    faces_err = fs.metres_per_unit / true_unit - 1
    people = [] if factors is None else factors
    print(f"{seed} scale: run's from {how}; error of the eye-height scale "
          f"{'n/a' if vf.scale is not None else f'{100 * (1 / sp - 1):+.1f} %'}, of the face "
          f"scale {100 * faces_err:+.1f} % (± {100 * fs.relative_sd:.1f} % said, "
          f"{len(fs.person)} faces measured; people's eye distances "
          f"{np.round(np.array(people) * 63, 1).tolist() or 'all 63'} mm)", flush=True)  # fmt: skip

    def to_truth(X: np.ndarray) -> np.ndarray:
        return s * np.asarray(X) @ R.T + t

    def to_truth_poses(X: np.ndarray) -> np.ndarray:
        return sp * np.asarray(X) @ Rp.T + tp

    dets = [_on_video_frames(d, rec.cameras[n].times, truth_cams[n].times)
            for n, d in zip(used, vf.detections, strict=True)]  # fmt: skip
    dets, f_sfm = _on_truth_cameras(tr, used, dets, vf.faces)
    r_sfm = faces_vs_truth(tr, dets, f_sfm, to_truth=to_truth)
    r_sfm_p = faces_vs_truth(tr, dets, f_sfm, to_truth=to_truth_poses)
    posed_true = []
    for n in used:
        tc = truth_cams[n]
        k = [int(np.argmin(np.abs(tc.times - x))) for x in rec.cameras[n].times]
        posed_true.append(Cameras(tc.K[k], tc.R[k], tc.C[k], rec.cameras[n].times))
    f_true = reconstruct_faces(list(vf.detections), posed_true, anchors=True)
    _, f_true = _on_truth_cameras(tr, used, list(vf.detections), f_true)
    r_true = faces_vs_truth(tr, dets, f_true)
    posed = res.report["poses"]["registered_fraction"]
    dis = [p["ego_exo_disagreement_deg_median"] for p in report["people"]
           if "ego_exo_disagreement_deg_median" in p]  # fmt: skip
    print(f"{seed} ego (optical axis, no calibration segment) vs exo per wearer, deg: "
          f"{np.round(dis, 1).tolist()}")  # fmt: skip
    rows = (("sfm poses, centres-aligned", r_sfm, vf.faces),
            ("sfm poses, poses-aligned  ", r_sfm_p, vf.faces),
            ("true poses                ", r_true, f_true))  # fmt: skip
    for label, r, f in rows:
        print(
            f"{seed} {label} posed {posed:.3f} detected {r['detected']:.3f} false "
            f"{r['false_surviving']:.3f} association {r['association']:.3f} landmark "
            f"{r['landmark_mm']:.1f} mm gaze {r['gaze_deg']:.2f} deg face-instants "
            f"{r['face_instants']} wearers {int(f.wearer.sum())} (scale to truth {s:.3f})",
            flush=True,
        )


def main(argv: list[str]) -> None:
    out = Path(argv[0])
    opts = dict(a.split("=", 1) for a in argv[1:] if "=" in a)
    known = {"face_spread", "duration", "calibrated", "same_lens", "repair"}
    if set(opts) - known:
        raise SystemExit(f"unknown options {sorted(set(opts) - known)}")
    spread = float(opts.get("face_spread", 0.0))
    duration = float(opts.get("duration", 3.0))
    calibrated = opts.get("calibrated", "0") not in ("0", "")
    same_lens = opts.get("same_lens", "0") not in ("0", "")
    repair = opts.get("repair", "1") not in ("0", "")
    for seed in [int(a) for a in argv[1:] if "=" not in a] or [11]:
        evaluate(out, seed, spread, duration, calibrated, same_lens, repair)


if __name__ == "__main__":
    main(sys.argv[1:])
