"""Logic of ``rigctl process`` that needs no cluster: scheduler addresses, the memory bound
(clock injected), the ledger."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from rigctl.depth.export import file_record
from rigctl.depth.options import DepthOptions
from rigctl.errors import ParameterError, TakeError
from rigctl.farm.ledger import FrameEntry, Ledger
from rigctl.farm.run import scheduler_url, worker_memory_bytes


@pytest.mark.parametrize("url", ["tcp://127.0.0.1:8786", "tcp://render-01.studio.lan:1", "tcp://[::1]:65535"])
def test_scheduler_addresses_accepted(url: str) -> None:
    assert scheduler_url(url) == url


@pytest.mark.parametrize(
    "url", ["127.0.0.1:8786", "tls://h:1", "tcp://h:0", "tcp://h:65536", "tcp://h", "tcp://h:80/x", "tcp://-h:1", ""]
)
def test_scheduler_addresses_refused(url: str) -> None:
    with pytest.raises(ParameterError, match="--scheduler: expected tcp://HOST:PORT"):
        scheduler_url(url)


def test_ledger_is_rewritten_whole_and_refuses_what_is_not_one(tmp_path: Path) -> None:
    led = Ledger(tmp_path)
    led.record("000001", FrameEntry(status="done", worker="tcp://a:1", seconds=1.5))
    led.record("000000", FrameEntry(status="failed", worker="tcp://b:2", seconds=0.1, error="x"))
    led.save()
    data = json.loads((tmp_path / "process.json").read_text())
    assert list(data["frames"]) == ["000000", "000001"]
    assert Ledger(tmp_path).done("000001") and not Ledger(tmp_path).done("000000")
    assert [p.name for p in tmp_path.iterdir()] == ["process.json"]  # no temporary file left
    (tmp_path / "process.json").write_text("{not json")
    with pytest.raises(TakeError, match=r"process\.json: not a process ledger"):
        Ledger(tmp_path)


@pytest.mark.parametrize(
    ("text", "where"),
    [
        ('{"frames": {"000000": 5}}', "frames.000000"),  # ended in an AttributeError before
        ('{"frames": {"000000": {"status": "maybe"}}}', "frames.000000.status"),
        ('{"frames": []}', "frames"),
        ("[1, 2]", "the file"),
        ('{"frames": {}, "extra": 1}', "extra"),
    ],
)
def test_a_ledger_that_is_not_one_is_refused_in_one_line_naming_file_and_field(
    tmp_path: Path, text: str, where: str
) -> None:
    (tmp_path / "process.json").write_text(text)
    with pytest.raises(TakeError) as info:
        Ledger(tmp_path)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(f"{tmp_path / 'process.json'}: not a process ledger"), msg
    assert f": {where}: " in msg, msg


def test_ledger_never_writes_nan(tmp_path: Path) -> None:
    with pytest.raises(ValueError):
        Ledger(tmp_path).record("000000", FrameEntry(status="done", seconds=float("nan")))


def test_resume_trusts_a_done_frame_only_while_its_files_are_whole(tmp_path: Path) -> None:
    folder = tmp_path / "depth" / "000000"
    folder.mkdir(parents=True)
    (folder / "r1c1.pfm").write_bytes(b"PF data")
    led = Ledger(tmp_path)
    led.record("000000", FrameEntry(status="done", files={"r1c1.pfm": file_record(folder / "r1c1.pfm")}))
    led.save()
    assert Ledger(tmp_path).whole("000000", folder)
    (folder / "r1c1.pfm").write_bytes(b"PF dat4")  # same size, other bytes: a damaged file
    assert not Ledger(tmp_path).whole("000000", folder)
    (folder / "r1c1.pfm").write_bytes(b"PF")  # cut short
    assert not Ledger(tmp_path).whole("000000", folder)
    (folder / "r1c1.pfm").unlink()
    assert not Ledger(tmp_path).whole("000000", folder)
    led.record("000001", FrameEntry(status="done"))  # a done frame that recorded no file is not trusted
    assert not led.whole("000001", folder)


def test_worker_memory_grows_with_pixels_and_cameras() -> None:
    small, big = worker_memory_bytes(480, 270, 9), worker_memory_bytes(3840, 2160, 9)
    assert small < worker_memory_bytes(480, 270, 18) and small < big


@pytest.mark.parametrize(
    "size,peak_gib",
    [
        *(((480, 270), 0.40), ((1920, 1080), 0.74), ((3840, 2160), 1.92)),
        *(((960, 540), 0.87), ((1920, 1080), 1.12), ((3840, 2160), 2.52)),
    ],
    ids=["270p", "1080p", "4K", "540p-chunk", "1080p-chunk", "4K-chunk"],
)
def test_the_worker_bound_leaves_the_measured_peaks_below_dasks_pause(size: tuple[int, int], peak_gib: float) -> None:
    """``rigctl bench depth --size`` peaks of nine cameras (README, issue 24), and the peaks of a chunk's
    frame sets with the temporal stabiliser's state (``benchmarks/chunk_memory.py``: three at 960x540 and
    1920x1080, two at 3840x2160): Dask pauses a worker at 80 % of its limit, which must lie above what a worker
    was measured to hold, with a fifth to spare for pictures other than the simulator's."""
    assert 0.8 * worker_memory_bytes(*size, 9) > 1.2 * peak_gib * 2**30


