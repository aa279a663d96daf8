"""One consistent API (issue 13): a probe over the public functions that substitutes bad
values (None, negative, huge, fractional, NaN/inf, strings, empty lists, bools) for each
argument of a valid call, and requires either a result or a ``ValueError`` whose message
names the argument — never a ``TypeError``, ``OverflowError``, ``IndexError``, a raw numpy
message or a silent truncation. Plus the conventions: keyword-only options, options
dataclasses, read-only results, names."""

from __future__ import annotations

import dataclasses
import inspect
import math
import re
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from _scenes import ring

import socialcam as sc
from socialcam import gazefield as gf
from socialcam.camera import Cameras

BAD: list[Any] = [
    None,
    -1,
    0,
    2.9,
    -(2**70),
    10**30,
    math.nan,
    math.inf,
    "x",
    [],
    True,
]


CAMS = ring(12)
T = CAMS.times
TRAJ = np.c_[np.sin(T), np.cos(T), 0.1 * T]
PIX_TRAJ = CAMS.project_trajectory(TRAJ)
PTS = np.random.default_rng(0).normal(scale=0.5, size=(4, 3))
PIX_NV2 = np.ascontiguousarray(CAMS.project(PTS).transpose(1, 0, 2))
_ang = np.linspace(0, 2 * np.pi, 5, endpoint=False)
EYES = np.c_[2 * np.cos(_ang), 2 * np.sin(_ang), np.full(5, 1.6)]
_v = np.array([0.0, 0.2, 1.0]) - EYES
DIRS = _v / np.linalg.norm(_v, axis=1, keepdims=True)
FRAMES = [(EYES, DIRS)] * 4
FIELD = sc.GazeField.fit(FRAMES, n_charges=1, kappa=30.0)
#: A bone 0.4 m from a parent moving with the trajectory; small, fast articulated calls.
PARENT = TRAJ - np.array([0.4, 0.0, 0.0])
BONE = dict(x=PIX_TRAJ, cameras=CAMS, parent=PARENT, length=0.4)
LIMB = dict(
    x=np.stack([PIX_TRAJ, PIX_TRAJ], axis=1),
    cameras=CAMS,
    skeleton=sc.Skeleton(["root", "joint"], [-1, 0], [0.0, 0.4]),
    root=PARENT,
)
FAST = dict(k=2, refine_k_max=0, node_limit=100)

