"""Disparity as NUKE names it, in a depth EXR's layers, and rigctl's disparity read back from them.

rigctl's disparity ``d`` of a camera is the shift, in pixels, of a point between this camera and a camera one
horizontal spacing to its left: the point sits at ``x + d * s`` in a camera ``s`` spacings to the left,
``x - d * s`` in one ``s`` spacings to the right, and ``y - d * t`` in one ``t`` horizontal spacings below
(image y down). NUKE (Ocula, CaraVR) stores with each view the vector field that maps it onto the other view
of a stereo pair: ``disparityL`` is carried by the left view and points to where its pixels are in the right
view, ``disparityR`` by the right view and points into the left view. On a planar grid every camera is the
left view of the pair with its right neighbour and the right view of the pair with its left neighbour, so
every camera carries both:

* ``disparityL.x/y``: this view onto the camera to its right, ``(-d * s_right, 0)``;
* ``disparityR.x/y``: this view onto the camera to its left, ``(+d * s_left, 0)``;
* ``disparityV.x/y``: this view onto the camera below it, ``(0, -d * t_below)``.

A camera at the end of a row (or column) has no neighbour on that side, but the rectified grid defines the
field all the same: the step is the row's (column's) spacing. The steps, in horizontal spacings, are in the
header (``STEPS``) so the disparity can be read back; files written before this convention (their
``disparityL`` pointed to the camera on the left) carry no ``CONVENTION`` attribute and are read by the
old rule.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from rigctl.errors import TakeError
from rigctl.exr import read_exr

log = logging.getLogger(__name__)

F32 = NDArray[np.float32]
CONVENTION = "rigctl:disparityConvention"  # header attribute: the convention the layers follow ("rigctl." before)
NUKE = "nuke"  # its value: disparityL maps onto the right camera, disparityR onto the left
STEPS = "rigctl:disparitySteps"  # "right left below" in horizontal spacings ("-" where the grid has none)
_SAME = 0.25  # offsets closer than this (in spacings) are the same row or column


@dataclass(frozen=True)
class Steps:
    """Distances, in horizontal spacings, from a camera to the neighbours its fields map onto; None where
    the grid has no such direction (one column: no right/left; one row: no below)."""

    right: float | None
    left: float | None
    below: float | None

    def header(self) -> str:
        return " ".join("-" if s is None else f"{s:.6f}" for s in (self.right, self.left, self.below))

    @classmethod
    def parse(cls, text: str, path: Path) -> Steps:
        parts = text.split()
        if len(parts) != 3:
            raise TakeError(f"{path}: {STEPS} {text!r} is not three steps (right left below)")
        vals: list[float | None] = []
        for p in parts:
            if p == "-":
                vals.append(None)
                continue
            try:
                v = float(p)
            except ValueError:
                raise TakeError(f"{path}: {STEPS} {text!r}: {p!r} is not a number") from None
            if not np.isfinite(v) or v <= 0:
                raise TakeError(f"{path}: {STEPS} {text!r}: a step must be a positive number, not {p}")
            vals.append(v)
        return cls(*vals)


def _gaps(values: list[float]) -> list[float]:
    s = sorted(set(round(v, 6) for v in values))
    return [b - a for a, b in itertools.pairwise(s) if b - a > _SAME]


def steps(offsets: Mapping[str, tuple[float, float]], name: str) -> Steps:
    """The steps to ``name``'s right, left and lower neighbours: the nearest camera of its row (column) on
    that side; at the end of a row the row's spacing (its smallest gap), in a row of one the grid's."""
    ox, oy = offsets[name]
    row = [x for x, y in offsets.values() if abs(y - oy) < _SAME]
    col = [y for x, y in offsets.values() if abs(x - ox) < _SAME]
    all_x = _gaps([x for x, _ in offsets.values()])
    all_y = _gaps([y for _, y in offsets.values()])
    row_gap = min(_gaps(row), default=min(all_x, default=None))
    col_gap = min(_gaps(col), default=min(all_y, default=None))
    right = min((x - ox for x in row if x - ox > _SAME), default=row_gap)
    left = min((ox - x for x in row if ox - x > _SAME), default=row_gap)
    below = min((y - oy for y in col if y - oy > _SAME), default=col_gap)
    return Steps(right, left, below)


def layer_scales(st: Steps) -> dict[str, float | None]:
    """The NUKE disparity layers of a camera with steps ``st``, in their order: the multiple of the disparity
    each holds, None for one that is all zeros."""
    out: dict[str, float | None] = {}
    if st.right is not None and st.left is not None:
        out.update({"disparityL.x": -st.right, "disparityL.y": None, "disparityR.x": st.left, "disparityR.y": None})
    if st.below is not None:
        out.update({"disparityV.x": None, "disparityV.y": -st.below})
    return out


def layers(disparity: F32, st: Steps) -> dict[str, F32]:
    """The NUKE disparity layers of one camera (:func:`layer_scales`); a missing estimate (+inf) is 0 (no
    motion), as NUKE has no marker for it (``depth.Z`` is 0 there)."""
    fin = np.asarray(np.where(np.isfinite(disparity), disparity, np.float32(0.0)), np.float32)
    zero = np.zeros_like(fin)

    def times(scale: float) -> F32:  # fin * scale, made in place (no frame-sized temporaries)
        out = np.negative(fin) if scale < 0 else fin.copy()
        return np.multiply(out, np.float32(abs(scale)), out=out)

    return {n: zero if s is None else times(s) for n, s in layer_scales(st).items()}


def header(st: Steps) -> dict[str, object]:
    return {CONVENTION: NUKE, STEPS: st.header()}


def disparity_file(folder: Path, name: str) -> Path:
    """Where camera ``name``'s disparity is in a depth output's frame ``folder``: its PFM, or, where there is
    none (written without ``--formats pfm``, the default since issue 24), its EXR (:func:`read_disparity`:
    the same values, bit for bit). The PFM's path when neither is there, for a caller's message."""
    pfm, exr = folder / f"{name}.pfm", folder / f"{name}.exr"
    return exr if not pfm.exists() and exr.exists() else pfm


def read_any_disparity(path: Path) -> F32:
    """The disparity in ``path``, a PFM or a depth EXR (:func:`disparity_file`)."""
    from rigctl.pfm import read_pfm

    return read_disparity(path) if path.suffix == ".exr" else read_pfm(path)


def read_disparity(path: Path) -> F32:
    """rigctl's disparity (pixels per horizontal spacing, +inf where there is none) from a depth EXR,
    in the NUKE convention or the one before it (told apart by ``CONVENTION``); an EXR without disparity
    layers, or one in a convention this version does not know, is refused in one line."""
    if not path.is_file():
        raise TakeError(f"{path}: not a regular file")
    channels, head = read_exr(path)
    conv = head.get(CONVENTION)
    if isinstance(conv, bytes):
        conv = conv.decode("utf-8", "replace")
    if conv is None:
        # written before the NUKE convention: disparityL.x = d (towards the left camera), disparityR.x = -d
        if "disparityL.x" in channels:
            d = channels["disparityL.x"]
        elif "disparityR.x" in channels:
            d = -channels["disparityR.x"]
        else:
            raise TakeError(f"{path}: no disparityL/disparityR layers: not a rigctl depth EXR")
        log.info("%s: written before the NUKE disparity convention: read by the old rule", path)
    elif conv == NUKE:
        steps_text = head.get(STEPS)
        if isinstance(steps_text, bytes):
            steps_text = steps_text.decode("utf-8", "replace")
        if not isinstance(steps_text, str):
            raise TakeError(f"{path}: {CONVENTION} is {NUKE!r} but the header has no {STEPS}")
        st = Steps.parse(steps_text, path)
        if "disparityL.x" in channels and st.right is not None:
            d = -channels["disparityL.x"] / np.float32(st.right)
        elif "disparityV.y" in channels and st.below is not None:
            d = -channels["disparityV.y"] / np.float32(st.below)
        else:
            raise TakeError(f"{path}: no disparity layers that {STEPS} {steps_text!r} can scale")
    else:
        raise TakeError(f"{path}: {CONVENTION} {conv!r} is not a disparity convention this rigctl reads ({NUKE!r})")
    d = np.asarray(d, np.float32)
    if d.ndim != 2:
        raise TakeError(f"{path}: a disparity layer is not one channel")
    if not np.isfinite(d).all():
        raise TakeError(f"{path}: disparity layers hold NaN or infinity")
    z = channels.get("depth.Z")
    if z is not None and z.shape == d.shape:
        d = np.where((z == 0) & (d == 0), np.inf, d).astype(np.float32)  # no estimate: written as 0, 1/Z 0
    return d


def checked_disparity(path: Path, disp: F32, shape: tuple[int, int], source: object) -> F32:
    """``disp`` as read from ``path``, refused in one line unless it is a disparity of ``source``'s pictures
    (``shape``: h, w): one channel of that size, no NaN, and nothing past the picture's width but +inf (the
    one mark of a missing estimate). Whatever reads a disparity from others checks it here."""
    h, w = shape
    if disp.ndim != 2:
        raise TakeError(f"{path}: a disparity is one channel (Pf), this file has three (PF)")
    if disp.shape != (h, w):
        raise TakeError(
            f"{path}: disparity is {disp.shape[1]}x{disp.shape[0]} but {source} has {w}x{h} images: "
            "the disparity folder does not match the input"
        )
    if np.isnan(disp).any():
        raise TakeError(f"{path}: disparity holds NaN (only +inf may mark a missing estimate)")
    beyond = (disp != np.inf) & (np.abs(disp) > w)
    if beyond.any():
        y, x = np.argwhere(beyond)[0]
        raise TakeError(
            f"{path}: disparity {disp[y, x]:g} at x={x}, y={y} is beyond the image's width ({w} px): "
            "no camera could see that point (only +inf may mark a missing estimate)"
        )
    return disp
