"""Fuzzes one function of ``socialcam._core`` with extreme arguments (run in a subprocess by
``tests/test_fuzz_binding.py``, so that an abort fails a test instead of killing pytest).

Usage: ``python tests/_fuzz_worker.py FUNCTION... MAX_EXAMPLES``. For each function it
prints ``START name``, one ``CALL ...`` line per call, then ``DONE name ok`` (every call
returned or raised an allowed exception) or ``DONE name fail`` (a forbidden exception,
printed). A crash (a signal) leaves the last ``START`` unanswered, its last ``CALL`` line
naming the input.

The kernel is the contract here: every ``_core`` function must return or raise
``ValueError`` (including ``DegenerateError``), ``TypeError``/``OverflowError`` (PyO3's
argument conversion) or ``ConvergenceError`` — never abort, panic (``PanicException``),
``SystemError``, ``MemoryError`` or the ``RuntimeError`` that marks a caught core panic.
"""

from __future__ import annotations

import dataclasses
import os
import resource
import signal
import sys
import traceback
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

# Big allocations must fail fast (and visibly) instead of swapping the shared machine.
_LIMIT = 6 << 30
resource.setrlimit(resource.RLIMIT_AS, (_LIMIT, _LIMIT))
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from socialcam import _core  # noqa: E402
from socialcam.articulated import ArticulatedOptions, BqpOptions  # noqa: E402
from socialcam.charges import ChargeOptions  # noqa: E402

ALLOWED: tuple[type[BaseException], ...] = (
    ValueError,
    TypeError,
    OverflowError,
    _core.ConvergenceError,
)
#: Seconds one call may take before it counts as a hang (the alarm also exercises the
#: Ctrl-C path: the handler's exception stops the core through ``detach``).
CALL_SECONDS = 20


class Hang(Exception):
    pass


def _alarm(signum: int, frame: object) -> None:
    raise Hang(f"call took more than {CALL_SECONDS} s")


# ------------------------------------------------------------------------- a small scene
F = 8  # frames / views
N = 5  # points
rng = np.random.default_rng(0)


def _look_at(c: np.ndarray) -> np.ndarray:
    z = -c / np.linalg.norm(c)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.array([x, y, z])


ang = np.linspace(0, 2 * np.pi, F, endpoint=False)
C = np.c_[5 * np.cos(ang), 5 * np.sin(ang), 1.5 + 0.2 * np.sin(3 * ang)]
R = np.array([_look_at(c) for c in C])
K = np.tile(np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]), (F, 1, 1))
TIMES = np.arange(F) * 0.1
X = rng.normal(scale=0.5, size=(N, 3))


def _proj(points: np.ndarray) -> np.ndarray:
    """(F, M, 2) pixels of (M, 3) points in every camera."""
    h = np.einsum("fij,fjk,fmk->fmi", K, R, points[None] - C[:, None])
    return np.asarray(h[..., :2] / h[..., 2:3])


PIX_FN2 = _proj(X)  # (F, N, 2)
PIX_NV2 = np.ascontiguousarray(PIX_FN2.transpose(1, 0, 2))  # (N, V, 2)
TRAJ = np.c_[np.linspace(-0.5, 0.5, F), 0.3 * np.sin(TIMES * 7), 0.2 * np.cos(TIMES * 5)]
PIX_TRAJ = np.array([[_proj(TRAJ[f][None])[f, 0] for f in range(F)]])  # (1, F, 2)

# gaze: 2 frames of 4 rays looking at a common point
P_EYE = np.array([[2.0, 0, 1.6], [-2, 0, 1.6], [0, 2, 1.6], [0, -2, 1.6]] * 2)
TARGET = np.array([0.1, 0.2, 1.0])
V_EYE = TARGET - P_EYE
V_EYE /= np.linalg.norm(V_EYE, axis=1, keepdims=True)
H_EYE = np.full(len(P_EYE), 0.1)
OFFSETS = np.array([0, 4, 8], dtype=np.int64)
MEMBERS = np.array([0, 1, 2, 3, 0, 1, 2, 3], dtype=np.int64)
WINDOWS = np.array([[0, 2, 1]], dtype=np.int64)
INIT = np.tile(TARGET, (2, 1, 1))
POS = INIT.copy()
MAG = np.ones((2, 1))
KAPPA = np.array([20.0, 20.0])
FRAME = np.array([0, 1], dtype=np.int64)
QPTS = np.array([[1.0, 1.0, 1.5], [-1.0, 0.5, 1.5]])