# name -> (callable, valid keyword arguments). Every parameter is probed.
CALLS: dict[str, tuple[Callable[..., Any], dict[str, Any]]] = {
    "triangulate": (sc.triangulate, dict(x=PIX_NV2, cameras=CAMS, refine=True, max_iter=20)),
    "dct_basis": (sc.dct_basis, dict(times=T, k=4, t0=-1.0, t1=2.0)),
    "align_similarity": (sc.align_similarity, dict(src=PTS, dst=2 * PTS + 1)),
    "ray_sphere": (
        sc.ray_sphere,
        dict(origins=CAMS.C[:3], directions=-CAMS.C[:3], centres=np.zeros((3, 3)), radii=1.0),
    ),
    "perspective_distance": (
        sc.perspective_distance,
        dict(p=EYES, v=DIRS, x=np.tile([0.0, 0.2, 1.0], (5, 1))),
    ),
    "reconstruct_trajectory": (
        sc.reconstruct_trajectory,
        dict(
            x=PIX_TRAJ,
            cameras=CAMS,
            k="auto",
            folds=3,
            k_min=1,
            k_max=4,
            cv_rule="min",
            refine=True,
            max_iter=20,
        ),
    ),
    "reconstruct_trajectories": (
        sc.reconstruct_trajectories,
        dict(x=PIX_TRAJ[None], cameras=CAMS, k=3, refine=False, max_iter=20),
    ),
    "reconstructability": (
        sc.reconstructability,
        dict(points=TRAJ, camera_centres=CAMS.C, k=3, times=T),
    ),
    "Cameras": (Cameras, dict(K=CAMS.K, R=CAMS.R, C=CAMS.C, times=T)),
    "Cameras.project": (CAMS.project, dict(points=PTS, return_depth=False)),
    "Cameras.project_trajectory": (CAMS.project_trajectory, dict(points=TRAJ)),
    "Cameras.back_project": (CAMS.back_project, dict(x=PIX_NV2.transpose(1, 0, 2))),
    "Cameras.with_times": (CAMS.with_times, dict(times=T)),
    "GazeField.fit": (
        sc.GazeField.fit,
        dict(
            frames=FRAMES,
            n_charges=1,
            times=np.arange(4.0),
            kappa=30.0,
            kappa_init=10.0,
            lambda_g=1.0,
            temporal_filter="velocity",
            membership="window",
            max_angle=0.5,
            min_window=2,
            max_iter=50,
            tol=1e-6,
            inner_iterations=3,
            seed=0,
        ),
    ),
    "GazeField.predict": (FIELD.predict, dict(points=EYES, t=1.0)),
    "GazeField.log_likelihood": (FIELD.log_likelihood, dict(p=EYES, v=DIRS, t=1.0)),
    "GazeField.angle_to_charges": (
        FIELD.angle_to_charges,
        dict(p=EYES, v=DIRS, t=1.0, self_radius=0.3),
    ),
    "GazeField.frame_index": (FIELD.frame_index, dict(t=1.0, n=5)),
    "cross_validate_gaze": (
        sc.cross_validate_gaze,
        dict(
            frames=FRAMES,
            leave_out=1,
            method="rbf",
            seed=0,
            times=np.arange(4.0),
            n_splits=2,
            eligible=[0, 1, 2],
        ),
    ),
    "detect_anomalies": (
        sc.detect_anomalies,
        dict(
            frames=FRAMES,
            field=FIELD,
            threshold=0.5,
            times=np.arange(4.0),
            kind="angle",
            self_radius=0.3,
        ),
    ),
    "fuse_gaze": (
        sc.fuse_gaze,
        dict(measured=DIRS, kappa_measured=10.0, predicted=DIRS, kappa_field=5.0),
    ),
    "rbf_predict": (
        gf.rbf_predict,
        dict(
            frames=FRAMES,
            points=EYES,
            frame=np.zeros(5, dtype=np.int64),
            kernel="linear",
            smoothing=0.0,
        ),
    ),
    "TrajectoryOptions": (
        sc.TrajectoryOptions,
        dict(k=3, folds=3, k_min=1, k_max=5, cv_rule="min", refine=True, max_iter=5),
    ),
    "GazeFieldOptions": (
        sc.GazeFieldOptions,
        dict(
            kappa=3.0,
            kappa_init=2.0,
            lambda_g=1.0,
            temporal_filter="velocity",
            membership="window",
            max_angle=0.5,
            min_window=2,
            max_iter=5,
            tol=1e-6,
            inner_iterations=2,
            seed=0,
        ),
    ),
}

#: Public functions of other branches' areas (charges: i13-charges; BQP: i12-bqp;
#: articulated: i12-artic), probed too so their owners see what is left.
OTHERS: dict[str, tuple[Callable[..., Any], dict[str, Any]]] = {
    "solve_bqp": (
        sc.solve_bqp,
        dict(Q=np.array([[1.0, -2], [-2, 1]]), c=np.ones(2), time_limit=5.0, node_limit=100),
    ),
    "articulated_reconstructability": (
        sc.articulated_reconstructability,
        dict(child=TRAJ + np.array([0.4, 0, 0]), cameras=CAMS, parent=TRAJ, k=3),
    ),
    "saliency_grid": (
        sc.saliency_grid,
        dict(
            rays=sc.GazeRays(EYES, DIRS, np.full(5, 0.1)),
            lo=(-1, -1, 0),
            hi=(1, 1, 2),
            shape=(4, 4, 3),
        ),
    ),
    "find_charges": (sc.find_charges, dict(rays=sc.GazeRays(EYES, DIRS, np.full(5, 0.1)), seed=0)),
}


