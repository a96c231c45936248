"""The output folder: the only code that writes it.

A build's files are :class:`Artifact` values (path, bytes, what it is for) until :func:`write` puts them
into place. The rules, in the order a user meets them:

* **Which folders a build may replace.** :func:`check_target` refuses, before any work, a folder that is
  not absent, empty or an earlier magfab build (one with a ``manifest.json``), and one magfab cannot write
  (read-only folder or mount): :class:`OutputError` naming the path and the OS error in words.
* **The build folder is magfab's only where its manifest says so.** A rebuild replaces exactly the files
  the previous ``manifest.json`` lists under ``artifacts`` (and the manifest itself); every other file or
  folder in it (a scan recorded into the folder, notes) is kept, byte for byte (it is hard-linked into the
  new build, copied where the file system cannot link). A kept file at a path the new build writes stops
  the build before anything changes: move it away. (A manifest without an ``artifacts`` list, which no
  magfab ever wrote, marks every file as magfab's.)
* **The swap is recoverable.** The new build is written into ``.NAME.tmp-*`` beside the target; a journal
  ``.NAME.swap`` naming where the previous build goes is written; then the two folders are exchanged in one
  step (Linux ``renameat2`` with ``RENAME_EXCHANGE``), so the path holds the previous build until it holds the
  new one, never neither; the journal is removed only once the new one is there. Where the platform, its C
  library (glibc before 2.28) or the file system refuses the exchange (``EINVAL``, ``ENOSYS``, ``ENOTSUP``), the
  previous build is renamed to ``.NAME.old-*`` and the new one into place: between those two renames (a few
  microseconds) no folder is at the path, and a run killed there leaves the journal, from which the next
  :func:`write` or :func:`check_target` puts the previous build back (:func:`_recover`). A run killed between
  any other two steps leaves a complete build at the path; an error or interrupt runs the same recovery at once.
* **Only what magfab made is ever removed.** Every temporary is written into the lock file's log (``+NAME``)
  before it is made, and ``-NAME`` once it is gone; the next run removes what a killed run left listed there or
  in its journal, and nothing else: a folder beside the build whose name only looks like a temporary
  (``.NAME.old-20241128``, a copy the user made) is never touched, nor is one left by a magfab before this rule.
* **One writer at a time.** Writers of one folder take an ``flock`` on ``.NAME.lock`` beside it for the
  swap (a few seconds at most); a second writer waits for it, and gives up with :class:`OutputError` naming
  the other build's process after ``lock_timeout_s``.

* **Updating the folder you stand in.** A shell whose working folder is the build (``magfab calibrate`` run
  inside it) would be left in the renamed previous build by the swap, so :func:`write` with ``in_place``
  replaces the changed files one by one instead: every new file is written beside the folder first and
  every file it replaces or removes is hard-linked into ``.NAME.old-*``; then a journal ``.NAME.inplace``
  lists them, the files are renamed into place, and the journal goes. A run killed with the journal present
  is rolled back by the next run (or at once on an error or interrupt): the previous build, byte for byte.

This guards against kills and errors, not power loss (nothing is fsynced).
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import re
import secrets
import shutil
import time
from collections.abc import Callable
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from .errors import OutputError
from .exchange import exchange
from .formats.bounded import InputFileError, loads_json, read_bytes

__all__ = ["Artifact", "check_target", "write", "is_build", "OutputError"]

LOCK_WAIT_S = 120.0  # how long a second writer of one folder waits for the first before giving up

_step_hook: Callable[[str], None] | None = None  # tests set it to kill the process between two steps


def _step(what: str) -> None:
    if _step_hook is not None:
        _step_hook(what)


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


def _absolute(out_dir: Path) -> Path:
    out = Path(os.path.abspath(out_dir))
    return out.resolve() if out.is_symlink() else out


# ---- the previous build: what is magfab's, what is the user's ----

def _listed(out: Path) -> set[str] | None:
    """The paths the previous build's manifest says magfab wrote (with the manifest); None if it lists none."""
    try:
        manifest = loads_json(read_bytes(out / "manifest.json", "JSON"), "manifest.json", out)
    except (OSError, ValueError, InputFileError):
        return {"manifest.json"}  # an empty folder (or a manifest gone bad meanwhile): all else is the user's
    items = manifest.get("artifacts") if isinstance(manifest, dict) else None
    if not isinstance(items, list):
        return None
    paths = {item if isinstance(item, str) else item.get("path") if isinstance(item, dict) else None for item in items}
    return {str(PurePosixPath(p)) for p in paths if isinstance(p, str) and p} | {"manifest.json"}


