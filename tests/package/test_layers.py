"""The package's layers: no import cycle between its sub-packages (and top-level modules), counting the
imports inside functions, which Python resolves late and so would let a cycle hide; and no module over
500 lines."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import uareme_fusion

PACKAGE_ROOT = Path(uareme_fusion.__file__).parent
MAX_MODULE_LINES = 500
OVER_THE_LIMIT_FOR_NOW = {
}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE_ROOT.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imported_modules(path: Path, this: str | None = None) -> list[tuple[str, int]]:
    """Every `uareme_fusion...` module that `path` (the module `this`, by default the one at that path)
    imports anywhere (module level, functions, methods, `if` blocks), relative imports resolved, with
    the line number."""
    this = this or _module_name(path)
    package = this.split(".") if path.name == "__init__.py" else this.split(".")[:-1]
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            found += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package[:len(package) - node.level + 1] + ([node.module] if node.module else []))
            # `from . import x` / `from uareme_fusion import x`: x may be a module
            found += [(f"{base}.{alias.name}", node.lineno) for alias in node.names] + [(base, node.lineno)]
    return [(name, line) for name, line in found if name.split(".")[0] == "uareme_fusion"]


def _layer(module: str) -> str | None:
    """The sub-package (`solver`, `pipeline`, ...) or top-level module (`types`, `config`, ...) of
    `module`; None for the package itself and for names that are not modules of it."""
    parts = module.split(".")
    if len(parts) < 2:
        return None
    if (PACKAGE_ROOT / parts[1]).is_dir() or (PACKAGE_ROOT / f"{parts[1]}.py").is_file():
        return parts[1]
    return None


def layer_imports() -> dict[tuple[str, str], list[str]]:
    """(importing layer, imported layer) -> where ("path:line"), for every import across layers."""
    edges = defaultdict(list)
    for path in sorted(PACKAGE_ROOT.rglob("*.py")):
        source = _layer(_module_name(path))
        for name, line in _imported_modules(path):
            target = _layer(name)
            where = f"{path.relative_to(PACKAGE_ROOT)}:{line}"
            if source and target and target != source and where not in edges[(source, target)]:
                edges[(source, target)].append(where)
    return edges


def find_cycle(edges) -> list[str] | None:
    """One cycle of the directed graph `edges` (its nodes in order, the first repeated at the end), or None."""
    graph = defaultdict(set)
    for a, b in edges:
        graph[a].add(b)
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node):
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


def test_no_import_cycle_between_layers():
    edges = layer_imports()
    assert ("pipeline", "solver") in edges  # the reader sees the package's imports at all
    cycle = find_cycle(edges)
    where = [f"{a} -> {b}: {', '.join(edges[(a, b)][:3])}" for a, b in zip(cycle, cycle[1:])] if cycle else []
    assert cycle is None, "import cycle between layers:\n" + "\n".join(where)


def test_cycle_finder_sees_imports_inside_functions(tmp_path):
    """The reader counts an import inside a function body, and the finder reports the cycle it makes."""
    module = tmp_path / "late.py"
    module.write_text("import numpy\n\n\ndef f():\n    from ..evaluation import compare\n    return compare\n")
    found = _imported_modules(module, "uareme_fusion.pipeline.late")
    assert ("uareme_fusion.evaluation.compare", 5) in found and all(name != "numpy" for name, _ in found)
    assert find_cycle({("pipeline", "evaluation"): [], ("evaluation", "pipeline"): []}) in (
        ["evaluation", "pipeline", "evaluation"], ["pipeline", "evaluation", "pipeline"])
    assert find_cycle({("cli", "pipeline"): [], ("pipeline", "solver"): []}) is None


def test_no_module_over_the_line_limit():
    long = {str(p.relative_to(PACKAGE_ROOT)): n for p in PACKAGE_ROOT.rglob("*.py")
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES}
    assert set(long) - set(OVER_THE_LIMIT_FOR_NOW) == set(), f"modules over {MAX_MODULE_LINES} lines: {long}"