def _probe(fn: Callable[..., Any], base: dict[str, Any]) -> list[str]:
    """Every (argument, bad value) that gives something other than a result or a
    ``ValueError`` naming the argument."""
    problems = []
    for name in base:
        for bad in BAD:
            if bad is None and base[name] is None:
                continue
            kwargs = {**base, name: bad}
            try:
                fn(**kwargs)
            except ValueError as e:
                if name not in str(e) and not (name == "frames" and "frames[" in str(e)):
                    problems.append(f"{name}={bad!r}: ValueError not naming it: {e}")
            except (KeyboardInterrupt, SystemExit):
                raise
            except BaseException as e:  # pyo3's PanicException is a BaseException
                problems.append(f"{name}={bad!r}: {type(e).__name__}: {e}")
    return problems


@pytest.mark.parametrize("name", sorted(CALLS))
def test_bad_arguments_raise_value_error_naming_them(name):
    fn, base = CALLS[name]
    fn(**base)  # the valid call works
    problems = _probe(fn, base)
    assert not problems, "\n".join(problems)


_RAYS = sc.GazeRays(EYES, DIRS, np.full(5, 0.1))
_SEQ = sc.find_charges_sequence([_RAYS] * 4)


def _plot_tracks(**kwargs: Any) -> None:
    import matplotlib.pyplot as plt

    plt.close(sc.plot_charge_tracks(**kwargs))


def _later_calls() -> dict[str, tuple[Callable[..., Any], dict[str, Any]]]:
    """Public functions added since the first probe (issue 13 asked for the whole class)."""
    from socialcam import faces, sync, synth

    seg = synth.fixation_segment(60, h=0.01, seed=9)
    return {
        "calibrate_gaze": (
            sc.calibrate_gaze,
            dict(cameras=seg.cameras, lambda_c=1e-4, lambda_axis=100.0, max_iter=20, tol=1e-12),
        ),
        "GazeRays": (sc.GazeRays, dict(p=EYES, v=DIRS, h=0.1, ids=np.arange(5))),
        "saliency_field": (sc.saliency_field, dict(rays=_RAYS, points=np.zeros((3, 3)))),
        "find_charges_sequence": (sc.find_charges_sequence, dict(frames=[_RAYS] * 2, seed=0)),
        "track_charges": (
            sc.track_charges,
            dict(
                charges_per_frame=_SEQ,
                bandwidth=0.3,
                max_iter=50,
                bin_seeding=True,
                max_gap=2,
                min_length=2,
            ),
        ),
        "plot_charge_tracks": (
            _plot_tracks,
            dict(tracks=sc.track_charges(_SEQ, min_length=2), legend_min_length=2),
        ),
        "reconstruct_articulated": (sc.reconstruct_articulated, {**BONE, **FAST}),
        "articulated_bqp": (sc.articulated_bqp, {**BONE, "k": 2}),
        "reconstruct_skeleton": (sc.reconstruct_skeleton, {**LIMB, **FAST}),
        "fuse_ego_exo": (
            faces.fuse_ego_exo,
            dict(ego_v=DIRS, ego_h=0.1, exo_v=DIRS, exo_h=0.1),
        ),
        "onset_envelope": (
            sync.onset_envelope,
            dict(x=np.random.default_rng(0).normal(size=4000), rate=8000),
        ),
    }


LATER = _later_calls()


@pytest.mark.parametrize("name", sorted(LATER))
def test_later_functions_bad_arguments(name):
    fn, base = LATER[name]
    fn(**base)
    problems = _probe(fn, base)
    assert not problems, "\n".join(problems)


def _probe_result(name: str) -> list[str]:
    fn, base = OTHERS[name]
    try:
        fn(**base)
    except TypeError as e:  # the signature moved on: report, do not hide
        return [f"base call: {e}"]
    return _probe(fn, base)


#: Functions known to fail the probe, with the reason (strict: a fix shows as XPASS).
KNOWN_BAD: dict[str, str] = {}


@pytest.mark.parametrize(
    "name",
    [
        pytest.param(n, marks=pytest.mark.xfail(strict=True, reason=KNOWN_BAD[n]))
        if n in KNOWN_BAD
        else n
        for n in sorted(OTHERS)
    ],
)
def test_other_areas_bad_arguments(name):
    problems = _probe_result(name)
    assert not problems, "\n".join(problems)


