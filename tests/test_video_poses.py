"""Videos → camera poses (issue 9): rendered scenes with exact truth, end to end.

Thresholds come from measured runs (stated beside each); they are per frame where the
issue states a per-frame bound (no pose more than 10 cm off).
"""

from __future__ import annotations

import csv
import json
import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import socialcam as sc
from socialcam import sfm
from socialcam.sfm import KnownDistance, VideoPosesWarning, VideoReconstruction, pose_errors

# COLMAP gives bit-identical results only single-threaded (its matching and bundle adjustment
# depend on thread scheduling): every SfM run here uses one thread, so a test's outcome does
# not change from run to run (measured: two runs, identical poses; 2 threads moved the small
# scene's median centre error between 1 and 6 cm across CI runs).
NT = 1
render = pytest.importorskip("socialcam.synth.render", reason="needs the issue-9 renderer")


def _truth_cams(truth):
    return {n: truth.cameras(v) for v, n in enumerate(truth.names)}


def _known_distance(truth, a: int = 0, b: int = 1) -> KnownDistance:
    """The true distance between wearer a (a third into its video) and wearer b then."""
    ca, cb = truth.cameras(a), truth.cameras(b)
    i = len(ca) // 3
    j = int(np.argmin(np.abs(cb.times - ca.times[i])))
    d = float(np.linalg.norm(ca.C[i] - cb.C[j]))
    return KnownDistance(truth.names[a], float(ca.times[i]), truth.names[b], float(cb.times[j]), d)


def _manual(truth) -> dict[str, float]:
    return {n: float(truth.start[v] - truth.start[0]) for v, n in enumerate(truth.names)}


@pytest.fixture(scope="module")
def no_vocab_tree():
    """Every pycolmap entry point of the vocabulary tree / loop detection raises: they
    abort the process without a local tree file (a C++ check failure in pycolmap 3.11,
    without internet) and must never be reached."""
    import pycolmap

    mp = pytest.MonkeyPatch()

    def boom(*_a, **_k):
        raise AssertionError("the vocabulary tree must never be used")

    for name in ("match_vocabtree", "VocabTreePairingOptions", "VocabTreePairGenerator"):
        if hasattr(pycolmap, name):
            mp.setattr(pycolmap, name, boom)
    if hasattr(pycolmap, "match_sequential"):  # its loop detection uses the tree
        mp.setattr(pycolmap, "match_sequential", boom)
    yield
    mp.undo()


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    # No calibration segment: in it every wearer fixates the central pillar from its own
    # side for the first seconds, so 3-s videos would share almost no view.
    out = tmp_path_factory.mktemp("scene")
    return render.render_scene(
        out,
        n_wearers=3,
        duration=4.0,
        size=(400, 300),
        seed=0,
        calibration=False,
        progress=False,
    )


def _pose_scene(scene, out, kd):
    """``socialcam.poses`` on the small scene, as the fixture and the cache test call it."""
    return sc.poses(
        scene.videos,
        out,
        fps=10,
        sync=_manual(scene.truth),
        known_distance=kd,
        progress=False,
        num_threads=NT,
    )


@pytest.fixture(scope="module")
def posed(scene, tmp_path_factory, no_vocab_tree):
    out = tmp_path_factory.mktemp("run")
    kd = _known_distance(scene.truth)
    rec = _pose_scene(scene, out, kd)
    return out, rec, kd


