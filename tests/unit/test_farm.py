"""Logic of ``rigctl process`` that needs no cluster: scheduler addresses, the progress line's rate and ETA
(clock injected), the ledger."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from rigctl.depth.export import file_record
from rigctl.errors import ParameterError, TakeError
from rigctl.farm.ledger import FrameEntry, Ledger
from rigctl.farm.run import Status, eta_text, scheduler_url, worker_memory_bytes


@pytest.mark.parametrize("url", ["tcp://127.0.0.1:8786", "tcp://render-01.studio.lan:1", "tcp://[::1]:65535"])
def test_scheduler_addresses_accepted(url: str) -> None:
    assert scheduler_url(url) == url


@pytest.mark.parametrize(
    "url", ["127.0.0.1:8786", "tls://h:1", "tcp://h:0", "tcp://h:65536", "tcp://h", "tcp://h:80/x", "tcp://-h:1", ""]
)
def test_scheduler_addresses_refused(url: str) -> None:
    with pytest.raises(ParameterError, match="--scheduler: expected tcp://HOST:PORT"):
        scheduler_url(url)


def test_rate_and_eta_follow_the_clock() -> None:
    now = [100.0]
    st = Status(total=10, clock=lambda: now[0])
    assert st.rate() == 0.0 and st.eta_s() is None and "ETA --:--" in st.line()
    now[0] = 120.0
    st.done, st.failed = 3, 1
    assert st.rate() == pytest.approx(0.2)
    assert st.eta_s() == pytest.approx(30.0)
    assert st.line() == "3 done, 1 failed of 10, 0.20 frames/s, ETA 0:00:30"
    assert eta_text(3725.0) == "1:02:05" and eta_text(float("inf")) == "--:--"


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
