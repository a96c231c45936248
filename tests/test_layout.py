"""The codebase reads as the pipeline: small modules and functions, and imports that point down it."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "magfab"
MODULE_LINES = 600  # "no module over ~500 lines": a docstring or a sourced table may take it a little past
FUNCTION_LINES = 80  # past this, the line above the def says why (a comment starting "# long:")

#: What each folder may not import: models compute values (no rendering, no pipeline, no printing); formats are
#: standard-library readers shipped inside the readout package too; board places and checks, KiCad writing aside.
FORBIDDEN = {
    "magfab.models": ("magfab.export", "magfab.pipeline", "magfab.cli", "magfab.output", "magfab.board"),
    "magfab.formats": ("magfab.models", "magfab.export", "magfab.pipeline", "magfab.cli", "magfab.board",
                       "magfab.spec", "magfab.design"),
    "magfab.board": ("magfab.export", "magfab.pipeline", "magfab.cli", "magfab.models"),
    "magfab.export": ("magfab.pipeline", "magfab.cli"),
}
PRINTING = ("click", "rich")  # only the CLI prints


def _modules():
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def _name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    package = _name(path) if path.name == "__init__.py" else _name(path).rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.add(mod)
            out |= {f"{mod}.{a.name}" for a in node.names}
    return out


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_module_and_function_sizes(path):
    lines = path.read_text().splitlines()
    assert len(lines) <= MODULE_LINES, f"{len(lines)} lines: split the module"
    for node in ast.walk(ast.parse("\n".join(lines))):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            size = node.end_lineno - node.lineno + 1
            first = min([node.lineno] + [d.lineno for d in node.decorator_list])
            reason = lines[first - 2].strip().startswith("# long:") if first >= 2 else False
            assert size <= FUNCTION_LINES or reason, f"{node.name} is {size} lines: split it, or say why above it"


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_imports_point_down_the_pipeline(path):
    name = _name(path)
    if name.startswith("magfab.readout."):
        return  # the readout package's own modules: standard library only, checked by its own tests
    imported = _imports(path)
    for folder, forbidden in FORBIDDEN.items():
        if name == folder or name.startswith(folder + "."):
            bad = sorted(m for m in imported if any(m == f or m.startswith(f + ".") for f in forbidden))
            assert not bad, f"{name} imports {bad}"
    if name != "magfab.cli":
        assert not {m for m in imported if m.split(".")[0] in PRINTING}, f"{name} prints: only magfab.cli may"
