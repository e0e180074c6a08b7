"""Argument types shared by the verbs: each refuses a bad value with one line naming the option."""

from __future__ import annotations

import argparse
import errno
import math
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

from rigctl.cli.helptext import HelpFormatter
from rigctl.errors import InputPathError, short_path
from rigctl.exr import COLOURS
from rigctl.layout import LAYOUTS, camera_name_problem, misspelt

if TYPE_CHECKING:
    from rigctl.depth.options import DepthOptions


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line on stderr and exit code 2 (no usage dump), and whose help
    is rigctl's (:mod:`rigctl.cli.helptext`: colour on a terminal, examples at the end)."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]

    def error(self, message: str) -> NoReturn:
        sys.stderr.write(f"{self.prog}: error: {message} (see {self.prog} --help)\n")
        sys.exit(2)


class InputPath:
    """Argument type of a path that is read (a take, a rig file, a calibration, a disparity folder): a path the
    system cannot look up at all, too long or a loop of symbolic links, is refused as the input's fault (exit 3)
    while the command line is read, naming ``what`` and the path shortened, before any output is made. A path
    that does not exist passes: the command says what it wanted there. ``text=True`` keeps the string (a rig
    argument may be a shipped rig's name)."""

    def __init__(self, what: str, text: bool = False) -> None:
        self.what = what
        self.text = text

    def __call__(self, value: str) -> Path | str:
        try:
            os.stat(value)
        except OSError as exc:
            shown = f"{self.what} {short_path(value)}"
            if exc.errno == errno.ENAMETOOLONG:
                raise InputPathError(f"{shown}: the path is too long for the file system") from None
            if exc.errno == errno.ELOOP:
                raise InputPathError(f"{shown}: a loop of symbolic links") from None
        except ValueError:  # a NUL byte: the command's own checks say what is wrong
            pass
        return value if self.text else Path(value)


def add_views_input(p: argparse.ArgumentParser) -> None:
    """INPUT and --disparity of the verbs that make views from colour + disparity (render, view)."""
    p.add_argument(
        "input", type=InputPath("INPUT"), metavar="INPUT", help="rectified take, ideal simulated take, or grid folder"
    )
    p.add_argument(
        "--disparity", type=InputPath("--disparity"), required=True, metavar="DIR",
        help="depth output or truth/disparity",
    )  # fmt: skip


