"""Scenes for the simulated array: the paper's presenter in front of a green screen, and a ChArUco board.

Surfaces carry real photographs (the images that ship inside scikit-image), not noise, so matching
behaves as it does on real footage. Geometry is in rig coordinates: metres, x right, y down, z towards
the scene, origin at the centre of the array.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache, lru_cache
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray
from rigctl.simulators.raycast import Ellipsoid, Primitive, Rectangle, Scene, Texture
from rigctl.simulators.settings import SimSettings

from rigctl.board import BoardSpec

GREEN = (0.16, 0.62, 0.24)
PRESENTER_DEPTH_M = 0.9  # hands to the back of the torso
MOTION_PERIOD_S = 1.6


F64 = NDArray[np.float64]
PHOTO_FILES = {"immunohistochemistry": "ihc.png", "rocket": "rocket.jpg"}  # the rest are NAME.png


@cache
def _photo(name: str) -> NDArray[np.float32]:
    import skimage.data  # imported here: only the photo textures need it

    # the files that ship inside scikit-image, decoded by OpenCV: its loader would first import
    # skimage.io and its plugins, half a second of a cold start
    path = Path(skimage.data.__file__).parent / PHOTO_FILES.get(name, f"{name}.png")
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    raw = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB) if bgr is not None else getattr(skimage.data, name)()
    img = np.asarray(raw, dtype=np.float32) / 255.0
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    return np.ascontiguousarray(img[..., :3])


@cache
def _texture(kind: str, part: str) -> Texture:
    """The texture of one body part for a texture kind (photo, flat, repetitive)."""
    flat = {
        "head": (0.85, 0.66, 0.55),
        "skin": (0.86, 0.68, 0.58),
        "torso": (0.20, 0.25, 0.55),
        "arm": (0.22, 0.27, 0.58),
        "desk": (0.55, 0.38, 0.22),
        "desk_front": (0.45, 0.30, 0.18),
    }
    if kind == "flat":
        return Texture.from_image(np.full((16, 16, 3), flat[part], dtype=np.float32))
    if kind == "repetitive":
        _yy, xx = np.mgrid[0:256, 0:256].astype(np.float32)
        stripes = 0.5 + 0.4 * np.sign(np.sin(xx * (2 * math.pi / 16)))
        img = stripes[..., None] * np.asarray(flat[part], dtype=np.float32) * 1.4
        return Texture.from_image(np.clip(img, 0, 1))
    crops = {
        "head": ("astronaut", (slice(20, 250), slice(150, 340))),
        "skin": ("coffee", (slice(0, 200), slice(0, 200))),
        "torso": ("immunohistochemistry", (slice(None), slice(None))),
        "arm": ("chelsea", (slice(None), slice(None))),
        "desk": ("coffee", (slice(None), slice(None))),
        "desk_front": ("rocket", (slice(None), slice(None))),
    }
    name, (ys, xs) = crops[part]
    img = _photo(name)[ys, xs]
    if part == "skin":
        img = 0.35 * img + 0.65 * np.asarray(flat["skin"], dtype=np.float32)
    return Texture.from_image(img)


@lru_cache(maxsize=4)
def _screen_texture(seed: int) -> Texture:
    """A green screen as lit on a stage: uneven by a few percent, with soft creases."""
    rng = np.random.default_rng(seed + 911)
    low = cv2.resize(rng.normal(0, 1, (6, 10)).astype(np.float32), (320, 192), interpolation=cv2.INTER_CUBIC)
    shade = 1.0 + 0.06 * low / max(float(np.abs(low).max()), 1e-6)
    img = shade[..., None] * np.asarray(GREEN, dtype=np.float32)
    return Texture.from_image(np.clip(img, 0, 1))


def _segment(a: NDArray[np.float64], b: NDArray[np.float64], radius: float, tex: Texture, name: str) -> Ellipsoid:
    """An ellipsoid from point a to point b (a limb), local y along the segment."""
    axis = b - a
    length = float(np.linalg.norm(axis))
    y = axis / length
    helper = np.array([0.0, 0.0, 1.0]) if abs(y[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(y, helper)
    x /= np.linalg.norm(x)
    z = np.cross(x, y)
    rot = np.stack([x, y, z], axis=1)
    return Ellipsoid(
        texture=tex,
        name=name,
        centre=(a + b) / 2,
        radii=np.array([radius, length / 2, radius]),
        rotation=rot,
        texture_extent_m=2 * radius,
    )


def _rot_y(deg: float) -> NDArray[np.float64]:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


HAIR = (0.62, 0.48, 0.30)  # dark blond: neither the head's photograph nor the screen
HAIR_STRANDS = 90
HAIR_RADIUS_M = 0.0004  # 0.8 mm across: about half a pixel at the presenter's distance on the paper's rig


def _hair(seed: int, centre: F64, radii: F64, rot: F64) -> list[Primitive]:
    """Strands from the top and sides of the head, each three straight pieces that droop, thinner than a pixel
    (``thin``: the soft-edge renderer supersamples all of their box). Drawn from the seed, fixed to the head."""
    rng = np.random.default_rng(seed + 577)
    tex = Texture.from_image(np.full((4, 4, 3), HAIR, dtype=np.float32))
    out: list[Primitive] = []
    for k in range(HAIR_STRANDS):
        angle = rng.uniform(-math.pi * 0.95, -math.pi * 0.05)  # around the crown, in the picture's plane
        local = np.array([math.cos(angle), math.sin(angle), rng.uniform(-0.3, 0.6)])
        local /= np.linalg.norm(local)
        point = centre + rot @ (radii * local * 0.97)
        step = rot @ local * rng.uniform(0.010, 0.022)
        for piece in range(3):
            step = step + np.array([rng.uniform(-0.004, 0.004), 0.006 + 0.003 * piece, 0.0])
            nxt = point + step
            strand = _segment(point, nxt, HAIR_RADIUS_M, tex, f"hair {k}.{piece}")
            strand.thin = True
            out.append(strand)
            point = nxt
    return out


def presenter(settings: SimSettings, time_s: float) -> Scene:
    """The paper's scenario: a presenter about 0.9 m deep (hands forward), a desk, a green screen."""
    kind = settings.texture
    near = settings.subject_distance_m
    phase = 2 * math.pi * time_s / MOTION_PERIOD_S if settings.motion else 0.0
    sway = 0.02 * math.sin(phase)
    reach = 0.04 * math.sin(phase + 1.0)
    torso_z = near + PRESENTER_DEPTH_M - 0.14  # back of the torso at near + 0.9
    prims: list[Primitive] = []
    head_c = np.array([sway * 1.3, -0.34, torso_z - 0.03])
    prims.append(
        Ellipsoid(
            texture=_texture(kind, "head"),
            name="head",
            centre=head_c,
            radii=np.array([0.085, 0.115, 0.1]),
            rotation=_rot_y(12 * math.sin(phase)),
            texture_extent_m=0.17,
        )
    )
    if settings.edges == "soft":
        prims.extend(_hair(settings.seed, head_c, np.array([0.085, 0.115, 0.1]), _rot_y(12 * math.sin(phase))))
    prims.append(
        Ellipsoid(
            texture=_texture(kind, "skin"),
            name="neck",
            centre=np.array([sway, -0.2, torso_z]),
            radii=np.array([0.05, 0.07, 0.05]),
            texture_extent_m=0.1,
        )
    )
    prims.append(
        Ellipsoid(
            texture=_texture(kind, "torso"),
            name="torso",
            centre=np.array([sway, 0.12, torso_z]),
            radii=np.array([0.2, 0.3, 0.13]),
            texture_extent_m=0.4,
        )
    )
    for side in (-1.0, 1.0):
        shoulder = np.array([side * 0.21 + sway, -0.08, torso_z])
        elbow = np.array([side * 0.27 + sway, 0.16, torso_z - 0.32 + reach * 0.5])
        hand = np.array([side * 0.12 + sway, 0.1 + 0.03 * math.sin(phase * 2 + side), near + 0.05 - reach * 0.5])
        tag = "left" if side < 0 else "right"
        prims.append(_segment(shoulder, elbow, 0.055, _texture(kind, "arm"), f"upper arm {tag}"))
        prims.append(_segment(elbow, hand, 0.045, _texture(kind, "arm"), f"forearm {tag}"))
        prims.append(
            Ellipsoid(
                texture=_texture(kind, "skin"),
                name=f"hand {tag}",
                centre=hand,
                radii=np.array([0.045, 0.05, 0.05]),
                texture_extent_m=0.09,
            )
        )
    if settings.desk:
        top_y = 0.3
        front_z = near + 0.12
        depth = 0.4
        prims.append(
            Rectangle(
                texture=_texture(kind, "desk"),
                name="desk top",
                centre=np.array([0.0, top_y, front_z + depth / 2]),
                u=np.array([1.0, 0.0, 0.0]),
                v=np.array([0.0, 0.0, -1.0]),
                half=(0.6, depth / 2),
                texture_extent_m=1.2,
            )
        )
        prims.append(
            Rectangle(
                texture=_texture(kind, "desk_front"),
                name="desk front",
                centre=np.array([0.0, top_y + 0.3, front_z]),
                u=np.array([1.0, 0.0, 0.0]),
                v=np.array([0.0, 1.0, 0.0]),
                half=(0.6, 0.3),
                texture_extent_m=1.2,
            )
        )
    screen_z = near + PRESENTER_DEPTH_M + settings.screen_gap_m
    prims.insert(
        0,
        Rectangle(
            texture=_screen_texture(settings.seed),
            name="green screen",
            subject=False,
            centre=np.array([0.0, 0.0, screen_z]),
            u=np.array([1.0, 0.0, 0.0]),
            v=np.array([0.0, 1.0, 0.0]),
            half=(3.0 * screen_z, 2.0 * screen_z),
            texture_extent_m=6.0 * screen_z,
        ),
    )
    return Scene(primitives=prims, background=GREEN, static=1)


