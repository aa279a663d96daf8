from __future__ import annotations

import re

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
    good = (
        "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition "
        "Zrotation Xrotation Yrotation\nJOINT b\n{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation "
        "Xrotation Yrotation\nEnd Site\n{\nOFFSET 0 1 0\n}\n}\n}\nMOTION\nFrames: 2\n"
        "Frame Time: 0.1\n0 0 0 0 0 0 0 0 0\n1 0 0 0 0 0 0 0 90\n"
    )
    p.write_text(good)
    m = load_bvh(p, scale=1.0)
    assert m.positions.shape == (2, 2, 3) and m.fps == pytest.approx(10.0)
    # each of these was an IndexError, a numpy or int() error without the file, or a
    # silent misreading (an unknown rotation axis read as Z, a NaN frame time, rows dropped)
    for before, after, why in (
        ("ROOT a", "ROOT", "ROOT needs one name at line 2"),
        ("OFFSET 0 1 0\nCHANNELS 3", "OFFSET 0 1\nCHANNELS 3", "bad OFFSET"),
        ("Zrotation Xrotation Yrotation\nEnd", "Wrotation Xrotation Yrotation\nEnd", "'Wrotation'"),
        ("CHANNELS 3 Zrotation", "CHANNELS 4 Zrotation", "CHANNELS count"),
        ("Frames: 2", "Frames: 1.5", "'Frames:' needs a whole number"),
        ("Frame Time: 0.1", "Frame Time: nan", "'Frame Time:' needs a finite number"),
        ("Frame Time: 0.1", "Frame Time: 0", "'Frame Time:' needs a finite number"),
        ("Frames: 2", "Frames: 1", "'Frames: 1' but 2 rows"),
        ("1 0 0 0 0 0 0 0 90", "1 0 0 0 0 0 0 0", "8 values where the hierarchy has 9"),
        ("1 0 0 0 0 0 0 0 90", "1 0 0 0 0 0 0 0 inf", "not finite at line 20"),
        ("HIERARCHY\nROOT a\n{", "HIERARCHY\nCHANNELS 1 Xposition\nROOT a\n{", "outside any"),
    ):
        assert before in good, before
        p.write_text(good.replace(before, after, 1))
        with pytest.raises(ValueError, match=f"path: .*bad.bvh: .*{re.escape(why)}"):
            load_bvh(p, scale=1.0)
    p.write_text(good)
    for kw, name in ((dict(scale=0.0), "scale"), (dict(frames=0), "frames"),
                     (dict(include_end_sites="no"), "include_end_sites")):  # fmt: skip
        with pytest.raises(ValueError, match=name):
            load_bvh(p, **kw)
    for path in (3, None, tmp_path):  # 3 used to be read (and closed) as file descriptor 3
        with pytest.raises(ValueError, match="path"):
            load_bvh(path)  # type: ignore[arg-type]


def test_c3d_damaged_files_name_the_file(data_dir, tmp_path):
    data = (data_dir / "mocap" / "cmu_85_02.c3d").read_bytes()
    for label, content, why in (
        ("empty", b"", "not a readable C3D file"),
        ("garbage", bytes(range(256)) * 12, "not a readable C3D file"),
        ("cut", data[: len(data) // 2], "cut short"),
    ):
        p = tmp_path / f"{label}.c3d"
        p.write_bytes(content)
        with pytest.raises(ValueError, match=f"path: .*{label}.c3d.* {why}"):
            load_c3d(p)


def test_c3d_markers_in_metres(data_dir):
    c = load_c3d(data_dir / "mocap" / "cmu_85_02.c3d")
    assert c.positions.shape == (810, 41, 3)
    assert c.fps == 120.0
    assert np.isfinite(c.positions).all()
    extent = np.ptp(c.positions[0], axis=0)
    assert 1.2 < extent.max() < 2.2  # a standing person, in metres
