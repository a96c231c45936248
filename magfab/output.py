"""The output folder: the only code that writes it.

A build's files are :class:`Artifact` values (path, bytes, what it is for) until :func:`write` puts them
into place: it writes a temporary folder beside the target and renames it into place only when every
file is there, so an error or an interrupt never leaves half an output and never clobbers the previous
good one; :func:`check_target` refuses, before any work, a folder that is not an earlier magfab build.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from .errors import OutputError

__all__ = ["Artifact", "check_target", "write", "OutputError"]


@dataclass(frozen=True)
class Artifact:
    path: str  # relative, POSIX separators
    data: bytes
    description: str


def _safe_relative(path: str) -> PurePosixPath:
    p = PurePosixPath(path)
    if p.is_absolute() or not p.parts or any(part in {"", ".", ".."} for part in p.parts):
        raise OutputError(f"artifact path {path!r} would leave the output directory")
    return p


def _is_previous_build(path: Path) -> bool:
    manifest = path / "manifest.json"
    try:
        return "magfab_version" in json.loads(manifest.read_text(encoding="utf-8"))
    except (OSError, ValueError, TypeError):
        return False


def check_target(out_dir: Path) -> Path:
    """``out_dir`` as an absolute path if a build may replace it (absent, empty, or an earlier magfab build);
    :class:`OutputError` otherwise. Checked before any work, and again just before the swap."""
    out_dir = Path(out_dir).absolute()
    if out_dir.exists() and not (out_dir.is_dir() and (_is_previous_build(out_dir) or not any(out_dir.iterdir()))):
        raise OutputError(f"--out {out_dir} exists and is not an earlier magfab build (no manifest.json); "
                          "refusing to replace it: choose another directory")
    return out_dir


def write(out_dir: Path, artifacts: list[Artifact]) -> Path:
    """Put the artifacts into ``out_dir`` atomically; an existing ``out_dir`` must be an earlier magfab build."""
    out_dir = check_target(out_dir)
    for a in artifacts:
        _safe_relative(a.path)
    parent = out_dir.parent
    parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.tmp-", dir=parent))
    old: Path | None = None
    try:
        for a in artifacts:
            target = tmp.joinpath(*_safe_relative(a.path).parts)
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(a.data)
        os.chmod(tmp, 0o755)
        if out_dir.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.old-", dir=parent))
            os.rename(out_dir, old / "previous")
        os.rename(tmp, out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        if old is not None and (old / "previous").exists() and not out_dir.exists():
            os.rename(old / "previous", out_dir)
        if old is not None and not (old / "previous").exists():  # restored: the empty holder goes too
            shutil.rmtree(old, ignore_errors=True)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
    return out_dir
