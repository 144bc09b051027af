"""The import graph of converter/ and webapp/: no cycles, and internal imports only at module top."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("converter", "webapp")


def module_files() -> dict[str, Path]:
    """Dotted module name -> source file, for every module of our packages."""
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = path
    return out


def _resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The longest prefix of a dotted name that is one of our modules."""
    parts = name.split(".")
    while parts:
        cand = ".".join(parts)
        if cand in modules:
            return cand
        parts.pop()
    return None


def imports_of(module: str, path: Path, modules: dict[str, Path]) -> list[tuple[str, int, bool]]:
    """(imported internal module, line, inside a function) for every import statement of a module."""
    tree = ast.parse(path.read_text(), str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            nested = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            names: list[str] = []
            if isinstance(child, ast.Import):
                names = [a.name for a in child.names]
            elif isinstance(child, ast.ImportFrom):
                base = child.module or ""
                if child.level:
                    anchor = package.split(".")[: len(package.split(".")) - child.level + 1]
                    base = ".".join(anchor + ([base] if base else []))
                # `from pkg import sub` imports the submodule when there is one, else pkg itself.
                names = [f"{base}.{a.name}" for a in child.names]
            targets = {_resolve(name, modules) for name in names}
            for target in sorted(t for t in targets if t and t != module):
                found.append((target, child.lineno, in_function))
            if not _is_type_checking_block(child):
                visit(child, nested)

    visit(tree, False)
    return found


def _is_type_checking_block(node: ast.AST) -> bool:
    """`if TYPE_CHECKING:` imports never run, so they make no edge."""
    return isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)


def import_graph() -> tuple[list[str], dict[str, list[tuple[str, int, bool]]]]:
    """Every module and its internal imports."""
    modules = module_files()
    return list(modules), {m: imports_of(m, p, modules) for m, p in modules.items()}


def cycles(names: list[str], edges: dict[str, list[tuple[str, int, bool]]]) -> list[list[str]]:
    """Strongly connected components with more than one module."""
    index = {m: i for i, m in enumerate(names)}
    src, dst = [], []
    for m, targets in edges.items():
        for t, _, _ in targets:
            src.append(index[m])
            dst.append(index[t])
    n = len(names)
    graph = coo_matrix((np.ones(len(src)), (src, dst)), shape=(n, n)).tocsr()
    _, labels = connected_components(graph, directed=True, connection="strong")
    groups: dict[int, list[str]] = {}
    for m, lab in zip(names, labels):
        groups.setdefault(int(lab), []).append(m)
    return sorted(sorted(g) for g in groups.values() if len(g) > 1)


def test_cycle_finder_finds_a_planted_cycle():
    names = ["a", "b", "c", "d"]
    edges = {"a": [("b", 1, False)], "b": [("c", 1, True)], "c": [("a", 1, False)], "d": [("a", 1, False)]}
    assert cycles(names, edges) == [["a", "b", "c"]]
    edges["c"] = []
    assert cycles(names, edges) == []


def test_the_graph_sees_imports_inside_functions(tmp_path, monkeypatch):
    pkg = tmp_path / "converter"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from converter import b\n")
    (pkg / "b.py").write_text("def f():\n    from converter.a import x\n    return x\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    names, edges = import_graph()
    assert ("converter.a", 2, True) in edges["converter.b"]
    assert cycles(names, edges) == [["converter.a", "converter.b"]]


def test_converter_and_webapp_have_no_import_cycles():
    names, edges = import_graph()
    assert len(names) > 40, "the graph found too few modules to be the real packages"
    found = cycles(names, edges)
    assert not found, "import cycles: " + "; ".join(" <-> ".join(c) for c in found)


def test_internal_imports_sit_at_module_top():
    _, edges = import_graph()
    inside = [f"{m}:{line} imports {t}" for m, targets in edges.items() for t, line, fn in targets if fn]
    assert not inside, "imports inside functions (move them to the top):\n" + "\n".join(inside)


if __name__ == "__main__":  # pragma: no cover - a quick report for developers
    names, edges = import_graph()
    print("\n".join(" <-> ".join(c) for c in cycles(names, edges)) or "no cycles")
    pytest.main([__file__, "-q"])


def test_the_command_loads_the_web_app_only_to_serve():
    code = ("import sys, converter.cli; p = converter.cli.build_parser(); "
            "print(sorted(m for m in ('flask', 'webapp.app', 'webapp.runner', 'waitress') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"  # `facesvg convert` builds the whole parser, serve and worker included
    code = "import webapp; print(webapp.create_app.__module__, callable(webapp.create_app))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.stdout.split() == ["webapp.app", "True"], out.stderr  # gunicorn 'webapp:create_app()' still finds it