def test_small_scene_every_frame_posed_against_truth(scene, posed):
    _, rec, _ = posed
    d = rec.to_dict()
    assert d["n_frames"] == 3 * 40
    # Measured on this scene size (3 wearers × 4 s, 400×300) over seeds 0–3 with upright
    # cameras: 98–100 % posed; centres 4.3–13 mm median, 12–97 mm max; rotations
    # 0.23–0.56° median; scale 0.994–1.020. (At 3 s, 320×240 with upright cameras, 4 seeds
    # of 5 left a wearer unplaced and seed 0 placed one with a 27 % wrong focal length:
    # too small a scene to self-calibrate.) COLMAP's matching is not deterministic across
    # runs (thread scheduling), so the bounds cover the spread seen.
    assert d["registered_fraction"] >= 0.9, d["quality"]
    e = pose_errors(rec, _truth_cams(scene.truth))
    assert np.median(e.centre) < 0.025
    assert np.degrees(np.median(e.rotation)) < 1.0
    assert e.centre.max() < 0.10  # no pose more than 10 cm off (drop instead)
    assert np.degrees(e.rotation.max()) < 3.0
    # metric scale from the known distance: the fitted truth/estimate scale is 1
    assert e.scale == pytest.approx(1.0, abs=0.03)
    # every wearer has keyframes and in-between frames
    for name in rec.names:
        q = rec.quality[name]
        assert q.keyframe.sum() >= 6  # at least MIN_KEYFRAMES per clip
        assert (q.posed & ~q.keyframe).sum() >= 12


def test_poses_are_gravity_aligned_and_pinhole(scene, posed):
    _, rec, _ = posed
    # gravity: the world's +z seen from each camera (R e_z) is the true up seen from it.
    # Measured 0.7–2.8° median over seeds 0–2 of this scene size; with the mean camera −y as
    # "up" (it leans where people look), 5.5–8.1°.
    truth = _truth_cams(scene.truth)
    ang = []
    for name, cam in rec.cameras.items():
        t = truth[name]
        k = np.abs(t.times[None] - cam.times[:, None]).argmin(axis=1)
        cos = np.einsum("fi,fi->f", cam.R[:, :, 2], t.R[k][:, :, 2])
        ang.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    assert np.median(np.concatenate(ang)) < 4.0
    # K is the pinhole part of the lens (OpenCV pixels): close to the true one
    for v, name in enumerate(scene.truth.names):
        K = rec.cameras[name].K[0]
        Kt = scene.truth.K[v]
        # measured 0.2–1.3 % in development runs, 3.3 % in a clean CI run (see above)
        assert K[0, 0] == pytest.approx(Kt[0, 0], rel=0.06)
        # the principal point is not refined (image centre): exact up to the COLMAP→OpenCV
        # half-pixel shift, which must be applied once
        assert np.abs(K[:2, 2] - Kt[:2, 2]).max() < 0.05


def _virtual_faces(truth, rng, n: int = 6, max_dist: float = 2.5):
    """Landmarks ``(n, 5, 3)`` of still faces at head height that at least two wearers see
    (in the image, turned to the camera by less than 70°, within ``max_dist`` metres: a
    conversation) in the most frames."""
    from socialcam.faces import LANDMARKS

    assert len(LANDMARKS) == 5
    cams = [truth.cameras(v) for v in range(len(truth.names))]
    W, H = truth.size
    cand, score = [], []
    for _ in range(300):
        c = np.r_[rng.uniform(-3, 3, 2), rng.uniform(1.5, 1.8)]
        yaw = rng.uniform(0, 2 * np.pi)
        f = np.array([np.cos(yaw), np.sin(yaw), 0.0])
        left = np.cross([0.0, 0.0, 1.0], f)
        up = np.array([0.0, 0.0, 0.03])
        X = np.array([c - 0.032 * left + up, c + 0.032 * left + up, c + 0.02 * f,
                      c - 0.025 * left - up, c + 0.025 * left - up])  # fmt: skip
        seen = 0
        for cam in cams:
            Xc = np.einsum("fij,fpj->fpi", cam.R, X[None] - cam.C[:, None])
            uv = Xc[..., :2] / Xc[..., 2:] * cam.K[:, None, [0, 1], [0, 1]] + cam.K[:, None, :2, 2]
            to_cam = cam.C - c
            ok = (Xc[..., 2] > 0.3).all(1) & (uv[..., 0] > 0).all(1) & (uv[..., 0] < W - 1).all(1)
            ok &= (uv[..., 1] > 0).all(1) & (uv[..., 1] < H - 1).all(1)
            dist = np.linalg.norm(to_cam, axis=1)
            ok &= (to_cam @ f > np.cos(np.radians(70)) * dist) & (dist < max_dist)
            seen += ok
        cand.append(X)
        score.append(int((seen >= 2).sum()) if isinstance(seen, np.ndarray) else 0)
    best = np.argsort(score)[::-1][:n]
    return np.array([cand[i] for i in best])


