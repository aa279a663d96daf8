"""Gaze-field EM (thesis Eq 7.10–7.13): socialcam's Rust core against the same EM written
with numpy in this file (vectorised over frames), on 10,000 frames × 11 members × 2
charges. Both run the identical algorithm (E-step, magnitudes, Levenberg–Marquardt M-step
with the capped perspective distance, ML κ); the script checks they agree and prints the
times and the ratio.

    python benches/bench_gazefield.py [--frames 10000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from socialcam import _core
from socialcam.gazefield import GazeFieldOptions
from socialcam.synth.people import primary_from_true

KAPPA_MIN, KAPPA_MAX = 1e-8, 1e8
MAX_ANGLE = np.pi / 6  # the core default (30 degrees)


def scene(n_frames: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two groups (6 + 5) around two slowly moving foci; gaze from the Sec 3.1 model."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames) / 10.0
    c = np.empty((n_frames, 2, 3))
    c[:, 0] = np.c_[-2.5 + 0.3 * np.sin(0.2 * t), 0.3 * np.cos(0.13 * t), np.full(n_frames, 1.0)]
    c[:, 1] = np.c_[
        np.full(n_frames, 2.5), 0.5 + 0.3 * np.sin(0.17 * t), 1.1 + 0.1 * np.cos(0.1 * t)
    ]
    group = np.array([0] * 6 + [1] * 5)
    k = np.array([*range(6), *range(5)])
    n = np.where(group == 0, 6, 5)
    a = 2 * np.pi * k / n + rng.uniform(-0.2, 0.2, 11)
    r = rng.uniform(1.2, 1.7, 11)
    p = c[:, group] + np.c_[r * np.cos(a), r * np.sin(a), rng.uniform(0.4, 0.7, 11)][None]
    p += rng.normal(0, 0.03, p.shape)
    u = c[:, group] - p
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    v = primary_from_true(u, 0.12, rng)
    return p, v, c


# ---------------------------------------------------------------- numpy reference
def log_c3(k: np.ndarray) -> np.ndarray:
    return np.log(k) - np.log(2 * np.pi) - k - np.log(-np.expm1(-2 * k))


def a3(k: np.ndarray) -> np.ndarray:
    small = k < 1e-4
    ks = np.where(small, 1.0, k)
    return np.where(small, k / 3 - k**3 / 45, 1 / np.tanh(ks) - 1 / ks)


def kappa_from_resultant(r: np.ndarray) -> np.ndarray:
    out = np.empty_like(r)
    lo = ~(r > 0)
    hi = r >= 1 - 1e-12
    mid = ~lo & ~hi
    rm = r[mid]
    k = rm * (3 - rm**2) / (1 - rm**2)
    active = np.ones_like(k, dtype=bool)
    for _ in range(50):
        f = a3(k) - rm
        sh = np.sinh(np.minimum(k, 300.0))
        d = np.where(
            k < 1e-3,
            1 / 3 - k**2 / 15,
            np.where(k > 300, 1 / k**2, 1 / k**2 - 1 / np.where(k > 300, 1.0, sh) ** 2),
        )
        nxt = np.clip(k - f / d, 0.1 * k, 10 * k)
        done = np.abs(nxt - k) <= 1e-12 * k
        k = np.where(active, nxt, k)
        active &= ~done
        if not active.any():
            break
    out[mid] = np.clip(k, KAPPA_MIN, KAPPA_MAX)
    out[lo] = KAPPA_MIN
    out[hi] = KAPPA_MAX
    return out


def capped_sq(p: np.ndarray, v: np.ndarray, x: np.ndarray, cap2: float) -> np.ndarray:
    """(F, J) capped squared perspective distances of rays (F, J, 3) to points (F, 3)."""
    w = x[:, None, :] - p
    a = np.einsum("fjk,fjk->fj", w, v)
    u = w - v * a[..., None]
    with np.errstate(divide="ignore", invalid="ignore"):
        d2 = np.einsum("fjk,fjk->fj", u, u) / (a * a)
    return np.where(a <= 1e-9, cap2, np.minimum(d2, cap2))


def m_step(p, v, w, x, cap2, trials, tol, active):
    """LM on Σⱼ wⱼ min(‖d‖², cap²) for every frame at once (frames in ``active``)."""
    F = len(x)
    x = x.copy()
    cur = (w * capped_sq(p, v, x, cap2)).sum(axis=1)
    mu = np.full(F, 1e-3)
    running = active.copy()
    eye = np.eye(3)
    H = np.zeros((F, 3, 3))
    g = np.zeros((F, 3))
    build = np.ones(F, dtype=bool)
    for _ in range(trials):
        if build.any():
            wv = x[:, None, :] - p
            a = np.einsum("fjk,fjk->fj", wv, v)
            u = wv - v * a[..., None]
            with np.errstate(divide="ignore", invalid="ignore"):
                d = u / a[..., None]
                ok = (a > 1e-9) & (np.einsum("fjk,fjk->fj", d, d) < cap2) & (w > 0)
                proj = eye - v[..., :, None] * v[..., None, :]
                J = (
                    proj / a[..., None, None]
                    - u[..., :, None] * v[..., None, :] / (a * a)[..., None, None]
                )
            ww = np.where(ok, w, 0.0)
            J = np.where(ok[..., None, None], J, 0.0)
            d = np.where(ok[..., None], d, 0.0)
            Hn = np.einsum("fj,fjki,fjkl->fil", ww, J, J)
            gn = np.einsum("fj,fjki,fjk->fi", ww, J, d)
            H = np.where(build[:, None, None], Hn, H)
            g = np.where(build[:, None], gn, g)
            build[:] = False
        running &= ~(g == 0).all(axis=1)
        if not running.any():
            break
        diag = np.einsum("fii->fi", H)
        floor = 1e-12 * diag.max(axis=1) + 1e-300
        sys = H + np.einsum(
            "fi,ij->fij", mu[:, None] * (diag + floor[:, None]) + floor[:, None], eye
        )
        step = np.zeros((F, 3))
        step[running] = -np.linalg.solve(sys[running], g[running][..., None])[..., 0]
        cand = x + step
        c = (w * capped_sq(p, v, cand, cap2)).sum(axis=1)
        acc = running & (c < cur)
        rej = running & ~acc
        x[acc] = cand[acc]
        cur[acc] = c[acc]
        mu[acc] = np.maximum(mu[acc] / 3, 1e-12)
        build[acc] = True
        small = acc & (np.linalg.norm(step, axis=1) < 0.01 * tol)
        running &= ~small
        mu[rej] *= 4
        running &= ~(rej & (mu > 1e12))
    return x


def numpy_em(p, v, init, kappa0, max_iter=200, tol=1e-7, max_angle=MAX_ANGLE, trials=5):
    """Per-frame EM of Eq 7.10–7.13 for all frames at once (the arithmetic runs only on the
    frames still iterating). p, v: (F, J, 3); init (F, I, 3)."""
    F, _J, _ = p.shape
    n_ch = init.shape[1]
    cap2 = np.tan(max_angle) ** 2
    r = init.copy()
    q = np.ones((F, n_ch))
    kappa = np.full(F, kappa0)
    prev_r = r.copy()
    prev_k = kappa.copy()
    running = np.ones(F, dtype=bool)
    it = np.zeros(F, dtype=np.int64)
    for n in range(max_iter + 1):
        a = np.flatnonzero(running)
        pa, va, ra, ka = p[a], v[a], r[a], kappa[a]
        # E-step (Eq 7.11) and magnitudes.
        d = ra[:, None, :, :] - pa[:, :, None, :]  # (A, J, I, 3)
        n2 = np.einsum("fjik,fjik->fji", d, d)
        mu = d / np.sqrt(n2)[..., None]
        with np.errstate(divide="ignore"):
            lw = np.log(q[a])[:, None, :] - np.log(n2)
        lw = lw - np.logaddexp.reduce(lw, axis=2, keepdims=True)
        logs = (
            lw + log_c3(ka)[:, None, None] + ka[:, None, None] * np.einsum("fjik,fjk->fji", mu, va)
        )
        gamma = np.exp(logs - logs.max(axis=2, keepdims=True))
        gamma /= gamma.sum(axis=2, keepdims=True)
        q[a] = gamma.sum(axis=1)
        if n > 0:
            moved = np.linalg.norm(ra - prev_r[a], axis=2).max(axis=1)
            dk = np.abs(ka - prev_k[a]) / prev_k[a]
            done = (moved < tol) & (dk < tol)
            running[a[done]] = False
            keep = ~done
            a, pa, va, ra, ka, gamma = a[keep], pa[keep], va[keep], ra[keep], ka[keep], gamma[keep]
        if n == max_iter or len(a) == 0:
            break
        it[a] += 1
        prev_r[a] = ra
        prev_k[a] = ka
        act = np.ones(len(a), dtype=bool)
        for i in range(n_ch):
            ra[:, i] = m_step(pa, va, gamma[:, :, i] ** 2, ra[:, i], cap2, trials, tol, act)
        r[a] = ra
        d = ra[:, None, :, :] - pa[:, :, None, :]
        mu = d / np.linalg.norm(d, axis=-1, keepdims=True)
        num = (gamma * np.einsum("fjik,fjk->fji", mu, va)).sum(axis=(1, 2))
        den = gamma.sum(axis=(1, 2))
        kappa[a] = kappa_from_resultant(num / den)
    return r, kappa, it


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=10_000)
    args = ap.parse_args()
    F = args.frames
    p, v, truth = scene(F)
    J = p.shape[1]
    offsets = np.arange(0, F * J + 1, J, dtype=np.int64)
    members = np.tile(np.arange(J, dtype=np.int64), F)
    windows = np.c_[np.arange(F), np.arange(1, F + 1), np.full(F, 2)].astype(np.int64)
    pf, vf = p.reshape(-1, 3), v.reshape(-1, 3)
    init = _core.gaze_init(pf, vf, offsets, windows, 0.25)
    kappa0 = 1 / 0.12**2

    t0 = time.perf_counter()
    opts = GazeFieldOptions(kappa_init=kappa0, max_angle=MAX_ANGLE, max_iter=200, tol=1e-7)
    pos, _mag, kap, *_rest, iters, conv = _core.gaze_em(
        pf, vf, members, offsets, windows, init, opts
    )
    t_rust = time.perf_counter() - t0

    t0 = time.perf_counter()
    r_np, k_np, it_np = numpy_em(p, v, init, kappa0)
    t_np = time.perf_counter() - t0

    dpos = np.linalg.norm(pos - r_np, axis=2).max(axis=1)
    dk = np.abs(kap - k_np) / k_np
    agree = (dpos < 1e-6) & (dk < 1e-6)
    order = np.argsort(pos[:, :, 0], axis=1)
    err = np.linalg.norm(np.take_along_axis(pos, order[..., None], axis=1) - truth, axis=2)
    print(f"EM over {F} frames x {J} members x 2 charges (per-frame EM, kappa estimated)")
    print(
        f"  socialcam (Rust, {_threads()} threads): {t_rust:8.3f} s   mean iterations {iters.mean():.1f}, converged {conv.mean():.3f}"
    )
    print(f"  numpy reference          : {t_np:8.3f} s   mean iterations {it_np.mean():.1f}")
    print(f"  ratio numpy / socialcam  : {t_np / t_rust:8.1f} x")
    print(
        f"  agreement: {agree.mean() * 100:.2f}% of frames within 1e-6 m and 1e-6 relative kappa; "
        f"median |dr| {np.median(dpos):.2e} m, max |dr| {dpos.max():.2e} m"
    )
    print(f"  charge error vs truth (x-sorted pairing): median {np.median(err) * 100:.1f} cm")
    if agree.mean() < 0.99:
        raise SystemExit("socialcam and the numpy EM disagree on more than 1% of the frames")


def _threads() -> str:
    import os

    return os.environ.get("RAYON_NUM_THREADS", str(os.cpu_count()))


if __name__ == "__main__":
    main()