def _options_classes() -> list[type]:
    from socialcam import bodies, faces, sfm

    return [
        sc.TrajectoryOptions,
        sc.GazeFieldOptions,
        sc.ChargeOptions,
        sc.ArticulatedOptions,
        sc.BqpOptions,
        sc.RunOptions,
        sfm.VideoSfmOptions,
        faces.FaceOptions,
        bodies.BodyOptions,
    ]


@pytest.mark.parametrize("cls", _options_classes(), ids=lambda c: c.__name__)
def test_every_options_field_refuses_bad_values_by_name(cls):
    """Every field of every options dataclass, with each bad value: a ``ValueError`` naming
    the field, or a value of the field's type — never a ``TypeError``, a NaN, a truthy
    number taken for a flag or a fraction taken for a count."""
    cls()
    problems = []
    for f in dataclasses.fields(cls):
        kind = str(f.type)
        for bad in BAD:
            try:
                got = getattr(cls(**{f.name: bad}), f.name)
            except ValueError as e:
                if f.name not in str(e):
                    problems.append(f"{f.name}={bad!r}: ValueError not naming it: {e}")
                continue
            except (KeyboardInterrupt, SystemExit):
                raise
            except BaseException as e:
                problems.append(f"{f.name}={bad!r}: {type(e).__name__}: {e}")
                continue
            if isinstance(got, float) and not math.isfinite(got):
                problems.append(f"{f.name}={bad!r}: accepted a non-finite value")
            elif kind == "bool" and not isinstance(got, bool | np.bool_):
                problems.append(f"{f.name}={bad!r}: accepted for a bool")
            elif bad is True and "bool" not in kind:
                problems.append(f"{f.name}={bad!r}: a bool accepted for {kind}")
            elif bad == 2.9 and "float" not in kind and "Any" not in kind:
                problems.append(f"{f.name}={bad!r}: a fraction accepted for {kind}")
    assert not problems, "\n".join(problems)


# ----------------------------------------------------------------------------- conventions


@pytest.mark.parametrize(
    ("fn", "first_option"),
    [
        (sc.triangulate, "refine"),
        (sc.dct_basis, "t0"),
        (sc.reconstruct_trajectory, "options"),
        (sc.reconstruct_trajectories, "options"),
        (sc.reconstructability, "times"),
        (sc.GazeField.fit, "times"),
        (sc.cross_validate_gaze, "leave_out"),
        (sc.detect_anomalies, "threshold"),
        (sc.GazeField.angle_to_charges, "self_radius"),
        (sc.find_charges, "seed"),
        (sc.find_charges_sequence, "seed"),
        (sc.solve_bqp, "options"),
        (sc.reconstruct_articulated, "options"),
        (sc.reconstruct_skeleton, "options"),
        (sc.run, "calibration"),
        (sc.poses, "fps"),
        (sc.calibrate_gaze, "lambda_c"),
        (sc.track_charges, "bandwidth"),
    ],
)
def test_options_are_keyword_only(fn, first_option):
    param = inspect.signature(fn).parameters[first_option]
    assert param.kind is inspect.Parameter.KEYWORD_ONLY


OLD_NAMES = {"max_iterations", "filter", "X", "reprojection_rms", "observed"}
#: Owned by i12-artic (articulated.py): X → points, reprojection_rms → rms there.
OTHER_BRANCH_NAMES: set[str] = set()


def test_articulated_results_use_the_new_names():
    fields = {
        f.name
        for c in (sc.ArticulatedTrajectory, sc.SkeletonReconstruction)
        for f in dataclasses.fields(c)
    }
    assert not fields & OLD_NAMES


def test_no_parameter_uses_the_old_names():
    old = OLD_NAMES
    for name in sorted(set(sc.__all__) - OTHER_BRANCH_NAMES):
        obj = getattr(sc, name)
        fns = [obj] if callable(obj) else []
        if isinstance(obj, type):
            fns = [getattr(obj, m) for m in vars(obj) if callable(getattr(obj, m, None))]
        for fn in fns:
            try:
                params = set(inspect.signature(fn).parameters)
            except (TypeError, ValueError):
                continue
            assert not params & old, f"{name}.{getattr(fn, '__name__', '')}: {params & old}"


