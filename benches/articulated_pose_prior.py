"""Is a pose prior new evidence against the impostor (issue 12)? A diagnosis on the BVH clips.

The robust method's wrong picks (relative error > 0.2 on ``benches/articulated_accuracy.py``'s
windows) fit the pixels, Eq 4.12 and the least-motion score as well as the truth (sessions
16-22). This asks whether they leave the range of poses a body takes. Per joint, the prior is
the set of the bone's unit directions in a local frame at its parent, over every frame of the
OTHER trial's clips (CMU 131_01* windows are judged by 131_02*'s frames and the reverse): axis 1
along the parent's bone (grandparent → parent; for the hips' children the body's up, hips →
chest), axis 2 the body's forward (left hip − right hip) × up made orthogonal to it. A
trajectory's distance to the prior is the 90th percentile over its frames of the angle to the
nearest prior direction.

Printed per condition (Fig 4.3(c) and exact length and root, as the accuracy bench):
1. how many wrong picks, right picks (error < 0.1) and true trajectories lie beyond ``tau``
   degrees of the prior, and which joints the wrong picks are;
2. a prototype of using it: where the chosen trajectory lies beyond ``tau``, its mirror (each
   frame's point moved to the other root of its viewing ray on the given parent's sphere) is
   taken if it lies at least 5° nearer the prior; mean / median error per window set, main →
   this, and how many switches helped or hurt by more than 0.05.
The local frames are built from the TRUE skeleton (the parent's and grandparent's truth, the
true hips and chest): an upper bound on what frames from reconstructed joints would give;
``--noisy-frames`` builds them from every joint off by a smooth offset of the condition's root
error, as a reconstructed skeleton would be. The
C3D clip (85_02: markers, no anatomy) keeps main's pick.
Run: python benches/articulated_pose_prior.py [--parts dev,held-out,...] [--seeds 0,1,2]
[--noisy-frames]
"""

from __future__ import annotations

import argparse
from collections import Counter

import numpy as np
from articulated_accuracy import (
    MOCAP,
    all_windows,
    bone,
    load_clips,
    observed,
    reconstruct,
    smooth_offset,
)

import socialcam as sc
from socialcam.mocap import load_bvh

LEFT_HIP, RIGHT_HIP, HIPS, CHEST = 1, 5, 0, 9  # Skeleton.from_bvh joints of the CMU 131 clips
TAUS = (15.0, 20.0, 25.0)
CONDITIONS = {
    "4.3(c)": {"noise": 1.0, "root": 0.05, "scale": 1.05, "missing": 0.05},
    "exact": {"noise": 0.5, "root": 0.0, "scale": 1.0, "missing": 0.0},
}


def local_directions(P: np.ndarray, j: int, p: int, g: int | None, X: np.ndarray) -> np.ndarray:
    """``(F, 3)`` unit directions from the true parent ``P[:, p]`` to ``X`` in the local frame
    at the parent (see the module docstring); ``g`` the grandparent or ``None``."""
    lat = P[:, LEFT_HIP] - P[:, RIGHT_HIP]
    up = P[:, CHEST] - P[:, HIPS]
    fwd = np.cross(lat, up)
    fwd /= np.linalg.norm(fwd, axis=1, keepdims=True)
    e1 = up if g is None else P[:, p] - P[:, g]
    e1 = e1 / np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = fwd - (fwd * e1).sum(1, keepdims=True) * e1
    e2 /= np.linalg.norm(e2, axis=1, keepdims=True)
    e3 = np.cross(e1, e2)
    u = X - P[:, p]
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return np.stack([(u * e1).sum(1), (u * e2).sum(1), (u * e3).sum(1)], axis=1)


