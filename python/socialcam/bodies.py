"""Bodies from photo collections (thesis Sec 5.3.2, issue 11 step 6) — first stage only.

Photos of one event taken by several photographers at different moments are placed on one
clock by their capture times; :func:`photo_times` reads them from EXIF
(``DateTimeOriginal`` + ``SubSecTimeOriginal``, with ``OffsetTimeOriginal`` when present)
or takes them as given. The later stages (``sfm.reconstruct_static`` poses, 2D body
keypoints, identity association, ``reconstruct_trajectories`` per joint) are not built yet.
"""

from __future__ import annotations

import datetime as _dt
import os
from collections.abc import Sequence

import numpy as np

from socialcam._validate import FloatArray, as_float_array

#: EXIF tags (Exif IFD): DateTimeOriginal, SubSecTimeOriginal, OffsetTimeOriginal
_DATETIME, _SUBSEC, _OFFSET = 0x9003, 0x9291, 0x9011
_EXIF_IFD = 0x8769


def _exif_time(path: str | os.PathLike[str]) -> float | None:
    """Capture time of one photo (POSIX seconds) from EXIF, ``None`` when it has none."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            ifd = im.getexif().get_ifd(_EXIF_IFD)
    except OSError as exc:
        raise ValueError(f"photos: cannot read {os.fspath(path)!r} ({exc})") from None
    stamp = ifd.get(_DATETIME)
    if not stamp:
        return None
    try:
        t = _dt.datetime.strptime(str(stamp).strip("\x00 "), "%Y:%m:%d %H:%M:%S")
    except ValueError:
        raise ValueError(
            f"photos: {os.fspath(path)!r} has an unreadable DateTimeOriginal {stamp!r}"
        ) from None
    off = ifd.get(_OFFSET)
    tz = _dt.timezone.utc
    if off:
        sign = -1 if str(off).startswith("-") else 1
        hh, mm = str(off).lstrip("+-").split(":")[:2]
        tz = _dt.timezone(sign * _dt.timedelta(hours=int(hh), minutes=int(mm)))
    sub = str(ifd.get(_SUBSEC, "") or "").strip("\x00 ")
    frac = float(f"0.{sub}") if sub.isdigit() else 0.0
    return t.replace(tzinfo=tz).timestamp() + frac


def photo_times(
    photos: Sequence[str | os.PathLike[str]],
    times: Sequence[float | None] | FloatArray | None = None,
) -> FloatArray:
    """Capture times ``(N,)`` of ``photos`` in seconds on one clock, relative to the
    earliest photo.

    Parameters
    ----------
    photos : image files (JPEG/TIFF with EXIF, or any image when its time is given)
    times : optional given times (s, any common origin) per photo; ``None`` entries (or
        NaN) are read from EXIF. Given and EXIF times must not be mixed: they are on
        different clocks.

    Raises
    ------
    ValueError
        A photo without EXIF ``DateTimeOriginal`` and no given time (the message names the
        file), a file that cannot be read, mixed given and EXIF times, a wrong count.
    """
    if isinstance(photos, (str, os.PathLike)) or not isinstance(photos, Sequence):
        raise ValueError("photos: expected a sequence of image paths")
    n = len(photos)
    if n == 0:
        raise ValueError("photos: no photo given")
    given = np.full(n, np.nan)
    if times is not None:
        if len(times) != n:
            raise ValueError(f"times: expected {n} times (one per photo), got {len(times)}")
        given = as_float_array([np.nan if t is None else t for t in times], "times", (n,),
                               allow_nan=True)  # fmt: skip
    known = np.isfinite(given)
    out = given.copy()
    for i in np.nonzero(~known)[0]:
        t = _exif_time(photos[int(i)])
        if t is None:
            raise ValueError(
                f"photos: {os.fspath(photos[int(i)])!r} has no EXIF DateTimeOriginal; give its "
                "capture time in times="
            )
        out[i] = t
    if known.any() and not known.all():
        raise ValueError(
            "times: give every photo's time or none (given times and EXIF times are on "
            "different clocks)"
        )
    return np.asarray(out - out.min(), dtype=np.float64)
