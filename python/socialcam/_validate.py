"""Input checks shared by the public API: every message names the argument."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def as_float_array(
    value: object,
    name: str,
    shape: Sequence[int | None] | None = None,
    *,
    allow_nan: bool = False,
) -> FloatArray:
    """Converts ``value`` to a C-contiguous float64 array and checks its shape.

    ``shape`` entries of ``None`` match any length. Infinite values are always rejected;
    NaN only when ``allow_nan`` is false.
    """
    try:
        arr = np.ascontiguousarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: cannot be converted to a float64 array ({exc})") from None
    if shape is not None:
        ok = arr.ndim == len(shape) and all(
            want is None or want == got for want, got in zip(shape, arr.shape, strict=False)
        )
        if not ok:
            want_s = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
            raise ValueError(f"{name}: expected shape {want_s}, got {arr.shape}")
    if allow_nan:
        if np.isinf(arr).any():
            raise ValueError(f"{name}: contains an infinite value")
    elif not np.isfinite(arr).all():
        raise ValueError(f"{name}: contains NaN or infinite values")
    return arr


def check_seed(seed: object, name: str = "seed") -> int:
    """Seeds are non-negative Python integers."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or int(seed) < 0:
        raise ValueError(f"{name}: expected a non-negative integer, got {seed!r}")
    return int(seed)


def readonly(arr: np.ndarray) -> np.ndarray:
    """Marks an array read-only (result objects are immutable) and returns it."""
    arr.flags.writeable = False
    return arr
