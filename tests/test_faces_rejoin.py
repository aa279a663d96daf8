"""``faces.rejoin_by_head_turns``: two groups of wearers that SfM joined turned about the
vertical relative to each other are put back together by their wearers' head turns, on
rendered conversation circles (4 wearers + 2 people, 8 s, detector-like landmarks from the
truth: 3 % of the face size noise at 1280×960 scale)."""

from __future__ import annotations

import numpy as np
import pytest

from socialcam import Cameras
from socialcam.faces import rejoin_by_head_turns
from socialcam.synth.evaluate import truth_detections
from socialcam.synth.render import render_scene


def _render(tmp_path_factory, seed):
    out = tmp_path_factory.mktemp(f"circle{seed}")
    return render_scene(out, n_wearers=4, n_people=2, duration=8.0, fps=10.0, size=(320, 240),
                        seed=seed, faces=True, arrangement="circle", audio=False,
                        calibration=False, start_spread=0.0, progress=False)  # fmt: skip


def _circle(tmp_path_factory, seed):
    return truth_detections(_render(tmp_path_factory, seed).truth, scale=4.0, seed=seed)


def _turned(cams, degrees, extra=0.0):
    """Cameras 2 and 3 turned by ``degrees`` about the circle's centre (as SfM joined
    them), their orientations by ``extra`` degrees more (a bias the test must catch)."""
    centre = np.mean([c.C.mean(axis=0) for c in cams], axis=0)

    def rz(d):
        a = np.radians(d)
        return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])

    R, E = rz(degrees), rz(degrees + extra)
    return [c if v < 2 else Cameras(c.K, c.R @ E.T, (c.C - centre) @ R.T + centre, c.times)
            for v, c in enumerate(cams)]  # fmt: skip


@pytest.fixture(scope="module")
def scene8(tmp_path_factory):
    return _render(tmp_path_factory, 8)


@pytest.fixture(scope="module")
def circle8(scene8):
    return truth_detections(scene8.truth, scale=4.0, seed=8)


def test_a_turned_pair_of_wearers_is_turned_back(circle8):
    """Seed 8, wearers 2 and 3 turned 35°: both match a face track of the reference pair
    (spread 1.3° and 4.9° over 77 and 42 instants); measured turn −34.6° (0.4° off; seeds 5
    and 6: 2.3° and 1.1°: the cameras' mounting angle on the head), centres 84 / 85 mm (the
    eyes are not the camera: seeds 5-6 56-110 mm). Red: the group's cameras turned 5° more
    than their centres (a bias) moves the turn found by 5°."""
    dets, cams = circle8
    r = rejoin_by_head_turns(dets, _turned(cams, 35.0), [0, 1], [2, 3])
    assert r is not None
    assert abs(np.degrees(r.turn) + 35.0) < 1.5, np.degrees(r.turn)
    assert {m[1] for m in r.matches} == {2, 3}, r.matches
    for v in range(4):
        err = np.median(np.linalg.norm(r.cameras[v].C - cams[v].C, axis=1))
        assert err < (1e-9 if v < 2 else 0.15), (v, err)
    ang = np.degrees(
        np.arccos(np.clip((np.trace(r.cameras[2].R[0] @ cams[2].R[0].T) - 1) / 2, -1, 1))
    )
    assert ang < 1.5, ang
    biased = rejoin_by_head_turns(dets, _turned(cams, 35.0, extra=5.0), [0, 1], [2, 3])
    assert biased is not None and abs(np.degrees(biased.turn) + 40.0) < 1.5


def test_no_confident_match_moves_nothing(tmp_path_factory):
    """Seed 3: the turned wearers' faces are seen by both reference cameras while their
    heads turn little (4° on the one that is), and a still face matches nobody: ``None``,
    no wrong move (seeds 3-12: 3 placed, 7 ``None``, none wrong)."""
    dets, cams = _circle(tmp_path_factory, 3)
    assert rejoin_by_head_turns(dets, _turned(cams, 35.0), [0, 1], [2, 3]) is None