# articulated: child on a 0.4 m sphere around a moving parent
PARENT = np.c_[0.1 * np.sin(TIMES), np.zeros(F), np.full(F, 1.0)]
CHILD = PARENT + 0.4 * np.c_[np.cos(TIMES * 3), np.sin(TIMES * 3), np.zeros(F)]
PIX_CHILD = np.array([_proj(CHILD[f][None])[f, 0] for f in range(F)])  # (F, 2)
Q = np.array([[1.0, -2.0, 0.5], [-2.0, 0.5, 1.0], [0.5, 1.0, -1.0]])

TRAJ_OPTS = dict(k=3, folds=5, k_min=1, k_max=None, cv_rule="min", refine=True, max_iter=20)
EM_OPTS = dict(
    kappa=None,
    kappa_init=10.0,
    max_iter=50,
    tol=1e-6,
    max_angle=0.5,
    inner_iterations=5,
    lambda_g=1.0,
    temporal_filter="velocity",
    membership="window",
)

CHARGE_OPTS = dataclasses.asdict(ChargeOptions(seeds_per_ray=5, max_iter=50))
BQP_OPTS = dataclasses.asdict(BqpOptions(time_limit=5.0, node_limit=1000))
ART_OPTS = dataclasses.asdict(ArticulatedOptions(k=3, time_limit=5.0, node_limit=10_000))


# faces: the N = 5 points as the 5 landmarks of one face seen by all F cameras
F_SLOT = np.arange(F, dtype=np.int64)
F_LM = np.ascontiguousarray(PIX_FN2)  # (F, 5, 2)
F_SIZE = np.full(F, 50.0)
F_GROUP = np.zeros(F, dtype=np.int64)
F_REST = [np.zeros(1, np.int64), np.array([0.25]), 0.1, 1.5, 0.035, 0.1]


class Opts(dict[str, Any]):
    """An options object (attribute access), fuzzed field by field."""


