"""BQP: socialcam's branch-and-bound against SCIP (pyscipopt) and HiGHS (highspy) on the
standard linearisation, same instances, same run, each to proven optimality under a cap.

Instances: the Eq 4.12 programs of articulated reconstruction of real CMU walking motion
(one camera per frame orbiting the subject at 1.5 m, 0.5 px noise) with n = 30, 60, 100
frames, and the OR-Library bqp50 instances (../shared/data/bqp when present, else the three
in tests/data/bqp). Run: python benches/bench_bqp.py [--cap SECONDS]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import socialcam as sc
from socialcam.mocap import load_bvh
from socialcam.synth.cameras import look_at

ROOT = Path(__file__).resolve().parent.parent
# ../shared/data from the main checkout (../../shared/data from a worktree), when present.
SHARED = next(
    (
        p
        for p in (ROOT.parent / "shared" / "data", ROOT.parent.parent / "shared" / "data")
        if p.exists()
    ),
    ROOT / "missing",
)


def read_qubo(path: Path) -> np.ndarray:
    lines = path.read_text().split("\n")
    n = int(lines[0])
    S = np.zeros((n, n))
    for ln in lines[1:]:
        if ln.strip():
            i, j, v = ln.split()
            S[int(i), int(j)] = S[int(j), int(i)] = float(v)
    return S


def articulated_instances(sizes: list[int]) -> list[tuple[str, np.ndarray, np.ndarray]]:
    bvh = SHARED / "mocap" / "cmu_131_01.bvh"
    if not bvh.exists():
        bvh = ROOT / "tests" / "data" / "mocap" / "cmu_131_01_walk300.bvh"
    m = load_bvh(bvh)
    sk, keep = sc.Skeleton.from_bvh(m)
    out = []
    rng = np.random.default_rng(0)
    for n in sizes:
        P = m.positions[::2][:n][:, keep]
        F = P.shape[0]
        d = P[-1, 0] - P[0, 0]
        d[1] = 0
        d /= np.linalg.norm(d)
        side = np.cross(d, [0.0, 1.0, 0.0])
        ang = np.linspace(-0.5, 0.5, F)
        C = P[:, 0] + 1.5 * (np.cos(ang)[:, None] * side + np.sin(ang)[:, None] * d) + [0, 0.3, 0]
        K = np.array([[1000.0, 0, 640], [0, 1000.0, 360], [0, 0, 1]])
        cams = sc.Cameras(K, look_at(C, P[:, 0], up=(0.0, 1.0, 0.0)), C, np.arange(F) / 60)
        for name in ("LeftElbow", "RightKnee"):
            j = sk.index(name)
            px = np.stack(
                [
                    sc._core.project(K[None], cams.R[i : i + 1], C[i : i + 1], P[i, j : j + 1])[0][
                        0, 0
                    ]
                    for i in range(F)
                ]
            ) + rng.normal(0, 0.5, (F, 2))
            Q, c, _ = sc.articulated_bqp(px, cams, P[:, sk.parents[j]], sk.lengths[j], 8)
            out.append((f"cmu-{name}-n{Q.shape[0]}", Q, c))
    return out


def solve_scip(Q: np.ndarray, c: np.ndarray, cap: float) -> tuple[float, float, bool]:
    from pyscipopt import Model, quicksum

    n = len(c)
    m = Model()
    m.hideOutput()
    m.setParam("limits/time", cap)
    m.setParam("parallel/maxnthreads", 1)
    x = [m.addVar(vtype="B") for _ in range(n)]
    y = {}
    for i in range(n):
        for j in range(i + 1, n):
            if Q[i, j] != 0:
                v = m.addVar(lb=0, ub=1)
                m.addCons(v <= x[i])
                m.addCons(v <= x[j])
                m.addCons(v >= x[i] + x[j] - 1)
                y[i, j] = v
    obj = quicksum((Q[i, i] + c[i]) * x[i] for i in range(n)) + quicksum(
        2 * Q[i, j] * v for (i, j), v in y.items()
    )
    m.setObjective(obj, "minimize")
    t = time.perf_counter()
    m.optimize()
    dt = time.perf_counter() - t
    return m.getObjVal(), dt, m.getStatus() == "optimal"


def solve_highs(Q: np.ndarray, c: np.ndarray, cap: float) -> tuple[float, float, bool]:
    import highspy

    n = len(c)
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("time_limit", cap)
    h.setOptionValue("threads", 1)
    inf = highspy.kHighsInf
    for i in range(n):
        h.addVar(0, 1)
        h.changeColCost(i, Q[i, i] + c[i])
        h.changeColIntegrality(i, highspy.HighsVarType.kInteger)
    k = n
    for i in range(n):
        for j in range(i + 1, n):
            if Q[i, j] != 0:
                h.addVar(0, 1)
                h.changeColCost(k, 2 * Q[i, j])
                h.addRow(-inf, 0, 2, np.array([k, i], dtype=np.int32), np.array([1.0, -1.0]))
                h.addRow(-inf, 0, 2, np.array([k, j], dtype=np.int32), np.array([1.0, -1.0]))
                h.addRow(
                    -1, inf, 3, np.array([k, i, j], dtype=np.int32), np.array([1.0, -1.0, -1.0])
                )
                k += 1
    t = time.perf_counter()
    h.run()
    dt = time.perf_counter() - t
    ok = h.getModelStatus() == highspy.HighsModelStatus.kOptimal
    return h.getInfo().objective_function_value, dt, ok


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cap", type=float, default=60.0, help="time cap per solve, seconds")
    ap.add_argument("--no-highs", action="store_true")
    args = ap.parse_args()
    inst = articulated_instances([30, 60, 100])
    bqp_dir = SHARED / "bqp" if (SHARED / "bqp").exists() else ROOT / "tests" / "data" / "bqp"
    for p in sorted(
        bqp_dir.glob("bqp50-*.qubo"), key=lambda p: int(p.stem.split("-")[1])
    ):  # n = 50 (+1 dummy)
        S = read_qubo(p)
        inst.append((p.stem, S, np.zeros(len(S))))
    print(
        f"{'instance':24s} {'n':>4s} {'ours s':>9s} {'opt':>4s} {'SCIP s':>9s} {'opt':>4s} "
        f"{'HiGHS s':>9s} {'opt':>4s} {'best/ours':>9s} agree"
    )
    for name, Q, c in inst:
        t = time.perf_counter()
        r = sc.solve_bqp(Q, c, time_limit=args.cap)
        ours = time.perf_counter() - t
        so, st, sok = solve_scip(Q, c, args.cap)
        if args.no_highs:
            ho, ht, hok = float("nan"), float("nan"), False
        else:
            ho, ht, hok = solve_highs(Q, c, args.cap)
        proved = [tt for tt, ok in ((st, sok), (ht, hok)) if ok]
        best = min(proved) if proved else float("inf")
        tol = 1e-6 * max(1.0, abs(r.objective))
        # Equal to every proven optimum, and no worse than an unproven incumbent.
        agree = all(
            abs(r.objective - v) <= tol if ok else r.objective <= v + tol
            for v, ok in ((so, sok), (ho, hok))
            if not np.isnan(v)
        )
        print(
            f"{name:24s} {len(c):4d} {ours:9.4f} {r.optimal!s:>4.4s} {st:9.4f} {sok!s:>4.4s} "
            f"{ht:9.4f} {hok!s:>4.4s} {best / ours:9.1f} {agree}"
        )


if __name__ == "__main__":
    main()
