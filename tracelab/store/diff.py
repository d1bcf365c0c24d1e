"""The first divergence of two episodes, of one run or of two runs, with what they were given and where
they ended (tracelab.store.diff_state: the rules and facts that differ, the atoms whose final bounds
differ).

Episodes are aligned on time relative to their start (episode_begin.t_start, else their first trace
row). At each relative time a change is the same in both when it sets the same atom (by its text) to the
same bound by the same cause (the same rule or fact by name, the same policy; any action or reset); the
first relative time with a change in one episode and not the other is where their states diverge.
Separately, the first step where the agents' actions differ.

Each episode is read from its own run's connection (the sandboxed read path); the comparison runs in a
scratch in-memory DuckDB over the two Arrow tables, which reaches no file."""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import duckdb

from tracelab.store.diff_state import (
    EndDifference,
    GivenDifference,
    end_difference,
    given_difference,
    render_end,
    render_given,
)
from tracelab.store.reader import RunConnection
from tracelab.store.sandbox import lock_down, sandbox_connection

# One episode's changes as comparable keys: names and texts, not ids, so that two runs compare too.
_CHANGES_SQL = """
SELECT c.seq, c.atom, c.new_lower, c.new_upper, c.cause_kind,
       CASE WHEN c.cause_kind IN (1, 4) THEN '' ELSE c.rule END AS cause,
       c.t - coalesce((SELECT t_start FROM raw.episode_begin WHERE episode = $e),
                      (SELECT min(t) FROM raw.changes WHERE episode = $e)) AS rt
FROM changes c WHERE c.episode = $e
"""

_STATE_SQL = """
WITH na AS (SELECT *, row_number() OVER (PARTITION BY rt, atom, new_lower, new_upper, cause_kind, cause
                                           ORDER BY seq) AS k FROM side_a),
     nb AS (SELECT *, row_number() OVER (PARTITION BY rt, atom, new_lower, new_upper, cause_kind, cause
                                           ORDER BY seq) AS k FROM side_b),
unmatched AS (
  SELECT coalesce(na.rt, nb.rt) AS rt, na.seq AS seq_a, nb.seq AS seq_b
  FROM na FULL JOIN nb USING (rt, atom, new_lower, new_upper, cause_kind, cause, k)
  WHERE na.seq IS NULL OR nb.seq IS NULL
)
SELECT rt, seq_a, seq_b FROM unmatched WHERE rt = (SELECT min(rt) FROM unmatched)
"""

_STEPS_SQL = "SELECT step, agent, action FROM raw.steps WHERE episode = $e"

_ACTION_SQL = """
SELECT step, agent, sa.action AS action_a, sb.action AS action_b
FROM steps_a sa FULL JOIN steps_b sb USING (step, agent)
WHERE sa.action IS DISTINCT FROM sb.action
ORDER BY step, agent LIMIT 1
"""

_ROW_COLUMNS = "episode, t, pass_no, atom, old_lower, old_upper, new_lower, new_upper, rule, seq"


@dataclass
class Divergence:
    episode_a: int
    episode_b: int
    rel_t: int | None                      # first relative time with differing changes (None: same)
    t_a: int | None = None                 # that time in each episode's own clock
    t_b: int | None = None
    only_in_a: list[dict[str, Any]] = field(default_factory=list)
    only_in_b: list[dict[str, Any]] = field(default_factory=list)
    first_action_difference: dict[str, Any] | None = None
    outcome_a: str | None = None
    outcome_b: str | None = None
    run_a: str | None = None               # the runs' names when two runs are compared
    run_b: str | None = None
    given: GivenDifference = field(default_factory=GivenDifference)   # rules and facts of one side only
    end: EndDifference = field(default_factory=EndDifference)         # atoms with other bounds at the end

    @property
    def identical(self) -> bool:
        return self.rel_t is None and self.first_action_difference is None and self.given.same

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "identical": self.identical}

    def name(self, side: str) -> str:
        """How the text names an episode: '3', or 'runA:3' across runs."""
        run, ep = (self.run_a, self.episode_a) if side == "a" else (self.run_b, self.episode_b)
        return f"{run}:{ep}" if run is not None else str(ep)


def _rows(con: RunConnection, seqs: list[int]) -> list[dict[str, Any]]:
    if not seqs:
        return []
    cur = con.execute(f"SELECT {_ROW_COLUMNS} FROM changes WHERE seq IN (SELECT unnest(?::BIGINT[])) "
                      "ORDER BY seq", [seqs])
    names = [d[0] for d in cur.description]
    return [dict(zip(names, r)) for r in cur.fetchall()]


def _check_present(con: RunConnection, episode: int, where: str) -> None:
    row = con.execute("SELECT EXISTS (SELECT 1 FROM raw.changes WHERE episode = $e) OR "
                      "EXISTS (SELECT 1 FROM raw.steps WHERE episode = $e)", {"e": episode}).fetchall()
    if not row[0][0]:  # fetchall: DuckDB 2.0 holds the connection until a result is read to its end
        raise KeyError(f"episode {episode} has no trace rows and no steps in {where}")


