"""Run one branch of the pipeline in a forked worker process while the main process runs another.

The build has two independent branches after the design is derived: the CAD branch (the CAD kernel, the
solids, the meshes, the board) and the physics branch (predictions, plots, calibration, firmware and the
bench papers). On a machine with two or more cores they run side by side: the worker is a ``fork`` of the
main process, so it inherits the derived design without pickling it and imports no CAD kernel of its own.
Its result comes back pickled through a pipe. Where ``fork`` is not the platform's way (Windows, macOS) or
``MAGFAB_JOBS=1`` is set, the branch runs in-process, first, with the same result.

Each branch forks smaller ones of its own where they are independent (the board beside the CAD kernel's import;
the speed-accuracy chart, the prediction's reference mesh and the mould's report views beside the rest): the
branches are uneven, and more, shorter chains let the operating system keep both cores busy to the end. A worker
may fork once more; its worker may not.

Results are the same bytes either way (tests compare the two): each branch is deterministic on its own.

While the branches run side by side each uses one BLAS thread (:func:`blas_threads`): OpenBLAS's worker threads
spin while they wait, and two processes each spinning a second thread on two cores cost more than they gave (the
calibration's least squares took twelve times as long under load). The numbers do not change with the thread count.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
import traceback
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from typing import Any

from .errors import BuildError

__all__ = ["Branch", "side_branch", "parallel_available", "deferred_interrupt", "blas_threads"]

_JOB: tuple[Callable[..., Any], tuple[Any, ...], Any] | None = None  # what the forked child runs, and the parent's
# end of the pipe (inherited, not pickled)
_DEPTH = 0  # how many forks deep this process is: 0 in the main process


def parallel_available() -> bool:
    """True where a second branch can run in a forked worker: Linux, two or more cores, MAGFAB_JOBS not 1, and not
    a worker's worker. A build's workers fork once more (the physics branch's prediction solves its reference mesh
    beside the chosen one): the branches are uneven, and the operating system gives a core that one of them left idle
    to whichever process is runnable, so more, shorter chains finish sooner on the same cores."""
    if os.environ.get("MAGFAB_JOBS", "").strip() == "1" or _DEPTH >= 2:
        return False
    return sys.platform.startswith("linux") and (os.cpu_count() or 1) >= 2


class Branch:
    """The side branch's result: :meth:`result` returns it, or raises what the branch raised."""

    def __init__(self, fn: Callable[..., Any], args: tuple[Any, ...], forked: bool) -> None:
        self._done = False
        self._value: tuple[str, Any] | None = None  # (kind, payload) once done
        self._process: multiprocessing.context.ForkProcess | None = None
        self._conn: multiprocessing.connection.Connection | None = None
        self.forked = forked
        if forked:
            global _JOB
            ctx = multiprocessing.get_context("fork")
            self._conn, child = ctx.Pipe(duplex=False)
            _JOB = (fn, args, self._conn)
            try:
                # not a daemon, so that a worker may fork one of its own; side_branch kills it on every way out
                self._process = ctx.Process(target=_child, args=(child,))
                self._process.start()
            finally:
                _JOB = None
            child.close()
        else:
            self._value = _outcome(fn, args)
            self._done = True

    def result(self) -> Any:
        if not self._done:
            assert self._conn is not None and self._process is not None  # not done yet: the branch was forked
            try:
                self._value = self._conn.recv()
            except EOFError:  # the worker died without a word (killed, out of memory)
                self._process.join(5)
                self._value = ("crash", f"the worker process ended without a result (exit code "
                                        f"{self._process.exitcode})")
            self._done = True
            self._process.join()
        assert self._value is not None
        kind, payload = self._value
        if kind == "ok":
            return payload
        if kind == "build-error":
            raise BuildError(payload)
        if kind == "interrupted":
            raise KeyboardInterrupt
        raise RuntimeError(f"in the build's worker process: {payload}")

    def cancel(self) -> None:
        if self._process is not None and self._process.is_alive():
            self._process.kill()
            self._process.join()


def _outcome(fn: Callable[..., Any], args: tuple[Any, ...]) -> tuple[str, Any]:
    """The branch's result as a tagged, picklable value; BuildError's findings travel as themselves."""
    try:
        return "ok", fn(*args)
    except BuildError as exc:
        return "build-error", exc.findings
    except KeyboardInterrupt:
        return "interrupted", None


