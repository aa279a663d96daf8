"""Input checks shared by the public API: every message names the argument."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


#: dtype kinds read as real numbers (integers, floats; ``O`` is checked on conversion)
_NUMERIC_KINDS = "iufO"


def _dtype_words(dtype: np.dtype[Any]) -> str:
    kind = {"b": "booleans", "c": "complex numbers", "U": "text", "S": "bytes"}
    return kind.get(dtype.kind, f"{dtype} values")


def as_int_array(value: object, name: str) -> npt.NDArray[np.int64]:
    """An int64 array from integer dtypes only: ``[1, 0.5]`` and booleans are refused, not
    truncated or read as 0/1, and unsigned values beyond int64 are refused, not wrapped."""
    a = np.asarray(value)
    if a.size == 0:
        return a.astype(np.int64)
    if not np.issubdtype(a.dtype, np.integer):
        raise ValueError(f"{name}: expected integers, got {_dtype_words(a.dtype)}")
    if np.issubdtype(a.dtype, np.unsignedinteger) and int(a.max()) > _I64_MAX:
        raise ValueError(f"{name}: values must fit in int64 (largest {_I64_MAX})")
    return a.astype(np.int64)


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
        raw = np.asarray(value)
        # bool, complex and text would convert (True → 1, the imaginary part dropped,
        # "1.5" → 1.5), each almost surely a caller's mistake
        if raw.dtype.kind not in _NUMERIC_KINDS and raw.size:
            raise ValueError(f"expected real numbers, got {_dtype_words(raw.dtype)}")
        arr = np.ascontiguousarray(raw, dtype=np.float64)
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


#: largest share of a scene's extent that float64's rounding of its coordinates may take
#: (:func:`check_rounding`)
ROUNDING_SHARE = 1e-3


def check_rounding(coords: np.ndarray, name: str, what: str, extent: float | None = None) -> None:
    """Refuses ``(N, 3)`` coordinates so far from the origin that float64 rounds them
    (``eps`` times their size) by more than ``ROUNDING_SHARE`` of ``extent`` metres, the
    size that matters to the geometry (``what``: "the bone", "the eyes' spread"; by default
    the coordinates' own largest range along an axis); a zero extent passes (the caller's
    degeneracy checks name it). Translation is otherwise harmless: a scene at 1e6 m (UTM,
    ECEF) keeps its answers."""
    if extent is None:
        extent = float(np.ptp(coords, axis=0).max()) if len(coords) else 0.0
    reach = float(np.abs(coords).max(initial=0.0))
    rounding = reach * float(np.finfo(np.float64).eps)
    if extent > 0 and rounding > ROUNDING_SHARE * extent:
        raise ValueError(
            f"{name}: coordinates up to {reach:.3g} m from the origin; float64 rounds them by "
            f"{rounding:.2g} m, more than {ROUNDING_SHARE:g} of {what} ({extent:.3g} m): "
            "subtract a point of the scene from every position"
        )


def check_seed(seed: object, name: str = "seed") -> int:
    """Seeds are integers in ``[0, 2⁶⁴)`` (the core's seed is a u64)."""
    if (
        isinstance(seed, bool)
        or not isinstance(seed, (int, np.integer))
        or not 0 <= int(seed) < 2**64
    ):
        raise ValueError(f"{name}: expected an integer in [0, 2**64), got {seed!r}")
    return int(seed)


def readonly(arr: np.ndarray) -> np.ndarray:
    """Marks an array read-only (result objects are immutable) and returns it."""
    arr.flags.writeable = False
    return arr


def readonly_fields(obj: object) -> None:
    """Marks every array field of a dataclass result read-only (for results assembled from
    parts that were filled in place first)."""
    for f in dataclasses.fields(obj):  # type: ignore[arg-type]
        value = getattr(obj, f.name)
        if isinstance(value, np.ndarray):
            value.flags.writeable = False


# --- scalar options -----------------------------------------------------------------
# One layer, one style: every public function and every options dataclass checks its
# scalar arguments with these helpers, so a bad value raises ``ValueError("name: ...")``
# (never a TypeError, OverflowError or a raw numpy message, and never a silent truncation
# such as ``k=2.9`` → 2).

_I64_MAX = 2**63 - 1


def check_int(
    value: object,
    name: str,
    *,
    min: int | None = None,
    max: int | None = None,
) -> int:
    """An integer option: Python/numpy integers only (no bool, no float), within bounds."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name}: expected an integer, got {value!r}")
    v = int(value)
    lo = min
    hi = _I64_MAX if max is None else max
    if lo is not None and v < lo:
        raise ValueError(f"{name}: expected an integer ≥ {lo}, got {v}")
    if v > hi:
        raise ValueError(f"{name}: expected an integer ≤ {hi}, got {v}")
    return v


def check_float(
    value: object,
    name: str,
    *,
    min: float | None = None,
    max: float | None = None,
    min_exclusive: bool = False,
    allow_inf: bool = False,
) -> float:
    """A real option: finite (unless ``allow_inf``), not NaN, within bounds."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name}: expected a real number, got {value!r}")
    v = float(value)
    if np.isnan(v) or (np.isinf(v) and not allow_inf):
        raise ValueError(f"{name}: expected a finite number, got {v}")
    if min is not None and (v <= min if min_exclusive else v < min):
        raise ValueError(
            f"{name}: expected a number {'>' if min_exclusive else '≥'} {min}, got {v}"
        )
    if max is not None and v > max:
        raise ValueError(f"{name}: expected a number ≤ {max}, got {v}")
    return v


