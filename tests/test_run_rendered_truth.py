"""Calibration and joint attention of ``socialcam run`` on the TRUE cameras of rendered
4 wearers × 20 s scenes (the renderer's motion and truth, without drawing the frames): the
range-of-motion segments of the renderer determine Eq 3.1 (thesis Sec 3.2.1), and the rays
it calibrates meet where the wearers look together (Sec 6.2). The same stages through SfM
poses are measured by ``benches/bench_run.py``."""

from __future__ import annotations

import numpy as np
import pytest

from socialcam.pipeline import RunOptions, gaze_and_charges
from socialcam.synth import render
from socialcam.synth.evaluate import (
    _calibration_errors,
    joint_attention,
    looking_groups,
    truth_segments,
)

SEEDS = (1, 2, 3)


def _truth_only(out, seed):
    """The truth of ``render_scene(seed)`` at 4 × 20 s, 640×480 without encoding videos."""
    orig = render._write_video
    render._write_video = lambda *a, **k: None
    try:
        return render.render_scene(
            out, n_wearers=4, duration=20.0, seed=seed, progress=False, audio=False
        ).truth
    finally:
        render._write_video = orig


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    out = {}
    for seed in SEEDS:
        truth = _truth_only(tmp_path_factory.mktemp(f"truth{seed}"), seed)
        names = list(truth.names)
        cams = {n: truth.cameras(i) for i, n in enumerate(names)}
        cals, times, _frames, charges = gaze_and_charges(
            cams, names, calibration=truth_segments(truth)
        )
        ja = joint_attention(truth, names, times, charges)
        # charges of one frame with the same members at one point (within 1 cm)
        ja["repeated"] = sum(
            {int(m) for m in a.members} == {int(m) for m in b.members}
            and np.linalg.norm(a.position - b.position) <= 0.01
            for cs in charges
            for i, a in enumerate(cs)
            for b in cs[:i]
        )
        out[seed] = (truth, _calibration_errors(cals, truth, 1.0), ja)
    return out


def test_range_of_motion_segments_are_well_posed(results):
    for truth, _cal, _ja in results.values():
        for v, (t0, t1, y) in enumerate(truth.calibration):
            ft = truth.frame_times[v]
            sel = (ft >= t0) & (ft <= t1)
            # the wearer steps back and forth towards the point: depth ratio 1.94-2.5 over seeds
            # 1-3, 21, 55, 178, 185, 436 (steps along the pillar face normal instead, as the
            # renderer did before session 16: 1.10-2.5 over seeds 1-480, 1.47 on seed 3) ...
            depth = np.linalg.norm(y - truth.eyes[v][sel], axis=1)
            assert depth.max() > 1.8 * depth.min() and depth.min() > 0.3
            # ... and rolls the head about ±15° (the camera turns about the gaze ray)
            tilt = np.degrees(np.arcsin(truth.R[v][sel][:, 0, 2]))  # image x axis vs level
            assert np.ptp(tilt) > 20.0
            # the primary gaze misses the point by the Sec 3.1 deviation of spread h
            u = (y - truth.eyes[v][sel]) / depth[:, None]
            dev = np.linalg.norm(np.cross(u, truth.gaze[v][sel]), axis=1)
            assert 0.7 < np.sqrt(np.mean(dev**2) / 2) / truth.h[v] < 1.4


def test_eq31_calibrates_every_rendered_wearer(results):
    # the targets: v within 0.5°, p within 2 cm, h within 20 %. Measured over seeds
    # 1-20 (80 wearers): v ≤ 0.40° (median 0.10°), p ≤ 1.0 cm (median 0.2 cm), h ×0.94-1.15;
    # over 1-480 (1920 wearers) v median 0.10°, 14 above 0.5° (max 0.96°, the wearers with
    # h near 2°, whose own v_std is ≥ 0.85°), p ≤ 2.1 cm, h ×0.89-1.24, no fallback.
    # Along the optical axis (no Eq 3.1) v is 4-12° off; a bias of 0.3° in v moves the median.
    v_err = []
    for seed, (_truth, cal, _ja) in results.items():
        for n, c in cal.items():
            assert c["calibrated"], (seed, n)
            assert c["v_error_deg"] < 0.5, (seed, n, c)
            assert c["p_error_m"] < 0.015, (seed, n, c)
            assert 0.85 < c["h_ratio"] < 1.2, (seed, n, c)
            v_err.append(c["v_error_deg"])
    assert np.median(v_err) < 0.25, v_err


