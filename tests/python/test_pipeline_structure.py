"""The pipeline's shape (issue 31): pipeline/simbake flows one way and shares only public names.

- no import cycle among the package's modules, counting imports inside functions too (a lazy
  import still ties the two modules together: it only moves the failure to run time);
- no module imports another module's leading-underscore name (``from .x import _y`` or
  ``x._y``): a helper two modules share lives in one module under a public name. The compiled
  extension ``simbake._core`` is private to the package, not to a module: every module may
  import it;
- no function longer than 100 lines;
- tests and benchmarks share code through modules they import normally (the package
  `benchmarks`, simbake itself), never by putting another folder on `sys.path`: a test edits
  no `sys.path`, and a benchmark script only adds its own folder (a peer engine's Python,
  Blender's for one, does not put a script's folder on its path).

The modules are read as source with `ast`, never imported. Each check runs first on a small
package written here with the fault in it, so a checker that finds nothing cannot pass.
"""

from __future__ import annotations

import ast
import textwrap
from pathlib import Path

import pytest

from conftest import REPO

PACKAGE = REPO / "pipeline" / "simbake"
EXTENSION = "_core"          # the compiled extension: a module of the package, not a .py file
LONGEST_FUNCTION = 100       # lines, decorators and docstring included


def _modules(package: Path) -> dict[str, ast.Module]:
    return {p.stem: ast.parse(p.read_text(), str(p)) for p in sorted(package.glob("*.py"))}


def _imports(tree: ast.Module, modules: set[str]):
    """(line, imported module, imported name or None) for every import of the package's own
    modules anywhere in `tree`; a name taken from the package itself (``from . import
    __version__``) is an import of ``__init__``."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                if parts[0] == "simbake":
                    yield node.lineno, parts[1] if len(parts) > 1 else "__init__", None
        elif isinstance(node, ast.ImportFrom):
            if node.level > 1:
                raise AssertionError(f"line {node.lineno}: an import from above the package")
            if node.level == 1:
                path = (node.module or "").split(".") if node.module else []
            elif (node.module or "").split(".")[0] == "simbake":
                path = node.module.split(".")[1:]
            else:
                continue
            if path:
                for alias in node.names:
                    yield node.lineno, path[0], alias.name
            else:  # from . import a, b: submodules, or names defined in __init__
                for alias in node.names:
                    if alias.name in modules or alias.name == EXTENSION:
                        yield node.lineno, alias.name, None
                    else:
                        yield node.lineno, "__init__", alias.name


def import_graph(package: Path) -> dict[str, set[str]]:
    trees = _modules(package)
    graph = {name: set() for name in trees}
    for name, tree in trees.items():
        for _, target, _ in _imports(tree, set(trees)):
            if target in trees and target != name:
                graph[name].add(target)
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of `graph` (its modules in import order, the first again at the end), or None."""
    state: dict[str, str] = {}
    path: list[str] = []

    def visit(module: str) -> list[str] | None:
        state[module] = "open"
        path.append(module)
        for target in sorted(graph[module]):
            if state.get(target) == "open":
                return path[path.index(target):] + [target]
            if target not in state and (cycle := visit(target)):
                return cycle
        path.pop()
        state[module] = "done"
        return None

    for module in sorted(graph):
        if module not in state and (cycle := visit(module)):
            return cycle
    return None


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def private_imports(package: Path) -> list[str]:
    """Every use of another module's leading-underscore name: imported by name, or read as an
    attribute of an imported module."""
    trees = _modules(package)
    found = []
    for name, tree in trees.items():
        module_names = {}  # local name -> the package's module it is bound to
        for line, target, imported in _imports(tree, set(trees)):
            if target == EXTENSION or target == name:
                continue
            if imported is not None and _private(imported):
                found.append(f"{name}.py:{line}: {imported} from {target}")
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level == 1 and not node.module:
                module_names.update({a.asname or a.name: a.name for a in node.names if a.name in trees})
            elif isinstance(node, ast.Import):
                module_names.update({a.asname: a.name.split(".")[1] for a in node.names
                                     if a.asname and a.name.startswith("simbake.")})
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in module_names and _private(node.attr)):
                found.append(f"{name}.py:{node.lineno}: {node.value.id}.{node.attr}")
    return found


