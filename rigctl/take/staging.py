"""A take is recorded under hidden names and published under its own at the end: no half take ever carries
the name asked for, and a failed recording leaves the name free.

While recording, each destination's take folder is ``.<NAME>.rigctl-recording``, each held under an ``flock``
for the length of the recording (the primary one holds the manifest). At the end the other destinations' folders are
renamed to ``NAME`` first, the primary one last: that rename publishes the take. A recording that wrote no
frame at all publishes nothing and its folders are removed.

A recorder killed on the way (SIGKILL, power loss) leaves its frames in the hidden folders, readable as they
are (``rigctl take check .<NAME>.rigctl-recording``): nothing recorded is lost. No later run publishes them
(a cut-off recording under the take's name would pass for the take) nor removes a frame of them: a recording
of the same name is refused in one line naming the leftover and what to do (rename it to ``NAME`` to keep it,
or remove it); a recording of another name records, with a warning naming the leftover. Only a leftover of
the same name without a frame anywhere (cut off before its first) is removed, in one line. A leftover is one
whose lock is free: nobody records it.
"""

from __future__ import annotations

import fcntl
import logging
import os
import shutil
from pathlib import Path

from rigctl.errors import RigctlError, TakeError
from rigctl.publish import fsync_dir
from rigctl.take.index import RECORD_SIZE
from rigctl.take.manifest import read_manifest
from rigctl.take.plan import TakePlan

log = logging.getLogger(__name__)

RECORDING_SUFFIX = ".rigctl-recording"


def staging_folder(take_folder: Path) -> Path:
    """Where ``take_folder`` (``<dest>/<NAME>``) is recorded before it is published."""
    return take_folder.parent / f".{take_folder.name}{RECORDING_SUFFIX}"


def _try_lock(folder: Path) -> int | None:
    """A descriptor holding ``folder``'s exclusive lock, or None when a live recorder holds it."""
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        return None
    return fd


def _other_destinations(staged: Path, name: str) -> list[tuple[Path, Path]]:
    """(staging, final) folders of a leftover take's cameras on other destinations, from its manifest (the
    manifest names them by their final, absolute paths)."""
    try:
        manifest = read_manifest(staged)
    except RigctlError:
        return []
    if manifest.take != name:  # a manifest that is not this leftover's own moves nothing
        return []
    out = []
    for entry in manifest.cameras.values():
        path = Path(entry.essence)
        # only this take's camera folder on another destination (``<dest>/<take>/cameras``), as the recorder
        # writes it: a manifest naming any other folder moves nothing
        if path.is_absolute() and path.parent.name == "cameras" and path.parent.parent.name == manifest.take:
            final = path.parent.parent
            pair = (staging_folder(final), final)
            if pair not in out and pair[0].is_dir() and not pair[0].is_symlink():
                out.append(pair)
    return out


