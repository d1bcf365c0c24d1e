"""An environment spec (a TOML file beside a rule program, docs/worlds.md) read into a `WorldSpec`.

`load_spec(path, **params)` reads the file (spec_file), computes every expression with the params
(expressions), builds the board's facts (board), loads the rule files, and checks every atom the spec
names against the program: a predicate it lacks or uses with another arity, or a constant that is neither
the program's, a board cell nor an agent, is a located error (`SpecError`: file:line: key: what was
expected). Nothing here steps an engine; world.py does."""
from __future__ import annotations

import ast
import dataclasses
import itertools
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from tracelab.engine.errors import ProgramError
from tracelab.engine.parser import check_program, load_program, parse_literal
from tracelab.engine.safe_files import FileRefused, path_inside
from tracelab.engine.program import CONSTANT_RE, Fact, Literal, Program, SourceLoc, Term
from tracelab.board import CELL_FORMAT, MAX_BOARD_CELLS, MAX_BOARD_FACTS, MAX_PIECE_KINDS, Board, Pieces, hex_color
from tracelab.expressions import ExpressionError, evaluate
from tracelab.envs.declared.spec_file import KeyPath, SpecError, SpecSource, read_spec_file
from tracelab.errors import close_names
from tracelab.envs.declared.spec_repeat import expand_spec
from tracelab.envs.declared.spec_size import SpecBudget, SpecTooBig

READS = ("index", "lower", "bounds", "onehot", "count", "nearest")
SPACES = ("Discrete", "MultiDiscrete", "Box", "Dict")
SECTIONS = ("env", "params", "data", "board", "agents", "actions", "observation", "reward", "end", "start",
            "random", "clock", "nearest")
AGENT_VAR, ACTION_VAR, THING_VAR = "Agent", "Action", "Thing"
MAX_DOMAIN = 100_000  # values of one `over` (or of a product of them), atoms of one observation part


@dataclass(frozen=True)
class Atom:
    """A ground atom the spec names, with the bound a fact sets (reads ignore it)."""
    pred: str
    args: tuple[str, ...]
    lower: float = 1.0
    upper: float = 1.0

    def __str__(self) -> str:
        return f"{self.pred}({','.join(self.args)})"


@dataclass(frozen=True)
class ObservationPart:
    name: str
    read: str  # one of READS
    per_agent: tuple[tuple[Atom, ...], ...]  # [agent] -> the atoms read, in the part's order
    # an index part of a Box or Dict: the number reported for each atom (its index when None) and for
    # none true (an error when None)
    values: tuple[float, ...] | None = None
    missing: float | None = None
    # a nearest part: per_agent holds the `from` atoms over the board's cells, then each thing's over them
    n_things: int = 0
    board_width: int = 0

    @property
    def atoms(self) -> tuple[Atom, ...]:
        """The first agent's atoms (every agent reads as many)."""
        return self.per_agent[0]

    @property
    def width(self) -> int:
        """Numbers this part puts in a Box (an index is one number)."""
        return {"index": 1, "lower": len(self.atoms), "bounds": 2 * len(self.atoms),
                "onehot": len(self.atoms), "count": 1, "nearest": 1}[self.read]

    @cached_property
    def value_array(self) -> np.ndarray | None:
        """`values` as float32, made once (an observation reads it every step)."""
        return None if self.values is None else np.asarray(self.values, np.float32)

    @property
    def is_discrete(self) -> bool:
        """An index without numbers of its own: a Dict's Discrete entry."""
        return self.read == "index" and self.values is None and self.missing is None

    @property
    def low_high(self) -> tuple[float, float]:
        """The least and greatest number the part reports (a Box's bounds)."""
        if self.read == "count":
            return 0.0, float(len(self.atoms))
        if self.read not in ("index", "nearest"):
            return 0.0, 1.0
        cells = len(self.atoms) // (1 + self.n_things)  # an index part: its atoms; nearest: the board's cells
        numbers = list(self.values) if self.values is not None else [0.0, cells - 1.0]
        if self.missing is not None:
            numbers.append(self.missing)
        return min(numbers), max(numbers)


@dataclass(frozen=True)
class Draw:
    """One draw from the env's np_random: value i sets the atoms `atoms[i]` (one per pattern).
    `method` "categorical" is gymnasium's categorical_sample over `probabilities` (fixed), or over the
    values whose `weights[i]` atoms are all true, equally likely (read when drawn); "choice" is
    np_random.choice over the values whose weights hold. `after`: a random fact drawn after the step,
    only when that atom is true then (applied by one more engine step)."""
    key: KeyPath
    name: str  # `name`, or the first atom's predicate: how records of the draws (traces) call it
    atoms: tuple[tuple[Atom, ...], ...]
    probabilities: np.ndarray | None
    weights: tuple[tuple[Atom, ...], ...] | None = None
    method: str = "categorical"
    after: Atom | None = None


@dataclass(frozen=True)
class Clock:
    """`[[clock]]`: facts set for the steps k of an episode (0: the first step after reset) with
    k % every == at, and [0,0] on the others (a step fact, as an action's)."""
    key: KeyPath
    atoms: tuple[Atom, ...]
    every: int
    at: int


@dataclass(frozen=True)
class NearestFacts:
    """`[[nearest]]`: for each of `who`, the fact atoms[who][thing] of its nearest thing, set for each
    step from the state the step starts from (none when no thing qualifies). `where` holds, over the
    board's cells, each who's atoms then each thing's (where it is); `lines`: only things straight
    along one of these (row, col) steps count, a tie going to the line listed first (the same cell
    counts as the first line); without lines every thing counts. Distance: rows plus columns; a tie
    left goes to the thing listed first."""
    key: KeyPath
    atoms: tuple[tuple[Atom, ...], ...]
    where: tuple[Atom, ...]
    n_who: int
    n_things: int
    board_width: int
    lines: tuple[tuple[int, int], ...] | None


