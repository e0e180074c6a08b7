"""A small ray caster for simulated scenes: textured ellipsoids and rectangles, exact depth.

Each camera casts one ray per pixel (through its own lens model, distortion included). Primitives are
intersected only inside the pixel box their bounding sphere projects to, so a person-sized subject costs
a fraction of the image. The same rays give colour, depth along the optical axis and the subject matte,
so the ground truth is exact by construction.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]


@dataclass
class Texture:
    """An RGB float32 image in [0, 1] with a mip pyramid, so minified textures do not alias."""

    levels: list[F32]

    @classmethod
    def from_image(cls, rgb: NDArray[np.floating]) -> Texture:
        img = np.asarray(rgb, dtype=np.float32)
        if img.ndim == 2:
            img = np.repeat(img[..., None], 3, axis=2)
        img = np.ascontiguousarray(img[..., :3])
        # sizes divisible by 2^k, so every level covers exactly the same area as the first
        h0, w0 = img.shape[:2]
        k = max(0, int(np.log2(max(min(h0, w0), 8) / 8)))
        h, w = max(h0 // 2**k, 1) * 2**k, max(w0 // 2**k, 1) * 2**k
        if (h, w) != (h0, w0):
            interp = cv2.INTER_AREA if w < w0 else cv2.INTER_CUBIC
            img = np.asarray(cv2.resize(img, (w, h), interpolation=interp), dtype=np.float32)
        levels = [img]
        for _ in range(k):
            # 2x2 averaging keeps texel centres aligned across levels (pyrDown shifts them a quarter texel)
            prev = levels[-1]
            half = cv2.resize(prev, (prev.shape[1] // 2, prev.shape[0] // 2), interpolation=cv2.INTER_AREA)
            levels.append(np.asarray(half, dtype=np.float32))
        return cls(levels)

    def sample(self, s: F32, t: F32, texels_per_pixel: float) -> F32:
        """Bilinear lookup at (s, t) in [0, 1] (mirrored outside) in the first level with at most one
        texel per pixel: magnified, never minified, so sharp edges (a calibration target's corners)
        keep their true position instead of aliasing."""
        level = int(np.clip(np.ceil(np.log2(max(texels_per_pixel, 1.0))), 0, len(self.levels) - 1))
        img = self.levels[level]
        h, w = img.shape[:2]
        n = s.size
        cols = 1024
        rows = -(-n // cols)
        mx = np.zeros(rows * cols, dtype=np.float32)
        my = np.zeros(rows * cols, dtype=np.float32)
        # s, t are in level-independent units: the level's own size scales them
        mx[:n] = s * w - 0.5
        my[:n] = t * h - 0.5
        # remap wants maps below 32767 in each dimension: lay the samples out as rows of 1024
        out = cv2.remap(
            img, mx.reshape(rows, cols), my.reshape(rows, cols), cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101
        )
        return np.asarray(out.reshape(-1, 3)[:n], dtype=np.float32)


@dataclass
class Primitive:
    """Common part of scene primitives: texture, albedo tint, and whether it belongs to the subject."""

    texture: Texture
    subject: bool = True
    tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    name: str = ""
    # world extent of the texture across (metres), for mip selection
    texture_extent_m: float = 1.0
    # thinner than a pixel (a strand of hair): one ray per pixel may miss it, so supersampling covers all of
    # its box instead of only where the pixel centres show an edge
    thin: bool = False

    def bounding_sphere(self) -> tuple[F64, float]:
        raise NotImplementedError

    def hull(self) -> F64:
        """Points (N x 3) whose convex hull contains the primitive, for screen-space culling."""
        raise NotImplementedError

    def intersect(self, origin: F64, dirs: F32) -> F32:
        """Ray parameter of the first hit (inf where missed) for rays origin + t * dirs."""
        raise NotImplementedError

    def surface(self, points: F32) -> tuple[F32, F32, F32]:
        """Texture coordinates (s, t) and unit normals at surface points (N x 3)."""
        raise NotImplementedError


@dataclass
class Ellipsoid(Primitive):
    centre: F64 = field(default_factory=lambda: np.zeros(3))
    radii: F64 = field(default_factory=lambda: np.ones(3))
    rotation: F64 = field(default_factory=lambda: np.eye(3))  # local -> world

    def bounding_sphere(self) -> tuple[F64, float]:
        return self.centre, float(np.max(self.radii))

    def hull(self) -> F64:
        box = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * self.radii
        return np.asarray(self.centre + box @ self.rotation.T, dtype=np.float64)

    def _to_unit(self) -> F64:
        return np.asarray(np.diag(1.0 / self.radii) @ self.rotation.T, dtype=np.float64)

    def intersect(self, origin: F64, dirs: F32) -> F32:
        m = self._to_unit().astype(np.float32)
        o = (m @ (origin - self.centre)).astype(np.float32)
        d = dirs @ m.T
        a = np.einsum("...i,...i->...", d, d)
        b = d @ o
        c = float(o @ o) - 1.0
        disc = b * b - a * c
        hit = disc >= 0
        with np.errstate(invalid="ignore", divide="ignore"):
            t = (-b - np.sqrt(np.where(hit, disc, 0))) / a
        return np.where(hit & (t > 0), t, np.float32(np.inf)).astype(np.float32)

    def surface(self, points: F32) -> tuple[F32, F32, F32]:
        m = self._to_unit().astype(np.float32)
        p = (points - self.centre.astype(np.float32)) @ m.T  # on the unit sphere
        phi = np.arctan2(p[:, 0], -p[:, 2])  # 0 facing the rig (local -z)
        theta = np.arcsin(np.clip(p[:, 1], -1, 1))
        s = 0.5 + phi / np.pi
        t = 0.5 + theta / np.pi
        normal = (p / self.radii.astype(np.float32)) @ self.rotation.T.astype(np.float32)
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        return s.astype(np.float32), t.astype(np.float32), normal.astype(np.float32)


@dataclass
class Rectangle(Primitive):
    """A flat rectangle: centre, two in-plane unit axes (u right, v down) and half extents."""

    centre: F64 = field(default_factory=lambda: np.zeros(3))
    u: F64 = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    v: F64 = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    half: tuple[float, float] = (1.0, 1.0)

    @property
    def normal(self) -> F64:
        n = np.cross(self.u, self.v)
        return np.asarray(n / np.linalg.norm(n), dtype=np.float64)

    def bounding_sphere(self) -> tuple[F64, float]:
        return self.centre, float(np.hypot(*self.half))

    def hull(self) -> F64:
        a, b = self.half
        return np.asarray(
            [self.centre + su * a * self.u + sv * b * self.v for su in (-1, 1) for sv in (-1, 1)], dtype=np.float64
        )

    def intersect(self, origin: F64, dirs: F32) -> F32:
        n = self.normal.astype(np.float32)
        denom = dirs @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.float32((self.centre - origin) @ self.normal) / denom
        p_rel = origin.astype(np.float32) - self.centre.astype(np.float32)
        su = t * (dirs @ self.u.astype(np.float32)) + np.float32(p_rel @ self.u)
        sv = t * (dirs @ self.v.astype(np.float32)) + np.float32(p_rel @ self.v)
        inside = (np.abs(su) <= self.half[0]) & (np.abs(sv) <= self.half[1]) & (t > 0) & np.isfinite(t)
        return np.where(inside, t, np.float32(np.inf)).astype(np.float32)

    def texcoords(self, points: F32) -> tuple[F32, F32]:
        rel = points - self.centre.astype(np.float32)
        s = 0.5 + (rel @ self.u.astype(np.float32)) / (2 * self.half[0])
        t = 0.5 + (rel @ self.v.astype(np.float32)) / (2 * self.half[1])
        return s.astype(np.float32), t.astype(np.float32)

    def surface(self, points: F32) -> tuple[F32, F32, F32]:
        s, t = self.texcoords(points)
        normal = np.broadcast_to(-self.normal.astype(np.float32), points.shape)
        return s, t, np.ascontiguousarray(normal)


@dataclass
class Scene:
    """Primitives and a light. ``background`` is what a ray that hits nothing sees. The first
    ``static`` primitives never move (the screen or wall behind the subject): they are rendered once
    per camera and reused."""

    primitives: list[Primitive]
    light_dir: F64 = field(default_factory=lambda: np.array([-0.4, -0.5, -0.75]))  # towards the light
    ambient: float = 0.45
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    static: int = 0


@dataclass
class RenderResult:
    rgb: F32  # H x W x 3 in [0, 1], before camera effects
    depth: F32  # ray parameter = depth along the camera's optical axis (inf where nothing was hit)
    subject: NDArray[np.bool_]  # pixels showing a subject primitive
    ids: NDArray[np.int16]  # index of the visible primitive, -1 for none


@dataclass
class RayCamera:
    """Per-pixel rays of one camera: origin (rig coords) and directions scaled to unit optical-axis depth."""

    origin: F64
    dirs: F32  # H x W x 3
    focal_px: float
    project_box: Callable[[F64], tuple[int, int, int, int] | None]  # hull points -> pixel box

    @property
    def shape(self) -> tuple[int, int]:
        return self.dirs.shape[0], self.dirs.shape[1]


def render(
    scene: Scene, cam: RayCamera, *, colour: bool = True, base: RenderResult | None = None, skip: int = 0
) -> RenderResult:
    """Render ``scene`` through ``cam``. With ``base`` (a render of the scene's first ``skip`` primitives,
    e.g. the static background), only the remaining primitives are cast and composited over it."""
    h, w = cam.shape
    if base is None:
        depth = np.full((h, w), np.inf, dtype=np.float32)
        ids = np.full((h, w), -1, dtype=np.int16)
        subject = np.zeros((h, w), dtype=bool)
        rgb = np.empty((h, w, 3), dtype=np.float32)
        rgb[:] = scene.background
    else:
        depth, ids, subject, rgb = base.depth.copy(), base.ids.copy(), base.subject.copy(), base.rgb.copy()
    boxes: dict[int, tuple[int, int, int, int]] = {}
    for k in range(skip, len(scene.primitives)):
        prim = scene.primitives[k]
        box = cam.project_box(prim.hull())
        if box is None:
            continue
        boxes[k] = box
        x0, y0, x1, y1 = box
        t = prim.intersect(cam.origin, cam.dirs[y0:y1, x0:x1])
        sub = depth[y0:y1, x0:x1]
        closer = t < sub
        np.copyto(sub, t, where=closer)
        np.copyto(ids[y0:y1, x0:x1], np.int16(k), where=closer)
    light = (scene.light_dir / np.linalg.norm(scene.light_dir)).astype(np.float32)
    for k, (x0, y0, x1, y1) in boxes.items():
        prim = scene.primitives[k]
        mask = ids[y0:y1, x0:x1] == k
        if not mask.any():
            continue
        if prim.subject:
            subject[y0:y1, x0:x1] |= mask
        else:
            subject[y0:y1, x0:x1] &= ~mask
        if not colour:
            continue
        whole = bool(mask.all())  # a background plane filling its box: slices, not boolean gathers
        t = depth[y0:y1, x0:x1].reshape(-1) if whole else depth[y0:y1, x0:x1][mask]
        dirs = cam.dirs[y0:y1, x0:x1].reshape(-1, 3) if whole else cam.dirs[y0:y1, x0:x1][mask]
        pts = cam.origin.astype(np.float32) + t[:, None] * dirs
        if isinstance(prim, Rectangle):  # one normal for the whole plane
            s, tt = prim.texcoords(pts)
            normal = -prim.normal.astype(np.float32)[None, :]
        else:
            s, tt, normal = prim.surface(pts)
        # texels per pixel: texture width over the primitive's extent on screen
        distance = float(np.linalg.norm(prim.bounding_sphere()[0] - cam.origin))
        on_screen = cam.focal_px * prim.texture_extent_m / max(distance, 1e-3)
        tpp = prim.texture.levels[0].shape[1] / max(on_screen, 1.0)
        if isinstance(prim, Rectangle):
            # a plane seen at a grazing angle is minified across its tilt: choose the level for that
            # direction (a blurrier plane, instead of one that aliases differently in every camera)
            view = cam.origin - prim.centre
            tpp /= max(abs(float(prim.normal @ view)) / float(np.linalg.norm(view)), 0.05)
        albedo = prim.texture.sample(s, tt, tpp) * np.asarray(prim.tint, dtype=np.float32)
        lambert = np.clip(normal @ light, 0.0, 1.0)
        shade = scene.ambient + (1.0 - scene.ambient) * lambert
        if whole:
            rgb[y0:y1, x0:x1] = (albedo * shade[:, None]).reshape(y1 - y0, x1 - x0, 3)
        else:
            rgb[y0:y1, x0:x1][mask] = albedo * shade[:, None]
    return RenderResult(rgb=rgb, depth=depth, subject=subject, ids=ids)
