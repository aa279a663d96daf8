"""Batched triangulation: socialcam against a vectorised numpy implementation of the same
algorithm (DLT on normalised coordinates + Levenberg–Marquardt on reprojection error), on
the same scene in one run. Prints times, agreement and the speed ratio.

    python benches/bench_triangulation.py [--points 100000] [--views 4]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import socialcam as sc
from socialcam import synth


def numpy_triangulate(
    x: np.ndarray, K: np.ndarray, R: np.ndarray, C: np.ndarray, iters: int = 20
) -> np.ndarray:
    """Reference: x (N,V,2) → (N,3), every point seen in every view."""
    n, v, _ = x.shape
    Kinv = np.linalg.inv(K)
    m = np.einsum("vij,nvj->nvi", Kinv, np.concatenate([x, np.ones((n, v, 1))], axis=2))
    mu = C.mean(axis=0)
    s = np.linalg.norm(C - mu, axis=1).mean()
    Cn = (C - mu) / s
    A = np.empty((n, 2 * v, 4))
    for j in range(v):
        for row, coord in ((0, m[:, j, 0]), (1, m[:, j, 1])):
            a = coord[:, None] * R[j, 2][None] - R[j, row][None]
            A[:, 2 * j + row, :3] = a
            A[:, 2 * j + row, 3] = -a @ Cn[j]
    _, _, vt = np.linalg.svd(A, full_matrices=False)
    h = vt[:, -1]
    X = h[:, :3] / h[:, 3:] * s + mu
    KR = K @ R  # (V,3,3)

    def residuals_and_jacobian(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        hX = np.einsum("vij,nvj->nvi", KR, X[:, None, :] - C[None])  # (N,V,3)
        p = hX[..., :2] / hX[..., 2:]
        r = (p - x).reshape(n, 2 * v)
        J = (KR[None, :, :2, :] - p[..., :, None] * KR[None, :, 2:3, :]) / hX[..., 2:3, None]
        return r, J.reshape(n, 2 * v, 3)

    lam = np.full(n, 1e-3)
    r, J = residuals_and_jacobian(X)
    cost = (r**2).sum(axis=1)
    for _ in range(iters):
        JtJ = np.einsum("nki,nkj->nij", J, J)
        Jtr = np.einsum("nki,nk->ni", J, r)
        A_ = JtJ + lam[:, None, None] * JtJ * np.eye(3)[None]
        step = -np.linalg.solve(A_, Jtr[..., None])[..., 0]
        Xn = X + step
        rn, Jn = residuals_and_jacobian(Xn)
        cn = (rn**2).sum(axis=1)
        ok = cn <= cost
        X[ok], r[ok], J[ok], cost[ok] = Xn[ok], rn[ok], Jn[ok], cn[ok]
        lam = np.where(ok, lam * 0.3, lam * 10)
    return X


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--points", type=int, default=100_000)
    ap.add_argument("--views", type=int, default=4)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    scene = synth.multiview_scene(args.points, args.views, noise_px=1.0, seed=0)
    cams, x = scene.cameras, scene.obs.x

    def best(fn):
        times, out = [], None
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            out = fn()
            times.append(time.perf_counter() - t0)
        return min(times), out

    t_sc, X_sc = best(lambda: sc.triangulate(x, cams))
    t_np, X_np = best(lambda: numpy_triangulate(x, cams.K, cams.R, cams.C))
    diff = np.linalg.norm(X_sc - X_np, axis=1)
    err = np.linalg.norm(X_sc - scene.obs.points, axis=1)
    print(f"batched triangulation, {args.points} points x {args.views} views, 1 px noise, DLT + LM")
    print(f"  socialcam : {t_sc * 1e3:9.1f} ms   (median 3D error {np.median(err) * 1e3:.2f} mm)")
    print(f"  numpy     : {t_np * 1e3:9.1f} ms")
    print(f"  agreement : max |X_sc - X_np| = {diff.max():.2e} m (median {np.median(diff):.1e})")
    assert diff.max() < 1e-6, "implementations disagree"
    print(f"  ratio     : socialcam is {t_np / t_sc:.1f}x faster")


if __name__ == "__main__":
    main()
