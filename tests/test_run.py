"""``socialcam run`` end to end on a small rendered scene (3 wearers × 6 s, 640×480, seed
8: the seed of the 12 scanned whose truth holds the most joint attention), against the
renderer's truth; the stage cache; bad input. One module-scoped run shared by the tests."""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
import sys
import warnings

import numpy as np
import pytest

from socialcam.cli import main
from socialcam.pipeline import RunWarning, load_run_config, run
from socialcam.sfm import reconstruct_videos
from socialcam.synth.evaluate import run_vs_truth
from socialcam.synth.render import render_scene

#: wearer0 is given a "calibration" segment in which it walks and looks around.
NOT_FIXATING = {"wearer0": (1.0, 3.0)}


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    out = tmp_path_factory.mktemp("runscene")
    res = render_scene(
        out / "scene", n_wearers=3, duration=6.0, seed=8, calibration=False, progress=False
    )
    return res


def _eye_height(truth):
    return float(np.mean([c[:, 2].mean() for c in truth.C]))


def _run(scene, out, **kw):
    # one thread: COLMAP then gives bit-identical poses, so the figures asserted below are
    # those of one repeatable run (with 2 threads the same videos gave 3/22 to 20/22 found
    # and once a wearer unposed for its last 1.8 s, registered 0.90 < 0.93)
    kw = {"num_threads": 1, **kw}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RunWarning)
        return run(
            list(scene.videos),
            out,
            calibration=NOT_FIXATING,
            eye_height=_eye_height(scene.truth),
            progress=False,
            **kw,
        )


@pytest.fixture(scope="module")
def first(scene, tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "out"
    return _run(scene, out), out


def test_outputs_and_report(first, scene):
    res, out = first
    names = list(scene.truth.names)
    for f in ("poses.csv", "sync.json", "gaze.csv", "charges.csv", "report.json",
              "charges_top.png", "charges_time.png"):  # fmt: skip
        assert (out / f).stat().st_size > 0, f
    for n in names:
        assert (out / f"overlay_{n}.mp4").stat().st_size > 10_000
        assert res.report["overlays"][n] > 0.8 * 6 * res.report["fps"]
    rows = list(csv.DictReader((out / "gaze.csv").read_text().splitlines()))
    assert list(rows[0]) == ["person", "time", "px", "py", "pz", "vx", "vy", "vz", "h"]
    assert {r["person"] for r in rows} == set(names)
    v = np.array([[float(r[k]) for k in ("vx", "vy", "vz")] for r in rows])
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), 1.0, atol=1e-6)
    ch = list(csv.DictReader((out / "charges.csv").read_text().splitlines()))
    assert list(ch[0]) == ["time", "track", "x", "y", "z", "magnitude", "members"]
    for r in ch:
        members = r["members"].split(";")
        assert len(members) >= 2 and set(members) <= set(names)
    rep = json.loads((out / "report.json").read_text())
    assert list(rep["stages"]) == ["poses", "calibration", "gaze", "charges", "tracks",
                                   "field", "outputs"]  # fmt: skip
    assert all(s["seconds"] >= 0 for s in rep["stages"].values())
    # wearer0 walked and looked around in its "segment": stated fallback, no calibration
    cal0 = rep["calibration"]["wearer0"]
    assert cal0["status"] == "optical_axis" and cal0["fallback_reason"]
    # its segment (2 s) was posed at the video's 30 fps for Eq 3.1, not at the 10 Hz output
    # rate (tests/test_dense_calibration.py: what that is worth)
    assert cal0["posed_at"] == "video rate" and cal0["n_frames"] >= 0.9 * 30 * 2, cal0
    assert any(
        w.startswith("wearer0: gaze along the camera's optical axis") for w in rep["warnings"]
    )
    assert any("wearer1" in w and "no calibration segment" in w for w in rep["warnings"])
    assert res.field is not None and rep["field"]["windows"] >= 1
    assert len(res.tracks) >= 1


def test_joint_attention_against_truth(first, scene):
    res, _out = first
    acc = run_vs_truth(res, scene.truth)
    ja, ref = acc["joint_attention"], acc["joint_attention_true_cameras"]
    assert ja["groups"] >= 10 and ref["groups"] == ja["groups"]
    # Nobody is calibrated here (no range of motion in this scene): the optical axis, which
    # the renderer pitches 4-12° below the primary gaze, puts the charges ~0.3 m from the
    # targets, near the 0.5 m that counts as found. COLMAP's mapping with 2 threads is not
    # repeatable, and these rays are sensitive to it: on the same videos, runs measured 17/22
    # found (median 0.319 m; true cameras 17/22, 0.321 m: ratio 0.99), 20/22 (0.272 m, ratio
    # 1.03) and, once in CI, 11/22 (0.356 m; true cameras 22/22, 0.264 m: ratio 1.35). The
    # bounds hold over that spread (the issue's ≤ 1.2 is for calibrated wearers: bench_run).
    assert ja["found_fraction"] >= 0.4, ja
    assert ja["error_median_m"] < 0.42, ja
    assert acc["error_ratio"] <= 1.5, acc


