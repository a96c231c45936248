"""The jinja2 environment for everything magfab renders from ``templates/``.

Templates live in the top-level ``templates/`` folder of the source tree and are installed as the package
``magfab.templates``. Rendering is strict (an undefined name is an error, never an empty string) and has
filters that escape a value for the language it lands in; a template must use one of them for any value
that comes from a spec (``c_string``, ``py_string``, ``c_float``...). HTML templates get autoescaping.
"""

from __future__ import annotations

import json
import math
import re
from functools import lru_cache
from importlib.resources import files
from pathlib import Path

# Imported lazily, inside the functions that use it, for speed: jinja2 takes a
# noticeable time to import, and importing this module should not.

__all__ = ["templates_dir", "environment", "render"]


def templates_dir() -> Path:
    """The folder holding the templates: the installed ``magfab.templates`` package, or the source tree's
    ``templates/`` (an editable install does not map the folder into the package)."""
    try:
        installed = Path(str(files("magfab.templates")))
        if (installed / "__init__.py").exists() and any(p.is_dir() for p in installed.iterdir()):
            return installed
    except (ModuleNotFoundError, TypeError, FileNotFoundError):
        pass
    return Path(__file__).resolve().parents[2] / "templates"


def c_string(value: object) -> str:
    """A C string literal (with quotes) holding ``value``: printable ASCII only, escaped."""
    out = []
    for ch in str(value):
        code = ord(ch)
        if ch in '"\\':
            out.append("\\" + ch)
        elif 32 <= code < 127 and ch != "?":  # '?' would start a trigraph
            out.append(ch)
        else:
            out.extend(f"\\x{b:02x}\"\"" for b in ch.encode("utf-8"))  # "" ends the hex escape
    return '"' + "".join(out) + '"'


def c_float(value: object) -> str:
    """A C float literal: finite, round-trip exact for float32 (9 significant digits), with the f suffix."""
    x = float(value)  # type: ignore[arg-type]
    if not math.isfinite(x):
        raise ValueError(f"a C float literal must be finite; instead received {value!r}")
    text = f"{x:.9g}"
    if "e" not in text and "." not in text:
        text += ".0"
    return text + "f"


def c_int(value: object) -> str:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"a C integer literal needs an int; instead received {value!r}")
    return str(value)


def py_string(value: object) -> str:
    """A Python string literal (JSON's escaping is valid Python)."""
    return json.dumps(str(value))


_MD_SPECIAL = re.compile(r"([\\`*_\[\]|~])")


def md(value: object) -> str:
    """Plain text safe inside a Markdown paragraph or list item: HTML-escaped (renderers pass raw HTML
    through), the characters that start emphasis, code, links or tables backslash-escaped, newlines folded."""
    text = " ".join(str(value).split())
    text = text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    return _MD_SPECIAL.sub(lambda m: "\\" + m.group(1), text)


@lru_cache(maxsize=4)
def environment(autoescape: bool = False):
    import jinja2

    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(templates_dir())),
        undefined=jinja2.StrictUndefined,
        autoescape=autoescape,
        keep_trailing_newline=True,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    env.filters.update(c_string=c_string, c_float=c_float, c_int=c_int, py_string=py_string, json=json.dumps, md=md)
    return env


def render(name: str, **context: object) -> str:
    """Render ``templates/<name>`` with ``context``; HTML templates are autoescaped."""
    return environment(name.removesuffix(".j2").endswith((".html", ".htm"))).get_template(name).render(**context)