def _number(text: str) -> float:
    try:
        value = float(text.strip().rstrip("m"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if math.isnan(value):
        raise argparse.ArgumentTypeError(f"not a number: {text!r}")
    return value


def distance(text: str) -> float:
    """A positive, finite distance in metres."""
    value = _number(text)
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"must be a positive distance in metres, got {text!r}")
    return value


def far_distance(text: str) -> float:
    """A positive distance in metres, or ``inf`` for the background at infinity."""
    value = _number(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be a positive distance in metres or 'inf', got {text!r}")
    return value


def extent(what: str) -> Callable[[str], float]:
    """The type of a non-negative, finite extent in metres whose refusal names it: ``extent("width")`` says
    "must be a width >= 0 in metres"."""

    def parse(text: str) -> float:
        value = _number(text)
        if not (value >= 0 and math.isfinite(value)):
            raise argparse.ArgumentTypeError(f"must be a {what} >= 0 in metres, got {text!r}")
        return value

    parse.__name__ = what
    return parse


depth = extent("depth")  # zero is a flat subject


def fraction(text: str) -> float:
    """A fraction in (0, 1]; ``4%`` is accepted for 0.04."""
    t = text.strip()
    scale = 0.01 if t.endswith("%") else 1.0
    try:
        value = float(t.rstrip("%")) * scale
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (0 < value <= 1):
        raise argparse.ArgumentTypeError(f"must be a fraction in (0, 1] such as 0.04 or 4%, got {text!r}")
    return value


def positive_int(text: str) -> int:
    """A whole number of at least 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {text!r}")
    return value


def non_negative_int(text: str) -> int:
    """A whole number of at least 0."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be at least 0, got {text!r}")
    return value


def camera(text: str) -> str:
    """A camera named on the command line (``--cameras``, ``--camera``): a grid position ``r{row}c{col}`` as every
    file writes it; ``r01c0`` is refused naming ``r1c0``, and no name holds a path (``/``, ``..``, NUL)."""
    if wrong := camera_name_problem(text):
        raise argparse.ArgumentTypeError(f"{text if misspelt(text) else repr(text)[:60]} {wrong}")
    return text


def add_layout(p: argparse.ArgumentParser) -> None:
    """``--layout`` of every command that writes per-frame, per-camera files (rigctl.layout), and ``--colour``
    of their EXR pictures (rigctl.exr)."""
    p.add_argument(
        "--colour",
        default="rec709",
        choices=tuple(COLOURS),
        help="EXR pictures in scene-linear Rec. 709 (default) or ACEScg (AP1, through OpenColorIO)",
    )
    p.add_argument(
        "--layout",
        default="frames",
        choices=LAYOUTS,
        help="frames: DIR/<frame:06d>/<camera>.<ext> (default); sequence: DIR/<camera>/<camera>.<frame:06d>.<ext>, "
        "one image sequence per camera as NUKE and Unreal's Img Media read it",
    )


def add_pipeline_options(p: argparse.ArgumentParser) -> None:
    """The take-level pipeline's options, the same for rigctl depth and rigctl process."""
    from rigctl.depth.export import DEFAULT_FORMATS, FORMATS
    from rigctl.depth.options import DEFAULT_CHUNK, DEFAULT_WARMUP

    p.add_argument("--no-temporal", action="store_true", help="each frame set on its own (no temporal stabilisation)")
    p.add_argument(
        "--formats",
        type=output_formats,
        default=DEFAULT_FORMATS,
        metavar="LIST",
        help=f"what to write per frame and camera, a comma-separated choice of {', '.join(FORMATS)} (default "
        f"{','.join(DEFAULT_FORMATS)}: the EXR holds the disparity; pfm adds it as PFM, png a colour preview)",
    )
    p.add_argument(
        "--chunk",
        type=positive_int,
        default=DEFAULT_CHUNK,
        metavar="N",
        help=f"frame sets per chunk: state carried between frame sets starts afresh at each (default {DEFAULT_CHUNK})",
    )
    p.add_argument(
        "--warmup",
        type=non_negative_int,
        default=DEFAULT_WARMUP,
        metavar="W",
        help=f"frame sets before a chunk processed, not written, to settle the stabiliser (default {DEFAULT_WARMUP})",
    )


def output_formats(text: str) -> tuple[str, ...]:
    """``--formats``: what a depth run writes (:func:`rigctl.depth.export.parse_formats`), refused as argparse
    refuses any other value (one line, exit 2)."""
    from rigctl.depth.export import parse_formats
    from rigctl.errors import ParameterError

    try:
        return parse_formats(text)
    except ParameterError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--formats: ")) from None


def depth_options(ns: argparse.Namespace) -> DepthOptions:
    """The depth options rigctl depth and rigctl process read from their shared arguments (the preset, the
    range, the key, the cameras and :func:`add_pipeline_options`'s): one reading and one check
    (:meth:`DepthOptions.check`), so the verbs cannot drift."""
    from rigctl.depth.options import DepthOptions

    opt = DepthOptions(
        preset=ns.preset,
        near_m=ns.near,
        far_m=ns.far if ns.far is not None else (math.inf if ns.near is not None else None),
        key=not ns.no_key,
        cameras=tuple(ns.cameras) if ns.cameras else None,
        temporal=not ns.no_temporal,
        chunk=ns.chunk,
        warmup=ns.warmup,
    )
    opt.check()  # before the verb makes any folder or starts any cluster
    return opt
