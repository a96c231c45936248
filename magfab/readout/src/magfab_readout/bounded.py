"""Input files read safely: a regular file of at most a stated size, and TOML or JSON of bounded nesting and keys.

Every reader of a user's file in magfab and magfab-readout goes through :func:`read_bytes` (a FIFO, a device such as
``/dev/zero`` or a directory is refused before a byte is read, and so is a file over its kind's limit in
:data:`LIMITS`), and every JSON or TOML text through :func:`loads_json` or :func:`check_toml` plus :func:`check_tree`:
the nesting depth is found by a linear scan *before* the recursive parser runs (Python's json and tomllib recurse
once per level and end in a RecursionError near 1,000), and no table or object may hold more than
:data:`MAX_KEYS` keys (each refused key would otherwise cost a validation error object). Each refusal is one
:class:`InputFileError` line naming the file and the limit (docs/bundle.md, "Limits of input files").

Standard library only, and no tomllib (the readout runs on Python 3.8 and reads no TOML; magfab parses TOML with
these checks around it, ``magfab.formats.bounded``).
"""

from __future__ import annotations

import json
import os
import re
import stat
from typing import Any, Dict, List, Optional, Tuple

if __name__.startswith("magfab."):  # magfab's import of this file (magfab.formats.bounded): an InputError, exit 2
    from magfab.errors import InputError as _Base
else:  # the readout package on the user's Python: its CLI exits 2 on it
    _Base = ValueError  # type: ignore[misc, assignment]

__all__ = ["LIMITS", "MAX_DEPTH", "MAX_KEYS", "InputFileError", "check_toml", "check_tree", "loads_json", "read_bytes",
           "read_text"]

MB = 1_000_000
#: Largest file of each kind, bytes; each far above what magfab writes or a lab records (docs/bundle.md).
LIMITS = {
    "spec": 1 * MB,               # a spec is a few kB (MagOne's, every key commented: 5.6 kB)
    "targets": 1 * MB,            # the same for a design's targets (the commented example: 1.8 kB)
    "spec.json": 1 * MB,          # a build's or a record's spec, every default filled in: about 3 kB
    "scan CSV": 256 * 1024 * 1024,      # the sensor records' own limit: about an hour of `record` rows (~100 bytes)
    "reference log": 256 * 1024 * 1024,  # at the chip's fastest conversion (1.27 ms); a calibration scan takes minutes
    "weighings CSV": 1 * MB,      # at most 500 weighings of about 100 bytes (magfab.formats.weights_csv)
    "calibration.json": 64 * MB,  # an MLS calibration keeps its scan points: over 500,000 of them
    "acceptance.json": 16 * MB,   # bands and one weight table: a few kB
    "array.json": 16 * MB,        # the neighbours' field tables of up to 16 taxels: tens of kB
    "JSON": 16 * MB,              # any other JSON a build or a record holds (predictions, manifest, events)
}
#: Deepest nesting of arrays, tables and objects inside each other (the document itself is 1); magfab's deepest nests 4.
MAX_DEPTH = 32
#: Most keys of one table or object (TOML: also most items of one array); the largest of any format holds under 50.
MAX_KEYS = 1000


class InputFileError(_Base):
    """An input file refused before it is parsed (exit 2): ``what`` it is, ``where`` (its path) and what is allowed,
    in one line ``what = where: allowed``."""

    def __init__(self, what: str, where: object, allowed: str) -> None:
        self.what, self.where, self.allowed = what, str(where), allowed
        super().__init__(f"{what} = {where}: {allowed}")


def size_text(n: int) -> str:
    """``n`` bytes as '1 MB', '256 MiB' or '12,345 bytes' (decimal units; a power of two in MiB)."""
    if n >= 1024 * 1024 and n % (1024 * 1024) == 0 and n % MB:
        return f"{n // (1024 * 1024):,} MiB"
    if n >= 1000 * MB:
        return f"{n / (1000 * MB):,.1f} GB"
    if n >= MB:
        return f"{round(n / MB, 1):g} MB"
    return f"{n:,} bytes"


