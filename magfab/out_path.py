"""The output folder's path, held to what the file system can hold before any work (``--out`` of build, design and
sweep): a name or a path too long is one line naming it and the most allowed, never ENAMETOOLONG halfway."""

from __future__ import annotations

import os
from pathlib import Path

from .errors import InputError, shown

__all__ = ["OUT_BESIDE_BYTES", "OUT_INSIDE_BYTES", "check_out"]

#: What magfab adds to the output folder's name for the files beside it (``.NAME.tmp-`` and 16 hex digits, the longest
#: of output.py's temporaries, journal and lock).
OUT_BESIDE_BYTES = 22
#: Room kept within the file system's longest path for what magfab writes inside the folder (its deepest file with a
#: temporary name: under 120 bytes).
OUT_INSIDE_BYTES = 256


def check_out(out_dir: Path | None) -> None:
    """Refuse an ``--out`` the file system cannot hold with what magfab writes in it and beside it, before any work:
    one line naming the name or the path that is too long and the most allowed (no ENAMETOOLONG halfway)."""
    if out_dir is None:
        return
    full = os.path.abspath(out_dir)
    here = full
    while not os.path.isdir(here) and os.path.dirname(here) != here:
        here = os.path.dirname(here)
    name_max, path_max = (_pathconf(here, key, default) for key, default in (("PC_NAME_MAX", 255),
                                                                             ("PC_PATH_MAX", 4096)))
    parts = Path(full).parts
    for i, part in enumerate(parts[1:], 1):
        most = name_max - (OUT_BESIDE_BYTES if i == len(parts) - 1 else 0)
        if len(os.fsencode(part)) > most:
            why = f", less {OUT_BESIDE_BYTES} for magfab's files beside the folder" if most < name_max else ""
            raise InputError(f"--out {shown(str(out_dir))}: a name of {len(os.fsencode(part))} bytes in it; at most "
                             f"{most} (the file system's {name_max}{why})")
    if len(os.fsencode(full)) > path_max - OUT_INSIDE_BYTES:
        raise InputError(f"--out {shown(str(out_dir))}: a path of {len(os.fsencode(full))} bytes; at most "
                         f"{path_max - OUT_INSIDE_BYTES} (the file system's {path_max}, less {OUT_INSIDE_BYTES} for "
                         "the files in it)")


def _pathconf(path: str, key: str, default: int) -> int:
    try:
        return int(os.pathconf(path, key))
    except (OSError, ValueError):
        return default