def _user_files(out: Path) -> list[str]:
    """Relative paths in ``out`` that its manifest does not list: files, links and empty folders (``name/``)."""
    listed = _listed(out) if out.is_dir() else None
    if listed is None:
        return []
    magfab_dirs = {str(q) for p in listed for q in PurePosixPath(p).parents}
    found: list[str] = []

    def walk(folder: str, prefix: str) -> None:
        with os.scandir(folder) as entries:
            for entry in sorted(entries, key=lambda e: e.name):
                rel = prefix + entry.name
                if entry.is_dir(follow_symlinks=False):
                    before = len(found)
                    walk(entry.path, rel + "/")
                    if len(found) == before and rel not in magfab_dirs:
                        found.append(rel + "/")
                elif rel not in listed:
                    found.append(rel)

    walk(str(out), "")
    return found


def _check_collisions(out: Path, users: list[str], paths: list[str]) -> None:
    files = set(paths)
    folders = {str(q) for p in paths for q in PurePosixPath(p).parents}
    for rel in users:
        p = rel.rstrip("/")
        above = {str(q) for q in PurePosixPath(p).parents}
        if p in files or (not rel.endswith("/") and p in folders) or above & files:
            raise OutputError(f"{out / p} is not magfab's (the previous manifest.json does not list it) but this "
                              "build writes that path; move it away and build again")


def _carry(src: Path, dst: Path, users: list[str]) -> None:
    """Put the user's files of ``src`` into ``dst`` (hard links: same bytes, same inode), skipping any there."""
    for rel in users:
        s, d = src / rel, dst / rel
        if os.path.lexists(d):
            continue
        d.parent.mkdir(parents=True, exist_ok=True)
        try:
            if rel.endswith("/"):
                os.mkdir(d)
            else:
                _link(s, d)
        except FileNotFoundError:  # the user removed it meanwhile
            continue
        _step(f"kept {rel}")


def _link(src: Path, dst: Path) -> None:
    try:
        os.link(src, dst, follow_symlinks=False)
    except OSError as exc:
        if exc.errno not in {errno.EPERM, errno.EMLINK, errno.EXDEV, errno.ENOTSUP, errno.EOPNOTSUPP}:
            raise
        if os.path.islink(src):
            os.symlink(os.readlink(src), dst)
        else:
            shutil.copy2(src, dst)


# ---- the folders beside the target: temporaries, journal, lock ----

def _sibling(out: Path, kind: str) -> Path:
    return out.parent / f".{out.name}.{kind}"


def _own_name(out: Path, name: object) -> bool:
    """Whether ``name`` is one this magfab gives a temporary of ``out`` (``.NAME.tmp-`` or ``.NAME.old-`` and 16
    hex digits): a record naming anything else (another path, a folder of the user's) is ignored."""
    pattern = rf"\.{re.escape(out.name)}\.(tmp|old)-[0-9a-f]{{16}}"
    return isinstance(name, str) and re.fullmatch(pattern, name) is not None


class _Lock:
    """The flock on ``.NAME.lock`` and the log in that file: the holder's process id, then ``+NAME`` written
    before each temporary beside the target is made and ``-NAME`` once it is gone, a line per write, so a kill
    leaves whole lines. The next holder inherits what a killed one left listed; only those are ever removed."""

    def __init__(self, out: Path, fd: int, log: bytes) -> None:
        self.out, self.fd = out, fd
        self.owned: list[str] = []
        for line in log.decode("utf-8", "replace").splitlines():
            name = line[1:]
            if line[:1] == "+" and _own_name(out, name) and name not in self.owned:
                self.owned.append(name)
            elif line[:1] == "-" and name in self.owned:
                self.owned.remove(name)
        self._log(str(os.getpid()))

    def _log(self, line: str) -> None:
        os.write(self.fd, f"{line}\n".encode())

    def adopt(self, name: object) -> None:
        """Record a temporary a journal names (a killed run's, recorded there too)."""
        if _own_name(self.out, name) and name not in self.owned:
            self._log(f"+{name}")
            self.owned.append(str(name))

    def make(self, kind: str) -> Path:
        """A new temporary's path, recorded (not yet made: the caller makes it, failing if it exists)."""
        path = self.out.parent / f".{self.out.name}.{kind}-{secrets.token_hex(8)}"
        while os.path.lexists(path):  # pragma: no cover - 2**-64
            path = self.out.parent / f".{self.out.name}.{kind}-{secrets.token_hex(8)}"
        self.adopt(path.name)
        return path

    def forget(self, name: str) -> None:
        self._log(f"-{name}")
        self.owned.remove(name)

    def remove_owned(self) -> None:
        """Remove every temporary on record (idempotent; one that cannot be removed stays on record)."""
        for name in list(self.owned):
            _remove(self.out.parent / name)
            if not os.path.lexists(self.out.parent / name):
                _step(f"removed {name}")
                self.forget(name)