@dataclass(frozen=True)
class BoardPose:
    """Board pose: R maps board coordinates (x right, y down, z into the board) to rig coordinates."""

    R: NDArray[np.float64]
    origin: NDArray[np.float64]  # rig coordinates of the board's top-left corner


def board_poses(settings: SimSettings, spec: BoardSpec, view_half_width: float) -> list[BoardPose]:
    """Varied, deterministic board poses: distances in range, tilts up to the limit, some off-centre."""
    rng = np.random.default_rng(settings.seed + 4242)
    w, h = spec.size_m
    poses = []
    d0, d1 = settings.board_distance_m
    for i in range(settings.board_poses):
        z = d0 + (d1 - d0) * ((i * 0.618034) % 1.0)  # spread distances evenly, in a scrambled order
        tilt = math.radians(settings.board_tilt_deg) * math.sqrt(rng.uniform(0.05, 1.0))
        axis_angle = rng.uniform(0, 2 * math.pi)
        axis = np.array([math.cos(axis_angle), math.sin(axis_angle), 0.0])
        rvec = axis * tilt
        roll = rng.uniform(-0.25, 0.25)
        R = cv2.Rodrigues(rvec)[0] @ cv2.Rodrigues(np.array([0.0, 0.0, roll]))[0]
        half_view = view_half_width * z
        cx = rng.uniform(-0.55, 0.55) * half_view
        cy = rng.uniform(-0.35, 0.35) * half_view * 0.56
        centre = np.array([cx, cy, z])
        origin = centre - R @ np.array([w / 2, h / 2, 0.0])
        poses.append(BoardPose(R=np.asarray(R, dtype=np.float64), origin=origin))
    return poses


