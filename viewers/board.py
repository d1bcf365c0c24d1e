"""The grid game's board of a traced episode, rebuilt from the run's change rows: the map, and per step and per
phase the agents (position, alive, health, ammo, action), the bullets (position, direction) and the rule
firings, as numpy columns.

Lives beside its users (the TUI's board view, the replay), not in the store, which knows no game: it reads
only through a connection from `tracelab.store.open_run` (live or sealed run), and only runs that declare
this board in their metadata (`BOARD`; tracelab.store.kind): a run without a board (a reasoning run) is
refused. Everything comes from the run itself: the map and the teams from its facts
(rules/gridworld/game.rules' vocabulary: `mountain(C)`, `edgeDown(C)`, `enemyBase(A,C)`, `team(A,T)`,
`owner(B,A)`, `killAt(Q)`), the dynamics from the changes of `atLoc`, `alive`, `hitMe`, `spent`, `dir`,
`move` and `shoot`.

Steps and phases. Step s is the episode's timestep t = s (each episode starts at t = 0 with the map
facts; step 0 is the start state). The engine runs one step in two passes: pass 0 (the snapshot rules,
Δt = 1, and the agents' actions) and pass 1, in which the immediate rules cascade through the phases of
docs/game.md in the order of the rule file. A change's *phase* is the section of game.rules its rule
belongs to (found from the line of each section's first rule, `PHASE_STARTS`), held monotone within a
step: a hit counted (section 2) while agents act stays in the act phase. State arrays are
[steps + 1, len(PHASES), n] and give the state at the end of each phase (a phase without changes
repeats the previous one); `[:, -1]` is the state at the end of each step.

    con = open_run("sample_runs/advanced")
    board = load_episode(con, 0)
    board.agent_x[:, 0]             # red-agent-1's x at the end of each step
    board.frame(5).agents[0]        # an AgentState at the end of step 5
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass
from typing import Any

import numpy as np

from tracelab.game.scenario import BOARD
from tracelab.store.kind import run_board, run_config
from tracelab.store.reader import RunConnection

PHASES = ("start", "bullets", "hits", "act", "walk-in", "deaths", "end", "shield")
# The first rule of each section of rules/gridworld/game.rules after the snapshot (phase 0 = "start").
PHASE_STARTS = ("b_up", "hm_struck", "p_act", "w_blank", "d_killed", "g_capture", "k_up_edge")
DIRECTIONS = ("up", "down", "left", "right")   # spec direction ids 0..3 (tracelab.game.facts)
TEAMS = ("red", "blue")
NOTHING = 8                                    # the spec's "do nothing" action id
NO_ACTION = -1                                 # no action recorded (step 0)

_CHANGE_COLUMNS = ("t, pass_no, seq, atom, old_lower, old_upper, new_lower, new_upper, cause_kind, cause_id, "
                   "grounding")
_STATE_LABELS = ("atLoc", "alive", "hitMe", "spent", "dir", "move", "shoot")


@dataclass(frozen=True)
class BoardMap:
    """The map: cells are (x, y), x right, y up; cell id = y·width + x."""
    width: int
    height: int
    mountains: np.ndarray          # [M, 2] int (x, y)
    bases: np.ndarray              # [2, 2] int: red's base, blue's base

    def xy(self, cell: np.ndarray | int) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) of cell ids; -1 stays (-1, -1)."""
        c = np.asarray(cell)
        return np.where(c >= 0, c % self.width, -1), np.where(c >= 0, c // self.width, -1)


@dataclass(frozen=True)
class Firings:
    """Rule firings of an episode (changes made by rules), one row each, in the order the engine made
    them. `cell` is where the firing happened on the board: the cell its head names, else the cell of
    the first agent (else bullet) its grounding names at that phase; -1 if none."""
    step: np.ndarray               # [F] int
    phase: np.ndarray              # [F] int, index into PHASES
    seq: np.ndarray                # [F] int
    rule: list[str]
    bindings: list[str]            # "A=red-agent-1, X=16"
    head: list[str]                # "atLoc(red-agent-1,16)"
    old: np.ndarray                # [F, 2] float: bound before
    new: np.ndarray                # [F, 2] float: bound after
    agent: np.ndarray              # [F] int: first agent the grounding names (index into agents), -1
    cell: np.ndarray               # [F] int cell id, -1

    def __len__(self) -> int:
        return len(self.step)

    def at(self, step: int) -> np.ndarray:
        """Row indices of the firings of one step."""
        lo, hi = np.searchsorted(self.step, [step, step + 1])
        return np.arange(lo, hi)


@dataclass(frozen=True)
class AgentState:
    name: str
    team: str
    x: int
    y: int
    alive: bool
    health: float
    ammo: int
    action: int                    # spec action id 0..8, or NO_ACTION


@dataclass(frozen=True)
class BulletState:
    name: str
    team: str
    x: int
    y: int
    direction: int                 # 0..3 (DIRECTIONS)


@dataclass(frozen=True)
class BoardFrame:
    """The board at the end of one phase of one step: living and dead agents, bullets in flight, and
    the firings of that step."""
    step: int
    phase: int
    agents: list[AgentState]
    bullets: list[BulletState]
    firings: list[dict[str, Any]]


@dataclass
class EpisodeBoard:
    """An episode's board over time. State arrays are [steps + 1, len(PHASES), n] (see the module
    docstring); the properties without `phase_` give the end of each step, [steps + 1, n]."""
    episode: int
    map: BoardMap
    agents: list[str]
    agent_team: np.ndarray         # [A] int (0 red, 1 blue)
    bullets: list[str]
    bullet_team: np.ndarray        # [B] int
    bullet_owner: np.ndarray       # [B] int agent index
    health_start: float
    phase_agent_cell: np.ndarray   # [S+1, P, A] int cell id
    phase_alive: np.ndarray        # [S+1, P, A] bool
    phase_health: np.ndarray       # [S+1, P, A] float
    phase_ammo: np.ndarray         # [S+1, P, A] int
    phase_bullet_cell: np.ndarray  # [S+1, P, B] int cell id, -1 when not on the board
    phase_bullet_dir: np.ndarray   # [S+1, P, B] int 0..3, -1 when not on the board
    action: np.ndarray             # [S+1, A] int spec action id taken in the step (NO_ACTION at step 0)
    firings: Firings
    outcome: str | None            # win | loss | draw | truncated | aborted (red's side), None if running
    changes: dict[str, np.ndarray]  # the episode's change rows as read (raw.changes columns, seq order)

    @property
    def steps(self) -> int:
        """Steps played (the frames are 0..steps)."""
        return self.phase_agent_cell.shape[0] - 1

    @property
    def agent_cell(self) -> np.ndarray:
        return self.phase_agent_cell[:, -1]

    @property
    def agent_x(self) -> np.ndarray:
        return self.map.xy(self.agent_cell)[0]

    @property
    def agent_y(self) -> np.ndarray:
        return self.map.xy(self.agent_cell)[1]

    @property
    def alive(self) -> np.ndarray:
        return self.phase_alive[:, -1]

    @property
    def health(self) -> np.ndarray:
        return self.phase_health[:, -1]

    @property
    def ammo(self) -> np.ndarray:
        return self.phase_ammo[:, -1]

    @property
    def bullet_cell(self) -> np.ndarray:
        return self.phase_bullet_cell[:, -1]

    @property
    def bullet_dir(self) -> np.ndarray:
        return self.phase_bullet_dir[:, -1]

    def frame(self, step: int, phase: int = -1) -> BoardFrame:
        """The board at the end of `phase` (default: the last) of `step`."""
        if not 0 <= step <= self.steps:
            raise IndexError(f"episode {self.episode} has steps 0..{self.steps}, not {step}")
        p = phase % len(PHASES)
        ax, ay = self.map.xy(self.phase_agent_cell[step, p])
        agents = [AgentState(name, TEAMS[self.agent_team[i]], int(ax[i]), int(ay[i]),
                             bool(self.phase_alive[step, p, i]), float(self.phase_health[step, p, i]),
                             int(self.phase_ammo[step, p, i]), int(self.action[step, i]))
                  for i, name in enumerate(self.agents)]
        bx, by = self.map.xy(self.phase_bullet_cell[step, p])
        bullets = [BulletState(name, TEAMS[self.bullet_team[i]], int(bx[i]), int(by[i]),
                               int(self.phase_bullet_dir[step, p, i]))
                   for i, name in enumerate(self.bullets) if self.phase_bullet_cell[step, p, i] >= 0]
        f = self.firings
        rows = [i for i in f.at(step) if f.phase[i] <= p]
        firings = [{"rule": f.rule[i], "bindings": f.bindings[i], "head": f.head[i],
                    "phase": PHASES[f.phase[i]], "old": f.old[i].tolist(), "new": f.new[i].tolist(),
                    "cell": int(f.cell[i])} for i in rows]
        return BoardFrame(step, p, agents, bullets, firings)


# ---- loading -------------------------------------------------------------------------------------------

def _parse_fact(name: str) -> tuple[str, list[str]]:
    pred, _, rest = name.partition("(")
    return pred, rest.rstrip(")").split(",") if rest else []


@dataclass
class _Cast:
    """Who plays, read from the run's facts."""
    map: BoardMap
    agents: list[str]
    agent_team: np.ndarray
    bullets: list[str]
    bullet_team: np.ndarray
    bullet_owner: np.ndarray
    hits_to_kill: int


def read_cast(con: RunConnection) -> _Cast:
    """The map, agents and bullets from the run's facts (tracelab/game/facts.py)."""
    facts: dict[str, list[list[str]]] = {}
    for (name,) in con.execute("SELECT name FROM raw.facts").fetchall():
        pred, args = _parse_fact(name)
        facts.setdefault(pred, []).append(args)
    if not facts.get("edgeDown") or not facts.get("team"):
        raise ValueError("this run has no grid-world facts (edgeDown, team): it is not a game of "
                         "rules/gridworld/game.rules")
    width, height = len(facts["edgeDown"]), len(facts["edgeLeft"])
    team_of = {a: TEAMS.index(t) for a, t in facts["team"]}
    agents = sorted(team_of, key=lambda a: (team_of[a], _ordinal(a)))
    agent_index = {a: i for i, a in enumerate(agents)}
    bases = np.zeros((2, 2), dtype=np.int64)
    for a, cell in facts.get("enemyBase", []):
        c = int(cell)
        bases[1 - team_of[a]] = (c % width, c // width)
    owner = dict(facts.get("owner", []))
    bullets = sorted(owner, key=lambda b: (team_of[owner[b]], agent_index[owner[b]], _ordinal(b)))
    mountains = np.array(sorted((int(c) % width, int(c) // width) for (c,) in facts.get("mountain", [])),
                         dtype=np.int64).reshape(-1, 2)
    kill_levels = [int(q.rsplit("_", 1)[1]) for (q,) in facts.get("killAt", [])]
    return _Cast(BoardMap(width, height, mountains, bases), agents,
                 np.array([team_of[a] for a in agents], dtype=np.int64), bullets,
                 np.array([team_of[owner[b]] for b in bullets], dtype=np.int64),
                 np.array([agent_index[owner[b]] for b in bullets], dtype=np.int64),
                 min(kill_levels) if kill_levels else 1)


def _ordinal(name: str) -> tuple[int, ...]:
    """red-bullet-1-10 sorts after red-bullet-1-2."""
    return tuple(int(p) for p in name.split("-") if p.isdigit())


def _health_scale(con: RunConnection, hits_to_kill: int) -> tuple[float, float]:
    """(start health, damage per hit): the scenario's, from the run's config if it holds the scenario's
    TOML (as `tracelab play` writes it), else health 1 split evenly over the hits that kill."""
    try:
        text = run_config(con).get("scenario")
        if isinstance(text, str) and "\n" in text:
            s = tomllib.loads(text)
            return float(s.get("health", 1.0)), float(s.get("damage", 1.0))
    except (ValueError, TypeError, tomllib.TOMLDecodeError):
        pass
    return 1.0, 1.0 / hits_to_kill


def rule_phases(con: RunConnection) -> np.ndarray:
    """Phase index of each rule id (0 where the run's program lacks the game's sections)."""
    rows = con.execute("SELECT rule, name, line FROM raw.rules ORDER BY rule").fetchall()
    phases = np.zeros(max((r for r, _, _ in rows), default=-1) + 1, dtype=np.int64)
    line_of = {name: line for _, name, line in rows}
    starts = [line_of.get(name) for name in PHASE_STARTS]
    if any(s is None for s in starts):
        return phases
    for rule, _, line in rows:
        phases[rule] = sum(line >= s for s in starts)
    return phases


class _Vocabulary:
    """The run's atoms decoded for the board (read again when an episode names an atom not yet read: the
    vocabulary of a live run grows), and the texts of atoms and groundings, cached."""

    def __init__(self, con: RunConnection, cast: _Cast) -> None:
        self.con, self.cast = con, cast
        rules = con.execute("SELECT rule, name, variables FROM raw.rules ORDER BY rule").fetchall()
        self.rule_name = {r: name for r, name, _ in rules}
        self.rule_vars = {r: list(v or ()) for r, _, v in rules}
        self.nodes: list[str] = []
        self.n_atoms = 0
        self._grounding_text: dict[int, str] = {}
        self._grounding_names: dict[int, tuple[int, int]] = {}   # first agent, first bullet it names
        self._atom_text: dict[int, str] = {}
        self.read_atoms()

    def read_atoms(self) -> None:
        self.nodes = [n for (n,) in self.con.execute("SELECT name FROM raw.nodes ORDER BY node").fetchall()]
        labels = dict(self.con.execute("SELECT label, name FROM raw.labels").fetchall())
        cols = self.con.sql("SELECT atom, label, arg0, arg1 FROM raw.atoms ORDER BY atom").fetchnumpy()
        n = int(cols["atom"].max()) + 1 if len(cols["atom"]) else 0
        self.label = np.full(n, -1, dtype=np.int64)
        self.arg0 = np.full(n, -1, dtype=np.int64)
        self.arg1 = np.full(n, -1, dtype=np.int64)
        self.label[cols["atom"]], self.arg0[cols["atom"]] = cols["label"], cols["arg0"]
        self.arg1[cols["atom"]] = cols["arg1"]
        self.label_names = labels
        self.n_atoms = n
        # what each node is on the board; one extra -1 at the end, so that node -1 (no argument) maps to -1
        agent_index = {a: i for i, a in enumerate(self.cast.agents)}
        bullet_index = {b: i for i, b in enumerate(self.cast.bullets)}
        n_cells = self.cast.map.width * self.cast.map.height
        self.node_agent = np.array([agent_index.get(x, -1) for x in self.nodes] + [-1], dtype=np.int64)
        self.node_bullet = np.array([bullet_index.get(x, -1) for x in self.nodes] + [-1], dtype=np.int64)
        self.node_cell = np.array([int(x) if x.isdigit() and int(x) < n_cells else -1 for x in self.nodes]
                                  + [-1], dtype=np.int64)
        # the cell an atom names (its first cell argument), -1 if none
        self.atom_cell = np.where(self.node_cell[self.arg0] >= 0, self.node_cell[self.arg0],
                                  self.node_cell[self.arg1])
        self.state = _state_atoms(self)

    def cover(self, atoms: np.ndarray) -> None:
        if len(atoms) and int(atoms.max()) >= self.n_atoms:
            self.read_atoms()

    def atom_text(self, atom: int) -> str:
        text = self._atom_text.get(atom)
        if text is None:
            args = [self.nodes[a] for a in (self.arg0[atom], self.arg1[atom]) if a >= 0]
            text = f"{self.label_names.get(int(self.label[atom]), '?')}({','.join(args)})"
            self._atom_text[atom] = text
        return text

    def grounding_texts(self, groundings: np.ndarray) -> list[str]:
        """'A=red-agent-1, X=16' for each grounding id (read from the run once each)."""
        missing = sorted({int(g) for g in groundings.tolist()} - self._grounding_text.keys())
        if missing:
            rows = self.con.execute("SELECT grounding, rule, var_values FROM raw.groundings "
                                    "WHERE grounding IN (SELECT unnest(?))", [missing]).fetchall()
            for g, rule, values in rows:
                values = values or []
                self._grounding_text[g] = ", ".join(
                    f"{var}={self.nodes[v]}" for var, v in zip(self.rule_vars.get(rule, []), values))
                agents = [a for a in self.node_agent[values].tolist() if a >= 0]
                bullets = [b for b in self.node_bullet[values].tolist() if b >= 0]
                self._grounding_names[g] = (agents[0] if agents else -1, bullets[0] if bullets else -1)
        return [self._grounding_text.get(int(g), "") for g in groundings.tolist()]

    def grounding_names(self, groundings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The first agent and the first bullet (indices, -1 if none) each grounding's bindings name
        (after grounding_texts read them)."""
        pairs = [self._grounding_names.get(g, (-1, -1)) for g in groundings.tolist()]
        both = np.array(pairs, dtype=np.int64).reshape(-1, 2)
        return both[:, 0], both[:, 1]


def check_board(con: RunConnection) -> None:
    """Refuse a run that does not declare this decoder's board (ValueError saying what it declares)."""
    board = run_board(con)
    if board is None:
        raise ValueError("this run has no board (a reasoning run, or a run whose writer declared none): "
                         "its episodes are a trace, not games")
    if board != BOARD:
        raise ValueError(f"this run declares the board {board!r}; tracelab draws only {BOARD!r}")


class BoardLoader:
    """Loads episodes of one run; what the episodes share (cast, rules, vocabulary) is read once."""

    def __init__(self, con: RunConnection) -> None:
        check_board(con)
        self.con = con
        self.cast = read_cast(con)
        self.health0, self.damage = _health_scale(con, self.cast.hits_to_kill)
        self.phase_of_rule = rule_phases(con)
        self.vocab = _Vocabulary(con, self.cast)
        self._read: dict[int, tuple[dict[str, np.ndarray], str | None]] = {}   # prefetched, not yet loaded

    def prefetch(self, episodes: list[int]) -> np.ndarray:
        """Read the change rows, outcomes and grounding texts of these episodes in one query each (a
        replay of many short games otherwise pays a few DuckDB round-trips per game); `load` then takes
        each episode from memory, once. Returns the grounding ids their rows name (for a why-tree
        reader to prefetch too)."""
        if not episodes:
            return np.zeros(0, np.int64)
        ch = self.con.sql(f"SELECT episode, {_CHANGE_COLUMNS} FROM raw.changes "
                          "WHERE episode IN (SELECT unnest($e::BIGINT[])) ORDER BY episode, seq",
                          params={"e": list(episodes)}).fetchnumpy()
        col = {name: np.asarray(v) for name, v in ch.items()}
        outcomes = dict(self.con.execute("SELECT episode, outcome FROM raw.episode_end "
                                         "WHERE episode IN (SELECT unnest(?::BIGINT[]))",
                                         [list(episodes)]).fetchall())
        self.vocab.cover(col["atom"])
        self.vocab.grounding_texts(col["grounding"][col["cause_kind"] == 2])
        ep = col.pop("episode")
        bounds = np.flatnonzero(np.r_[True, ep[1:] != ep[:-1], True]) if len(ep) else np.zeros(1, np.int64)
        for lo, hi in zip(bounds[:-1].tolist(), bounds[1:].tolist()):
            self._read[int(ep[lo])] = ({k: v[lo:hi] for k, v in col.items()}, outcomes.get(int(ep[lo])))
        return np.unique(col["grounding"])

    def load(self, episode: int) -> EpisodeBoard:
        """Rebuild one episode's board (see the module docstring); prefetched episodes come from memory."""
        con, cast = self.con, self.cast
        if episode not in self._read:
            self.prefetch([episode])
        if episode not in self._read:
            raise KeyError(f"episode {episode} has no trace rows")
        col, outcome = self._read.pop(episode)
        t = col["t"].astype(np.int64)
        t = t - t.min()
        is_rule = (col["cause_kind"] == 2) & (col["pass_no"] > 0)
        rule_id = np.where(is_rule, col["cause_id"], 0)
        if is_rule.any() and rule_id.max() >= len(self.phase_of_rule):
            self.phase_of_rule = rule_phases(con)
        phase = np.where(is_rule, self.phase_of_rule[rule_id], 0)
        # hold the phase monotone within a step: running max of step·P + phase
        n_ph = len(PHASES)
        phase = np.maximum.accumulate(t * n_ph + phase) - t * n_ph
        steps = int(t.max())
        state = _replay_state(cast, self.vocab.state, col, t, phase, steps)
        hits, alive = state["hits"], state["alive"]
        health = np.where(alive, np.maximum(self.health0 - hits * self.damage, 0.0), 0.0)
        health = np.where(health <= 1e-9, 0.0, health)
        firings = _firings(self.vocab, cast, t, phase, col, state["agent_cell"], state["bullet_cell"])
        return EpisodeBoard(episode, cast.map, cast.agents, cast.agent_team, cast.bullets, cast.bullet_team,
                            cast.bullet_owner, self.health0, state["agent_cell"], alive, health,
                            state["ammo"], state["bullet_cell"], state["bullet_dir"], state["action"],
                            firings, outcome, col)


def load_episode(con: RunConnection, episode: int) -> EpisodeBoard:
    """One episode's board; to load several episodes of a run, keep a BoardLoader."""
    return BoardLoader(con).load(episode)


@dataclass
class _Atoms:
    """The state atoms of the vocabulary, decoded: per atom id, which kind, which entity, which value."""
    kind: np.ndarray               # [n_atoms] int: index into _STATE_LABELS, -1 for other atoms
    entity: np.ndarray             # agent or bullet index (atLoc: agents then bullets)
    value: np.ndarray              # cell id, direction, or -1


def _state_atoms(vocab: _Vocabulary) -> _Atoms:
    """Decoded by node tables, not atom by atom (a 5v5 game on 16x16 has ~10^4 atLoc atoms)."""
    n_agents = len(vocab.cast.agents)
    agent, bullet = vocab.node_agent, vocab.node_bullet          # index -1 (no argument) gives -1
    number = np.array([int(x) if x.isdigit() else -1 for x in vocab.nodes] + [-1], dtype=np.int64)
    direction = np.array([DIRECTIONS.index(x) if x in DIRECTIONS else -1 for x in vocab.nodes] + [-1],
                         dtype=np.int64)
    name_of = {lid: name for lid, name in vocab.label_names.items() if name in _STATE_LABELS}
    label_kind = np.full(max(vocab.label_names, default=-1) + 2, -1, dtype=np.int64)
    for lid, name in name_of.items():
        label_kind[lid] = _STATE_LABELS.index(name)
    kind = label_kind[vocab.label]                                 # label -1 (no atom) maps to -1
    a0, a1 = vocab.arg0, vocab.arg1
    at, hit = _STATE_LABELS.index("atLoc"), _STATE_LABELS.index("hitMe")
    on_bullet = (kind == _STATE_LABELS.index("dir")) | (kind == _STATE_LABELS.index("spent"))
    # atLoc(E, C): agents, then bullets; hitMe(B, A): the agent is the second argument; dir(B, D) and
    # spent(B): a bullet; alive(A), move(A, D), shoot(A, D): an agent
    entity = np.select([kind == at, kind == hit, on_bullet],
                       [np.where(agent[a0] >= 0, agent[a0], np.where(bullet[a0] >= 0, n_agents + bullet[a0], -1)),
                        agent[a1], bullet[a0]], agent[a0])
    value = np.select([kind == at, kind == hit, kind == _STATE_LABELS.index("spent")],
                      [number[a1], -1, -1], direction[a1])
    keep = (kind >= 0) & (entity >= 0)
    return _Atoms(np.where(keep, kind, -1), np.where(keep, entity, -1), np.where(keep, value, -1))


def _replay_state(cast: _Cast, atoms: _Atoms, col: dict[str, np.ndarray], t: np.ndarray,
                  phase: np.ndarray, steps: int) -> dict[str, np.ndarray]:
    """Apply the state atoms' changes in engine order, recording the state at each phase's end."""
    n_a, n_b, n_ph = len(cast.agents), len(cast.bullets), len(PHASES)
    atom = col["atom"]
    known = atom < len(atoms.kind)
    kind = np.where(known, atoms.kind[np.where(known, atom, 0)], -1)
    rows = np.flatnonzero(kind >= 0)
    slot = (t * n_ph + phase)[rows]
    kinds, ents, vals = kind[rows], atoms.entity[atom[rows]], atoms.value[atom[rows]]
    true = (col["new_lower"][rows] >= 1.0).tolist()

    cell = np.full(n_a + n_b, -1, dtype=np.int64)   # agents, then bullets
    alive = np.zeros(n_a, dtype=bool)
    hits = np.zeros(n_a, dtype=np.int64)
    spent = np.zeros(n_b, dtype=bool)
    direction = np.full(n_b, -1, dtype=np.int64)
    move = np.full(n_a, -1, dtype=np.int64)         # direction of the move atom set true, -1 none
    shoot = np.full(n_a, -1, dtype=np.int64)
    n_slots = (steps + 1) * n_ph
    out_cell = np.empty((n_slots, n_a + n_b), dtype=np.int64)
    out_alive = np.empty((n_slots, n_a), dtype=bool)
    out_hits = np.empty((n_slots, n_a), dtype=np.int64)
    out_spent = np.empty((n_slots, n_b), dtype=bool)
    out_dir = np.empty((n_slots, n_b), dtype=np.int64)
    out_action = np.full((steps + 1, n_a), NO_ACTION, dtype=np.int64)
    written = 0
    action_step = 0                         # the first step whose action is not yet in out_action

    def record(upto: int) -> None:          # the current state is the state of slots [written, upto)
        nonlocal written
        out_cell[written:upto], out_alive[written:upto], out_hits[written:upto] = cell, alive, hits
        out_spent[written:upto], out_dir[written:upto] = spent, direction
        written = upto

    AT, ALIVE, HIT, SPENT, DIR, MOVE, _SHOOT = range(len(_STATE_LABELS))
    for s, k, e, v, on in zip(slot.tolist(), kinds.tolist(), ents.tolist(), vals.tolist(), true):
        if s >= written:
            if s // n_ph > action_step:     # the steps before this row's are over: their actions are final
                _set_action(out_action[action_step:s // n_ph], move, shoot)
                action_step = s // n_ph
            record(s)
        if k == AT:
            if on:
                cell[e] = v
            elif cell[e] == v:
                cell[e] = -1
        elif k == ALIVE:
            alive[e] = on
        elif k == HIT:
            hits[e] += 1 if on else -1
        elif k == SPENT:
            spent[e] = on
        elif k == DIR:
            if on:
                direction[e] = v
            elif direction[e] == v:
                direction[e] = -1
        else:
            acts = move if k == MOVE else shoot
            if on:
                acts[e] = v
            elif acts[e] == v:
                acts[e] = -1
    _set_action(out_action[action_step:], move, shoot)
    record(n_slots)
    out_action[0] = NO_ACTION

    def shaped(a: np.ndarray) -> np.ndarray:
        return a.reshape(steps + 1, n_ph, *a.shape[1:])

    bullet_cell = shaped(out_cell[:, n_a:])
    on_board = bullet_cell >= 0
    own = cast.bullet_owner
    ammo = np.zeros((n_slots, n_a), dtype=np.int64)
    np.add.at(ammo.T, own, ~out_spent.T)
    return {"agent_cell": shaped(out_cell[:, :n_a]), "alive": shaped(out_alive), "hits": shaped(out_hits),
            "ammo": shaped(ammo), "bullet_cell": bullet_cell,
            "bullet_dir": np.where(on_board, shaped(out_dir), -1), "action": out_action}


def _set_action(out: np.ndarray, move: np.ndarray, shoot: np.ndarray) -> None:
    out[:] = np.where(move >= 0, move, np.where(shoot >= 0, shoot + 4, NOTHING))


def _firings(vocab: _Vocabulary, cast: _Cast, t: np.ndarray, phase: np.ndarray, col: dict[str, np.ndarray],
             agent_cell: np.ndarray, bullet_cell: np.ndarray) -> Firings:
    rows = np.flatnonzero(col["cause_kind"] == 2)
    rule = [vocab.rule_name.get(r, f"rule#{r}") for r in col["cause_id"][rows].tolist()]
    groundings, atoms = col["grounding"][rows], col["atom"][rows]
    bindings = vocab.grounding_texts(groundings)
    head = [vocab.atom_text(a) for a in atoms.tolist()]
    agent, bullet = vocab.grounding_names(groundings)
    step, ph = t[rows], phase[rows]
    # where on the board: the head's cell, else the named agent's cell, else the named bullet's
    cell = vocab.atom_cell[atoms]
    by_agent = (cell < 0) & (agent >= 0)
    cell[by_agent] = agent_cell[step[by_agent], ph[by_agent], agent[by_agent]]
    by_bullet = (cell < 0) & (agent < 0) & (bullet >= 0)
    cell[by_bullet] = bullet_cell[step[by_bullet], ph[by_bullet], bullet[by_bullet]]
    return Firings(step, ph, col["seq"][rows], rule, bindings, head,
                   np.stack([col["old_lower"][rows], col["old_upper"][rows]], axis=1),
                   np.stack([col["new_lower"][rows], col["new_upper"][rows]], axis=1), agent, cell)
