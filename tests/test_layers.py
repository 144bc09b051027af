"""The layer rules of docs/ARCHITECTURE.md: pyproject's import-linter contracts, and what imports cannot show."""

from __future__ import annotations

import ast
import os
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("converter", "webapp")

# What the AST checks let through, as (path relative to the repo, the literal or call found). Empty: every
# module keeps the rules today. An entry is the lead's decision, and a stale one fails the check.
MARKUP_IN_ENCODER_ALLOWED: frozenset[tuple[str, str]] = frozenset()
FILE_CALLS_IN_WRITERS_ALLOWED: frozenset[tuple[str, str]] = frozenset()

# A string that starts a tag or a closing tag: '<path', '<g>', '</g>'; not '<= 3' nor '< 5'.
_TAG = re.compile(r"\s*</?[A-Za-z]")
# Modules whose every use touches the file system.
_FILE_MODULES = frozenset({"tempfile", "shutil"})
_OS_FILE_CALLS = frozenset({"open", "fdopen", "replace", "rename", "remove", "unlink", "makedirs", "mkdir", "rmdir",
                            "write", "truncate", "link", "symlink"})
_OPENING_MODULES = frozenset({"io", "os", "gzip", "bz2", "lzma", "codecs"})
# pathlib's writers and mutators; reading a package's own resource (player.js) is not a user's file.
_PATH_FILE_METHODS = frozenset({"write_bytes", "write_text", "touch", "unlink", "mkdir", "rmdir", "symlink_to",
                                "hardlink_to"})


def lint_imports(root: Path, config: Path) -> tuple[int, dict[str, str]]:
    """Run `lint-imports` on the packages under root: its exit code and each contract's name -> KEPT/BROKEN."""
    env = {**os.environ, "PYTHONPATH": str(root), "COLUMNS": "1000", "NO_COLOR": "1"}
    cmd = [sys.executable, "-c", "from importlinter.cli import lint_imports_command; lint_imports_command()",
           "--config", str(config), "--no-cache"]
    run = subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True, timeout=300)
    states = dict(re.findall(r"^(.+?) (KEPT|BROKEN)\b", run.stdout, re.MULTILINE))
    return run.returncode, states


def contract_names(config: Path) -> dict[str, str]:
    """Id -> name of every contract a pyproject.toml declares."""
    return {c["id"]: c["name"] for c in tomllib.loads(config.read_text())["tool"]["importlinter"]["contracts"]}


def markup_literals(source: str) -> list[tuple[int, str]]:
    """(line, literal) for every string constant of a module that starts with a tag ('<path', '</g>')."""
    return sorted((node.lineno, node.value) for node in ast.walk(ast.parse(source))
                  if isinstance(node, ast.Constant) and isinstance(node.value, str) and _TAG.match(node.value))


def _dotted(node: ast.AST) -> str:
    """'os.replace' for `os.replace`, 'open' for `open`; '' when the callee is not a plain name chain."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        base = _dotted(node.value)
        return f"{base}.{node.attr}" if base else f"?.{node.attr}"
    return ""


def file_calls(source: str) -> list[tuple[int, str]]:
    """(line, what) for every import or call of a module that opens, writes, moves or removes files."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, f"import {a.name}") for a in node.names if a.name.split(".")[0] in _FILE_MODULES]
        elif isinstance(node, ast.ImportFrom) and not node.level:
            module = node.module or ""
            if module in _FILE_MODULES or (module == "os" and {a.name for a in node.names} & _OS_FILE_CALLS):
                found.append((node.lineno, f"from {module} import"))
        elif isinstance(node, ast.Call):
            name = _dotted(node.func)
            head, _, attr = name.rpartition(".")
            if (name == "open" or (head in _OPENING_MODULES and attr == "open")
                    or (head == "os" and attr in _OS_FILE_CALLS) or head.split(".")[0] in _FILE_MODULES
                    or (head and attr in _PATH_FILE_METHODS)):
                found.append((node.lineno, name))
    return sorted(found)