def _kind_of(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def read_bytes(path: Any, what: str, limit: Optional[int] = None) -> bytes:
    """The bytes of the regular file ``path`` (a str or path-like), of at most ``limit`` bytes (default: ``what``'s
    in :data:`LIMITS`). Opening never waits (a FIFO is opened non-blocking, then refused); :class:`InputFileError`
    for anything that is not a regular file or is over the limit; OSError (FileNotFoundError...) as ``open``."""
    limit = LIMITS[what] if limit is None else limit
    allowed = "must be a regular file of at most " + size_text(limit)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_BINARY", 0)
    fd = os.open(os.fspath(path), flags)
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise InputFileError(what, path, f"{allowed} (it is {_kind_of(st.st_mode)})")
        if st.st_size > limit:
            raise InputFileError(what, path, f"{allowed} (it holds {size_text(st.st_size)})")
        chunks: List[bytes] = []
        total = 0
        while total <= limit:  # the file may grow while it is read: never more than limit + 1 bytes
            chunk = os.read(fd, min(1 << 20, limit + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
        if total > limit:
            raise InputFileError(what, path, f"{allowed} (it grew past that while read)")
        return b"".join(chunks)
    finally:
        os.close(fd)


def read_text(path: Any, what: str, limit: Optional[int] = None) -> str:
    """:func:`read_bytes` decoded as UTF-8 (UnicodeDecodeError as ``bytes.decode``)."""
    return read_bytes(path, what, limit).decode("utf-8")


def _line(text: str, pos: int) -> int:
    return text.count("\n", 0, pos) + 1


def _too_deep(what: str, where: object, text: str, pos: int, max_depth: int) -> InputFileError:
    return InputFileError(what, where, f"nests arrays, tables or objects more than {max_depth} deep "
                          f"(line {_line(text, pos)})")


# A JSON string (an unterminated one runs to the end, so a run of escaped quotes is scanned once) or a bracket.
_JSON_TOKEN = re.compile(r'"[^"\\]*(?:\\[\s\S][^"\\]*)*"?|[\[\]{}]')


def check_json_depth(text: str, what: str, where: object = "", max_depth: int = MAX_DEPTH) -> None:
    """:class:`InputFileError` when JSON ``text`` nests deeper than ``max_depth``: a linear scan of the brackets
    outside strings, so json's recursive parser never sees such a text."""
    if text.count("[") + text.count("{") <= max_depth:
        return
    depth = 0
    for m in _JSON_TOKEN.finditer(text):
        c = text[m.start()]
        if c in "[{":
            depth += 1
            if depth > max_depth:
                raise _too_deep(what, where, text, m.start(), max_depth)
        elif c in "]}":
            depth = max(0, depth - 1)


def loads_json(text: Any, what: str, where: object = "", max_depth: int = MAX_DEPTH,
               max_keys: int = MAX_KEYS) -> Any:
    """``json.loads(text)`` (str, or UTF-8 bytes) after :func:`check_json_depth`, refusing an object of more than
    ``max_keys`` keys; :class:`InputFileError` for either, ValueError (json's, or UnicodeDecodeError) otherwise."""
    if isinstance(text, (bytes, bytearray)):
        text = text.decode("utf-8")
    check_json_depth(text, what, where, max_depth)

    def pairs(items: List[Tuple[str, Any]]) -> Dict[str, Any]:
        if len(items) > max_keys:
            raise InputFileError(what, where, f"an object holds {len(items):,} keys; at most {max_keys:,} "
                                 f"(its first: {items[0][0][:40]!r})")
        return dict(items)

    try:
        return json.loads(text, object_pairs_hook=pairs)
    except RecursionError:  # the scan above makes this unreachable; kept so no parser ever ends in a traceback
        raise _too_deep(what, where, text, 0, max_depth) from None


# TOML tokens the depth scan needs: strings and comments (skipped whole; an unterminated one runs to its end) and the
# characters that open, close or separate arrays, inline tables, headers and dotted keys.
_TOML_TOKEN = re.compile(
    r'"""(?:[^\\"]|\\[\s\S]|"(?!""))*(?:"""|\Z)'
    r"|'''[\s\S]*?(?:'''|\Z)"
    r'|"[^"\\\n]*(?:\\.[^"\\\n]*)*"?'
    r"|'[^'\n]*'?"
    r"|#[^\n]*"
    r"|[\[\]{}=,.\n]")


def check_toml(text: str, what: str, where: object = "", max_depth: int = MAX_DEPTH) -> None:
    """:class:`InputFileError` when TOML ``text`` may nest deeper than ``max_depth``: a linear scan, before tomllib
    (which recurses once per array or inline table, and takes quadratic time over a long dotted key). The level it
    counts (table header parts, dotted key parts and open arrays and inline tables) is at least the parsed depth;
    :func:`check_tree` then checks the parsed document exactly."""
    stack: List[str] = []  # the open arrays ("[") and inline tables ("{") of the current value
    saved: List[int] = []  # ``dots`` when each of them opened
    header = dots = header_brackets = 0
    key = True  # at a key (a line's start, or an inline table's), where "." separates key parts
    for m in _TOML_TOKEN.finditer(text):
        c = text[m.start()]
        if c == "\n":
            if not stack:
                key, dots = True, 0
        elif c == ".":
            if key:
                dots += 1
        elif c == "=":
            key = False
        elif c == "," and stack:
            key = stack[-1] == "{"
            if key:
                dots = saved[-1]
        elif c == "[" and (header_brackets or (key and not stack)):  # a table header, [a.b] or [[a.b]]
            header_brackets += 1
            dots = 0
        elif c == "]" and header_brackets and not stack:
            header_brackets -= 1
            if not header_brackets:
                header, dots, key = dots + 2, 0, False
        elif c in "[{":
            stack.append(c)
            saved.append(dots)
            key = c == "{"
        elif c in "]}" and stack:
            stack.pop()
            dots = saved.pop()
            key = False
        else:
            continue
        if header + dots + len(stack) > max_depth:
            raise _too_deep(what, where, text, m.start(), max_depth)


def check_tree(data: Any, what: str, where: object = "", max_depth: int = MAX_DEPTH, max_keys: int = MAX_KEYS) -> None:
    """:class:`InputFileError` when parsed ``data`` (dicts and lists) nests deeper than ``max_depth`` or one of its
    tables or arrays holds more than ``max_keys`` entries. Iterative, so any depth is walked safely."""
    todo: List[Tuple[Any, int, str]] = [(data, 1, "")]
    while todo:
        node, depth, path = todo.pop()
        if depth > max_depth:
            raise InputFileError(what, where, f"nests arrays and tables more than {max_depth} deep (at {path[:60]})")
        if len(node) > max_keys:
            raise InputFileError(what, where, "{} holds {:,} {}; at most {:,}".format(
                path[:60] or "the top level", len(node), "keys" if isinstance(node, dict) else "items", max_keys))
        items = node.items() if isinstance(node, dict) else enumerate(node)
        for k, v in items:
            if isinstance(v, (dict, list)):
                todo.append((v, depth + 1, f"{path}.{k}" if path else str(k)))
