"""Readers for motion capture: BVH (skeleton + joint angles) and C3D (optical markers).

Both return positions in metres as ``(F, J, 3)`` arrays, with NaN for gaps.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from socialcam._validate import FloatArray

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
        A malformed file, naming the line.
    """
    with open(path, encoding="utf-8") as fh:
        tokens_by_line = [ln.split() for ln in fh]
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
            parent = stack[-1] if stack else -1
            names.append(f"{names[parent]}_end" if end else tok[1])
            parents.append(parent)
            offsets.append([0.0, 0.0, 0.0])
            channels.append([])
            is_end.append(end)
            pending_parent = len(names) - 1
        elif head == "{":
            stack.append(pending_parent)
        elif head == "}":
            if not stack:
                raise ValueError(f"path: unbalanced '}}' at line {i}")
            stack.pop()
        elif head == "OFFSET":
            try:
                offsets[stack[-1]] = [float(v) for v in tok[1:4]]
            except (ValueError, IndexError):
                raise ValueError(f"path: bad OFFSET at line {i}") from None
        elif head == "CHANNELS":
            channels[stack[-1]] = tok[2:]
        elif head == "MOTION":
            break
    if not names:
        raise ValueError("path: no HIERARCHY found")
    n_frames, frame_time = None, None
    while i < len(tokens_by_line) and (n_frames is None or frame_time is None):
        tok = tokens_by_line[i]
        i += 1
        if tok[:1] == ["Frames:"]:
            n_frames = int(tok[1])
        elif tok[:2] == ["Frame", "Time:"]:
            frame_time = float(tok[2])
    if n_frames is None or frame_time is None or frame_time <= 0:
        raise ValueError("path: missing 'Frames:' or 'Frame Time:' in MOTION")
    data = np.array([[float(v) for v in ln] for ln in tokens_by_line[i : i + n_frames] if ln])
    n_ch = sum(len(c) for c in channels)
    if data.shape != (n_frames, n_ch):
        raise ValueError(f"path: expected {n_frames} frames of {n_ch} channels, got {data.shape}")
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
            elif ch.endswith("rotation"):
                local_r = local_r @ _axis_rotation(ch[0], v)
            else:
                raise ValueError(f"path: unknown channel {ch!r} of joint {names[j]!r}")
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
    file's ``POINT:UNITS`` to metres and marking invalid samples (negative residual) NaN."""
    import warnings

    try:
        import c3d
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise ImportError("load_c3d needs c3d: pip install 'socialcam[mocap]'") from exc

    with open(path, "rb") as fh, warnings.catch_warnings():
        # The reader warns about absent analog channels, which marker files rarely have.
        warnings.filterwarnings("ignore", message="No analog data found")
        reader = c3d.Reader(fh)
        units = "mm"
        try:
            units = reader.get("POINT:UNITS").string_value.strip().lower()
        except (AttributeError, KeyError):
            pass
        to_m = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}.get(units)
        if to_m is None:
            raise ValueError(f"path: unsupported POINT:UNITS {units!r}")
        labels = [s.strip() for s in reader.point_labels]
        fps = float(reader.point_rate)
        pts = []
        for _, points, _ in reader.read_frames():
            xyz = np.array(points[:, :3], dtype=np.float64) * to_m
            xyz[points[:, 3] < 0] = np.nan
            pts.append(xyz)
    out = np.array(pts)
    if frames is not None:
        out = out[frames]
    return C3dMarkers(positions=out, labels=labels, fps=fps)
