"""Publishing outputs: every file a command writes appears whole under its final name or not at all.

:func:`publish_bytes` writes to a hidden temporary name in the same folder (``.<name>.<pid>.rigctl-tmp``),
flushes, fsyncs and renames it over the final name, then fsyncs the folder. A run killed at any instant
leaves the final name either absent, or the previous whole file, or the new whole file; its temporary files
are recognised by their suffix and removed by the next run on the same folder (:func:`remove_stale_temps`).
PNG is encoded in memory (``cv2.imencode``) and published the same way: ``cv2.imwrite`` crashes the process
on a path that is not UTF-8.

:class:`OutputLock` holds an ``flock`` on the output folder itself for the length of a run (the kernel drops
it when the process dies, however it dies): a second run on the same folder is refused in one line.
:func:`prepare_output` refuses, before any work, an output path that cannot be used: not valid UTF-8, a
file where a folder is needed, a folder that cannot be created or written. Failures while writing (disk
full, read-only) become :class:`~rigctl.errors.OutputError`: one line naming the file.
"""

from __future__ import annotations

import errno
import fcntl
import io
import json
import logging
import os
import shutil
import stat
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

from rigctl.errors import DiskFullError, OutputError, ParameterError, RigctlError, TakeError, short_path

if TYPE_CHECKING:  # numpy and OpenCV load when a picture is written, not with every command line
    import numpy as np
    from numpy.typing import NDArray

log = logging.getLogger(__name__)

TEMP_SUFFIX = ".rigctl-tmp"


def utf8_path(path: Path, what: str = "--out") -> None:
    """Refuse a path that is not valid UTF-8 (a byte the file system allows, which OpenCV and OpenEXR do not)."""
    try:
        os.fsencode(path).decode("utf-8")
        str(path).encode("utf-8")
    except UnicodeError:
        shown = os.fsencode(path).decode("utf-8", "backslashreplace")
        raise ParameterError(f"{what} {shown}: the path is not valid UTF-8; choose another name") from None


def output_error(path: Path, exc: OSError) -> RigctlError:
    """One line for a write that failed: the file (shortened when long) and why (full disk and read-only said
    plainly)."""
    shown = short_path(path)
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return DiskFullError(f"{shown}: no space left on the device; the file was not written")
    if exc.errno == errno.EROFS:
        return OutputError(f"{shown}: the file system is read-only")
    if exc.errno in (errno.EACCES, errno.EPERM):
        return OutputError(f"{shown}: permission denied")
    return OutputError(f"{shown}: cannot write: {exc.strerror or exc}")


def prepare_output(out: Path, what: str = "--out") -> Path:
    """Create the output folder (and parents) and prove it usable before any work: valid UTF-8, a folder,
    writable. Returns ``out``."""
    utf8_path(out, what)
    if out.exists() and not out.is_dir():
        raise OutputError(f"{what} {out}: is {kind(out.stat().st_mode)}, not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        if exc.errno in (errno.ENOSPC, errno.EROFS, errno.EACCES, errno.EPERM):
            raise output_error(out, exc) from None
        raise OutputError(f"{out}: cannot make the output folder: {exc.strerror or exc}") from None
    if not os.access(out, os.W_OK | os.X_OK):
        ro = os.statvfs(out).f_flag & os.ST_RDONLY
        raise OutputError(f"{what} {out}: {'the file system is read-only' if ro else 'not writable'}")
    return out


def refuse_inside(out: Path, source: Path, noun: str = "take") -> None:
    """``--out`` may not be the input folder nor lie inside it: a run would write its pictures into what it reads
    (a take then holds files no camera recorded, and the next run over it reads them too)."""
    try:
        src, dst = source.resolve(), out.resolve()
    except (RuntimeError, OSError):  # a loop of links: the reader or the output side names it
        return
    if dst == src or dst.is_relative_to(src):
        raise ParameterError(f"--out {out}: is inside the {noun} {source}; choose a folder outside it")


def check_creatable(path: Path, what: str = "--out", noun: str = "file") -> None:
    """Refuse, before any work, a ``path`` that cannot be made: its nearest existing ancestor must be a folder
    this process can write (nothing is created here, so a run that then fails on its input leaves nothing)."""
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise OutputError(
            f"{what} {path}: cannot make the output {noun}: {parent} is {kind(parent.stat().st_mode)}, not a folder"
        )
    if not os.access(parent, os.W_OK | os.X_OK):
        ro = os.statvfs(parent).f_flag & os.ST_RDONLY
        raise OutputError(
            f"{what} {path}: cannot make the output {noun}: {parent} is {'read-only' if ro else 'not writable'}"
        )


def check_output_file(path: Path, what: str = "--out") -> None:
    """Refuse, before any work, an output file that could not be published: not UTF-8, a name held by a folder,
    device, FIFO or socket, or in a place that cannot be written. A regular file there is replaced."""
    utf8_path(path, what)
    try:
        mode: int | None = os.lstat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):  # the latter: a parent is a file, said below
        mode = None
    except OSError as exc:
        raise output_error(path, exc) from None
    if mode is not None and not (stat.S_ISREG(mode) or stat.S_ISLNK(mode)):
        raise OutputError(f"{what} {path}: is {kind(mode)}, not a file (give a file name)")
    check_creatable(path, what)


