"""Social charges: socialcam against a vectorised numpy implementation of the same
mean-shift (Eq 6.7 on the cone kernel of Eq 6.1–6.4), on the same frames in one run;
then the saliency field on a 128³ grid against numpy; then 1 against 2 threads.

Both sides run the plain Eq 6.7 update from 20 seeds per ray (stratified depths, each
side with its own random draws), to the same tolerance, and merge/filter modes with the
same rules; agreement is checked as "same number of charges, positions within 1 cm" per
frame. socialcam's default (Newton-accelerated) is timed too.

    python benches/bench_charges.py [--frames 10000] [--chunk 250]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

import numpy as np

import socialcam as sc
from socialcam import synth

SQRT2PI = np.sqrt(2 * np.pi)
CUTOFF = 100.0  # same as the core: ‖d/h‖² above this contributes nothing


def numpy_field(p: np.ndarray, v: np.ndarray, h: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Eq 6.4 at points x (M,3) for rays (N,3); chunked over points."""
    out = np.empty(len(x))
    for a in range(0, len(x), 65536):
        w = x[a : a + 65536, None, :] - p[None]
        s = np.einsum("mnk,nk->mn", w, v)
        pp = np.einsum("mnk,mnk->mn", w, w) - s * s
        with np.errstate(divide="ignore", invalid="ignore"):
            q = pp / (s * s * h * h)
        q = np.where(s < 0, np.inf, q)
        q = np.where((s == 0) & (pp <= 0), 0.0, q)
        out[a : a + 65536] = np.where(q > CUTOFF, 0.0, np.exp(-0.5 * q) / (h * SQRT2PI)).mean(1)
    return out


