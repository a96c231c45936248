"""Pydantic's validation errors as our one-line :class:`~magfab.errors.SpecError`: the dotted key, the value as given
(bounded in length) and what is allowed, with a close match for a misspelt key. Used for specs and for the design
search's targets."""

from __future__ import annotations

import difflib
import json
import re
from typing import Any, get_args

from pydantic import BaseModel, ValidationError

from .errors import SHOWN_MAX_CHARS, SpecError, shorten, shown

__all__ = ["translate_error", "did_you_mean"]


def _model_at(loc: tuple[Any, ...], root: type[BaseModel]) -> type[BaseModel] | None:
    model = root
    for part in loc:
        field = model.model_fields.get(str(part))
        annotation = field and next((a for a in (field.annotation, *get_args(field.annotation))
                                     if isinstance(a, type) and issubclass(a, BaseModel)), None)  # Optional[X] too
        if annotation is None:
            return None
        model = annotation
    return model


def did_you_mean(word: str, choices: list[str]) -> str:
    if len(word) > 4 * max(map(len, choices), default=0):  # nothing that long is a typo of a choice
        return ""
    close = difflib.get_close_matches(word, choices, n=1, cutoff=0.6)
    return f"did you mean {close[0]!r}?" if close else ""


def _lookup(raw: dict[str, Any], loc: tuple[Any, ...]) -> Any:
    value: Any = raw
    for part in loc:
        if (isinstance(value, dict) and part in value) or (isinstance(value, (list, tuple)) and isinstance(part, int)
                                                           and 0 <= part < len(value)):
            value = value[part]
        else:
            return "<missing>"
    return value


def _key_part(part: object) -> str:
    """A key as TOML would write it: bare when it can be, else quoted with escapes (one line, always, and
    shortened like a value when it is long)."""
    if isinstance(part, int):
        return f"[{part}]"
    text = str(part)
    return (text if re.fullmatch(r"[A-Za-z0-9_-]+", text) and len(text) <= SHOWN_MAX_CHARS
            else shorten(json.dumps(text)))


def _key(loc: tuple[Any, ...]) -> str:
    return "".join(p if p.startswith("[") or not i else "." + p for i, p in enumerate(map(_key_part, loc)))


#: Unit suffixes of key names, as a message prints them after a bound.
_UNITS = {"mm": "mm", "deg": "deg", "kPa": "kPa", "pct": "%", "mN": "mN", "G": "G", "h": "h", "min": "min",
          "hz": "Hz", "C": "C", "Am2": "A m^2"}
_BOUNDS = {"greater_than": ("gt", "greater than"), "greater_than_equal": ("ge", "at least"),
           "less_than": ("lt", "less than"), "less_than_equal": ("le", "at most")}


def _number(x: object) -> str:
    """A bound exactly as the model holds it: 10.0 -> '10', 0.5 -> '0.5', 2147483647 -> '2147483647'."""
    if isinstance(x, float) and x.is_integer() and abs(x) < 1e16:
        return str(int(x))
    return repr(x) if isinstance(x, float) else str(x)


def translate_error(exc: ValidationError, raw: dict[str, Any], root: type[BaseModel]) -> SpecError:
    """Turn pydantic's first error into our one-line message: the key, the value exactly and bounded in
    length (:func:`shown`), and what is allowed with its bound printed as the model holds it. ``root``: the model
    validated (:class:`magfab.spec.Spec`, or the design search's targets)."""
    err = exc.errors(include_url=False)[0]
    loc = tuple(err["loc"])
    key = _key(loc)
    value = err.get("input", _lookup(raw, loc))
    kind = err["type"]
    if isinstance(value, dict):
        value = "{...}"
    if kind == "extra_forbidden":
        parent = _model_at(loc[:-1], root)
        allowed = sorted(parent.model_fields) if parent else []
        what = "unknown section" if len(loc) == 1 and value == "{...}" else "unknown key"
        return SpecError(key, shown(value), f"{what}; allowed: {', '.join(allowed)}",
                         did_you_mean(str(loc[-1]), allowed))
    if kind == "missing":
        return SpecError(key, "<missing>", "required key is missing")
    if kind == "model_type":
        return SpecError(key, shown(value), "must be a table (a [section])")
    last = next((str(p) for p in reversed(loc) if not isinstance(p, int)), "")
    suffix = last.rsplit("_", 1)[-1] if "_" in last else ""
    unit = f" {_UNITS[suffix]}" if suffix in _UNITS else ""
    ctx = err.get("ctx") or {}
    if kind in _BOUNDS:
        name, words = _BOUNDS[kind]
        msg = f"must be {words} {_number(ctx[name])}{unit}"
    elif kind == "float_type":
        msg = "must be a number" + (unit and f" (in{unit})")
    elif kind in {"int_type", "int_from_float", "int_parsing"}:
        msg = "must be an integer (a whole number such as 12 or 12.0)"
    elif kind == "value_error":
        msg = str(ctx.get("error", err["msg"])).removeprefix("Value error, ")
    elif kind == "string_pattern_mismatch":
        msg = f"must match the pattern {ctx.get('pattern', '')}"
    else:
        msg = err["msg"].replace("Input should be", "must be").replace("String should", "must")
    return SpecError(key, shown(value), msg)
