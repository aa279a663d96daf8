"""Eq 3.1 through SfM poses needs every video frame of the calibration segment
(``socialcam.sfm.pose_segment``, used by ``socialcam run``): the rendered range-of-motion
segments carry the eye-in-head deviation as 3-12 Hz head jitter about the fixation, which
poses at the 10 Hz output rate alias into the slow head motion that Eq 3.1 separates the eye
centre from the gaze direction with.

A small rendered scene (2 wearers × 10 s, 400×300, 3-s segments) posed by SfM once, single
threaded (bit-identical from run to run)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

import socialcam as sc
from socialcam.pipeline import gaze_and_charges
from socialcam.sfm import pose_segment
from socialcam.synth.evaluate import _alignment, _calibration_errors, truth_segments
from socialcam.synth.render import render_scene


@pytest.fixture(scope="module")
def posed(tmp_path_factory):
    out = tmp_path_factory.mktemp("dense")
    scene = render_scene(
        out / "scene", n_wearers=2, duration=10.0, seed=1, size=(400, 300), progress=False
    )
    truth = scene.truth
    sync = {n: float(truth.start[v] - truth.start[0]) for v, n in enumerate(truth.names)}
    eye_height = float(np.mean([c[:, 2].mean() for c in truth.C]))
    rec = sc.poses(
        scene.videos,
        out / "run",
        fps=10,
        sync=sync,
        eye_height=eye_height,
        progress=False,
        num_threads=1,
    )
    segs = truth_segments(truth)
    dense = {
        n: pose_segment(rec, video, *segs[n], num_threads=1)
        for n, video in zip(truth.names, scene.videos, strict=True)
    }
    return scene, rec, segs, dense


def _calibrate(cams, truth, segs, scale):
    names = list(truth.names)
    cals = gaze_and_charges(cams, names, calibration=segs)[0]
    return _calibration_errors(cals, truth, scale)


def test_every_frame_of_the_segment_is_posed_against_truth(posed):
    scene, rec, segs, dense = posed
    truth = scene.truth
    s, R, t = _alignment(rec, truth)
    for v, n in enumerate(truth.names):
        cams, (t0, t1) = dense[n], segs[n]
        # the video's 30 fps, not the 10 Hz output rate: 3 s → 90 frames (measured: 91)
        assert len(cams) >= 0.95 * 30 * (t1 - t0), (n, len(cams))
        assert cams.times.min() >= t0 and cams.times.max() <= t1
        # the output-rate poses in the segment are among them, unchanged
        out = rec.cameras[n]
        sel = (out.times >= t0) & (out.times <= t1)
        j = np.searchsorted(cams.times, out.times[sel] - 1e-6)
        assert np.allclose(cams.times[j], out.times[sel], atol=1e-6)
        tc = truth.cameras(v)
        k = np.searchsorted(tc.times, cams.times - 1e-6)
        err = np.linalg.norm(s * cams.C @ R.T + t - tc.C[k], axis=1)
        # measured: median 2.8 / 2.2 mm, max 5.5 / 4.9 mm (wearer0 / wearer1)
        assert np.median(err) < 0.01 and err.max() < 0.03, (n, np.median(err), err.max())


def test_eq31_through_sfm_needs_the_video_rate(posed):
    # The targets: v within 0.5°, p within 2 cm, h within 20 %. On every frame of
    # the segment (measured: v 0.23 / 0.07°, p 0.9 / 0.1 cm, h ×1.14 / 0.95) they are met;
    # on the 10 Hz output poses of the same SfM run wearer0's calibration falls back to the
    # optical axis (v 9.4° off) and wearer1 misses p (2.6 cm). The same on the true cameras
    # of seeds 1-5 at this scene size: 30 Hz v ≤ 0.33°, p ≤ 0.8 cm; 10 Hz 5 of 10 wearers
    # fall back, the others v 0.3-2.6°, p 1.6-8.5 cm.
    scene, rec, segs, dense = posed
    truth = scene.truth
    s = _alignment(rec, truth)[0]
    for n, e in _calibrate(dense, truth, segs, s).items():
        assert e["calibrated"], (n, e)
        assert e["v_error_deg"] < 0.5, (n, e)
        assert e["p_error_m"] < 0.02, (n, e)
        assert 0.8 < e["h_ratio"] < 1.25, (n, e)
    sparse = _calibrate(rec.cameras, truth, segs, s)
    assert any(
        not e["calibrated"] or e["v_error_deg"] > 0.5 or e["p_error_m"] > 0.02
        for e in sparse.values()
    ), sparse


def test_pose_segment_bad_input(posed, tmp_path):
    scene, rec, _segs, _dense = posed
    video = scene.videos[0]
    with pytest.raises(ValueError, match="t1"):
        pose_segment(rec, video, 3.0, 1.0)
    with pytest.raises(ValueError, match="t0"):
        pose_segment(rec, video, float("nan"), 1.0)
    other = tmp_path / "nobody.mp4"
    shutil.copy(video, other)
    with pytest.raises(ValueError, match="nobody"):
        pose_segment(rec, other, 1.0, 2.0)
    # a segment outside the video: no frame, no error
    assert len(pose_segment(rec, video, 100.0, 101.0)) == 0
