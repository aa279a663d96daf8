"""Rich, non-repetitive surface textures for the rendered test bed.

Repetitive texture gives structure from motion wrong poses that look right (a repetitive
texture gave "12/12 registered" at a low reprojection error with wrong poses), so
every surface gets its own texture, seeded, with detail at every scale:

- a "dead leaves" image — overlapping disks, ellipses, rectangles and polygons whose sizes
  follow a power law, the classic model of natural-image statistics (occlusion, edges and
  corners at all scales);
- a 1/f colour-noise field underneath and fine grain on top;
- a few strokes and letters (thin high-contrast corners, as on posters and signs).

Real photographs can be mixed in (``photos``): a random crop of a photo, randomly flipped
and colour-shifted, blended with the procedural layer so that two surfaces never share
the same pixels.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
import numpy.typing as npt

U8Image = npt.NDArray[np.uint8]

_LETTERS = "ABCDEFGHJKLMNPQRSTUVWXYZ0123456789#@&%"
_FONTS = (
    cv2.FONT_HERSHEY_SIMPLEX,
    cv2.FONT_HERSHEY_DUPLEX,
    cv2.FONT_HERSHEY_COMPLEX,
    cv2.FONT_HERSHEY_TRIPLEX,
)


# sector → which of (v, p, q, t) feeds (r, g, b), the six 60° sectors of the hue circle
_SECTOR_RGB = np.array([[0, 3, 1], [2, 0, 1], [1, 0, 3], [1, 2, 0], [3, 1, 0], [0, 1, 2]])


def hsv_to_rgb_u8(hsv: npt.ArrayLike) -> U8Image:
    """8-bit HSV ``(..., 3)`` (hue in [0, 180), saturation and value in [0, 255], OpenCV's
    8-bit convention) → 8-bit RGB ``(..., 3)``, computed here in float32 so that rendered
    scenes depend neither on the OpenCV version nor on the CPU.

    The arithmetic is fixed, operation by operation: s = S·(1/255), v = V·(1/255),
    h = H·(6/180) split into sector ⌊h⌋ and fraction f, p = v·(1 − s),
    q = v·fma(−s, f, 1), t = v·fma(−s, 1 − f, 1), each channel ×255. The pixels, taken in
    C order, are truncated to integers in whole runs of 32 and the last ``n mod 32`` are
    rounded: this is what OpenCV 4.9–5.0's ``COLOR_HSV2RGB`` does on one row of ``n``
    pixels on an x86-64 CPU with AVX2 (its vector loop truncates, its scalar tail rounds),
    bit for bit on every input, so the scenes the tests were measured on are unchanged.
    OpenCV 5.1 rounds differently, and other CPUs have other vector widths;
    ``tests/test_render.py`` pins the table.
    """
    a = np.asarray(hsv)
    if a.shape[-1:] != (3,):
        raise ValueError(f"hsv: expected shape (..., 3), got {a.shape}")
    flat = a.reshape(-1, 3)
    f32, f64 = np.float32, np.float64
    s = flat[:, 1].astype(f32) * f32(1 / 255)
    v = flat[:, 2].astype(f32) * f32(1 / 255)
    h = flat[:, 0].astype(f32) * f32(6 / 180)
    whole = np.floor(h)
    frac = h - whole
    sector = whole.astype(np.int64) % 6

    def fused(x: npt.NDArray[np.float32], y: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        # 1 − x·y rounded once (x·y is exact in float64), as a fused multiply-add does
        return (1.0 - x.astype(f64) * y.astype(f64)).astype(f32)

    one = f32(1)
    table = np.stack([v, v * (one - s), v * fused(s, frac), v * fused(s, one - frac)], axis=-1)
    rgb = np.take_along_axis(table, _SECTOR_RGB[sector], axis=-1) * f32(255)
    runs = len(rgb) // 32 * 32
    rgb[:runs] = np.trunc(rgb[:runs])
    rgb[runs:] = np.rint(rgb[runs:])
    return np.clip(rgb, 0, 255).astype(np.uint8).reshape(a.shape)


def _colour_noise(rng: np.random.Generator, h: int, w: int) -> npt.NDArray[np.float32]:
    """A 1/f-like colour field ``(h, w, 3)`` in [0, 255]: noise added at every octave while
    upsampling from 4 texels to the full size (amplitude × 0.6 per octave)."""
    side = max(h, w)
    ch, cw = max(2, round(4 * h / side)), max(2, round(4 * w / side))
    cur = rng.normal(0.0, 28.0, (ch, cw, 3)).astype(np.float32)
    amp = 28.0
    while max(ch, cw) * 2 <= side:
        ch, cw = ch * 2, cw * 2
        amp *= 0.6
        cur = np.asarray(cv2.resize(cur, (cw, ch), interpolation=cv2.INTER_LINEAR), np.float32)
        cur += rng.normal(0.0, amp, cur.shape).astype(np.float32)
    cur = np.asarray(cv2.resize(cur, (w, h), interpolation=cv2.INTER_LINEAR), np.float32)
    base = rng.uniform(70, 190, 3).astype(np.float32)
    return np.clip(cur + base, 0, 255)


def procedural_texture(
    height: int, width: int, *, seed: int, density: float = 1.0, palette: int | None = None
) -> U8Image:
    """A seeded RGB texture ``(height, width, 3)`` uint8 (see module docstring).

    ``density`` scales the number of shapes (per unit area); ``palette`` picks a colour
    family (0–5) so that surfaces look different; ``None`` draws it from the seed.
    """
    rng = np.random.default_rng(seed)
    img = _colour_noise(rng, height, width)
    hues = rng.uniform(0, 180) if palette is None else 30.0 * palette
    area = height * width
    rmax = max(6.0, min(height, width) / 4)
    rmin = 2.5
    # enough leaves to cover the surface about twice: E[πr²] for p(r) ∝ r⁻³
    mean_area = 2 * np.pi * rmin**2 * np.log(rmax / rmin) / (1 - (rmin / rmax) ** 2)
    n = int(density * 1.5 * area / mean_area) + 8
    # power-law radii: p(r) ∝ r^-3 between rmin and rmax (dead-leaves model)
    u = rng.uniform(0, 1, n)
    r = 1.0 / np.sqrt(u / rmin**2 + (1 - u) / rmax**2)
    order = np.argsort(-r)  # big first, small on top
    cx = rng.uniform(-0.05, 1.05, n) * width
    cy = rng.uniform(-0.05, 1.05, n) * height
    hue = (hues + rng.normal(0, 20, n)) % 180
    sat = rng.uniform(0, 1, n) ** 1.5 * 170
    val = rng.uniform(25, 240, n)
    hsv = np.stack([hue, sat, val], axis=1).astype(np.uint8)[None]
    rgb = hsv_to_rgb_u8(hsv[0]).astype(np.float64)
    kind = rng.integers(0, 3, n)
    ang = rng.uniform(0, 180, n)
    ecc = rng.uniform(0.3, 1.0, n)
    canvas = img
    cols = rgb.tolist()
    cxl, cyl, rl = cx.tolist(), cy.tolist(), r.tolist()
    kl, al, el = kind.tolist(), ang.tolist(), ecc.tolist()
    for i in order.tolist():
        c = cols[i]
        centre = (int(cxl[i]), int(cyl[i]))
        ri = max(1, int(rl[i]))
        k = kl[i]
        if k == 0:
            cv2.circle(canvas, centre, ri, c, -1, cv2.LINE_AA)
        elif k == 1:
            axes = (ri, max(1, int(ri * el[i])))
            cv2.ellipse(canvas, centre, axes, al[i], 0, 360, c, -1, cv2.LINE_AA)
        else:
            box = cv2.boxPoints(((cxl[i], cyl[i]), (2 * rl[i], 2 * rl[i] * el[i]), al[i]))
            cv2.fillConvexPoly(canvas, box.astype(np.int32), c, cv2.LINE_AA)
    canvas8 = np.clip(canvas, 0, 255).astype(np.uint8)
    n_lines = int(density * area / 20000) + 2
    for _ in range(n_lines):
        p0 = rng.uniform(0, 1, 2) * (width, height)
        p1 = p0 + rng.normal(0, min(width, height) / 6, 2)
        c = tuple(float(x) for x in rng.uniform(0, 255, 3))
        cv2.line(
            canvas8,
            (round(p0[0]), round(p0[1])),
            (round(p1[0]), round(p1[1])),
            c,
            int(rng.integers(1, 4)),
            cv2.LINE_AA,
        )
    n_text = int(density * area / 30000) + 1
    for _ in range(n_text):
        s = "".join(rng.choice(list(_LETTERS), int(rng.integers(2, 7))))
        scale = float(rng.uniform(0.4, 2.0))
        org = (int(rng.integers(0, width)), int(rng.integers(0, height)))
        c = tuple(float(x) for x in rng.uniform(0, 255, 3))
        font = _FONTS[int(rng.integers(0, len(_FONTS)))]
        cv2.putText(canvas8, s, org, font, scale, c, int(rng.integers(1, 3)), cv2.LINE_AA)
    grain = rng.normal(0.0, 6.0, canvas8.shape).astype(np.float32)
    return np.clip(canvas8 + grain, 0, 255).astype(np.uint8)


def photo_texture(
    photos: Sequence[U8Image], height: int, width: int, *, seed: int, density: float = 1.0
) -> U8Image:
    """A texture made of a random crop of one of ``photos`` (RGB uint8), randomly flipped
    and colour-shifted, blended 60/40 with a :func:`procedural_texture` of the same seed so
    that no two surfaces share pixels."""
    rng = np.random.default_rng(seed)
    photo = photos[int(rng.integers(0, len(photos)))]
    ph, pw = photo.shape[:2]
    aspect = width / height
    ch = int(min(ph, pw / aspect) * rng.uniform(0.4, 1.0))
    cw = max(2, int(ch * aspect))
    ch = max(2, ch)
    y0 = int(rng.integers(0, ph - ch + 1))
    x0 = int(rng.integers(0, pw - cw + 1))
    crop = photo[y0 : y0 + ch, x0 : x0 + cw]
    if rng.uniform() < 0.5:
        crop = crop[:, ::-1]
    crop = np.asarray(
        cv2.resize(np.ascontiguousarray(crop), (width, height), interpolation=cv2.INTER_AREA),
        np.uint8,
    )
    gain = rng.uniform(0.8, 1.2, 3)
    proc = procedural_texture(height, width, seed=seed + 7919, density=density)
    mixed = 0.6 * crop.astype(np.float32) * gain + 0.4 * proc.astype(np.float32)
    return np.clip(mixed, 0, 255).astype(np.uint8)


def load_photos(paths: Sequence[str], max_side: int = 1024) -> list[U8Image]:
    """Reads photos as RGB uint8, downscaled so that the longer side is ≤ ``max_side``.
    Raises ValueError naming a file that cannot be read."""
    out = []
    for p in paths:
        img = cv2.imread(str(p), cv2.IMREAD_COLOR)
        if img is None:
            raise ValueError(f"photos: cannot read an image from {p}")
        s = max_side / max(img.shape[:2])
        if s < 1:
            img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
        out.append(np.asarray(cv2.cvtColor(img, cv2.COLOR_BGR2RGB), np.uint8))
    if not out:
        raise ValueError("photos: no image given")
    return out