def distance(L: np.ndarray, prior: np.ndarray) -> float:
    """90th percentile over frames of the angle (degrees) to the nearest prior direction."""
    near = np.clip(L @ prior.T, -1.0, 1.0).max(axis=1)
    return float(np.percentile(np.degrees(np.arccos(near)), 90))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--parts", default="dev,held-out,new,fresh,lowrate")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument(
        "--noisy-frames",
        action="store_true",
        help="build the local frames from joints each off by the condition's root error",
    )
    args = ap.parse_args()
    parts = args.parts.split(",")
    seeds = [int(s) for s in args.seeds.split(",")]
    clips = load_clips()
    names = sc.Skeleton.from_bvh(load_bvh(MOCAP / "cmu_131_01_walk300.bvh"))[0].names
    priors: dict[tuple[str, int], list[np.ndarray]] = {}
    for clip, (P, pairs) in clips.items():
        if clip == "85_02":
            continue
        par = dict(pairs)
        for j, p in pairs:
            L = local_directions(P, j, p, par.get(p), P[:, j])
            priors.setdefault((clip[:6], j), []).append(L)
    prior = {k: np.concatenate(v) for k, v in priors.items()}
    wins = [(pt, w) for pt, w in all_windows(clips) if pt in parts]
    for cname, kw in CONDITIONS.items():
        rows = []
        for s in seeds:
            for pt, w in wins:
                par = dict(w.pairs)
                for j, p in w.pairs:
                    if w.eta[j] <= 1.25:
                        continue
                    F = w.P.shape[0]
                    x, rng = observed(w, j, kw["noise"], kw["missing"], s)
                    parent = w.P[:, p] + smooth_offset(F, kw["root"] * bone(w, j, p), rng)
                    X = reconstruct(w, j, p, x, parent, method="robust", seed=s, **{
                        k: kw[k] for k in ("noise", "scale", "missing")})  # fmt: skip
                    length = np.linalg.norm(w.P[:, j] - w.P[:, p])
                    row = {"part": pt, "j": j, "bvh": w.clip != "85_02",
                           "err": float(np.linalg.norm(X - w.P[:, j]) / length)}  # fmt: skip
                    if row["bvh"]:
                        C = w.cams.C
                        r = (X - C) / np.linalg.norm(X - C, axis=1, keepdims=True)
                        s0, s1 = ((parent - C) * r).sum(1), ((X - C) * r).sum(1)
                        M = C + (2 * s0 - s1)[:, None] * r  # the other root of each ray
                        T = prior[("131_02" if w.clip.startswith("131_01") else "131_01", j)]
                        g = par.get(p)
                        Pf = w.P
                        if args.noisy_frames:  # every joint of the frame off like the parent
                            frng = np.random.default_rng([s, j, 99])
                            Pf = w.P + np.stack([smooth_offset(F, kw["root"] * length.mean(), frng)
                                                 for _ in range(w.P.shape[1])], axis=1)  # fmt: skip
                        row["d"] = distance(local_directions(Pf, j, p, g, Pf[:, p] + X - parent), T)
                        row["d_true"] = distance(local_directions(w.P, j, p, g, w.P[:, j]), T)
                        row["d_mirror"] = distance(
                            local_directions(Pf, j, p, g, Pf[:, p] + M - parent), T
                        )
                        row["err_mirror"] = float(np.linalg.norm(M - w.P[:, j]) / length)
                    rows.append(row)
        b = [r for r in rows if r["bvh"]]
        wrong = [r for r in b if r["err"] > 0.2]
        right = [r for r in b if r["err"] < 0.1]
        print(f"\n{cname}, seeds {args.seeds}, BVH joint-windows {len(b)}: wrong picks {len(wrong)} "
              f"(their share of the summed error {sum(r['err'] for r in wrong) / sum(r['err'] for r in b):.2f}), "
              f"right {len(right)}")  # fmt: skip
        print("  wrong picks by joint:", ", ".join(f"{names[j]} {n}" for j, n in
                                                   Counter(r["j"] for r in wrong).most_common()))  # fmt: skip
        for tau in (10.0, *TAUS, 30.0):
            print(f"  beyond {tau:4.1f} deg of the prior: wrong {sum(r['d'] > tau for r in wrong):3d}/"
                  f"{len(wrong)}, right {sum(r['d'] > tau for r in right):3d}/{len(right)}, "
                  f"truth {sum(r['d_true'] > tau for r in b):3d}/{len(b)}")  # fmt: skip
        for pt in parts:
            sel = [r for r in rows if r["part"] == pt]
            e = np.array([r["err"] for r in sel])
            line = f"  {pt:8s} n {len(sel):3d} main {e.mean():.3f} / {np.median(e):.3f}"
            for tau in TAUS:
                new = [r["err_mirror"] if r["bvh"] and r["d"] > tau and r["d_mirror"] < r["d"] - 5
                       else r["err"] for r in sel]  # fmt: skip
                gain = sum(1 for r, n in zip(sel, new, strict=True) if n < r["err"] - 0.05)
                loss = sum(1 for r, n in zip(sel, new, strict=True) if n > r["err"] + 0.05)
                line += (
                    f" | tau {tau:.0f}: {np.mean(new):.3f} / {np.median(new):.3f} (+{gain} -{loss})"
                )
            print(line, flush=True)


if __name__ == "__main__":
    main()