@dataclass
class WorldSpec:
    path: str
    params: dict[str, Any]
    program: Program  # the rule files' program with the board's facts
    agents: tuple[str, ...]
    action_names: tuple[str, ...]
    action_facts: tuple[tuple[tuple[Atom, ...], ...], ...]  # [agent][action] -> facts for the step
    mask: tuple[tuple[Atom, ...], ...] | None  # [agent][action] -> the atom that allows it
    space: str
    parts: tuple[ObservationPart, ...]
    reward_table: tuple[tuple[tuple[Atom, float], ...], ...]  # [agent] -> (atom, value)
    reward_scaled: tuple[tuple[tuple[Atom, float], ...], ...]  # [agent] -> (atom, scale)
    terminated: tuple[Atom, ...]  # every agent's, together: the episode ends for all at once
    truncated: tuple[Atom, ...]
    max_steps: int | None
    start_facts: tuple[Atom, ...]
    start_choices: tuple[Draw, ...]
    random_facts: tuple[Draw, ...]
    board: Board | None
    render_fps: int
    source: SpecSource = field(repr=False)
    # the board's facts and the atoms the spec names, every agent's: the fewest atoms its engine has
    # (what a batch of worlds is estimated from, spec_size.check_worlds)
    named_atoms: int = 0
    # the names of the reward's terms, as each agent's reward_table then reward_scaled entries are
    # recorded (tracelab.store.agent_rows): the [reward.table] keys, then the scaled atom
    reward_terms: tuple[str, ...] = ()
    # what a game's end counts as (`[end] win`, `loss`): an episode that terminated with one of them [1,1]
    win: tuple[Atom, ...] = ()
    loss: tuple[Atom, ...] = ()
    # `[observation] previous`: the observations of that many earlier steps follow the current one
    # (history.py; at a reset every one of them is the start's)
    previous: int = 0
    clocks: tuple[Clock, ...] = ()
    nearest_facts: tuple[NearestFacts, ...] = ()
    # `[agents] decides`, `alive` (per agent, or empty): whether an agent chooses its action this step, and
    # whether it still plays (a trainer's transitions: env_trainer.py, "Several agents a team")
    decides: tuple[Atom, ...] = ()
    alive: tuple[Atom, ...] = ()
    # `[agents] script`: [agent][action] -> the atom naming that action as the world's scripted choice (what
    # a trainer's --explore-scripted explores with), or None
    script: tuple[tuple[Atom, ...], ...] | None = None


# ---- reading typed values, located ----

