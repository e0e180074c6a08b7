"""``rigctl miv``: MPEG immersive-video interchange. ``miv ivpsnr`` scores raw YUV pictures with IV-PSNR;
``miv export`` writes a rectified take and its disparity as MIV content (camera JSON + YUV files);
``miv import`` reads MIV content into grid folders that ``depth`` and ``render`` take."""

from __future__ import annotations

import argparse
import json
import logging
import re
from pathlib import Path

from rigctl.cli import args
from rigctl.cli.args import non_negative_int
from rigctl.cli.helptext import examples
from rigctl.errors import ParameterError
from rigctl.take.framesets import parse_frames

log = logging.getLogger(__name__)

PIX_FMT = re.compile(r"yuv420p(?:(9|10|12|14|16)le)?")


def _size(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"(\d+)x(\d+)", text)
    if m is None or int(m[1]) < 1 or int(m[2]) < 1:
        raise argparse.ArgumentTypeError(f"size must be WIDTHxHEIGHT, e.g. 1920x1080, got {text!r}")
    return int(m[1]), int(m[2])


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "miv",
        help="MPEG immersive video: IV-PSNR, export and import of MIV content",
        epilog=examples(
            ("an ideal simulated take and its true disparity as MIV content",
             "rigctl miv export takes/ideal takes/ideal/truth/disparity --out miv"),
            ("that content back as grid folders", "rigctl miv import miv/cameras.json --out miv-grid"),
        ),
    )
    verbs = p.add_subparsers(dest="miv_verb", metavar="ACTION")

    iv = verbs.add_parser(
        "ivpsnr",
        epilog=examples(
            ("a camera's picture scored against itself (the cap: identical pictures)",
             "rigctl miv ivpsnr miv/r1c1_texture_960x540_yuv420p10le.yuv miv/r1c1_texture_960x540_yuv420p10le.yuv "
             "--size 960x540 --pix-fmt yuv420p10le"),
            ("frame 2 of two 8-bit files, as JSON",
             "rigctl miv ivpsnr ref.yuv test.yuv --size 1920x1080 --frame 2 --json"),
        ),
        help="IV-PSNR (and PSNR) of a raw YUV 4:2:0 picture against a reference",
        description="IV-PSNR as MPEG defines it (search range 2, global colour offset tolerated up to 1 % of "
        "the peak, components 4:1:1), written from the paper; the same figures as the authors' software.",
    )
    iv.add_argument("reference", type=args.InputPath("reference"), help="raw .yuv file (the original)")
    iv.add_argument("test", type=args.InputPath("test"), help="raw .yuv file (the synthesised or compressed picture)")
    iv.add_argument("--size", type=_size, required=True, metavar="WxH")
    iv.add_argument("--pix-fmt", default="yuv420p", help="yuv420p (8 bits) or yuv420p10le, 12le, 14le")
    iv.add_argument("--frame", type=non_negative_int, default=0, help="frame index in both files (default 0)")
    iv.add_argument(
        "--mask", type=args.InputPath("--mask"), help="raw 8-bit 4:2:0 .yuv: compare only where its luma is non-zero"
    )
    iv.add_argument("--json", action="store_true")
    iv.set_defaults(func=cmd_ivpsnr)

    ex = verbs.add_parser(
        "export",
        epilog=examples(
            ("an ideal simulated take and its true disparity",
             "rigctl miv export takes/ideal takes/ideal/truth/disparity --out miv"),
            ("the demo's rectified take with its estimated depth, frame set 0",
             "rigctl miv export rigctl-demo/takes/presenter-rectified rigctl-demo/depth --out demo-miv --frames 0"),
        ),
        help="a rectified take and its disparity as MIV content: camera JSON, YUV 4:2:0 10-bit colour, 16-bit depth",
    )
    ex.add_argument("take", type=args.InputPath("take"), help="a rectified take (or an ideal=true simulated take)")
    ex.add_argument(
        "disparity",
        type=args.InputPath("disparity"),
        help="disparity folder: <frame>/<camera>.pfm or, without one, .exr (a depth output, truth)",
    )
    ex.add_argument("--out", type=Path, required=True, help="new folder for the content")
    ex.add_argument("--frames", metavar="A-B", help="frame sets A-B (default: every one with a disparity)")
    ex.set_defaults(func=cmd_export)

    im = verbs.add_parser(
        "import",
        epilog=examples(
            ("MIV content as one grid folder per frame", "rigctl miv import miv/cameras.json --out miv-grid"),
            ("then depth on its first frame, scored against the content's own depth",
             "rigctl depth miv-grid/000000 --out miv-depth"),
        ),
        help="MIV content (camera JSON + YUV) as grid folders for rigctl depth and render, one per frame",
    )
    im.add_argument("cameras", type=args.InputPath("cameras"), help="the content's camera JSON")
    im.add_argument(
        "--out", type=Path, required=True, help="new folder: <frame>/grid.yaml, images, truth/ (the content's depth)"
    )
    im.add_argument("--frames", metavar="A-B", help="frames A-B (default: every frame of the content)")
    im.set_defaults(func=cmd_import)
    p.set_defaults(func=lambda ns: p.print_help() or 2)


def _bits(pix_fmt: str) -> int:
    m = PIX_FMT.fullmatch(pix_fmt)
    if m is None or (m[1] is not None and int(m[1]) > 14):
        raise ParameterError(f"--pix-fmt {pix_fmt!r}: give yuv420p, yuv420p10le, yuv420p12le or yuv420p14le")
    return int(m[1] or 8)


def cmd_ivpsnr(ns: argparse.Namespace) -> int:
    from rigctl.interop import yuv
    from rigctl.interop.ivpsnr import ivpsnr, upsample_420

    w, h = ns.size
    bits = _bits(ns.pix_fmt)
    pics = [upsample_420(*yuv.read_frame(f, w, h, bits, ns.frame)) for f in (ns.reference, ns.test)]  # type: ignore[arg-type]
    mask = None
    if ns.mask is not None:
        mask = yuv.read_frame(ns.mask, w, h, 8, ns.frame)[0]
        if not mask.any():
            raise ParameterError(f"{ns.mask}: the mask is zero everywhere: nothing to compare")
    r = ivpsnr(pics[0], pics[1], bits, mask, mask_bit_depth=8)
    if ns.json:
        print(json.dumps({"ivpsnr_db": r.ivpsnr_db, "psnr_db": list(r.psnr_db), "offset": list(r.offset)}))
    else:
        print(f"IV-PSNR {r.ivpsnr_db:.4f} dB  PSNR Y {r.psnr_db[0]:.4f} Cb {r.psnr_db[1]:.4f} Cr {r.psnr_db[2]:.4f} dB"
              f"  colour offset {r.offset[0]} {r.offset[1]} {r.offset[2]}")  # fmt: skip
    return 0


def cmd_export(ns: argparse.Namespace) -> int:
    from rigctl.interop.miv import export_miv
    from rigctl.publish import refuse_inside

    refuse_inside(ns.out, ns.take)
    files = export_miv(ns.take, ns.disparity, ns.out, parse_frames(ns.frames) if ns.frames else None)
    print(f"wrote {len(files)} files of MIV content to {ns.out} (listed in {ns.out / 'README.txt'})")
    return 0


def cmd_import(ns: argparse.Namespace) -> int:
    from rigctl.interop.miv_import import import_miv

    folders = import_miv(ns.cameras, ns.out, parse_frames(ns.frames) if ns.frames else None)
    print(f"wrote {len(folders)} grid folder(s) to {ns.out}")
    return 0