def _findings(package: str, check) -> set[tuple[str, str, int]]:
    """(path, what, line) for every finding of a check over the modules of one package folder."""
    return {(str(p.relative_to(ROOT)), what, line) for p in sorted((ROOT / package).rglob("*.py"))
            for line, what in check(p.read_text())}


def _compare(found: set[tuple[str, str, int]], allowed: frozenset[tuple[str, str]], rule: str) -> None:
    """Fail on a finding not allowed, naming file:line, and on an allowance that no longer matches anything."""
    new = sorted(f"{path}:{line}: {what!r}" for path, what, line in found if (path, what) not in allowed)
    stale = sorted(allowed - {(path, what) for path, what, _ in found})
    assert not new, f"{rule}:\n" + "\n".join(new)
    assert not stale, f"allowances that match nothing any more (remove them): {stale}"


def test_layer_contracts_hold():
    config = ROOT / "pyproject.toml"
    code, states = lint_imports(ROOT, config)
    broken = [name for name, state in states.items() if state == "BROKEN"]
    assert not broken, f"broken layer contracts (run `lint-imports --no-cache` for the imports): {broken}"
    assert set(states) == set(contract_names(config).values()), f"lint-imports did not check every contract: {states}"
    assert code == 0


def test_a_forbidden_import_breaks_its_contract(tmp_path):
    for pkg in PACKAGES:
        shutil.copytree(ROOT / pkg, tmp_path / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    config = tmp_path / "pyproject.toml"
    shutil.copy(ROOT / "pyproject.toml", config)
    keys = tmp_path / "converter" / "encode" / "keys.py"
    keys.write_text(keys.read_text() + "\nfrom lxml import etree  # noqa\n")
    obj = tmp_path / "converter" / "formats" / "obj.py"
    obj.write_text(obj.read_text() + "\nimport converter.writers.svg_anim  # noqa\n")
    code, states = lint_imports(tmp_path, config)
    names = contract_names(config)
    assert code != 0
    assert states[names["encoder"]] == "BROKEN"
    assert states[names["loaders"]] == "BROKEN"
    assert states[names["core-webapp"]] == "KEPT"


def test_encoder_writes_no_markup():
    _compare(_findings("converter/encode", markup_literals), MARKUP_IN_ENCODER_ALLOWED,
             "the encoder returns numbers, the writers spell them: markup in converter/encode")


def test_writers_touch_no_files():
    _compare(_findings("converter/writers", file_calls), FILE_CALLS_IN_WRITERS_ALLOWED,
             "writers return bytes, orchestration writes them: file access in converter/writers")


@pytest.mark.parametrize("source, found", [
    ("x = '<path d=\"M0 0\"/>'", [(1, '<path d="M0 0"/>')]),
    ("x = f'<g transform=\"{t}\">'", [(1, '<g transform="')]),
    ("x = 1\ny = '</g>'", [(2, "</g>")]),
    ("x = '\\n  <svg'", [(1, "\n  <svg")]),
    ("x = 'a < b'\ny = '<= 3'\nz = '< 5'\nw = '<1>'", []),
    ('"""Returns keys, never a <path>."""', []),
])
def test_markup_literals_are_found(source, found):
    assert markup_literals(source) == found


@pytest.mark.parametrize("source, found", [
    ("open(p, 'wb')", [(1, "open")]),
    ("Path(p).write_bytes(b)", [(1, "?.write_bytes")]),
    ("out.write_text(s)", [(1, "out.write_text")]),
    ("import os\nos.replace(a, b)", [(2, "os.replace")]),
    ("import tempfile\nf = tempfile.mkstemp()", [(1, "import tempfile"), (2, "tempfile.mkstemp")]),
    ("from shutil import copy", [(1, "from shutil import")]),
    ("with gzip.open(p) as f: pass", [(1, "gzip.open")]),
    ("s = s.replace('a', 'b')\nq = pos._replace(values=1)\nb = io.BytesIO()", []),
    ("t = resources.files('converter.writers').joinpath('player.js').read_text(encoding='utf-8')", []),
])
def test_file_calls_are_found(source, found):
    assert file_calls(source) == found
