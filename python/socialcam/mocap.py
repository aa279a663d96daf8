"""Readers for motion capture: BVH (skeleton + joint angles) and C3D (optical markers).

Both return positions in metres as ``(F, J, 3)`` arrays, with NaN for gaps.
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from socialcam._validate import FloatArray, check_float

#: Metres per unit of the CMU BVH conversion. Those files store ASF lengths, whose unit is
#: 1/0.45 inch (the ASF header's ``:units length 0.45``): 0.0254 / 0.45 m.
CMU_BVH_METRES_PER_UNIT = 0.0254 / 0.45


@dataclass(frozen=True)
class BvhMotion:
    """Forward kinematics of a BVH file.

    Attributes
    ----------
    names : joint names (end sites are named ``<parent>_end``)
    parents : (J,) parent index per joint, -1 for the root
    offsets : (J, 3) rest offsets from the parent, metres
    positions : (F, J, 3) world positions, metres (Y up in CMU files)
    fps : frames per second
    """

    names: list[str]
    parents: npt.NDArray[np.int64]
    offsets: FloatArray
    positions: FloatArray
    fps: float

    @property
    def bone_lengths(self) -> FloatArray:
        """``(J,)`` distance to the parent (0 for the root)."""
        return np.linalg.norm(self.offsets, axis=1)

    def to_dict(self) -> dict[str, Any]:
        return {
            "names": self.names,
            "parents": self.parents.tolist(),
            "offsets": self.offsets.tolist(),
            "fps": self.fps,
            "positions": self.positions.tolist(),
        }


def _axis_rotation(axis: str, deg: FloatArray) -> FloatArray:
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    if axis == "X":
        m = [[o, z, z], [z, c, -s], [z, s, c]]
    elif axis == "Y":
        m = [[c, z, s], [z, o, z], [-s, z, c]]
    else:
        m = [[c, -s, z], [s, c, z], [z, z, o]]
    return np.moveaxis(np.array(m), (0, 1), (-2, -1))


def _motion_path(path: object) -> str:
    """A motion file's path as a string; anything else (a file descriptor) is refused."""
    if not isinstance(path, (str, os.PathLike)):
        raise ValueError(f"path: expected a file path, got {type(path).__name__}")
    file = os.fspath(path)
    if not os.path.isfile(file):
        raise ValueError(f"path: {file} is not a file")
    return str(file)


def _check_frames(frames: object) -> None:
    if frames is not None and not isinstance(frames, slice):
        raise ValueError(f"frames: expected a slice or None, got {type(frames).__name__}")