def _arrow(con: RunConnection, sql: str, episode: int) -> Any:
    return con.sql(sql, params={"e": episode}).to_arrow_table()


def _scratch() -> duckdb.DuckDBPyConnection:
    """An in-memory database for comparing the two sides: no files, no extensions, no network."""
    con = sandbox_connection()
    lock_down(con)
    return con


def first_divergence(con: RunConnection, a: int, b: int, con_b: RunConnection | None = None,
                     run_names: tuple[str, str] | None = None) -> Divergence:
    """Where episode `a` of `con`'s run and episode `b` first diverge; `b` is read from `con_b` when
    given (another run; `run_names` then name the two runs in messages and output)."""
    same_run = con_b is None
    con_b = con if con_b is None else con_b
    if same_run and a == b:
        raise ValueError(f"diff needs two different episodes, got {a} twice")
    names = run_names or ("this run", "this run")
    _check_present(con, a, names[0])
    _check_present(con_b, b, names[1])
    scratch = _scratch()
    try:
        scratch.register("side_a", _arrow(con, _CHANGES_SQL, a))
        scratch.register("side_b", _arrow(con_b, _CHANGES_SQL, b))
        scratch.register("steps_a", _arrow(con, _STEPS_SQL, a))
        scratch.register("steps_b", _arrow(con_b, _STEPS_SQL, b))
        rows = scratch.execute(_STATE_SQL).fetchall()
        # fetchall: DuckDB 2.0 holds the connection until a result is read to its end
        act = next(iter(scratch.execute(_ACTION_SQL).fetchall()), None)
        given = given_difference(scratch, con, a, con_b, b)
        end = end_difference(scratch, con, a, con_b, b)
    finally:
        scratch.close()
    d = Divergence(a, b, rel_t=None, given=given, end=end)
    if run_names is not None and not same_run:
        d.run_a, d.run_b = run_names
    if rows:
        d.rel_t = int(rows[0][0])
        d.only_in_a = _rows(con, [int(r[1]) for r in rows if r[1] is not None])
        d.only_in_b = _rows(con_b, [int(r[2]) for r in rows if r[2] is not None])
        d.t_a, d.t_b = _clock(con, a, d.rel_t), _clock(con_b, b, d.rel_t)
    if act is not None:
        d.first_action_difference = dict(zip(("step", "agent", "action_a", "action_b"), act))
    d.outcome_a, d.outcome_b = _outcome(con, a), _outcome(con_b, b)
    return d


def _outcome(con: RunConnection, episode: int) -> str | None:
    row = con.execute("SELECT outcome FROM episodes WHERE episode = ?", [episode]).fetchone()
    return None if row is None else row[0]


def _clock(con: RunConnection, episode: int, rel_t: int) -> int:
    row = con.execute("SELECT coalesce((SELECT t_start FROM raw.episode_begin WHERE episode = $e), "
                      "(SELECT min(t) FROM raw.changes WHERE episode = $e))", {"e": episode}).fetchone()
    return int(row[0] or 0) + rel_t


def render_divergence(d: Divergence) -> str:
    def bound(lo: float, up: float) -> str:
        return f"[{lo:g},{up:g}]"

    ea, eb = d.name("a"), d.name("b")
    lines = [f"episodes {ea} ({d.outcome_a or 'unfinished'}) and {eb} ({d.outcome_b or 'unfinished'})"]
    if d.identical:
        lines.append("no divergence: the same rules and facts, the same changes by the same causes at the "
                     "same times, the same actions")
        return "\n".join(lines)
    lines += render_given(d.given, ea, eb)
    lines += render_end(d.end, ea, eb)
    if d.first_action_difference:
        f = d.first_action_difference
        lines.append(f"first different action: step {f['step']} agent {f['agent'] or '-'}: "
                     f"{f['action_a']} in {ea}, {f['action_b']} in {eb}")
    if d.rel_t is None:
        lines.append("the traces do not diverge")
        return "\n".join(lines)
    lines.append(f"first divergence of the trace: {d.rel_t} steps in (t={d.t_a} in episode {ea}, "
                 f"t={d.t_b} in episode {eb})")
    for label, rows in ((f"only in {ea}", d.only_in_a), (f"only in {eb}", d.only_in_b)):
        lines.append(f"  {label}: {len(rows)} change(s)")
        for r in rows:
            lines.append(f"    t={r['t']} pass {r['pass_no']}  {r['atom']}  "
                         f"{bound(r['old_lower'], r['old_upper'])} -> {bound(r['new_lower'], r['new_upper'])}"
                         f"  by {r['rule']}")
    return "\n".join(lines)
