"""Issue 13 held-out target of the social-charge rule on ``synth.marker_check_family``.

Per scene: fraction of frames with the right number of charges, mean error of the charges
against the markers divided by the mean error of the oracle intersection of the true
groups, and the scene's parameters (people, markers, h, closest marker pair); then both
targets per scene and pooled over the frames of each condition of the issue (people per
marker, i.e. mean group size; the room's longer side; ``h``).

    python benches/charges_heldout.py --seeds 100-119            # the held-out figures
    python benches/charges_heldout.py --seeds 0-29 --sequence     # development seeds
    python benches/charges_heldout.py --seeds 100-119 --set joint_window=False  # pooled rule only
"""

from __future__ import annotations

import argparse
import itertools
import time

import numpy as np

import socialcam as sc
from socialcam import synth


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b or a) + 1))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", default="0-29")
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--no-bounds", action="store_true")
    ap.add_argument("--set", action="append", default=[], help="option=value (Python literal)")
    args = ap.parse_args()
    over = {}
    for kv in args.set:
        k, _, val = kv.partition("=")
        over[k] = eval(val)
    rows = []
    conds: list[tuple[float, float, float, float, float]] = []
    for seed in _seeds(args.seeds):
        scene = synth.marker_check_family(seed, n_frames=args.frames)
        bounds = None if args.no_bounds else tuple(scene.room)
        t0 = time.process_time()
        charges = sc.find_charges_sequence(scene.ray_frames(), bounds=bounds, **over)
        cpu = time.process_time() - t0
        right, err, oerr = scene.charge_scores(charges)
        m = scene.targets[0]
        dmin = min(np.linalg.norm(m[a] - m[b]) for a in range(len(m)) for b in range(a))
        moving = not np.allclose(scene.targets[0], scene.targets[-1])
        rows.append((right, err / oerr))
        conds.append((scene.n_people / m.shape[0], max(scene.room[1][:2]), scene.h[0], err, oerr))
        print(f"seed {seed:3d}: P={scene.n_people:2d} T={m.shape[0]} h={scene.h[0]:.3f} "
              f"room={scene.room[1][0]:4.1f}x{scene.room[1][1]:4.1f} dmin={dmin:4.2f} "
              f"{'moving' if moving else 'static'}  right {right:.2f}  err/oracle "
              f"{err / oerr:5.2f} (oracle {100 * oerr:5.1f} cm)  cpu {cpu:.1f}s"
              + ("" if right >= 0.95 and err <= 1.25 * oerr else "   <- misses"))  # fmt: skip
    r = np.array(rows)
    print(
        f"right count: mean {r[:, 0].mean():.3f} median {np.median(r[:, 0]):.3f} "
        f"min {r[:, 0].min():.2f}; scenes >= 0.95: {(r[:, 0] >= 0.95).sum()}/{len(r)}"
    )
    print(
        f"error/oracle: mean {r[:, 1].mean():.3f} median {np.median(r[:, 1]):.3f} "
        f"max {r[:, 1].max():.2f}; scenes <= 1.25: {(r[:, 1] <= 1.25).sum()}/{len(r)}"
    )
    both = ((r[:, 0] >= 0.95) & (r[:, 1] <= 1.25)).sum()
    print(f"both targets: {both}/{len(r)}")
    _by_condition(r, np.array(conds))


def _by_condition(r: np.ndarray, c: np.ndarray) -> None:
    """The targets pooled over the frames of the scenes of one condition: people per
    marker (mean group size), the room's longer side and ``h``, three bins each."""
    bins = {
        "people/marker": (0, [2, 3, 4.5, 6.01]),
        "room side m": (1, [0, 10, 15, 20.01]),
        "h": (2, [0.01, 0.02, 0.045, 0.1001]),
    }
    for name, (col, edges) in bins.items():
        for lo, hi in itertools.pairwise(edges):
            sel = (c[:, col] >= lo) & (c[:, col] < hi)
            if not sel.any():
                continue
            right = r[sel, 0].mean()
            ratio = c[sel, 3].mean() / c[sel, 4].mean()
            print(f"  {name:13s} [{lo:5.3g}, {hi:5.3g}): {sel.sum():3d} scenes, right count "
                  f"{right:.3f} of frames, pooled error/oracle {ratio:.3f}")  # fmt: skip


if __name__ == "__main__":
    main()
