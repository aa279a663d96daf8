"""A small software rasteriser for textured rectangles (no OpenGL): per-plane homography
warps with a depth test, in OpenCV.

A :class:`Plane` is a rectangle ``origin + a·u + b·v`` (``0 ≤ a ≤ width``, ``0 ≤ b ≤
height``) carrying a texture image whose x axis runs along ``u`` and y axis along ``v``;
it is seen from the side its normal ``v × u`` points to (when ``u`` is "right" and ``v``
"down" for a viewer, the normal points at the viewer). Texel ``(x, y)`` (OpenCV
convention, integer = texel centre) is the point ``origin + (x + ½)·sᵤ·u + (y + ½)·sᵥ·v``
with ``sᵤ = width / texture_width`` metres per texel.

Per plane and frame the renderer clips the rectangle against the near plane, projects it,
warps the texture with the homography ``H = K R [sᵤu, sᵥv, origin + ½sᵤu + ½sᵥv − C]``
(texel → pixel, thesis Eq A.1 applied to the plane) into the polygon's bounding box, and
keeps the pixels inside the polygon that are nearer than what is already drawn. Inverse
depth is affine in the pixel coordinates on a plane, so the depth test costs one affine
map per pixel. Textures are mip-mapped by exact 2×2 averaging (level ``L`` texel ``x_L``
is level-0 texel ``2^L (x_L + ½) − ½``) and each plane is drawn from the level matching
its on-screen scale, so distant surfaces do not alias; large surfaces are cut into tiles
so that each tile picks its own level.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
import numpy.typing as npt

from socialcam._validate import FloatArray

U8Image = npt.NDArray[np.uint8]

NEAR = 0.03  # metres: near clipping plane
MIP_LEVELS = 5


@dataclass(frozen=True)
class Plane:
    """A textured rectangle (see the module docstring).

    Attributes
    ----------
    name : str
    origin : (3,) corner, metres
    u, v : (3,) unit vectors along the texture's x and y axes (orthogonal)
    size : (2,) extent along ``u`` and ``v``, metres
    texture : index into the texture list
    """

    name: str
    origin: FloatArray
    u: FloatArray
    v: FloatArray
    size: tuple[float, float]
    texture: int
    normal: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # unit normal v × u, pointing to the side the plane is seen from
        u, v = self.u, self.v
        n = np.array(
            [v[1] * u[2] - v[2] * u[1], v[2] * u[0] - v[0] * u[2], v[0] * u[1] - v[1] * u[0]]
        )
        object.__setattr__(self, "normal", n)

    def corners(self) -> FloatArray:
        """``(4, 3)`` corners in order origin, +u, +u+v, +v."""
        a = self.size[0] * self.u
        b = self.size[1] * self.v
        return np.stack([self.origin, self.origin + a, self.origin + a + b, self.origin + b])

    def point(self, a: npt.ArrayLike, b: npt.ArrayLike) -> FloatArray:
        """World points ``(..., 3)`` at plane coordinates ``a, b`` (metres)."""
        a_ = np.asarray(a, dtype=np.float64)[..., None]
        b_ = np.asarray(b, dtype=np.float64)[..., None]
        return self.origin + a_ * self.u + b_ * self.v

    def texel(self, a: npt.ArrayLike, b: npt.ArrayLike, shape: tuple[int, ...]) -> FloatArray:
        """Texel coordinates ``(..., 2)`` (x, y; OpenCV convention) of plane coordinates
        ``a, b`` in a texture of ``shape (th, tw, ...)``."""
        th, tw = shape[:2]
        x = np.asarray(a, dtype=np.float64) / self.size[0] * tw - 0.5
        y = np.asarray(b, dtype=np.float64) / self.size[1] * th - 0.5
        return np.stack([x, y], axis=-1)

    def to_dict(self) -> dict[str, object]:
        return {
            "name": self.name,
            "origin": self.origin.tolist(),
            "u": self.u.tolist(),
            "v": self.v.tolist(),
            "size": list(self.size),
            "texture": self.texture,
        }


def face(
    name: str,
    centre: npt.ArrayLike,
    normal: npt.ArrayLike,
    width: float,
    height: float,
    texture: int,
    right: npt.ArrayLike | None = None,
) -> Plane:
    """A rectangle of ``width × height`` metres centred at ``centre`` and seen from the
    side of ``normal``. Vertical faces have ``u`` horizontal and ``v`` pointing down (the
    texture is upright); horizontal faces need ``right`` (the direction of ``u``)."""
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.sqrt(n @ n)
    if right is None:
        r = np.array([-n[1], n[0], 0.0])  # z × n
    else:
        r = np.asarray(right, dtype=np.float64)
        r = r - (r @ n) * n
    r = r / np.sqrt(r @ r)
    d = _cross(r, n)  # v × u = n with u = r, v = d
    c = np.asarray(centre, dtype=np.float64)
    origin = c - 0.5 * width * r - 0.5 * height * d
    return Plane(name, origin, r, d, (float(width), float(height)), texture)


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """Cross product of two 3-vectors (np.cross is slow on single vectors)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def tiles(plane: Plane, max_size: float) -> list[Plane]:
    """Cuts ``plane`` into tiles of at most ``max_size`` metres a side; each tile keeps the
    texture of the whole plane (see :func:`Renderer.draw`, which maps tile coordinates back
    to the parent's texels)."""
    na = max(1, int(np.ceil(plane.size[0] / max_size)))
    nb = max(1, int(np.ceil(plane.size[1] / max_size)))
    if na == nb == 1:
        return [plane]
    out = []
    wa, wb = plane.size[0] / na, plane.size[1] / nb
    for i in range(na):
        for j in range(nb):
            o = plane.origin + i * wa * plane.u + j * wb * plane.v
            out.append(Plane(f"{plane.name}[{i},{j}]", o, plane.u, plane.v, (wa, wb), -1))
    return out


