"""A listener that speaks Dask's handshake, then claims a huge message (never imported by runtime code):
``python hostile_scheduler.py length|buffers``; prints its address, then serves for a minute.

``length``: the next message's 8-byte length says 4 EiB. ``buffers``: a small, well-formed header that lists
two buffers of a TiB each (the bytes a reader would allocate before reading them)."""

from __future__ import annotations

import asyncio
import struct
import sys
from typing import Any

from distributed.comm import listen


async def main(mode: str) -> None:
    if mode == "length":
        payload = struct.pack("<Q", 1 << 62)
    else:
        header = struct.pack("<QQQ", 2, 1 << 40, 1 << 40)
        payload = struct.pack("<Q", len(header)) + header

    async def handler(comm: Any) -> None:
        await comm.stream.write(payload + b"\0" * 64)
        await asyncio.sleep(60)

    listener = listen("tcp://127.0.0.1:0", handler)
    await listener.start()
    print(listener.listen_address, flush=True)
    await asyncio.sleep(60)


if __name__ == "__main__":
    asyncio.run(main(sys.argv[1]))
