"""Smoke test of an installed socialcam wheel: import, then one call per thesis chapter.

Run from outside the repository (so the installed package is imported, not ./python) in a
virtual environment that has only the wheel and its dependencies: `.ci/run` does this.
"""

import numpy as np

import socialcam as sc
from socialcam import synth

assert not sc.__file__.startswith("python/"), sc.__file__
print("socialcam", sc.__version__, "from", sc.__file__)

# Geometry: multi-view triangulation (Sec 4.1).
cams = synth.ring_rig(4, seed=0)
X = synth.random_points(50, seed=1)
obs = synth.observe(X, cams, noise_px=0.0, seed=2)
Y = sc.triangulate(obs.x, cams)
assert np.nanmax(np.linalg.norm(Y - X, axis=1)) < 1e-6

# Ch. 5: the DCT trajectory basis is orthonormal on uniform samples, and a trajectory in
# its span is reconstructed exactly from random photographers.
B = sc.dct_basis(np.linspace(0.0, 1.0, 30), 5)
assert np.allclose(B.T @ B, np.eye(5), atol=1e-9)
photos = synth.random_photographers(40, seed=3)
theta = sc.dct_basis(photos.times, 4)
traj = theta @ np.random.default_rng(4).normal(scale=0.3, size=(4, 3)) + [0.0, 0.0, 1.0]
tr = sc.reconstruct_trajectory(photos.project_trajectory(traj), photos, k=4)
assert np.abs(tr.points - traj).max() < 1e-6, np.abs(tr.points - traj).max()

# Ch. 3: ego-motion gaze calibration recovers the gaze direction of a fixation segment.
seg = synth.fixation_segment(200, h=0.005, seed=5)
cal = sc.calibrate_gaze(seg.cameras)
assert np.degrees(np.arccos(np.clip(cal.v @ seg.direction, -1, 1))) < 1.0

# Ch. 4: exact binary quadratic programming agrees with enumeration on a small instance.
rng = np.random.default_rng(0)
Q = rng.normal(size=(8, 8))
Q = Q + Q.T
res = sc.solve_bqp(Q)
best = min(
    float(x @ Q @ x)
    for x in (np.array([(i >> k) & 1 for k in range(8)], dtype=float) for i in range(256))
)
xb = np.asarray(res.x, dtype=float)
assert abs(float(xb @ Q @ xb) - best) < 1e-9 * max(1.0, abs(best)), (res, best)

# Ch. 4: an articulated joint (a bone of known length from a known parent) from one
# photographer per frame, exact pixels: within 2 cm of the truth (3.9 mm measured; the
# motion is not exactly in the span of k = 4 cosines per angle).
par = np.c_[np.zeros(40), np.zeros(40), np.ones(40)]
ang = np.c_[np.sin(photos.times), 0.3 * np.cos(photos.times)]
child = (
    par
    + 0.4
    * np.c_[
        np.cos(ang[:, 0]) * np.cos(ang[:, 1]),
        np.sin(ang[:, 0]) * np.cos(ang[:, 1]),
        np.sin(ang[:, 1]),
    ]
)
art = sc.reconstruct_articulated(photos.project_trajectory(child), photos, par, 0.4, k=4)
assert np.abs(art.points - child).max() < 0.02, np.abs(art.points - child).max()

# Ch. 6 and 7: social charges and the gaze field on the simulated meeting.
scene = synth.meeting(seed=0)
frames = scene.ray_frames()[:20]
charges = sc.find_charges(frames[0])
assert len(charges) >= 1
field = sc.GazeField.fit(frames, times=scene.times[:20])
v = field.predict([[0.0, 0.0, 1.6]], t=float(scene.times[5]))
assert np.allclose(np.linalg.norm(v, axis=-1), 1.0)
print("wheel smoke test passed")