def test_faces_on_sfm_poses(scene, posed):
    """Issue 11 on these poses: still faces placed where two wearers' views overlap, seen
    through the true cameras (detector-like landmarks: projection + 3 % of the face size
    noise, at 1280×960 scale), reconstructed (Eq 3.2–3.4, ``reconstruct_faces``) with the
    SfM cameras and mapped onto the truth by the similarity of the camera centres. Measured
    on this scene 26 mm median landmark error over 160 face-instants (target ≤ 3 cm; the
    same detections with the true cameras: 3.6 mm; faces up to 4 m away instead of 2.5 m:
    43 mm, the depth error growing with distance over a short baseline)."""
    from socialcam.faces import FaceDetections, reconstruct_faces
    from socialcam.geometry import align_similarity

    _, rec, _ = posed
    truth = scene.truth
    rng = np.random.default_rng(0)
    faces = _virtual_faces(truth, rng)
    scale = 3.2
    S = np.diag([scale, scale, 1.0])

    def scaled(K):
        Ks = S @ K
        Ks[..., :2, 2] = (K[..., :2, 2] + 0.5) * scale - 0.5
        return Ks

    dets, cams, E, T = [], [], [], []
    for v, name in enumerate(truth.names):
        tc, sc_ = truth.cameras(v), rec.cameras[name]
        k = np.abs(tc.times[None] - sc_.times[:, None]).argmin(axis=1)
        Kt = scaled(tc.K[0])
        fr, lm = [], []
        for i, kk in enumerate(k):
            Xc = np.einsum("ij,fpj->fpi", tc.R[kk], faces - tc.C[kk])
            uv = Xc[..., :2] / Xc[..., 2:] * np.diag(Kt)[:2] + Kt[:2, 2]
            inside = (uv >= 0).all((1, 2)) & (uv[..., 0] < 1279).all(1) & (uv[..., 1] < 959).all(1)
            for p in np.nonzero(inside & (Xc[..., 2] > 0.3).all(1))[0]:
                size = Kt[0, 0] * 0.13 / Xc[p, :, 2].mean()
                fr.append(i)
                lm.append(uv[p] + 0.03 * size * rng.normal(size=(5, 2)))
        lm_ = np.array(lm).reshape(-1, 5, 2)
        c = lm_.mean(axis=1)
        sz = Kt[0, 0] * 0.13 / 2.0
        box = np.c_[c - sz / 2, np.full((len(c), 2), sz)]
        dets.append(FaceDetections(np.array(fr, np.int64), box, np.ones(len(fr)), lm_,
                                   len(sc_), (1280, 960)))  # fmt: skip
        cams.append(sc.Cameras(scaled(sc_.K), sc_.R, sc_.C, sc_.times))
        E.append(sc_.C)
        T.append(tc.C[k])
    s, Rs, t = align_similarity(np.concatenate(E), np.concatenate(T))
    f3 = reconstruct_faces(dets, cams, anchors=False)
    err = []
    for j in range(len(f3.person)):
        for ti in np.nonzero(np.isfinite(f3.landmarks[:, j, 0, 0]))[0]:
            X = s * f3.landmarks[ti, j] @ Rs.T + t
            d = np.linalg.norm(X[None] - faces, axis=-1).mean(-1)
            err.append(d.min())
    assert len(err) >= 60, len(err)
    assert np.median(err) <= 0.03, np.median(err)


def _posed_with(scene, out, **options):
    """``reconstruct_videos`` on the small scene with its known distance and ``options``:
    the reconstruction, its summary, its pose errors against the truth, and both for
    assertion messages."""
    rec = sfm.reconstruct_videos(
        scene.videos,
        out_dir=out,
        sync=_manual(scene.truth),
        known_distance=_known_distance(scene.truth),
        progress=False,
        num_threads=NT,
        **options,
    )
    d = rec.to_dict()
    e = pose_errors(rec, _truth_cams(scene.truth))
    return rec, d, e, (d["registered_fraction"], e.to_dict())


