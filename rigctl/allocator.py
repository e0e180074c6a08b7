"""The C allocator's arenas for depth work (issue 24: a worker's memory).

glibc gives each thread that allocates while another holds the main arena an arena of its own, up to eight
per core. Depth's threads (numba's workers, OpenCV's, OpenEXR's, the write's soft key) all allocate
frame-sized and smaller arrays, and each arena keeps what its threads freed for their next allocation, not
for another thread's: the process's resident memory holds several copies of the same working set. With one
arena, ``rigctl bench depth --size 3840x2160`` (nine cameras) peaked at 3.98 GiB, with glibc's default 4.22
GiB, no slower (235 and 253 s, one run each); at 1920x1080 the two were within the runs' spread (1.17 to
1.25 GiB). The allocator changes no value. Recording keeps glibc's default (its capture threads must not wait
on one another's allocations): this is for processes that estimate depth, set before their threads start.
"""

from __future__ import annotations

import ctypes
import logging
from typing import Any

log = logging.getLogger(__name__)

M_ARENA_MAX = -8  # glibc's malloc.h
DEPTH_ARENAS = 1


def limit_arenas(arenas: int = DEPTH_ARENAS) -> bool:
    """At most ``arenas`` allocator arenas from now on (threads that have one keep it); False where the C
    library has no such setting (not glibc)."""
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    ok = bool(mallopt(M_ARENA_MAX, arenas))
    if not ok:
        log.debug("the C library refused M_ARENA_MAX=%d", arenas)
    return ok


# Dask's nanny starts each worker with MALLOC_TRIM_THRESHOLD_=65536 (its "pre-spawn-environ"). Any such setting
# also fixes glibc's mmap threshold at 128 KB, which otherwise rises to 32 MB as large arrays are freed: then
# every array over 128 KB is mapped on allocation and unmapped on free, its pages faulted in again each time.
# `rigctl process --workers 1` on the demo's three 960x540 frame sets: 71 s of system time (145 s elapsed)
# against 8 s (92 s) for `rigctl depth` on the same take, the same user time (one run each, issue 24).
DASK_WORKER_TRIM = "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_"


def dask_workers_allocate_as_depth() -> Any:
    """A ``dask.config.set`` context in which the workers a local cluster starts keep glibc's own allocator
    settings, as ``rigctl depth`` does (see :data:`DASK_WORKER_TRIM`)."""
    import dask

    return dask.config.set({DASK_WORKER_TRIM: None})