def load_bvh(
    path: str | os.PathLike[str],
    *,
    scale: float = CMU_BVH_METRES_PER_UNIT,
    include_end_sites: bool = False,
    frames: slice | None = None,
) -> BvhMotion:
    """Reads a BVH file and runs forward kinematics.

    Parameters
    ----------
    path : BVH file.
    scale : metres per file unit (default: the CMU conversion's, see
        :data:`CMU_BVH_METRES_PER_UNIT`).
    include_end_sites : also return the ``End Site`` points.
    frames : optional slice of frames to keep.

    Raises
    ------
    ValueError
        A malformed file, naming the file and the line: a joint without a name, CHANNELS
        other than ``[XYZ]position`` / ``[XYZ]rotation`` or not as many as counted, an
        OFFSET without three finite numbers, a ``Frame Time`` that is not a finite
        positive number, other than ``Frames`` rows of motion, a row of another length or
        with a value that is not a finite number; a bad ``scale`` or ``frames``.
    """
    file = _motion_path(path)
    scale = check_float(scale, "scale", min=0.0, min_exclusive=True)
    if not isinstance(include_end_sites, (bool, np.bool_)):
        raise ValueError(f"include_end_sites: expected True or False, got {include_end_sites!r}")
    _check_frames(frames)
    try:
        with open(file, encoding="utf-8") as fh:
            tokens_by_line = [ln.split() for ln in fh]
    except UnicodeDecodeError:  # names in another 8-bit code page
        with open(file, encoding="latin-1") as fh:
            tokens_by_line = [ln.split() for ln in fh]

    def bad(why: str, line: int) -> ValueError:
        return ValueError(f"path: {file}: {why} at line {line}")

    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float]] = []
    channels: list[list[str]] = []
    is_end: list[bool] = []
    stack: list[int] = []
    i = 0
    pending_parent = -1
    while i < len(tokens_by_line):
        tok = tokens_by_line[i]
        i += 1
        if not tok:
            continue
        head = tok[0]
        if head in ("ROOT", "JOINT") or (head == "End" and len(tok) > 1 and tok[1] == "Site"):
            end = head == "End"
            if end and not stack:
                raise bad("an End Site outside any joint", i)
            if not end and len(tok) != 2:
                raise bad(f"{head} needs one name", i)
            if head == "JOINT" and not stack:
                raise bad("a JOINT outside any joint", i)
            parent = stack[-1] if stack else -1
            names.append(f"{names[parent]}_end" if end else tok[1])
            parents.append(parent)
            offsets.append([0.0, 0.0, 0.0])
            channels.append([])
            is_end.append(end)
            pending_parent = len(names) - 1
        elif head == "{":
            if pending_parent < 0:
                raise bad("'{' before any ROOT", i)
            stack.append(pending_parent)
            pending_parent = -1
        elif head == "}":
            if not stack:
                raise bad("unbalanced '}'", i)
            stack.pop()
        elif head == "OFFSET":
            try:
                if not stack or len(tok) != 4:
                    raise ValueError
                offsets[stack[-1]] = [float(v) for v in tok[1:4]]
                if not np.isfinite(offsets[stack[-1]]).all():
                    raise ValueError
            except ValueError:
                raise bad("bad OFFSET (three finite numbers inside a joint)", i) from None
        elif head == "CHANNELS":
            if not stack:
                raise bad("CHANNELS outside any joint", i)
            if len(tok) < 2 or not tok[1].isdigit() or int(tok[1]) != len(tok) - 2:
                raise bad("CHANNELS count does not match the channels listed", i)
            for ch in tok[2:]:
                if ch[:1] not in ("X", "Y", "Z") or ch[1:] not in ("position", "rotation"):
                    raise bad(f"unknown channel {ch!r} (Xposition ... Zrotation)", i)
            channels[stack[-1]] = tok[2:]
        elif head == "MOTION":
            break
    if not names:
        raise ValueError(f"path: {file}: no HIERARCHY found")
    if stack:
        raise ValueError(f"path: {file}: {len(stack)} joint(s) not closed with '}}'")
    n_frames, frame_time = None, None
    while i < len(tokens_by_line) and (n_frames is None or frame_time is None):
        tok = tokens_by_line[i]
        i += 1
        if tok[:1] == ["Frames:"]:
            if len(tok) != 2 or not tok[1].isdigit():
                raise bad("'Frames:' needs a whole number", i)
            n_frames = int(tok[1])
        elif tok[:2] == ["Frame", "Time:"]:
            try:
                frame_time = float(tok[2]) if len(tok) == 3 else float("nan")
            except ValueError:
                frame_time = float("nan")
            if not (np.isfinite(frame_time) and frame_time > 0):
                raise bad("'Frame Time:' needs a finite number of seconds > 0", i)
    if n_frames is None or frame_time is None:
        raise ValueError(f"path: {file}: missing 'Frames:' or 'Frame Time:' in MOTION")
    n_ch = sum(len(c) for c in channels)
    rows = [(k + 1, ln) for k, ln in enumerate(tokens_by_line[i:], start=i) if ln]
    if len(rows) != n_frames:
        raise ValueError(
            f"path: {file}: 'Frames: {n_frames}' but {len(rows)} rows of motion follow (frames)"
        )
    data = np.empty((n_frames, n_ch))
    for f, (line, ln) in enumerate(rows):
        if len(ln) != n_ch:
            raise bad(f"{len(ln)} values where the hierarchy has {n_ch} channels", line)
        try:
            data[f] = [float(v) for v in ln]
        except ValueError:
            raise bad("a value that is not a number", line) from None
        if not np.isfinite(data[f]).all():
            raise bad("a value that is not finite", line)
    if frames is not None:
        data = data[frames]
    F, J = data.shape[0], len(names)
    off = np.array(offsets) * scale
    pos = np.zeros((F, J, 3))
    rot = np.zeros((F, J, 3, 3))
    col = 0
    for j in range(J):
        local_t = np.broadcast_to(off[j], (F, 3)).copy()
        local_r = np.broadcast_to(np.eye(3), (F, 3, 3)).copy()
        for ch in channels[j]:
            v = data[:, col]
            col += 1
            if ch.endswith("position"):
                local_t[:, "XYZ".index(ch[0])] += v * scale
            else:  # checked: [XYZ]rotation
                local_r = local_r @ _axis_rotation(ch[0], v)
        p = parents[j]
        if p < 0:
            pos[:, j], rot[:, j] = local_t, local_r
        else:
            pos[:, j] = pos[:, p] + np.einsum("fij,fj->fi", rot[:, p], local_t)
            rot[:, j] = rot[:, p] @ local_r
    keep = np.array([include_end_sites or not e for e in is_end])
    remap = np.cumsum(keep) - 1
    new_parents = np.array(
        [remap[p] if p >= 0 else -1 for p in np.array(parents)[keep]], dtype=np.int64
    )
    return BvhMotion(
        names=[n for n, k in zip(names, keep, strict=False) if k],
        parents=new_parents,
        offsets=off[keep],
        positions=pos[:, keep],
        fps=1.0 / frame_time,
    )


