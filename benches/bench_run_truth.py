"""``socialcam run``'s middle stages (calibration → gaze rays → social charges) on the TRUE
cameras of many rendered scenes (issue 10): joint attention found per scene, without the
cost of drawing the videos and running SfM, so that many unseen seeds can be checked.

For every seed: the renderer's motion and truth of 4 wearers × 20 s (no frames encoded),
the true camera poses, the rendered range-of-motion segments for Eq 3.1, then
:func:`socialcam.pipeline.gaze_and_charges` with the run defaults (or ``--option``), scored
by :func:`socialcam.synth.evaluate.joint_attention`: the fraction of (frame, group) pairs —
≥ 2 wearers looking at one target for ≥ 0.6 s — with a charge of ≥ 2 of them within 0.5 m
of the target (issue target ≥ 90 % per scene), the median error and the false fraction.
The same stages through SfM poses: ``benches/bench_run.py``.

Usage: ``python benches/bench_run_truth.py 17 18 ... [--option member_sigma=3.5]``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from bench_run import parse_options

from socialcam.pipeline import RunWarning, gaze_and_charges
from socialcam.synth.evaluate import joint_attention, truth_segments

# the renderer's truth without encoding videos: the helper of the true-camera tests
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from test_run_rendered_truth import _truth_only


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("seeds", type=int, nargs="+")
    ap.add_argument(
        "--option", action="append", default=[], help="a RunOptions field, KEY=VALUE (repeatable)"
    )
    args = ap.parse_args()
    extra = parse_options(args.option)
    print(f"options: {extra or 'run defaults'}")
    print(f"{'seed':>5} {'found':>9} {'fraction':>8} {'median m':>8} {'false':>6} {'s':>5}")
    found = groups = 0
    fractions = []
    for seed in args.seeds:
        t0 = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
            warnings.simplefilter("ignore", RunWarning)
            truth = _truth_only(Path(tmp), seed)
            names = list(truth.names)
            cams = {n: truth.cameras(i) for i, n in enumerate(names)}
            _cals, times, _frames, charges = gaze_and_charges(
                cams, names, calibration=truth_segments(truth), **extra
            )
        ja = joint_attention(truth, names, times, charges)
        found += ja["found"]
        groups += ja["groups"]
        fractions.append(ja["found_fraction"])
        print(
            f"{seed:>5} {ja['found']:>4}/{ja['groups']:<4} {ja['found_fraction']:>8.3f} "
            f"{ja['error_median_m']:>8.3f} {ja['false_fraction']:>6.2f} "
            f"{time.perf_counter() - t0:>5.1f}"
        )
    f = np.array(fractions, dtype=float)
    print(
        f"pooled {found}/{groups} = {found / max(groups, 1):.3f}; per scene min "
        f"{np.nanmin(f):.3f}, median {np.nanmedian(f):.3f}; scenes below 0.90: "
        f"{[s for s, x in zip(args.seeds, f, strict=True) if x < 0.9]}"
    )


if __name__ == "__main__":
    main()
