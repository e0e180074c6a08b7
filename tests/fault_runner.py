"""Run ``rigctl`` in this process and kill it with a real signal at a chosen point (never imported by runtime
code): ``python fault_runner.py CALL N SIGNAL -- rigctl arguments``.

CALL is the system call whose N-th use (from 1) is the point: ``fsync`` (a file written whole under its
temporary name, not yet renamed), ``replace`` (just before a rename publishes it), ``write`` (inside a file
being written: a rectified take's essence), ``unlink`` (a file about to be removed: a folder being cleared).
SIGNAL is ``KILL`` or ``TERM``; the process signals itself, so the point is exact and the death is the kernel's,
as from outside.
"""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Callable
from typing import Any


def main() -> int:
    call, nth, sig = sys.argv[1], int(sys.argv[2]), getattr(signal, f"SIG{sys.argv[3]}")
    argv = sys.argv[sys.argv.index("--") + 1 :]
    name = {"fsync": "fsync", "replace": "replace", "write": "write", "unlink": "unlink"}[call]
    real: Callable[..., Any] = getattr(os, name)
    count = 0

    def patched(*args: Any, **kwargs: Any) -> Any:
        nonlocal count
        count += 1
        if count == nth:
            os.kill(os.getpid(), sig)
            signal.pause()  # SIGTERM is delivered on return to the interpreter loop; never go on
        return real(*args, **kwargs)

    setattr(os, name, patched)
    if name == "replace":
        os.rename = patched  # a folder published by rename (rectify) counts as well
    from rigctl.cli.main import main as rigctl_main

    return rigctl_main(argv)


if __name__ == "__main__":
    sys.exit(main())