def _child(conn) -> None:
    global _DEPTH
    _DEPTH += 1
    _die_with_parent()
    assert _JOB is not None  # the parent sets it just before it forks this child
    fn, args, reader = _JOB
    # The child's copy of the parent's end: closed, so a parent that died (a crash, a kill) makes the send below fail
    # at once instead of blocking on a full pipe nobody reads, which left the worker holding the terminal's pipes.
    reader.close()
    try:
        value = _outcome(fn, args)
    except BaseException:
        value = ("crash", traceback.format_exc(limit=-8))
    try:
        conn.send(value)
    finally:
        conn.close()
        os._exit(0)  # no atexit handlers, no buffers flushed twice: the parent owns those


def _die_with_parent() -> None:
    """Ask Linux to kill this worker when its parent dies: a worker's own worker would otherwise finish its work for
    nobody after a Ctrl-C or a kill of the build (the parent's cancel reaches only its direct child)."""
    with suppress(OSError, AttributeError):  # not Linux's libc: the worker lives on a little, as it did
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))  # 1: PR_SET_PDEATHSIG


@contextmanager
def side_branch(fn: Callable[..., Any], *args: Any, parallel: bool | None = None) -> Iterator[Branch]:
    """Start ``fn(*args)`` beside the block (forked when ``parallel``, default :func:`parallel_available`);
    the block calls ``.result()`` when it needs it. Leaving the block early kills the worker."""
    forked = parallel_available() if parallel is None else parallel
    with blas_threads(1 if forked else None):
        branch = Branch(fn, args, forked)
        try:
            yield branch
        finally:
            branch.cancel()


#: The OpenBLAS builds numpy and scipy each ship, by the name of their thread-count setter.
_BLAS_SETTERS = ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads", "openblas_set_num_threads")
_BLAS_GETTERS = tuple(name.replace("_set_", "_get_") for name in _BLAS_SETTERS)


def _loaded_blas() -> list[Any]:
    """The OpenBLAS libraries loaded in this process (ctypes handles; none where /proc does not exist)."""
    try:
        with open("/proc/self/maps") as maps:
            paths = sorted({line.split()[-1] for line in maps if "openblas" in line.rsplit("/", 1)[-1].lower()})
    except OSError:
        return []
    return [ctypes.CDLL(path) for path in paths]


def _call_first(lib: Any, names: tuple[str, ...], *args: int) -> int | None:
    for name in names:
        fn = getattr(lib, name, None)
        if fn is not None:
            return fn(*args)
    return None


def _set_blas_threads(n: int) -> list[tuple[Any, int | None]]:
    """Set every loaded OpenBLAS to ``n`` threads, and those loaded later (they read OPENBLAS_NUM_THREADS when they
    load); returns each library's previous count."""
    os.environ["OPENBLAS_NUM_THREADS"] = str(n)
    before = []
    for lib in _loaded_blas():
        before.append((lib, _call_first(lib, _BLAS_GETTERS)))
        _call_first(lib, _BLAS_SETTERS, n)
    return before


@contextmanager
def blas_threads(n: int | None) -> Iterator[None]:
    """Run the block with ``n`` BLAS threads (None: as it is), then restore the thread counts and the environment."""
    if n is None:
        yield
        return
    env = os.environ.get("OPENBLAS_NUM_THREADS")
    before = _set_blas_threads(n)
    try:
        yield
    finally:
        if env is None:
            os.environ.pop("OPENBLAS_NUM_THREADS", None)
        else:
            os.environ["OPENBLAS_NUM_THREADS"] = env
        for lib, count in before:
            if count is not None:
                _call_first(lib, _BLAS_SETTERS, count)


@contextmanager
def deferred_interrupt() -> Iterator[None]:
    """Hold Ctrl-C (SIGINT) back for the block and deliver it after: for imports of extension modules that are not
    safe to interrupt half-way (VTK, loaded by the CAD kernel, crashed the process with a segmentation fault when
    the CLI's KeyboardInterrupt landed inside its initialisation). Where signal masks do not exist, a no-op."""
    mask = getattr(signal, "pthread_sigmask", None)
    if mask is None:
        yield
        return
    mask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        mask(signal.SIG_UNBLOCK, {signal.SIGINT})

