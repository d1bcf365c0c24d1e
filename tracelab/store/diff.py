"""The first divergence of two episodes of one run.

Episodes are aligned on time relative to their start (episode_begin.t_start, else their first trace
row). At each relative time a change is the same in both when it sets the same atom to the same bound by
the same cause (the same rule, fact, policy; any action or reset); the first relative time with a change in one episode and not
the other is where their states diverge. Separately, the first step where the agents' actions differ."""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from tracelab.store.reader import RunConnection

_STATE_SQL = """
WITH base AS (
  SELECT c.episode, c.seq, c.atom, c.new_lower, c.new_upper, c.cause_kind,
         CASE WHEN c.cause_kind = 1 THEN -1 ELSE c.cause_id END AS cause_id,  -- actions: any index
         c.t - coalesce(b.t_start, min(c.t) OVER (PARTITION BY c.episode)) AS rt
  FROM raw.changes c LEFT JOIN raw.episode_begin b ON b.episode = c.episode
  WHERE c.episode IN ($a, $b)
), numbered AS (
  SELECT *, row_number() OVER (PARTITION BY episode, rt, atom, new_lower, new_upper, cause_kind, cause_id
                               ORDER BY seq) AS k
  FROM base
), ea AS (SELECT * FROM numbered WHERE episode = $a),
   eb AS (SELECT * FROM numbered WHERE episode = $b),
unmatched AS (
  SELECT coalesce(ea.rt, eb.rt) AS rt, ea.seq AS seq_a, eb.seq AS seq_b
  FROM ea FULL JOIN eb USING (rt, atom, new_lower, new_upper, cause_kind, cause_id, k)
  WHERE ea.seq IS NULL OR eb.seq IS NULL
)
SELECT rt, seq_a, seq_b FROM unmatched WHERE rt = (SELECT min(rt) FROM unmatched)
"""

_ACTION_SQL = """
WITH sa AS (SELECT step, agent, action FROM raw.steps WHERE episode = $a),
     sb AS (SELECT step, agent, action FROM raw.steps WHERE episode = $b)
SELECT step, agent, sa.action AS action_a, sb.action AS action_b
FROM sa FULL JOIN sb USING (step, agent)
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

    @property
    def identical(self) -> bool:
        return self.rel_t is None and self.first_action_difference is None

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "identical": self.identical}


def _rows(con: RunConnection, seqs: list[int]) -> list[dict[str, Any]]:
    if not seqs:
        return []
    cur = con.execute(f"SELECT {_ROW_COLUMNS} FROM changes WHERE seq IN (SELECT unnest(?::BIGINT[])) "
                      "ORDER BY seq", [seqs])
    names = [d[0] for d in cur.description]
    return [dict(zip(names, r)) for r in cur.fetchall()]


def first_divergence(con: RunConnection, a: int, b: int) -> Divergence:
    if a == b:
        raise ValueError(f"diff needs two different episodes, got {a} twice")
    present = {e for (e,) in con.execute(
        "SELECT DISTINCT episode FROM raw.changes WHERE episode IN (?, ?) UNION "
        "SELECT DISTINCT episode FROM raw.steps WHERE episode IN (?, ?)", [a, b, a, b]).fetchall()}
    for e in (a, b):
        if e not in present:
            raise KeyError(f"episode {e} has no trace rows and no steps in this run")
    params = {"a": a, "b": b}
    rows = con.execute(_STATE_SQL, params).fetchall()
    d = Divergence(a, b, rel_t=None)
    if rows:
        d.rel_t = int(rows[0][0])
        d.only_in_a = _rows(con, [int(r[1]) for r in rows if r[1] is not None])
        d.only_in_b = _rows(con, [int(r[2]) for r in rows if r[2] is not None])
        d.t_a, d.t_b = _clock(con, a, d.rel_t), _clock(con, b, d.rel_t)
    act = con.execute(_ACTION_SQL, params).fetchone()
    if act is not None:
        d.first_action_difference = dict(zip(("step", "agent", "action_a", "action_b"), act))
    outcomes = dict(con.execute("SELECT episode, outcome FROM episodes WHERE episode IN (?, ?)",
                                [a, b]).fetchall())
    d.outcome_a, d.outcome_b = outcomes.get(a), outcomes.get(b)
    return d


def _clock(con: RunConnection, episode: int, rel_t: int) -> int:
    row = con.execute("SELECT coalesce((SELECT t_start FROM raw.episode_begin WHERE episode = $e), "
                      "(SELECT min(t) FROM raw.changes WHERE episode = $e))", {"e": episode}).fetchone()
    return int(row[0] or 0) + rel_t


def render_divergence(d: Divergence) -> str:
    def bound(lo: float, up: float) -> str:
        return f"[{lo:g},{up:g}]"

    lines = [f"episodes {d.episode_a} ({d.outcome_a or 'unfinished'}) and {d.episode_b} "
             f"({d.outcome_b or 'unfinished'})"]
    if d.identical:
        lines.append("no divergence: the same changes by the same causes at the same times, the same actions")
        return "\n".join(lines)
    if d.first_action_difference:
        f = d.first_action_difference
        lines.append(f"first different action: step {f['step']} agent {f['agent'] or '-'}: "
                     f"{f['action_a']} in {d.episode_a}, {f['action_b']} in {d.episode_b}")
    if d.rel_t is None:
        lines.append("the traces do not diverge")
        return "\n".join(lines)
    lines.append(f"first divergence of the trace: {d.rel_t} steps in (t={d.t_a} in episode {d.episode_a}, "
                 f"t={d.t_b} in episode {d.episode_b})")
    for label, rows in ((f"only in {d.episode_a}", d.only_in_a), (f"only in {d.episode_b}", d.only_in_b)):
        lines.append(f"  {label}: {len(rows)} change(s)")
        for r in rows:
            lines.append(f"    t={r['t']} pass {r['pass_no']}  {r['atom']}  "
                         f"{bound(r['old_lower'], r['old_upper'])} -> {bound(r['new_lower'], r['new_upper'])}"
                         f"  by {r['rule']}")
    return "\n".join(lines)
