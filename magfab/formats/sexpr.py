"""KiCad S-expression writing: numbers, strings and nested lists rendered deterministically.

A node is a tuple ``(head, *children)``; children are nodes, numbers, :class:`Sym` (bare words such as
``smd``) or strings (always quoted). Numbers print with at most six decimals and no trailing zeros, the
way KiCad writes them, so the same input always gives the same bytes.
"""

from __future__ import annotations

from collections.abc import Iterable


class Sym(str):
    """A bare S-expression word (``smd``, ``roundrect``, ``yes``), written without quotes."""


Node = tuple | Sym | str | float | int


def num(x: float) -> str:
    """A length or angle as KiCad writes it: up to 6 decimals, no trailing zeros, never ``-0``."""
    text = f"{round(float(x), 6):.6f}".rstrip("0").rstrip(".")
    return "0" if text in {"-0", ""} else text


def quote(text: str) -> str:
    """A KiCad string literal. Backslashes and quotes are escaped; control characters are refused."""
    if any(ord(c) < 32 for c in text):
        raise ValueError(f"control character in KiCad string {text!r}")
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _atom(x: Node) -> str:
    if isinstance(x, Sym):
        return str(x)
    if isinstance(x, str):
        return quote(x)
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, (int, float)):
        return num(x)
    raise TypeError(f"not an S-expression atom: {x!r}")


def _flat(node: tuple) -> bool:
    return all(not isinstance(c, tuple) or all(not isinstance(g, tuple) for g in c[1:]) for c in node[1:])


def render(node: Node, indent: int = 0, *, wrap: Iterable[str] = ()) -> str:
    """Render a node. Nodes whose head is in ``wrap`` put each child on its own line (like KiCad)."""
    wrap = frozenset(wrap)
    if not isinstance(node, tuple):
        return _atom(node)
    head, *children = node
    if head not in wrap and _flat(node):
        return "(" + " ".join([str(head), *(render(c, wrap=wrap) for c in children)]) + ")"
    pad = "  " * (indent + 1)
    parts = [f"({head}"]
    line: list[str] = []
    for child in children:
        if isinstance(child, tuple):
            if line:
                parts[-1] += " " + " ".join(line)
                line = []
            parts.append(pad + render(child, indent + 1, wrap=wrap))
        else:
            line.append(_atom(child))
    if line:
        parts[-1] += " " + " ".join(line)
    if len(parts) == 1:
        return parts[0] + ")"
    return "\n".join(parts) + "\n" + "  " * indent + ")"


def xy(x: float, y: float) -> tuple:
    return ("xy", x, y)


def at(x: float, y: float, angle: float = 0.0) -> tuple:
    return ("at", x, y, angle) if angle else ("at", x, y)
