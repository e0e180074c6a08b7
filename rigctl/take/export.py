"""``rigctl take export``: frame sets as images, 8-bit PNG or scene-linear EXR, in a layout of rigctl.layout.

A damaged frame stops the export (naming file and byte) unless the reader skips damaged frames; then it is
left out and listed in ``DIR/export.json`` under ``skipped_damaged``.

Each frame set is written whole into a hidden folder of its own in ``DIR`` (``.take-export-<frame>`` +
:data:`rigctl.publish.PARTIAL_SUFFIX`) and published when all its pictures are there: in the frames layout a
new frame set's folder is renamed to ``DIR/<frame>`` (it appears whole or not at all), otherwise each picture
is renamed to its place. A run that fails on a frame set (a damaged frame, a full disk) leaves nothing of it;
the frame sets before it stay whole, as ``rigctl depth`` leaves its own. A killed run's hidden folders are
removed by the next run on ``DIR``.

``DIR/export.json`` is the record of the export in ``DIR``: every file it published (``files``), whether it
finished (``complete``) and the damaged frames it left out. A run on a ``DIR`` exported before replaces that
export, as ``rigctl depth`` replaces its outputs: before its first picture it publishes a record (``complete:
false``) listing the previous export's files and its own, removes the previous files it will not write, and
at its end removes those it planned and did not write (damaged) and publishes its own record. A run killed at
any instant leaves a record listing every file of ours in ``DIR``, so the next run leaves exactly its own. Only
files a record lists are ever removed: anything else in ``DIR`` stays. A record that lists no files (an older
rigctl's), or frame or camera folders with no record, are refused in one line: they cannot be told from the
user's.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from collections.abc import Callable, Iterable
from contextlib import suppress
from pathlib import Path

import numpy as np

from rigctl.diskspace import check_free_space
from rigctl.errors import ParameterError, TakeError
from rigctl.exr import picture, picture_attributes, to_colour, write_exr
from rigctl.keying import Keyer
from rigctl.layout import SAFE_CAMERA, check_layout, inside, output_path
from rigctl.publish import PARTIAL_SUFFIX, fsync_dir, move_into, output_error, publish_json, publish_png
from rigctl.regular import read_regular
from rigctl.take.framesets import check_frames, parse_frames
from rigctl.take.reader import TakeReader


def export_take(
    reader: TakeReader,
    out: Path,
    frames: str | None = None,
    fmt: str = "png",
    progress: Callable[[int, int], None] | None = None,
    layout: str = "frames",
    colour: str = "rec709",
) -> dict[str, int]:
    """Write every member of the chosen frame sets; returns counts of images written and members missing.

    PNG holds the camera's BT.709 picture as captured (8-bit); EXR holds it scene-linear with the soft key's
    coverage as ``A`` and the subject's unmixed colour premultiplied by it as RGB, ``chromaticities``,
    ``framesPerSecond`` and the frame's ``timeCode``.
    """
    if fmt not in ("png", "exr"):
        raise ParameterError(f"--format {fmt!r}: choose png or exr")
    check_layout(layout)  # an unknown layout is refused before any work
    to_colour(np.zeros((1, 3), np.float32), colour)  # and an unknown colour space
    sets = reader.frame_sets
    if not sets:
        raise TakeError(f"{reader.folder}: the take holds no frames")
    asked = parse_frames(frames) if frames is not None else None
    chosen = check_frames(asked, range(len(sets)), reader.folder, "frame set")
    keyer = Keyer()
    remove_stale_staging(out)
    ext = f".{fmt}"
    members = [(n, c) for n in chosen for c in reader.names if c in sets[n].members]
    planned = {relative(out, output_path(out, layout, n, c, ext)) for n, c in members}
    previous = previous_files(out)
    w, h = reader.width, reader.height
    need = len(members) * (w * h * BYTES_PER_PIXEL[fmt] + FILE_BYTES)
    check_free_space(out, need, f"{len(members)} pictures of {w}x{h} ({fmt.upper()})")
    head = {"take": str(reader.folder), "format": fmt, "layout": layout}
    publish_json(out / RECORD, {**head, "complete": False, "files": sorted(previous | planned)})
    remove_ours(out, previous - planned)  # the previous export's files this run does not write
    published: set[str] = set()
    written = missing = 0
    for k, n in enumerate(chosen):
        fs = sets[n]
        tc = reader.set_timecode(fs)
        staged = staging_folder(out, n)
        try:
            for name in reader.names:
                if name not in fs.members:
                    missing += 1
                    continue
                image = reader.image_or_none(name, fs.members[name], "bgr8" if fmt == "png" else "float")
                if image is None:
                    continue  # damaged, skipped: listed in reader.damaged
                path = output_path(staged, "flat", n, name, f".{fmt}")
                if fmt == "png":
                    publish_png(path, image)
                else:
                    rgb = np.asarray(image, np.float32)
                    attrs = picture_attributes(reader.fps, tc, colour)
                    attrs.update({"rigctl:camera": name, "rigctl:frame_set": str(n)})
                    key = keyer.soft(rgb)  # A: the subject's coverage; RGB: its unmixed colour, premultiplied
                    write_exr(path, picture(key.foreground, key.alpha, colour), attrs)
                written += 1
            mine = [relative(out, output_path(out, layout, n, f.stem, f.suffix)) for f in staged.iterdir()]
            publish_frame_set(staged, out, layout, n)
            published.update(mine)
        finally:
            shutil.rmtree(staged, ignore_errors=True)  # a frame set that failed leaves nothing
        if progress:
            progress(k + 1, len(chosen))
    remove_ours(out, planned - published)  # left out as damaged: a previous export's picture there goes too
    result = {"images": written, "missing": missing, "sets": len(chosen), "skipped_damaged": len(reader.damaged)}
    skipped = [d.model_dump(exclude_none=True) for d in reader.damaged]
    record = {**head, "complete": True, **result, "skipped_damaged": skipped, "files": sorted(published)}
    publish_json(out / RECORD, record)
    return result


# what a picture takes a pixel at most, as if nothing compressed (with a margin): 8-bit BGR PNG, float32 RGBA
# EXR; and a file's headers (the record beside them within it)
BYTES_PER_PIXEL = {"png": 4, "exr": 17}
FILE_BYTES = 1 << 16

RECORD = "export.json"
RECORD_LIMIT = 64 << 20  # 64 MB: a million files' names
# what take export publishes, in the frames and the sequence layout (rigctl.layout.output_path)
OURS = re.compile(
    r"(?:[0-9]{6,9}/(r[0-9]{1,4}c[0-9]{1,4})|(r[0-9]{1,4}c[0-9]{1,4})/\2\.[0-9]{6,9})\.(?:png|exr)"
)
FRAME_FOLDER = re.compile(r"[0-9]{6,9}")


def relative(out: Path, path: Path) -> str:
    return path.relative_to(out).as_posix()


def previous_files(out: Path) -> set[str]:
    """The files the export already in ``out`` published, as its record lists them (none without a record).
    Refused in one line: a record that lists no files or names a file take export never writes (an older
    rigctl's, or not ours), and frame or camera folders with no record: their files cannot be told from others."""
    path = out / RECORD
    if not os.path.lexists(path):
        strays = sorted(
            p.name
            for p in out.iterdir()
            if p.is_dir() and not p.is_symlink() and (FRAME_FOLDER.fullmatch(p.name) or SAFE_CAMERA.fullmatch(p.name))
        )
        if strays:
            raise ParameterError(
                f"--out {out}: holds {strays[0]}/ but no {RECORD} listing what an export wrote there, so its files "
                "cannot be told from others (an older rigctl's export, or another command's): choose another --out"
            )
        return set()
    try:
        data = json.loads(read_regular(path, RECORD_LIMIT, ParameterError, "export record"))
    except ValueError:  # not JSON, or not UTF-8
        data = None
    files = data.get("files") if isinstance(data, dict) else None
    if not isinstance(files, list) or not all(isinstance(f, str) and OURS.fullmatch(f) for f in files):
        raise ParameterError(
            f"{path}: not a record of the files a take export wrote (an older rigctl's lists none), so they cannot "
            "be told from others: choose another --out"
        )
    return set(files)


def remove_ours(out: Path, files: Iterable[str]) -> None:
    """Remove files of ours (listed by a record, or planned by this run) and the frame or camera folders they
    leave empty; a folder holding anything else stays, and so does what it holds."""
    folders = set()
    for name in sorted(files):
        rel = Path(name)
        path = inside(out, out / rel.parent) / rel.name  # never through a link planted in DIR
        try:
            if path.is_file() and not path.is_symlink():
                path.unlink()
        except OSError as exc:
            raise output_error(path, exc) from None
        folders.add(path.parent)
    for folder in sorted(folders):
        with suppress(OSError):
            folder.rmdir()  # only when empty
    if folders:
        fsync_dir(out)


STAGING_PREFIX = ".take-export-"


def staging_folder(out: Path, number: int) -> Path:
    """A new, empty hidden folder in ``out`` where frame set ``number`` is written before it is published."""
    staged = out / f"{STAGING_PREFIX}{number:06d}{PARTIAL_SUFFIX}"
    try:
        if staged.is_dir() and not staged.is_symlink():
            shutil.rmtree(staged)
        staged.mkdir()
    except OSError as exc:
        raise output_error(staged, exc) from None
    return staged


def remove_stale_staging(out: Path) -> None:
    """The hidden frame-set folders a killed export left in ``out`` (this run holds the folder's lock)."""
    for p in out.glob(f"{STAGING_PREFIX}*{PARTIAL_SUFFIX}"):
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)


def publish_frame_set(staged: Path, out: Path, layout: str, number: int) -> None:
    """Publish the whole frame set ``staged`` (its pictures ``<camera>.<ext>``) into ``out`` in ``layout``: a new
    frame set's folder by one rename; an existing one's pictures, and the sequence layout's, each by rename."""
    files = sorted(staged.iterdir())
    if not files:
        return  # every member missing or damaged: nothing to publish, as before
    try:
        if layout == "frames":
            final = inside(out, out / f"{number:06d}")
            if not final.exists():
                os.rename(staged, final)
                fsync_dir(out)
            else:
                move_into(staged, final)
            return
        folders = set()
        for f in files:
            dest = output_path(out, layout, number, f.stem, f.suffix)
            dest.parent.mkdir(exist_ok=True)
            os.replace(f, dest)
            folders.add(dest.parent)
        for folder in sorted(folders):
            fsync_dir(folder)
        fsync_dir(out)
    except OSError as exc:
        raise output_error(out, exc) from None