def test_the_take_search_settles_on_the_hull_of_every_chunk_whatever_their_order() -> None:
    from rigctl.depth.pipeline import ChunkEnd, settle
    from rigctl.depth.take_range import MAX_ROUNDS, SearchState, Widening, hull

    a = SearchState(disparity_range_px=(10.0, 20.0))
    b = SearchState(disparity_range_px=(10.0, 26.0), spurious_hits=(0, 70))
    c = SearchState(disparity_range_px=(6.0, 20.0))
    assert hull([a, b, c]) == hull([c, b, a]) == SearchState(disparity_range_px=(6.0, 26.0), spurious_hits=(0, 70))
    wide = Widening(frame=7, before=(10.0, 20.0), after=(10.0, 26.0), low_hits=0, high_hits=900)
    starts: list[SearchState] = []

    def run_round(state: SearchState, n: int) -> list[ChunkEnd]:  # chunk 2 widens in the first round only
        starts.append(state)
        return [ChunkEnd(state, []), ChunkEnd(hull([state, b]), [wide] if n == 1 else [])]

    done = settle(run_round, a, planned=False)
    assert starts == [a, hull([a, b])] and done.state == hull([a, b]) and done.rounds == 2 and done.settled
    assert done.widenings == [wide]
    starts.clear()
    assert settle(run_round, a, planned=True).rounds == 1 and starts == [a]  # a plan is never widened

    def ever_wider(state: SearchState, n: int) -> list[ChunkEnd]:
        lo, hi = state.disparity_range_px
        return [ChunkEnd(SearchState(disparity_range_px=(lo, hi + 1)), [])]

    endless = settle(ever_wider, a, planned=False)
    assert endless.rounds == MAX_ROUNDS and not endless.settled


def test_resume_skips_a_whole_chunk_only_when_it_started_from_the_take_state(tmp_path: Path) -> None:
    from rigctl.depth.take_range import SearchState
    from rigctl.farm.run import Work

    s1, s2 = SearchState(disparity_range_px=(0.0, 8.0)), SearchState(disparity_range_px=(0.0, 12.0))
    led = Ledger(tmp_path)
    for n, start in ((0, s1), (1, s1), (2, s1), (3, s2)):
        led.record(f"{n:06d}", FrameEntry(status="done", start=start))
    work = Work([[0, 1], [2, 3]], {0, 1, 2, 3}, led)
    assert work.todo(s1) == ([[2, 3]], [0, 1])
    assert work.todo(s2) == ([[0, 1], [2, 3]], [])
    assert Work([[0, 1], [2, 3]], {0, 1, 2, 3}, led, redo=True).todo(s1) == ([[0, 1], [2, 3]], [])


