"""An interrupted ``rigctl process`` ends with our one line, not with what Dask says while its local cluster is
closed under running tasks: each worker's ``Async instruction ... ended with CancelledError`` (Dask: "this
should exclusively happen in Worker.close()"), the nanny's ``Worker process still alive after 4.0 seconds,
killing`` (a worker busy in a chunk's compiled code cannot stop sooner), and, when Ctrl-C reached the workers
too (a terminal signals the whole process group), each worker's own ``KeyboardInterrupt`` traceback.

The workers of the local clusters :func:`rigctl.farm.run.dask_client` starts preload this module
(:func:`dask_setup`): they ignore SIGINT (this process stops them when it is interrupted) and drop the
cancellation notice; :func:`quiet_nannies` drops the nanny's. A user's ``--scheduler`` and its workers are
left as they are, and nothing else Dask logs is touched."""

from __future__ import annotations

import logging
import signal
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

SHUTDOWN_NOTICES = ("ended with CancelledError", "Worker process still alive after")


class ShutdownNotices(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        text = record.getMessage()
        return not any(n in text for n in SHUTDOWN_NOTICES)


def dask_setup(worker: Any) -> None:
    """Dask's preload hook, run in each worker process as it starts (on its main thread)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    logging.getLogger("distributed.worker.state_machine").addFilter(ShutdownNotices())


@contextmanager
def quiet_nannies() -> Iterator[None]:
    """Within (a local cluster's whole life, its close included): this process's nannies drop their notice."""
    nanny, notices = logging.getLogger("distributed.nanny"), ShutdownNotices()
    nanny.addFilter(notices)
    try:
        yield
    finally:
        nanny.removeFilter(notices)
