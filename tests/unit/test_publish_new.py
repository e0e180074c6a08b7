"""``publish.publishing(..., exists=...)``: a file published only where nothing holds its name, decided at the
moment of publishing (a hard link, or an exclusive create where the file system has no hard links), never by
a rename that would replace what another run published meanwhile."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest

from rigctl.errors import ParameterError
from rigctl.publish import publish_bytes

NOTE = "already exists; never replaced"


def no_hard_links(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*_args: object, **_kw: object) -> None:
        raise OSError(errno.EPERM, "Operation not permitted")  # what FAT and many FUSE mounts answer

    monkeypatch.setattr(os, "link", refuse)


@pytest.mark.parametrize("links", [True, False])
def test_a_free_name_is_published_whole(tmp_path: Path, links: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    if not links:
        no_hard_links(monkeypatch)
    publish_bytes(tmp_path / "a.yaml", b"mine", exists=NOTE)
    assert [p.name for p in tmp_path.iterdir()] == ["a.yaml"]  # the temporary name is gone
    assert (tmp_path / "a.yaml").read_bytes() == b"mine"
    assert os.stat(tmp_path / "a.yaml").st_nlink == 1


@pytest.mark.parametrize("links", [True, False])
def test_a_taken_name_is_refused_and_kept(tmp_path: Path, links: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    if not links:
        no_hard_links(monkeypatch)
    (tmp_path / "a.yaml").write_bytes(b"theirs")
    with pytest.raises(ParameterError, match=r"a\.yaml: already exists; never replaced"):
        publish_bytes(tmp_path / "a.yaml", b"mine", exists=NOTE)
    assert [p.name for p in tmp_path.iterdir()] == ["a.yaml"]
    assert (tmp_path / "a.yaml").read_bytes() == b"theirs"


def test_without_exists_a_file_is_still_replaced(tmp_path: Path) -> None:
    (tmp_path / "a.yaml").write_bytes(b"old")
    publish_bytes(tmp_path / "a.yaml", b"new")
    assert (tmp_path / "a.yaml").read_bytes() == b"new"