def test_rejoin_bad_input(circle8):
    dets, cams = circle8
    with pytest.raises(ValueError, match="ref, group"):
        rejoin_by_head_turns(dets, cams, [0, 1], [1, 2])
    with pytest.raises(ValueError, match="ref, group"):
        rejoin_by_head_turns(dets, cams, [0, 1], [])
    with pytest.raises(ValueError, match="ref, group"):
        rejoin_by_head_turns(dets, cams, [0, 1], [2, 9])
    with pytest.raises(ValueError, match="cameras"):
        rejoin_by_head_turns(dets, cams[:3], [0, 1], [2])
    with pytest.raises(ValueError, match="detections"):
        rejoin_by_head_turns(dets[0], cams, [0, 1], [2])
    with pytest.raises(ValueError, match="min_sweep"):
        rejoin_by_head_turns(dets, cams, [0, 1], [2, 3], min_sweep=0.0)


def _centre_errors(cams, truth_cams):
    return [
        float(np.median(np.linalg.norm(c.C - t.C, axis=1)))
        for c, t in zip(cams, truth_cams, strict=True)
    ]


def _turn_errors(cams, truth_cams):
    return [
        float(np.degrees(np.median(np.arccos(np.clip(
            (np.einsum("kij,kij->k", c.R, t.R) - 1) / 2, -1, 1)))))
        for c, t in zip(cams, truth_cams, strict=True)
    ]  # fmt: skip


def test_repair_finds_the_wrong_group_and_puts_it_back(circle8, scene8):
    """``repair_joins``: the sightings split the cameras into {0, 1} and {2, 3} (no group
    given), the head turns place {2, 3}, and the faces both pairs see refine it: measured
    centres 2 / 2 mm and orientations 0.05° off (seeds 5, 6, 13, 14: 1-4 mm, ≤ 0.12°)
    against 84 / 85 mm and 0.4° from the head turns alone. Red: without the refinement
    the centres stay 84 mm off. The true poses are left alone."""
    from socialcam.faces import repair_joins

    dets, cams = circle8
    r = repair_joins(dets, _turned(cams, 35.0))
    assert r.ref == (0, 1) and [p[0] for p in r.placed] == [(2, 3)] and not r.unplaced, r
    assert r.wrong_before and not r.wrong_after, (r.wrong_before, r.wrong_after)
    _, turn, _, refined, resid = r.placed[0]
    assert refined and abs(np.degrees(turn) + 35.0) < 0.5, np.degrees(turn)
    assert max(_centre_errors(r.cameras, cams)) < 0.015, _centre_errors(r.cameras, cams)
    assert max(_turn_errors(r.cameras, cams)) < 0.3, _turn_errors(r.cameras, cams)
    assert resid < 1.5  # median reprojection error in units of the landmark noise
    bad = _turned(cams, 35.0)
    for v in range(4):  # each camera's motion puts it where the repair holds it
        R, t = r.motion(v)
        m = bad[v].moved(R, t)
        assert np.allclose(m.C, r.cameras[v].C, atol=1e-9) and np.allclose(m.R, r.cameras[v].R)
        assert (v >= 2) == (not np.allclose(R, np.eye(3)))
    with pytest.raises(ValueError, match="camera"):
        r.motion(4)
    coarse = repair_joins(dets, _turned(cams, 35.0), refine=False)
    assert [p[3] for p in coarse.placed] == [False]
    assert min(_centre_errors(coarse.cameras, cams)[2:]) > 0.05
    # the head turns place the wearers' eyes and primary gaze where a gaze calibration puts
    # them (its eye centre normal to the primary gaze, its direction): measured 84 / 85 mm
    # and a turn 0.40 deg off -> 6 / 11 mm and 0.0x deg here (46 circles with 1 cm and 0.3
    # deg of noise: median 74 -> 19 mm, turn 1.3 -> 0.8 deg)
    tr = scene8.truth
    pn = np.array([o - o.dot(d) * d for o, d in zip(tr.eye_offset, tr.primary_dir, strict=True)])
    cal = repair_joins(dets, _turned(cams, 35.0), refine=False, eye_offsets=pn,
                       gaze_directions=tr.primary_dir)  # fmt: skip
    assert max(_centre_errors(cal.cameras, cams)[2:]) < 0.03, _centre_errors(cal.cameras, cams)
    turn_err = abs(np.degrees(cal.placed[0][1]) + 35.0)
    assert turn_err < 0.2 < abs(np.degrees(coarse.placed[0][1]) + 35.0), turn_err
    part = pn.copy()
    part[[2, 3]] = np.nan  # the placed wearers' unknown: their camera centres, as without
    unknown = repair_joins(dets, _turned(cams, 35.0), refine=False, eye_offsets=part)
    for a, b in zip(unknown.cameras, coarse.cameras, strict=True):
        np.testing.assert_allclose(a.C, b.C, atol=1e-12)
    with pytest.raises(ValueError, match="eye_offsets"):
        repair_joins(dets, cams, eye_offsets=pn[:3])
    with pytest.raises(ValueError, match="eye_offsets"):
        repair_joins(dets, cams, eye_offsets=np.full((4, 3), np.inf))
    with pytest.raises(ValueError, match="gaze_directions"):
        repair_joins(dets, cams, gaze_directions=np.zeros((4, 3)))
    with pytest.raises(ValueError, match="gaze_directions"):
        repair_joins(dets, cams, gaze_directions=np.ones((3, 3)))
    same = repair_joins(dets, cams)
    assert not same.placed and not same.unplaced and not same.wrong_before
    assert all(a is b for a, b in zip(same.cameras, cams, strict=True))