@pytest.mark.parametrize("cls", [sc.TrajectoryOptions, sc.GazeFieldOptions])
def test_options_dataclasses_are_frozen_and_overrides_checked(cls):
    o = cls()
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.max_iter = 3  # type: ignore[misc]
    assert {"max_iter", "tol"} & {f.name for f in dataclasses.fields(o)}


def test_unknown_override_is_named():
    with pytest.raises(ValueError, match=r"^max_iterations: not an option of TrajectoryOptions"):
        sc.reconstruct_trajectory(PIX_TRAJ, CAMS, max_iterations=5)
    with pytest.raises(ValueError, match=r"^filter: not an option of GazeFieldOptions"):
        sc.GazeField.fit(FRAMES, n_charges=1, filter="velocity")


def test_options_object_and_overrides_agree():
    a = sc.reconstruct_trajectory(PIX_TRAJ, CAMS, options=sc.TrajectoryOptions(k=3))
    b = sc.reconstruct_trajectory(PIX_TRAJ, CAMS, k=3)
    np.testing.assert_array_equal(a.points, b.points)
    assert a.n_observed == 12


def _arrays(obj: Any) -> list[np.ndarray]:
    return (
        [v for v in vars(obj).values() if isinstance(v, np.ndarray)]
        if hasattr(obj, "__dict__")
        else [
            getattr(obj, f.name)
            for f in dataclasses.fields(obj)
            if isinstance(getattr(obj, f.name), np.ndarray)
        ]
    )


def test_result_arrays_are_read_only():
    results = [
        sc.triangulate(PIX_NV2, CAMS, return_info=True)[1],
        sc.reconstruct_trajectory(PIX_TRAJ, CAMS, k=3),
        sc.reconstruct_trajectories(PIX_TRAJ[None], CAMS, k=3),
        FIELD,
        sc.cross_validate_gaze(FRAMES, method="rbf"),
        sc.detect_anomalies(FRAMES, FIELD),
        sc.solve_bqp(np.array([[1.0, -2], [-2, 1]])),
        sc.reconstruct_articulated(**BONE, **FAST),
        sc.reconstruct_skeleton(**LIMB, **FAST),
        sc.find_charges(sc.GazeRays(EYES, DIRS, np.full(5, 0.1)))[0],
    ]
    for r in results:
        arrays = _arrays(r)
        assert arrays
        for a in arrays:
            assert not a.flags.writeable, type(r).__name__
    for a in (CAMS.K, CAMS.R, CAMS.C, CAMS.times):
        assert not a.flags.writeable


def test_no_reference_to_documents_the_repo_lacks():
    """Every ``NAME.md`` the code, tests, benches and CI mention is a file of the repository,
    and nothing points outside it (the development notes are not shipped)."""
    root = Path(__file__).resolve().parents[1]
    texts = [root / "README.md", root / "pyproject.toml"]
    for top in ("python", "tests", "crates", "benches", ".ci", ".github"):
        texts += [
            p
            for p in (root / top).rglob("*")
            if p.suffix in {".py", ".pyi", ".rs", ".md", ".toml", ".yml", ".txt"}
            and "data" not in p.relative_to(root).parts
            and p != Path(__file__).resolve()
        ]
    have = {
        p.name
        for top in ("python", "tests", "crates", "benches")
        for p in (root / top).rglob("*.md")
    }
    have.add("README.md")
    problems = []
    for p in texts:
        text = p.read_text(errors="replace")
        for name in set(re.findall(r"\b([\w-]+\.md)\b", text)) - have:
            problems.append(f"{p.relative_to(root)}: {name}")
        if "../shared" in text or "/work/" in text:
            problems.append(f"{p.relative_to(root)}: a path outside the repository")
    assert not problems, problems


