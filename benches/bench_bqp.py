"""BQP: socialcam's branch-and-bound against Gurobi (gurobipy, binary MIQP, Threads=1,
MIPGap=0), SCIP (pyscipopt) and HiGHS (highspy) on the standard linearisation, same
instances, same run, each to proven optimality under a cap (single thread for the
references; ours runs its parallel rounds on the rayon pool unless --serial).

Instances: the Eq 4.12 programs of articulated reconstruction of real CMU walking motion
(one camera per frame orbiting the subject at 1.5 m, 0.5 px noise) with n = 30, 60, 100
frames; the OR-Library bqp50 instances ($SOCIALCAM_DATA/bqp when set, else the three in
tests/data/bqp); and Beasley-style random instances generated here (the OR-Library
bqp100/bqp250 family: each upper-triangle entry nonzero with probability 10 %, integer
uniform in [−100, 100], seeds 0, 1, …). Beasley *maximises* ``xᵀSx``; every solver here
minimises ``xᵀQx`` with ``Q = −S``, so the minima printed are the negated maxima.

Run: python benches/bench_bqp.py [--cap SECONDS] [--n100 10] [--n150 3] [--no-highs]
[--no-scip] [--serial] [--first-seed 0]. "cpu s" is the process CPU time of our solve (all threads).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

import socialcam as sc
from socialcam.mocap import load_bvh
from socialcam.synth.cameras import look_at

ROOT = Path(__file__).resolve().parent.parent
# Extra data (a folder with ``mocap/`` and ``bqp/``) named by $SOCIALCAM_DATA, when set.
SHARED = Path(os.environ.get("SOCIALCAM_DATA", str(ROOT / "missing")))


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


def beasley(n: int, seed: int, density: float = 0.1) -> np.ndarray:
    """Minimisation matrix ``Q = −S`` of a Beasley-style instance (see the module docs)."""
    rng = np.random.default_rng(seed)
    S = np.where(rng.random((n, n)) < density, rng.integers(-100, 101, (n, n)), 0)
    S = np.triu(S)
    S = S + np.triu(S, 1).T
    return -S.astype(float)


def solve_gurobi(Q: np.ndarray, c: np.ndarray, cap: float) -> tuple[float, float, bool]:
    import gurobipy as gp
    from gurobipy import GRB

    env = gp.Env(params={"OutputFlag": 0})
    m = gp.Model(env=env)
    m.Params.Threads = 1
    m.Params.MIPGap = 0.0
    m.Params.TimeLimit = cap
    x = m.addMVar(len(c), vtype=GRB.BINARY)
    m.setObjective(x @ Q @ x + c @ x, GRB.MINIMIZE)
    t = time.perf_counter()
    m.optimize()
    dt = time.perf_counter() - t
    return m.ObjVal, dt, m.Status == GRB.OPTIMAL


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


def consistent(ours: float, ours_proven: bool, theirs: float, theirs_proven: bool) -> bool:
    """Both proven: equal. Ours proven: no worse than their incumbent. Theirs proven: our
    incumbent no better than their optimum."""
    tol = 1e-6 * max(1.0, abs(ours))
    if ours_proven and theirs_proven:
        return abs(ours - theirs) <= tol
    if ours_proven:
        return ours <= theirs + tol
    return ours >= theirs - tol if theirs_proven else True


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cap", type=float, default=60.0, help="time cap per solve, seconds")
    ap.add_argument("--n100", type=int, default=10, help="Beasley n = 100 instances")
    ap.add_argument("--n150", type=int, default=3, help="Beasley n = 150 instances")
    ap.add_argument("--first-seed", type=int, default=0, help="seed of the first Beasley instance")
    ap.add_argument("--no-highs", action="store_true")
    ap.add_argument("--no-scip", action="store_true")
    ap.add_argument("--no-articulated", action="store_true")
    ap.add_argument("--serial", action="store_true", help="our tree search on one thread")
    args = ap.parse_args()
    inst = [] if args.no_articulated else articulated_instances([30, 60, 100])
    if not args.no_articulated:
        bqp_dir = SHARED / "bqp" if (SHARED / "bqp").exists() else ROOT / "tests" / "data" / "bqp"
        for p in sorted(
            bqp_dir.glob("bqp50-*.qubo"), key=lambda p: int(p.stem.split("-")[1])
        ):  # n = 50 (+1 dummy)
            S = read_qubo(p)
            inst.append((p.stem, S, np.zeros(len(S))))
    for n, count in ((100, args.n100), (150, args.n150)):
        for seed in range(args.first_seed, args.first_seed + count):
            inst.append((f"beasley{n}-s{seed}", beasley(n, seed), np.zeros(n)))
    print(
        f"{'instance':22s} {'n':>4s} {'ours s':>8s} {'cpu s':>8s} {'opt':>4s} {'nodes':>7s} "
        f"{'Gurobi s':>8s} {'opt':>4s} {'SCIP s':>8s} {'opt':>4s} {'HiGHS s':>8s} {'opt':>4s} "
        f"{'grb/ours':>8s} {'grb cpu':>8s} {'cpu rat':>8s} agree",
        flush=True,
    )
    totals: dict[str, list[float]] = {}
    for name, Q, c in inst:
        t, cpu = time.perf_counter(), time.process_time()
        r = sc.solve_bqp(Q, c, time_limit=args.cap, parallel=not args.serial)
        ours, cpu = time.perf_counter() - t, time.process_time() - cpu
        gcpu = time.process_time()
        go, gt, gok = solve_gurobi(Q, c, args.cap)
        gcpu = time.process_time() - gcpu
        if args.no_scip:
            so, st, sok = float("nan"), float("nan"), False
        else:
            so, st, sok = solve_scip(Q, c, args.cap)
        if args.no_highs or len(c) > 100:
            ho, ht, hok = float("nan"), float("nan"), False
        else:
            ho, ht, hok = solve_highs(Q, c, args.cap)

        agree = all(
            consistent(r.objective, r.optimal, v, ok)
            for v, ok in ((go, gok), (so, sok), (ho, hok))
            if not np.isnan(v)
        )
        print(
            f"{name:22s} {len(c):4d} {ours:8.3f} {cpu:8.3f} {r.optimal!s:>4.4s} {r.nodes:7d} "
            f"{gt:8.3f} {gok!s:>4.4s} {st:8.3f} {sok!s:>4.4s} {ht:8.3f} {hok!s:>4.4s} "
            f"{gt / ours:8.2f} {gcpu:8.3f} {gcpu / max(cpu, 1e-9):8.2f} {agree}",
            flush=True,
        )
        fam = name.split("-")[0]
        tot = totals.setdefault(fam, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        tot[0] += ours
        tot[1] += gt
        tot[2] += float(r.optimal)
        tot[3] += float(gok)
        tot[4] += cpu
        tot[5] += gcpu
    print("totals per family (seconds; proven counts; CPU seconds, load-independent):")
    for fam, (o, g, po, pg, oc, gc) in totals.items():
        print(
            f"  {fam:12s} ours {o:8.2f} s ({po:.0f} proven)  Gurobi {g:8.2f} s ({pg:.0f} proven)"
            f"  Gurobi/ours {g / o:6.2f}  CPU ours {oc:7.2f} Gurobi {gc:7.2f}"
            f"  ratio {gc / max(oc, 1e-9):6.2f}"
        )


if __name__ == "__main__":
    main()