def _made(lock: _Lock, kind: str) -> Path:
    """A new empty temporary folder, recorded before it is made; one that exists already is not ours."""
    path = lock.make(kind)
    try:
        os.mkdir(path)
    except FileExistsError:  # pragma: no cover - made by someone else between the check and the mkdir
        lock.forget(path.name)
        raise
    return path


def _remove(path: Path) -> None:
    if path.is_symlink() or not path.is_dir():
        with suppress(FileNotFoundError):
            os.unlink(path)
    else:
        shutil.rmtree(path, ignore_errors=True)


def _inode(path: Path) -> list[int] | None:
    try:
        st = os.lstat(path)
    except OSError:
        return None
    return [st.st_dev, st.st_ino]


def _journal(out: Path) -> tuple[Path, list[int] | None] | None:
    """Where the journal says the previous build goes and the new build's inode (None in a journal of a magfab
    before the exchange); None: no journal, one cut short, or one naming no temporary of ours."""
    try:
        plan = json.loads(_sibling(out, "swap").read_text(encoding="utf-8"))
        name, inode = plan["old"], plan.get("new_inode")
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None
    if not _own_name(out, name):
        return None
    return out.parent / name, inode if isinstance(inode, list) else None


def _acquire(out: Path, timeout_s: float) -> _Lock | None:
    """The flock on ``.NAME.lock`` with its log, or None if another process still holds it after the wait."""
    path = _sibling(out, "lock")
    deadline = time.monotonic() + timeout_s
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            if time.monotonic() >= deadline:
                return None
            time.sleep(0.02)
            continue
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(path))
        except FileNotFoundError:
            same = False
        if same:  # else its holder removed it as we opened it: lock the new one
            break
        os.close(fd)
    try:
        chunks = []
        while chunk := os.read(fd, 1 << 16):
            chunks.append(chunk)
        return _Lock(out, fd, b"".join(chunks))  # appends after what a killed holder left
    except BaseException:
        os.close(fd)
        raise


def _release(out: Path, lock: _Lock) -> None:
    if not lock.owned:  # else the log stays, for the next run to remove what it lists
        with suppress(FileNotFoundError):
            os.unlink(_sibling(out, "lock"))  # while still holding it, so no waiter locks a removed file
    os.close(lock.fd)


def _busy(out: Path) -> OutputError:
    try:
        lines = _sibling(out, "lock").read_text(errors="replace").split()
    except OSError:
        lines = []
    pid = next((line for line in reversed(lines) if line.isdigit()), "")
    who = f"another magfab build (process {pid})" if pid else "another magfab build"
    return OutputError(f"{who} is writing {out}; try again when it has finished")


# ---- recovery and the swap ----

def _recover(out: Path, lock: _Lock) -> None:
    """Finish or undo what a killed or failed run left beside ``out``: with the lock held, and idempotent.

    Killed between the two renames of the fallback: the previous build goes back. After the exchange (or the
    renames): the user's files that appeared in the previous build meanwhile are carried over. Then the journal
    and every temporary on record go."""
    _roll_back_in_place(out, lock)
    journal = _journal(out)
    if journal is not None:
        old, new_inode = journal
        lock.adopt(old.name)
        new_in_place = _inode(out) == new_inode if new_inode is not None else os.path.lexists(out)
        if old.is_dir() and (new_inode is None or _inode(old) != new_inode):  # else the new build, not swapped
            if not os.path.lexists(out):
                os.rename(old, out)
                _step("restored")
            elif new_in_place:
                _carry(old, out, _user_files(old))
    with suppress(FileNotFoundError):
        os.unlink(_sibling(out, "swap"))
        _step("journal removed")
    lock.remove_owned()


