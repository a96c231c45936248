"""The commands a page tells a person to type: its fenced code blocks tagged ``sh`` (and ``python``), in order.

    for block in blocks(text, "README.md"):
        block.lang, block.line, block.commands      # "sh", the line the fence opens on, one command a line

Blocks inside list items (indented fences) are read with their indentation removed. The README's test
command (between ``<!-- test-command -->`` markers) is CI's own and is left out, as is the install command
right above it (``test_readme_install_command`` runs that one, behind the slow marker)."""

from __future__ import annotations

import re
from dataclasses import dataclass

__all__ = ["Block", "blocks", "RUNNABLE"]

RUNNABLE = ("sh", "python")
_FENCE = re.compile(r"^(?P<indent>\s*)```(?P<lang>[\w-]*)\s*$")


@dataclass(frozen=True)
class Block:
    page: str
    lang: str
    line: int
    text: str

    @property
    def commands(self) -> list[str]:
        """The block's shell commands: one a line, blank lines and whole-line comments left out."""
        return [c for c in (raw.strip() for raw in self.text.splitlines()) if c and not c.startswith("#")]

    def __str__(self) -> str:
        return f"{self.page}:{self.line}"


def blocks(text: str, page: str, *, every: bool = False) -> list[Block]:
    """The runnable fenced blocks of a Markdown page, in order (``every``: whatever their language)."""
    out: list[Block] = []
    lines = text.splitlines()
    skip = False
    i = 0
    while i < len(lines):
        if "<!-- test-command -->" in lines[i]:
            skip = True
        elif "<!-- /test-command -->" in lines[i]:
            skip = False
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        indent, lang, start = m["indent"], m["lang"], i
        body = []
        i += 1
        while i < len(lines) and lines[i].strip() != "```":
            body.append(lines[i][len(indent):] if lines[i].startswith(indent) else lines[i].lstrip())
            i += 1
        i += 1
        if (every or lang in RUNNABLE) and not skip:
            out.append(Block(page, lang, start + 1, "\n".join(body) + "\n"))
    return out


def install_command(readme: str) -> str:
    """The README's first command: install and run the default build on a fresh machine."""
    first = next(b for b in blocks(readme, "README.md") if b.lang == "sh")
    return first.commands[0]
