"""``socialcam demo``: runs what socialcam does on an embedded, seeded sample scene and
compares every result with the ground truth that generated it."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from socialcam import synth
from socialcam.geometry import align_similarity, triangulate
from socialcam.io import save_figure, write_json


def _stage_triangulation(seed: int, out: Path, plots: bool) -> dict[str, Any]:
    """Static points seen by a 4-camera rig with 1 px noise and 10% missing views."""
    scene = synth.multiview_scene(2000, 4, noise_px=1.0, missing=0.1, seed=seed)
    t0 = time.perf_counter()
    X, info = triangulate(scene.obs.x, scene.cameras, return_info=True)
    dt = time.perf_counter() - t0
    ok = np.isfinite(X).all(axis=1)
    err = np.linalg.norm(X[ok] - scene.obs.points[ok], axis=1)
    s, R, t = align_similarity(scene.obs.points[ok], X[ok])
    if plots:
        from socialcam.viz import plot_reconstruction

        fig = plot_reconstruction(
            scene.cameras, scene.obs.points, X, title="4-view triangulation, 1 px noise"
        )
        save_figure(fig, out / "triangulation.png")
    return {
        "points": len(X),
        "views": len(scene.cameras),
        "noise_px": 1.0,
        "missing_fraction": 0.1,
        "triangulated": int(ok.sum()),
        "not_triangulable": int((~ok).sum()),
        "error_mm_median": float(1e3 * np.median(err)),
        "error_mm_mean": float(1e3 * err.mean()),
        "rms_px_linear_mean": float(np.nanmean(info.rms_linear)),
        "rms_px_refined_mean": float(np.nanmean(info.rms)),
        "similarity_to_truth": {
            "scale": s,
            "rotation_deg": float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))),
            "translation_m": float(np.linalg.norm(t)),
        },
        "seconds": dt,
    }


def _walker() -> tuple[Any, np.ndarray]:
    """The shipped 2 s of real walking (CMU 131), every 2nd frame (60 Hz), turned from the
    BVH's y-up to our z-up world. Returns the motion and positions ``(F, J, 3)``."""
    from socialcam.data import sample_bvh
    from socialcam.mocap import load_bvh

    m = load_bvh(sample_bvh(), frames=slice(None, None, 2))
    P = m.positions
    return m, np.stack([P[..., 0], -P[..., 2], P[..., 1]], axis=-1)


def _stage_trajectory(seed: int, out: Path, plots: bool) -> dict[str, Any]:
    """Every joint of a real walking person, photographed by many independent
    photographers (one photo per instant, 1 px noise), reconstructed by the DCT trajectory
    method of Chapter 5 with a per-joint K chosen by cross validation."""
    from socialcam.trajectory import reconstruct_trajectories

    _, P = _walker()
    F = P.shape[0]
    times = np.arange(F) / 60.0
    centre = P[:, 0].mean(axis=0)
    cams = synth.random_photographers(
        F, seed=seed, target=centre, radius=(3.0, 6.0), height=(1.2, 2.0), times=times
    )
    X = np.transpose(P, (1, 0, 2))  # (J, F, 3)
    obs = synth.observe(X, cams, noise_px=1.0, missing=0.1, seed=seed + 1)
    t0 = time.perf_counter()
    res = reconstruct_trajectories(obs.x, cams)
    dt = time.perf_counter() - t0
    err = np.linalg.norm(res.points - X, axis=2)
    rel = err.sum(axis=1) / np.linalg.norm(X - centre, axis=2).sum(axis=1)
    if plots:
        from socialcam.viz import plot_trajectories

        fig = plot_trajectories(cams, X, res.points, title="walking joints from 120 random photos")
        save_figure(fig, out / "trajectory.png")
    return {
        "joints": int(X.shape[0]),
        "frames": F,
        "noise_px": 1.0,
        "missing_fraction": 0.1,
        "k_median": float(np.median(res.k)),
        "error_mm_median": float(1e3 * np.median(err)),
        "error_mm_mean": float(1e3 * err.mean()),
        "relative_error_mean": float(rel.mean()),
        "rms_px_mean": float(np.mean(res.rms)),
        "seconds": dt,
    }