class _Reader:
    """Typed access to the spec's values: each mistake a SpecError at the key's line."""

    def __init__(self, src: SpecSource, names: dict[str, Any]) -> None:
        self.src = src
        self.names = names  # params and data, for expressions
        self.budget = SpecBudget()  # what the spec builds, charged before it is built

    def err(self, path: KeyPath, msg: str) -> SpecError:
        return self.src.error(path, msg)

    def charge(self, path: KeyPath, atoms: int, agents: int = 1) -> None:
        """Charge the atoms a key is about to ground (`atoms` for each of `agents`) to the spec's budget."""
        try:
            self.budget.charge(atoms * agents, _atoms_for(atoms, agents))
        except SpecTooBig as e:
            raise self.err(path, str(e)) from None

    def budget_ahead(self, path: KeyPath, n: int, what: str) -> None:
        """Refuse now if `n` more atoms, about to be made from the text, would pass the budget."""
        try:
            self.budget.ahead(n, f"{n:,} {what}")
        except SpecTooBig as e:
            raise self.err(path, str(e)) from None

    def raw(self, path: KeyPath, default: Any = ...) -> Any:
        node: Any = self.src.data
        for p in path:
            if isinstance(node, dict) and isinstance(p, str) and p in node:
                node = node[p]
            elif isinstance(node, list) and isinstance(p, int) and p < len(node):
                node = node[p]
            else:
                if default is ...:
                    raise self.err(path, "missing (required)")
                return default
        return node

    def value(self, path: KeyPath, default: Any = ..., *, expr: bool = True) -> Any:
        """The value at path; a string where a number, boolean or list is expected is an expression."""
        v = self.raw(path, default)
        if expr and isinstance(v, str) and v is not default:
            try:
                return evaluate(v, self.names)
            except ExpressionError as e:
                raise self.err(path, str(e)) from None
        return v

    def table(self, path: KeyPath, allowed: tuple[str, ...] | None = None, default: Any = ...) -> dict[str, Any]:
        v = self.raw(path, default)
        if not isinstance(v, dict):
            raise self.err(path, f"expected a table, got {_kind(v)}")
        if allowed is not None:
            for k in v:
                if k not in allowed:
                    raise self.err((*path, k), f"unknown key (expected one of: {', '.join(allowed)})")
        return v

    def string(self, path: KeyPath, default: Any = ..., choices: tuple[str, ...] | None = None) -> str:
        v = self.raw(path, default)
        if not isinstance(v, str):
            raise self.err(path, f"expected a string, got {_kind(v)}")
        if choices is not None and v not in choices:
            raise self.err(path, f"expected one of {', '.join(choices)}, got {v!r}")
        return v

    def number(self, path: KeyPath, default: Any = ...) -> float:
        v = self.value(path, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise self.err(path, f"expected a finite number, got {_kind(v)}")
        return float(v)

    def integer(self, path: KeyPath, default: Any = ..., minimum: int = 0) -> int:
        v = self.value(path, default)
        if v is None and default is None:
            return None  # type: ignore[return-value]
        if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
            raise self.err(path, f"expected an integer >= {minimum}, got {_kind(v)}")
        return v

    def strings(self, path: KeyPath, default: Any = ...) -> list[str]:
        v = self.value(path, default)
        if not isinstance(v, list) or not all(isinstance(s, str) for s in v):
            raise self.err(path, f"expected a list of strings, got {_kind(v)}")
        return v

    def numbers(self, path: KeyPath, n: int) -> np.ndarray:
        v = self.value(path)
        if not isinstance(v, list) or len(v) != n or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
            raise self.err(path, f"expected a list of {n} numbers, got {_kind(v)}")
        p = np.asarray(v, np.float64)
        if not np.isfinite(p).all() or (p < 0).any() or p.sum() <= 0:
            raise self.err(path, "expected probabilities >= 0 with a positive sum")
        return p


def _atoms_for(atoms: int, agents: int) -> str:
    return f"{atoms:,} atoms" + (f" for each of {agents:,} agents" if agents > 1 else "")


def _kind(v: Any) -> str:
    if isinstance(v, str):
        return f"the string {v[:40]!r}"
    if isinstance(v, bool):
        return f"the boolean {str(v).lower()}"
    if isinstance(v, (int, float)):
        return f"the number {v}"
    if isinstance(v, list):
        return f"a list of {len(v)}"
    if isinstance(v, dict):
        return "a table"
    return "nothing" if v is None else type(v).__name__


# ---- atoms, checked against the program ----

class _Names:
    """The program's predicates (with arity) and constants, the board's cells and the agents: what an
    atom in the spec may name."""

    def __init__(self, reader: _Reader, program: Program, extra_constants: list[str]) -> None:
        self.r = reader
        self.arity: dict[str, int] = {}
        for item in [*program.rules, *program.facts]:
            lits = (item.literal,) if isinstance(item, Fact) else (item.head, *item.body)
            for lit in lits:
                self.arity.setdefault(lit.pred, len(lit.args))
        self.constants = set(program.constants()) | set(extra_constants)
        # a pattern is grounded for every agent: parsed and checked once (its first use raises any error)
        self._checked: dict[tuple[str, tuple[str, ...], bool], Literal] = {}

    def pattern(self, path: KeyPath, text: Any, variables: tuple[str, ...], *, bounds: bool = False) -> Literal:
        """A literal whose variables are among `variables`, naming the program's predicates."""
        key = (text, variables, bounds) if isinstance(text, str) else None
        if key in self._checked:
            return self._checked[key]
        lit = self._check_pattern(path, text, variables, bounds=bounds)
        self._checked[key] = lit  # type: ignore[index]
        return lit

    def _check_pattern(self, path: KeyPath, text: Any, variables: tuple[str, ...], *, bounds: bool) -> Literal:
        if not isinstance(text, str):
            raise self.r.err(path, f"expected an atom such as \"p(a)\", got {_kind(text)}")
        try:
            lit = parse_literal(text)
        except ProgramError as e:
            raise self.r.err(path, f"{text!r} is not an atom: {e.message}") from None
        if lit.negated:
            raise self.r.err(path, f"{text!r}: '~' is not allowed here")
        if not bounds and (lit.lower, lit.upper) != (1.0, 1.0):
            raise self.r.err(path, f"{text!r}: a bound is not allowed here (an atom is read, not set)")
        if lit.pred not in self.arity:
            raise self.r.err(path, f"{text!r}: the program has no predicate {lit.pred!r}")
        if self.arity[lit.pred] != len(lit.args):
            raise self.r.err(path, f"{text!r}: {lit.pred} takes {self.arity[lit.pred]} argument(s) in the "
                                   f"program, not {len(lit.args)}")
        for a in lit.args:
            if a.is_var and a.name not in variables:
                allowed = f"only {', '.join(variables)}" if variables else "none: the atom must be ground"
                raise self.r.err(path, f"{text!r}: variable {a.name} is not allowed here ({allowed})")
            if not a.is_var:
                self.constant(path, a.name, f"{text!r}: ")
        return lit

    def constant(self, path: KeyPath, name: str, context: str = "") -> None:
        """A constant the spec names (in an atom, a domain, `things`): the program's, a board cell, an
        agent or one of [env] constants; otherwise an error with the closest ones."""
        if name not in self.constants:
            near = close_names(name, sorted(self.constants))
            hint = f"; did you mean {', '.join(near)}?" if near else ""
            raise self.r.err(path, f"{context}the program, the board and the agents have no constant "
                                   f"{name!r}{hint}")

    def ground(self, lit: Literal, values: Mapping[str, str]) -> Atom:
        return Atom(lit.pred, tuple(values[a.name] if a.is_var else a.name for a in lit.args), lit.lower, lit.upper)

    def atoms(self, path: KeyPath, texts: list[Any], values: Mapping[str, str], *, bounds: bool = False
              ) -> tuple[Atom, ...]:
        return tuple(self.ground(self.pattern((*path, i), t, tuple(values), bounds=bounds), values)
                     for i, t in enumerate(texts))

    def over(self, path: KeyPath, pattern: Any, domain: list[str], agent: str) -> tuple[Atom, ...]:
        """A pattern with one variable besides `Agent`, grounded over the domain in order."""
        lit = self.pattern(path, pattern, tuple(a.name for a in _vars(pattern)))
        names = {a.name for a in lit.args if a.is_var} - {AGENT_VAR}
        if len(names) != 1:
            raise self.r.err(path, f"{pattern!r}: expected exactly one variable besides {AGENT_VAR} (it ranges "
                                   "over `over`)")
        var = names.pop()
        return tuple(self.ground(lit, {var: v, AGENT_VAR: agent}) for v in domain)

    def domain(self, path: KeyPath, values: list[str]) -> None:
        """Every value of an `over` is a constant an atom can take (a typo would leave an atom never true)."""
        for i, v in enumerate(values):
            self.constant((*path, i), v)


def _vars(text: Any) -> list[Term]:
    """The variables of an atom's text (none for a text that is not an atom: pattern() says why)."""
    if not isinstance(text, str):
        return []
    try:
        return [a for a in parse_literal(text).args if a.is_var]
    except ProgramError:
        return []


# ---- the sections ----

def load_spec(path: str | os.PathLike[str], **params: Any) -> WorldSpec:
    """Read and check the spec at `path` with `params` overriding its [params] defaults."""
    src = read_spec_file(path)
    for k in src.data:
        if k not in SECTIONS:
            raise src.error((k,), f"unknown section (expected one of: {', '.join(SECTIONS)})")
    base = _Reader(src, {})
    defaults = base.table(("params",), default={})
    for k in params:
        if k not in defaults:
            known = ", ".join(defaults) or "none"
            raise SpecError(f"{src.path}: unknown keyword argument {k!r} (the spec's [params]: {known})")
    data = base.table(("data",), default={})
    clash = set(data) & set(defaults)
    if clash:
        raise src.error(("data", sorted(clash)[0]), "a name in both [data] and [params]")
    names = {**data, **defaults, **{k: _plain(v) for k, v in params.items()}}
    r = _Reader(src, names)
    _require(r)  # before anything is generated from the params
    r.src = src = expand_spec(src, names, lambda path, n: r.budget_ahead(path, n, "generated values"))

    r.table(("env",), ("rules", "render_fps", "constants", "require"))
    rule_files = [_inside(r, ("env", "rules", i), f) for i, f in enumerate(r.strings(("env", "rules")))]
    if not rule_files:
        raise r.err(("env", "rules"), "expected at least one rule file")
    board = _board(r) if "board" in src.data else None
    rules = _load_rules(r, rule_files)

    agents_t = r.table(("agents",), ("names", "mask", "decides", "alive", "script"))
    agents = r.strings(("agents", "names"))
    if not agents or len(set(agents)) != len(agents):
        raise r.err(("agents", "names"), "expected one or more distinct agents")
    for i, a in enumerate(agents):
        if not CONSTANT_RE.fullmatch(a):
            raise r.err(("agents", "names", i), f"{a!r} is not a plain constant (lower-case letter or digit first)")
    _every_agents_atoms_ahead(r, board, len(agents))
    # the board's predicates are names the spec may use too (FrozenLake's start cells are weights of the
    # start choice, not read by a rule); a typo among them leaves the rules' predicate "never set"
    program = _with_board(r, rules, board)
    constants = r.strings(("env", "constants"), [])  # things no rule names (an opponent, its bullets)
    for i, c in enumerate(constants):
        if not CONSTANT_RE.fullmatch(c):
            raise r.err(("env", "constants", i), f"{c!r} is not a plain constant (lower-case letter or digit first)")
    check = _Names(r, program, [*(board.cells if board else []), *agents, *constants])
    for pred in (board.marks if board else {}):  # a predicate of one argument, true of cells
        check.pattern(("board", "marks", pred), f"{pred}(Cell)", ("Cell",))
    for name, p in (board.pieces if board else {}).items():  # drawn only: each predicate with its arity
        for key, text in (("at", f"{p.at}(Thing, Cell)"), ("things", f"{p.things}(Thing)"),
                          ("alive", p.alive and f"{p.alive}(Thing)"), ("heading", p.heading and f"{p.heading}(Thing, D)")):
            if text:
                check.pattern(("board", "pieces", name, key), text, ("Thing", "Cell", "D"))
    for i, pred in enumerate(board.annotate if board else ()):
        if pred not in check.arity:
            raise r.err(("board", "annotate", i), f"{pred!r}: the program has no predicate {pred!r}")

    action_names, action_facts, mask = _actions(r, check, agents, agents_t.get("mask"))
    decides, alive = (_per_agent(r, check, key, agents, agents_t.get(key)) for key in ("decides", "alive"))
    script = None
    if agents_t.get("script") is not None:  # as the mask: an atom per agent and action
        lit = check.pattern(("agents", "script"), agents_t["script"], (AGENT_VAR, ACTION_VAR))
        script = tuple(tuple(check.ground(lit, {AGENT_VAR: a, ACTION_VAR: n}) for n in action_names) for a in agents)
    domains = {"cells": board.cells} if board else {}
    space, parts = _observation(r, check, domains, agents)
    previous = _previous(r, space)
    reward_table, reward_scaled, reward_terms = _reward(r, check, agents)
    end = r.table(("end",), ("terminated", "truncated", "max_steps", "win", "loss"), default={})
    terminated = _every_agents(r, check, ("end", "terminated"), agents)
    truncated = _every_agents(r, check, ("end", "truncated"), agents)
    win = _every_agents(r, check, ("end", "win"), agents)
    loss = _every_agents(r, check, ("end", "loss"), agents)
    max_steps = r.integer(("end", "max_steps"), None, minimum=1) if "max_steps" in end else None
    if not (terminated or truncated or max_steps):  # play --env would step such a world forever
        raise r.err(("end",), "the episode can never end: expected `terminated`, `truncated` or `max_steps` "
                              "(max_steps = N for a task that never ends by itself)")
    r.table(("start",), ("facts", "choose"), default={})
    start_facts = _every_agents(r, check, ("start", "facts"), agents, bounds=True)
    choices = tuple(d for i in range(len(_list(r, ("start", "choose"))))
                    if (d := _draw(r, check, ("start", "choose", i), domains, start=True)) is not None)
    randoms = tuple(d for i in range(len(_list(r, ("random",))))
                    if (d := _draw(r, check, ("random", i), domains, start=False)) is not None)
    seen: dict[str, KeyPath] = {}
    for d in (*choices, *randoms):
        if d.name in seen:
            raise r.err(d.key, f"the draw name {d.name!r} is also the name of {'.'.join(map(str, seen[d.name]))} "
                               "(give each draw its own `name`)")
        seen[d.name] = d.key
    clocks = tuple(_clock(r, check, ("clock", i)) for i in range(len(_list(r, ("clock",)))))
    nearest_facts = tuple(_nearest_facts(r, check, ("nearest", i), domains)
                          for i in range(len(_list(r, ("nearest",)))))
    fps = r.integer(("env", "render_fps"), 4, minimum=1)
    if board is not None:
        spec_read = [*(a for part in parts for atoms in part.per_agent for a in atoms), *terminated, *truncated,
                     *(a for per_agent in (*reward_table, *reward_scaled) for a, _ in per_agent),
                     *(a for per_agent in (mask or ()) for a in per_agent), *decides, *alive,
                     *(a for d in (*choices, *randoms) for value in (d.weights or ()) for a in value),
                     *(a for n in nearest_facts for a in n.where)]
        _check_board_names(r, rules, board, {a.pred for a in spec_read})
    # the program's warnings again, knowing what the env sets: no "never set" for pressed(...), slip(...)
    env_set = [*(a for per_agent in action_facts for facts in per_agent for a in facts), *start_facts,
               *(a for d in (*choices, *randoms) for value in d.atoms for a in value),
               *(a for c in clocks for a in c.atoms), *(a for n in nearest_facts for per in n.atoms for a in per)]
    check_program(program, {a.pred: len(a.args) for a in env_set})
    return WorldSpec(src.path, names, program, tuple(agents), action_names, action_facts, mask, space, parts,
                     reward_table, reward_scaled, terminated, truncated, max_steps, start_facts, choices,
                     randoms, board, fps, src, r.budget.board_facts + r.budget.atoms, reward_terms, win, loss,
                     previous, clocks, nearest_facts, decides, alive, script)


def _require(r: _Reader) -> None:
    """`[env.require]`: each key an expression over the params that must hold, its value the reason; one
    that is false refuses the spec at its line, with the params it names."""
    for text, reason in r.table(("env", "require"), default={}).items():
        path = ("env", "require", text)
        if not isinstance(reason, str):
            raise r.err(path, f"expected the reason as a string, got {_kind(reason)}")
        try:
            holds = evaluate(text, r.names)
        except ExpressionError as e:
            raise r.err(path, str(e)) from None
        if not holds:
            named = dict.fromkeys(n.id for n in ast.walk(ast.parse(text.strip(), mode="eval"))
                                  if isinstance(n, ast.Name) and n.id in r.names and not isinstance(r.names[n.id], dict))
            given = ", ".join(f"{n} = {r.names[n]!r}"[:60] for n in named)
            raise r.err(path, f"{reason} (given {given})" if given else reason)


def _every_agents_atoms_ahead(r: _Reader, board: Board | None, agents: int) -> None:
    """Refuse a spec whose atoms for every agent (actions, mask, observation parts, rewards, ends, start
    facts), counted from its text, could not fit, before the board's facts or any atom is made."""
    def length(v: Any) -> int:
        return len(v) if isinstance(v, (list, dict)) else 1
    cells = board.height * board.width if board else 0
    actions = r.raw(("actions",), {})
    n = sum(length(v) for v in actions.values()) if isinstance(actions, dict) else 0
    n += length(actions) if "mask" in r.raw(("agents",), {}) else 0
    for part in r.raw(("observation", "parts"), []):
        if not isinstance(part, dict):
            continue
        over = part.get("over")
        n += length(part.get("atoms", [])) + (cells if over == "cells" else len(over) if isinstance(over, list) else 0)
        n += (1 + length(part.get("things", []))) * cells if part.get("read") == "nearest" else 0
    n += length(r.raw(("reward", "table"), {})) + 1
    n += sum(length(r.raw(path, [])) for path in (("end", "terminated"), ("end", "truncated"), ("end", "win"),
                                                   ("end", "loss"), ("start", "facts")))
    try:
        r.budget.ahead(n * agents, _atoms_for(n, agents))
    except SpecTooBig as e:
        raise r.err(("agents", "names"), str(e)) from None


def _actions(r: _Reader, check: _Names, agents: list[str], mask_text: Any
             ) -> tuple[tuple[str, ...], tuple[tuple[tuple[Atom, ...], ...], ...], tuple[tuple[Atom, ...], ...] | None]:
    """[actions] in order: names, each agent's facts per action, and the mask's atom per agent and action."""
    actions_t = r.table(("actions",))
    if not actions_t:
        raise r.err(("actions",), "expected at least one action")
    names = tuple(actions_t)
    for name in names:
        if not CONSTANT_RE.fullmatch(name):
            raise r.err(("actions", name), "an action's name must be a plain constant (lower-case letter or "
                                           "digit first; letters, digits, _ and -)")
        r.strings(("actions", name))
    r.charge(("actions",), sum(len(actions_t[n]) for n in names) + (len(names) if mask_text is not None else 0),
             len(agents))
    facts = tuple(tuple(check.atoms(("actions", n), actions_t[n], {AGENT_VAR: a}, bounds=True) for n in names)
                  for a in agents)
    if mask_text is None:
        return names, facts, None
    lit = check.pattern(("agents", "mask"), mask_text, (AGENT_VAR, ACTION_VAR))
    for name in names:  # the mask's atoms name the actions: rules must be able to set them
        if name not in check.constants:
            raise r.err(("actions", name), f"the mask {mask_text!r} names this action, but the program has "
                                           f"no constant {name!r}")
    mask = tuple(tuple(check.ground(lit, {AGENT_VAR: a, ACTION_VAR: n}) for n in names) for a in agents)
    return names, facts, mask


def _plain(value: Any) -> Any:
    """A keyword argument as expressions see it: numpy arrays and tuples as lists, bytes as text
    (gymnasium's FrozenLake takes desc as strings, lists of characters or a numpy array of bytes)."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (bytes, np.bytes_)):
        return bytes(value).decode("latin-1")
    if isinstance(value, np.generic):
        return value.item()
    return value


def _per_agent(r: _Reader, check: _Names, key: str, agents: list[str], text: Any) -> tuple[Atom, ...]:
    """`[agents] decides` / `alive`: an atom with `Agent`, one per agent (none when the key is absent)."""
    if text is None:
        return ()
    lit = check.pattern(("agents", key), text, (AGENT_VAR,))
    return tuple(check.ground(lit, {AGENT_VAR: a}) for a in agents)


def _every_agents(r: _Reader, check: _Names, path: KeyPath, agents: list[str], *, bounds: bool = False
                  ) -> tuple[Atom, ...]:
    """A list of atoms, `Agent` standing for each agent in turn (an atom without it once)."""
    texts = r.strings(path, [])
    r.charge(path, len(texts), len(agents))
    out = (a for agent in agents for a in check.atoms(path, texts, {AGENT_VAR: agent}, bounds=bounds))
    return tuple(dict.fromkeys(out))


def _list(r: _Reader, path: KeyPath) -> list[Any]:
    v = r.raw(path, [])
    if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
        raise r.err(path, f"expected an array of tables ([[{'.'.join(map(str, path))}]]), got {_kind(v)}")
    return v


def _inside(r: _Reader, path: KeyPath, name: str) -> str:
    """A file named by the spec: relative, inside the spec's folder once links are resolved (a spec never
    makes tracelab read elsewhere); the resolved path."""
    try:
        return str(path_inside(r.src.folder, name))
    except FileRefused as e:
        raise r.err(path, f"{e} (a path relative to the spec's folder, inside it)") from None


def _load_rules(r: _Reader, files: list[str]) -> Program:
    try:
        return load_program(*files)
    except FileNotFoundError as e:
        raise r.err(("env", "rules"), f"{e.filename}: no such file") from None


def _check_board_names(r: _Reader, rules: Program, board: Board, spec_read: set[str]) -> None:
    """Each predicate the board makes (legend, neighbours, rays, edges) is read by a rule or by an atom of
    the spec: one that nothing reads is a typo (`G = ["floor", "gaol"]` leaves the rules' goal never
    true), named with the predicates the rules read but nothing sets."""
    read = {lit.pred for rule in rules.rules for lit in rule.body} | spec_read
    set_by = {f.literal.pred for f in rules.facts} | {rule.head.pred for rule in rules.rules}
    wanted = sorted(read - set_by) or sorted(read)
    made = [(("board", "legend", ch, i), p) for ch, preds in board.legend.items() for i, p in enumerate(preds)]
    made += [(("board", key, name), name) for key, names in (("neighbours", board.neighbours),
                                                             ("rays", board.rays), ("edges", board.edges))
             for name in names]
    for path, pred in made:
        if pred not in read:
            near = close_names(pred, wanted)
            hint = f"did you mean {', '.join(near)}?" if near else f"the rules read: {', '.join(wanted[:12])}"
            raise r.err(path, f"no rule and no atom of the spec reads the predicate {pred!r}; {hint}")


def _with_board(r: _Reader, program: Program, board: Board | None) -> Program:
    """The program with the board's facts (static, at t = 0), checked again."""
    if board is None:
        return program
    loc = SourceLoc(r.src.path, r.src.key_lines.line(("board", "rows")), 1)
    facts = [Fact(f"board{i}", Literal(p, tuple(Term(a, False) for a in args), loc=loc), static=True, loc=loc)
             for i, (p, args) in enumerate(board.facts())]
    out = dataclasses.replace(program, facts=[*program.facts, *facts], warnings=[])
    try:
        check_program(out)
    except ProgramError as e:
        raise r.err(("board",), f"the board's facts do not fit the program: {e.message}") from None
    return out


