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
