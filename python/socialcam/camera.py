"""Calibrated camera sequences: ``P = K R [I | -C]`` (OpenCV pixel convention)."""

from __future__ import annotations

import itertools
import os
from collections.abc import Sequence
from typing import Any, overload

import numpy as np
import numpy.typing as npt

from socialcam import _core
from socialcam._validate import FloatArray, as_float_array, check_bool, check_size, readonly

#: COLMAP puts pixel (0, 0) at the corner of the top-left pixel, OpenCV at its centre.
COLMAP_TO_OPENCV_PIXEL = -0.5


class Cameras:
    """A sequence of ``F`` calibrated pinhole cameras (one per frame or per view).

    Parameters
    ----------
    K : array_like, shape (3, 3) or (F, 3, 3)
        Upper-triangular intrinsics in pixels, shared or per frame.
    R : array_like, shape (F, 3, 3)
        World→camera rotations (camera looks along +z, x right, y down).
    C : array_like, shape (F, 3)
        Camera centres in world coordinates (metres).
    times : array_like, shape (F,), optional
        Capture time of each frame in seconds, on one clock shared by all cameras. Needed
        by trajectory reconstruction; any order, not necessarily uniform.

    Raises
    ------
    ValueError
        Wrong shapes, non-finite values, a singular or non-upper-triangular ``K``, an ``R``
        that is not a rotation — naming the argument and the frame.
    """

    __slots__ = ("_C", "_K", "_R", "_colmap", "_times")

    def __init__(
        self,
        K: npt.ArrayLike,
        R: npt.ArrayLike,
        C: npt.ArrayLike,
        times: npt.ArrayLike | None = None,
    ) -> None:
        R_ = as_float_array(R, "R", (None, 3, 3))
        f = R_.shape[0]
        C_ = as_float_array(C, "C", (f, 3))
        K_ = as_float_array(K, "K")
        if K_.shape == (3, 3):
            K_ = np.broadcast_to(K_, (f, 3, 3)).copy()
        elif K_.shape != (f, 3, 3):
            raise ValueError(f"K: expected shape (3, 3) or ({f}, 3, 3), got {K_.shape}")
        _core.validate_cameras(K_, R_, C_)
        K_ = K_ / K_[:, 2:3, 2:3]
        t_ = None
        if times is not None:
            t_ = readonly(as_float_array(times, "times", (f,)))
        self._K = readonly(K_)
        self._R = readonly(R_)
        self._C = readonly(C_)
        self._times = t_
        self._colmap: list[Any] | None = None

    # ----------------------------------------------------------------- properties
    @property
    def K(self) -> FloatArray:
        """Intrinsics, ``(F, 3, 3)``."""
        return self._K

    @property
    def R(self) -> FloatArray:
        """World→camera rotations, ``(F, 3, 3)``."""
        return self._R

    @property
    def C(self) -> FloatArray:
        """Camera centres in world coordinates, ``(F, 3)`` metres."""
        return self._C

    @property
    def times(self) -> FloatArray | None:
        """Capture times ``(F,)`` in seconds, or ``None``."""
        return self._times

    @property
    def P(self) -> FloatArray:
        """Projection matrices ``K R [I | -C]``, ``(F, 3, 4)``."""
        return _core.projection_matrices(self._K, self._R, self._C)

    @property
    def optical_axes(self) -> FloatArray:
        """Unit viewing directions (camera +z) in world coordinates, ``(F, 3)``."""
        return np.ascontiguousarray(self._R[:, 2, :])

    def __len__(self) -> int:
        return self._R.shape[0]

    def __repr__(self) -> str:
        t = (
            ""
            if self._times is None or len(self._times) == 0
            else f", times=[{self._times.min():.3f}, {self._times.max():.3f}] s"
        )
        return f"Cameras(F={len(self)}{t})"

    @overload
    def __getitem__(self, index: int) -> Cameras: ...
    @overload
    def __getitem__(self, index: slice | Sequence[int] | npt.NDArray[Any]) -> Cameras: ...
    def __getitem__(self, index: Any) -> Cameras:
        """Sub-sequence of cameras: an integer gives a one-camera sequence; a slice, a 1-D
        array or sequence of integers, or a boolean mask of length ``F`` select several."""
        n = len(self)
        if isinstance(index, (bool, np.bool_)):
            raise IndexError("camera index: a bool is not an index (use a mask of length F)")
        if isinstance(index, (int, np.integer)):
            if not -n <= int(index) < n:
                raise IndexError(f"camera index {index} out of range for {n} cameras")
            index = slice(int(index), int(index) + 1 if int(index) != -1 else None)
        elif not isinstance(index, slice):
            arr = np.asarray(index)
            if arr.ndim != 1 or not (
                np.issubdtype(arr.dtype, np.integer)
                or (arr.dtype == np.bool_ and len(arr) == n)
                or len(arr) == 0
            ):
                raise IndexError(
                    f"camera index: expected an integer, a slice, 1-D integers or a mask of "
                    f"{n} bools, got {type(index).__name__} of shape {arr.shape} ({arr.dtype})"
                )
            if arr.dtype != np.bool_ or len(arr) == 0:
                arr = arr.astype(np.int64)
                if len(arr) and not ((-n <= arr) & (arr < n)).all():
                    raise IndexError(
                        f"camera index out of range for {n} cameras: {arr.tolist()[:5]}"
                    )
            index = arr
        out = Cameras.__new__(Cameras)
        out._K = readonly(np.ascontiguousarray(self._K[index]))
        out._R = readonly(np.ascontiguousarray(self._R[index]))
        out._C = readonly(np.ascontiguousarray(self._C[index]))
        out._times = (
            None if self._times is None else readonly(np.ascontiguousarray(self._times[index]))
        )
        out._colmap = (
            None if self._colmap is None else list(np.asarray(self._colmap, dtype=object)[index])
        )
        return out

    def with_times(self, times: npt.ArrayLike) -> Cameras:
        """The same cameras with capture times ``(F,)`` seconds."""
        out = self[:]
        out._times = readonly(as_float_array(times, "times", (len(self),)))
        return out

    def moved(self, R: npt.ArrayLike, t: npt.ArrayLike) -> Cameras:
        """The same cameras in a world moved rigidly by ``X' = R X + t`` (``R (3, 3)`` a
        rotation, ``t (3,)`` in the world's unit): centres ``R C + t``, world→camera
        rotations ``Rᵢ Rᵀ``; intrinsics, lens and times kept. E.g. a group of cameras that
        structure from motion joined wrongly, put back (``socialcam.faces.repair_joins``)."""
        R_ = as_float_array(R, "R", (3, 3))
        t_ = as_float_array(t, "t", (3,))
        if not np.allclose(R_ @ R_.T, np.eye(3), atol=1e-6) or np.linalg.det(R_) < 0:
            raise ValueError("R: expected a rotation matrix (orthonormal, det +1)")
        # the nearest rotation: moves within the tolerance above would otherwise pile up
        # (2000 of them left det R = 1.005, which the constructor refuses)
        u, _, vt = np.linalg.svd(R_)
        R_ = u @ vt
        out = self[:]
        out._R = readonly(np.ascontiguousarray(self._R @ R_.T))
        with np.errstate(over="ignore", invalid="ignore"):
            C = self._C @ R_.T + t_
        if not np.isfinite(C).all():
            raise ValueError("t: the moved camera centres overflow float64")
        out._C = readonly(np.ascontiguousarray(C))
        return out

    def scaled(self, s: float) -> Cameras:
        """The same cameras in a world scaled by ``s`` about its origin (centres ``C · s``;
        intrinsics, rotations, lens and times kept): e.g. a map of unknown unit put in
        metres once its scale is known."""
        from socialcam._validate import check_float

        s_ = check_float(s, "s")
        if not s_ > 0:
            raise ValueError(f"s: must be > 0, got {s}")
        with np.errstate(over="ignore"):
            C = self._C * s_
        if not np.isfinite(C).all():
            raise ValueError(f"s: centres times {s_:g} overflow float64")
        out = self[:]
        out._C = readonly(np.ascontiguousarray(C))
        return out

    # ----------------------------------------------------------------- geometry
    def project(
        self, points: npt.ArrayLike, *, return_depth: bool = False
    ) -> FloatArray | tuple[FloatArray, FloatArray]:
        """Projects world points into every camera.

        Parameters
        ----------
        points : array_like, shape (3,) or (N, 3)
            World points in metres.
        return_depth : bool
            Also return the depth along each optical axis (negative = behind the camera).

        Returns
        -------
        pixels : ndarray, shape (F, 2) or (F, N, 2)
        depth : ndarray, shape (F,) or (F, N), only with ``return_depth``
        """
        return_depth = check_bool(return_depth, "return_depth")
        X_ = as_float_array(points, "points")
        single = X_.ndim == 1
        if single:
            X_ = X_.reshape(1, -1)
        if X_.ndim != 2 or X_.shape[1] != 3:
            raise ValueError(f"points: expected shape (3,) or (N, 3), got {np.shape(points)}")
        check_size("points", (len(self), X_.shape[0], 2))
        px, depth = _core.project(self._K, self._R, self._C, X_)
        if single:
            px, depth = px[:, 0], depth[:, 0]
        return (px, depth) if return_depth else px

    def project_trajectory(self, points: npt.ArrayLike) -> FloatArray:
        """Projects a moving point, frame ``f`` into camera ``f``.

        ``points`` is ``(F, 3)`` (one point) or ``(N, F, 3)``; returns ``(F, 2)`` or
        ``(N, F, 2)``. Points at or behind a camera give NaN pixels.
        """
        X_ = as_float_array(points, "points")
        f = len(self)
        single = X_.ndim == 2
        if single:
            X_ = X_[None]
        if X_.ndim != 3 or X_.shape[1:] != (f, 3):
            raise ValueError(
                f"points: expected shape ({f}, 3) or (N, {f}, 3), got {np.shape(points)}"
            )
        Xc = np.einsum("fij,nfj->nfi", self._R, X_ - self._C[None])
        h = np.einsum("fij,nfj->nfi", self._K, Xc)
        with np.errstate(divide="ignore", invalid="ignore"):
            px = h[..., :2] / h[..., 2:3]
        px[Xc[..., 2] <= 0] = np.nan
        return px[0] if single else px

    def _pixels_per_camera(self, x: npt.ArrayLike, *, allow_nan: bool) -> tuple[FloatArray, bool]:
        """``x`` as ``(F, N, 2)``, and whether it was given as one pixel per camera ``(F, 2)``."""
        x_ = as_float_array(x, "x", allow_nan=allow_nan)
        single = x_.ndim == 2
        if single:
            x_ = x_[:, None]
        if x_.ndim != 3 or x_.shape[0] != len(self) or x_.shape[2] != 2:
            f = len(self)
            raise ValueError(f"x: expected shape ({f}, 2) or ({f}, N, 2), got {np.shape(x)}")
        return x_, single

    def back_project(self, x: npt.ArrayLike) -> FloatArray:
        """Unit world directions of the rays through pixels.

        ``x`` is ``(F, 2)`` (one pixel per camera) or ``(F, N, 2)``; returns ``(F, 3)`` or
        ``(F, N, 3)``. The ray of pixel ``x[f]`` starts at ``C[f]``.
        """
        x_, single = self._pixels_per_camera(x, allow_nan=False)
        d = _core.back_project(self._K, self._R, self._C, x_)
        return d[:, 0] if single else d

    # ----------------------------------------------------------------- COLMAP
    @classmethod
    def from_colmap(
        cls,
        reconstruction: str | os.PathLike[str] | Any,
        *,
        image_names: Sequence[str] | None = None,
        times: npt.ArrayLike | None = None,
    ) -> Cameras:
        """Cameras of a COLMAP reconstruction (a folder with ``cameras/images/points3D``
        files, or a ``pycolmap.Reconstruction``), ordered by image name unless
        ``image_names`` gives the order.

        The principal point is moved from COLMAP's pixel convention (top-left pixel centre at
        (0.5, 0.5)) to OpenCV's ((0, 0)). For camera models with lens distortion ``K`` holds
        the pinhole part; use :meth:`undistort_points` to map raw pixel measurements to the
        undistorted pinhole pixels that every socialcam solver expects.
        """
        try:
            import pycolmap
        except ImportError as exc:  # pragma: no cover - depends on the install
            raise ImportError(
                "Cameras.from_colmap needs pycolmap: pip install 'socialcam[sfm]'"
            ) from exc

        rec = reconstruction
        if not isinstance(rec, pycolmap.Reconstruction):
            rec = _read_colmap(rec)
        by_name = {img.name: img for img in rec.images.values()}
        if not by_name:
            raise ValueError("reconstruction: has no registered images")
        if len(by_name) != len(rec.images):
            names_all = sorted(img.name for img in rec.images.values())
            twice = sorted({n for a, n in itertools.pairwise(names_all) if a == n})
            raise ValueError(f"reconstruction: image names registered twice: {twice[:5]}")
        names = sorted(by_name) if image_names is None else list(image_names)
        missing = [n for n in names if n not in by_name]
        if missing:
            raise ValueError(f"image_names: not in the reconstruction: {missing[:5]}")
        Ks, Rs, Cs, cams = [], [], [], []
        for n in names:
            img = by_name[n]
            cam = rec.cameras[img.camera_id]
            pose = img.cam_from_world() if callable(img.cam_from_world) else img.cam_from_world
            Rm = np.asarray(pose.rotation.matrix(), dtype=np.float64)
            t = np.asarray(pose.translation, dtype=np.float64)
            Km = np.asarray(cam.calibration_matrix(), dtype=np.float64).copy()
            Km[0, 2] += COLMAP_TO_OPENCV_PIXEL
            Km[1, 2] += COLMAP_TO_OPENCV_PIXEL
            Ks.append(Km)
            Rs.append(Rm)
            Cs.append(-Rm.T @ t)
            cams.append(cam)
        out = cls(np.array(Ks), np.array(Rs), np.array(Cs), times)
        out._colmap = cams
        return out

    def undistort_points(self, x: npt.ArrayLike) -> FloatArray:
        """Maps raw (distorted) pixels ``(F, 2)`` or ``(F, N, 2)`` in OpenCV convention to the
        undistorted pinhole pixels of ``K``. Cameras that did not come from COLMAP (or have
        no distortion) return the input unchanged. NaN rows stay NaN.
        """
        x_, single = self._pixels_per_camera(x, allow_nan=True)
        if self._colmap is None:
            out = x_.copy()
        else:
            out = np.full_like(x_, np.nan)
            for f, cam in enumerate(self._colmap):
                ok = np.isfinite(x_[f]).all(axis=1)
                if not ok.any():
                    continue
                img = x_[f, ok] - COLMAP_TO_OPENCV_PIXEL
                normed = np.asarray(cam.cam_from_img(img), dtype=np.float64)
                if normed.shape[1] == 3:
                    normed = normed[:, :2] / normed[:, 2:3]
                h = np.c_[normed, np.ones(len(normed))] @ self._K[f].T
                out[f, ok] = h[:, :2] / h[:, 2:3]
        return out[:, 0] if single else out

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able data."""
        return {
            "K": self._K.tolist(),
            "R": self._R.tolist(),
            "C": self._C.tolist(),
            "times": None if self._times is None else self._times.tolist(),
        }


def _colmap_bin_problem(path: str) -> str | None:
    """What is wrong with the length of a COLMAP binary file, or ``None``. Every file
    starts with its record count (each record takes at least a byte); ``images.bin`` and
    ``points3D.bin`` are walked record by record (image: id, quaternion, translation,
    camera id, NUL-ended name, 2D point count, 24 bytes per point; point: id, position,
    colour, error, track length, 8 bytes per track element). pycolmap loops without end,
    or reserves memory for minutes, on such files cut short."""
    with open(path, "rb") as f:
        data = f.read()
    n, at = len(data), 8
    if n < 8:
        return "shorter than its record count"
    count = int.from_bytes(data[:8], "little")
    if count > n:
        return f"a count of {count} records in {n} bytes"
    kind = os.path.basename(path)
    for i in range(count if kind in ("images.bin", "points3D.bin") else 0):
        if kind == "images.bin":
            end = data.find(b"\0", at + 64) if at + 64 <= n else -1
            head = end + 1
        else:
            head = at + 43
        if head <= 0 or head + 8 > n:
            return f"cut short in record {i} of {count}"
        step = 24 if kind == "images.bin" else 8
        at = head + 8 + step * int.from_bytes(data[head : head + 8], "little")
        if at > n:
            return f"cut short in record {i} of {count}"
    if kind in ("images.bin", "points3D.bin") and at != n:
        return f"{n - at} bytes after its {count} records"
    return None


def _read_colmap(folder: object) -> Any:
    """``pycolmap.Reconstruction`` of a model folder, or a ``ValueError`` naming the
    folder and the file when it cannot be read whole: pycolmap reads a binary file cut
    short as far as it goes (or loops without end), so a binary model is written back
    and compared file by file."""
    import tempfile

    import pycolmap

    try:
        path = os.fspath(folder)  # type: ignore[call-overload]
    except TypeError:
        raise ValueError(
            f"reconstruction: expected a folder or a pycolmap.Reconstruction, got "
            f"{type(folder).__name__}"
        ) from None
    if not os.path.isdir(path):
        raise ValueError(f"reconstruction: {path!r} is not a folder")
    binary = os.path.isfile(os.path.join(path, "images.bin")) and not os.path.isfile(
        os.path.join(path, "images.txt")
    )
    for name in ("cameras.bin", "images.bin", "points3D.bin", "rigs.bin", "frames.bin"):
        file = os.path.join(path, name)
        if binary and os.path.isfile(file):
            why = _colmap_bin_problem(file)
            if why:
                raise ValueError(f"reconstruction: {file} is damaged ({why})")
    try:
        rec = pycolmap.Reconstruction(path)
    except (ValueError, IndexError, RuntimeError, MemoryError) as exc:
        raise ValueError(f"reconstruction: cannot read the COLMAP model in {path}: {exc}") from None
    if binary:
        with tempfile.TemporaryDirectory() as again:
            rec.write_binary(again)
            for name in sorted(os.listdir(again)):
                mine = os.path.join(path, name)
                if os.path.isfile(mine) and os.path.getsize(mine) != os.path.getsize(
                    os.path.join(again, name)
                ):
                    raise ValueError(
                        f"reconstruction: {mine} is cut short or damaged: it holds "
                        f"{os.path.getsize(mine)} bytes, what pycolmap reads of it "
                        f"{os.path.getsize(os.path.join(again, name))}"
                    )
    return rec
