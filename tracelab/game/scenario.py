"""Scenarios: the map, teams and rule settings of one grid-world game (docs/game.md).

A `Scenario` is immutable and always valid: construction checks every field, and `load_scenario` /
`scenario_from_dict` report problems as `ScenarioError("<file>: field '<name>': <what is wrong>")`.
"""
from __future__ import annotations

import json
import math
import tomllib
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from tracelab.engine.safe_files import FileRefused, read_bytes

# The board a run of this game declares in its metadata (RunMeta.board); viewers/board_state.py draws it
# (war.toml's [board] for the scenario's map).
BOARD = "gridworld"

# Action ids of the spec's table. Moves use the first four ids, shots the next four in the same
# direction order, so `shot direction = action - 4`.
UP, DOWN, LEFT, RIGHT = 0, 1, 2, 3
SHOOT_UP, SHOOT_DOWN, SHOOT_LEFT, SHOOT_RIGHT = 4, 5, 6, 7
NOTHING = 8
ACTION_NAMES = ("up", "down", "left", "right", "shoot_up", "shoot_down", "shoot_left", "shoot_right",
                "nothing")
# (dx, dy) per direction 0..3 (up, down, left, right); y grows upwards.
DIRECTION_DELTAS = ((0, 1), (0, -1), (-1, 0), (1, 0))
BASE_ACTION_IDS = (UP, DOWN, LEFT, RIGHT, NOTHING)
ADVANCED_ACTION_IDS = tuple(range(9))

RED, BLUE = 0, 1
TEAMS = ("red", "blue")

SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"
_MAX_SIDE = 4096  # cell ids must fit comfortably in int32
# Sizes read from a scenario file are checked before anything is built from them, in facts of the game
# it describes (game_fact_counts: what RuleSim's fact builder made, a 200x200 map's 359,285 in 40 s; a
# measure of size now, as RefSim's arrays grow with the same fields): at most this many (a 330x330 map at 1
# agent a team; the built-in scenarios count 600-1,600, a 8x8 map at 20 a team 4,400).
MAX_GAME_FACTS = 1_000_000
MAX_HITS_TO_KILL = 1000  # health / damage: each hit an agent can take is a step of the game's tally chain
MAX_EPISODE_STEPS = 100_000  # max_steps: training keeps a [worlds, max_steps, 2, agents] action history
SCENARIO_FILE_CAP = 8 << 20  # a scenario file is a few hundred bytes; a big map's mountains a few MB

Cell = tuple[int, int]


def team_index(team: int | str) -> int:
    """0 for red, 1 for blue; accepts either the index or the name."""
    if isinstance(team, str):
        if team not in TEAMS:
            raise ValueError(f"unknown team {team!r}; expected 'red' or 'blue'")
        return TEAMS.index(team)
    if team not in (RED, BLUE):
        raise ValueError(f"unknown team {team!r}; expected 0 (red) or 1 (blue)")
    return int(team)


DEAD_EPS = 1e-9  # health at or below this is 0 (float damage would otherwise leave 1e-16 alive)


class ScenarioError(ValueError):
    """A scenario file or dict is invalid; the message names the source and the field."""

    def __init__(self, source: str, field_name: str | None, message: str):
        self.source = source
        self.field = field_name
        self.message = message
        where = f"field '{field_name}': " if field_name else ""
        super().__init__(f"{source}: {where}{message}")

    def with_source(self, source: str) -> "ScenarioError":
        return ScenarioError(source, self.field, self.message)


_DIRECT = "<Scenario>"  # source named in errors of scenarios built in code


def _fmt(cell: Cell) -> str:
    return f"({cell[0]},{cell[1]})"


def _is_int(v: Any) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))


def _check_int(name: str, v: Any, minimum: int, maximum: int | None = None) -> int:
    if not _is_int(v):
        raise ScenarioError(_DIRECT, name, f"expected an integer, got {v!r}")
    if v < minimum or (maximum is not None and v > maximum):
        upper = f" and at most {maximum}" if maximum is not None else ""
        raise ScenarioError(_DIRECT, name, f"must be at least {minimum}{upper}, got {v}")
    return int(v)


