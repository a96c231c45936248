"""Writing a study's files: each one whole or not at all (a temporary name beside it, then a rename), and only
inside the study's folder."""

from __future__ import annotations

import os
import re
from pathlib import Path

import tomli_w

from ..errors import OutputError
from ..spec import Spec

__all__ = ["write_bytes", "spec_toml"]


def write_bytes(path: Path, data: bytes) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    return path


def spec_toml(spec: Spec, header: str) -> bytes:
    """A spec as TOML ``magfab build`` reads back to the same spec (omitted optional keys stay omitted)."""
    raw = spec.toml_dict()
    comment = "".join(f"# {line}\n" if line else "#\n" for line in header.splitlines())
    return (comment + "\n" + _hex_addresses(tomli_w.dumps(raw))).encode("utf-8")


#: A 7-bit I2C address as tomli_w writes it (decimal).
_ADDRESS = re.compile(r"^(i2c_address = )(\d+)$", re.MULTILINE)


def _hex_addresses(text: str) -> str:
    """I2C addresses in hex, as the chip's datasheet and a bus scan give them (TOML reads 0x0C as 12)."""
    return _ADDRESS.sub(lambda m: f"{m[1]}0x{int(m[2]):02X}", text)