def _frames_in(folders: list[Path]) -> int:
    """Frames the index files under ``folders`` hold; 1 for a folder with essence bytes and no index record yet
    (a frame written, its record not): what is recorded there is never removed."""
    frames = 0
    for f in folders:
        cams = [p for p in (f / "cameras").glob("*") if p.is_file() and not p.is_symlink()]
        indexed = sum(p.stat().st_size // RECORD_SIZE for p in cams if p.suffix == ".index")
        frames += indexed or int(any(p.stat().st_size for p in cams if p.suffix == ".essence"))
    return frames


def _status(staged: Path) -> str:
    try:
        return read_manifest(staged).status
    except RigctlError:
        return "no manifest here" if not (staged / "take.yaml").exists() else "unreadable manifest"


def _leftovers(dest: Path) -> list[tuple[Path, int]]:
    """Every hidden take folder on ``dest`` no live recorder holds, each with its lock taken (the caller closes
    every descriptor)."""
    out: list[tuple[Path, int]] = []
    if not dest.is_dir():
        return out
    for staged in sorted(dest.glob(f".*{RECORDING_SUFFIX}")):
        if staged.is_symlink() or not staged.is_dir():
            continue
        try:
            fd = _try_lock(staged)
        except OSError:
            continue
        if fd is not None:  # None: being recorded now
            out.append((staged, fd))
    return out


def cut_off_message(staged: Path, name: str, frames: int, others: list[Path]) -> str:
    """What a recording of ``name`` cut off (killed, power lost) left in ``staged``, and what to do with it."""
    head = f"{staged}: a recording of {name} that was cut off ({frames} frame(s), status: {_status(staged)})"
    if not frames:
        return f"{head}; it holds no frame: remove it (recording {name} there again does)"
    if others:
        return (
            f"{head}, with cameras in {', '.join(map(str, others))}; rigctl never publishes nor removes it: rename "
            f"each folder to {name} beside it to keep it as that take, or remove them"
        )
    return (
        f"{head}; rigctl never publishes nor removes it: 'rigctl take check {staged}' reads it; rename it to "
        f"{staged.parent / name} to keep it as that take, or remove it"
    )


def check_leftovers(destinations: list[Path], final: TakePlan, dry_run: bool = False) -> None:
    """What recorders killed on ``destinations`` left, before recording ``final`` there. No run publishes
    another's interrupted recording, nor removes a frame of it: a leftover of this take's name that holds a frame
    refuses the recording in one line naming it; one without a frame anywhere (cut off before its first) is
    removed, in one line; a leftover of another name is named in a warning and left as it is. ``dry_run``: the
    refusal only, nothing said or removed."""
    held: list[tuple[Path, int]] = []
    try:
        for dest in destinations:
            held.extend(_leftovers(dest))
        ours = {staging_folder(final.folder), *(staging_folder(f.parent) for f in final.camera_folders.values())}
        mine = [s for s, _ in held if s in ours]
        primary = staging_folder(final.folder)
        if primary in mine:  # its manifest names the take's folders elsewhere (by absolute paths), maybe not here
            known = {s.resolve() for s in mine}
            mine += [s for s, _ in _other_destinations(primary, final.name) if s.resolve() not in known]
        for staged, _ in held if not dry_run else []:
            if staged not in ours:
                name = staged.name[1 : -len(RECORDING_SUFFIX)]
                others = [s for s, _ in _other_destinations(staged, name)]
                log.warning("%s", cut_off_message(staged, name, _frames_in([staged, *others]), others))
        frames = _frames_in(mine)
        if frames:
            first = primary if primary in mine else mine[0]
            others = [s for s in mine if s != first]
            raise TakeError(cut_off_message(first, final.name, frames, others))
        for staged in (s for s, _ in held if s in mine and not dry_run):  # under our lock: nobody records it
            shutil.rmtree(staged, ignore_errors=True)
            log.warning("%s: removed what a recording cut off before its first frame left", staged)
    finally:
        for _, fd in held:
            os.close(fd)


class Staging:
    """The hidden folders one recording writes into (:attr:`plan`) and publishes as :attr:`final` at its end."""

    def __init__(self, final: TakePlan) -> None:
        self.final = final
        self.plan = TakePlan(
            final.name,
            staging_folder(final.folder),
            {c: staging_folder(f.parent) / f.name for c, f in final.camera_folders.items()},
        )
        self._fds: list[int] = []  # every take folder's lock, the primary's first

    def take_folders(self) -> list[tuple[Path, Path]]:
        """(staging, final) take folder on every destination, the primary one last."""
        pairs = {(staging_folder(f.parent), f.parent) for f in self.final.camera_folders.values()}
        primary = (self.plan.folder, self.final.folder)
        return [*sorted(pairs - {primary}), primary]

    def check(self) -> None:
        """Refuse in one line, before anything is made, a take whose name is taken or that a cut-off recording
        of the name is in the way of (:meth:`create` decides again, and says what it finds of other names)."""
        self._check(dry_run=True)

    def _check(self, dry_run: bool) -> None:
        check_leftovers([final.parent for _, final in reversed(self.take_folders())], self.final, dry_run)
        if self.final.folder.exists() or self.final.folder.is_symlink():
            raise TakeError(f"{self.final.folder}: a take of that name exists already; takes are never overwritten")

    def create(self) -> None:
        """Check what killed recorders left on the destinations (:func:`check_leftovers`), then make this
        recording's hidden folders (locked); refused in one line when the name is taken, being recorded, or a
        cut-off recording of it is in the way."""
        self._check(dry_run=False)
        folder = self.final.folder
        for staged, _ in reversed(self.take_folders()):  # the primary first: it decides who records the name
            try:
                staged.mkdir(parents=True)
            except FileExistsError:
                self.discard()
                raise TakeError(
                    f"{folder}: {staged} is in the way: another rigctl run is recording a take of that name"
                ) from None
            fd = _try_lock(staged)
            if fd is None:  # made and locked between our mkdir and lock: never ours
                self.discard()
                raise TakeError(f"{folder}: another rigctl run is recording a take of that name")
            self._fds.append(fd)

    def publish(self) -> None:
        """Rename every destination's folder to the take's name, the primary one (the manifest) last."""
        if len(self._fds) != len(self.take_folders()):
            raise TakeError(f"{self.final.folder}: the take was not created by this run")
        try:
            for staged, final in self.take_folders():
                if final.exists() or final.is_symlink():
                    raise TakeError(f"{final}: appeared while recording; the take stays in {staged}")
                os.rename(staged, final)
                fsync_dir(final.parent)
        except OSError as exc:
            raise TakeError(f"{self.final.folder}: cannot publish the take: {exc.strerror or exc}") from None
        finally:
            self.release()

    def settle(self, written: bool, error: RigctlError | None) -> RigctlError | None:
        """At the end of the recording, before its manifest: with no frame ``written``, remove every folder
        and return the error that says nothing was kept; else ``error`` with the files it names called by the
        names they are published under (the hidden ones are gone once the take is published)."""
        if not written:
            self.discard()
            return error or TakeError(f"{self.final.folder}: no frame was recorded; nothing was kept")
        if error is None:
            return None
        text = str(error)
        for staged, final in self.take_folders():
            text = text.replace(str(staged), str(final))
        return error if text == str(error) else type(error)(text)

    def discard(self) -> None:
        """Remove every hidden folder (a recording that wrote no frame: nothing to keep); only this run's."""
        for (staged, _), _fd in zip(reversed(self.take_folders()), self._fds, strict=False):  # those we made
            shutil.rmtree(staged, ignore_errors=True)
        self.release()

    def release(self) -> None:
        for fd in self._fds:
            os.close(fd)
        self._fds.clear()