def test_align_by_faces_corrects_a_small_offset(circle8):
    """The refinement alone, from a placement 3° and 10 cm off (what the head turns leave):
    back within 1.5 cm and 0.3°; a placement 1 m off matches no face and moves nothing."""
    from socialcam.faces import align_by_faces

    dets, cams = circle8
    a3 = np.radians(3.0)
    Rz = np.array([[np.cos(a3), -np.sin(a3), 0], [np.sin(a3), np.cos(a3), 0], [0, 0, 1.0]])
    off = [c if v < 2 else Cameras(c.K, c.R @ Rz.T, c.C @ Rz.T + np.array([0.1, 0.0, 0.0]), c.times)
           for v, c in enumerate(cams)]  # fmt: skip
    a = align_by_faces(dets, off, [0, 1], [2, 3])
    assert a is not None and a.points >= 50
    assert max(_centre_errors(a.cameras, cams)) < 0.015, _centre_errors(a.cameras, cams)
    assert max(_turn_errors(a.cameras, cams)) < 0.3, _turn_errors(a.cameras, cams)
    far = [c if v < 2 else Cameras(c.K, c.R, c.C + np.array([1.0, 0.0, 0.0]), c.times)
           for v, c in enumerate(cams)]  # fmt: skip
    assert align_by_faces(dets, far, [0, 1], [2, 3]) is None


def test_sighting_groups():
    """Rows see columns. Cameras 2 and 3 turned: 2 finds wearer 1 by chance where its wrong
    pose puts another face (20 of 22, as measured on circle 6), 1 finds 2 of 21 the other
    way; the split is still {0, 1} | {2, 3}. Camera 4 has no evidence: a group of its own.
    All found: one group."""
    from socialcam.faces import sighting_groups

    e = np.array([[0, 26, 17, 0, 0], [16, 0, 21, 16, 0], [14, 22, 0, 6, 0],
                  [28, 59, 12, 0, 0], [0, 0, 0, 0, 0]])  # fmt: skip
    f = np.array([[0, 26, 0, 0, 0], [16, 0, 2, 16, 0], [0, 20, 0, 6, 0],
                  [0, 0, 12, 0, 0], [0, 0, 0, 0, 0]])  # fmt: skip
    g = sighting_groups(e, f)
    assert g == [[0, 1], [2, 3], [4]], g
    assert sighting_groups(e, e) == [[0, 1, 2, 3], [4]]
    with pytest.raises(ValueError, match="expected, found"):
        sighting_groups(e, e[:3])
    with pytest.raises(ValueError, match="min_expected"):
        sighting_groups(e, e, min_expected=0)


