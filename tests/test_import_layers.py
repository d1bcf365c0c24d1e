"""How the packages lean on each other (issue 28 §2), read from the source: the commands sit on top and
nothing else imports them; tracelab's modules (the engine's, the viewers' and the rest) import each other
without a circle, counting the imports written inside functions (which hide a circle from Python but not
from a reader); and `tracelab --help` loads none of the heavy packages the commands defer."""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ENGINE = ROOT / "engine"
# the source folders and the packages they are imported as (pyproject's package-dir)
PACKAGES = {"tracelab": ROOT / "tracelab", "tracelab.engine": ENGINE, "tracelab.viewers": ROOT / "viewers"}


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


def _module_files() -> dict[str, Path]:
    """Every module of tracelab by its dotted name (a package by its __init__.py)."""
    out = {}
    for prefix, folder in PACKAGES.items():
        for path in folder.rglob("*.py"):
            parts = list(path.relative_to(folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join([prefix, *parts])] = path
    return out


def _imported_names(path: Path, package: str) -> list[str]:
    """Every name an import of the file gives, absolute, at any depth of the file: `from p import x` as
    p.x (x may be a module; _tree_graph takes p when it is not)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[:len(parts) - (node.level - 1)] + ([base] if base else []))
            out += [f"{base}.{a.name}" for a in node.names]
    return out


def _tree_graph() -> dict[str, set[str]]:
    """tracelab module -> the tracelab modules it imports. A module's parent packages are left out
    (Python runs their __init__ first, but a reader does not follow them there)."""
    files = _module_files()
    graph: dict[str, set[str]] = {}
    for name, path in files.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        targets = set()
        for imported in _imported_names(path, package):
            while imported not in files and "." in imported:  # p.x where x is no module: p
                imported = imported.rpartition(".")[0]
            if imported in files and imported != name:
                targets.add(imported)
        graph[name] = targets
    return graph


def test_tracelab_modules_import_each_other_without_a_circle() -> None:
    graph = _tree_graph()
    assert len(graph) > 250 and "tracelab.viewers.tui.app" in graph["tracelab.viewers.tui"]  # the reading found them
    assert "tracelab.train.experiments.run" in graph["tracelab.train.experiments.report"]
    assert _a_cycle(graph) is None, " -> ".join(_a_cycle(graph) or [])


HEAVY = ("torch", "ray", "pandas", "pyarrow", "duckdb", "rerun", "textual", "matplotlib", "numba",
         "stable_baselines3", "tensorboard", "gymnasium")


def test_the_commands_parser_loads_no_heavy_package() -> None:
    """`tracelab --help` builds every command's parser: the packages a command needs are imported when it
    runs, not when the CLI starts."""
    code = ("import sys; from tracelab.cli import build_parser; build_parser(); "
            f"print(' '.join(m for m in {HEAVY!r} if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.split() == []


def test_the_cycle_finder_finds_one() -> None:
    assert _a_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _a_cycle({"a": {"b"}, "b": set()}) is None


def test_only_the_war_games_registration_and_refsim_name_it() -> None:
    """Issue 38: the war game's code lives in its registration (envs/declared/gridwar*.py) and in RefSim, its
    oracle (tracelab/game/); the generic stack names it nowhere, not even as an example."""
    named = sorted(p.relative_to(ROOT).as_posix() for tree in ("tracelab", "viewers")
                   for p in (ROOT / tree).rglob("*.py") if "GridWar" in p.read_text())
    assert "tracelab/envs/declared/gridwar.py" in named  # the reading found the registration
    assert [f for f in named if not f.startswith(("tracelab/envs/declared/gridwar", "tracelab/game/"))] == []


# the war game's notions a generic module must leave to its registration: its opponent's p, names of the game or
# of RuleSim (its earlier simulator, whose files the registration reads), and the modules of its scenarios, of
# RuleSim's files and of RefSim's game (tracelab.game: the scenario dataclass among them)
WAR_NOTIONS = {"opponent_p", "p_toward"}
WAR_WORDS = ("gridwar", "rulesim")
WAR_MODULES = ("tracelab.envs.declared.gridwar_scenarios", "tracelab.envs.declared.gridwar_runs", "tracelab.game")
# where they may be named: the registration itself (envs/__init__.py registers every world's ids) and RefSim's
# game; the commands and the sweep file's reader (their flags: --scenario, --opponent-p); the benches and the
# method's experiments, which measure and train the war game by name. TrainConfig holds none of its settings
# (they are its spec's params).
MAY_NAME_THE_WAR_GAME = ("tracelab/envs/declared/gridwar", "tracelab/game/", "tracelab/envs/__init__.py",
                         "tracelab/commands/", "tracelab/train/sweep_spec.py", "tracelab/bench/",
                         "tracelab/train/experiments/")


def _war_game_notions(path: Path) -> list[str]:
    """`line: what` for each use of WAR_NOTIONS or a name holding WAR_WORDS (a variable, attribute, parameter,
    keyword, function or class; not in a string) and each import of WAR_MODULES in the file, at any depth."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        names = [node.id] if isinstance(node, ast.Name) else [node.attr] if isinstance(node, ast.Attribute) else \
            [node.arg] if isinstance(node, (ast.arg, ast.keyword)) and node.arg else []
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.append(node.name)
        found += [f"{node.lineno}: {n}" for n in names if n in WAR_NOTIONS or any(w in n.lower() for w in WAR_WORDS)]
        modules = [a.name for a in node.names] if isinstance(node, ast.Import) else \
            [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else []
        found += [f"{node.lineno}: imports {m}" for m in modules if m.startswith(WAR_MODULES)]
    return found


def test_the_generic_modules_leave_the_war_games_notions_to_its_registration() -> None:
    """Issue 38: checkpoints, evaluations, reward terms, sweeps and the rest ask a world's registration
    (tracelab/world_extras.py) instead of naming the war game's opponent, scenarios or RuleSim's files."""
    assert _war_game_notions(ROOT / "tracelab" / "envs" / "declared" / "gridwar_scenarios.py")  # the reading finds them
    found = [f"{p.relative_to(ROOT).as_posix()}:{use}" for tree in ("tracelab", "viewers", "engine")
             for p in sorted((ROOT / tree).rglob("*.py"))
             if not p.relative_to(ROOT).as_posix().startswith(MAY_NAME_THE_WAR_GAME) for use in _war_game_notions(p)]
    assert found == []
