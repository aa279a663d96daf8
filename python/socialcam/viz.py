"""Plots (matplotlib, imported lazily; the Agg backend is used when no display is set)."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from socialcam.camera import Cameras


def _plt() -> Any:
    import matplotlib

    if matplotlib.get_backend().lower() not in ("agg", "pdf", "svg") and not _has_display():
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _has_display() -> bool:
    import os

    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def plot_cameras(
    ax: Any,
    cameras: Cameras,
    *,
    size: float = 0.4,
    color: str = "tab:blue",
    label: str | None = "cameras",
) -> None:
    """Draws camera centres and optical axes on a 3D axis."""
    C, z = cameras.C, cameras.optical_axes
    ax.scatter(C[:, 0], C[:, 1], C[:, 2], c=color, marker="^", s=30, label=label)
    ax.quiver(C[:, 0], C[:, 1], C[:, 2], z[:, 0], z[:, 1], z[:, 2], length=size, color=color)


def set_equal_aspect(ax: Any, points: npt.ArrayLike) -> None:
    """Gives a 3D axis the same scale on x, y and z around ``points (N, 3)``."""
    P = np.asarray(points, dtype=float).reshape(-1, 3)
    P = P[np.isfinite(P).all(axis=1)]
    lo, hi = P.min(axis=0), P.max(axis=0)
    c, r = (lo + hi) / 2, max((hi - lo).max() / 2, 1e-9)
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_zlim(c[2] - r, c[2] + r)
    ax.set_box_aspect((1, 1, 1))


def plot_reconstruction(
    cameras: Cameras,
    truth: npt.ArrayLike,
    estimate: npt.ArrayLike,
    *,
    title: str = "",
) -> Any:
    """3D view of cameras, true and reconstructed points, beside a histogram of the 3D
    errors in millimetres. Returns the figure."""
    plt = _plt()
    X = np.asarray(truth, dtype=float).reshape(-1, 3)
    Y = np.asarray(estimate, dtype=float).reshape(-1, 3)
    err_mm = 1e3 * np.linalg.norm(X - Y, axis=1)
    fig = plt.figure(figsize=(11, 4.5))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    plot_cameras(ax, cameras)
    ax.scatter(X[:, 0], X[:, 1], X[:, 2], s=2, c="0.6", label="ground truth")
    ok = np.isfinite(Y).all(axis=1)
    ax.scatter(Y[ok, 0], Y[ok, 1], Y[ok, 2], s=2, c="tab:red", label="reconstructed")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(title)
    set_equal_aspect(ax, np.r_[X, cameras.C])
    ax2 = fig.add_subplot(1, 2, 2)
    e = err_mm[np.isfinite(err_mm)]
    hi = np.percentile(e, 99.5)
    ax2.hist(np.minimum(e, hi), bins=50, range=(0, hi), color="tab:red", alpha=0.8)
    ax2.axvline(np.median(e), color="k", ls="--", label=f"median {np.median(e):.1f} mm")
    ax2.set_xlabel("3D error [mm] (last bin: the worst 0.5%)")
    ax2.set_ylabel("points")
    ax2.legend()
    fig.tight_layout()
    return fig


def plot_trajectories(
    cameras: Cameras,
    truth: npt.ArrayLike,
    estimate: npt.ArrayLike,
    *,
    title: str = "",
) -> Any:
    """True (grey) and reconstructed (red) trajectories ``(N, F, 3)`` with the camera
    centres, beside the 3D error over time (median and 90th percentile over points, mm).
    Returns the figure."""
    plt = _plt()
    X = np.asarray(truth, dtype=float)
    Y = np.asarray(estimate, dtype=float)
    fig = plt.figure(figsize=(11, 4.5))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    ax.scatter(*cameras.C.T, s=6, c="tab:blue", label="camera centres")
    for i in range(X.shape[0]):
        ax.plot(*X[i].T, c="0.6", lw=1, label="ground truth" if i == 0 else None)
        ax.plot(*Y[i].T, c="tab:red", lw=1, label="reconstructed" if i == 0 else None)
    set_equal_aspect(ax, np.r_[X.reshape(-1, 3), cameras.C])
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(title)
    ax2 = fig.add_subplot(1, 2, 2)
    err = 1e3 * np.linalg.norm(X - Y, axis=2)
    t = np.arange(X.shape[1]) if cameras.times is None else cameras.times
    ax2.plot(t, np.nanmedian(err, axis=0), c="tab:red", label="median over points")
    ax2.plot(t, np.nanpercentile(err, 90, axis=0), c="tab:red", ls=":", label="90th percentile")
    ax2.set_xlabel("time [s]" if cameras.times is not None else "frame")
    ax2.set_ylabel("3D error [mm]")
    ax2.legend()
    fig.tight_layout()
    return fig


def plot_body(
    cameras: Cameras,
    points: npt.ArrayLike,
    bones: Any,
    *,
    truth: npt.ArrayLike | None = None,
    smooth: npt.ArrayLike | None = None,
    names: Any = None,
    n_shown: int = 6,
    title: str = "",
) -> Any:
    """A skeleton over a photo collection (:func:`socialcam.bodies.reconstruct_body`):
    ``points (F, J, 3)`` drawn with its ``bones`` (pairs of joint indices, e.g.
    ``synth.photos.BODY_BONES``) at ``n_shown`` photos spread over time (coloured from early
    to late; the truth in grey when given); beside it, when
    ``truth (F, J, 3)`` is given, each joint's median 3D error over the photos, mm (and that
    of ``smooth``, e.g. ``Body.smooth``, the trajectories before the ray fusion). Returns the
    figure.
    """
    from socialcam._validate import as_float_array

    plt = _plt()
    P = as_float_array(points, "points", (len(cameras), None, 3), allow_nan=True)
    F, J = P.shape[:2]
    bones_ = [(int(a), int(b)) for a, b in bones]
    if any(not (0 <= a < J and 0 <= b < J) for a, b in bones_):
        raise ValueError(f"bones: every pair must index joints 0..{J - 1}")
    T = None if truth is None else as_float_array(truth, "truth", (F, J, 3), allow_nan=True)
    S = None if smooth is None else as_float_array(smooth, "smooth", (F, J, 3), allow_nan=True)
    t = np.arange(F, dtype=float) if cameras.times is None else np.asarray(cameras.times)
    order = np.argsort(t, kind="stable")
    shown = order[np.unique(np.linspace(0, F - 1, min(max(n_shown, 1), F)).round().astype(int))]
    fig = plt.figure(figsize=(11, 4.5) if T is not None else (6, 4.5))
    ax = fig.add_subplot(1, 2 if T is not None else 1, 1, projection="3d")
    cmap = plt.get_cmap("viridis")
    for i, f in enumerate(shown):
        colour = cmap(i / max(len(shown) - 1, 1))
        for k, (a, b) in enumerate(bones_):
            if T is not None:
                ax.plot(*T[f, [a, b]].T, c="0.6", lw=1, label="truth" if i == k == 0 else None)
            ax.plot(*P[f, [a, b]].T, c=colour, lw=2, label=f"t = {t[f]:.2f} s" if k == 0 else None)
    set_equal_aspect(ax, P[shown].reshape(-1, 3) if T is None else np.r_[P[shown], T[shown]])
    ax.legend(loc="upper left", fontsize=7)
    ax.set_title(title)
    if T is not None:
        ax2 = fig.add_subplot(1, 2, 2)
        x = np.arange(J)
        err = 1e3 * np.nanmedian(np.linalg.norm(P - T, axis=2), axis=0)
        width = 0.4 if S is not None else 0.8
        ax2.bar(x, err, width=width, color="tab:red", label="body")
        if S is not None:
            e_s = 1e3 * np.nanmedian(np.linalg.norm(S - T, axis=2), axis=0)
            ax2.bar(x + width, e_s, width=width, color="0.6", label="trajectories alone")
        ax2.set_xticks(x + (width / 2 if S is not None else 0))
        ax2.set_xticklabels(list(names) if names is not None else [str(j) for j in x],
                            rotation=60, ha="right", fontsize=7)  # fmt: skip
        ax2.set_ylabel("median 3D error over the photos [mm]")
        ax2.legend()
    fig.tight_layout()
    return fig


def _track_colour(tid: int) -> Any:
    plt = _plt()
    return plt.get_cmap("tab10")(tid % 10) if tid >= 0 else "0.6"


def plot_charges_top(
    charges: Any,
    tracks: Any,
    cameras: dict[str, Cameras],
    *,
    points: npt.ArrayLike | None = None,
    title: str = "social charges, top view",
) -> Any:
    """Top view (x, y in metres) of every charge (grey dots), the charge tracks (coloured
    lines, labelled by id), the wearers' camera paths and the static map points.
    ``charges``: per frame a list of :class:`socialcam.Charge`; ``tracks``:
    :class:`socialcam.ChargeTrack` list; ``cameras``: person → Cameras. Returns the
    figure."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 6))
    if points is not None:
        P = np.asarray(points, dtype=float).reshape(-1, 3)
        if len(P):
            ax.scatter(P[:, 0], P[:, 1], s=0.3, c="0.85", label="map points", rasterized=True)
    for name, cam in cameras.items():
        if len(cam):
            ax.plot(cam.C[:, 0], cam.C[:, 1], lw=1, alpha=0.8, label=f"{name} (camera)")
    allc = np.array([c.position for cs in charges for c in cs]).reshape(-1, 3)
    if len(allc):
        ax.scatter(allc[:, 0], allc[:, 1], s=4, c="0.4", label="charges")
    for tr in tracks:
        col = _track_colour(tr.id)
        ax.plot(tr.positions[:, 0], tr.positions[:, 1], "-", c=col, lw=2)
        ax.annotate(f"#{tr.id}", tr.positions[0, :2], color=col, fontsize=9)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title)
    ax.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    return fig


