"""Making frame sets' bundles ahead of the page, on one thread, kept in a bounded LRU cache.

A frame set dropped from the cache is no longer wanted: if its bundle is still queued, it is cancelled and the
thread skips it (before, it was made anyway and thrown away, while the page waited behind it for the frame
set it did ask for). A frame set someone is waiting for is never cancelled, even when a busier client pushes
it out of the cache: it is made, handed over, and made again if asked for again.
"""

from __future__ import annotations

import queue
import threading
from collections import OrderedDict
from collections.abc import Callable, Sequence
from concurrent.futures import Future


class MakeAhead:
    """``make(number)`` run on one thread of its own for the numbers asked for, with at most ``cache`` results
    (made, being made or queued) kept."""

    def __init__(self, make: Callable[[int], bytes], cache: int, name: str = "rigctl-view-bundles") -> None:
        self.make = make
        self.cache = cache
        self._lock = threading.Lock()
        self._cache: OrderedDict[int, Future[bytes]] = OrderedDict()
        self._waiting: dict[int, int] = {}  # frame set -> how many get() calls wait for it
        self._jobs: queue.SimpleQueue[tuple[int, Future[bytes]]] = queue.SimpleQueue()
        self._closed = threading.Event()
        # a daemon: at exit (Ctrl-C) nothing waits for the bundle being made (a pool's thread is joined, and a
        # second Ctrl-C during that join ended in a traceback)
        self._thread = threading.Thread(target=self._work, name=name, daemon=True)
        self._thread.start()

    def get(self, number: int, ahead: Sequence[int] = ()) -> bytes:
        """``number``'s result, with ``ahead`` queued behind it (made while the caller uses this one)."""
        with self._lock:
            self._waiting[number] = self._waiting.get(number, 0) + 1
        try:
            wanted = self.future(number)
            for later in ahead:
                self.future(later)
            return wanted.result()
        finally:
            with self._lock:
                left = self._waiting.pop(number) - 1
                if left:
                    self._waiting[number] = left

    def future(self, number: int) -> Future[bytes]:
        """``number``'s result to come, queued if it is not kept; the least recently asked for that no longer
        fit are dropped, and cancelled when still queued and nobody waits for them."""
        with self._lock:
            if number in self._cache:
                self._cache.move_to_end(number)
                return self._cache[number]
            made: Future[bytes] = Future()
            if self._closed.is_set():
                made.cancel()  # never made: its waiter is not left waiting
            self._jobs.put((number, made))
            self._cache[number] = made
            while len(self._cache) > self.cache:
                dropped, old = self._cache.popitem(last=False)
                if dropped not in self._waiting:
                    old.cancel()  # a no-op once being made or made: only queued work is skipped
            return made

    def kept(self) -> list[int]:
        """The numbers kept, least recently asked for first."""
        with self._lock:
            return list(self._cache)

    def close(self, wait_s: float) -> None:
        """Drop what is queued and end the thread, waiting up to ``wait_s`` for the one being made: a process
        that exits while that thread is inside OpenCV or OpenEXR is aborted by the C++ runtime ("terminate
        called without an active exception"). A second Ctrl-C does not cut the wait short into a traceback."""
        self._closed.set()
        with self._lock:
            for made in self._cache.values():
                made.cancel()
        self._jobs.put((-1, Future()))  # wakes the thread
        if self._thread is threading.current_thread():
            return
        try:
            self._thread.join(wait_s)
        except KeyboardInterrupt:
            self._thread.join(wait_s)

    def _work(self) -> None:
        while not self._closed.is_set():
            number, made = self._jobs.get()
            if self._closed.is_set() or not made.set_running_or_notify_cancel():
                continue  # closed, or dropped from the cache while queued: nobody will use it
            try:
                made.set_result(self.make(number))
            except BaseException as exc:  # whoever waits for the bundle gets it (a pool's worker does the same)
                made.set_exception(exc)
