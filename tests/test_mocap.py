from __future__ import annotations

import numpy as np
import pytest

from socialcam.mocap import CMU_BVH_METRES_PER_UNIT, load_bvh, load_c3d


def test_bvh_forward_kinematics_keeps_bone_lengths(data_dir):
    m = load_bvh(data_dir / "mocap" / "cmu_131_01_walk300.bvh")
    assert m.positions.shape == (300, 31, 3)
    assert m.fps == pytest.approx(120.0, rel=1e-4)
    assert m.parents[0] == -1 and (m.parents[1:] < np.arange(1, 31)).all()
    bones = np.linalg.norm(m.positions[:, 1:] - m.positions[:, m.parents[1:]], axis=2)
    np.testing.assert_allclose(bones, np.broadcast_to(m.bone_lengths[1:], bones.shape), atol=1e-9)
    # A walking adult in metres: the body spans 1.2–2 m vertically (CMU BVH is y-up).
    span = np.ptp(m.positions[0, :, 1])
    assert 1.0 < span < 2.0
    # The subject walks: the root travels more than a metre over 2.5 s.
    assert np.linalg.norm(m.positions[-1, 0] - m.positions[0, 0]) > 1.0


def test_bvh_end_sites_and_scale(data_dir):
    path = data_dir / "mocap" / "cmu_131_01_walk300.bvh"
    raw = load_bvh(path, scale=1.0, frames=slice(0, 10))
    m = load_bvh(path, include_end_sites=True, frames=slice(0, 10))
    assert len(m.names) > len(raw.names) and any(n.endswith("_end") for n in m.names)
    keep = [m.names.index(n) for n in raw.names]
    np.testing.assert_allclose(
        m.positions[:, keep], raw.positions * CMU_BVH_METRES_PER_UNIT, atol=1e-12
    )


def test_bvh_malformed(tmp_path):
    p = tmp_path / "bad.bvh"
    p.write_text(
        "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\n}\nMOTION\nFrames: 2\nFrame Time: 0.1\n0 0 0\n"
    )
    with pytest.raises(ValueError, match="frames"):
        load_bvh(p)


def test_c3d_markers_in_metres(data_dir):
    c = load_c3d(data_dir / "mocap" / "cmu_85_02.c3d")
    assert c.positions.shape == (810, 41, 3)
    assert c.fps == 120.0
    assert np.isfinite(c.positions).all()
    extent = np.ptp(c.positions[0], axis=0)
    assert 1.2 < extent.max() < 2.2  # a standing person, in metres
