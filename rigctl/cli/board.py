"""``rigctl board``: a printable ChArUco calibration target and the file describing it."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from PIL import Image

from rigctl.board import DICTIONARIES, BoardSpec
from rigctl.cli.helptext import examples
from rigctl.errors import ParameterError
from rigctl.publish import publishing, refuse_special, utf8_path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "board",
        epilog=examples(
            ("board.png and board.yaml: the 8x6 ChArUco board of 75 mm squares the simulator shows",
             "rigctl board --out board"),
            ("a smaller board for close work, printed at 300 dpi",
             "rigctl board --out small-board --squares 10x7 --square-mm 30 --marker-mm 22 --dpi 300"),
        ),
        help="write a printable ChArUco target (PNG) and its description (board.yaml)",
        description="Write OUT.png, to be printed at 100 % scale at --dpi, and OUT.yaml describing the board for "
        "rigctl calibrate. Measure a printed square and correct square_m in the YAML if the print is off.",
    )
    p.add_argument("--out", type=Path, default=Path("board"), metavar="STEM", help="output stem (default: board)")
    p.add_argument("--squares", default="8x6", metavar="XxY", help="squares across x down (default 8x6)")
    p.add_argument("--square-mm", type=float, default=75.0, metavar="MM", help="square side (default 75)")
    marker_help = "marker side, 0.1 mm to below --square-mm (default 55)"
    p.add_argument("--marker-mm", type=float, default=55.0, metavar="MM", help=marker_help)
    p.add_argument("--dictionary", default="DICT_5X5_250", choices=sorted(DICTIONARIES))
    p.add_argument("--dpi", type=float, default=150.0, help="print resolution (default 150)")
    p.add_argument("--margin-mm", type=float, default=10.0, metavar="MM", help="white margin (default 10)")
    p.set_defaults(func=run)


EXISTS = "already exists; a board is never replaced: choose another --out or remove it"
MAX_BOARD_PIXELS = 1 << 28  # 256 MB of grey: a 2 x 1.5 m board at 200 dpi


DICTIONARY_SIZE = 250  # markers in each dictionary offered (DICT_*_250)


def run(ns: argparse.Namespace) -> int:
    try:
        sx, sy = (int(v) for v in ns.squares.lower().split("x"))
    except ValueError:
        raise ParameterError(f"--squares {ns.squares!r}: expected COLUMNSxROWS such as 8x6") from None
    if not (3 <= sx <= 40 and 3 <= sy <= 40):
        raise ParameterError(f"--squares {ns.squares}: each count must be 3..40")
    markers = sx * sy // 2  # a ChArUco board has a marker in every other square
    if markers > DICTIONARY_SIZE:
        raise ParameterError(
            f"--squares {sx}x{sy}: needs {markers} markers, {ns.dictionary} has {DICTIONARY_SIZE} (fewer squares)"
        )
    if not ns.out.name:
        raise ParameterError(f"--out {str(ns.out)!r}: give a file stem such as board")
    if not (ns.square_mm > 0 and math.isfinite(ns.square_mm)):
        raise ParameterError(f"--square-mm {ns.square_mm:g}: must be a positive length")
    if not 0.1 <= ns.marker_mm < ns.square_mm:  # 0.1 mm: what a board file's marker_m is held to
        raise ParameterError(
            f"--marker-mm {ns.marker_mm:g} must be at least 0.1 mm and smaller than --square-mm {ns.square_mm:g}"
        )
    if not 30 <= ns.dpi <= 2400 or ns.margin_mm < 0:
        raise ParameterError("--dpi must be 30..2400 and --margin-mm at least 0")
    if not (math.isfinite(ns.square_mm) and ns.square_mm <= 1000 and math.isfinite(ns.margin_mm)):
        raise ParameterError(f"--square-mm {ns.square_mm:g}: at most 1000 mm (and a finite --margin-mm)")
    spec = BoardSpec(sx, sy, ns.square_mm / 1000, ns.marker_mm / 1000, ns.dictionary)
    px_per_square = round(ns.square_mm / 25.4 * ns.dpi)
    margin_px = 2 * round(ns.margin_mm / 25.4 * ns.dpi)
    if (sx * px_per_square + margin_px) * (sy * px_per_square + margin_px) > MAX_BOARD_PIXELS:
        raise ParameterError(
            f"--squares {sx}x{sy} of {ns.square_mm:g} mm with {ns.margin_mm:g} mm margins at {ns.dpi:g} dpi is over "
            f"{MAX_BOARD_PIXELS:,} pixels: lower --dpi, --square-mm or --margin-mm"
        )
    if px_per_square < 20:
        raise ParameterError(f"{ns.square_mm} mm at {ns.dpi} dpi is {px_per_square} px per square: raise --dpi")
    bits = int(ns.dictionary.split("_")[1].split("X")[0])  # DICT_5X5_250: 5 x 5 bits
    marker_px = math.floor(px_per_square * ns.marker_mm / ns.square_mm)
    if marker_px < bits + 2:  # its bits and a black border: below that OpenCV's assertion ended the run
        raise ParameterError(
            f"--marker-mm {ns.marker_mm:g} at {ns.dpi:g} dpi is {marker_px} px: a {ns.dictionary} marker needs at "
            f"least {bits + 2} px (raise --marker-mm or --dpi)"
        )
    png, yml = ns.out.with_suffix(".png"), ns.out.with_suffix(".yaml")
    for path in (png, yml):  # a name held by a folder, FIFO or device is refused before any drawing
        utf8_path(path)
        refuse_special(path)
    for path in (png, yml):  # never replaced: a printed board measured by another description calibrates wrong
        if path.exists() or path.is_symlink():
            raise ParameterError(f"{path}: {EXISTS}")
    margin = round(ns.margin_mm / 25.4 * ns.dpi)
    image = spec.image(px_per_square, margin)
    # the PNG states its physical resolution (pHYs, whole pixels per metre): the one at which a square of
    # px_per_square pixels is square_mm, so "print at 100 %" gives the board's size whatever the tool
    px_per_m = round(px_per_square / (ns.square_mm / 1000))
    dpi = px_per_m * 0.0254  # what the print gives exactly (--dpi rounded to whole pixels per square)
    # published whole like every output: a read-only or full destination is one line with exit 4 (OutputError)
    # and never over a board another run published since the check above (the name is claimed atomically)
    with publishing(png, exists=EXISTS) as tmp:
        # OpenCV cannot write pHYs; Pillow writes dpi as round(dpi / 0.0254) pixels per metre
        Image.fromarray(image).save(tmp, format="PNG", dpi=(dpi, dpi), optimize=True)
    # the printed square size follows from the DPI: record it so a user can check the print with a ruler
    try:
        spec.save(yml, exists=EXISTS)
    except ParameterError:
        png.unlink()  # ours, just published: no picture is left without the description it was drawn from
        raise
    h, w = image.shape
    print(
        f"wrote {png} ({w}x{h} px = {w / dpi * 25.4:.0f} x {h / dpi * 25.4:.0f} mm at {dpi:.2f} dpi, stored in it; "
        f"squares {sx}x{sy} of {ns.square_mm:g} mm, markers {ns.marker_mm:g} mm, {ns.dictionary}) and {yml}"
    )
    return 0