def plot_faces_top(
    faces: Any,
    names: Any,
    cameras: dict[str, Cameras] | None = None,
    *,
    every: int = 5,
    arrow: float = 0.5,
    title: str = "faces of everyone in view, top view",
) -> Any:
    """Top view (x, y in metres) of the faces of :func:`socialcam.pipeline.faces_in_videos`
    (or :func:`socialcam.faces.reconstruct_faces`): each person's eye midpoint over time (a
    line, wearers solid, people without a camera dashed) with its gaze every ``every``
    instants (arrows ``arrow`` metres long), and the wearers' camera paths (grey) when
    ``cameras`` (person → Cameras) is given. ``names``: the wearers' names in camera order
    (person ``v`` < ``len(names)`` is ``names[v]``). Returns the figure."""
    from socialcam._validate import check_float, check_int

    every_ = check_int(every, "every", min=1)
    length = check_float(arrow, "arrow", min=0.0, min_exclusive=True)
    for field in ("person", "wearer", "p", "v"):
        if not hasattr(faces, field):
            raise ValueError(f"faces: expected a Faces3D (no {field!r})")
    names_ = [str(n) for n in names]
    V = len(names_)
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 6))
    for cam in (cameras or {}).values():
        if len(cam):
            ax.plot(cam.C[:, 0], cam.C[:, 1], c="0.75", lw=1)
    cmap = plt.get_cmap("tab10")
    for j, pid in enumerate(np.asarray(faces.person)):
        ok = np.flatnonzero(np.isfinite(faces.v[:, j]).all(axis=1))
        if not len(ok):
            continue
        col = cmap(j % 10)
        label = names_[pid] if pid < V else f"person{pid - V} (no camera)"
        P, G = faces.p[ok, j], faces.v[ok, j]
        ax.plot(P[:, 0], P[:, 1], "-" if faces.wearer[j] else "--", c=col, lw=1.5, label=label)
        sel = slice(None, None, every_)
        ax.quiver(P[sel, 0], P[sel, 1], length * G[sel, 0], length * G[sel, 1], color=col,
                  angles="xy", scale_units="xy", scale=1.0, width=0.004)  # fmt: skip
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    return fig