def _board(r: _Reader) -> Board:
    r.table(("board",), ("rows", "cell", "legend", "neighbours", "rays", "edges", "edge", "marks", "colors",
                         "mark_colors", "pieces", "annotate"))
    rows = r.value(("board", "rows"))
    if isinstance(rows, list):  # rows of single characters, as gymnasium's np.asarray(desc, dtype="c") reads
        rows = ["".join(x) if isinstance(x, list) and all(isinstance(c, str) for c in x) else x for x in rows]
    if not isinstance(rows, list) or not all(isinstance(x, str) for x in rows):
        raise r.err(("board", "rows"), f"expected a list of strings (one character per cell), got {_kind(rows)}")
    if not rows or any(len(x) != len(rows[0]) for x in rows) or not rows[0]:
        raise r.err(("board", "rows"), "expected rows of one length, at least one cell")
    if len(rows) * len(rows[0]) > MAX_BOARD_CELLS:
        raise r.err(("board", "rows"), f"more than {MAX_BOARD_CELLS} cells")
    fmt = r.string(("board", "cell"), "c{row}_{col}")
    if not CELL_FORMAT.fullmatch(fmt) or "{row}" not in fmt or "{col}" not in fmt \
            or not CONSTANT_RE.fullmatch(fmt.format(row=0, col=0)):
        raise r.err(("board", "cell"), f"expected a name made of letters, digits, _ and - with {{row}} and "
                                       f"{{col}}, starting with a lower-case letter, such as \"c{{row}}_{{col}}\"; "
                                       f"got {fmt!r}")
    legend: dict[str, tuple[str, ...]] = {}
    for ch, preds in r.table(("board", "legend"), default={}).items():
        if len(ch) != 1:
            raise r.err(("board", "legend", ch), "expected a single character as the key")
        legend[ch] = tuple(r.strings(("board", "legend", ch)))
    neighbours = {name: _offsets(r, ("board", "neighbours", name), several=True)
                  for name in r.table(("board", "neighbours"), default={})}
    rays = {name: _offsets(r, ("board", "rays", name))[0] for name in r.table(("board", "rays"), default={})}
    edges = {name: _offsets(r, ("board", "edges", name))[0] for name in r.table(("board", "edges"), default={})}
    for key, names in (("rays", rays), ("edges", edges)):
        for name, (dr, dc) in names.items():
            if (dr, dc) == (0, 0):
                raise r.err(("board", key, name), "expected a step that moves: [0, 0] stays on the cell")
    edge = r.string(("board", "edge"), "stay", choices=("stay", "none"))
    marks = {}
    for pred, ch in r.table(("board", "marks"), default={}).items():
        if not isinstance(ch, str) or len(ch) != 1:
            raise r.err(("board", "marks", pred), "expected one character")
        marks[pred] = ch
    colors = {ch: _color(r, ("board", "colors", ch)) for ch in r.table(("board", "colors"), default={})}
    mark_colors = {p: _color(r, ("board", "mark_colors", p)) for p in r.table(("board", "mark_colors"), default={})}
    for pred in mark_colors:
        if pred not in marks:
            raise r.err(("board", "mark_colors", pred), "not a predicate of `marks`")
    board = Board(tuple(rows), fmt, legend, neighbours, edge, marks, colors, mark_colors, rays, edges,
                  _pieces(r), tuple(r.strings(("board", "annotate"), [])))
    if board.fact_count() > MAX_BOARD_FACTS:  # refused before the facts are built
        raise r.err(("board",), f"makes {board.fact_count():,} facts; a board may make at most {MAX_BOARD_FACTS:,}")
    try:
        r.budget.board(board.fact_count())
    except SpecTooBig as e:
        raise r.err(("board",), str(e)) from None
    return board