@pytest.mark.filterwarnings("ignore::socialcam.sfm.VideoPosesWarning")
def test_global_mapping(scene, tmp_path, no_vocab_tree):
    """COLMAP's global mapper instead of the incremental one, behind the same outlier check
    (keyframes observing too few map points are rejected) and the same frame posing."""
    _rec, d, e, got = _posed_with(scene, tmp_path / "o", global_mapping=True)
    # measured on seed 0: 100 % posed, centres 7.3 mm median and 15.5 mm max, rotations
    # 0.41° median, scale 1.015
    assert d["registered_fraction"] >= 0.9, got
    assert np.median(e.centre) < 0.025, got
    assert e.centre.max() < 0.10, got
    assert np.degrees(np.median(e.rotation)) < 1.0, got
    assert e.scale == pytest.approx(1.0, abs=0.03), got


def test_same_lens(scene, tmp_path, no_vocab_tree):
    """``same_lens``: one lens estimated from every video (COLMAP's single camera), for
    wearers with the same camera model. The renderer's wearers' focal lengths differ by up
    to ±3 %, so the shared one is a compromise: the poses must still hold."""
    rec, d, e, got = _posed_with(scene, tmp_path / "o", same_lens=True)
    Ks = [c.K[0] for c in rec.cameras.values()]
    assert len(Ks) == 3 and all(np.array_equal(K, Ks[0]) for K in Ks)
    f_true = scene.truth.K[:, 0, 0]
    assert f_true.min() * 0.97 < Ks[0][0, 0] < f_true.max() * 1.03, (Ks[0][0, 0], f_true)
    assert d["registered_fraction"] >= 0.9, got
    assert np.median(e.centre) < 0.025, got
    assert np.degrees(np.median(e.rotation)) < 1.0, got
    K = scene.truth.K
    with pytest.raises(ValueError, match="same_lens: the given intrinsics differ"):
        sfm.reconstruct_videos(
            scene.videos,
            out_dir=tmp_path / "x",
            sync=_manual(scene.truth),
            intrinsics=[(K[0], [0.0]), (K[0] * [[1.1], [1.1], [1.0]], [0.0]), None],
            same_lens=True,
            progress=False,
        )


@pytest.mark.filterwarnings("ignore::socialcam.sfm.VideoPosesWarning")
def test_eye_height_gives_metric_scale(scene, tmp_path, no_vocab_tree):
    """Scale from the wearers' mean eye (camera) height above the floor found among the map
    points, instead of a known distance; the origin is on the floor."""
    eye = float(np.mean([scene.truth.cameras(v).C[:, 2].mean() for v in range(3)]))
    rec = sfm.reconstruct_videos(
        scene.videos,
        out_dir=tmp_path / "o",
        sync=_manual(scene.truth),
        eye_height=eye,
        progress=False,
        num_threads=NT,
    )
    assert rec.counts["floor_found"], rec.warnings
    e = pose_errors(rec, _truth_cams(scene.truth))
    # measured over seeds 0–2 of this scene size: scale 0.980–1.065, and 1.14 on seed 0 of
    # the current renderer in a run whose map came out worse (6 cm median centre error:
    # COLMAP is not deterministic across runs). The floor of a 4-s clip is seen from few
    # places, so its map points scatter by ±0.1 m: a coarse bound here; the floor search
    # and the gravity rule have exact unit tests in test_sfm.py.
    assert e.scale == pytest.approx(1.0, abs=0.2), e.to_dict()
    heights = np.concatenate([c.C[:, 2] for c in rec.cameras.values()])
    assert heights.mean() == pytest.approx(eye, rel=0.05)