@dataclass
class _Tile:
    plane: Plane  # the tile's rectangle
    parent: Plane  # the plane whose texture it shows


@dataclass
class _Batch:
    """Tiles as arrays, for culling all of them at once."""

    tiles: list[_Tile]
    corners: FloatArray  # (N, 4, 3)
    normals: FloatArray  # (N, 3)
    depth_test: bool = True

    @staticmethod
    def of(items: Sequence[_Tile], depth_test: bool = True) -> _Batch:
        if not items:
            return _Batch([], np.zeros((0, 4, 3)), np.zeros((0, 3)), depth_test)
        return _Batch(
            list(items),
            np.stack([t.plane.corners() for t in items]),
            np.stack([t.parent.normal for t in items]),
            depth_test,
        )


@dataclass
class Renderer:
    """Draws textured planes into a ``width × height`` pinhole image of intrinsics ``K``.

    ``textures`` are RGB uint8 images; their dimensions are cropped to a multiple of
    ``2**(MIP_LEVELS-1)`` so that every mip level is exact.
    """

    K: FloatArray
    width: int
    height: int
    textures: Sequence[U8Image]
    tile_size: float = 3.0
    background: int = 90
    _mips: list[list[U8Image]] = field(default_factory=list, init=False)
    _Kinv: FloatArray = field(default_factory=lambda: np.eye(3), init=False)
    _xs: npt.NDArray[np.float32] = field(
        default_factory=lambda: np.zeros(0, np.float32), init=False
    )
    _ys: npt.NDArray[np.float32] = field(
        default_factory=lambda: np.zeros(0, np.float32), init=False
    )

    def __post_init__(self) -> None:
        self._Kinv = np.asarray(np.linalg.inv(self.K), dtype=np.float64)
        self._mips = [mip_pyramid(t) for t in self.textures]
        self._xs = np.arange(self.width, dtype=np.float32)
        self._ys = np.arange(self.height, dtype=np.float32)

    def texture_shape(self, index: int) -> tuple[int, int]:
        h, w = self._mips[index][0].shape[:2]
        return h, w

    def prepare(
        self, planes: Sequence[Plane], tile_size: float | None = None, *, depth_test: bool = True
    ) -> _Batch:
        """Tiles planes (see :func:`tiles`) into a batch; static planes are prepared once.
        ``depth_test=False`` is for the first batch of surfaces that cannot occlude each
        other (the inside of a convex room): they are drawn without comparing depths."""
        ts = self.tile_size if tile_size is None else tile_size
        return _Batch.of([_Tile(t, p) for p in planes for t in tiles(p, ts)], depth_test)

    def render(self, R: FloatArray, C: FloatArray, *batches: _Batch) -> U8Image:
        """An RGB frame ``(height, width, 3)`` of the tiles seen by the camera ``R, C``."""
        img = np.full((self.height, self.width, 3), self.background, np.uint8)
        zbuf = np.zeros((self.height, self.width), np.float32)  # inverse depth, 0 = far
        for b in batches:
            if not b.tiles:
                continue
            front = np.einsum("nk,nk->n", b.normals, C - b.corners[:, 0]) > 1e-9
            Xc = (b.corners - C) @ R.T  # (N, 4, 3)
            z = Xc[..., 2]
            ahead = (z >= NEAR).any(axis=1)
            zs = np.maximum(z, NEAR)
            px = self.K[0, 0] * Xc[..., 0] / zs + self.K[0, 2]
            py = self.K[1, 1] * Xc[..., 1] / zs + self.K[1, 2]
            allin = (z >= NEAR).all(axis=1)
            off = allin & (
                (px < -1).all(axis=1)
                | (px > self.width).all(axis=1)
                | (py < -1).all(axis=1)
                | (py > self.height).all(axis=1)
            )
            for i in np.nonzero(front & ahead & ~off)[0]:
                self._draw(img, zbuf, R, C, Xc[i], b.tiles[i].parent, b.depth_test)
        return img

    def _draw(
        self,
        img: U8Image,
        zbuf: npt.NDArray[np.float32],
        R: FloatArray,
        C: FloatArray,
        Xc: FloatArray,
        parent: Plane,
        depth_test: bool = True,
    ) -> None:
        """Draws one tile (corners ``Xc (4, 3)`` in the camera frame) of ``parent``."""
        poly = _clip_near(Xc, NEAR)
        if poly.shape[0] < 3:
            return
        pix = poly @ self.K.T
        pix = pix[:, :2] / pix[:, 2:3]
        x0 = max(int(np.floor(pix[:, 0].min())), 0)
        x1 = min(int(np.ceil(pix[:, 0].max())) + 1, self.width)
        y0 = max(int(np.floor(pix[:, 1].min())), 0)
        y1 = min(int(np.ceil(pix[:, 1].max())) + 1, self.height)
        if x1 <= x0 or y1 <= y0:
            return
        bw, bh = x1 - x0, y1 - y0
        # inverse depth 1/z = gᵀ [x, y, 1] on the plane (n_c · X_c = d_c)
        n_c = R @ parent.normal
        d_c = float(n_c @ Xc[0])
        if abs(d_c) < 1e-12:
            return
        g = ((self._Kinv.T @ n_c) / d_c).astype(np.float32)
        invz = np.add.outer(g[1] * self._ys[y0:y1] + g[2], g[0] * self._xs[x0:x1])
        mask = np.zeros((bh, bw), np.uint8)
        cv2.fillConvexPoly(
            mask, np.round((pix - (x0, y0)) * 16).astype(np.int32), (255,), cv2.LINE_8, 4
        )
        sub_z = zbuf[y0:y1, x0:x1]
        if depth_test:
            cv2.bitwise_and(mask, cv2.compare(invz, sub_z, cv2.CMP_GT), dst=mask)
            if not cv2.countNonZero(mask):
                return
        # texel → pixel homography of the parent's level-0 texture
        mips = self._mips[parent.texture]
        th, tw = mips[0].shape[:2]
        su, sv = parent.size[0] / tw, parent.size[1] / th
        o = parent.origin + 0.5 * su * parent.u + 0.5 * sv * parent.v - C
        H = self.K @ R @ np.column_stack([su * parent.u, sv * parent.v, o])
        # mip level: texel area per pixel at the tile's centre ≈ d² / (f² cos θ sᵤ sᵥ)
        m = poly.mean(axis=0)
        d2 = float(m @ m)
        cos = abs(float(n_c @ m)) / np.sqrt(d2)
        area = d2 / (self.K[0, 0] * self.K[1, 1] * max(cos, 0.05) * su * sv)
        level = 0
        if area > 1.0:
            level = int(min(len(mips) - 1, max(0, np.floor(0.5 * np.log2(area) + 0.3))))
        s = float(2**level)
        S = np.array([[s, 0, 0.5 * s - 0.5], [0, s, 0.5 * s - 0.5], [0, 0, 1.0]])
        T = np.array([[1.0, 0, -x0], [0, 1.0, -y0], [0, 0, 1.0]])
        warped = cv2.warpPerspective(
            mips[level], T @ H @ S, (bw, bh), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT
        )
        cv2.copyTo(warped, mask, img[y0:y1, x0:x1])
        cv2.copyTo(invz, mask, sub_z)