def _durability_log(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, str]]:
    """Every rename (its source) and fsync (the path of what it made durable) in order."""
    import os

    events: list[tuple[str, str]] = []
    real_fsync, real_replace, real_rename = os.fsync, os.replace, os.rename

    def fsync(fd: int) -> None:
        events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}")))
        real_fsync(fd)

    def renaming(real):  # type: ignore[no-untyped-def]
        def rename(src: object, dst: object) -> None:
            events.append(("rename", str(Path(src).resolve())))  # type: ignore[arg-type]
            real(src, dst)

        return rename

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", renaming(real_replace))
    monkeypatch.setattr(os, "rename", renaming(real_rename))
    return events


def _durable_after_last_rename(events: list[tuple[str, str]], *folders: Path) -> bool:
    last = max(i for i, (kind, _) in enumerate(events) if kind == "rename")
    synced = {p for kind, p in events[last:] if kind == "fsync"}
    return all(str(f.resolve()) in synced for f in folders)


def test_a_farm_frame_is_published_durably_files_then_their_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The farm stages a frame's files and renames them into the frame's folder: the frame's folder (new, so
    its parent too) is fsynced after the last rename, so a power cut cannot take back a frame the ledger has."""
    from rigctl.depth.export import publish
    from rigctl.publish import publish_bytes

    staged = tmp_path / ".partial-000003-abc"
    for name in ("r0c0.pfm", "r0c0.png"):
        publish_bytes(staged / name, name.encode() * 100)
    events = _durability_log(monkeypatch)
    final = tmp_path / "000003"
    records = publish(staged, final)
    assert sorted(records) == ["r0c0.pfm", "r0c0.png"] and not staged.exists()
    assert (final / "r0c0.pfm").read_bytes() == b"r0c0.pfm" * 100
    assert _durable_after_last_rename(events, final, tmp_path)


def test_the_process_ledger_is_fsynced_before_and_after_its_rename(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    ledger = Ledger(tmp_path)
    ledger.record("000000", FrameEntry(status="failed", error="x"))
    events = _durability_log(monkeypatch)
    ledger.save()
    renamed = [(i, p) for i, (kind, p) in enumerate(events) if kind == "rename"]
    assert renamed
    i, source = renamed[-1]
    assert ("fsync", source) in events[:i]  # the file's bytes are on the device before its name is
    assert _durable_after_last_rename(events, tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == ["process.json"]


def test_plots_are_published_whole_through_a_temporary_name(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """savefig wrote report plots in place (a kill left a cut PNG); now each is rendered in memory, written
    under a temporary name, fsynced and renamed."""
    import cv2
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from rigctl.publish import publish_figure

    fig, ax = plt.subplots(figsize=(2, 1))
    ax.plot([0, 1], [1, 0])
    events = _durability_log(monkeypatch)
    publish_figure(tmp_path / "plot.png", fig, 50)
    plt.close(fig)
    renamed = [p for kind, p in events if kind == "rename"]
    assert len(renamed) == 1 and renamed[0] != str((tmp_path / "plot.png").resolve())
    assert ("fsync", renamed[0]) in events and _durable_after_last_rename(events, tmp_path)
    img = cv2.imdecode(np.frombuffer((tmp_path / "plot.png").read_bytes(), np.uint8), cv2.IMREAD_UNCHANGED)
    assert img is not None and img.shape[:2] == (50, 100)
    assert [p.name for p in tmp_path.iterdir()] == ["plot.png"]


@pytest.mark.parametrize(
    ("opt", "words"),
    [
        (DepthOptions(near_m=3.0, far_m=2.0), "--near must be positive and below --far"),
        (DepthOptions(near_m=2.0, far_m=2.0), "--near must be positive and below --far"),
        (DepthOptions(preset="slowest"), "unknown preset"),
        (DepthOptions(disparity_range=(40.0, 10.0)), "disparity range"),
        (DepthOptions(margin_px=float("nan")), "margin"),
        (DepthOptions(chunk=0), "--chunk"),
        (DepthOptions(warmup=-1), "--warmup"),
    ],
)
def test_depth_options_no_take_could_run_with_are_refused_without_a_take(opt: DepthOptions, words: str) -> None:
    with pytest.raises(ParameterError, match=re.escape(words)):
        opt.check()


def test_depth_options_a_take_could_run_with_pass_the_check() -> None:
    DepthOptions(near_m=1.0, far_m=math.inf).check()
    DepthOptions(disparity_range=(0.0, 40.0), chunk=1, warmup=0).check()
