"""The codebase reads as the pipeline: small modules and functions, and imports that point down it."""

from __future__ import annotations

import ast
import graphlib
import io
import re
import tokenize
from dataclasses import dataclass
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
#: The command line: magfab.cli and the command groups it registers, each beside the engine it calls.
CLI_MODULES = {"magfab.cli", "magfab.sensor_cli", "magfab.weigh_cli", "magfab.cli_usage", "magfab.calibration_input",
               "magfab.cli_progress"}


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
    if name not in CLI_MODULES:
        assert not {m for m in imported if m.split(".")[0] in PRINTING}, f"{name} prints: only magfab.cli may"


# ---- the import graph: no cycle, no upward import, function-level imports counted -------------------------------
#
# Every ``import`` in a module is an edge, inside functions too (an import put in a function to dodge a cycle is still
# the cycle); imports under ``if TYPE_CHECKING:`` are not, since they never run. The readout package is a separate
# distribution (standard library only) with its own graph.

#: The pipeline's layers, bottom first: a module may import its own layer and those below, never one above. A module
#: belongs to the layer of its longest matching prefix.
LAYERS = (
    ("magfab", "magfab.units", "magfab.errors", "magfab.recipes", "magfab.outline", "magfab.fork"),
    ("magfab.spec_errors", "magfab.spec_options"),
    ("magfab.spec", "magfab.spec_sections"),
    ("magfab.formats",),  # file formats: standard library (and magfab.errors), shipped in the readout package too
    ("magfab.design", "magfab.plausible"),  # the design, and the unit-mistake guard it runs first
    ("magfab.elastomer", "magfab.mould", "magfab.pad", "magfab.fit"),  # the CAD solids and the mould's fit
    ("magfab.models", "magfab.reference_chip"),  # the reference chip is placed by the physics, read by the board
    ("magfab.limits",),
    ("magfab.board", "magfab.pcb", "magfab.jig"),  # below the checks: preflight holds the board's size to what
    # placement can make; the weight jig stands on the board and carries the weight plan's loads
    ("magfab.check",),
    ("magfab.export", "magfab.output", "magfab.exchange", "magfab.array_bench", "magfab.sensor_calibration"),
    ("magfab.pipeline", "magfab.stages", "magfab.sensors", "magfab.verdict"),
    ("magfab.inverse",),
    ("magfab.cli_usage", "magfab.calibration_input", "magfab.cli_progress"),  # the command line's group class and its
    # one-line refusal; its progress on stderr;
    # what `magfab calibrate` fits, read as the command line defers it
    ("magfab.sensor_cli", "magfab.weigh_cli"),
    ("magfab.cli",),
)
#: Libraries slow enough to import that a function may import them where it needs them (with the reason in a comment
#: saying "lazy" or "lazily", in the function or at module level); any other function-level import goes to the top.
HEAVY = {"cadquery", "OCP", "trimesh", "manifold3d", "matplotlib", "mpl_toolkits", "skfem", "magpylib", "optuna",
         "dask", "distributed", "pyarrow", "pcbnew", "scipy", "sqlalchemy", "PIL", "jinja2", "rich", "qdldl",
         "triangle",
         # the readout's live view: its server and browser, 25 ms of every other readout command's start
         "http", "webbrowser"}
#: Optional dependencies, imported where they are needed so that the package works without them.
OPTIONAL = {"serial", "mcap", "mcap_ros2"}  # pyserial; the readout's record --format mcap
#: The entry point may defer anything, magfab's own modules included, so that ``magfab --help`` stays fast.
ENTRY_POINTS = CLI_MODULES
_LAZY = re.compile(r"\blaz(y|ily)\b", re.IGNORECASE)


@dataclass(frozen=True)
class Import:
    module: str  # the importing module
    target: str  # what it imports: a module of the set when it names one, else the dotted name as written
    line: int
    in_function: str  # the enclosing function's name, "" at module level
    reason: bool  # a comment saying why it is lazy: in the enclosing function, or at module level


def _graph_imports(name: str, source: str, is_package: bool, modules: set[str]) -> list[Import]:
    """Every import of one module (see above), relative ones resolved against ``name``."""
    tree = ast.parse(source)
    package = name if is_package else name.rsplit(".", 1)[0]
    comments = {tok.start[0]: tok.string for tok in tokenize.generate_tokens(io.StringIO(source).readline)
                if tok.type == tokenize.COMMENT}
    spans = [(n.lineno, n.end_lineno) for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
    module_note = any(_LAZY.search(text) for line, text in comments.items()
                      if not any(a <= line <= b for a, b in spans))
    out: list[Import] = []

    def visit(node: ast.AST, function: ast.AST | None) -> None:
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for child in node.orelse:
                visit(child, function)
            return
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and function is None:
            function = node
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            reason = module_note or (function is not None and any(
                _LAZY.search(t) for line, t in comments.items() if function.lineno <= line <= function.end_lineno))
            where = function.name if function is not None else ""
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                base = package.split(".")[: len(package.split(".")) - node.level + 1] if node.level else []
                mod = ".".join(base + ([node.module] if node.module else []))
                targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in modules else mod for a in node.names]
            out.extend(Import(name, t, node.lineno, where, reason) for t in dict.fromkeys(targets))
        for child in ast.iter_child_nodes(node):
            visit(child, function)

    visit(tree, None)
    return out


def _package_imports(root: Path) -> list[Import]:
    paths = {_name(p): p for p in root.rglob("*.py") if "__pycache__" not in p.parts}
    return [i for name, p in sorted(paths.items())
            for i in _graph_imports(name, p.read_text(), p.name == "__init__.py", set(paths))]