def mip_pyramid(texture: U8Image) -> list[U8Image]:
    """Exact 2×2-average mip levels of ``texture`` (cropped to a multiple of 16)."""
    m = 2 ** (MIP_LEVELS - 1)
    h, w = (texture.shape[0] // m) * m, (texture.shape[1] // m) * m
    if h == 0 or w == 0:
        raise ValueError(f"texture: at least {m}×{m} texels needed, got {texture.shape[:2]}")
    levels = [np.ascontiguousarray(texture[:h, :w])]
    for _ in range(MIP_LEVELS - 1):
        t = levels[-1].astype(np.uint16)
        t = (t[0::2, 0::2] + t[1::2, 0::2] + t[0::2, 1::2] + t[1::2, 1::2] + 2) // 4
        levels.append(t.astype(np.uint8))
    return levels


def _clip_near(P: FloatArray, near: float) -> FloatArray:
    """Sutherland–Hodgman clip of a convex polygon ``(n, 3)`` (camera frame) to ``z ≥ near``."""
    out = []
    n = P.shape[0]
    for i in range(n):
        a, b = P[i], P[(i + 1) % n]
        ina, inb = a[2] >= near, b[2] >= near
        if ina:
            out.append(a)
        if ina != inb:
            t = (near - a[2]) / (b[2] - a[2])
            out.append(a + t * (b - a))
    return np.array(out) if out else np.zeros((0, 3))
