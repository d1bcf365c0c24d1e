"""How the packages lean on each other (issue 28 §2), read from the source: the commands sit on top and
nothing else imports them; the engine's modules import each other without a circle, counting the imports
written inside functions (which hide a circle from Python but not from a reader)."""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ENGINE = ROOT / "engine"


def _imports(path: Path) -> list[tuple[str, int]]:
    """(module named, line) for every import in the file, at any depth: `from .x import` as `.x`,
    `from . import x` as `.x`."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = "." * node.level + (node.module or "")
            if node.module is None:  # from . import x, y: the submodules
                out += [(base + a.name, node.lineno) for a in node.names]
            else:
                out.append((base, node.lineno))
    return out


def test_nothing_outside_the_cli_imports_the_commands() -> None:
    found = []
    for tree in ("tracelab", "engine", "viewers"):
        for path in sorted((ROOT / tree).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel.startswith("tracelab/commands/") or rel == "tracelab/cli.py":
                continue
            found += [f"{rel}:{line} imports {name}" for name, line in _imports(path)
                      if name.startswith("tracelab.commands") or name.startswith("..commands")]
    assert found == []


def _engine_graph() -> dict[str, set[str]]:
    """engine module -> the engine modules it imports (the package's lazy __init__ left out)."""
    names = {p.stem for p in ENGINE.glob("*.py")} - {"__init__"}
    graph: dict[str, set[str]] = {}
    for name in names:
        targets = set()
        for imported, _ in _imports(ENGINE / f"{name}.py"):
            if imported.startswith("tracelab.engine."):
                imported = "." + imported.removeprefix("tracelab.engine.")
            if imported.startswith(".") and not imported.startswith(".."):
                target = imported[1:].split(".")[0]
                if target in names and target != name:
                    targets.add(target)
        graph[name] = targets
    return graph


def _a_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
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

    for start in sorted(graph):
        if start not in state and (cycle := visit(start)):
            return cycle
    return None


def test_the_engine_modules_import_each_other_without_a_circle() -> None:
    graph = _engine_graph()
    assert graph["core"] and graph["parser"]  # the reading found the imports
    assert _a_cycle(graph) is None, " -> ".join(_a_cycle(graph) or [])


def test_the_cycle_finder_finds_one() -> None:
    assert _a_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _a_cycle({"a": {"b"}, "b": set()}) is None