def _stage_articulated(seed: int, out: Path, plots: bool) -> dict[str, Any]:
    """The same walker (1 s at 60 Hz) seen by a single camera swinging around it at 1.5 m:
    each joint from its parent
    and bone length by the binary quadratic program of Chapter 4, recursively from the
    (known) root trajectory."""
    from socialcam.articulated import Skeleton, reconstruct_skeleton
    from socialcam.camera import Cameras

    m, P = _walker()
    skeleton, keep = Skeleton.from_bvh(m)
    P = P[:60][:, keep]  # 60 Hz, 60 frames
    F = P.shape[0]
    rng = np.random.default_rng(seed)
    ang = rng.uniform(0, 2 * np.pi) + np.linspace(0.0, 1.0, F)
    C = P[:, 0] + np.c_[1.5 * np.cos(ang), 1.5 * np.sin(ang), np.full(F, 0.3)]
    cams = Cameras(synth.intrinsics(), synth.look_at(C, P[:, 0]), C, np.arange(F) / 60.0)
    x = synth.observe(np.transpose(P, (1, 0, 2)), cams, noise_px=0.5, seed=seed + 1).x
    t0 = time.perf_counter()
    res = reconstruct_skeleton(np.transpose(x, (1, 0, 2)), cams, skeleton, P[:, 0], k=8)
    dt = time.perf_counter() - t0
    err = np.linalg.norm(res.points - P, axis=2)[:, 1:]
    par = np.asarray(skeleton.parents[1:])
    bone_true = P[:, 1:] - P[:, par]
    bone_est = res.points[:, 1:] - res.points[:, par]
    rel = np.linalg.norm(bone_est - bone_true, axis=2) / np.linalg.norm(bone_true, axis=2)
    return {
        "joints": len(skeleton.names),
        "frames": F,
        "noise_px": 0.5,
        "error_mm_median": float(1e3 * np.median(err)),
        "error_mm_mean": float(1e3 * err.mean()),
        "relative_bone_error_median": float(np.median(rel)),
        "seconds": dt,
    }


def _stage_bodies(seed: int, out: Path, plots: bool) -> dict[str, Any]:
    """The same walker (2 s at 120 Hz) photographed by 6 photographers at 60 random moments,
    with a detector-like pose model (3 px noise, misses, left/right swaps, a second person,
    the walk played backwards beside it, in 30 % of the photos): the person found in every
    photo, swaps repaired, each joint's trajectory (Ch. 5) moved towards its rays (Sec
    5.3.2, :func:`socialcam.bodies.reconstruct_body`)."""
    from socialcam.bodies import reconstruct_body
    from socialcam.data import sample_bvh
    from socialcam.mocap import load_bvh
    from socialcam.synth.photos import BODY_BONES, BODY_JOINTS, BODY_PAIRS, photo_collection

    m = load_bvh(sample_bvh())
    pc = photo_collection(m.positions, m.names, m.fps, other=m.positions[::-1], seed=seed)
    t0 = time.perf_counter()
    body = reconstruct_body(pc.detections, pc.cameras, BODY_PAIRS)
    dt = time.perf_counter() - t0
    err = np.linalg.norm(body.points - pc.points, axis=-1)
    smooth = np.linalg.norm(body.smooth - pc.points, axis=-1)
    right = [
        f for f in range(len(pc.who)) if body.chosen[f] >= 0 and pc.who[f][body.chosen[f]] == 0
    ]
    seen = np.zeros(pc.swapped.shape, bool)  # a swap can be seen when both joints are
    for f, (d, w) in enumerate(zip(pc.detections, pc.who, strict=True)):
        uv = d[int(np.argmax(w == 0))]
        seen[f] = [np.isfinite(uv[[a, b]]).all() for a, b in BODY_PAIRS]
    if plots:
        from socialcam.viz import plot_body

        fig = plot_body(pc.cameras, body.points, BODY_BONES, truth=pc.points,
                        smooth=body.smooth, names=BODY_JOINTS,
                        title="a body from 60 photos (sample walk)")  # fmt: skip
        save_figure(fig, out / "body.png")
    return {
        "photos": len(pc.cameras),
        "photos_with_second_person": int(sum(len(w) > 1 for w in pc.who)),
        "person_found_fraction": len(right) / len(pc.who),
        "swaps": int((pc.swapped & seen).sum()),
        "swaps_repaired": int((pc.swapped & seen & body.swapped).sum()),
        "false_repairs": int((~pc.swapped & body.swapped).sum()),
        "error_mm_median": float(1e3 * np.nanmedian(err)),
        "error_mm_median_trajectories": float(1e3 * np.nanmedian(smooth)),
        "seconds": dt,
    }


def _stage_charges(seed: int, out: Path, plots: bool) -> dict[str, Any]:
    """The meeting of Fig 6.6 (11 people: two groups, a presenter, two groups again): social
    charges in every frame (Chapter 6) and their tracks over time."""
    from socialcam.charges import find_charges_sequence, track_charges

    scene = synth.meeting(seed=seed)
    frames = scene.ray_frames()
    t0 = time.perf_counter()
    charges = find_charges_sequence(frames, seed=seed)
    tracks = track_charges(charges)
    dt = time.perf_counter() - t0
    truth = scene.n_charges()
    found = np.array([len(c) for c in charges])
    dist = [
        np.linalg.norm(scene.targets[f] - c.position, axis=1).min()
        for f, cs in enumerate(charges)
        for c in cs
    ]
    if plots:
        from socialcam.charges import plot_charge_tracks, plot_saliency

        f = scene.n_frames // 6
        fig = plot_saliency(
            frames[f], scene.room[0], scene.room[1], charges=charges[f], truth=scene.targets[f]
        )
        save_figure(fig, out / "saliency.png")
        save_figure(
            plot_charge_tracks(tracks, times=scene.times, truth=scene.targets),
            out / "charge_tracks.png",
        )
    return {
        "frames": scene.n_frames,
        "people": scene.n_people,
        "correct_count_fraction": float((found == truth).mean()),
        "charge_error_cm_median": float(100 * np.median(dist)) if dist else None,
        "tracks": sum(len(t) >= 10 for t in tracks),
        "short_tracks": sum(len(t) < 10 for t in tracks),
        "seconds": dt,
    }