@dataclass(frozen=True)
class C3dMarkers:
    """Optical markers: ``positions (F, M, 3)`` metres (NaN in gaps), ``labels``, ``fps``."""

    positions: FloatArray
    labels: list[str]
    fps: float


def load_c3d(path: str | os.PathLike[str], *, frames: slice | None = None) -> C3dMarkers:
    """Reads marker trajectories from a C3D file (via the ``c3d`` package), converting the
    file's ``POINT:UNITS`` to metres and marking invalid samples (negative residual) NaN.

    Raises
    ------
    ValueError
        Naming the file: not a C3D file, cut short (fewer frames than its header counts),
        units other than mm / cm / m, a rate that is not > 0; ``frames`` not a slice.
    """
    import warnings

    try:
        import c3d
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise ImportError("load_c3d needs c3d: pip install 'socialcam[mocap]'") from exc

    file = _motion_path(path)
    _check_frames(frames)
    try:
        with open(file, "rb") as fh, warnings.catch_warnings():
            # The reader warns about absent analog channels, which marker files rarely have.
            warnings.filterwarnings("ignore", message="No analog data found")
            # a file cut short: the reader warns and stops; counted below and refused
            warnings.filterwarnings("ignore", message="reached end of file")
            reader = c3d.Reader(fh)
            units = "mm"
            try:
                units = reader.get("POINT:UNITS").string_value.strip().lower()
            except (AttributeError, KeyError):
                pass
            to_m = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}.get(units)
            if to_m is None:
                raise ValueError(f"path: {file}: unsupported POINT:UNITS {units!r}")
            labels = [s.strip() for s in reader.point_labels]
            fps = float(reader.point_rate)
            if not (np.isfinite(fps) and fps > 0):
                raise ValueError(f"path: {file}: POINT:RATE {fps} is not a rate in Hz > 0")
            expected = int(reader.frame_count)
            pts = []
            for _, points, _ in reader.read_frames():
                xyz = np.array(points[:, :3], dtype=np.float64) * to_m
                xyz[points[:, 3] < 0] = np.nan
                pts.append(xyz)
    except (struct.error, AssertionError, EOFError, IndexError, KeyError, TypeError) as exc:
        raise ValueError(f"path: {file} is not a readable C3D file ({exc})") from None
    except ValueError as exc:
        if str(exc).startswith("path:"):
            raise
        raise ValueError(f"path: {file} is not a readable C3D file ({exc})") from None
    if len(pts) != expected:
        raise ValueError(f"path: {file} is cut short: {len(pts)} of its {expected} frames")
    out = np.array(pts)
    if frames is not None:
        out = out[frames]
    return C3dMarkers(positions=out, labels=labels, fps=fps)