def _check_number(name: str, v: Any) -> float:
    if not (_is_int(v) or isinstance(v, (float, np.floating))) or isinstance(v, bool):
        raise ScenarioError(_DIRECT, name, f"expected a number, got {v!r}")
    if not math.isfinite(float(v)):
        raise ScenarioError(_DIRECT, name, f"must be finite, got {v!r}")
    return float(v)


def _check_cell(name: str, v: Any, width: int, height: int) -> Cell:
    if isinstance(v, (str, bytes)) or not isinstance(v, (list, tuple)) or len(v) != 2 \
            or not all(_is_int(c) for c in v):
        raise ScenarioError(_DIRECT, name, f"expected a cell [x, y] of two integers, got {v!r}")
    cell = (int(v[0]), int(v[1]))
    if not (0 <= cell[0] < width and 0 <= cell[1] < height):
        raise ScenarioError(_DIRECT, name, f"{_fmt(cell)} is outside the {width}x{height} grid")
    return cell


def _check_list(name: str, v: Any) -> list:
    if isinstance(v, (str, bytes)) or not isinstance(v, (list, tuple)):
        raise ScenarioError(_DIRECT, name, f"expected a list, got {v!r}")
    return list(v)


@dataclass(frozen=True)
class Rewards:
    """Reward terms (the method's values by default). Per-step terms apply per agent."""
    win: float = 250.0
    loss: float = -250.0
    hit_opponent: float = 400.0
    got_shot: float = -200.0
    valid_action: float = -2.0
    unsafe: float = -200.0
    invalid: float = -10.0

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, _check_number(f"rewards.{f.name}", getattr(self, f.name)))


@dataclass(frozen=True)
class SlowAgents:
    """Indices of the slow agents of each team (non-Markov variant)."""
    red: tuple[int, ...] = ()
    blue: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        for team in TEAMS:
            name = f"slow_agents.{team}"
            raw = _check_list(name, getattr(self, team))
            idx = tuple(_check_int(f"{name}[{i}]", v, 0) for i, v in enumerate(raw))
            for i, v in enumerate(idx):
                if v in idx[:i]:
                    raise ScenarioError(_DIRECT, f"{name}[{i}]", f"agent {v} is listed twice")
            object.__setattr__(self, team, idx)

    def __getitem__(self, team: int | str) -> tuple[int, ...]:
        return getattr(self, TEAMS[team_index(team)])


def _reachable(width: int, height: int, blocked: np.ndarray, start: Cell) -> np.ndarray:
    """Cells reachable from `start` by unit moves avoiding `blocked` (bool [width, height])."""
    seen = np.zeros((width, height), dtype=bool)
    seen[start] = True
    queue = deque([start])
    while queue:
        x, y = queue.popleft()
        for dx, dy in DIRECTION_DELTAS:
            nx, ny = x + dx, y + dy
            if 0 <= nx < width and 0 <= ny < height and not blocked[nx, ny] and not seen[nx, ny]:
                seen[nx, ny] = True
                queue.append((nx, ny))
    return seen


def game_fact_counts(width: int, height: int, agents: int, ammo: int, hits_to_kill: int) -> dict[str, int]:
    """A scenario's size in facts of its game (as RuleSim's fact builder made them), by the field that
    drives them: per cell its kind and, per direction, a neighbour and nextTo or an edge; per agent 15
    and per team 1; per bullet 5 and one per enemy target; per bullet place of a team 1, and 3 per hit
    to kill; 6 more (the clock's)."""
    cells = width * height + 4 * ((width - 1) * height + width * (height - 1)) + 2 * (width + height)
    bullets = agents * ammo
    return {"width": cells,
            "agents_per_team": 2 * (15 * agents + 1) + 2 * bullets * agents + 6,
            "ammo": 2 * bullets * 5 + bullets,
            "health": 3 * bullets * hits_to_kill}