def test_joint_attention_is_found_where_wearers_look_together(results):
    # found: a charge of >= 2 of the group within 0.5 m of the target, in the frames where
    # >= 2 wearers look at one target (settled for 0.6 s, head turned to within 3 h).
    # Measured on seeds 1-12: 91-100 % (pooled 97.3 %; seeds 1-3: 96, 100, 99 %), median
    # error 5-11 cm; unseen seeds 13-16: 92-100 %. A member within 2.5 bandwidths instead
    # of 3 (member_sigma) finds 92, 90, 96 % on seeds 1-3 (85 % on seed 5); exclusive
    # membership ("partition") 77 % on seed 3 and 47 % on seed 7; along the optical axis
    # (no Eq 3.1) 35-49 %.
    for seed, (_truth, _cal, ja) in results.items():
        assert ja["groups"] >= 20, (seed, ja)
        assert ja["found_fraction"] >= 0.93, (seed, ja)
        assert ja["error_median_m"] < 0.12, (seed, ja)
        # false charges (no two members look at one thing): the wearers' rays inside their
        # own calibration segments are left out of the charges (with them in, wearers
        # calibrating side by side on nearby points make half of all charges), and so are
        # rays 0.5 m or less from the charge (min_charge_depth). Measured on seeds 1-3:
        # 0.59, 0.52, 0.50 (before the persistence rule below); with calibration rays: 0.79, 0.82, 0.77; without the depth
        # gate 0.61, 0.59, 0.55 (with member_sigma 2.5; 3 adds 0.01-0.02).
        assert ja["false_fraction"] < 0.7, (seed, ja)
        # no charge twice: the track fit moves a mode and a pair's candidate of the same
        # members to one point (5 such repeats on seeds 1-3 before they were merged)
        assert ja["repeated"] == 0, (seed, ja)
    # ... and charges seen in one frame only (crossings of turning heads; charge_persistence):
    # 0.57, 0.38, 0.36 on seeds 1-3 (mean 0.44); keeping them: 0.59, 0.52, 0.50 (mean 0.54).
    # Session 15 (later stages in): 0.586, 0.414, 0.411 (mean 0.47) without
    # charge_continuation, 0.604, 0.461, 0.441 (mean 0.50) with it (the carried tracks of
    # rays aimed at different things); keeping one-frame charges: mean 0.57, red here.
    false = [ja["false_fraction"] for _t, _c, ja in results.values()]
    assert np.mean(false) < 0.53, false


def test_looking_groups_are_wearers_settled_on_one_target(results):
    # the groups joint_attention scores: >= 2 wearers whose truth names one target, looked
    # at for >= settle seconds, at that target's true position
    truth = results[1][0]
    names = list(truth.names)
    times = np.arange(0.0, 20.0, 0.1)
    looking = looking_groups(truth, names, times)
    n = 0
    for k, groups in enumerate(looking):
        for members, target in groups:
            assert len(members) >= 2
            for i in members:
                j = int(np.argmin(np.abs(truth.frame_times[i] - truth.start[0] - times[k])))
                assert truth.target_of[i][j] == truth.target_of[members[0]][j]
                # wearers' frames are not simultaneous; a target moves <= 1.3 m/s
                assert np.linalg.norm(truth.regard[i][j] - target) < 0.05
            n += 1
    assert n >= 20
    # a longer settling time only removes groups
    later = looking_groups(truth, names, times, settle=1.5)
    assert 0 < sum(map(len, later)) < n
    # bad input names the argument
    for kw, name in [
        (dict(times=np.full(3, np.nan)), "times"),
        (dict(times=np.zeros((2, 2))), "times"),
        (dict(settle=-1.0), "settle"),
        (dict(max_deviation=0.0), "max_deviation"),
        (dict(max_deviation=float("nan")), "max_deviation"),
    ]:
        args = {"times": times, **kw}
        with pytest.raises(ValueError, match=name):
            looking_groups(truth, names, args.pop("times"), **args)


