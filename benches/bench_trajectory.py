"""Trajectory reconstruction (thesis Chapter 5): socialcam against a straightforward
numpy/scipy implementation of the same algorithm written here — per point, N-fold cross
validation of K with ``numpy.linalg.lstsq`` (Eq 5.7–5.8), then Levenberg–Marquardt on the
reprojection error with ``scipy.optimize.least_squares(method="lm")`` and the analytic
Jacobian (Eq 5.9). Same scene, same run; prints times, agreement and the speed ratio.

The reference is run on a subset of the points (``--ref-points``) and its time scaled to
the full set, which is stated in the output.

    python benches/bench_trajectory.py [--points 10000] [--frames 200] [--k-max 30]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.optimize import least_squares

import socialcam as sc
from socialcam import synth


def dct_rows(times: np.ndarray, k: int) -> np.ndarray:
    """The ``(F, k)`` DCT basis on the span of ``times`` (as socialcam defines it)."""
    return sc.dct_basis(times, k)


def reference_point(
    x: np.ndarray, P: np.ndarray, theta: np.ndarray, folds: int, k_max: int
) -> tuple[np.ndarray, int]:
    """One point: ``x (F,2)`` with NaN rows, cameras ``P (F,3,4)``, basis ``theta (F,Kc)``.
    Returns the trajectory ``(F,3)`` and the chosen K."""
    seen = np.flatnonzero(np.isfinite(x).all(axis=1))
    n = len(seen)
    xs, Ps, th = x[seen], P[seen], theta[seen]
    # Sec 5.3 normalisation: mean 0, mean distance √2.
    m = xs.mean(axis=0)
    s = np.sqrt(2) / np.linalg.norm(xs - m, axis=1).mean()
    T = np.array([[s, 0, -s * m[0]], [0, s, -s * m[1]], [0, 0, 1.0]])
    xn = (xs - m) * s
    Pn = T @ Ps
    # Rows (·)_{1:2} of [x]_× P (Eq 5.1): y P3 − P2 and P1 − x P3; a·X = b.
    r1 = xn[:, 1:2] * Pn[:, 2] - Pn[:, 1]
    r2 = Pn[:, 0] - xn[:, 0:1] * Pn[:, 2]
    rows = np.stack([r1, r2], axis=1)  # (n, 2, 4)
    kc = min(k_max, theta.shape[1], (2 * n) // 3)
    # A[(i,r), 3k+c] = θ_k(t_i) a_{i,r,c}: unknowns ordered basis-function major.
    A = np.einsum("ik,irc->irkc", th[:, :kc], rows[:, :, :3]).reshape(n, 2, 3 * kc)
    b = -rows[:, :, 3]

    def project(beta: np.ndarray, idx: np.ndarray, k: int) -> np.ndarray:
        X = th[idx, :k] @ beta.reshape(k, 3)
        h = np.einsum("fij,fj->fi", Ps[idx, :, :3], X) + Ps[idx, :, 3]
        return h[:, :2] / h[:, 2:3]

    order = np.argsort(seen, kind="stable")  # frames are in time order here
    nf = min(folds, n)
    fold_of = np.empty(n, dtype=int)
    fold_of[order] = np.arange(n) % nf
    cv = np.full(kc + 1, np.inf)
    for k in range(1, kc + 1):
        total = 0.0
        for j in range(nf):
            train, held = fold_of != j, fold_of == j
            if 2 * train.sum() < 3 * k:
                total = np.inf
                break
            beta = np.linalg.lstsq(
                A[train][:, :, : 3 * k].reshape(-1, 3 * k), b[train].ravel(), rcond=None
            )[0]
            held_idx = np.flatnonzero(held)
            total += ((project(beta, held_idx, k) - xs[held_idx]) ** 2).sum()
        cv[k] = total
    k = int(np.argmin(cv[1:]) + 1)
    beta0 = np.linalg.lstsq(A[:, :, : 3 * k].reshape(-1, 3 * k), b.ravel(), rcond=None)[0]
    all_idx = np.arange(n)
    KR = Ps[:, :, :3]

    def fun(beta: np.ndarray) -> np.ndarray:
        return (project(beta, all_idx, k) - xs).ravel()

    def jac(beta: np.ndarray) -> np.ndarray:
        X = th[:, :k] @ beta.reshape(k, 3)
        h = np.einsum("fij,fj->fi", KR, X) + Ps[:, :, 3]
        p = h[:, :2] / h[:, 2:3]
        J = (KR[:, :2, :] - p[:, :, None] * KR[:, 2:3, :]) / h[:, 2:3, None]  # (n,2,3)
        return np.einsum("ik,irc->irkc", th[:, :k], J).reshape(2 * n, 3 * k)

    sol = least_squares(fun, beta0, jac=jac, method="lm", xtol=1e-12, ftol=1e-12)
    return theta[:, :k] @ sol.x.reshape(k, 3), k


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--points", type=int, default=10_000)
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--k-max", type=int, default=30)
    ap.add_argument("--folds", type=int, default=5)
    ap.add_argument("--ref-points", type=int, default=40)
    args = ap.parse_args()
    cams = synth.random_photographers(args.frames, seed=0)
    X = synth.smooth_trajectories(args.points, cams.times, seed=1)
    obs = synth.observe(X, cams, noise_px=1.0, missing=0.05, seed=2)
    x = obs.x
    print(
        f"scene: {args.points} points × {args.frames} frames, random photographers, 1 px noise, "
        f"5 % missing; auto K ({args.folds} folds, K ≤ {args.k_max}) + LM refinement"
    )

    t0 = time.perf_counter()
    b = sc.reconstruct_trajectories(x, cams, folds=args.folds, k_max=args.k_max)
    t_sc = time.perf_counter() - t0
    assert b.ok.all()
    err = np.sqrt(((b.points - X) ** 2).sum(-1).mean(-1))
    print(f"socialcam : {t_sc:8.2f} s  ({1e3 * t_sc / args.points:.3f} ms/point)")
    print(
        f"            median RMS 3D error {1e3 * np.median(err):.2f} mm, median K {np.median(b.k)}"
    )

    m = min(args.ref_points, args.points)
    P = cams.P
    theta = dct_rows(cams.times, args.k_max)
    t0 = time.perf_counter()
    ref = [reference_point(x[i], P, theta, args.folds, args.k_max) for i in range(m)]
    t_ref = time.perf_counter() - t0
    t_ref_all = t_ref / m * args.points
    print(
        f"numpy/scipy: {t_ref:8.2f} s on {m} points ({1e3 * t_ref / m:.1f} ms/point) → "
        f"{t_ref_all:.0f} s scaled to {args.points} points"
    )
    same_k = np.array([r[1] == b.k[i] for i, r in enumerate(ref)])
    diff = np.array([np.abs(r[0] - b.points[i]).max() for i, r in enumerate(ref)])
    print(
        f"agreement : same K for {same_k.sum()}/{m} points; where K agrees, max |ΔX| = "
        f"{diff[same_k].max():.2e} m (median {np.median(diff[same_k]):.2e} m)"
    )
    if (~same_k).any():
        print(f"            where K differs, max |ΔX| = {diff[~same_k].max():.2e} m")
    assert same_k.mean() >= 0.9 and diff[same_k].max() < 1e-4, "implementations disagree"
    print(f"ratio     : socialcam is {t_ref_all / t_sc:.0f}× faster")


if __name__ == "__main__":
    main()
