"""Face detection cost per frame at 1080p (the cost of socialcam.faces): eight shipped face
photographs (30–130 px) pasted into a 1920×1080 noise frame; CPU seconds per frame (the
machine may be loaded), with and without the stretched second pass for turned faces
(``detect_faces(turned=...)``). Association + triangulation + refinement cost ≈ 1 ms per instant
of 4 cameras (measured in the rendered-scene evaluation), far under 10 % of detection.

Run: python benches/bench_faces.py [n_frames]
"""

from __future__ import annotations

import sys
import time

import numpy as np

from socialcam.faces import detect_faces
from socialcam.synth.render import load_face_set


def main(n: int = 3) -> None:
    imgs, _ = load_face_set()
    rng = np.random.default_rng(0)
    frame = rng.integers(60, 200, (1080, 1920, 3)).astype(np.uint8)
    # eight faces of 30–130 px at random places
    import cv2

    for k in range(8):
        s = int(rng.uniform(30, 130))
        face = cv2.resize(imgs[k % len(imgs)], (s, int(s * 1.5)), interpolation=cv2.INTER_AREA)
        y, x = int(rng.uniform(0, 1080 - face.shape[0])), int(rng.uniform(0, 1920 - s))
        frame[y : y + face.shape[0], x : x + s] = face
    frames = np.stack([frame] * n)
    cost = {}
    for turned in (None, 1.5):  # the plain pass alone, and with the stretched second pass
        t0 = time.process_time()
        d = detect_faces(frames, turned=turned)
        cost[turned] = (time.process_time() - t0) / n
        print(
            f"detect_faces 1920x1080 turned={turned}: {cost[turned]:.3f} CPU s/frame, "
            f"{len(d) / n:.1f} faces/frame"
        )
    print(f"second pass costs {cost[1.5] / cost[None]:.2f}x the plain pass alone")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 3)
