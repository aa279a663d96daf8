"""Bodies from photo collections: where the time goes (issue 11: "detection is the cost ...
keep association + refinement under 10 % of the total").

Detection: MediaPipe Pose (``bodies.detect_body_joints``, full model) on a 1920×1080 photo
(the shipped real photograph of a person, 256×300, scaled to 600 px tall and pasted into a
noise frame), CPU seconds per photo, from arrays and from JPEG files (decoding included, as
``reconstruct_body_from_photos`` reads them). Reconstruction: ``bodies.reconstruct_body`` on
simulated collections of the shipped walk (``synth.photos``: 3 px noise, misses, swaps, a
second person) of 60 and 270 photos (seed 0), with and without the ray fusion. Prints each
one's CPU seconds per photo and the reconstruction's share of detection + reconstruction.

Run: python benches/bench_bodies.py [n_photos_detected]
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main(n: int = 5) -> None:
    import cv2
    from PIL import Image

    from socialcam.bodies import detect_body_joints, reconstruct_body
    from socialcam.data import sample_bvh
    from socialcam.mocap import load_bvh
    from socialcam.synth.photos import BODY_PAIRS, photo_collection

    img = np.asarray(Image.open(Path(__file__).parent.parent / "tests/data/grace_hopper_256.jpg"))
    rng = np.random.default_rng(0)
    frame = rng.integers(60, 200, (1080, 1920, 3)).astype(np.uint8)
    person = cv2.resize(img, (512, 600), interpolation=cv2.INTER_CUBIC)
    frame[300:900, 700:1212] = person
    photos = [frame] * n
    detect_body_joints(photos[:1])  # the model's first load, not counted
    t0 = time.process_time()
    found = detect_body_joints(photos)
    per_photo = (time.process_time() - t0) / n
    seen = sum(len(d) for d in found)
    print(f"detect_body_joints 1920x1080 arrays: {per_photo:.3f} CPU s/photo ({seen} of {n} found)")
    with tempfile.TemporaryDirectory() as tmp:  # as reconstruct_body_from_photos: JPEG files
        files = [Path(tmp) / f"p{i}.jpg" for i in range(n)]
        for f in files:
            Image.fromarray(frame).save(f, quality=90)
        t0 = time.process_time()
        detect_body_joints(files)
        from_files = (time.process_time() - t0) / n
    print(
        f"detect_body_joints 1920x1080 JPEG files: {from_files:.3f} CPU s/photo (decoding included)"
    )
    m = load_bvh(sample_bvh())
    for count in (60, 270):
        pc = photo_collection(m.positions, m.names, m.fps, other=m.positions[::-1],
                              n_photos=count, seed=0)  # fmt: skip
        for fuse in (False, True):
            t0 = time.process_time()
            reconstruct_body(pc.detections, pc.cameras, BODY_PAIRS, fuse_rays=fuse)
            rec = (time.process_time() - t0) / count
            print(
                f"reconstruct_body {count} photos fuse_rays={fuse}: {rec * 1e3:.1f} CPU ms/photo, "
                f"{100 * rec / (rec + per_photo):.1f} % of detection + reconstruction "
                f"({100 * rec / (rec + from_files):.1f} % from JPEG files)"
            )


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:2]))