def plot_charges_over_time(
    times: npt.ArrayLike,
    charges: Any,
    tracks: Any,
    names: Any,
    *,
    segments: Any = None,
) -> Any:
    """Charges over time: above, each charge's magnitude (coloured by track); below, for
    every wearer, the track whose charge it belongs to at each time (calibration segments
    shaded). Returns the figure."""
    plt = _plt()
    t = np.asarray(times, dtype=float)
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    track_of = {
        (int(f), hash(p.tobytes())): tr.id
        for tr in tracks
        for f, p in zip(tr.frames, tr.positions, strict=True)
    }
    ct, cm, ctid, mt, mm, mtid = [], [], [], [], [], []  # one scatter each: fast
    for f, cs in enumerate(charges):
        for c in cs:
            tid = track_of.get((f, hash(c.position.tobytes())), -1)
            ct.append(t[f])
            cm.append(c.magnitude)
            ctid.append(tid)
            for m in c.members:
                mt.append(t[f])
                mm.append(int(m))
                mtid.append(tid)
    if ct:
        ax1.scatter(ct, cm, s=6, c=[_track_colour(i) for i in ctid])
        ax2.scatter(mt, mm, s=8, marker="s", c=[_track_colour(i) for i in mtid])
    ax1.set_ylabel("magnitude")
    ax1.set_title("social charges over time (colour = track; grey = no track)")
    for i, n in enumerate(names):
        if segments and n in segments:
            a, b = segments[n]
            ax2.axvspan(a, b, ymin=(i + 0.1) / len(names), ymax=(i + 0.9) / len(names),
                        color="0.9")  # fmt: skip
    ax2.set_yticks(range(len(names)))
    ax2.set_yticklabels(list(names))
    ax2.set_ylim(-0.5, len(names) - 0.5)
    ax2.set_xlabel("time [s] (common clock)")
    ax2.set_ylabel("member of")
    fig.tight_layout()
    return fig
