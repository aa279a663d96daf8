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
    assert "report written" in capsys.readouterr().out


def test_demo_plots(tmp_path):
    main(["demo", "--out", str(tmp_path)])
    png = tmp_path / "triangulation.png"
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
