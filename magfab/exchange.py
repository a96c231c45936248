"""Swapping two folders in one step: Linux's ``renameat2`` with ``RENAME_EXCHANGE``, through ctypes.

:mod:`magfab.output` swaps a finished build into place with it, so the path holds the previous build until it holds
the new one; where the platform, the C library or the file system cannot exchange, :func:`exchange` says so and the
caller renames twice (its docstring gives that window)."""

from __future__ import annotations

import ctypes
import errno
import functools
import os
import sys
from collections.abc import Callable
from pathlib import Path

__all__ = ["exchange"]

_NO_EXCHANGE = {errno.EINVAL, errno.ENOSYS, errno.ENOTSUP, errno.EOPNOTSUPP}  # the file system or kernel lacks it


@functools.cache
def _renameat2() -> Callable[..., int] | None:
    """libc's ``renameat2`` (glibc 2.28+, Linux 3.15+); None elsewhere."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        call = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):
        return None
    call.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    call.restype = ctypes.c_int
    return call


def exchange(a: Path, b: Path) -> bool:
    """Swap the folders at ``a`` and ``b`` in one step (``RENAME_EXCHANGE``); False where the platform, the C
    library or the file system cannot, so the caller renames twice. Any other failure is the OSError."""
    call = _renameat2()
    if call is None:
        return False
    at_fdcwd, rename_exchange = -100, 2  # <fcntl.h>, <linux/fs.h>
    if call(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    err = ctypes.get_errno()
    if err in _NO_EXCHANGE:
        return False
    raise OSError(err, os.strerror(err), str(a))


