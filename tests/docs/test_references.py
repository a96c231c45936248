"""The project explains itself from its own files: no tracked text cites a document outside the repository (a
design brief, an issue tracker's numbers, equation numbers of no file here), and every section it cites in
docs/models.md or docs/bundle.md is a heading there."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
THIS = Path(__file__).resolve().relative_to(ROOT).as_posix()

#: Outside references, each with what to write instead. Equation numbers must be a section of docs/models.md
#: (M<n>), so "eq. 6" with or without brackets is refused; "-eq 5" (a shell test) is not an equation.
OUTSIDE = {
    "a design brief": re.compile(r"\bBRIEF\b|(?i:\b(?:the|of the|per|in the) brief\b)"),
    "an issue number": re.compile(r"(?i:\bissues?\s*(?:#\s*)?\d+)"),
    "an equation number": re.compile(r"(?i:(?<![-\w])(?:eqs?\.\s*|eqs?\s+|equations?\s+)\(?\d)"),
}
#: An issue of another, named project ("facebookresearch/digit-design issue #30") is a source like any other.
NAMED_REPO = re.compile(r"[\w.-]+/[\w.-]+\s+$")
#: A citation of docs/models.md: the file, then a section or a range or list of them (M6, M12 to M14, M5-M11).
MODELS_CITE = re.compile(r"models\.md`?[,:]?\s*\(?((?:M\d+)(?:\s*(?:,|-|to|and)\s*M\d+)*)")
#: A citation of docs/bundle.md by section number: "docs/bundle.md section 4", "docs/bundle.md, section 1".
BUNDLE_CITE = re.compile(r"bundle\.md`?,?\s+sections?\s+(\d+)(?:\s*-\s*(\d+))?")


def _tracked_texts() -> list[tuple[str, str]]:
    """(path, text) of every tracked file that decodes as UTF-8 without NUL bytes, this file excepted."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("needs a git checkout to know which files are tracked")
    names = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    out = []
    for name in names.decode().split("\0"):
        path = ROOT / name
        if not name or name == THIS or not path.is_file():
            continue
        data = path.read_bytes()
        if b"\0" in data:
            continue
        try:
            out.append((name, data.decode("utf-8")))
        except UnicodeDecodeError:
            continue
    return out


def _headings(path: Path, pattern: str) -> set[str]:
    return {m.group(1) for m in re.finditer(pattern, path.read_text(encoding="utf-8"), re.MULTILINE)}


def _line(text: str, pos: int) -> int:
    return text.count("\n", 0, pos) + 1


def _outside(text: str):
    """(what, match) for every outside reference in ``text``."""
    for what, rx in OUTSIDE.items():
        for m in rx.finditer(text):
            if what == "an issue number" and NAMED_REPO.search(text, max(0, m.start() - 100), m.start()):
                continue
            yield what, m


def test_no_text_cites_a_document_outside_the_repository():
    bad = [f"{name}:{_line(text, m.start())}: {what} ({m.group(0)!r})"
           for name, text in _tracked_texts() for what, m in _outside(text)]
    assert not bad, ("cite docs/models.md (its M<n> sections) or the original source instead:\n" + "\n".join(bad))


def test_every_cited_section_exists():
    models = _headings(ROOT / "docs" / "models.md", r"^## (M\d+)\. ")
    bundle = _headings(ROOT / "docs" / "bundle.md", r"^## (\d+)\. ")
    assert {f"M{i}" for i in range(1, 25)} <= models and {"1", "2", "3", "4", "5"} <= bundle  # the parser itself
    bad, cited = [], 0
    for name, text in _tracked_texts():
        for m in MODELS_CITE.finditer(text):
            for ref in re.findall(r"M\d+", m.group(1)):
                cited += 1
                if ref not in models:
                    bad.append(f"{name}:{_line(text, m.start())}: docs/models.md has no section {ref}")
        for m in BUNDLE_CITE.finditer(text):
            for ref in filter(None, m.groups()):
                cited += 1
                if ref not in bundle:
                    bad.append(f"{name}:{_line(text, m.start())}: docs/bundle.md has no section {ref}")
    assert cited > 0 and not bad, "\n".join(bad)


def test_the_checks_catch_what_they_are_for():
    """Negative controls: each pattern finds the forms it is meant to, and passes the look-alikes."""
    found = {what: [s for s in ("BRIEF sec. 3", "eq. 12 of the brief", "(issue 13)", "Issue #12, finding 4",
                                "eq. 6", "Eq. (9)", "eqs. 12-14", "equation 11", "eq 9")
                    if rx.search(s)] for what, rx in OUTSIDE.items()}
    assert found == {"a design brief": ["BRIEF sec. 3", "eq. 12 of the brief"],
                     "an issue number": ["(issue 13)", "Issue #12, finding 4"],
                     "an equation number": ["eq. 12 of the brief", "eq. 6", "Eq. (9)", "eqs. 12-14", "equation 11",
                                            "eq 9"]}
    for fine in ('if [ "$rc" -eq 5 ]', "let air in briefly", "the IPC-7351B equations (sec. 3.1.5)", "eq6(d)",
                 "used in facebookresearch/digit-design issue #30"):
        assert not list(_outside(fine)), fine
    assert MODELS_CITE.search("(docs/models.md, M12 to M14)").group(1) == "M12 to M14"
    assert BUNDLE_CITE.search("`docs/bundle.md` sections 3-5").groups() == ("3", "5")
    assert MODELS_CITE.search("(`docs/models.md`, M9)").group(1) == "M9"
