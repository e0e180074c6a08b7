"""Issue 25, property-based: a valid recorded take, mutated (a manifest value, an index record rewritten with a
valid CRC, a file swapped for a FIFO, a folder, /dev/zero, an empty or cut file), then read as every reader
reads it. Each example either refuses with the project's one-line error, or reads exactly what was
recorded; and whenever ``take check`` passes, every reader succeeds (check proves what readers rely on).
Memory is bounded by tracemalloc's peak; time by the same limits (not asserted with a clock)."""

from __future__ import annotations

import os
import shutil
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from reliab_support import FIELDS, camera_file, make_tiny, rewrite_records  # type: ignore[import-not-found]

from rigctl.errors import RigctlError
from rigctl.take.check import check_take
from rigctl.take.reader import TakeReader

MEMORY_BOUND = 64 << 20
PROPERTY = settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**64), max_value=2**64),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.sampled_from(["../../x", "/dev/zero", "r0c1.essence", "cameras/r0c1.index", "bogus", "r0c0\n"]),
    st.lists(st.integers(-5, 5), max_size=3),
    st.dictionaries(st.text(max_size=5), st.integers(), max_size=2),
)
CAMS = [f"r{r}c{c}" for r in range(3) for c in range(3)]
RECORD_VALUES = {
    "version": st.integers(0, 2**16 - 1),
    "flags": st.integers(0, 2**16 - 1),
    "sequence": st.integers(0, 2**64 - 1),
    "capture_ns": st.integers(-(2**63), 2**63 - 1),
    "host_ns": st.integers(-(2**63), 2**63 - 1),
    "offset": st.integers(0, 2**64 - 1),
    "size": st.integers(0, 2**32 - 1),
    "set": st.integers(-(2**31), 2**31 - 1),
    "tc": st.integers(0, 2**32 - 1),
}


@pytest.fixture
def scratch(tmp_path: Path) -> Path:
    """One test's folder, reused by each of its examples (a copy per example filled the disk)."""
    return tmp_path


def copy(take: Path, scratch: Path) -> Path:
    """A fresh copy of the take for one example, in place of the last example's."""
    shutil.rmtree(scratch / "t", ignore_errors=True)
    return Path(shutil.copytree(take, scratch / "t"))


class Recorded(tuple):  # type: ignore[type-arg]
    """(take, frames): shown briefly when hypothesis reports an example."""

    def __repr__(self) -> str:
        return f"Recorded({self[0]})"


@pytest.fixture(scope="module")
def recorded(module_tmp: Callable[[str], Path]) -> tuple[Path, dict[tuple[str, int], bytes]]:
    """The take, and every frame it holds by camera and essence offset, as recorded."""
    take, _ = make_tiny(module_tmp("mut"))
    with TakeReader(take) as r:
        frames = {
            (n, int(r.index[n][i]["offset"])): r.frame_bytes(n, i).tobytes()
            for n in r.names
            for i in range(len(r.index[n]))
        }
    return Recorded((take, frames))


def read_everything(take: Path, recorded: dict[tuple[str, int], bytes]) -> None:
    """What every reader does: manifest, indexes, frame sets, each frame's bytes (they must be as recorded)."""
    with TakeReader(take) as r:
        r.summary()
        for fs in r.frame_sets:
            for name, i in fs.members.items():
                data = r.frame_bytes(name, i).tobytes()
                assert data == recorded[(name, int(r.index[name][i]["offset"]))], "a frame read is not as recorded"


def verdict(take: Path, recorded: dict[tuple[str, int], bytes]) -> None:
    tracemalloc.start()
    try:
        proven = check_take(take).ok
        try:
            read_everything(take, recorded)
        except RigctlError as exc:
            assert str(exc) and "\n" not in str(exc)
            assert not proven, f"take check passed, a reader refused: {exc}"
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    assert peak < MEMORY_BOUND


def mutate(data: Any, path: list[int], value: Any) -> Any:
    if not path or not isinstance(data, dict | list) or not data:
        return value
    if isinstance(data, dict):
        key = list(data)[path[0] % len(data)]
        return {**data, key: mutate(data[key], path[1:], value)}
    i = path[0] % len(data)
    return [*data[:i], mutate(data[i], path[1:], value), *data[i + 1 :]]


@PROPERTY
@given(path=st.lists(st.integers(0, 40), min_size=1, max_size=4), value=VALUES)
def test_a_manifest_value_changed(recorded, scratch, path: list[int], value: Any) -> None:  # type: ignore[no-untyped-def]
    take = copy(recorded[0], scratch)
    data = yaml.safe_load((take / "take.yaml").read_text())
    (take / "take.yaml").write_text(yaml.safe_dump(mutate(data, path, value), sort_keys=False))
    verdict(take, recorded[1])


@PROPERTY
@given(
    cam=st.sampled_from(CAMS),
    record=st.integers(0, 2),
    field=st.sampled_from(sorted(RECORD_VALUES)),
    data=st.data(),
)
def test_an_index_record_rewritten_with_a_valid_crc(recorded, scratch, cam, record, field, data) -> None:  # type: ignore[no-untyped-def]
    take = copy(recorded[0], scratch)
    value = data.draw(RECORD_VALUES[field])
    assert field in FIELDS

    def edit(i: int, f: dict[str, Any]) -> None:
        if i == record:
            f[field] = value

    rewrite_records(camera_file(take, cam, "index"), edit)
    verdict(take, recorded[1])


@PROPERTY
@given(
    which=st.sampled_from(["take.yaml", "essence", "index"]),
    kind=st.sampled_from(["fifo", "folder", "dev_zero", "empty", "cut", "missing"]),
    cam=st.sampled_from(CAMS),
)
def test_a_file_of_another_kind(recorded, scratch, which: str, kind: str, cam: str) -> None:  # type: ignore[no-untyped-def]
    take = copy(recorded[0], scratch)
    path = take / "take.yaml" if which == "take.yaml" else camera_file(take, cam, which)
    size = path.stat().st_size
    if kind == "cut":
        os.truncate(path, size // 2)
    elif kind == "empty":
        os.truncate(path, 0)
    else:
        path.unlink()
        if kind == "fifo":
            os.mkfifo(path)
        elif kind == "folder":
            path.mkdir()
        elif kind == "dev_zero":
            path.symlink_to("/dev/zero")
    verdict(take, recorded[1])
