"""Generators of adversarial inputs shared by the tests and bench/adversarial.py (the second adversarial pass's
runner): TOML and JSON nested past the readers' depth limit, files that are not regular files or are over a
reader's size limit, and names beside a build that look like magfab's temporaries.

Plain functions and Hypothesis strategies (no test in here); the test modules and the bench import them."""

from __future__ import annotations

import json
import os
import random
from pathlib import Path

from hypothesis import strategies as st

DEPTH = 32  # magfab_readout.bounded.MAX_DEPTH, written out so the tests run against a tree without the module
KEYS = 1000  # bounded.MAX_KEYS


# --- nesting --------------------------------------------------------------------------------------------------

@st.composite
def deep_toml_value(draw) -> str:
    """A TOML line nesting more than DEPTH levels: arrays and inline tables mixed at random (under a plain or a
    dotted key), a dotted key or a table header of that many parts; 33 to 5,000 levels."""
    depth = draw(st.integers(DEPTH + 1, 5000))
    rng = random.Random(draw(st.integers(0, 2**32)))
    form = draw(st.sampled_from(["value", "dotted value", "dotted key", "header", "array of tables"]))
    if form in ("dotted key", "header", "array of tables"):
        path = ".".join(rng.choice(["a", "b_1", '"q.k"', "'l'"]) for _ in range(depth))
        return {"dotted key": f"{path} = 1", "header": f"[{path}]\nx = 1", "array of tables": f"[[{path}]]"}[form]
    kinds = [rng.choice("[{") for _ in range(depth)]
    opens = "".join("[" if k == "[" else "{k = " for k in kinds)
    closes = "".join("]" if k == "[" else "}" for k in reversed(kinds))
    key = "x.y.z" if form == "dotted value" else "deep_key"
    return f"{key} = {opens}1{closes}"


def inserted(document: str, line: str, rng: random.Random) -> str:
    """``line`` put at a random line boundary of ``document`` (inside a table, or at the top)."""
    lines = document.splitlines()
    at = rng.randint(0, len(lines))
    return "\n".join([*lines[:at], line, *lines[at:]]) + "\n"


@st.composite
def deep_toml_document(draw, base: str) -> str:
    return inserted(base, draw(deep_toml_value()), random.Random(draw(st.integers(0, 2**32))))


@st.composite
def deep_json_document(draw, base: dict) -> str:
    """``base`` with one value, at a random place (a key of any of its objects), replaced by arrays and objects
    nested 33 to 5,000 deep in random order."""
    depth = draw(st.integers(DEPTH + 1, 5000))
    rng = random.Random(draw(st.integers(0, 2**32)))
    objects = [base]
    todo = [base]
    while todo:
        node = todo.pop()
        for v in node.values():
            if isinstance(v, dict):
                objects.append(v)
                todo.append(v)
    target = rng.choice(objects)
    key = rng.choice([*target, "extra"])
    saved = target.get(key, None)
    target[key] = "@@DEEP@@"
    text = json.dumps(base)
    if saved is None:
        del target[key]
    else:
        target[key] = saved
    kinds = [rng.choice("[{") for _ in range(depth)]
    deep = "".join("[" if k == "[" else '{"k": ' for k in kinds) + "1" + "".join(
        "]" if k == "[" else "}" for k in reversed(kinds))
    return text.replace('"@@DEEP@@"', deep, 1)


# --- files that are not regular files, or too large -------------------------------------------------------------

#: What :func:`special` makes.
KINDS = ["fifo", "dev-zero", "symlink", "directory", "oversize"]


def special(kind: str, folder: Path, size: int) -> Path:
    """A file of ``kind``: a FIFO, /dev/zero, a symlink to it, a directory, or a sparse file of ``size`` bytes."""
    path = folder / f"input-{kind}"
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "dev-zero":
        return Path("/dev/zero")
    elif kind == "symlink":
        path.symlink_to("/dev/zero")
    elif kind == "directory":
        path.mkdir()
    else:
        with open(path, "wb") as f:
            f.truncate(size)  # sparse: no disk, no time
    return path


# --- names beside a build that look like magfab's temporaries ----------------------------------------------------

_HEX, _WORD = "0123456789abcdef", "abcdefghijklmnopqrstuvwxyz0123456789_"
_SUFFIXES = st.one_of(st.text(_HEX, min_size=16, max_size=16), st.text(_WORD, min_size=8, max_size=8),
                      st.dates().map(lambda d: d.strftime("%Y%m%d")), st.dates().map(str),
                      st.text(_WORD + "-.", max_size=24))
#: (temporary kind "tmp" or "old", suffix, shape): ``.<build name>.<kind>-<suffix>`` beside the build, as a folder
#: with a file in it, an empty folder, a file or a link (:func:`make_look_alike`).
LOOK_ALIKES = st.lists(st.tuples(st.sampled_from(["tmp", "old"]), _SUFFIXES,
                                 st.sampled_from(["folder", "empty folder", "file", "link"])),
                       min_size=1, max_size=6, unique_by=lambda t: t[:2])


def make_look_alike(root: Path, name: str, kind: str, suffix: str, shape: str) -> Path:
    """``.<name>.<kind>-<suffix>`` in ``root`` (beside the build ``root / name``) of ``shape`` (see LOOK_ALIKES)."""
    path = root / f".{name}.{kind}-{suffix}"
    if shape == "folder":
        (path / "sub").mkdir(parents=True)
        (path / "sub" / "data.bin").write_bytes(suffix.encode())
    elif shape == "empty folder":
        path.mkdir()
    elif shape == "file":
        path.write_bytes(suffix.encode())
    else:
        os.symlink(name, path)
    return path
