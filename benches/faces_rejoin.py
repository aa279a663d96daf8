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

Run: python benches/faces_rejoin.py OUT_DIR [seed ...] [turn=DEG ...] [repair=1]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from socialcam import Cameras
from socialcam.faces import rejoin_by_head_turns, repair_joins
from socialcam.synth.evaluate import truth_detections
from socialcam.synth.render import load_truth, render_scene


def _errors(cams, truth):
    """Median centre (mm) and orientation (deg) errors of cameras 2 and 3."""
    ce = [round(1e3 * float(np.median(np.linalg.norm(cams[v].C - truth[v].C, axis=1))))
          for v in (2, 3)]  # fmt: skip
    re = [round(float(np.degrees(np.median(Rotation.from_matrix(
        cams[v].R @ np.transpose(truth[v].R, (0, 2, 1))).magnitude()))), 2)
        for v in (2, 3)]  # fmt: skip
    return ce, re


def evaluate(out: Path, seed: int, turns: list[float], repair: bool = False) -> None:
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
            j = repair_joins(dets, bad)
            dt = time.perf_counter() - t0
            placed = [(g, round(float(np.degrees(a)), 1), ref, round(res, 2))
                      for g, a, _, ref, res in j.placed]  # fmt: skip
            coarse = repair_joins(dets, bad, refine=False)
            same = repair_joins(dets, cams)
            moved = [v for v in range(len(cams)) if same.cameras[v] is not cams[v]]
            moved_bad = [v for v in range(len(cams)) if j.cameras[v] is not bad[v]]
            print(f"{seed} turn {turn:+.0f}: groups ref {j.ref}, moved {moved_bad}, wrong before "
                  f"{list(j.wrong_before)} after {list(j.wrong_after)}, placed {placed}, "
                  f"unplaced {list(j.unplaced)}; cameras 2, 3 (mm, deg): "
                  f"{_errors(j.cameras, cams)}, head turns alone {_errors(coarse.cameras, cams)}"
                  f"; true poses: flagged {list(same.wrong_before)}, moved {moved} "
                  f"({dt:.2f} s)", flush=True)  # fmt: skip
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
    for seed in [int(a) for a in argv[1:] if "=" not in a] or [3]:
        evaluate(out, seed, turns, repair)


if __name__ == "__main__":
    main(sys.argv[1:])