def _check_game_size(width: int, height: int, agents: int, ammo: int, hits_to_kill: int) -> None:
    """Refuse a scenario that would make more than MAX_GAME_FACTS facts, naming the field that makes most."""
    counts = game_fact_counts(width, height, agents, ammo, hits_to_kill)
    total = sum(counts.values())
    if total <= MAX_GAME_FACTS:
        return
    key = max(counts, key=counts.__getitem__)
    what = {"width": f"a {width}x{height} map", "agents_per_team": f"{agents} agents a team",
            "ammo": f"ammo {ammo} ({agents * ammo:,} bullets a team)",
            "health": f"{hits_to_kill} hits to kill (health / damage) for {agents * ammo:,} bullets a team"}[key]
    raise ScenarioError(_DIRECT, key, f"{what}: {counts[key]:,} facts of the game ({total:,} in all); a "
                                      f"scenario may make at most {MAX_GAME_FACTS:,}")


@dataclass(frozen=True)
class Scenario:
    """One game's settings. Cells are (x, y); x grows right, y grows up; cell id = y * width + x."""
    name: str
    width: int
    height: int
    red_base: Cell
    blue_base: Cell
    mountains: tuple[Cell, ...] = ()
    agents_per_team: int = 1
    red_starts: tuple[Cell, ...] | None = None  # None: every agent starts on its own base
    blue_starts: tuple[Cell, ...] | None = None
    ammo: int = 3
    health: float = 1.0
    damage: float = 1.0
    max_steps: int = 200
    advanced: bool = False
    slow_agents: SlowAgents = field(default_factory=SlowAgents)
    rewards: Rewards = field(default_factory=Rewards)

    def __post_init__(self) -> None:
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731  (frozen dataclass)
        if not isinstance(self.name, str) or not self.name:
            raise ScenarioError(_DIRECT, "name", f"expected a non-empty string, got {self.name!r}")
        w = _check_int("width", self.width, 1, _MAX_SIDE)
        h = _check_int("height", self.height, 1, _MAX_SIDE)
        set_("width", w)
        set_("height", h)
        red_base = _check_cell("red_base", self.red_base, w, h)
        blue_base = _check_cell("blue_base", self.blue_base, w, h)
        if red_base == blue_base:
            raise ScenarioError(_DIRECT, "blue_base", f"{_fmt(blue_base)} is also the red base")
        set_("red_base", red_base)
        set_("blue_base", blue_base)

        mountains: list[Cell] = []
        for i, v in enumerate(_check_list("mountains", self.mountains)):
            cell = _check_cell(f"mountains[{i}]", v, w, h)
            if cell in mountains:
                raise ScenarioError(_DIRECT, f"mountains[{i}]",
                                    f"{_fmt(cell)} repeats mountains[{mountains.index(cell)}]")
            for team, base in zip(TEAMS, (red_base, blue_base)):
                if cell == base:
                    raise ScenarioError(_DIRECT, f"mountains[{i}]", f"{_fmt(cell)} is the {team} base")
            mountains.append(cell)
        set_("mountains", tuple(mountains))

        n = _check_int("agents_per_team", self.agents_per_team, 1)
        free = w * h - len(mountains)
        if 2 * n > free:  # both teams, one agent per free cell
            raise ScenarioError(_DIRECT, "agents_per_team",
                                f"{n} agents a team do not fit the {w}x{h} map: it has {free} free cells "
                                f"(not mountains), room for at most {free // 2} agents a team")
        set_("agents_per_team", n)
        set_("ammo", _check_int("ammo", self.ammo, 0))
        set_("max_steps", _check_int("max_steps", self.max_steps, 1, MAX_EPISODE_STEPS))
        for name in ("health", "damage"):
            value = _check_number(name, getattr(self, name))
            if value <= 0:
                raise ScenarioError(_DIRECT, name, f"must be positive, got {value}")
            set_(name, value)
        if not self.health / self.damage <= MAX_HITS_TO_KILL:  # also refuses inf
            raise ScenarioError(_DIRECT, "health", f"health {self.health:g} / damage {self.damage:g} is "
                                                   f"{self.health / self.damage:.3g} hits to kill; at most "
                                                   f"{MAX_HITS_TO_KILL} are played")
        _check_game_size(w, h, n, self.ammo, self.hits_to_kill)
        if not isinstance(self.advanced, (bool, np.bool_)):
            raise ScenarioError(_DIRECT, "advanced", f"expected true or false, got {self.advanced!r}")
        set_("advanced", bool(self.advanced))
        if not isinstance(self.rewards, Rewards):
            raise ScenarioError(_DIRECT, "rewards", f"expected a Rewards, got {self.rewards!r}")
        if not isinstance(self.slow_agents, SlowAgents):
            raise ScenarioError(_DIRECT, "slow_agents", f"expected a SlowAgents, got {self.slow_agents!r}")
        for team in TEAMS:
            for i, idx in enumerate(self.slow_agents[team]):
                if idx >= n:
                    raise ScenarioError(_DIRECT, f"slow_agents.{team}[{i}]",
                                        f"agent {idx} does not exist (agents_per_team is {n})")

        # Every agent must be able to walk to the enemy base, or the game could not be won by capture.
        blocked = np.zeros((w, h), dtype=bool)
        for cell in mountains:
            blocked[cell] = True
        from_red = _reachable(w, h, blocked, red_base)
        if not from_red[blue_base]:
            raise ScenarioError(_DIRECT, "mountains",
                                f"cut the red base {_fmt(red_base)} off from the blue base {_fmt(blue_base)}")
        bases = (red_base, blue_base)
        for t, team in enumerate(TEAMS):
            key = f"{team}_starts"
            raw = getattr(self, key)
            if raw is None:
                set_(key, (bases[t],) * n)
                continue
            starts = _check_list(key, raw)
            if len(starts) != n:
                raise ScenarioError(_DIRECT, key, f"has {len(starts)} cells, agents_per_team is {n}")
            cells = []
            for i, v in enumerate(starts):
                cell = _check_cell(f"{key}[{i}]", v, w, h)
                if blocked[cell]:
                    raise ScenarioError(_DIRECT, f"{key}[{i}]", f"{_fmt(cell)} is a mountain")
                if cell == bases[1 - t]:
                    raise ScenarioError(_DIRECT, f"{key}[{i}]", f"{_fmt(cell)} is the enemy base")
                if not from_red[cell]:
                    raise ScenarioError(_DIRECT, f"{key}[{i}]",
                                        f"{_fmt(cell)} cannot reach the {TEAMS[1 - t]} base")
                cells.append(cell)
            set_(key, tuple(cells))

    # ----- derived views -----
    @property
    def action_ids(self) -> tuple[int, ...]:
        """The spec action ids this scenario offers, in the order of the learner's action indices."""
        return ADVANCED_ACTION_IDS if self.advanced else BASE_ACTION_IDS

    @property
    def n_actions(self) -> int:
        return len(self.action_ids)

    @property
    def bases(self) -> tuple[Cell, Cell]:
        """(red base, blue base), indexable by team."""
        return (self.red_base, self.blue_base)

    def starts(self, team: int | str) -> tuple[Cell, ...]:
        return (self.red_starts, self.blue_starts)[team_index(team)]  # type: ignore[return-value]

    @property
    def hits_to_kill(self) -> int:
        """How many hits take an agent's health to 0: the least k with health - k·damage <= DEAD_EPS
        (docs/game.md, 'Hits resolve')."""
        k = 1
        while self.health - k * self.damage > DEAD_EPS:
            k += 1
        return k

    @cached_property
    def mountain_grid(self) -> np.ndarray:
        """Read-only bool array [width, height], True on mountains (index it as grid[x, y])."""
        grid = np.zeros((self.width, self.height), dtype=bool)
        for cell in self.mountains:
            grid[cell] = True
        grid.setflags(write=False)
        return grid

    @cached_property
    def slow_mask(self) -> np.ndarray:
        """Read-only bool array [2, agents_per_team], True for slow agents."""
        mask = np.zeros((2, self.agents_per_team), dtype=bool)
        for t, team in enumerate(TEAMS):
            mask[t, list(self.slow_agents[team])] = True
        mask.setflags(write=False)
        return mask

    @property
    def is_non_markov(self) -> bool:
        return bool(self.slow_agents.red or self.slow_agents.blue)

    # ----- serialisation -----
    def to_toml(self) -> str:
        """TOML text that `load_scenario` reads back into an equal Scenario."""
        def cell(c: Cell) -> str:
            return f"[{c[0]}, {c[1]}]"

        def cells(cs: Iterable[Cell]) -> str:
            return "[" + ", ".join(cell(c) for c in cs) + "]"

        lines = [
            f"name = {json.dumps(self.name)}",
            f"width = {self.width}",
            f"height = {self.height}",
            f"red_base = {cell(self.red_base)}",
            f"blue_base = {cell(self.blue_base)}",
            f"mountains = {cells(self.mountains)}",
            f"agents_per_team = {self.agents_per_team}",
            f"advanced = {'true' if self.advanced else 'false'}",
            f"ammo = {self.ammo}",
            f"health = {self.health!r}",
            f"damage = {self.damage!r}",
            f"max_steps = {self.max_steps}",
        ]
        for team, base in zip(TEAMS, self.bases):
            starts = self.starts(team)
            if any(s != base for s in starts):  # default starts stay implicit
                lines.append(f"{team}_starts = {cells(starts)}")
        if self.is_non_markov:
            lines += ["", "[slow_agents]"]
            lines += [f"{team} = [{', '.join(map(str, self.slow_agents[team]))}]" for team in TEAMS]
        lines += ["", "[rewards]"]
        lines += [f"{f.name} = {getattr(self.rewards, f.name)!r}" for f in fields(Rewards)]
        return "\n".join(lines) + "\n"


