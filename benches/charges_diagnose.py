"""Search or model? The joint window's objective on ``synth.marker_check_family`` scenes.

Per scene: the objective (log likelihood minus the sources' Occam costs, nats) of the
assignment ``find_charges_sequence`` finds, of the true groups (groups of fewer than
``min_members`` people as none) with their positions fitted from nothing, and of the
search started from the true groups. Found below searched-from-the-truth: the search
missed a better assignment (a search failure); the truth above both where the count is
wrong: the model prefers the wrong answer.

    python benches/charges_diagnose.py --seeds 1473,115
"""

from __future__ import annotations

import argparse

import numpy as np
from charges_heldout import _seeds

from socialcam import _core, synth
from socialcam.charges import ChargeOptions, _options


def true_groups(scene: synth.SocialScene, min_members: int) -> np.ndarray:
    """(F, P) each person's true group, -1 where the group has fewer than ``min_members``."""
    g = scene.group.copy()
    for f in range(g.shape[0]):
        for t in np.unique(g[f]):
            if t >= 0 and (g[f] == t).sum() < min_members:
                g[f][g[f] == t] = -1
    return g


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", default="1473")
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--set", action="append", default=[], help="option=value (Python literal)")
    args = ap.parse_args()
    over = {k: eval(v) for k, _, v in (kv.partition("=") for kv in args.set)}
    for seed in _seeds(args.seeds):
        scene = synth.marker_check_family(seed, n_frames=args.frames)
        opts: ChargeOptions = _options(None, {"bounds": tuple(scene.room), **over})
        frames = scene.ray_frames()
        counts = np.array([len(f) for f in frames], dtype=np.int64)
        found, truth, searched = _core.diagnose_window(
            np.concatenate([f.p for f in frames]),
            np.concatenate([f.v for f in frames]),
            np.concatenate([f.h for f in frames]),
            np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
            0,
            opts,
            true_groups(scene, opts.min_members).reshape(-1).astype(np.int64),
            ids=np.concatenate([f.ids for f in frames]),
        )
        print(
            f"seed {seed}: found {found:.1f}  truth refitted {truth:.1f}  "
            f"searched from the truth {searched:.1f}  (search gap {searched - found:.1f})"
        )


if __name__ == "__main__":
    main()
