"""The package's layering: no module imports a module of a higher floor, and no import cycle.

Floors (issue 9): errors/vocab/units/progress/stopping/jit/pages and the package root = 0,
device = 1, io/stats = 2, recording/model = 3, analysis = 4, report = 5, testing = 5.5 (may import
anything below the API), api/cli/__main__ = 6.  Every import statement counts, also those inside
functions and under ``if TYPE_CHECKING:`` (a deferred import is still a dependency), except
the package root's lazy re-exports of the public API.  Every
module is also imported, so that a module the walk misses cannot hide.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

import imupipe

ROOT = Path(imupipe.__file__).parent
FLOORS = {
    "imupipe": 0,
    "errors": 0,
    "vocab": 0,
    "units": 0,
    "progress": 0,
    "escape": 0,
    "stopping": 0,
    "jit": 0,
    "pages": 0,
    "schemas": 0,
    "device": 1,
    "io": 2,
    "stats": 2,
    "recording": 3,
    "model": 3,
    "analysis": 4,
    "report": 5,
    "testing": 5.5,
    "fleet": 5.7,
    "api": 6,
    "cli": 6,
    "__main__": 6,
}


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(("imupipe", *parts))


def floor(module: str) -> float:
    parts = module.split(".")
    return FLOORS[parts[1]] if len(parts) > 1 else FLOORS["imupipe"]


def imported(path: Path, name: str) -> set[str]:
    """The imupipe modules ``path`` (module ``name``) imports, resolved to module names."""
    out: set[str] = set()
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.split(".")[0] == "imupipe")
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            if base.split(".")[0] != "imupipe":
                continue
            for alias in node.names:  # `from imupipe.io import decode` names a module
                sub = f"{base}.{alias.name}"
                out.add(sub if sub in MODULES else base)
    out.discard(name)
    return out


MODULES = {module_name(p): p for p in sorted(ROOT.rglob("*.py"))}
GRAPH = {name: imported(path, name) for name, path in MODULES.items()}
GRAPH["imupipe"] = set()  # the root re-exports the API lazily (PEP 562: importlib on first use;
# its imports are under TYPE_CHECKING only), so that `from imupipe import __version__` is light


@pytest.mark.parametrize("name", sorted(MODULES))
def test_module_imports_and_respects_floors(name: str) -> None:
    if name != "imupipe.__main__":  # running it would start the command line
        importlib.import_module(name)
    higher = sorted(m for m in GRAPH[name] if floor(m) > floor(name))
    assert not higher, f"{name} (floor {floor(name)}) imports higher floors: {higher}"


def test_no_import_cycle() -> None:
    state: dict[str, int] = {}  # 1: on the current path, 2: done

    def visit(name: str, path: list[str]) -> None:
        state[name] = 1
        for dep in sorted(GRAPH.get(name, ())):
            if dep not in GRAPH:  # a package's __init__ that is no module file of ours
                continue
            assert state.get(dep) != 1, "import cycle: " + " -> ".join([*path, name, dep])
            if dep not in state:
                visit(dep, [*path, name])
        state[name] = 2

    for name in sorted(GRAPH):
        if name not in state:
            visit(name, [])


def test_the_floor_check_sees_a_violation(tmp_path: Path) -> None:
    """The walk resolves absolute, relative and deferred imports (so the tests above can fail)."""
    module = ROOT / "stats" / "allan.py"
    source = tmp_path / "x.py"
    source.write_text(
        "def f():\n    from imupipe.report import report\n    from ..analysis import condition\n"
    )
    found = imported(source, "imupipe.stats.x")
    assert found == {"imupipe.report.report", "imupipe.analysis.condition"}
    assert module.exists()


TESTS = Path(__file__).resolve().parent


def test_tests_mirror_the_package_tree_and_share_fixtures_not_imports() -> None:
    """tests/<stage>/ exists only for a sub-package of imupipe; builders shared by several test
    files are conftest fixtures, so no test module imports another."""
    stages = {p.name for p in ROOT.iterdir() if (p / "__init__.py").exists()}
    folders = {p.name for p in TESTS.iterdir() if p.is_dir() and any(p.glob("test_*.py"))}
    assert folders <= stages, folders - stages
    assert {"stats", "model", "io", "analysis", "report"} <= folders
    for path in TESTS.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            bad = [n for n in names if n.split(".")[0].startswith(("test_", "conftest", "tests"))]
            assert not bad, f"{path.relative_to(TESTS)} imports {bad}"


def test_the_command_line_does_not_import_what_an_analysis_rarely_needs() -> None:
    """scipy.signal (~0.9 s with what it pulls in; only a prefilter's or a spread line's Welch
    check needs it) and rerun-sdk (only when recording.rrd is written) are imported on use."""
    import subprocess
    import sys

    code = (
        "import sys, imupipe.cli, imupipe.analysis.analyze; "
        "print(sorted(m for m in ('scipy.signal', 'rerun') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_the_command_line_imports_the_analysis_only_for_a_command_that_runs_it() -> None:
    """``imupipe --help``, ``view`` and ``export`` need typer and the export formats: importing
    a submodule of ``imupipe.report`` or ``imupipe.analysis`` does not pull in the analysis
    (numba, polars; ~0.9 s, the command's 1.06 s → 0.37 s in session 25)."""
    import subprocess
    import sys

    code = (
        "import sys, imupipe.cli; heavy = ('numba', 'polars', 'imupipe.analysis.analyze'); "
        "print(sorted(m for m in heavy if m in sys.modules)); "
        "import imupipe.analysis.results; print(sorted(m for m in heavy if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.splitlines() == ["[]", "['polars']"]  # a result's frames are polars ones
