"""``socialcam run``'s middle stages (calibration → gaze rays → social charges) on the TRUE
cameras of many rendered scenes (issue 10): joint attention found per scene, without the
cost of drawing the videos and running SfM, so that many unseen seeds can be checked.

For every seed: the renderer's motion and truth of 4 wearers × 20 s (no frames encoded),
the true camera poses, the rendered range-of-motion segments for Eq 3.1, then
:func:`socialcam.pipeline.gaze_and_charges` with the run defaults (or ``--option``), scored
by :func:`socialcam.synth.evaluate.joint_attention`: the fraction of (frame, group) pairs —
≥ 2 wearers looking at one target for ≥ 0.6 s — with a charge of ≥ 2 of them within 0.5 m
of the target (issue target ≥ 90 % per scene), the median error and the false fraction.

``--oracle`` adds the same score for an oracle that knows who looks at what: in each
frame, each true group's rays (the calibrated rays the charge stage gets) intersected at
their most likely point (:func:`socialcam.pipeline._motion_point` at lag 0, the perspective
distance of Eq 6.2). Where it falls below 90 %, the rays themselves do not meet within
0.5 m of the target: no membership rule can find those frames from one frame's rays.
The same stages through SfM poses: ``benches/bench_run.py``.

Usage: ``python benches/bench_run_truth.py 17 18 65-96 [--option member_sigma=3.5]
[--cache DIR]``. With ``--cache`` each seed's truth (1.1-1.3 s CPU to draw) and gaze frames
are kept in ``DIR``: a rerun that changes only charge-stage options
(``pipeline.CHARGE_STAGE_OPTIONS``) replays the charge stage alone.
"""

from __future__ import annotations

import argparse
import hashlib
import pickle
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from bench_run import parse_options

from socialcam.pipeline import (
    CHARGE_STAGE_OPTIONS,
    RunOptions,
    RunWarning,
    _find_charges,
    _gaze_frames,
    _made_charge,
    _motion_point,
)
from socialcam.synth.evaluate import joint_attention, looking_groups, truth_segments

# the renderer's truth without encoding videos: the helper of the true-camera tests
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from test_run_rendered_truth import _truth_only


def _seeds(words: list[str]) -> list[int]:
    out: list[int] = []
    for w in words:
        a, _, b = w.partition("-")
        out += list(range(int(a), int(b or a) + 1))
    return out


def _cached(path: Path | None, make):  # type: ignore[no-untyped-def]
    if path is not None and path.exists():
        return pickle.loads(path.read_bytes())
    value = make()
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_bytes(pickle.dumps(value))
        tmp.replace(path)
    return value


def _truth(seed: int):  # type: ignore[no-untyped-def]
    with tempfile.TemporaryDirectory() as tmp:
        return _truth_only(Path(tmp), seed)


def _oracle(truth, names, times, frames):  # type: ignore[no-untyped-def]
    """Charges at the most likely intersection of each true group's rays, per frame."""
    out = []
    for k, groups in enumerate(looking_groups(truth, names, times)):
        f, made = frames[k], []
        for members in (np.asarray(m) for m, _ in groups):
            sel = np.isin(f.ids, members) if f is not None else np.zeros(0, bool)
            if sel.sum() < 2:
                continue
            p, v, h = f.p[sel], f.v[sel], f.h[sel]
            proj = np.eye(3)[None] - v[:, :, None] * v[:, None, :]
            start = np.linalg.lstsq(proj.sum(0), np.einsum("ijk,ik->j", proj, p), rcond=None)[0]
            x = _motion_point(p, v, h, np.zeros(len(p)), 1.0, start)
            if x is not None:
                made.append(_made_charge(f, f.ids[sel], x, k))
        out.append(made)
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("seeds", nargs="+", help="seeds or ranges (17 18 65-96)")
    ap.add_argument(
        "--option", action="append", default=[], help="a RunOptions field, KEY=VALUE (repeatable)"
    )
    ap.add_argument("--cache", type=Path, help="folder for each seed's truth and gaze frames")
    ap.add_argument("--oracle", action="store_true", help="also score the true groups' rays")
    args = ap.parse_args()
    seeds = _seeds(args.seeds)
    extra = parse_options(args.option)
    opts = RunOptions(**extra)
    # the gaze frames depend on every option the charge stage does not read
    pre = {k: v for k, v in vars(opts).items() if k not in CHARGE_STAGE_OPTIONS}
    tag = hashlib.sha256(repr(sorted(pre.items())).encode()).hexdigest()[:12]
    print(f"options: {extra or 'run defaults'}")
    print(
        f"{'seed':>5} {'found':>9} {'fraction':>8} {'median m':>8} {'false':>6} {'s':>5}"
        + (f" {'oracle':>9}" if args.oracle else "")
    )
    found = groups = o_found = 0
    fractions, o_fractions = [], []
    cpu = 0.0
    for seed in seeds:
        t0 = time.perf_counter()
        c0 = time.process_time()
        cache = args.cache
        truth = _cached(cache and cache / f"truth_{seed}.pkl", lambda s=seed: _truth(s))
        names = list(truth.names)
        cams = {n: truth.cameras(i) for i, n in enumerate(names)}

        def frames_of(truth=truth, names=names, cams=cams):  # type: ignore[no-untyped-def]
            return _gaze_frames(cams, names, truth_segments(truth), None, opts)[1:]

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RunWarning)
            times, frames = _cached(cache and cache / f"frames_{seed}_{tag}.pkl", frames_of)
            charges = _find_charges(frames, times, opts)
        cpu += time.process_time() - c0
        ja = joint_attention(truth, names, times, charges)
        found += ja["found"]
        groups += ja["groups"]
        fractions.append(ja["found_fraction"])
        line = (
            f"{seed:>5} {ja['found']:>4}/{ja['groups']:<4} {ja['found_fraction']:>8.3f} "
            f"{ja['error_median_m']:>8.3f} {ja['false_fraction']:>6.2f} "
            f"{time.perf_counter() - t0:>5.1f}"
        )
        if args.oracle:
            jo = joint_attention(truth, names, times, _oracle(truth, names, times, frames))
            o_found += jo["found"]
            o_fractions.append(jo["found_fraction"])
            line += f" {jo['found']:>4}/{jo['groups']:<4}"
        print(line)
    f = np.array(fractions, dtype=float)
    print(
        f"pooled {found}/{groups} = {found / max(groups, 1):.3f}; per scene min "
        f"{np.nanmin(f):.3f}, median {np.nanmedian(f):.3f}; scenes below 0.90: "
        f"{[s for s, x in zip(seeds, f, strict=True) if x < 0.9]}; CPU {cpu:.1f} s"
    )
    if args.oracle:
        o = np.array(o_fractions, dtype=float)
        print(
            f"oracle (true groups' rays intersected per frame) {o_found}/{groups} = "
            f"{o_found / max(groups, 1):.3f}; scenes below 0.90: "
            f"{[s for s, x in zip(seeds, o, strict=True) if x < 0.9]}"
        )


if __name__ == "__main__":
    main()