def _stage_gazefield(seed: int, out: Path, plots: bool) -> dict[str, Any]:
    """The gaze field of Chapter 7 fitted to the meeting, and leave-one-out prediction of
    each member's gaze from everybody else's, against radial-basis regression."""
    from socialcam.gazefield import GazeField, cross_validate_gaze

    scene = synth.meeting(n_frames=120, seed=seed)
    frames = scene.ray_frames()
    t0 = time.perf_counter()
    field = GazeField.fit(frames, times=scene.times)
    cv = cross_validate_gaze(frames, leave_out=1, method="field", seed=seed)
    rbf = cross_validate_gaze(frames, leave_out=1, method="rbf", seed=seed)
    dt = time.perf_counter() - t0
    if plots:
        ax = field.plot(t=float(scene.times[10]), rays=frames[10])
        save_figure(ax.figure, out / "gaze_field.png")
    return {
        "frames": scene.n_frames,
        "leave_one_out_deg_mean": cv.mean,
        "leave_one_out_deg_median": float(np.median(cv.errors)),
        "rbf_deg_mean": rbf.mean,
        "rbf_deg_median": float(np.median(rbf.errors)),
        "seconds": dt,
    }


def _stage_run(seed: int, out: Path, plots: bool) -> dict[str, Any]:
    """``socialcam run`` on the rendered clips shipped with socialcam (4 wearers × 8 s,
    with their range-of-motion segments and the true mean camera height as
    ``eye_height``), compared with the renderer's truth: calibration errors and joint
    attention, also of the same stages on the true cameras."""
    import warnings

    from socialcam.pipeline import RunWarning, run
    from socialcam.synth.evaluate import run_vs_truth, truth_segments
    from socialcam.synth.render import load_truth, shipped_scene

    scene = shipped_scene()
    truth = load_truth(scene)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RunWarning)  # listed in the report
        res = run(
            [scene / f"{n}.mp4" for n in truth.names],
            out / "run",
            calibration=truth_segments(truth),
            eye_height=float(np.mean([c[:, 2].mean() for c in truth.C])),
            seed=seed,
            plots=plots,
            progress=False,
        )
    dt = time.perf_counter() - t0
    acc = run_vs_truth(res, truth)
    rep = res.report
    return {
        "wearers": len(truth.names),
        "seconds_per_video": float(truth.frame_times[0][-1] - truth.frame_times[0][0]),
        "posed_fraction": rep["poses"]["n_posed"] / max(rep["poses"]["n_frames"], 1),
        "calibrated": [n for n, c in rep["calibration"].items() if c["status"] == "calibrated"],
        "v_error_deg_median": float(
            np.median([c["v_error_deg"] for c in acc["calibration"].values()])
        ),
        "joint_attention_groups": acc["joint_attention"]["groups"],
        "joint_attention_found": acc["joint_attention"]["found"],
        "charges_total": rep["charges"]["total"],
        "calibration_vs_truth": acc["calibration"],
        "charges": rep["charges"],
        "joint_attention_vs_truth": acc["joint_attention"],
        "joint_attention_true_cameras": acc["joint_attention_true_cameras"],
        "warnings": rep["warnings"],
        "stage_seconds": {k: v["seconds"] for k, v in rep["stages"].items()},
        "run_folder": str(out / "run"),
        "seconds": dt,
    }


#: Stages of the demo, in order: name → function(seed, out_dir, plots) → summary dict.
STAGES: dict[str, Callable[[int, Path, bool], dict[str, Any]]] = {
    "triangulation": _stage_triangulation,
    "trajectory": _stage_trajectory,
    "articulated": _stage_articulated,
    "bodies": _stage_bodies,
    "social_charges": _stage_charges,
    "gaze_field": _stage_gazefield,
    "run": _stage_run,
}


def run_demo(
    out_dir: str | Path = "socialcam-out",
    *,
    seed: int = 0,
    plots: bool = True,
    progress: bool = True,
    stages: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Runs the demo stages (default: all of :data:`STAGES`), writes ``report.json`` (and
    PNG plots) into ``out_dir``, and returns the report."""
    chosen = list(STAGES) if stages is None else list(stages)
    for name in chosen:
        if name not in STAGES:
            raise ValueError(f"stages: unknown stage {name!r} (stages: {', '.join(STAGES)})")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report: dict[str, Any] = {"seed": seed, "stages": {}}
    for name in tqdm(chosen, desc="socialcam demo", disable=not progress, unit="stage"):
        c0 = time.process_time()
        report["stages"][name] = STAGES[name](seed, out, plots)
        report["stages"][name]["cpu_seconds"] = time.process_time() - c0
    write_json(out / "report.json", report)
    return report
