"""The viewer's make-ahead queue (rigctl.viewer.makeahead) with an injected ``make``: what is dropped from the
bounded cache while still queued is not made, what someone waits for is. Deterministic: the thread is held
inside the first ``make`` while the queue is arranged, so nothing depends on timing."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator

import pytest

from rigctl.viewer.makeahead import MakeAhead


class Held:
    """A ``make`` that records what it makes and holds the thread inside the first one until released."""

    def __init__(self) -> None:
        self.made: list[int] = []
        self.inside = threading.Event()
        self.gate = threading.Event()

    def __call__(self, number: int) -> bytes:
        self.made.append(number)
        if len(self.made) == 1:
            self.inside.set()
            assert self.gate.wait(30)
        return b"%d" % number


@pytest.fixture
def held() -> Iterator[tuple[Held, MakeAhead]]:
    make = Held()
    ahead = MakeAhead(make, cache=3)
    yield make, ahead
    make.gate.set()
    ahead.close(30)


def until(condition: Callable[[], bool]) -> None:
    """Wait for a state another thread reaches (not for a time): fails only if it never comes."""
    deadline = time.monotonic() + 30
    while not condition():
        assert time.monotonic() < deadline, "never reached"
        time.sleep(0.001)


def test_frame_sets_dropped_from_the_cache_while_queued_are_not_made(held: tuple[Held, MakeAhead]) -> None:
    """A review: frame sets pushed out of the bounded cache were still made (the page had moved on), and the one
    it did ask for waited behind them."""
    make, ahead = held
    first = ahead.future(0)
    assert make.inside.wait(30)  # the thread is inside make(0): what follows is only queued
    dropped = [ahead.future(n) for n in (1, 2)]
    wanted = [ahead.future(n) for n in (5, 6, 7)]  # 0, 1 and 2 fall out of the cache of 3
    assert ahead.kept() == [5, 6, 7]
    assert all(f.cancelled() for f in dropped) and not first.cancelled()  # 0 is being made: not cancellable
    make.gate.set()
    assert [f.result(30) for f in wanted] == [b"5", b"6", b"7"] and first.result(30) == b"0"
    assert make.made == [0, 5, 6, 7]


def test_a_frame_set_someone_waits_for_is_made_even_when_pushed_out(held: tuple[Held, MakeAhead]) -> None:
    """Two pages on one viewer: one waits for frame set 1 while the other's requests push it out of the cache;
    it is made and handed over, not cancelled under the waiter."""
    make, ahead = held
    ahead.future(0)
    assert make.inside.wait(30)
    got: list[bytes] = []
    waiter = threading.Thread(target=lambda: got.append(ahead.get(1, ahead=(2,))))
    waiter.start()
    until(lambda: ahead.kept() == [0, 1, 2])  # the waiter has asked: it is counted before it is queued
    for n in (5, 6, 7):
        ahead.future(n)
    assert ahead.kept() == [5, 6, 7]
    make.gate.set()
    waiter.join(30)
    assert got == [b"1"]
    until(lambda: make.made[-1:] == [7])
    assert make.made == [0, 1, 5, 6, 7]  # 2, queued ahead and dropped with nobody waiting, was skipped


def test_a_result_asked_for_again_is_not_made_again(held: tuple[Held, MakeAhead]) -> None:
    make, ahead = held
    make.gate.set()
    assert ahead.get(3, ahead=(4,)) == b"3" and ahead.get(4) == b"4" and ahead.get(3) == b"3"
    assert make.made == [3, 4]