def _roll_back_in_place(out: Path, lock: _Lock) -> None:
    """An in-place update cut short (its journal ``.NAME.inplace`` is there): every replaced or removed file
    back from the hard links in ``.NAME.old-*`` (which stay until the journal goes), every added file and the
    folders made for them removed. Idempotent: a rollback cut short is finished by the next."""
    journal = _sibling(out, "inplace")
    try:
        plan = json.loads(journal.read_text(encoding="utf-8"))
        name, kept, added = plan["old"], list(plan["kept"]), list(plan["added"])
        made = list(plan["made"])
    except FileNotFoundError:
        return
    except (OSError, ValueError, KeyError, TypeError):  # cut short while written: nothing was renamed yet
        name, kept, added, made = None, [], [], []
    lock.adopt(name)
    old = out.parent / name if _own_name(out, name) else None
    for rel in kept:  # link back, the hard link in old/ kept: a second rollback finds it again
        if old is None or not os.path.lexists(old / rel):
            continue
        target = out / rel
        if os.path.lexists(target) and not os.path.samestat(os.lstat(target), os.lstat(old / rel)):
            os.unlink(target)
        if not os.path.lexists(target):
            target.parent.mkdir(parents=True, exist_ok=True)
            _link(old / rel, target)
        _step(f"put back {rel}")
    for rel in added:
        with suppress(FileNotFoundError):
            os.unlink(out / rel)
    for folder in sorted(made, key=len, reverse=True):
        with suppress(OSError):  # still holds something (a user's file): it stays
            os.rmdir(out / folder)
    os.unlink(journal)
    _step("in-place update rolled back")


def _swap(out: Path, tmp: Path, lock: _Lock) -> None:
    """The new build ``tmp`` to ``out``; the previous build (if any) ends at the journal's ``old``."""
    if not os.path.lexists(out):
        os.rename(tmp, out)
        _step("new in place")
        return
    journal, new_inode = _sibling(out, "swap"), _inode(tmp)
    journal.write_text(json.dumps({"old": tmp.name, "new": tmp.name, "new_inode": new_inode}), encoding="utf-8")
    _step("journal written")
    if exchange(out, tmp):  # the previous build now at tmp's name
        _step("new in place")
        return
    old = lock.make("old")
    journal.write_text(json.dumps({"old": old.name, "new": tmp.name, "new_inode": new_inode}), encoding="utf-8")
    _step("journal rewritten for two renames")
    os.rename(out, old)
    _step("previous moved aside")
    os.rename(tmp, out)
    _step("new in place")


def _update_in_place(out: Path, tmp: Path, paths: list[str], lock: _Lock) -> None:
    """Rename the files of ``tmp`` that differ from ``out``'s into it, remove the previous build's files the
    new one does not have; journalled so that a kill can be rolled back (see the module's rules)."""
    previous = (_listed(out) or set()) - {"manifest.json"}
    changed = [p for p in paths if not _same_file(tmp / p, out / p)]
    removed = sorted(p for p in previous - set(paths) if os.path.isfile(out / p))
    added = [p for p in changed if not os.path.lexists(out / p)]
    made = sorted({str(q) for p in added for q in PurePosixPath(p).parents
                   if str(q) != "." and not os.path.lexists(out / str(q))})
    kept = [p for p in changed + removed if p not in set(added)]
    old = _made(lock, "old")
    for rel in kept:
        (old / rel).parent.mkdir(parents=True, exist_ok=True)
        _link(out / rel, old / rel)
    journal = _sibling(out, "inplace")
    draft = lock.make("tmp")
    with open(draft, "x", encoding="utf-8") as f:  # "x": never over a file of the same name
        f.write(json.dumps({"old": old.name, "kept": kept, "added": added, "made": made}))
    os.replace(draft, journal)
    _step("journal written")
    for rel in changed:
        (out / rel).parent.mkdir(parents=True, exist_ok=True)
        os.replace(tmp / rel, out / rel)
        _step(f"replaced {rel}")
    for rel in removed:
        os.unlink(out / rel)
        _step(f"removed {rel}")
        folder = (out / rel).parent
        while folder != out and not any(folder.iterdir()):  # the folders it leaves empty (a rollback remakes them)
            folder.rmdir()
            folder = folder.parent
    os.unlink(journal)
    _step("in-place update committed")


def _same_file(a: Path, b: Path) -> bool:
    try:
        return b.is_file() and not b.is_symlink() and a.stat().st_size == b.stat().st_size \
            and a.read_bytes() == b.read_bytes()
    except OSError:
        return False


def _write_tree(tmp: Path, artifacts: list[Artifact]) -> None:
    for a in artifacts:
        target = tmp.joinpath(*_safe_relative(a.path).parts)
        target.parent.mkdir(parents=True, exist_ok=True)
        try:
            with open(target, "wb") as f:
                f.write(a.data)
        except OSError as exc:
            exc.filename = exc.filename or str(target)
            raise
        _step(f"wrote {a.path}")


# ---- errors ----

