"""A take is recorded under hidden names and published under its own at the end: no half take ever carries
the name asked for, and a failed recording leaves the name free.

While recording, each destination's take folder is ``.<NAME>.rigctl-recording``, each held under an ``flock``
for the length of the recording (the primary one holds the manifest). At the end the other destinations' folders are
renamed to ``NAME`` first, the primary one last: that rename publishes the take. A recording that wrote no
frame at all publishes nothing and its folders are removed.

A recorder killed on the way (SIGKILL, power loss) leaves its frames in the hidden folders, readable as they
are (``rigctl take check .<NAME>.rigctl-recording``): nothing recorded is lost. The next recording on that
destination finds them (their lock is free: nobody records them) and publishes them under their name as the
take they are (``status: recording``, every indexed frame readable), in one line; a leftover without a frame
is removed, also in one line; one that cannot be published (its name is taken) is named and left alone.
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
    return sum(p.stat().st_size // RECORD_SIZE for f in folders for p in (f / "cameras").glob("*.index") if p.is_file())


def recover_leftovers(dest: Path) -> list[Path]:
    """Publish (or, holding no frame, remove) what recorders killed on ``dest`` left; returns the takes
    published. A leftover a live recorder holds is not touched."""
    published: list[Path] = []
    if not dest.is_dir():
        return published
    for staged in sorted(dest.glob(f".*{RECORDING_SUFFIX}")):
        if staged.is_symlink() or not staged.is_dir():
            continue
        try:
            fd = _try_lock(staged)
        except OSError:
            continue
        if fd is None:
            continue  # being recorded now
        try:
            final = dest / staged.name[1 : -len(RECORDING_SUFFIX)]
            others = _other_destinations(staged, final.name)
            frames = _frames_in([staged, *(s for s, _ in others)])
            if frames and not (staged / "take.yaml").is_file():  # cameras of a take whose manifest is elsewhere
                log.warning(
                    "%s: %d frame(s) of cameras of a recording of %s that was cut off; they are published with the "
                    "folder that holds its take.yaml (on the first destination), else left here",
                    staged,
                    frames,
                    final.name,
                )
            elif frames == 0:
                for s in [staged, *(s for s, _ in others)]:
                    shutil.rmtree(s, ignore_errors=True)
                log.warning("%s: removed what a recording cut off before its first frame left", staged)
            elif final.exists() or final.is_symlink() or any(f.exists() for _, f in others):
                log.warning(
                    "%s: %d frame(s) of a recording of %s that was cut off; %s exists, so they stay here (rename "
                    "the folder to keep them as a take, or remove it)",
                    staged,
                    frames,
                    final.name,
                    final,
                )
            else:
                for s, f in others:
                    os.rename(s, f)
                    fsync_dir(f.parent)
                os.rename(staged, final)
                fsync_dir(dest)
                published.append(final)
                log.warning(
                    "%s: the %d frame(s) of a recording that was cut off are kept as take %s (status: recording; "
                    "rigctl take check %s)",
                    final,
                    frames,
                    final.name,
                    final,
                )
        except OSError as exc:
            log.warning("%s: left as it is, a recording that was cut off: %s", staged, exc.strerror or exc)
        finally:
            os.close(fd)
    return published


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

    def create(self) -> None:
        """Publish what killed recorders left on the destinations, then make this recording's hidden folders
        (locked); refused in one line when the name is taken or being recorded."""
        for _, final in reversed(self.take_folders()):  # the primary first: it takes its other folders along
            recover_leftovers(final.parent)
        folder = self.final.folder
        if folder.exists() or folder.is_symlink():
            raise TakeError(f"{folder}: a take of that name exists already; takes are never overwritten")
        for staged, _ in reversed(self.take_folders()):  # the primary first: it decides who records the name
            try:
                staged.mkdir(parents=True)
            except FileExistsError:
                self.discard()
                raise TakeError(
                    f"{folder}: {staged} is in the way: another rigctl run is recording a take of that name, or "
                    "a recording of it was cut off (see the line above)"
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