def _layer(module: str) -> int:
    found = [(len(prefix), i) for i, layer in enumerate(LAYERS) for prefix in layer
             if module == prefix or module.startswith(prefix + ".")]
    assert found, f"{module} is in no layer: add it to LAYERS"
    return max(found)[1]


def _cycle(imports: list[Import]) -> list[str]:
    """One import cycle among the modules of ``imports`` (graphlib names it), or []."""
    modules = {i.module for i in imports}
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for i in imports:
        if i.target in modules and i.target != i.module:
            graph[i.module].add(i.target)
    try:
        graphlib.TopologicalSorter(graph).prepare()
    except graphlib.CycleError as exc:
        return list(exc.args[1])
    return []


def _upward(imports: list[Import]) -> list[str]:
    modules = {i.module for i in imports}
    return [f"{i.module}:{i.line} imports {i.target}" for i in imports
            if i.target in modules and _layer(i.target) > _layer(i.module)]


def _unjustified(imports: list[Import]) -> list[str]:
    """Function-level imports that are not a heavy library's (or the entry point's), or that give no reason."""
    bad = []
    for i in imports:
        if not i.in_function:
            continue
        allowed = i.target.split(".")[0] in HEAVY | OPTIONAL or i.module in ENTRY_POINTS
        if not (allowed and i.reason):
            why = "no reason given" if allowed else "a light or magfab module: import it at the top"
            bad.append(f"{i.module}:{i.line} ({i.in_function}) imports {i.target}: {why}")
    return bad


def test_no_import_cycle():
    assert _cycle(_package_imports(PACKAGE)) == []


def test_no_import_cycle_in_the_readout_package():
    """The readout package's own graph (test_no_import_cycle sees it inside magfab's as well)."""
    readout = PACKAGE / "readout"
    assert _cycle(_package_imports(readout)) == []


def test_imports_point_down_the_layers():
    assert _upward(_package_imports(PACKAGE)) == []


def test_function_level_imports_are_heavy_libraries_with_a_reason():
    assert _unjustified(_package_imports(PACKAGE)) == []


def test_the_checks_see_a_planted_cycle_an_upward_import_and_an_unexplained_lazy_import():
    """Negative control: a small synthetic package with each fault once, and the allowed forms beside them."""
    sources = {
        "magfab.design": "import json\n\ndef derive():\n    from .pipeline import plan\n    import re\n",
        "magfab.pipeline": "from .design import derive\n",
        "magfab.models.a": "from . import b\n\ndef f():\n    import scipy.sparse  # lazy: slow to import\n",
        "magfab.models.b": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from ..pipeline import plan\n\n"
                           "def g():\n    from .a import f\n\n\ndef h():\n    import matplotlib\n",
    }
    names = set(sources)
    imports = [i for n, s in sources.items() for i in _graph_imports(n, s, False, names)]
    assert set(_cycle(imports)) in ({"magfab.design", "magfab.pipeline"}, {"magfab.models.a", "magfab.models.b"})
    assert _upward(imports) == ["magfab.design:4 imports magfab.pipeline"]  # the TYPE_CHECKING one is not counted
    bad = _unjustified(imports)
    assert [b.split(" (")[0] for b in bad] == ["magfab.design:4", "magfab.design:5", "magfab.models.b:6",
                                               "magfab.models.b:10"], bad
    assert "no reason given" in bad[-1] and "import it at the top" in bad[0]
    acyclic = [i for i in imports if i.module != "magfab.pipeline" and i.module != "magfab.models.b"]
    assert _cycle(acyclic) == []


def _private_across_packages(name: str, source: str, is_package: bool) -> list[str]:
    """Private names (``_x``) one module imports from a module of another package, or between the top-level
    modules (each its own unit): a subpackage's own helpers are shared among its modules, never with the rest of
    the code (tests may reach them)."""
    package = name if is_package else name.rsplit(".", 1)[0]
    bad = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.ImportFrom):
            continue
        base = package.split(".")[: len(package.split(".")) - node.level + 1] if node.level else []
        source_module = ".".join(base + ([node.module] if node.module else []))
        # where the name lives: ``from . import _m`` names a module of that package, ``from .m import _x`` a name of m
        home = source_module if node.module is None else source_module.rsplit(".", 1)[0]
        for alias in node.names:
            private = alias.name.startswith("_") and not alias.name.startswith("__")
            reexport = is_package and node.module is not None  # an __init__ re-exporting a private name
            if private and (home != package or reexport or (package == "magfab" and node.module is not None)):
                bad.append(f"{name}:{node.lineno} imports {source_module}.{alias.name}")
    return bad


def test_private_names_stay_in_their_package():
    paths = {_name(p): p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts}
    bad = [b for name, p in sorted(paths.items())
           for b in _private_across_packages(name, p.read_text(), p.name == "__init__.py")]
    assert bad == [], "make the name public where it is defined, or keep its use inside the package"


def test_the_private_name_check_sees_a_name_taken_across_packages():
    assert _private_across_packages("magfab.reference_chip", "from .design import _plan\n", False) == [
        "magfab.reference_chip:1 imports magfab.design._plan"]
    assert _private_across_packages("magfab.export.a", "from .figures import _render\n", False) == []
    assert _private_across_packages("magfab.export.x", "from ..design import _plan\n", False) == [
        "magfab.export.x:1 imports magfab.design._plan"]
    assert _private_across_packages("magfab.models.m", "from .mesh import _body as _body\n", True) == [
        "magfab.models.m:1 imports magfab.models.m.mesh._body"]
    assert _private_across_packages("magfab.readout", "from . import _build\n", True) == []
    assert _private_across_packages("magfab.models.a", "from .b import _c\nfrom typing import _T\n", False) == [
        "magfab.models.a:2 imports typing._T"]