# name -> (positional args, keyword args); every base call must succeed.
BASE: dict[str, tuple[list[Any], dict[str, Any]]] = {
    "validate_cameras": ([K, R, C], {}),
    "projection_matrices": ([K, R, C], {}),
    "project": ([K, R, C, X], {}),
    "back_project": ([K, R, C, PIX_FN2], {}),
    "triangulate": ([K, R, C, PIX_NV2], {"refine": True, "max_iter": 20}),
    "dct_basis": ([TIMES, 4], {"t0": None, "t1": None}),
    "align_similarity": ([X, 2 * X + 1], {}),
    "ray_sphere": ([C[:3], -C[:3], np.zeros((3, 3)), np.ones(3)], {}),
    "perspective_distance": ([P_EYE, V_EYE, np.tile(TARGET, (8, 1))], {}),
    # The ring's optical axes meet at the origin: a valid fixation segment.
    "calibrate_gaze": ([R, C, 1e-4, 100.0, 50, 1e-12], {}),
    "gaze_rays": ([R, C, np.zeros(3), np.array([0.0, 0.0, 1.0])], {}),
    "face_associate": (
        [K, R, C, np.zeros(F, np.int64), F_SLOT, F_LM, F_SIZE, C[:1] * 0.9, F_SLOT[:1], *F_REST],
        {},
    ),
    "face_triangulate": ([K, R, C, F_SLOT, F_LM, F_SIZE * 0.02, F_GROUP], {}),
    "face_refine_track": (
        [K, R, C, F_GROUP, F_SLOT, F_LM, F_SIZE * 0.02, X[None].copy(), 10.0, 3],
        {"lam_shape": 100.0},
    ),
    "face_gaze": ([X[None].copy(), np.full((1, 5), 0.01)], {}),
    "reconstruct_trajectories": (
        [K, R, C, TIMES, PIX_TRAJ, Opts(TRAJ_OPTS)],
        {"keep_covariance": True, "strict": False},
    ),
    "reconstructability": ([TRAJ, C, 3], {"times": TIMES}),
    "null_residual": ([TRAJ, 3], {"times": TIMES}),
    "saliency_field": ([P_EYE[:4], V_EYE[:4], H_EYE[:4], QPTS], {}),
    "saliency_grid": ([P_EYE[:4], V_EYE[:4], H_EYE[:4], (-1, -1, 0), (1, 1, 2), (4, 4, 3)], {}),
    "find_charges": ([P_EYE, V_EYE, H_EYE, OFFSETS, 0, Opts(CHARGE_OPTS)], {}),
    "diagnose_window": (
        [P_EYE, V_EYE, H_EYE, OFFSETS, 0, Opts(CHARGE_OPTS), np.zeros(len(P_EYE), np.int64)],
        {},
    ),
    "track_charges": (
        [np.eye(4)[[0, 0, 1, 1, 2]].astype(float), np.array([0, 1, 2, 3, 4], dtype=np.int64)],
        {"bandwidth": 0.3, "max_iter": 50},
    ),
    "gaze_split_windows": ([np.array([1, 1, 2, 2, 2], dtype=np.int64), 2], {}),
    "gaze_init": ([P_EYE, V_EYE, OFFSETS, WINDOWS, 0.25], {"candidates": None}),
    "gaze_em": ([P_EYE, V_EYE, MEMBERS, OFFSETS, WINDOWS, INIT, Opts(EM_OPTS)], {}),
    "gaze_predict": ([POS, MAG, KAPPA, FRAME, QPTS], {}),
    "gaze_log_density": ([POS, MAG, KAPPA, FRAME, QPTS, V_EYE[:2]], {}),
    "gaze_angle_to_charges": ([POS, MAG, KAPPA, FRAME, QPTS, V_EYE[:2], 0.3], {}),
    "solve_bqp": ([Q, np.ones(3), Opts(BQP_OPTS)], {}),
    "reconstruct_articulated": (
        [K, R, C, PIX_CHILD, PARENT, TIMES, 0.4, Opts(ART_OPTS), [(PIX_CHILD, 0.3)]],
        {},
    ),
    "reconstruct_skeleton": (
        [
            K,
            R,
            C,
            PIX_CHILD[:, None].repeat(2, 1),
            [-1, 0],
            [0.0, 0.4],
            PARENT,
            TIMES,
            Opts(ART_OPTS),
        ],
        {},
    ),
    "skeleton_order": ([[-1, 0, 1], [0.0, 0.4, 0.3]], {}),
    "articulated_reconstructability": ([K, R, C, PARENT, CHILD, TIMES, 3], {}),
    "articulated_bqp": ([K, R, C, PIX_CHILD, PARENT, TIMES, 0.4, 3], {"fit_radius": False}),
}

# ------------------------------------------------------------------------- extreme values
SCALARS: list[Any] = [
    None,
    float("nan"),
    float("inf"),
    -float("inf"),
    -1,
    0,
    1,
    2.9,
    -(2**63),
    2**63 - 1,
    2**64,
    10**12,
    1e20,
    -1e20,
    1e-300,
    True,
    "x",
    [],
    (1e20, 1e20, 1e20),
    (10**9, 10**9, 10**9),
    (-1, 0, 3),
]


def _array_variants(a: np.ndarray) -> list[Callable[[], Any]]:
    """Broken versions of a valid array argument."""
    out: list[Callable[[], Any]] = [
        lambda: None,
        lambda: a[:0],  # empty along the first axis
        lambda: a.reshape(-1),  # wrong ndim
        lambda: a[..., None],  # one axis too many
        lambda: np.zeros((*a.shape[:-1], a.shape[-1] + 1), dtype=a.dtype) if a.ndim else a,
        lambda: a.astype(np.complex128),
        lambda: a.astype(object),
        lambda: a.astype(np.float32),
        lambda: np.asarray(a, dtype=np.int32),
        lambda: np.broadcast_to(a[:1], (200_000, *a.shape[1:])).copy() if a.ndim else a,
        lambda: "abc",
        lambda: 3.0,
    ]

    def with_value(v: float) -> Callable[[], Any]:
        def make() -> np.ndarray:
            b = a.copy()
            if b.size:
                b.flat[rng.integers(b.size)] = v
            return b

        return make

    if a.dtype.kind == "f":
        out += [with_value(x) for x in (np.nan, np.inf, -np.inf, 1e300, -1e300, 0.0, 1e-300)]
        out += [lambda: a * 1e12, lambda: np.zeros_like(a), lambda: -a]
    elif a.dtype.kind == "i":
        out += [with_value(x) for x in (-1, 2**62, 2**63 - 1, -(2**63), 10**12, 0)]
        out += [lambda: a.astype(np.uint64), lambda: a.astype(float) + 0.5]
    return out