def numpy_mean_shift(
    P: np.ndarray,
    V: np.ndarray,
    H: np.ndarray,
    seeds: np.ndarray,
    tol: float,
    max_iter: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Plain Eq 6.7 for frames (F,N,3) rays and seeds (F,S,3), all at once; the step is
    halved where it would lower the field, as in the core. Returns modes (F,S,3), field
    values (F,S) and converged (F,S)."""
    F, S, _ = seeds.shape
    x = seeds.reshape(F * S, 3).copy()
    fi = np.repeat(np.arange(F), S)
    p, v, h = P[fi], V[fi], H[fi]  # (M,N,3), (M,N,3), (M,N)

    def terms(x, p, v, h):
        w = x[:, None, :] - p
        s = np.einsum("mnk,mnk->mn", w, v)
        perp = w - s[..., None] * v
        pp = np.einsum("mnk,mnk->mn", perp, perp)
        ok = s > 1e-12
        with np.errstate(divide="ignore", invalid="ignore"):
            q = np.where(ok, pp / (s * s * h * h), np.inf)
        live = ok & (q <= CUTOFF)
        e = np.where(live, np.exp(-0.5 * np.where(live, q, 0.0)), 0.0)
        field = (e / h).sum(1)
        with np.errstate(divide="ignore", invalid="ignore"):
            wgt = np.where(live, e / (h**3 * s * s), 0.0)
            xt = x[:, None, :] - perp + v * np.where(live, pp / s, 0.0)[..., None]
        num = np.einsum("mn,mnk->mk", wgt, xt)
        den = wgt.sum(1)
        return field, num, den

    field, num, den = terms(x, p, v, h)
    active = np.ones(len(x), bool)
    converged = np.zeros(len(x), bool)
    for _ in range(max_iter):
        idx = np.flatnonzero(active)
        if len(idx) == 0:
            break
        dead = den[idx] <= 0
        active[idx[dead]] = False
        idx = idx[~dead]
        step = num[idx] / den[idx, None] - x[idx]
        pending = np.ones(len(idx), bool)
        xn = x[idx].copy()
        fn, nn, dn = field[idx].copy(), num[idx].copy(), den[idx].copy()
        for _ in range(30):
            j = np.flatnonzero(pending)
            if len(j) == 0:
                break
            cand = x[idx[j]] + step[j]
            f2, n2, d2 = terms(cand, p[idx[j]], v[idx[j]], h[idx[j]])
            up = f2 >= field[idx[j]] * (1 - 1e-12)
            jj = j[up]
            xn[jj], fn[jj], nn[jj], dn[jj] = cand[up], f2[up], n2[up], d2[up]
            pending[jj] = False
            step[j[~up]] *= 0.5
        moved = np.linalg.norm(np.where(pending[:, None], 0.0, step), axis=1)
        stuck = pending  # no ascent possible: a numerical maximum
        x[idx], field[idx], num[idx], den[idx] = xn, fn, nn, dn
        done = stuck | (moved < tol)
        converged[idx[done]] = True
        active[idx[done]] = False
    n_rays = P.shape[1]
    return x.reshape(F, S, 3), (field / n_rays).reshape(F, S), converged.reshape(F, S)


def numpy_charges(P, V, H, rng, seeds_per_ray=20, depth=(0.3, 10.0), tol=1e-5, max_iter=100,
                  merge_radius=0.2, member_sigma=2.5, min_members=2, bounds=None):  # fmt: skip
    """The whole of find_charges (without confidence regions) in numpy: seeds, mean-shift,
    then per-frame merge in seed order and winner-take-all membership."""
    F, N, _ = P.shape
    j = np.arange(seeds_per_ray)
    u = rng.uniform(size=(F, N, seeds_per_ray))
    d = depth[0] + (depth[1] - depth[0]) * (j + u) / seeds_per_ray
    seeds = (P[:, :, None, :] + V[:, :, None, :] * d[..., None]).reshape(F, N * seeds_per_ray, 3)
    t0 = time.perf_counter()
    modes, vals, conv = numpy_mean_shift(P, V, H, seeds, tol, max_iter)
    t_ms = time.perf_counter() - t0
    out = []
    for f in range(F):
        kept: list[list] = []
        for x, val in zip(modes[f][conv[f]], vals[f][conv[f]], strict=True):
            for m in kept:
                if np.linalg.norm(m[0] - x) <= merge_radius:
                    if val > m[1]:
                        m[0], m[1] = x, val
                    break
            else:
                kept.append([x, val])
        cands = []
        for x, val in kept:
            if bounds is not None and (np.any(x < bounds[0]) or np.any(x > bounds[1])):
                continue
            w = x - P[f]
            s = (w * V[f]).sum(1)
            perp = np.sqrt(np.maximum((w * w).sum(1) - s * s, 0))
            mem = np.flatnonzero((s >= 0) & (perp <= member_sigma * H[f] * np.maximum(s, 0)))
            if len(mem) >= min_members and val > 0:
                cands.append((val, x, mem))
        cands.sort(key=lambda c: -c[0])
        taken = np.zeros(N, bool)
        charges = []
        for _val, x, mem in cands:
            mem = mem[~taken[mem]]
            if len(mem) >= min_members:
                taken[mem] = True
                charges.append(x)
        out.append(charges)
    return out, t_ms


def agree(a: list[list[np.ndarray]], b: list[list[np.ndarray]], tol: float = 0.01) -> float:
    ok = 0
    for fa, fb in zip(a, b, strict=True):
        if len(fa) == len(fb) and all(
            min((np.linalg.norm(x - y) for y in fb), default=np.inf) <= tol for x in fa
        ):
            ok += 1
    return ok / len(a)


#: The search the numpy reference implements: the thesis' seeds along the rays only, plain
#: Eq 6.7, winner-take-all membership (the default adds pair seeds and the partition rule,
#: timed separately, with the former default "strongest" beside it).
THESIS_SEARCH = {"newton": False, "pair_seeds": False, "membership": "strongest"}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=10000)
    ap.add_argument("--chunk", type=int, default=250, help="numpy frames per batch")
    ap.add_argument("--threads-child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()

    scene = synth.meeting(args.frames, seed=0)
    frames = scene.ray_frames()
    bounds = tuple(scene.room)
    if args.threads_child:
        t0 = time.perf_counter()
        sc.find_charges_sequence(frames, seed=0, bounds=bounds, **THESIS_SEARCH)
        t1 = time.perf_counter()
        g = sc.saliency_grid(frames[0], scene.room[0], scene.room[1], shape=128)
        t2 = time.perf_counter()
        print(f"{t1 - t0:.4f} {t2 - t1:.4f} {g.sum():.6e}")
        return

    print(f"meeting scene: {args.frames} frames x 11 rays x 20 seeds per ray")
    t0 = time.perf_counter()
    ours = sc.find_charges_sequence(frames, seed=0, bounds=bounds, **THESIS_SEARCH)
    t_ours = time.perf_counter() - t0
    t0 = time.perf_counter()
    ours_newton = sc.find_charges_sequence(
        frames, seed=0, bounds=bounds, **dict(THESIS_SEARCH, newton=True)
    )
    t_newton = time.perf_counter() - t0
    t0 = time.perf_counter()
    sc.find_charges_sequence(frames, seed=0, bounds=bounds)
    t_default = time.perf_counter() - t0
    t0 = time.perf_counter()
    sc.find_charges_sequence(frames, seed=0, bounds=bounds, membership="strongest")
    t_strongest = time.perf_counter() - t0

    rng = np.random.default_rng(0)
    ref: list[list[np.ndarray]] = []
    t_ref_ms = 0.0
    t0 = time.perf_counter()
    for a in range(0, args.frames, args.chunk):
        P, V = scene.eyes[a : a + args.chunk], scene.gaze[a : a + args.chunk]
        H = np.broadcast_to(scene.h, P.shape[:2])
        out, t_ms = numpy_charges(P, V, H, rng, bounds=(scene.room[0], scene.room[1]))
        ref.extend(out)
        t_ref_ms += t_ms
    t_ref = time.perf_counter() - t0

    pos_ours = [[c.position for c in cs] for cs in ours]
    pos_newton = [[c.position for c in cs] for cs in ours_newton]
    print(f"  socialcam (plain Eq 6.7, incl. regions + objects): {t_ours:8.2f} s")
    print(f"  socialcam (Newton-accelerated):                   {t_newton:8.2f} s")
    print(f"  socialcam defaults (Newton, pair seeds, partition):{t_default:8.2f} s")
    print(f"  socialcam membership='strongest' (former default): {t_strongest:8.2f} s "
          f"(partition / strongest {t_default / t_strongest:.2f}x)")  # fmt: skip
    print(f"  numpy (plain Eq 6.7), mean-shift only:           {t_ref_ms:8.2f} s")
    print(f"  numpy total (seeds + mean-shift + merge/filter): {t_ref:8.2f} s")
    print(f"  frames agreeing (same count, within 1 cm): plain {agree(pos_ours, ref):.4f}, "
          f"newton {agree(pos_newton, ref):.4f}")  # fmt: skip
    print(f"  speed-up vs numpy total: plain {t_ref / t_ours:.1f}x, newton {t_ref / t_newton:.1f}x; "
          f"vs numpy mean-shift only: plain {t_ref_ms / t_ours:.1f}x")  # fmt: skip

    # Field on a 128^3 grid, 50 rays.
    rng = np.random.default_rng(1)
    P = rng.uniform([0, 0, 1], [8, 8, 2], (50, 3))
    T = rng.uniform([2, 2, 0.5], [6, 6, 1.5], (50, 3))
    rays = sc.GazeRays(P, T - P, rng.uniform(0.05, 0.1, 50), normalize=True)
    lo, hi = (0.0, 0.0, 0.0), (8.0, 8.0, 3.0)
    t0 = time.perf_counter()
    g = sc.saliency_grid(rays, lo, hi, shape=128)
    t_g = time.perf_counter() - t0
    xs = [np.linspace(lo[a], hi[a], 128) for a in range(3)]
    pts = np.stack(np.meshgrid(*xs, indexing="ij"), -1).reshape(-1, 3)
    t0 = time.perf_counter()
    g_ref = numpy_field(rays.p, rays.v, rays.h, pts).reshape(g.shape)
    t_gr = time.perf_counter() - t0
    err = np.abs(g - g_ref).max() / g_ref.max()
    print(f"field on 128^3 grid, 50 rays: socialcam {t_g:.3f} s, numpy {t_gr:.3f} s, "
          f"{t_gr / t_g:.1f}x, max rel. difference {err:.1e}")  # fmt: skip

    # Threads: the same work in child processes with 1 and 2 rayon threads.
    times = {}
    for n in (1, 2):
        env = dict(os.environ, RAYON_NUM_THREADS=str(n))
        out = subprocess.run(
            [sys.executable, __file__, "--frames", str(args.frames), "--threads-child"],
            env=env, capture_output=True, text=True, check=True,
        ).stdout.split()  # fmt: skip
        times[n] = (float(out[0]), float(out[1]), out[2])
    assert times[1][2] == times[2][2], "grid differs between thread counts"
    print(f"threads: charges 1 -> 2: {times[1][0]:.2f} s -> {times[2][0]:.2f} s "
          f"({times[1][0] / times[2][0]:.2f}x); meeting-room grid 128^3: {times[1][1]:.3f} s -> "
          f"{times[2][1]:.3f} s ({times[1][1] / times[2][1]:.2f}x); os.cpu_count()={os.cpu_count()}")  # fmt: skip


if __name__ == "__main__":
    main()