def test_faces_of_a_run_repair_a_wrong_join(tmp_path, scene8, circle8, monkeypatch, capsys):
    """``pipeline.faces`` on a run whose poses put wearers 2 and 3 35° round the circle:
    the pose check finds them, the repair puts them back, the faces are reconstructed again
    with the moved cameras (the detections: the truth's detector-like landmarks, in place
    of MTCNN on these 320×240 frames). Measured: turn −35.0°, refined by the faces;
    face-instants 221, as many as with the true poses; without ``repair`` the warning and
    132. The same poses in a map without a scale (units of 2 m), scaled by the faces' eyes:
    the scale measured again on the repaired map (0.09 % off) and the cameras returned in
    metres (2-5 mm off; red: the repaired cameras scaled twice, 1.9-3.1 m).

    The run's gaze (the wearers' true primary gaze rays, moved with the turned cameras) is
    made again with the repaired poses into ``repaired/``: wearers 2 and 3 within 2.3 mm
    and 0.05° of the truth, joint attention median error 2 mm (the run's, with the turned
    poses: 96 mm); in the map, the same rays in its unit. The ego gaze compared with the
    faces moves too: ego-exo disagreement 1.5-5.0° for all four wearers (red: wearers 2
    and 3 left in SfM's frame, 35°)."""
    import json
    from dataclasses import asdict
    from types import SimpleNamespace

    from socialcam import pipeline
    from socialcam.faces import INTEROCULAR, reconstruct_faces, scale_from_faces
    from socialcam.sfm import FrameQuality, VideoReconstruction
    from socialcam.synth.evaluate import joint_attention

    dets, cams = circle8
    names = [p.stem for p in scene8.videos]
    bad = _turned(cams, 35.0)
    truth = scene8.truth
    times = cams[0].times
    opts = pipeline.RunOptions()
    centre = np.mean([c.C.mean(axis=0) for c in cams], axis=0)
    a = np.radians(35.0)
    Rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])

    def rays(turned, unit=1.0):
        """The wearers' true primary gaze rays, wearers 2 and 3 moved as their cameras."""
        out = {}
        for v, n in enumerate(names):
            p, d = truth.eyes[v], truth.gaze[v]
            if turned and v >= 2:
                p, d = (p - centre) @ Rz.T + centre, d @ Rz.T
            out[n] = (p / unit, d, np.full(len(p), truth.h[v]))
        return out

    def scored(charges_at):
        return joint_attention(truth, names, times, charges_at)["error_median_m"]

    bad_charges = pipeline._find_charges(pipeline._frames(names, rays(True)), times, opts)

    def run_folder(folder, cameras, scale, unit=1.0):
        (folder / "cache" / "sfm").mkdir(parents=True)
        rc = dict(zip(names, cameras, strict=True))
        q = {n: FrameQuality(times=c.times, posed=np.ones(len(c), bool),
                             keyframe=np.zeros(len(c), bool), rms=np.zeros(len(c)),
                             n_inliers=np.zeros(len(c), np.int64), reasons={})
             for n, c in rc.items()}  # fmt: skip
        VideoReconstruction(names=tuple(names), cameras=rc, quality=q, points=np.zeros((0, 3)),
                            colors=np.zeros((0, 3), np.uint8), offsets=np.zeros(len(rc)),
                            sync={}, scale=scale, unplaced=(), timings={}, warnings=(),
                            counts={}, out_dir=folder / "cache" / "sfm").save()  # fmt: skip
        (folder / "gaze.csv").write_text(pipeline.gaze_csv(names, times, rays(True, unit)))
        (folder / "report.json").write_text(json.dumps({
            "inputs": {"videos": [str(v) for v in scene8.videos], "calibration": {}},
            "names": names, "options": asdict(opts),
            "calibration": {n: {"status": "optical_axis"} for n in names},
            "charges": {"total": sum(len(c) for c in bad_charges)},
        }))  # fmt: skip
        return folder

    run = run_folder(tmp_path / "run", bad, 1.0)
    # the run's gaze calibration (wearer 1 not calibrated): the repair gets its eye centres
    from dataclasses import replace

    import socialcam.faces as sf
    from socialcam.gaze import GazeCalibration

    pn = np.array([o - o.dot(d) * d for o, d in zip(truth.eye_offset, truth.primary_dir,
                                                     strict=True)])  # fmt: skip
    stored = {n: {"summary": {}, "calibration": (GazeCalibration.optical_axis() if v == 1 else
              replace(GazeCalibration.optical_axis(), p=pn[v], v=truth.primary_dir[v],
                      calibrated=True)).to_dict()}
              for v, n in enumerate(names)}  # fmt: skip
    (run / "cache" / "calibration").mkdir(parents=True)
    (run / "cache" / "calibration" / "calibration.json").write_text(json.dumps(stored))
    seen_offsets = []
    real_repair = sf.repair_joins

    def spy(*a, **k):
        seen_offsets.append((k.get("eye_offsets"), k.get("gaze_directions")))
        return real_repair(*a, **k)

    monkeypatch.setattr(sf, "repair_joins", spy)

    def detected(videos, cameras, interocular=None, **_):
        c = [cameras[n] for n in names]
        if interocular is None:
            return pipeline.VideoFaces(faces=reconstruct_faces(dets, c), names=tuple(names),
                                       detections=tuple(dets))  # fmt: skip
        sc, f3 = scale_from_faces(dets, c, interocular=interocular)
        return pipeline.VideoFaces(faces=f3, names=tuple(names), detections=tuple(dets),
                                   scale=sc)  # fmt: skip

    monkeypatch.setattr(pipeline, "faces_in_videos", detected)
    n_true = int(np.isfinite(reconstruct_faces(dets, cams).v[..., 0]).sum())
    found, report = pipeline.faces(run, plots=False, progress=False)
    pc = report["pose_check"]
    assert [r["wearers"] for r in pc["repaired"]] == [names[2:]], pc
    for got, want in zip(seen_offsets[-1], (pn, truth.primary_dir), strict=True):
        assert np.isnan(got[1]).all() and np.allclose(np.delete(got, 1, 0), np.delete(want, 1, 0))
    assert abs(pc["repaired"][0]["turn_deg"] + 35.0) < 0.5 and pc["repaired"][0]["refined_by_faces"]
    assert pc["wrong_pairs_before_repair"] and "warning" not in pc, pc
    dis = {p["name"]: p["ego_exo_disagreement_deg_median"] for p in report["people"]
           if p["wearer"]}  # fmt: skip
    assert max(dis.values()) < 8.0, dis
    assert report["repaired_run"]["moved"] == names[2:], report["repaired_run"]
    t2, g2 = pipeline.read_gaze_csv(run / "repaired" / "gaze.csv", names, opts.fps)
    assert np.allclose(t2, times)
    true_rays = rays(False)
    for v, n in enumerate(names):
        de = np.linalg.norm(g2[n][0] - true_rays[n][0], axis=1)
        da = np.degrees(np.arccos(np.clip((g2[n][1] * true_rays[n][1]).sum(1), -1, 1)))
        assert np.median(de) < (0.01 if v >= 2 else 1e-5) and np.median(da) < 0.3, (n, de, da)
    rows = (run / "repaired" / "charges.csv").read_text().splitlines()[1:]
    fixed_charges: list[list[SimpleNamespace]] = [[] for _ in times]
    for r in rows:
        c = r.split(",")
        fixed_charges[int(np.rint(float(c[0]) * opts.fps))].append(SimpleNamespace(
            position=np.array([float(x) for x in c[2:5]]),
            members=np.array([names.index(m) for m in c[6].split(";")])))  # fmt: skip
    ja_fixed, ja_bad = scored(fixed_charges), scored(bad_charges)
    assert ja_fixed < 0.03 and ja_bad > 0.05, (ja_fixed, ja_bad)
    assert (run / "repaired" / "poses.csv").is_file()
    n_fixed = int(np.isfinite(found.faces.v[..., 0]).sum())
    _, plain = pipeline.faces(run, plots=False, progress=False, repair=False)
    assert "warning" in plain["pose_check"] and "repaired" not in plain["pose_check"]
    assert "repaired_run" not in plain and not (run / "repaired").exists()  # not left stale
    n_plain = sum(p["instants"] for p in plain["people"])
    assert n_fixed >= 0.95 * n_true and n_plain < 0.8 * n_true, (n_fixed, n_plain, n_true)
    from socialcam.cli import main

    capsys.readouterr()
    assert main(["faces", str(run), "--no-plots"]) == 0
    out = capsys.readouterr()
    assert f"repaired a wrong join: {names[2]}, {names[3]} turned -35" in out.out, out.out
    assert "joint attention again with the repaired poses: repaired/" in out.out, out.out
    assert "warning" not in out.err, out.err
    # a map without a scale (units of 2 m): the faces' scale is measured again on the
    # repaired map and the cameras returned in metres
    unit = 2.0
    bad_map = [Cameras(c.K, c.R, c.C / unit, c.times) for c in bad]
    map_run = run_folder(tmp_path / "map", bad_map, float("nan"), unit)
    in_map = {n: {"summary": {}, "calibration": replace(GazeCalibration.optical_axis(),
              p=pn[v] / unit, calibrated=True).to_dict()} for v, n in enumerate(names)}  # fmt: skip
    (map_run / "cache" / "calibration").mkdir(parents=True)
    (map_run / "cache" / "calibration" / "calibration.json").write_text(json.dumps(in_map))
    found_m, rep_m = pipeline.faces(map_run, plots=False, progress=False,
                                    interocular=INTEROCULAR)  # fmt: skip
    assert [r["wearers"] for r in rep_m["pose_check"]["repaired"]] == [names[2:]]
    s = rep_m["scale"]["metres_per_unit"]
    assert np.allclose(seen_offsets[-1][0], pn, atol=2e-3), (seen_offsets[-1], pn)  # metres
    err = [float(np.median(np.linalg.norm(found_m.cameras[n].C - c.C, axis=1)))
           for n, c in zip(names, cams, strict=True)]  # fmt: skip
    assert abs(s / unit - 1) < 0.05 and max(err) < 0.1, (s, err)
    _, g_m = pipeline.read_gaze_csv(tmp_path / "map" / "repaired" / "gaze.csv", names, opts.fps)
    eye_err = [float(np.median(np.linalg.norm(g_m[n][0] * s - true_rays[n][0], axis=1)))
               for n in names]  # fmt: skip
    assert max(eye_err) < 0.1, eye_err


