"""Dependencies run one way: each package, imported alone in a fresh
interpreter, pulls in none of the packages above it."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROJECT = ("spacecraft_conventions", "spacecraft_env", "identifiers", "controllers",
           "spacecraft_lab")

#: package -> project packages it must never load.
FORBIDDEN = {
    "spacecraft_conventions": {"spacecraft_env", "identifiers", "controllers", "spacecraft_lab"},
    "spacecraft_env": {"identifiers", "controllers", "spacecraft_lab"},
    "identifiers": {"spacecraft_env", "controllers", "spacecraft_lab"},
    "controllers": {"spacecraft_env", "spacecraft_lab"},
    "spacecraft_lab": set(),
}


def _loaded_after_import(package: str) -> set[str]:
    code = (f"import sys, json; import {package}; "
            "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT)
    return set(json.loads(out.stdout))


@pytest.mark.parametrize("package", PROJECT)
def test_package_imports_nothing_above_it(package):
    loaded = _loaded_after_import(package)
    assert package in loaded
    assert not loaded & FORBIDDEN[package], f"{package} pulled in {loaded & FORBIDDEN[package]}"


def test_application_layer_imports_all_three_libraries():
    loaded = _loaded_after_import("spacecraft_lab.cli")
    assert {"spacecraft_env", "identifiers", "controllers"} <= loaded


def _nested_project_imports(path: Path) -> list[str]:
    """Project imports inside function bodies (how a cycle is usually dodged)."""
    tree = ast.parse(path.read_text())
    found = []
    for func in ast.walk(tree):
        if not isinstance(func, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        for node in ast.walk(func):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            found += [f"{path.relative_to(ROOT)}:{node.lineno} {n}" for n in names
                      if n.split(".")[0] in PROJECT]
    return found


def test_no_function_level_imports_of_project_packages():
    offenders = [hit for pkg in PROJECT for path in (ROOT / pkg).rglob("*.py")
                 for hit in _nested_project_imports(path)]
    assert offenders == []


@pytest.mark.parametrize("package", PROJECT)
def test_every_module_declares_all(package):
    missing = [str(p.relative_to(ROOT)) for p in (ROOT / package).rglob("*.py")
               if p.name != "__main__.py" and "__all__" not in p.read_text()]
    assert missing == []


def test_nothing_points_outside_the_repository():
    """Docs and code cite the repository's own docs/, never a file users lack."""
    patterns = ("DESIGN" + ".md", ".." + "/shared")   # spelled so this file does not match
    texts = [p for p in ROOT.rglob("*") if p.is_file() and p.suffix in (".py", ".md", ".toml",
                                                                          ".cff", ".yaml")
             and not {".venv", ".git", "results"} & set(p.parts)]
    offenders = [str(p.relative_to(ROOT)) for p in texts
                 if any(pat in p.read_text(errors="ignore") for pat in patterns)]
    assert offenders == []


#: The families inside ``identifiers``, lowest first: a module may import its own
#: family and the ones before it, never a later one.
IDENTIFIER_LAYERS = ("identifiers.core", "identifiers.subspace", "identifiers.modal",
                     "identifiers.physical", "identifiers.structured", "identifiers")
#: The structure-aware families: siblings that import core and subspace, never each other.
SIBLINGS = ("identifiers.modal", "identifiers.physical", "identifiers.structured")
#: Longest module the identifiers package holds (lines).
MAX_MODULE_LINES = 400


def _layer(module: str) -> int:
    """Index in :data:`IDENTIFIER_LAYERS` of a module of ``identifiers``."""
    return next(i for i, prefix in enumerate(IDENTIFIER_LAYERS)
                if module == prefix or module.startswith(prefix + "."))


def _identifier_module_imports() -> list[tuple[str, str]]:
    """(importing module, imported module) for every import within ``identifiers``."""
    edges = []
    for path in (ROOT / "identifiers").rglob("*.py"):
        parts = path.relative_to(ROOT).with_suffix("").parts
        module = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module] if isinstance(node, ast.ImportFrom) and node.module else [])
            edges += [(module, n) for n in names if n.split(".")[0] == "identifiers"]
    return edges


def test_identifier_layers_import_only_downward():
    edges = _identifier_module_imports()
    assert any(_layer(b) == 0 for _, b in edges)          # the parse sees the imports
    upward = [f"{a} -> {b}" for a, b in edges if _layer(b) > _layer(a)]
    # the three structure-aware families are siblings: no arrow between them
    upward += [f"{a} -> {b}" for a, b in edges if _layer(a) != _layer(b) and
               {IDENTIFIER_LAYERS[_layer(a)], IDENTIFIER_LAYERS[_layer(b)]} <= set(SIBLINGS)]
    # a subpackage's __init__ re-exports its own layer only
    upward += [f"{a} -> {b}" for a, b in edges if a in IDENTIFIER_LAYERS[:-1] and
               _layer(b) != _layer(a)]
    assert upward == []


def test_no_identifier_module_is_over_the_line_budget():
    long = {str(p.relative_to(ROOT)): n for p in (ROOT / "identifiers").rglob("*.py")
            if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES}
    assert long == {}
