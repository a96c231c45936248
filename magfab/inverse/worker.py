"""What each worker process of a local Dask cluster runs as it starts (Dask's worker preload, named by
:func:`magfab.inverse.study.client`): Ctrl-C back to the operating system's default.

A terminal's Ctrl-C reaches every process of the foreground group, the workers too. Python's own handler would raise
KeyboardInterrupt in a worker and print its traceback beside magfab's one line; with the default a worker ends
quietly, and magfab (whose handler ends the run) closes the cluster. The cluster starts its workers with SIGINT
blocked (:func:`magfab.inverse.study.client`), so one pressed before this runs waits here and ends the worker quietly.
"""

from __future__ import annotations

import signal

__all__ = ["default_interrupt", "dask_setup"]


def default_interrupt() -> None:
    """SIGINT's default action (end the process), unblocked."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def dask_setup(worker: object = None) -> None:
    """Dask's preload hook (the module is imported in the worker's main thread, which runs this too)."""
    default_interrupt()


default_interrupt()