def _pieces(r: _Reader) -> dict[str, Pieces]:
    """`[board.pieces.NAME]`: things the viewers draw where they stand (their predicates are checked
    against the program with the marks')."""
    out = {}
    kinds = r.table(("board", "pieces"), default={})
    if len(kinds) > MAX_PIECE_KINDS:
        raise r.err(("board", "pieces"), f"at most {MAX_PIECE_KINDS} kinds of pieces")
    for name in kinds:
        path = ("board", "pieces", name)
        r.table(path, ("at", "things", "colors", "alive", "heading"))
        colors = {k: _color(r, (*path, "colors", k)) for k in r.table((*path, "colors"), default={})}
        optional = [r.string((*path, k)) if r.raw((*path, k), None) is not None else None
                    for k in ("alive", "heading")]
        out[name] = Pieces(r.string((*path, "at")), r.string((*path, "things")), colors, *optional)
    return out


def _offsets(r: _Reader, path: KeyPath, *, several: bool = False) -> tuple[tuple[int, int], ...]:
    """[row step, column step], or (`several`) a list of them."""
    d = r.raw(path)
    is_step = lambda x: isinstance(x, list) and len(x) == 2 and all(  # noqa: E731
        isinstance(v, int) and not isinstance(v, bool) for v in x)
    if is_step(d):
        return ((d[0], d[1]),)
    if several and isinstance(d, list) and d and all(is_step(x) for x in d):
        return tuple((x[0], x[1]) for x in d)
    more = ", or a list of them" if several else ""
    raise r.err(path, f"expected [row step, column step]{more}, got {_kind(d)}")


