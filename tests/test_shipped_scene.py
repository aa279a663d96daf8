"""The rendered scene shipped in the package (for the demo): present, consistent with its
truth, and reproducible from ``SHIPPED_SCENE``."""

from __future__ import annotations

import numpy as np

from socialcam.synth.render import SHIPPED_SCENE, load_truth, shipped_scene
from socialcam.video import open_video


def test_shipped_scene_matches_its_truth():
    d = shipped_scene()
    truth = load_truth(d)
    assert truth.names == tuple(f"wearer{v}" for v in range(SHIPPED_SCENE["n_wearers"]))
    assert truth.seed == SHIPPED_SCENE["seed"] and truth.size == SHIPPED_SCENE["size"]
    total = 0
    for v, name in enumerate(truth.names):
        p = d / f"{name}.mp4"
        total += p.stat().st_size
        with open_video(p) as vid:
            assert vid.info.n_frames == len(truth.frame_times[v])
            np.testing.assert_allclose(
                vid.timestamps(), truth.frame_times[v] - truth.start[v], atol=1e-6
            )
            assert vid.info.has_audio
    assert total < 10e6  # a few MB


def test_shipped_scene_holds_calibration_and_joint_attention():
    # what `socialcam demo` compares with the truth: every wearer's range-of-motion segment
    # determines Eq 3.1 on the true cameras, and the truth holds joint attention that the
    # charges find (measured on the true cameras: v ≤ 0.35°, 18 of 20 group-frames found)
    from socialcam.pipeline import gaze_and_charges
    from socialcam.synth.evaluate import _calibration_errors, joint_attention, truth_segments

    truth = load_truth(shipped_scene())
    names = list(truth.names)
    assert len(truth.calibration) == len(names)
    cams = {n: truth.cameras(i) for i, n in enumerate(names)}
    cals, times, _frames, charges = gaze_and_charges(cams, names, calibration=truth_segments(truth))
    for n, c in _calibration_errors(cals, truth, 1.0).items():
        assert c["calibrated"] and c["v_error_deg"] < 0.5 and c["p_error_m"] < 0.02, (n, c)
    ja = joint_attention(truth, names, times, charges)
    assert ja["groups"] >= 20 and ja["found_fraction"] >= 0.8, ja