def long_functions(folder: Path, longest: int = LONGEST_FUNCTION) -> list[str]:
    found = []
    for path in sorted(folder.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                first = min([node.lineno] + [d.lineno for d in node.decorator_list])
                lines = node.end_lineno - first + 1
                if lines > longest:
                    found.append(f"{path.relative_to(folder)}:{first}: {node.name}, {lines} lines")
    return found


@pytest.fixture
def faulty_package(tmp_path):
    """A package with a lazy import cycle, private imports (by name and by attribute) and a
    101-line function."""
    files = {
        "__init__.py": "from .a import run\n",
        "a.py": """
            from . import _core
            from .b import _helper
            def run():
                from . import c
                return c._secret
        """,
        "b.py": "def _helper():\n    pass\n",
        "c.py": """
            _secret = 1
            def later():
                from .a import run
                return run
        """,
        "d.py": "def long():\n" + "    x = 1\n" * 100,
    }
    for name, text in files.items():
        (tmp_path / name).write_text(textwrap.dedent(text))
    return tmp_path


def test_the_checks_find_the_faults_of_a_small_package(faulty_package):
    assert find_cycle(import_graph(faulty_package)) == ["a", "c", "a"]
    assert private_imports(faulty_package) == ["a.py:3: _helper from b", "a.py:6: c._secret"]
    assert long_functions(faulty_package) == ["d.py:1: long, 101 lines"]
    assert long_functions(faulty_package, longest=101) == []


def test_the_pipeline_has_no_import_cycle():
    graph = import_graph(PACKAGE)
    assert len(graph) > 30 and "scene" in graph["usd_scene"]  # the package was read
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_no_module_uses_another_modules_private_names():
    assert private_imports(PACKAGE) == []


def test_no_pipeline_function_is_over_100_lines():
    assert long_functions(REPO / "pipeline") == []


# how a script names its own folder
OWN_FOLDER = {"os.path.dirname(os.path.abspath(__file__))", "str(Path(__file__).resolve().parent)", "str(HERE)"}


def path_edits(folder: Path, pattern: str) -> list[str]:
    """Every sys.path.insert / append / extend / assignment in the files `pattern` below
    `folder` that adds anything but the file's own folder (`HERE` must be that folder too)."""
    found = []
    for path in sorted(folder.glob(pattern)):
        if any(part.startswith(".venv") for part in path.relative_to(folder).parts):
            continue  # (the peers' virtual environments, gitignored: not ours)
        tree = ast.parse(path.read_text(), str(path))
        here = [ast.unparse(n.value) for n in ast.walk(tree) if isinstance(n, ast.Assign)
                and any(isinstance(t, ast.Name) and t.id == "HERE" for t in n.targets)]
        own = OWN_FOLDER if here in ([], ["Path(__file__).resolve().parent"]) else OWN_FOLDER - {"str(HERE)"}
        edits = []
        for node in ast.walk(tree):
            target = None
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
                if ast.unparse(node.func.value) == "sys.path" and node.func.attr in ("insert", "append", "extend"):
                    target = ast.unparse(node.args[-1]) if node.args else ""
            elif isinstance(node, (ast.Assign, ast.AugAssign)):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                if any(ast.unparse(t).startswith("sys.path") for t in targets):
                    target = ast.unparse(node.value)
            if target is not None and target not in own:
                edits.append((node.lineno, target))
        found += [f"{path.relative_to(folder)}:{line}: {target}" for line, target in sorted(edits)]
    return found


def test_the_path_check_finds_other_folders(tmp_path):
    (tmp_path / "own.py").write_text("import os, sys\nsys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))\n")
    (tmp_path / "here.py").write_text("import sys\nfrom pathlib import Path\nHERE = Path(__file__).resolve().parent\n"
                                      "sys.path.insert(0, str(HERE))\n")
    (tmp_path / "up.py").write_text("import sys\nfrom pathlib import Path\nHERE = Path(__file__).resolve().parents[1]\n"
                                    "sys.path.insert(0, str(HERE))\nsys.path += ['x']\n")
    assert path_edits(tmp_path, "*.py") == ["up.py:4: str(HERE)", "up.py:5: ['x']"]
    assert path_edits(tmp_path, "own.py") == []


def test_tests_and_benchmarks_put_no_other_folder_on_sys_path():
    assert path_edits(REPO / "tests" / "python", "*.py") == []
    assert path_edits(REPO / "benchmarks", "**/*.py") == []