_SCENARIO_FIELDS = {f.name for f in fields(Scenario)}
_REQUIRED = ("name", "width", "height", "red_base", "blue_base")


def _table(source: str, name: str, value: Any, allowed: set[str]) -> dict:
    if not isinstance(value, Mapping):
        raise ScenarioError(source, name, f"expected a table, got {value!r}")
    for key in value:
        if key not in allowed:
            raise ScenarioError(source, f"{name}.{key}",
                                f"unknown field (expected one of: {', '.join(sorted(allowed))})")
    return dict(value)


def scenario_from_dict(d: Mapping[str, Any], source: str = "<dict>") -> Scenario:
    """Build a Scenario from plain data (as parsed from TOML); errors name `source` and the field."""
    if not isinstance(d, Mapping):
        raise ScenarioError(source, None, f"expected a table of fields, got {type(d).__name__}")
    for key in d:
        if key not in _SCENARIO_FIELDS:
            raise ScenarioError(source, key, "unknown field")
    for key in _REQUIRED:
        if key not in d:
            raise ScenarioError(source, key, "is required")
    kwargs = dict(d)
    try:
        if "rewards" in kwargs:
            kwargs["rewards"] = Rewards(**_table(source, "rewards", kwargs["rewards"],
                                                 {f.name for f in fields(Rewards)}))
        if "slow_agents" in kwargs:
            kwargs["slow_agents"] = SlowAgents(**_table(source, "slow_agents", kwargs["slow_agents"],
                                                        set(TEAMS)))
        return Scenario(**kwargs)
    except ScenarioError as e:
        raise e.with_source(source) from None