def test_a_rendered_near_collinear_stretch_is_carried_by_the_track(tmp_path):
    """Rendered seed 50 (a development seed of sessions 8-11): two wearers face each other
    across a circling target, their rays 163-175° apart; for 0.5 s one ray stays 2.2-2.5 h
    off and single frames put the charge 0.5-0.8 m along the line between them. The track
    fit's acceleration term over ±1 s carries it from the frames with better geometry:
    20 of 20 frames found (measured 100 %); session 8's local-linear fit over ±0.5 s
    (``TRACK_ACCEL`` 0, ``charge_pooling`` 0.5) found 15 (75 %), local-linear over ±1 s
    16 (80 %): both red here."""
    truth = _truth_only(tmp_path, 50)
    names = list(truth.names)
    cams = {n: truth.cameras(i) for i, n in enumerate(names)}
    _cals, times, _frames, charges = gaze_and_charges(
        cams, names, calibration=truth_segments(truth)
    )
    ja = joint_attention(truth, names, times, charges)
    assert ja["groups"] == 20, ja
    assert ja["found_fraction"] >= 0.9, ja


@pytest.mark.parametrize("seed", [80, 298])
def test_rendered_facing_pairs_are_carried_by_their_tracks(tmp_path, seed):
    """Rendered seeds 80 (development, session 15) and 298 (first seen in session 14): two
    wearers face each other across what they look at, 3.1 m apart, their rays nearly
    collinear; at the start (80) or in the middle (298) of the look the saliency field has
    no joint mode (it peaks near an eye, dropped by ``min_charge_depth``). The track
    carried by ``charge_continuation`` finds them: measured 43/46 and 14/14 frames; without
    it 41/46 (0.89) and 11/14 (0.79), both red here."""
    truth = _truth_only(tmp_path, seed)
    names = list(truth.names)
    cams = {n: truth.cameras(i) for i, n in enumerate(names)}
    found = {}
    for continuation in (0.5, 0.0):
        _cals, times, _frames, charges = gaze_and_charges(
            cams,
            names,
            calibration=truth_segments(truth),
            options=RunOptions(charge_continuation=continuation),
        )
        found[continuation] = joint_attention(truth, names, times, charges)["found_fraction"]
    assert found[0.5] >= 0.9, found
    assert found[0.0] < 0.9, found  # the case is still hard without the stage


def test_run_poses_at_its_output_rate(tmp_path, monkeypatch):
    # `socialcam run --fps` sets the rate the videos are posed at (poses() has its own
    # `fps` default, which run() once left at 10 Hz whatever its option said)
    import socialcam.pipeline as pipeline
    from socialcam.sfm import VideoSfmOptions

    seen = {}

    def fake(videos, **kw):
        seen["options"] = kw["options"]
        raise ValueError("videos: stop here")

    monkeypatch.setattr(pipeline, "reconstruct_videos", fake)
    video = tmp_path / "a.mp4"
    video.write_bytes(b"")
    with pytest.raises(ValueError, match="stop here"):
        pipeline.run([video], tmp_path / "out", fps=30.0, progress=False)
    assert seen["options"].fps == 30.0
    # and keyframes at the least rate of `socialcam poses` (issue 9's bench): run's own
    # default of 2 keyframes/s gave 262 keyframes instead of 217 on seed 2 and a third more
    # mapping time; a lower overlap than poses' (fewer keyframes in the calibration
    # segments' range of motion: 191) is passed on
    assert seen["options"].keyframe_fps == VideoSfmOptions().keyframe_fps
    assert seen["options"].keyframe_overlap == 0.4 < VideoSfmOptions().keyframe_overlap
    with pytest.raises(ValueError, match="keyframe_overlap"):
        pipeline.RunOptions(keyframe_overlap=1.5)
    # the SfM threads are passed on too (1: repeatable poses, tests/test_run.py)
    assert seen["options"].num_threads == pipeline.RunOptions().num_threads == 2
    with pytest.raises(ValueError, match="stop here"):
        pipeline.run([video], tmp_path / "out1", num_threads=1, progress=False)
    assert seen["options"].num_threads == 1
    with pytest.raises(ValueError, match="num_threads"):
        pipeline.RunOptions(num_threads=0)
    # a calibrated lens can be kept fixed (the default lets bundle adjustment refine it)
    assert seen["options"].refine_intrinsics is True
    with pytest.raises(ValueError, match="stop here"):
        pipeline.run([video], tmp_path / "out2", refine_intrinsics=False, progress=False)
    assert seen["options"].refine_intrinsics is False
    with pytest.raises(ValueError, match="refine_intrinsics"):
        pipeline.RunOptions(refine_intrinsics="no")