def _color(r: _Reader, path: KeyPath) -> tuple[int, int, int]:
    v = r.raw(path)
    rgb = hex_color(v) if isinstance(v, str) else None
    if rgb is None:
        raise r.err(path, f"expected a colour \"#rrggbb\", got {_kind(v)}")
    return rgb


def _domain(r: _Reader, path: KeyPath, domains: dict[str, list[str]]) -> list[str]:
    """`over`: a named domain ("cells", the board's), a list of constants, or an expression giving one."""
    expected = f"expected {' or '.join(map(repr, domains)) or 'a named domain'}, a list of constants, or an " \
               "expression giving one"
    v = r.raw(path)
    if isinstance(v, str):
        if v in domains:
            return domains[v]
        try:
            v = evaluate(v, r.names)
        except ExpressionError as e:
            raise r.err(path, f"{expected} ({e})") from None
    if not isinstance(v, list) or not v or not all(isinstance(x, str) for x in v):
        raise r.err(path, f"{expected}, got {_kind(v)}")
    if len(v) > MAX_DOMAIN:
        raise r.err(path, f"more than {MAX_DOMAIN} values")
    return v


def _observation(r: _Reader, check: _Names, domains: dict[str, list[str]], agents: list[str]
                 ) -> tuple[str, tuple[ObservationPart, ...]]:
    r.table(("observation",), ("space", "parts", "previous"))
    space = r.string(("observation", "space"), choices=SPACES)
    parts = []
    raw_parts = _list(r, ("observation", "parts"))
    if not raw_parts:
        raise r.err(("observation", "parts"), "expected at least one [[observation.parts]]")
    for i, p in enumerate(raw_parts):
        path = ("observation", "parts", i)
        r.table(path, ("name", "read", "atom", "over", "atoms", "values", "missing", "things", "from"))
        name = r.string((*path, "name"), f"part{i}")
        read = r.string((*path, "read"), choices=READS)
        if read == "nearest":
            parts.append(_nearest(r, check, path, p, name, space, domains, agents))
            continue
        for key in ("things", "from"):
            if key in p:
                raise r.err((*path, key), f"`{key}` is for a part with read = \"nearest\"")
        if ("atoms" in p) == ("atom" in p):
            raise r.err(path, "expected either `atom` (with `over`) or `atoms` (a list of ground atoms)")
        if "atoms" in p:
            texts = r.strings((*path, "atoms"))
            r.charge((*path, "atoms"), len(texts), len(agents))
            per_agent = tuple(check.atoms((*path, "atoms"), texts, {AGENT_VAR: a}) for a in agents)
        else:
            domain = _domain(r, (*path, "over"), domains)
            r.charge((*path, "over"), len(domain), len(agents))
            check.domain((*path, "over"), domain)
            per_agent = tuple(check.over((*path, "atom"), p["atom"], domain, a) for a in agents)
        if not per_agent[0]:
            raise r.err(path, "no atoms to read")
        values, missing = _index_numbers(r, path, p, read, space, len(per_agent[0]))
        parts.append(ObservationPart(name, read, per_agent, values, missing))
    if space in ("Discrete", "MultiDiscrete"):
        for i, p in enumerate(parts):
            if p.read != "index":
                raise r.err(("observation", "parts", i, "read"), f"a {space} observation reads indices: "
                                                                  f"expected \"index\", got {p.read!r}")
    if len({p.name for p in parts}) != len(parts):
        raise r.err(("observation", "parts"), "two parts with one name")
    return space, tuple(parts)