def load_scenario(path: str | Path) -> Scenario:
    """Read and check a scenario TOML file."""
    source = str(path)
    try:
        text = read_bytes(path, SCENARIO_FILE_CAP, what="scenario file").decode("utf-8")
    except FileRefused as e:  # a FIFO, a device, too big: its message names the file
        raise ScenarioError(source, None, str(e).removeprefix(f"{source}: ")) from None
    except OSError as e:
        raise ScenarioError(source, None, f"cannot read: {e.strerror or e}") from None
    except UnicodeDecodeError as e:
        raise ScenarioError(source, None, f"not UTF-8 text: byte 0x{e.object[e.start]:02x} at byte offset "
                                          f"{e.start}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(source, None, f"invalid TOML: {e}") from None
    return scenario_from_dict(data, source=source)


def builtin_scenario_names() -> list[str]:
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.toml"))


def builtin_scenario(name: str) -> Scenario:
    """One of the scenarios shipped in tracelab/game/scenarios (base, advanced, nonmarkov)."""
    path = SCENARIO_DIR / f"{name}.toml"
    if not path.is_file():
        raise ValueError(f"no built-in scenario {name!r}; available: {', '.join(builtin_scenario_names())}")
    return load_scenario(path)


def _cheapest_path(width: int, height: int, blocked: np.ndarray, start: Cell, goal: Cell) -> list[Cell]:
    """A path from start to goal crossing the fewest blocked cells (0-1 BFS)."""
    inf = width * height + 1
    cost = np.full((width, height), inf, dtype=np.int64)
    parent: dict[Cell, Cell] = {}
    cost[start] = 0
    queue = deque([start])
    while queue:
        x, y = queue.popleft()
        for dx, dy in DIRECTION_DELTAS:
            nx, ny = x + dx, y + dy
            if not (0 <= nx < width and 0 <= ny < height):
                continue
            step = int(blocked[nx, ny])
            if cost[x, y] + step < cost[nx, ny]:
                cost[nx, ny] = cost[x, y] + step
                parent[(nx, ny)] = (x, y)
                (queue.append if step else queue.appendleft)((nx, ny))
    path = [goal]
    while path[-1] != start:
        path.append(parent[path[-1]])
    return path[::-1]


def generate_scenario(width: int, height: int, agents_per_team: int = 1, mountain_fraction: float = 0.1,
                      seed: int = 0, advanced: bool = False, *, max_steps: int = 200,
                      name: str | None = None) -> Scenario:
    """A random map: red base bottom-right, blue base top-left, round(fraction * (cells - 2)) mountains
    placed uniformly at random, never on a base, and never cutting the bases apart. Agents start on
    their own base. Deterministic for a given seed."""
    if not 0.0 <= mountain_fraction < 1.0:
        raise ValueError(f"mountain_fraction must be in [0, 1), got {mountain_fraction}")
    if width * height < 2:
        raise ValueError(f"a {width}x{height} grid has no room for two bases")
    red_base, blue_base = (width - 1, 0), (0, height - 1)
    candidates = [(x, y) for x in range(width) for y in range(height) if (x, y) not in (red_base, blue_base)]
    count = round(mountain_fraction * len(candidates))
    rng = np.random.default_rng(seed)
    order = [candidates[i] for i in rng.permutation(len(candidates))]
    blocked = np.zeros((width, height), dtype=bool)
    for cell in order[:count]:
        blocked[cell] = True
    spare = order[count:]  # free cells, in random order, to replace mountains moved off a path
    if not _reachable(width, height, blocked, red_base)[blue_base]:
        # Clear the path that crosses the fewest mountains and put those mountains elsewhere, off the path.
        path = _cheapest_path(width, height, blocked, red_base, blue_base)
        on_path = set(path)
        removed = [c for c in path if blocked[c]]
        spare = [c for c in spare if c not in on_path]
        if len(spare) < len(removed):
            raise ValueError(f"mountain_fraction {mountain_fraction} leaves no free path between the bases")
        for c in removed:
            blocked[c] = False
        for c in spare[:len(removed)]:
            blocked[c] = True
    mountains = tuple(sorted((int(x), int(y)) for x, y in zip(*np.nonzero(blocked))))
    if name is None:
        name = f"generated-{width}x{height}-{agents_per_team}v{agents_per_team}-m{mountain_fraction:g}-s{seed}"
    return Scenario(name=name, width=width, height=height, red_base=red_base, blue_base=blue_base,
                    mountains=mountains, agents_per_team=agents_per_team, advanced=advanced,
                    max_steps=max_steps)
