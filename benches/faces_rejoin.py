"""``faces.rejoin_by_head_turns`` on rendered conversation circles (issue 11: SfM can join
two groups of wearers turned about the vertical; the faces' pose check flags it, this puts
them back): 4 wearers + 2 people, 8 s at 10 fps rendered at 320×240, detector-like
landmarks from the truth at 1280×960 scale (3 % of the face size noise), cameras 2 and 3
turned by TURN degrees about the circle's centre. Prints per seed and turn: the turn found
against the truth, the matches (face track, wearer, turn, spread in degrees, instants), the
moved cameras' median centre errors (mm), or ``None``.

With ``repair=1`` (session 38) the whole repair instead, as ``socialcam faces`` runs it
(``faces.repair_joins``): the groups found from the sightings (none given), placed by the head
turns, refined by the faces both sides see; per seed and turn the groups, what was placed
(turn, refined, residual in units of the landmark noise), the moved cameras' centre (mm) and
orientation (deg) errors before and after the refinement, and the same on the true poses
(which must stay where they are).

With ``attention=1`` as well (session 39) the wearers' joint attention from their ego gaze, as
``socialcam faces`` makes it again into ``repaired/``: the true primary gaze rays moved with
each camera (true poses, turned, repaired: ``JoinRepair.motion``), charges as ``socialcam run``
finds them (default options), scored against the truth (``synth.evaluate.joint_attention``):
median and p90 error (mm) and the fraction of the looking groups found.

With ``eyes=1`` as well (session 39) the repair also gets each wearer's eye centre in its
camera's frame as a gaze calibration gives it (``GazeCalibration.p``: the true eye offset
normal to the primary gaze, plus 1 cm of noise per coordinate, seeded by the circle), and the
head-turn placement alone is printed both without and with it (``cal``). ``gaze=1`` adds the
calibration's primary gaze direction (``GazeCalibration.v``: the true one plus 0.005 of noise
per coordinate, about 0.3°), which the head turns then follow instead of the optical axis.

Run: python benches/faces_rejoin.py OUT_DIR [seed ...] [turn=DEG ...] [repair=1 [attention=1] [eyes=1 [gaze=1]]]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from socialcam import Cameras
from socialcam.faces import rejoin_by_head_turns, repair_joins
from socialcam.pipeline import RunOptions, _find_charges, _frames
from socialcam.synth.evaluate import joint_attention, truth_detections
from socialcam.synth.render import load_truth, render_scene


def _errors(cams, truth):
    """Median centre (mm) and orientation (deg) errors of cameras 2 and 3."""
    ce = [round(1e3 * float(np.median(np.linalg.norm(cams[v].C - truth[v].C, axis=1))))
          for v in (2, 3)]  # fmt: skip
    re = [round(float(np.degrees(np.median(Rotation.from_matrix(
        cams[v].R @ np.transpose(truth[v].R, (0, 2, 1))).magnitude()))), 2)
        for v in (2, 3)]  # fmt: skip
    return ce, re


def _attention(truth, times, motion) -> str:
    """Joint attention of the wearers' true gaze rays moved by ``motion(v) -> (R, t)``."""
    names = list(truth.names)
    gaze = {}
    for v, n in enumerate(names):
        R, t = motion(v)
        gaze[n] = (truth.eyes[v] @ R.T + t, truth.gaze[v] @ R.T, np.full(len(times), truth.h[v]))
    r = joint_attention(truth, names, times, _find_charges(_frames(names, gaze), times,
                                                           RunOptions()))  # fmt: skip
    return (
        f"{1e3 * r['error_median_m']:.0f}/{1e3 * r['error_p90_m']:.0f} mm "
        f"found {r['found_fraction']:.2f}"
    )


