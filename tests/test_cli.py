from __future__ import annotations

import json
import subprocess
import sys

import pytest

from socialcam.cli import main


def test_demo_writes_report_and_recovers_the_scene(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--no-plots"]) == 0
    report = json.loads((tmp_path / "report.json").read_text())
    tri = report["stages"]["triangulation"]
    assert tri["triangulated"] > 0.98 * tri["points"]
    assert tri["error_mm_median"] < 15.0
    assert tri["rms_px_refined_mean"] <= tri["rms_px_linear_mean"]
    assert abs(tri["similarity_to_truth"]["scale"] - 1) < 1e-2
    st = report["stages"]
    assert st["trajectory"]["error_mm_median"] < 15.0  # 1 px noise, real walking
    assert st["trajectory"]["relative_error_mean"] < 0.05
    assert st["social_charges"]["correct_count_fraction"] > 0.9
    assert st["social_charges"]["charge_error_cm_median"] < 20
    gf = st["gaze_field"]
    assert gf["leave_one_out_deg_median"] < gf["rbf_deg_median"]
    # Measured over seeds 0–7 with upright cameras: 36–115 mm (100.9 at seed 0); with the
    # 180°-rolled cameras of before seed 0 gave 46.8 mm: the thesis method's result moves
    # with the noise realisation (issue 12). A bound, not only finite.
    assert st["articulated"]["error_mm_median"] < 150.0
    # a body from 60 photos of the same walk with a second person in some (seeds 0-9:
    # 16.3-21.0 mm, the person right in 98-100 % of the photos, 83-100 % of the visible
    # swaps repaired, 0-3 pairs exchanged that were not swapped)
    b = st["bodies"]
    assert b["error_mm_median"] < 30.0 and b["person_found_fraction"] > 0.95
    assert b["photos_with_second_person"] > 0 and b["swaps_repaired"] >= 0.75 * b["swaps"] > 0
    assert b["false_repairs"] <= 0.1 * b["swaps"]
    # socialcam run on the shipped clips (4 wearers × 8 s): every stage, compared with the
    # truth. Their 2.4 s range-of-motion segments determine Eq 3.1 on every video frame (72
    # per segment, sfm.pose_segment): measured all 4 calibrated, v 0.04-0.30°, p 0.3-2.0 cm,
    # h ×1.04-1.15. At the 10 Hz output rate alone (24 poses, standard error of p 8-14 cm)
    # all 4 fell back to the optical axis. The truth holds 20 group-frames of joint
    # attention; measured 18 found, median 8.4 cm (optical axis: 20, median 20 cm).
    run = st["run"]
    assert run["posed_fraction"] > 0.85
    assert len(run["calibrated"]) >= 3 and run["v_error_deg_median"] < 0.5, run["calibrated"]
    assert run["joint_attention_groups"] >= 20
    assert run["joint_attention_found"] >= 0.8 * run["joint_attention_groups"]
    assert set(run["stage_seconds"]) == {"poses", "calibration", "gaze", "charges", "tracks",
                                         "field", "outputs"}  # fmt: skip
    for n, c in run["calibration_vs_truth"].items():
        if not c["calibrated"]:
            assert any(w.startswith(f"{n}: gaze along the camera's optical axis")
                       for w in run["warnings"])  # fmt: skip
    assert (tmp_path / "run" / "charges.csv").is_file()
    assert "report written" in capsys.readouterr().out


def test_demo_plots(tmp_path):
    stages = ["triangulation", "trajectory", "articulated", "bodies", "social_charges",
              "gaze_field"]  # fmt: skip
    main(["demo", "--out", str(tmp_path), *(a for s in stages for a in ("--stage", s))])
    for name in ("triangulation", "trajectory", "body", "saliency", "charge_tracks",
                 "gaze_field"):  # fmt: skip
        png = tmp_path / f"{name}.png"
        assert png.stat().st_size > 10_000
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_console_script_and_bad_arguments():
    out = subprocess.run(
        [sys.executable, "-m", "socialcam.cli", "--version"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert out.stdout.startswith("socialcam ")
    with pytest.raises(SystemExit):
        main(["demo", "--seed", "-3"])
    with pytest.raises(SystemExit):
        main(["demo", "--stage", "nope"])


def test_render_command_writes_videos_and_truth(tmp_path, capsys):
    out = tmp_path / "scene"
    args = ["render", str(out), "--wearers", "2", "--duration", "0.4", "--size", "96x64"]
    assert main([*args, "--seed", "3", "--fps", "15", "--distortion", "radial"]) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "truth.json",
        "truth.npz",
        "wearer0.mp4",
        "wearer1.mp4",
    ]
    truth = json.loads((out / "truth.json").read_text())
    assert truth["n_frames"] == [6, 6] and truth["dist"][0]["model"] == "radial"
    assert "wearer1.mp4" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["render", str(out), "--size", "big"])
    with pytest.raises(SystemExit):
        main(["render", str(out), "--wearers", "0"])


def test_same_lens_flag_reaches_poses_and_run(tmp_path, monkeypatch):
    """``--same-lens`` (one lens for wearers with the same camera model) is passed on by
    ``socialcam poses`` and ``socialcam run``; without it, each wearer has its own lens."""
    import socialcam.pipeline as pl

    seen = []

    def stop(*_a, **kw):
        seen.append(kw)
        raise ValueError("videos: stop here")

    monkeypatch.setattr(pl, "poses", stop)
    monkeypatch.setattr(pl, "run", stop)
    video = tmp_path / "a.mp4"
    video.write_bytes(b"")
    for cmd in ("poses", "run"):
        for flag, want in (([], False), (["--same-lens"], True)):
            assert main([cmd, str(video), "--out", str(tmp_path / "o"), *flag]) == 2
            assert seen[-1].get("same_lens", False) is want, (cmd, seen[-1])