def test_run_folder_files(scene, posed):
    out, rec, _ = posed
    with (out / "poses.csv").open() as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == "person,time,cx,cy,cz,qw,qx,qy,qz".split(",")
    body = rows[1:]
    assert len(body) == sum(len(c) for c in rec.cameras.values())
    assert {r[0] for r in body} == set(scene.truth.names)
    q = np.array([[float(x) for x in r[5:]] for r in body])
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)
    # the quaternion is world-from-camera: it rotates camera +z onto the optical axis
    first = rec.cameras[body[0][0]]
    w, x, y, z = q[0]
    Rwc = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    np.testing.assert_allclose(Rwc, first.R[0].T, atol=1e-6)
    np.testing.assert_allclose([float(v) for v in body[0][2:5]], first.C[0], atol=1e-5)
    sync = json.loads((out / "sync.json").read_text())
    assert [v["person"] for v in sync["videos"]] == list(scene.truth.names)
    assert sync["videos"][0]["offset"] == 0.0
    report = json.loads((out / "report.json").read_text())
    for stage in ("features", "matching", "mapping", "posing frames"):
        assert report["timings"][stage] >= 0
    assert report["counts"]["posed"] == len(body)
    # written with the umask's permissions, no temporary left
    mode = stat.S_IMODE(os.stat(out / "poses.csv").st_mode)
    umask = os.umask(0)
    os.umask(umask)
    assert mode == 0o666 & ~umask
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]
    assert not (out / "frames").exists()  # the grey-frame cache is removed after posing


def test_rerun_reloads_instead_of_recomputing(scene, posed, monkeypatch):
    out, rec, kd = posed

    def fail(*_a, **_k):
        raise AssertionError("recomputed")

    monkeypatch.setattr("socialcam.pipeline.reconstruct_videos", fail)
    again = _pose_scene(scene, out, kd)
    assert json.loads((out / "report.json").read_text())["cached"] is True
    for name in rec.names:
        np.testing.assert_array_equal(again.cameras[name].C, rec.cameras[name].C)
        np.testing.assert_array_equal(again.cameras[name].times, rec.cameras[name].times)
    loaded = VideoReconstruction.load(out / "cache" / "sfm")
    assert loaded.names == rec.names
    assert len(loaded.points) == len(rec.points)
    # the loaded cameras still know their lens
    x = np.array([[10.0, 20.0]])
    name = rec.names[0]
    np.testing.assert_allclose(
        loaded.cameras[name][:1].undistort_points(x), rec.cameras[name][:1].undistort_points(x)
    )