def evaluate(
    out: Path,
    seed: int,
    turns: list[float],
    repair: bool = False,
    attention: bool = False,
    eyes: bool = False,
    gaze: bool = False,
) -> None:
    folder = out / f"circle{seed}_8s"
    if (folder / "truth.npz").exists():
        truth = load_truth(folder)
    else:
        truth = render_scene(folder, n_wearers=4, n_people=2, duration=8.0, fps=10.0,
                             size=(320, 240), seed=seed, faces=True, arrangement="circle",
                             audio=False, calibration=False, start_spread=0.0,
                             progress=False).truth  # fmt: skip
    dets, cams = truth_detections(truth, scale=4.0, seed=seed)
    centre = np.mean([c.C.mean(axis=0) for c in cams], axis=0)
    for turn in turns:
        R = Rotation.from_euler("z", turn, degrees=True).as_matrix()
        bad = [c if v < 2 else Cameras(c.K, c.R @ R.T, (c.C - centre) @ R.T + centre, c.times)
               for v, c in enumerate(cams)]  # fmt: skip
        t0 = time.perf_counter()
        if repair:
            offsets = None
            if eyes:
                rng = np.random.default_rng(seed)
                pn = np.array([o - o.dot(d) * d for o, d in zip(truth.eye_offset,
                               truth.primary_dir, strict=True)])  # fmt: skip
                offsets = pn + rng.normal(0.0, 0.01, pn.shape)
            directions = None
            if eyes and gaze:
                directions = truth.primary_dir + rng.normal(0.0, 0.005, (len(cams), 3))
            j = repair_joins(dets, bad, eye_offsets=offsets, gaze_directions=directions)
            dt = time.perf_counter() - t0
            placed = [(g, round(float(np.degrees(a)), 1), ref, round(res, 2))
                      for g, a, _, ref, res in j.placed]  # fmt: skip
            coarse = repair_joins(dets, bad, refine=False)
            cal = ""
            if eyes:
                c2 = repair_joins(dets, bad, refine=False, eye_offsets=offsets,
                                  gaze_directions=directions)  # fmt: skip
                cal = f", head turns alone with the calibration {_errors(c2.cameras, cams)}"
            same = repair_joins(dets, cams)
            moved = [v for v in range(len(cams)) if same.cameras[v] is not cams[v]]
            moved_bad = [v for v in range(len(cams)) if j.cameras[v] is not bad[v]]
            print(f"{seed} turn {turn:+.0f}: groups ref {j.ref}, moved {moved_bad}, wrong before "
                  f"{list(j.wrong_before)} after {list(j.wrong_after)}, placed {placed}, "
                  f"unplaced {list(j.unplaced)}; cameras 2, 3 (mm, deg): "
                  f"{_errors(j.cameras, cams)}, head turns alone {_errors(coarse.cameras, cams)}"
                  f"{cal}"
                  f"; true poses: flagged {list(same.wrong_before)}, moved {moved} "
                  f"({dt:.2f} s)", flush=True)  # fmt: skip
            if attention:
                times = cams[0].times

                def turned(v, R=R):
                    return (np.eye(3), np.zeros(3)) if v < 2 else (R, centre - R @ centre)

                def fixed(v, j=j, turned=turned):
                    (A, a), (B, b) = j.motion(v), turned(v)
                    return A @ B, A @ b + a

                print(f"   ego joint attention (median/p90): true poses "
                      f"{_attention(truth, times, lambda v: (np.eye(3), np.zeros(3)))}, turned "
                      f"{_attention(truth, times, turned)}, repaired "
                      f"{_attention(truth, times, fixed)}", flush=True)  # fmt: skip
            continue
        r = rejoin_by_head_turns(dets, bad, [0, 1], [2, 3])
        dt = time.perf_counter() - t0
        if r is None:
            print(f"{seed} turn {turn:+.0f}: None ({dt:.2f} s)", flush=True)
            continue
        cerr = [round(1e3 * float(np.median(np.linalg.norm(r.cameras[v].C - cams[v].C, axis=1))))
                for v in (2, 3)]  # fmt: skip
        m = [(k, j, round(float(np.degrees(a)), 1), round(float(np.degrees(s)), 1), n)
             for k, j, a, s, n in r.matches]  # fmt: skip
        print(f"{seed} turn {turn:+.0f}: found {np.degrees(r.turn):+.1f} (error "
              f"{np.degrees(r.turn) + turn:+.1f} deg), matches {m}, centres of 2 and 3 {cerr} mm "
              f"({dt:.2f} s)", flush=True)  # fmt: skip


def main(argv: list[str]) -> None:
    out = Path(argv[0])
    turns = [float(a.split("=", 1)[1]) for a in argv[1:] if a.startswith("turn=")] or [35.0]
    repair = any(a == "repair=1" for a in argv[1:])
    attention = any(a == "attention=1" for a in argv[1:])
    eyes = any(a == "eyes=1" for a in argv[1:])
    gaze = any(a == "gaze=1" for a in argv[1:])
    for seed in [int(a) for a in argv[1:] if "=" not in a] or [3]:
        evaluate(out, seed, turns, repair, attention, eyes, gaze)


if __name__ == "__main__":
    main(sys.argv[1:])