@lru_cache(maxsize=8)
def _board_texture(spec: BoardSpec, px_per_square: int) -> Texture:
    img = spec.image(px_per_square).astype(np.float32) / 255.0
    # print contrast: paper white is not 1.0 and toner black is not 0.0
    img = 0.08 + 0.82 * img
    return Texture.from_image(img)


def charuco(settings: SimSettings, spec: BoardSpec, pose: BoardPose, px_per_square: int) -> Scene:
    """A ChArUco board at ``pose`` in front of a grey studio wall."""
    w, h = spec.size_m
    u, v = pose.R[:, 0], pose.R[:, 1]
    centre = pose.origin + u * w / 2 + v * h / 2
    board = Rectangle(
        texture=_board_texture(spec, px_per_square),
        name="board",
        centre=centre,
        u=u,
        v=v,
        half=(w / 2, h / 2),
        texture_extent_m=w,
    )
    wall = Rectangle(
        texture=Texture.from_image(np.full((8, 8, 3), 0.5, dtype=np.float32)),
        name="wall",
        subject=False,
        centre=np.array([0.0, 0.0, 6.0]),
        u=np.array([1.0, 0.0, 0.0]),
        v=np.array([0.0, 1.0, 0.0]),
        half=(20.0, 12.0),
        texture_extent_m=40.0,
    )
    return Scene(primitives=[wall, board], background=(0.5, 0.5, 0.5), ambient=0.75, static=1)