def test_every_wearer_is_posed_to_the_end(first, scene):
    res, _out = first
    poses = res.report["poses"]
    assert poses["registered_fraction"] >= 0.93, poses
    for n in scene.truth.names:
        assert res.report["frames_with_gaze"][n] >= 0.85 * 6 * res.report["fps"], n


def test_second_mapping_pass_registers_the_keyframes_left_out(scene, tmp_path, monkeypatch):
    """The red CI of 840e37d, made reproducible. COLMAP's two-view verification draws from
    its matching threads' own generators, so with 2 threads its inlier sets vary from run to
    run; in that run (and with every pair's RANSAC seeded at 0, as here) the first mapping
    pass left wearer1's last 4 of 10 keyframes out (it walks straight ahead after 3.3 s, and
    they see fewer than COLMAP's 30 triangulated points): 156 of 180 frames posed, wearer1
    in 42 of 60, and 7 of the 22 joint-attention groups found. With the second pass
    (``retry_min_inliers``) they are registered: 173 of 180 frames, wearer1 60 of 60."""
    import pycolmap

    real = pycolmap.match_image_pairs

    def seeded(*args, **kwargs):
        verification = pycolmap.TwoViewGeometryOptions()
        verification.ransac.random_seed = 0
        return real(*args, **{**kwargs, "verification_options": verification})

    monkeypatch.setattr(pycolmap, "match_image_pairs", seeded)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = reconstruct_videos(
            list(scene.videos),
            out_dir=tmp_path / "sfm",
            eye_height=_eye_height(scene.truth),
            fps=10.0,
            keyframe_overlap=0.4,
            progress=False,
        )
    posed = {n: float(q.posed.mean()) for n, q in rec.quality.items()}
    assert min(posed.values()) >= 0.8, posed
    assert rec.to_dict()["registered_fraction"] >= 0.93, posed


def test_rerun_resumes_and_reruns_only_what_changed(first, scene):
    _res, out = first
    # everything cached
    again = _run(scene, out)
    assert all(s["cached"] for s in again.report["stages"].values()), again.report["stages"]
    assert (out / "charges.csv").read_text() == (out / "charges.csv").read_text()
    # a crash in the tracks stage: its key is missing, it and what follows rerun
    (out / "cache" / "tracks" / "key.txt").unlink()
    again = _run(scene, out)
    cached = {k: s["cached"] for k, s in again.report["stages"].items()}
    assert cached["poses"] and cached["calibration"] and cached["gaze"] and cached["charges"]
    assert not cached["tracks"]
    # a changed charge option reruns charges onwards, not poses / calibration / gaze
    again = _run(scene, out, member_sigma=2.0)
    cached = {k: s["cached"] for k, s in again.report["stages"].items()}
    assert cached["poses"] and cached["calibration"] and cached["gaze"]
    assert not cached["charges"] and not cached["field"]
    # no charges at all (more members than wearers): valid output, stated
    none = _run(scene, out, min_members=5)
    assert none.report["charges"]["total"] == 0 and none.field is None
    assert any("no social charges" in w for w in none.report["warnings"])
    assert (out / "charges.csv").read_text().strip() == "time,track,x,y,z,magnitude,members"
    _run(scene, out)  # back to the defaults for the other tests


def test_out_dir_of_another_run_is_refused(first, scene, tmp_path):
    _res, out = first
    before = (out / "poses.csv").read_bytes()
    with pytest.raises(ValueError, match="another run"):
        run(list(scene.videos[:2]), out, progress=False)
    assert (out / "poses.csv").read_bytes() == before


