"""A bound on what a Dask peer may make this process allocate.

Dask's TCP comm reads a message as an 8-byte length, a header of that many bytes, then the buffers the
header lists, each allocated whole before it is read. ``rigctl process --scheduler`` probes the first message
(the handshake, :func:`rigctl.cli.process.probe_scheduler`); :func:`bounded_messages` bounds every later one:
a length over the bound is refused before any allocation, the connection is dropped and the refusal is kept
for the caller to say in one line (``--scheduler tcp://...: sent a message of N bytes ...``). A farm's own
messages are task specifications and per-chunk reports (kilobytes): the frames travel through shared storage.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

log = logging.getLogger(__name__)

MAX_MESSAGE_BYTES = 256 << 20  # one message; a farm's largest are reports of a chunk, kilobytes


class MessageTooLarge(OSError):
    """A peer's message claims more bytes than the bound: refused before anything is allocated."""


class Refusals:
    """What was refused while the bound was in place (the first is what the command says)."""

    def __init__(self) -> None:
        self.sizes: list[int] = []

    def first(self, what: str, bound: int) -> str | None:
        if not self.sizes:
            return None
        return (
            f"{what}: sent a message of {self.sizes[0]:,} bytes, more than the {bound >> 20} MiB a farm's messages "
            "need: not a Dask scheduler rigctl can work with; refused"
        )


@contextmanager
def bounded_messages(max_bytes: int = MAX_MESSAGE_BYTES) -> Iterator[Refusals]:
    """Within the ``with``, every message this process reads over Dask's TCP comm holds at most ``max_bytes``
    (header and buffers together); the sizes refused are in the yielded :class:`Refusals`."""
    from distributed.comm import tcp

    refusals = Refusals()
    read_bytes_rw, unpack_frames = tcp.read_bytes_rw, tcp.unpack_frames

    def refuse(n: int) -> None:
        refusals.sizes.append(n)
        log.debug("refused a Dask message of %d bytes (bound %d)", n, max_bytes)
        raise MessageTooLarge(f"a Dask message of {n:,} bytes is over the bound of {max_bytes:,}")

    async def bounded_read(stream: Any, n: int) -> Any:
        if not 0 <= n <= max_bytes:
            refuse(n)
        return await read_bytes_rw(stream, n)

    def bounded_unpack(frames: Any, *args: Any, **kwargs: Any) -> Any:
        out = unpack_frames(frames, *args, **kwargs)
        if isinstance(out, tuple) and len(out) == 2:  # (frames, sizes of the buffers still to read)
            total = sum(int(n) for n in out[1])
            if total > max_bytes:
                refuse(total)
        return out

    tcp.read_bytes_rw, tcp.unpack_frames = bounded_read, bounded_unpack  # type: ignore[assignment]
    try:
        yield refusals
    finally:
        tcp.read_bytes_rw, tcp.unpack_frames = read_bytes_rw, unpack_frames
