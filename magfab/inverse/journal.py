"""The study's journal file: Optuna's journal backend, made durable once per result rather than at every write.

Optuna's ``JournalFileBackend`` takes its lock, appends and calls ``fsync`` at every write; a trial of the search
takes about six writes (its creation, its result, its constraints, its state and values), so a 250-trial study made
1,440 fsyncs, 0.9 s of a 7 s study's main loop (the example targets, 2 workers, cProfile). :func:`journal`'s
backend writes under the same lock, with the same lines, and leaves the ``fsync`` to its ``sync()``, which
:func:`~magfab.inverse.study.tell` calls once a trial's result is written: every told result is on the disk before
the next trial is asked, as before.

What this gives up: a write not yet synced (the trial being asked, its result half written) survives the process
being killed (it is in the operating system's cache) but not the machine losing power. A journal cut short there
ends in a partial line, which Optuna's reader skips, and the trial it belonged to is asked again when the study
resumes (:func:`~magfab.inverse.study._recover`).
"""

from __future__ import annotations

import json
import os
from functools import lru_cache
from typing import Any

__all__ = ["journal"]


def journal(file_path: str) -> Any:
    """Optuna's journal file backend at ``file_path`` (the same file format and lock), each write's ``fsync`` left to
    its ``sync()`` (module doc)."""
    return _journal_class()(file_path)


@lru_cache(maxsize=1)
def _journal_class() -> type:
    """The backend's class, made on first use: it subclasses Optuna's, and importing Optuna takes a noticeable time
    that importing this module should not."""
    from optuna.storages.journal import JournalFileBackend, JournalFileSymlinkLock  # lazy: Optuna is slow to import

    class Journal(JournalFileBackend):
        def __init__(self, file_path: str) -> None:
            self._held = JournalFileSymlinkLock(file_path)
            super().__init__(file_path, lock_obj=self._held)
            self._path = file_path
            self._unsynced = False

        def append_logs(self, logs: list[dict[str, Any]]) -> None:
            """Append ``logs`` as Optuna's backend does (one JSON line each, under the lock), without the ``fsync``."""
            lines = "".join(json.dumps(log, separators=(",", ":")) + "\n" for log in logs).encode("utf-8")
            self._held.acquire()
            try:
                with open(self._path, "ab") as f:
                    f.write(lines)
            finally:
                self._held.release()
            self._unsynced = True

        def sync(self) -> None:
            """Put every write so far on the disk (``fsync``); nothing to do when none is pending."""
            if self._unsynced:
                fd = os.open(self._path, os.O_RDONLY)
                try:
                    os.fsync(fd)
                finally:
                    os.close(fd)
                self._unsynced = False

    return Journal