def _variants(value: Any) -> list[Callable[[], Any]]:
    if isinstance(value, np.ndarray):
        return _array_variants(value)
    if isinstance(value, Opts):
        out: list[Callable[[], Any]] = [lambda: None, lambda: 3, lambda: "options"]
        for field in value:
            for s in SCALARS:
                out.append(lambda f=field, s=s: SimpleNamespace(**{**value, f: s}))
            out.append(
                lambda f=field: SimpleNamespace(**{k: v for k, v in value.items() if k != f})
            )
        return out
    if isinstance(value, list):
        return [lambda: None, lambda: [], lambda: [*value, 0.5], lambda: [2**70] * len(value)] + [
            (lambda s=s: [s] * len(value)) for s in SCALARS
        ]
    return [(lambda s=s: s) for s in SCALARS] + [lambda: np.zeros(3)]


def _materialise(v: Any) -> Any:
    return SimpleNamespace(**v) if isinstance(v, Opts) else v


def run(name: str, max_examples: int) -> int:
    fn = getattr(_core, name)
    args, kwargs = BASE[name]
    slots: list[tuple[str, Any]] = [(f"arg{i}", a) for i, a in enumerate(args)]
    slots += [(k, v) for k, v in kwargs.items()]
    variants = {s: _variants(v) for s, v in slots}

    def call(mutation: dict[str, Any]) -> None:
        a = [_materialise(mutation.get(f"arg{i}", v)) for i, v in enumerate(args)]
        kw = {k: _materialise(mutation.get(k, v)) for k, v in kwargs.items()}
        desc = ", ".join(f"{k}={_short(v)}" for k, v in mutation.items()) or "base call"
        print(f"CALL {name}({desc})", file=sys.stderr, flush=True)
        signal.alarm(CALL_SECONDS)
        try:
            fn(*a, **kw)
        finally:
            signal.alarm(0)

    # The unmutated call must succeed, or the fuzzing below would only test the first check.
    call({})

    slot_names = [s for s, _ in slots]

    @settings(
        max_examples=max_examples,
        deadline=None,
        database=None,
        derandomize=True,
        suppress_health_check=list(HealthCheck),
    )
    @given(st.data())
    def fuzz(data: st.DataObject) -> None:
        chosen = data.draw(st.lists(st.sampled_from(slot_names), min_size=1, max_size=2))
        mutation = {}
        for s in chosen:
            make = data.draw(st.sampled_from(variants[s]))
            mutation[s] = make()
        try:
            call(mutation)
        except ALLOWED:
            pass

    fuzz()
    return 0


def _short(v: Any) -> str:
    if isinstance(v, np.ndarray):
        return f"array{v.shape}:{v.dtype}"
    if isinstance(v, SimpleNamespace):
        return f"options{vars(v)}"
    r = repr(v)
    return r if len(r) < 60 else r[:57] + "..."


def main() -> int:
    """``FUNCTIONS... MAX_EXAMPLES``: fuzzes each function in turn, printing
    ``DONE name ok|fail`` after each; a crash leaves the last ``START name`` unanswered."""
    *names, n = sys.argv[1:]
    signal.signal(signal.SIGALRM, _alarm)
    status = 0
    for name in names:
        print(f"START {name}", file=sys.stderr, flush=True)
        try:
            run(name, int(n))
            print(f"DONE {name} ok", file=sys.stderr, flush=True)
        except BaseException:  # a forbidden exception (PanicException is a BaseException)
            traceback.print_exc()
            print(f"DONE {name} fail", file=sys.stderr, flush=True)
            status = 1
    return status


if __name__ == "__main__":
    if sys.argv[1:] == ["--list"]:
        print("\n".join(sorted(BASE)))
        sys.exit(0)
    sys.exit(main())
