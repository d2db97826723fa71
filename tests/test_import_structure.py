"""The import structure (docs/architecture.md): imports at module top, every module placed in a layer.

``lint-imports`` (in ``make lint``) checks the layers, the cycles and the independence of the contracts in
pyproject.toml on the import graph. What it cannot see is checked here on the source:

* no import inside a function (or under ``if TYPE_CHECKING:``) of a module of the project: such an import hides
  a dependency from the graph, which is how a cycle is dodged; a third-party package may be imported lazily only
  where :data:`LAZY_THIRD_PARTY` says why;
* every module of the three packages is in exactly one layer of the layers contract (a new module the contract does
  not place would otherwise go unchecked), apart from the package modules the forbidden contracts hold.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    tomllib = pytest.importorskip("tomli")

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("spaceid_gym", "estimators", "agents")

#: third-party packages imported inside a function, by module, with the reason: each costs seconds at import and is
#: needed by one estimator or one plot only
LAZY_THIRD_PARTY: dict[tuple[str, str], str] = {
    ("estimators.reference", "cma"): "importing cma takes ~1.5 s; only the cma-es estimator needs it",
    ("estimators.reference", "pyswarms"): "importing pyswarms takes ~0.8 s; only the pyswarms-local estimator needs it",
    ("estimators.evaluation", "matplotlib"): "pyplot (~0.7 s) for the evaluation's plots only, after selecting Agg",
    (
        "spaceid_gym.executors",
        "distributed",
    ): "Dask is an optional extra; only --executor dask needs it, and its absence gives a clear message",
}


def _modules() -> dict[str, Path]:
    """Every module of the project's packages by dotted name (a package by its own name)."""
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def _is_project(module: str | None) -> bool:
    return module is not None and module.split(".")[0] in PACKAGES


def _imported(node: ast.Import | ast.ImportFrom) -> list[str]:
    if isinstance(node, ast.ImportFrom):
        return ["." * node.level + (node.module or "")]
    return [alias.name for alias in node.names]


def _hidden_imports(tree: ast.Module) -> list[tuple[int, str, str]]:
    """``(line, imported module, where)`` of every import inside a function or an ``if TYPE_CHECKING:`` block."""
    found = []

    def visit(node: ast.AST, where: str | None) -> None:
        for child in ast.iter_child_nodes(node):
            inside = where
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                inside = f"function {getattr(child, 'name', 'lambda')}"
            elif isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                inside = "if TYPE_CHECKING"
            if isinstance(child, (ast.Import, ast.ImportFrom)) and inside is not None:
                found.extend((child.lineno, name, inside) for name in _imported(child))
            visit(child, inside)

    visit(tree, None)
    return found


def test_no_import_inside_a_function() -> None:
    problems = []
    for name, path in _modules().items():
        for line, imported, where in _hidden_imports(ast.parse(path.read_text(encoding="utf-8"))):
            relative = imported.startswith(".")
            top = imported.split(".")[0]
            if relative or _is_project(imported):
                problems.append(f"{path.relative_to(ROOT)}:{line}: imports {imported} in {where} (move it to the top)")
            elif (name, top) not in LAZY_THIRD_PARTY:
                problems.append(f"{path.relative_to(ROOT)}:{line}: imports {imported} in {where} (not in LAZY_THIRD_PARTY)")
    assert not problems, "\n".join(problems)


def test_the_allow_list_has_no_stale_entry() -> None:
    used = set()
    for name, path in _modules().items():
        for _, imported, _ in _hidden_imports(ast.parse(path.read_text(encoding="utf-8"))):
            used.add((name, imported.split(".")[0]))
    assert set(LAZY_THIRD_PARTY) <= used, f"entries no module needs: {sorted(set(LAZY_THIRD_PARTY) - used)}"


def test_the_check_finds_a_hidden_import() -> None:
    """The walk sees an import in a nested function and under TYPE_CHECKING, and not one at module top."""
    source = (
        "from typing import TYPE_CHECKING\nimport numpy\nif TYPE_CHECKING:\n    from estimators.problem import X\n"
        "class A:\n    def f(self):\n        def g():\n            import spaceid_gym.log\n"
    )
    found = _hidden_imports(ast.parse(source))
    assert [(line, name) for line, name, _ in found] == [(4, "estimators.problem"), (8, "spaceid_gym.log")]


def _contracts() -> list[dict]:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    return config["tool"]["importlinter"]["contracts"]


def test_every_module_is_in_exactly_one_layer() -> None:
    contracts = {c["id"]: c for c in _contracts()}
    layers = [[part.strip() for part in layer.replace("|", ":").split(":")] for layer in contracts["layers"]["layers"]]
    # the package modules that hold modules of several layers: the forbidden contracts hold what they may import
    held = {m for key in ("core-package-inits", "identification-package-inits") for m in contracts[key]["source_modules"]}
    problems = []
    for name in _modules():
        placed = [i for i, layer in enumerate(layers) for entry in layer if name == entry or name.startswith(entry + ".")]
        if name in held:
            if placed:
                problems.append(f"{name}: a package module held by a forbidden contract, also in layer {placed}")
        elif len(placed) != 1:
            problems.append(f"{name}: in {len(placed)} layers of the layers contract (expected 1): add it to pyproject.toml")
    entries = [entry for layer in layers for entry in layer]
    problems += [f"{entry}: in the layers contract but no such module" for entry in entries if entry not in _modules()]
    assert not problems, "\n".join(problems)