def _clock(r: _Reader, check: _Names, path: KeyPath) -> Clock:
    """A `[[clock]]`: its facts on the episode's steps k with k % every == at."""
    t = r.table(path, ("atom", "every", "at"))
    if isinstance(t.get("atom"), str):
        atoms = (check.ground(check.pattern((*path, "atom"), t["atom"], (), bounds=True), {}),)
    else:
        atoms = check.atoms((*path, "atom"), r.strings((*path, "atom")), {}, bounds=True)
    if not atoms:
        raise r.err((*path, "atom"), "expected at least one atom")
    every = r.integer((*path, "every"), minimum=1)
    at = r.integer((*path, "at"), 0)
    if at >= every:
        raise r.err((*path, "at"), f"expected a step in 0..{every - 1} (of every {every}), got {at}")
    return Clock(path, atoms, every, at)


WHO_VAR = "Who"


def _nearest_facts(r: _Reader, check: _Names, path: KeyPath, domains: dict[str, list[str]]) -> NearestFacts:
    """A `[[nearest]]`: `atom` (with Who and Thing) set for each of `who` and its nearest of `things`, where
    each is found by `where` (Thing and a cell variable), before every step."""
    t = r.table(path, ("atom", "who", "things", "where", "lines"))
    cells = domains.get("cells")
    if cells is None:
        raise r.err(path, "[[nearest]] measures distances on the [board]; the spec has none")
    who, things = r.strings((*path, "who")), r.strings((*path, "things"))
    check.domain((*path, "who"), who)
    check.domain((*path, "things"), things)
    if not who or not things or (len(who) + len(things)) * len(cells) > MAX_DOMAIN:
        raise r.err(path, f"expected `who` and `things`, together at most {MAX_DOMAIN // len(cells)}")
    lit = check.pattern((*path, "atom"), r.string((*path, "atom")), (WHO_VAR, THING_VAR), bounds=True)
    if {a.name for a in lit.args if a.is_var} != {WHO_VAR, THING_VAR}:
        raise r.err((*path, "atom"), f"expected the variables {WHO_VAR} and {THING_VAR}")
    text = r.string((*path, "where"))
    where = check.pattern((*path, "where"), text, tuple(v.name for v in _vars(text)))
    others = {a.name for a in where.args if a.is_var} - {THING_VAR}
    if THING_VAR not in {a.name for a in where.args if a.is_var} or len(others) != 1:
        raise r.err((*path, "where"), f"{text!r}: expected {THING_VAR} and one variable for the cell")
    cell_var = others.pop()
    r.charge(path, (len(who) + len(things)) * len(cells) + len(who) * len(things))
    where_atoms = tuple(check.ground(where, {THING_VAR: x, cell_var: c}) for x in (*who, *things) for c in cells)
    atoms = tuple(tuple(check.ground(lit, {WHO_VAR: w, THING_VAR: x}) for x in things) for w in who)
    lines = None
    if "lines" in t:
        raw = r.value((*path, "lines"))
        if not isinstance(raw, list) or not raw or not all(
                isinstance(x, list) and len(x) == 2 and all(type(v) is int for v in x) and x != [0, 0] for x in raw):
            raise r.err((*path, "lines"), "expected a list of [row, col] steps such as [[-1, 0], [1, 0]]")
        lines = tuple((int(x[0]), int(x[1])) for x in raw)
    width = len(cells) // len(r.value(("board", "rows")))
    return NearestFacts(path, atoms, where_atoms, len(who), len(things), width, lines)


MAX_PREVIOUS = 64  # earlier observations an observation may carry


def _previous(r: _Reader, space: str) -> int:
    """`[observation] previous = N`: the observations of the N steps before follow the current one."""
    path = ("observation", "previous")
    n = r.integer(path, 0)
    if n > MAX_PREVIOUS:
        raise r.err(path, f"at most {MAX_PREVIOUS} earlier observations, got {n}")
    if n and space == "Discrete":
        raise r.err(path, "a Discrete observation is one number: earlier observations need a MultiDiscrete, "
                          "Box or Dict space")
    return n