def fsync_dir(folder: Path) -> None:
    """Make a folder's entries (a rename, a new file) durable: what a rename publishes survives a power cut."""
    fsync_path(folder, os.O_DIRECTORY)


def fsync_path(path: Path, flags: int = 0) -> None:
    """Make a written file's bytes durable (OSError as the open or the fsync raise it)."""
    fd = os.open(path, os.O_RDONLY | flags)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def temp_name(path: Path) -> Path:
    """The temporary name ``path`` is written under before it is published (same folder, hidden, ours)."""
    return path.with_name(f".{path.name}.{os.getpid()}{TEMP_SUFFIX}")


_KINDS = (
    (stat.S_ISREG, "a file"), (stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket")
)  # fmt: skip


def refuse_special(path: Path) -> None:
    """An output is published by rename over its final name, which would put a regular file in place of a
    FIFO, a device (``/dev/null`` as root) or a socket there, or fail on a folder: refused in one line first."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return
    except OSError as exc:
        raise output_error(path, exc) from None
    if stat.S_ISREG(mode) or stat.S_ISLNK(mode):
        return
    raise OutputError(f"{path}: exists and is {kind(mode)}, not a file: not replaced (choose another output name)")


def kind(mode: int) -> str:
    """What a file of ``st_mode`` is, for a message: ``a file``, ``a folder``, ``a FIFO``, ``a socket``,
    ``a device``."""
    return next((k for test, k in _KINDS if test(mode)), "a device")


@contextmanager
def publishing(path: Path, durable: bool = True, exists: str | None = None) -> Iterator[Path]:
    """Yields the temporary name to write (same folder, hidden, ours), then fsyncs it, renames it over ``path``
    and fsyncs the folder; on any failure the temporary file is removed and an OSError becomes one line.
    ``durable=False`` leaves out the two fsyncs (about 10 ms a file on a busy disk) for files that can be made
    again, such as a simulated take's truth: a killed process still leaves each whole or absent, a power cut
    may not. ``exists``: never replace ``path``; if something holds the name when the file is published (made
    by another run since the caller looked), the ParameterError ``"<path>: <exists>"`` and nothing changed."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise output_error(path.parent, exc) from None
    refuse_special(path)
    tmp = temp_name(path)
    try:
        yield tmp
        if durable:
            fsync_path(tmp)
        if exists is None:
            os.replace(tmp, path)
        else:
            _publish_new(tmp, path, exists)
        if durable:
            fsync_dir(path.parent)
    except OSError as exc:
        _discard(tmp)
        raise output_error(path, exc) from None
    except BaseException:
        _discard(tmp)
        raise


# a link() a file system does not offer (FAT, some network and FUSE mounts)
_NO_LINKS = {errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EXDEV, errno.EMLINK}


def _publish_new(tmp: Path, path: Path, exists: str) -> None:
    """``tmp`` published as ``path`` only if nothing holds that name: a hard link, which the kernel refuses
    atomically when the name exists (a rename would replace it), then the temporary name removed. Where the
    file system has no hard links, an exclusive create claims the name first and the rename fills it."""
    try:
        os.link(tmp, path)
    except FileExistsError:
        _discard(tmp)
        raise ParameterError(f"{path}: {exists}") from None
    except OSError as exc:
        if exc.errno not in _NO_LINKS:
            raise
        try:
            os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
        except FileExistsError:
            _discard(tmp)
            raise ParameterError(f"{path}: {exists}") from None
        os.replace(tmp, path)
        return
    tmp.unlink()


def _discard(tmp: Path) -> None:
    """Remove a temporary that may never have been made: on a read-only file system unlink fails with EROFS
    rather than ENOENT, and that must not hide why the write failed."""
    with suppress(OSError):
        tmp.unlink()


def move_into(staged: Path, final: Path) -> list[Path]:
    """Publish the whole files of the staging folder ``staged`` (written through :func:`publishing`, so each
    already fsynced) into ``final`` by rename, one by one (a reader sees a whole file or none), then fsync
    ``final`` and the folder it is in (it may be new) and remove the empty staging folder. Returns the files
    as published, in name order."""
    try:
        fresh = not final.exists()
        final.mkdir(parents=True, exist_ok=True)
        moved = []
        for f in sorted(staged.iterdir()):
            os.replace(f, final / f.name)
            moved.append(final / f.name)
        fsync_dir(final)
        if fresh:
            fsync_dir(final.parent)
        staged.rmdir()
    except OSError as exc:
        raise output_error(final, exc) from None
    return moved


def publish_bytes(path: Path, data: bytes | memoryview, durable: bool = True, exists: str | None = None) -> None:
    """Write ``data`` to ``path`` atomically: temporary name, flush, fsync, rename, fsync the folder
    (``exists``: never over an existing file, see :func:`publishing`)."""
    with publishing(path, durable, exists) as tmp, open(tmp, "wb") as f:
        f.write(data)


def publish_text(path: Path, text: str, exists: str | None = None) -> None:
    publish_bytes(path, text.encode("utf-8"), exists=exists)


def publish_json(path: Path, data: object, **kwargs: object) -> None:
    publish_text(path, json.dumps(data, indent=1, **kwargs))  # type: ignore[arg-type]


def publish_png(path: Path, image: NDArray[np.integer] | NDArray[np.floating], durable: bool = True) -> None:
    """Encode ``image`` (8- or 16-bit, 1, 3 or 4 channels, OpenCV's channel order) as PNG and publish it."""
    import cv2

    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise OutputError(f"{path}: the image could not be encoded as PNG")
    publish_bytes(path, buf.data, durable)


def publish_figure(path: Path, figure: Any, dpi: int) -> None:
    """A matplotlib figure rendered as PNG in memory and published whole (``savefig`` writes in place)."""
    buf = io.BytesIO()
    figure.savefig(buf, format="png", dpi=dpi)
    publish_bytes(path, buf.getbuffer())


def remove_stale_temps(folder: Path) -> int:
    """Remove the temporary files a killed run left under ``folder`` (ours by their suffix); the caller
    holds the folder's :class:`OutputLock`, so none of them belongs to a live run. Returns how many."""
    removed = 0
    if not folder.is_dir():
        return 0
    for p in folder.rglob(f".*{TEMP_SUFFIX}"):
        if p.is_file() and not p.is_symlink():
            p.unlink(missing_ok=True)
            removed += 1
    if removed:
        log.info("%s: removed %d unfinished file(s) of an interrupted run", folder, removed)
    return removed


class OutputLock:
    """An exclusive ``flock`` on an output folder for the length of a run; refused in one line when another
    run holds it. The lock is on the folder itself, so it leaves nothing behind and dies with the process."""

    def __init__(self, folder: Path, verb: str) -> None:
        self.folder = folder
        self.verb = verb
        self.fd: int | None = None

    def __enter__(self) -> OutputLock:
        try:
            fd = os.open(self.folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        except OSError as exc:
            raise output_error(self.folder, exc) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise OutputError(
                f"{self.folder}: another rigctl run is writing this folder; wait for it to end or choose another --out"
            ) from None
        self.fd = fd
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        if self.fd is not None:
            os.close(self.fd)  # closing the descriptor drops the lock
            self.fd = None


class NewFolders:
    """Output folders and those of their parents that do not exist yet, noted before a run makes them, so that
    :meth:`remove_empty` takes away again what the run made and left empty (a run that fails before writing
    anything leaves no empty folder behind, to be found and cleared by hand). A folder the user made, or one
    holding anything, stays."""

    def __init__(self, *outs: Path) -> None:
        self.chains: list[list[Path]] = []  # per output, deepest first
        for out in outs:
            chain, p = [], out
            while not p.exists() and not p.is_symlink() and p != p.parent:
                chain.append(p)
                p = p.parent
            self.chains.append(chain)

    def remove_empty(self) -> None:
        for chain in self.chains:
            for folder in chain:
                try:
                    folder.rmdir()
                except FileNotFoundError:
                    continue  # another output of the run that shares it removed it, or it was never made
                except OSError:
                    break  # not empty (or not ours to remove): it stays, and so do its parents


@contextmanager
def output_folder(out: Path, verb: str, what: str = "--out") -> Iterator[Path]:
    """An output folder prepared (:func:`prepare_output`), locked for this run (:class:`OutputLock`) and
    cleared of the temporary files of an interrupted run: the whole of a writing command's output side. A
    folder this run made is removed again when the run fails before writing anything into it (a wrong input
    leaves no empty folder behind); nothing a run wrote is ever removed."""
    made = NewFolders(out)
    prepare_output(out, what)
    with OutputLock(out, verb):
        try:
            remove_stale_temps(out)
            yield out
        except BaseException:
            made.remove_empty()
            raise


PARTIAL_SUFFIX = ".rigctl-partial"


def partial_name(out: Path) -> Path:
    """Where a new folder (a rectified take) is built before it is published under ``out``."""
    return out.parent / f".{out.name}{PARTIAL_SUFFIX}"


@contextmanager
def publishing_folder(out: Path, verb: str, exists_message: str) -> Iterator[Path]:
    """Build a new folder under a hidden partial name beside ``out`` (ours, locked for this run) and rename it
    to ``out`` once whole. A run killed on the way leaves only the partial folder, which the same command run
    again clears and rebuilds; a run holding it is refused in one line; an existing ``out`` is never touched."""
    utf8_path(out)
    if out.exists() or out.is_symlink():
        raise TakeError(f"{out}: {exists_message}")
    prepare_output(out.parent)
    partial = partial_name(out)
    if partial.is_symlink() or (partial.exists() and not partial.is_dir()):
        raise OutputError(f"{partial}: is in the way of {out} and not a folder rigctl made; remove it")
    try:
        partial.mkdir(exist_ok=True)
    except OSError as exc:
        raise output_error(partial, exc) from None
    with OutputLock(partial, verb):
        leftovers = list(partial.iterdir())
        for p in leftovers:  # an interrupted run of ours: begun again from nothing
            shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink()
        if leftovers:
            log.warning("%s: removed the unfinished output of an interrupted run", partial)
        try:
            yield partial
            if out.exists() or out.is_symlink():
                raise TakeError(f"{out}: {exists_message}")
            os.rename(partial, out)
            fsync_dir(out.parent)
        except OSError as exc:
            shutil.rmtree(partial, ignore_errors=True)
            raise output_error(out, exc) from None
        except BaseException:
            shutil.rmtree(partial, ignore_errors=True)
            raise