def check_bool(value: object, name: str) -> bool:
    """A flag: ``True``/``False`` (Python or numpy) only, never a truthy number or string."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name}: expected a bool, got {value!r}")
    return bool(value)


def check_sequence(value: object, name: str) -> list[Any]:
    """A sequence argument (frames, tracks, ...) as a list; anything else, a string
    included, is a ``ValueError`` naming the argument."""
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        raise ValueError(f"{name}: expected a sequence, got {type(value).__name__}")
    return list(value)


def check_choice(value: object, name: str, choices: Sequence[str]) -> str:
    """A string option from a fixed set."""
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name}: expected one of {', '.join(map(repr, choices))}, got {value!r}")
    return value


# --- sizes --------------------------------------------------------------------------
#: The largest array (bytes) allocated on behalf of a user-given size; the Rust core uses
#: the same limit (``socialcore::error::MAX_ALLOC_BYTES``).
MAX_ALLOC_BYTES = 2 << 30


def check_size(name: str, shape: Sequence[int], itemsize: int = 8) -> None:
    """Refuses, with ``ValueError`` naming ``name``, an array of ``shape`` that would need
    more than :data:`MAX_ALLOC_BYTES` (instead of an abort or a ``MemoryError`` later)."""
    total = itemsize
    for d in shape:
        total *= max(int(d), 0)
    if total > MAX_ALLOC_BYTES:
        dims = ", ".join(str(int(d)) for d in shape)
        raise ValueError(
            f"{name}: too large: an array of shape ({dims}) would need more than "
            f"{MAX_ALLOC_BYTES >> 30} GiB"
        )


# --- options dataclasses -------------------------------------------------------------
_T = TypeVar("_T")


def apply_overrides(options: object, cls: type[_T], overrides: dict[str, object]) -> _T:
    """``options`` (an instance of the frozen dataclass ``cls``, or ``None`` for the
    defaults) with the fields named in ``overrides`` replaced; an unknown name raises
    ``ValueError`` naming it. Validation happens in ``cls.__post_init__``."""
    if options is None:
        base = cls()
    elif isinstance(options, cls):
        base = options
    else:
        raise ValueError(f"options: expected a {cls.__name__}, got {type(options).__name__}")
    if not overrides:
        return base
    names = {f.name for f in dataclasses.fields(base)}  # type: ignore[arg-type]
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise ValueError(
            f"{unknown[0]}: not an option of {cls.__name__} (options: {', '.join(sorted(names))})"
        )
    return dataclasses.replace(base, **overrides)  # type: ignore[type-var]