def _nearest(r: _Reader, check: _Names, path: KeyPath, p: dict[str, Any], name: str, space: str,
             domains: dict[str, list[str]], agents: list[str]) -> ObservationPart:
    """A `nearest` part: of the `things` (in order, the first winning a tie), the board cell of the one
    nearest (Manhattan distance, in rows and columns) to the cell where `from` holds; `atom` says where
    a thing is (`Thing` and a cell variable)."""
    cells = domains.get("cells")
    if cells is None:
        raise r.err((*path, "read"), "\"nearest\" measures distances on the [board]; the spec has none")
    for key in ("atom", "things", "from"):
        if key not in p:
            raise r.err((*path, key), "missing (required for read = \"nearest\")")
    if "over" in p or "atoms" in p:
        raise r.err(path, "a \"nearest\" part reads the board's cells: no `over` or `atoms`")
    things = r.strings((*path, "things"))
    check.domain((*path, "things"), things)
    if not things or len(things) * len(cells) > MAX_DOMAIN:
        raise r.err((*path, "things"), f"expected 1 to {MAX_DOMAIN // len(cells)} things")
    text = p["atom"]
    lit = check.pattern((*path, "atom"), text, tuple(v.name for v in _vars(text)))
    others = {a.name for a in lit.args if a.is_var} - {AGENT_VAR, THING_VAR}
    if THING_VAR not in {a.name for a in lit.args if a.is_var} or len(others) != 1:
        raise r.err((*path, "atom"), f"{text!r}: expected {THING_VAR} (each of `things`) and one variable for "
                                     "the cell")
    cell_var = others.pop()
    r.charge((*path, "things"), (1 + len(things)) * len(cells), len(agents))
    per_agent = tuple((*check.over((*path, "from"), p["from"], cells, a),
                       *(check.ground(lit, {THING_VAR: t, cell_var: c, AGENT_VAR: a}) for t in things for c in cells))
                      for a in agents)
    values, missing = _index_numbers(r, path, p, "nearest", space, len(cells))
    width = len(cells) // len(r.value(("board", "rows")))
    return ObservationPart(name, "nearest", per_agent, values, missing, len(things), width)


def _index_numbers(r: _Reader, path: KeyPath, part: dict[str, Any], read: str, space: str, n: int
                   ) -> tuple[tuple[float, ...] | None, float | None]:
    """An index part's `values` (a number per atom, reported instead of its position) and `missing` (the
    number when no atom is true): Box and Dict parts only, where an index is a number."""
    values = missing = None
    for key in ("values", "missing"):
        if key in part and (read not in ("index", "nearest") or space not in ("Box", "Dict")):
            raise r.err((*path, key), f"`{key}` is for an index or nearest part of a Box or Dict observation")
    if "values" in part:
        v = r.value((*path, "values"))
        if not isinstance(v, list) or len(v) != n or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v):
            raise r.err((*path, "values"), f"expected a list of {n} finite numbers (one per atom), got {_kind(v)}")
        values = tuple(float(x) for x in v)
    if "missing" in part:
        missing = r.number((*path, "missing"))
    return values, missing


def _reward(r: _Reader, check: _Names, agents: list[str]
            ) -> tuple[tuple[tuple[tuple[Atom, float], ...], ...], tuple[tuple[tuple[Atom, float], ...], ...],
                       tuple[str, ...]]:
    """Per agent: the table's (atom, value) pairs and the scaled atom's (atom, scale); the terms' names
    (the table's keys, then the scaled atom's text)."""
    r.table(("reward",), ("table", "atom", "scale"), default={})
    r.charge(("reward",), len(r.table(("reward", "table"), default={})) + ("atom" in r.raw(("reward",), {})),
             len(agents))
    table = []
    for text in r.table(("reward", "table"), default={}):
        path = ("reward", "table", text)
        table.append((check.pattern(path, text, (AGENT_VAR,)), r.number(path)))
    scaled, names = [], list(r.table(("reward", "table"), default={}))
    if "atom" in r.raw(("reward",), {}):
        lit = check.pattern(("reward", "atom"), r.string(("reward", "atom")), (AGENT_VAR,))
        scaled.append((lit, r.number(("reward", "scale"), 1.0)))
        names.append(r.string(("reward", "atom")))
    return tuple(tuple((check.ground(lit, {AGENT_VAR: a}), v) for lit, v in table) for a in agents), \
        tuple(tuple((check.ground(lit, {AGENT_VAR: a}), v) for lit, v in scaled) for a in agents), tuple(names)


DRAW_METHODS = ("categorical", "choice")


def _draw(r: _Reader, check: _Names, path: KeyPath, domains: dict[str, list[str]], *, start: bool) -> Draw | None:
    """A start choice (`start`) or a random fact; None when its `when` expression is false."""
    keys = ("name", "atom", "over", "probabilities", "weights", "method", "when", *(() if start else ("after",)))
    t = r.table(path, keys)
    if "when" in t:
        when = r.value((*path, "when"))
        if not isinstance(when, bool):
            raise r.err((*path, "when"), f"expected a boolean, got {_kind(when)}")
        if not when:
            return None
    patterns = t.get("atom")
    patterns = [patterns] if isinstance(patterns, str) else r.strings((*path, "atom"))
    variables = list(dict.fromkeys(v.name for p in patterns for v in _vars(p)))
    over = r.raw((*path, "over"))
    if isinstance(over, dict):
        if list(over) != variables:
            raise r.err((*path, "over"), f"expected one domain per variable of `atom`, in order: {', '.join(variables)}")
        axes = [_domain(r, (*path, "over", v), domains) for v in variables]
        for v, axis in zip(variables, axes):
            check.domain((*path, "over", v), axis)
    else:
        if len(variables) != 1:
            raise r.err((*path, "atom"), "expected exactly one variable (or `over` as a table, a domain per variable)")
        axes = [_domain(r, (*path, "over"), domains)]
        check.domain((*path, "over"), axes[0])
    if math.prod(len(a) for a in axes) > MAX_DOMAIN:  # refused before the product is built
        raise r.err((*path, "over"), f"more than {MAX_DOMAIN} combinations")
    n_weights = len(w) if isinstance(w := t.get("weights", []), list) else 1
    r.charge((*path, "over"), math.prod(len(a) for a in axes) * (len(patterns) + n_weights))
    values = [dict(zip(variables, combo)) for combo in itertools.product(*axes)]
    lits = [check.pattern((*path, "atom"), p, tuple(variables), bounds=True) for p in patterns]
    atoms = tuple(tuple(check.ground(lit, v) for lit in lits) for v in values)
    method = r.string((*path, "method"), "categorical", choices=DRAW_METHODS)
    after = None
    if "after" in t:
        after = check.ground(check.pattern((*path, "after"), r.string((*path, "after")), ()), {})
    weights = probabilities = None
    if "weights" in t:
        if "probabilities" in t:
            raise r.err(path, "expected `probabilities` or `weights`, not both")
        w = t["weights"]
        wtexts = [w] if isinstance(w, str) else r.strings((*path, "weights"))
        wlits = [check.pattern((*path, "weights"), x, tuple(variables)) for x in wtexts]
        weights = tuple(tuple(check.ground(lit, v) for lit in wlits) for v in values)
    elif "probabilities" in t:
        if method == "choice":
            raise r.err((*path, "method"), "\"choice\" draws uniformly among the values whose `weights` hold: "
                                           "it takes no probabilities")
        probabilities = r.numbers((*path, "probabilities"), len(values))
    else:
        probabilities = np.full(len(values), 1.0 / len(values))
    name = r.string((*path, "name"), lits[0].pred)
    return Draw(path, name, atoms, probabilities, weights, method, after)
