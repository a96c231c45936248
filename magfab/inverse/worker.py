"""What each worker process of a local Dask cluster runs as it starts (Dask's worker preload, named by
:func:`magfab.inverse.study.client`): Ctrl-C back to the operating system's default.

A terminal's Ctrl-C reaches every process of the foreground group, the workers too. Python's own handler would raise
KeyboardInterrupt in a worker and print its traceback beside magfab's one line; with the default a worker ends
quietly, and magfab (whose handler ends the run) closes the cluster. The cluster starts its workers with SIGINT
blocked (:func:`magfab.inverse.study.client`), so one pressed before this runs waits here and ends the worker quietly.

And glibc's allocator thresholds (:func:`malloc_thresholds`). Dask's nanny starts every worker with
``MALLOC_TRIM_THRESHOLD_=65536`` (its ``distributed.nanny.pre-spawn-environ``), to hand freed memory back to the
system quickly. Setting it also switches off glibc's dynamic mmap threshold, so every array over 128 KiB the FE
allocates is a fresh mmap, page-faulted in and unmapped again: on 6 FE designs of the example targets on 2 workers
the workers spent 19.2 s of system time with Dask's setting against 1.5 s with these thresholds, and 78 s of user
time against 68 s (one cluster, the settings in turn; bench/design.py measures the ratio on each run). The process
has read the variable by the time this runs, so the thresholds are set again with ``mallopt``: mmap from 32 MiB and
trim past 64 MiB, glibc's own dynamic ceilings on 64-bit (an array over 32 MiB is still mapped afresh each time).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import signal

__all__ = ["default_interrupt", "dask_setup", "malloc_thresholds", "MMAP_THRESHOLD", "TRIM_THRESHOLD"]

#: glibc's mallopt parameters (malloc.h) and the values :func:`malloc_thresholds` sets, bytes (module doc).
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD, TRIM_THRESHOLD = 32 * 1024 * 1024, 64 * 1024 * 1024


def default_interrupt() -> None:
    """SIGINT's default action (end the process), unblocked."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def malloc_thresholds(mmap: int = MMAP_THRESHOLD, trim: int = TRIM_THRESHOLD) -> bool:
    """Set glibc's mmap and trim thresholds (module doc); False where the C library is not glibc (nothing set)."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(M_MMAP_THRESHOLD, mmap)) and bool(mallopt(M_TRIM_THRESHOLD, trim))


def dask_setup(worker: object = None) -> None:
    """Dask's preload hook (the module is imported in the worker's main thread, which runs this too)."""
    default_interrupt()


default_interrupt()
malloc_thresholds()