def test_repair_and_align_bad_input(circle8, tmp_path):
    from socialcam.faces import align_by_faces, repair_joins
    from socialcam.pipeline import read_gaze_csv

    dets, cams = circle8
    (tmp_path / "x.csv").write_text("time,track,x\n")
    with pytest.raises(ValueError, match=r"path: .* is not a gaze\.csv"):
        read_gaze_csv(tmp_path / "x.csv", ["a"], 10.0)
    (tmp_path / "g.csv").write_text("person,time,px,py,pz,vx,vy,vz,h\na,0.1,1,2,3,0,0,1\n")
    with pytest.raises(ValueError, match="line 2: 8 fields"):
        read_gaze_csv(tmp_path / "g.csv", ["a"], 10.0)
    head = "person,time,px,py,pz,vx,vy,vz,h\na,0.1,1,2,3,0,0,1,0.03\n"
    for row, why in (
        ("a,0.2,1,2,3,0,0,1,nan", "not finite"),
        ("a,0.2,1,2,3,0,5,0,0.03", "not a unit vector"),
        ("a,0.2,1,2,3,0,0,1,-1", "h = -1, must be > 0"),
    ):
        (tmp_path / "g.csv").write_text(head + row + "\n")
        with pytest.raises(ValueError, match=rf"path: .*g\.csv line 3: .*{why}"):
            read_gaze_csv(tmp_path / "g.csv", ["a"], 10.0)
    with pytest.raises(ValueError, match="ref, group"):
        align_by_faces(dets, cams, [0, 1], [1, 2])
    with pytest.raises(ValueError, match="cameras"):
        align_by_faces(dets, cams[:3], [0, 1], [2])
    with pytest.raises(ValueError, match="gate"):
        align_by_faces(dets, cams, [0, 1], [2, 3], gate=0.0)
    with pytest.raises(ValueError, match="min_points"):
        align_by_faces(dets, cams, [0, 1], [2, 3], min_points=1)
    with pytest.raises(ValueError, match="refine"):
        repair_joins(dets, cams, refine="yes")
    with pytest.raises(ValueError, match="cameras"):
        repair_joins(dets, cams[:3])
    with pytest.raises(ValueError, match="min_expected"):
        repair_joins(dets, cams, min_expected=0)
    with pytest.raises(ValueError, match="detections: expected a list"):
        repair_joins(None, None)
    with pytest.raises(ValueError, match=r"eye_offsets: expected numbers of shape \(4, 3\)"):
        repair_joins(dets, cams, eye_offsets="abc")
    with pytest.raises(ValueError, match="gaze_directions: expected numbers"):
        repair_joins(dets, cams, gaze_directions=[["a", "b", "c"]] * 4)
    with pytest.raises(ValueError, match=r"ref\[0\]: expected an integer"):
        align_by_faces(dets, cams, [0.5], [2, 3])