def _os_error(exc: OSError, out: Path) -> OutputError:
    """One line: the path the user knows (in the target, not in our temporary) and the OS error in words."""
    shown = Path(exc.filename) if exc.filename else out
    try:
        first, *rest = shown.relative_to(out.parent).parts
    except ValueError:
        first, rest = "", []
    if first.startswith(f".{out.name}.tmp-") and rest:
        shown = out.joinpath(*rest)
    elif first.startswith(f".{out.name}."):  # the temporary itself, the lock, the journal
        shown = out.parent
    words = os.strerror(exc.errno) if exc.errno else str(exc)
    return OutputError(f"cannot write {shown}: {words}")


def _cannot_write(path: Path) -> OutputError:
    try:
        read_only = bool(os.statvfs(path).f_flag & os.ST_RDONLY)
    except OSError:
        read_only = False
    return OutputError(f"cannot write {path}: {os.strerror(errno.EROFS if read_only else errno.EACCES)}")


def _check_replaceable(out: Path) -> None:
    if os.path.lexists(out):
        if not out.is_dir() or not (is_build(out) or not any(out.iterdir())):
            raise OutputError(f"--out {out} exists and is not an earlier magfab build (no manifest.json); "
                              "refusing to replace it: choose another directory")
        need = [out.parent, out]
    else:
        need = [next(p for p in out.parents if os.path.lexists(p))]
        if not need[0].is_dir():
            raise OutputError(f"cannot write {out}: {need[0]} is not a folder")
    for folder in need:
        if not os.access(folder, os.W_OK | os.X_OK):
            raise _cannot_write(folder)


def is_build(path: Path) -> bool:
    """Whether ``path`` holds an earlier magfab build (a manifest.json magfab wrote)."""
    try:  # read within bounds: a manifest.json that is a FIFO, /dev/zero or nested past the stack is not magfab's
        manifest = loads_json(read_bytes(path / "manifest.json", "JSON"), "manifest.json", path)
        return isinstance(manifest, dict) and "magfab_version" in manifest
    except (OSError, ValueError, TypeError, InputFileError):
        return False


# ---- the two entry points ----

def check_target(out_dir: Path) -> Path:
    """``out_dir`` as an absolute path if a build may replace it (absent, empty, or an earlier magfab build,
    and writable); :class:`OutputError` otherwise. Also finishes what a killed run left beside it. Checked
    before any work, and again just before the swap."""
    out = _absolute(out_dir)
    try:
        if any(os.path.lexists(_sibling(out, k)) for k in ("swap", "inplace", "lock")):
            lock = _acquire(out, 0.0)
            if lock is not None:  # else the build holding it recovers
                try:
                    _recover(out, lock)
                finally:
                    _release(out, lock)
        _check_replaceable(out)
    except OSError as exc:
        raise _os_error(exc, out) from exc
    return out


def write(out_dir: Path, artifacts: list[Artifact], *, lock_timeout_s: float = LOCK_WAIT_S,
          in_place: bool | None = None) -> Path:
    """Put the artifacts into ``out_dir`` (see the module's rules); returns it as an absolute path.
    ``in_place``: replace the changed files one by one instead of swapping the folder (default: when this
    process's working folder is ``out_dir`` or inside it, so a shell standing there is not left behind).

    Any OS error (full disk, read-only folder) is an :class:`OutputError` naming the path, with the previous
    output as it was and no temporaries left."""
    out = _absolute(out_dir)
    paths = [str(_safe_relative(a.path)) for a in artifacts]
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        lock = _acquire(out, lock_timeout_s)
    except OSError as exc:
        raise _os_error(exc, out) from exc
    if lock is None:
        raise _busy(out)
    try:
        _step("locked")
        _recover(out, lock)
        _check_replaceable(out)
        users = _user_files(out)
        _check_collisions(out, users, paths)
        tmp = _made(lock, "tmp")
        _step("temporary made")
        _write_tree(tmp, artifacts)
        if in_place is None:
            in_place = _working_folder_inside(out)
        if in_place and out.is_dir():
            _update_in_place(out, tmp, paths, lock)
        else:
            _carry(out, tmp, users)
            if out.is_dir():
                shutil.copymode(out, tmp)  # a user's chmod 700 on the folder stays
            _swap(out, tmp, lock)
        _recover(out, lock)  # commits: the journal goes, then the previous build
    except BaseException as exc:
        with suppress(OSError):
            _recover(out, lock)
        if isinstance(exc, OSError):
            raise _os_error(exc, out) from exc
        raise
    finally:
        _release(out, lock)
    return out


def _working_folder_inside(out: Path) -> bool:
    try:
        here, target = Path.cwd().resolve(), out.resolve()
    except OSError:  # the working folder was removed under us
        return False
    return here == target or target in here.parents