def test_pose_results_filled_in_place_are_handed_out_read_only():
    """The per-frame pose quality is filled in place while the poses are checked; the
    reconstruction and the pose errors hand their arrays out read-only all the same."""
    from socialcam import sfm

    q = sfm.FrameQuality(
        times=np.arange(3.0),
        posed=np.ones(3, bool),
        keyframe=np.zeros(3, bool),
        rms=np.ones(3),
        n_inliers=np.full(3, 50),
        reasons={},
    )
    q.posed[0] = False  # still writable while the reconstruction is being assembled
    rec = sfm.VideoReconstruction(
        names=("a",),
        cameras={},
        quality={"a": q},
        points=np.zeros((0, 3)),
        colors=np.zeros((0, 3), np.uint8),
        offsets=np.zeros(1),
        sync={},
        scale=1.0,
        unplaced=(),
        timings={},
        warnings=(),
        counts={},
        out_dir=Path("."),
    )
    errors = sfm.PoseErrors(("a",), np.zeros(2, np.int64), np.zeros(2), np.zeros(2), 1.0)
    for r in (rec.quality["a"], errors):
        for a in _arrays(r):
            assert not a.flags.writeable, type(r).__name__


def test_import_stays_light():
    """``import socialcam`` loads numpy and the extension only: the optional extras and the
    heavy dependencies of single stages are imported by the functions that use them."""
    heavy = ("scipy", "matplotlib", "cv2", "av", "pycolmap", "PIL", "tqdm", "c3d", "rerun")
    code = f"import sys, socialcam; print([m for m in {heavy!r} if m in sys.modules])"
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "[]", out


def test_angles_are_radians_unless_named_deg():
    """Angles in the API are radians; a parameter in degrees ends in ``_deg`` (README,
    Conventions). Checked on the documented fields of every options dataclass and the
    documented parameters of every public function."""
    documented: list[tuple[str, str, str]] = []  # (owner, name, its doc line)
    owners: list[Any] = list(_options_classes())
    # Functions, not result classes: a result may report in degrees, as the thesis' figures
    # do (``GazeCrossValidation.errors``, documented so).
    owners += [getattr(sc, n) for n in sc.__all__ if inspect.isfunction(getattr(sc, n))]
    for owner in owners:
        doc = inspect.getdoc(owner) or ""
        try:
            names = list(inspect.signature(owner).parameters)
        except (TypeError, ValueError):
            continue
        for name in names:
            for m in re.finditer(rf"^\s*{name}\b[^:\n]*: (.*)$", doc, re.M):
                documented.append((getattr(owner, "__name__", str(owner)), name, m.group(1)))
    assert len(documented) > 100
    wrong = [
        f"{o}.{n}: {line}"
        for o, n, line in documented
        if re.search(r"\bdegrees\b|°", line.split(";")[0].split("(default")[0])
        and "radians" not in line
        and not n.endswith("_deg")
    ]
    assert not wrong, wrong


@pytest.mark.parametrize("entry", ["run", "poses", "reconstruct_videos"])
def test_video_entry_points_check_arguments_before_touching_files(entry, tmp_path):
    """``run``, ``poses`` and ``reconstruct_videos`` refuse a bad argument by name before
    opening a video or creating ``out_dir`` (``out_dir=None`` was a TypeError, ``sync=5``
    and ``intrinsics=5`` were only noticed after decoding)."""
    from socialcam import sfm

    videos = [tmp_path / "a.mp4", tmp_path / "b.mp4"]
    for v in videos:
        v.write_bytes(b"")  # exists; never opened
    out = tmp_path / "out"
    fn = {
        "run": sc.run,
        "poses": sc.poses,
        "reconstruct_videos": lambda videos, out_dir, **kw: sfm.reconstruct_videos(
            videos, out_dir=out_dir, **kw
        ),
    }[entry]
    cases: dict[str, dict[str, Any]] = {
        "videos": dict(videos=None),
        "out_dir": dict(out_dir=None),
        "sync": dict(sync=5),
        "intrinsics": dict(intrinsics=5),
        "known_distance": dict(known_distance=5),
        "eye_height": dict(eye_height=-1.0),
        "progress": dict(progress="yes"),
    }
    if entry == "run":
        cases["overwrite"] = dict(overwrite="yes")
    for name, bad in cases.items():
        kwargs = {"videos": videos, "out_dir": out, "progress": False, **bad}
        with pytest.raises(ValueError, match=rf"^{name}:"):
            fn(**kwargs)
    assert not out.exists()