def test_cli_poses(scene, posed, tmp_path):
    out, _, _ = posed
    # the same inputs and options through the CLI → the cached model is reused
    kd = _known_distance(scene.truth)
    args = [str(p) for p in scene.videos] + ["--out", str(out), "--fps", "10"]
    for n, off in _manual(scene.truth).items():
        args += ["--offset", f"{n}={off!r}"]
    args += ["--known-distance", kd.person_a, repr(kd.time_a), kd.person_b, repr(kd.time_b)]
    args += [repr(kd.metres), "--num-threads", str(NT)]
    r = subprocess.run(
        [sys.executable, "-m", "socialcam.cli", "poses", *args],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr
    assert "posed" in r.stdout and "poses.csv" in r.stdout
    bad = subprocess.run(
        [
            sys.executable,
            "-m",
            "socialcam.cli",
            "poses",
            str(tmp_path / "nope.mp4"),
            "--out",
            str(tmp_path / "o"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert bad.returncode == 2
    assert "nope.mp4" in bad.stderr


# ----------------------------------------------------------------------------- bad input


def test_not_a_video(tmp_path):
    p = tmp_path / "notes.mp4"
    p.write_text("not a video")
    with pytest.raises(ValueError, match=r"notes\.mp4"):
        sfm.reconstruct_videos([p], out_dir=tmp_path / "o", progress=False)


def test_video_without_audio_needs_manual_offsets(tmp_path):
    s = render.render_scene(
        tmp_path / "s", n_wearers=2, duration=0.5, size=(160, 120), audio=False, progress=False
    )
    with pytest.raises(ValueError, match=r"no audio.*manual offsets"):
        sfm.reconstruct_videos(s.videos, out_dir=tmp_path / "o", progress=False)


def test_bad_options(tmp_path):
    with pytest.raises(ValueError, match="keyframe_fps"):
        sfm.VideoSfmOptions(fps=10, keyframe_fps=20)
    with pytest.raises(ValueError, match="camera_model"):
        sfm.VideoSfmOptions(camera_model="FISHY")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="bogus"):
        sfm.reconstruct_videos(["a.mp4"], out_dir=tmp_path, bogus=1)
    with pytest.raises(ValueError, match="videos"):
        sfm.reconstruct_videos([], out_dir=tmp_path)
    with pytest.raises(ValueError, match="known_distance"):
        KnownDistance("a", 0.0, "b", 1.0, -2.0)


@pytest.mark.filterwarnings("ignore::socialcam.sfm.VideoPosesWarning")
def test_one_wearer_and_a_wearer_from_another_room(scene, tmp_path, no_vocab_tree):
    """One wearer alone works; a video sharing no view with it (another room) is reported
    as not placed, and the run goes on with the largest model."""
    # walking, like the scene's wearers (in a calibration segment the clip's steps to and from
    # the pillar give it a larger model than the wearer's own)
    kw = dict(n_wearers=1, duration=2.0, size=(320, 240), calibration=False, progress=False)
    other = render.render_scene(tmp_path / "other", seed=7, **kw)
    stranger = tmp_path / "stranger.mp4"
    shutil.copy(other.videos[0], stranger)
    with pytest.warns(VideoPosesWarning, match="stranger: could not be placed"):
        rec = sfm.reconstruct_videos(
            [scene.videos[0], stranger],
            out_dir=tmp_path / "o",
            sync={scene.truth.names[0]: 0.0, "stranger": 0.0},
            progress=False,
            num_threads=NT,
        )
    assert rec.unplaced == ("stranger",)
    assert "stranger" not in rec.cameras
    q = rec.quality[scene.truth.names[0]]
    assert q.posed.mean() >= 0.8  # measured 27/30 (30/30 with the earlier renderer)
    e = pose_errors(rec, {scene.truth.names[0]: scene.truth.cameras(0)})
    # one wearer, 3 s: no scale (similarity fit), measured 3 mm / 0.2°
    assert np.median(e.centre) < 0.01 and e.centre.max() < 0.10
    assert all(
        r == "wearer not placed in the model" for r in rec.quality["stranger"].reasons.values()
    )


class _CorruptFrames:
    """A video whose output frame ``bad`` decodes to noise (a corrupt frame)."""

    def __init__(self, video, bad: int) -> None:
        self._v, self._bad = video, bad
        self.info = video.info

    def frames(self, fps=None, **kw):
        rng = np.random.default_rng(0)
        for k, fr in enumerate(self._v.frames(fps, **kw)):
            if k == self._bad:
                noise = rng.integers(0, 256, fr.image.shape, dtype=np.uint8)
                fr = type(fr)(fr.index, fr.time, noise)
            yield fr

    def __getattr__(self, name):
        return getattr(self._v, name)


@pytest.mark.filterwarnings("ignore::socialcam.sfm.VideoPosesWarning")
@pytest.mark.parametrize("frame_cache", [True, False], ids=["cached", "decoded twice"])
def test_corrupt_frame_is_dropped_not_guessed(
    scene, tmp_path, monkeypatch, no_vocab_tree, frame_cache
):
    from socialcam import video as video_mod

    if not frame_cache:  # a scene too large for the grey-frame cache is decoded twice
        monkeypatch.setattr(sfm, "FRAME_CACHE_BYTES", 0)
    real_open = video_mod.open_video
    bad = 12  # between keyframes 10 and 20 (at least one keyframe per second at 10 fps)

    def opener(path, **kw):
        v = real_open(path, **kw)
        return _CorruptFrames(v, bad) if Path(path).stem == scene.truth.names[0] else v

    monkeypatch.setattr(video_mod, "open_video", opener)
    two = scene.truth.names[:2]
    rec = sfm.reconstruct_videos(
        scene.videos[:2],
        out_dir=tmp_path / "o",
        sync={n: _manual(scene.truth)[n] for n in two},
        progress=False,
        num_threads=NT,
    )
    q = rec.quality[scene.truth.names[0]]
    assert not q.posed[bad]
    assert bad in q.reasons
    # the frames around it are still posed (from the other keyframe's tracks), and right
    assert q.posed[bad - 1] and q.posed[bad + 1]
    truth = _truth_cams(scene.truth)
    e = pose_errors(rec, {n: truth[n] for n in scene.truth.names[:2]})
    assert e.centre.max() < 0.10  # measured 9 mm


def test_one_gross_outlier_does_not_take_its_neighbours_with_it():
    # a head walking 0.1 m per output frame; one frame (a keyframe, rendered seed 484)
    # registered 1.04 m off. Its neighbours' neighbour means are pulled 0.52 m towards
    # it: judged all at once, they broke the 0.5 m limit too. Worst first, only it goes.
    n = 12
    idx = np.arange(n)
    C = np.c_[0.1 * idx, np.zeros(n), np.full(n, 1.7)]
    R = np.repeat(np.eye(3)[None], n, axis=0)
    C[6] += [-0.9, -0.52, 0.05]
    bad = sfm._neighbour_outliers(idx, C, R, 0.5, np.radians(20))
    assert np.flatnonzero(bad).tolist() == [6]
    # a turn alone (same centres): the rotation limit
    C[6] -= [-0.9, -0.52, 0.05]
    R[3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # 90° about x
    assert np.flatnonzero(sfm._neighbour_outliers(idx, C, R, 0.5, np.radians(20))).tolist() == [3]
    # nothing wrong: nothing dropped; a gap of more than two frames is no neighbour
    R[3] = np.eye(3)
    assert not sfm._neighbour_outliers(idx, C, R, 0.5, np.radians(20)).any()
    far = np.r_[0, 1, 2, 10, 11]
    Cf = C[far] + np.array([[0, 0, 0]] * 3 + [[5, 0, 0]] * 2)  # 5 m away after the gap
    assert not sfm._neighbour_outliers(far, Cf, R[far], 0.5, 1.0).any()


@pytest.mark.filterwarnings("ignore::socialcam.sfm.VideoPosesWarning")
def test_wrong_intrinsics_are_detected(scene, tmp_path, no_vocab_tree):
    """Focal lengths 25 % too long, refined (the default): the videos move them back towards
    the truth and a warning says the given ones look wrong and to self-calibrate."""
    names = scene.truth.names
    wrong = [(scene.truth.K[v] * [[1.25], [1.25], [1]], [0.0]) for v in range(len(names))]
    with pytest.warns(VideoPosesWarning, match="intrinsics look wrong.*intrinsics=None"):
        rec = sfm.reconstruct_videos(
            scene.videos,
            out_dir=tmp_path / "refined",
            sync={n: _manual(scene.truth)[n] for n in names},
            intrinsics=wrong,
            progress=False,
            num_threads=NT,
        )
    # refined from +25 %: measured 246.8, 267.6, 251.8 px for a true 253.2, 255.2, 257.1 —
    # at least halfway back to the truth. (With only the first 2 wearers, the second stayed
    # at 321 px: two 4-s clips give bundle adjustment too little to calibrate from.)
    for v, n in enumerate(names):
        f_true, f_given = scene.truth.K[v, 0, 0], wrong[v][0][0, 0]
        assert abs(rec.cameras[n].K[0, 0, 0] - f_true) < 0.5 * abs(f_given - f_true)
    # The poses themselves are wrong (measured 0.59 m median, 2.3 m max after a similarity):
    # the warning says so and tells the user to self-calibrate; the self-calibrated run
    # is the small-scene test above.
    # Kept fixed (refine_intrinsics=False), the same wrong focal gave a keyframe
    # reprojection error under 1 px (bundle adjustment bends the structure): that case is
    # NOT detected yet — see the issue-9 report.


@pytest.fixture(scope="module")
def lens_scenes(tmp_path_factory):
    """The fixture scene's size (3 wearers × 4 s, 400×300) with another seed, seen through a
    radial and a fisheye lens (rendered once each)."""
    out = tmp_path_factory.mktemp("lens")
    cache: dict[str, render.RenderedScene] = {}

    def get(lens: str) -> render.RenderedScene:
        if lens not in cache:
            cache[lens] = render.render_scene(
                out / lens,
                n_wearers=3,
                duration=4.0,
                size=(400, 300),
                seed=1,
                distortion=lens,
                calibration=False,
                progress=False,
            )
        return cache[lens]

    return get


def _true_undistort(truth, v: int, px: np.ndarray) -> np.ndarray:
    """Pixels ``px (N, 2)`` of wearer ``v``'s distorted image on the true pinhole image."""
    import cv2

    K, d = truth.K[v], truth.dist[v]
    pts = px[:, None].astype(np.float64)
    if d["model"] == "fisheye":
        return cv2.fisheye.undistortPoints(pts, K, np.asarray(d["params"], float), P=K)[:, 0]
    coeffs = np.r_[np.asarray(d["params"], float), np.zeros(2)]
    return cv2.undistortPoints(pts, K, coeffs, P=K)[:, 0]


@pytest.mark.filterwarnings("ignore::socialcam.sfm.VideoPosesWarning")
@pytest.mark.parametrize(
    ("lens", "model", "lens_px"),
    # lens_px: largest error of the self-calibrated lens on a 3×3 grid of pixels over the
    # three wearers, measured 0.7 px (radial) and 2.7 px (fisheye: 4 coefficients from 4 s)
    [("radial", "RADIAL", 1.5), ("fisheye", "OPENCV_FISHEYE", 4.0)],
)
def test_distorted_lens_scene(lens_scenes, tmp_path, lens, model, lens_px, no_vocab_tree):
    """Action-camera lenses: poses and the lens model itself, self-calibrated from the
    videos. A fisheye model needs a focal-length prior (``focal_prior``, default 0.5 of the
    image width): without it COLMAP marks every pair as degenerate and no model is built."""
    s = lens_scenes(lens)
    rec = sfm.reconstruct_videos(
        s.videos,
        out_dir=tmp_path / "o",
        sync=_manual(s.truth),
        camera_model=model,
        progress=False,
        num_threads=NT,
    )
    frac = rec.to_dict()["registered_fraction"]
    e = pose_errors(rec, _truth_cams(s.truth))
    got = (frac, e.to_dict())
    # measured on seeds 0 and 1 of this scene size: radial 97–100 % posed, centres 8.3–9.3 mm
    # median, rotations 0.15–0.42° median; fisheye 100 %, 7.7–12.8 mm, 0.21–1.25°; focal
    # lengths within 1 % of the truth
    assert frac >= 0.9, got
    assert np.median(e.centre) < 0.025, got
    assert np.degrees(np.median(e.rotation)) < 2.0, got
    assert e.centre.max() < 0.10, got
    # undistortion: the lens model maps raw pixels onto the true pinhole pixels, compared
    # as normalised rays (the estimated K differs slightly from the true one)
    w, h = 400, 300
    grid = np.stack(np.meshgrid([20.0, w / 2, w - 20.0], [20.0, h / 2, h - 20.0]), -1)
    grid = grid.reshape(-1, 2)
    for v, name in enumerate(s.truth.names):
        K = s.truth.K[v]
        tn = (_true_undistort(s.truth, v, grid) - K[:2, 2]) / K[0, 0]
        est_K = rec.cameras[name].K[0]
        en = (rec.cameras[name][:1].undistort_points(grid[None])[0] - est_K[:2, 2]) / est_K[0, 0]
        assert np.abs(tn - en).max() * K[0, 0] < lens_px, (name, np.abs(tn - en).max() * K[0, 0])


def test_focal_prior_option():
    """The focal-length prior: validated, 0.5 of the image for fisheye models by default
    (without a prior, test_distorted_lens_scene[fisheye] builds no model at all)."""
    with pytest.raises(ValueError, match="focal_prior"):
        sfm.VideoSfmOptions(focal_prior=0.0)
    with pytest.raises(ValueError, match="focal_prior"):
        sfm.VideoSfmOptions(focal_prior=float("nan"))
    assert sfm.VideoSfmOptions(focal_prior=0.7).focal_factor == 0.7
    assert sfm.VideoSfmOptions(camera_model="OPENCV_FISHEYE").focal_factor == 0.5
    assert sfm.VideoSfmOptions(camera_model="RADIAL").focal_factor == 1.2