def test_cli_run(first, scene, tmp_path, capsys, monkeypatch):
    _res, out = first
    cfg = tmp_path / "run.toml"
    h = _eye_height(scene.truth)
    cfg.write_text(f"eye_height = {h}\n[calibration]\nwearer0 = [1.0, 3.0]\n")
    args = ["run", *map(str, scene.videos), "--out", str(out), "--config", str(cfg)]
    args += ["--num-threads", "1"]  # `socialcam run` once dropped this flag
    assert main(args) == 0  # all cached: the same inputs as the fixture's run
    text = capsys.readouterr()
    assert "cached" in text.out and "results written" in text.out
    assert "wearer0: gaze along the camera's optical axis" in text.err
    # --faces: then `socialcam faces` on the run folder (the faces themselves are tested in
    # test_faces_run.py, a scene without faces included)
    import socialcam.pipeline

    seen = []

    def fake_faces(run_dir, **kw):
        seen.append((str(run_dir), kw))
        return None, {"detections": {}, "instants": 0, "wearers_found": 0, "others_found": 0,
                      "people": [], "scale": {"source": "run", "metres_per_unit": 1.0}}  # fmt: skip

    monkeypatch.setattr(socialcam.pipeline, "faces", fake_faces)
    assert main([*args, "--faces", "--no-plots"]) == 0
    assert seen == [(str(out), {"landmarks": "mtcnn", "min_face": 12.0, "plots": False,
                                "progress": False, "interocular": None})]  # fmt: skip
    assert "faces written" in capsys.readouterr().out


def test_cli_bad_input(scene, tmp_path, capsys):
    vids = list(map(str, scene.videos))
    with pytest.raises(SystemExit):
        main(["run", *vids, "--out", str(tmp_path), "--calibration", "wearer0=1-3"])
    assert "--calibration" in capsys.readouterr().err
    cfg = tmp_path / "bad.toml"
    cfg.write_text("fsp = 10\n")
    with pytest.raises(SystemExit):
        main(["run", *vids, "--out", str(tmp_path), "--config", str(cfg)])
    assert "fsp" in capsys.readouterr().err
    cfg.write_text("[intrinsics.wearer0]\nK = 3\n")
    with pytest.raises(SystemExit):
        main(["run", *vids, "--out", str(tmp_path), "--config", str(cfg)])
    assert "intrinsics" in capsys.readouterr().err
    assert main(["run", *vids, "--out", str(tmp_path), "--calibration", "nobody=1:3"]) == 2
    assert "nobody" in capsys.readouterr().err
    with pytest.raises(ValueError, match="calibration"):
        run(vids, tmp_path, calibration={"wearer0": (3.0, 1.0)}, progress=False)
    with pytest.raises(ValueError, match="videos"):
        run([str(tmp_path / "missing.mp4")], tmp_path, progress=False)
    with pytest.raises(ValueError, match="fps"):
        run(vids, tmp_path, fps=0, progress=False)


def test_load_run_config(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text("[run]\nfps = 5\nmember_sigma = 2.0\noffsets = {a = 0.5}\n")
    opts, inputs = load_run_config(cfg)
    assert opts == {"fps": 5, "member_sigma": 2.0} and inputs == {"offsets": {"a": 0.5}}
    with pytest.raises(ValueError, match="config"):
        load_run_config(tmp_path / "nope.toml")


def _rrd_chunks(path):
    """Entity path -> rows logged, read back with the rerun CLI shipped in rerun-sdk."""
    env = dict(os.environ, RERUN_ANALYTICS="0")
    cmd = [sys.executable, "-m", "rerun", "rrd"]
    subprocess.run([*cmd, "verify", str(path)], check=True, capture_output=True, env=env)
    out = subprocess.run(
        [*cmd, "print", str(path)], check=True, capture_output=True, text=True, env=env
    ).stdout
    rows: dict[str, int] = {}
    for n, entity in re.findall(r"with (\d+) rows .*? - (/\S+) - data columns", out):
        rows[entity] = rows.get(entity, 0) + int(n)
    return rows


def test_view_writes_a_rerun_recording(first, scene, tmp_path):
    from socialcam.view import write_rrd

    res, out = first
    path = write_rrd(out, tmp_path / "r.rrd", frames=False)
    rows = _rrd_chunks(path)
    n_times = len(res.times)
    # the static map, every wearer's camera over time, gaze and charges at every output time
    assert rows.get("/world/map") == 1, rows
    for n in scene.truth.names:
        assert rows.get(f"/world/{n}", 0) > n_times // 2, (n, rows)
    assert rows.get("/world/gaze") == n_times, rows
    assert rows.get("/world/charges") == n_times, rows
    tracks = [e for e in rows if e.startswith("/world/tracks/")]
    assert len(tracks) == len(res.tracks) > 0, rows
    with pytest.raises(ValueError, match="no finished socialcam run"):
        write_rrd(tmp_path, tmp_path / "x.rrd")
    with pytest.raises(ValueError, match=r"^frames: expected a bool"):  # "no" wrote them
        write_rrd(out, tmp_path / "y.rrd", frames="no")  # type: ignore[arg-type]
