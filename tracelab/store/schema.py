"""The trace store's tables: their columns and types (the same in Parquet parts and in a sealed .duckdb
file; as Arrow schemas for the writers) and the readable SQL views built on them.

Storage tables live in the DuckDB schema `raw`; the views users query (`changes`, `firings`, `episodes`,
`steps`, `metrics`, `rules`, `facts`, `atoms`, `groundings`, `edges`, `decisions`, `action_values`, `rewards`,
`returns`, `run`) live in `main` and only read `raw.*`,
so the same view text serves a live run (raw.* are views over Parquet parts) and a sealed one (raw.* are
tables)."""
from __future__ import annotations

import re
from functools import cache
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # built on first use (arrow_schema): a reading command never loads pyarrow for it
    import pyarrow as pa

# The engine's cause kinds (tracelab.engine.CAUSE_*), as the store names them: external facts are the
# agents' actions.
CAUSE_NAMES = {0: "fact", 1: "action", 2: "rule", 3: "policy", 4: "reset"}

# Each stored table's columns and their DuckDB types, the one statement of the schema: the Arrow schemas
# of the parts and of the writer's tables are built from it (arrow_schema), and a sealed file's catalog is
# checked against it (tracelab.store.sealed_catalog) without loading pyarrow. TIMESTAMP is UTC (naive:
# reading TIMESTAMPTZ into Python needs pytz).
# Tables in flush order: whatever a row refers to is written before it, so a reader that sees part of a
# flush never sees a change whose atom, rule or grounding is missing, nor an ended episode without its rows.
COLUMNS: dict[str, dict[str, str]] = {
    "nodes": {"node": "INTEGER", "name": "VARCHAR"},
    "labels": {"label": "INTEGER", "name": "VARCHAR", "arity": "TINYINT"},
    "atoms": {"atom": "INTEGER", "label": "INTEGER", "arg0": "INTEGER", "arg1": "INTEGER"},
    # The graph's edges (a reasoning run's GraphML, tracelab.store.graph_tables), node ids of `nodes`; an
    # undirected edge both ways. Its labels are the binary facts on the pair.
    "edges": {"source": "INTEGER", "target": "INTEGER"},
    "rules": {"rule": "INTEGER", "name": "VARCHAR", "text": "VARCHAR", "head": "VARCHAR", "delay": "INTEGER",
              "immediate": "BOOLEAN", "mode": "VARCHAR", "variables": "VARCHAR[]", "file": "VARCHAR",
              "line": "INTEGER"},
    # One row per clause of a rule: pos -1 is the head, 0.. the body in source order.
    "clauses": {"rule": "INTEGER", "pos": "INTEGER", "label": "VARCHAR", "args": "VARCHAR[]",
                "is_var": "BOOLEAN[]", "negated": "BOOLEAN", "lower": "DOUBLE", "upper": "DOUBLE",
                "text": "VARCHAR", "closed": "BOOLEAN"},
    "facts": {"fact": "INTEGER", "name": "VARCHAR", "text": "VARCHAR", "literal": "VARCHAR", "start": "INTEGER",
              "end": "INTEGER", "static": "BOOLEAN", "file": "VARCHAR", "line": "INTEGER",
              "episode": "BIGINT"},  # the one episode the fact belongs to, NULL: every one
    # The files the run's program was read from (a spec, its rule files), with their texts: in a part,
    # not in meta.json, whose readers refuse more than a few MiB (tracelab.store.sources).
    "sources": {"role": "VARCHAR", "path": "VARCHAR", "bytes": "BIGINT", "sha256": "VARCHAR", "text": "VARCHAR"},
    "policies": {"code": "INTEGER", "name": "VARCHAR"},
    "groundings": {"grounding": "INTEGER", "rule": "INTEGER", "body_atoms": "INTEGER[]",
                   "var_values": "INTEGER[]"},
    "episode_begin": {"episode": "BIGINT", "world": "INTEGER", "t_start": "INTEGER", "seed": "BIGINT",
                      "started_at": "TIMESTAMP", "info": "VARCHAR"},
    "changes": {"seq": "BIGINT", "episode": "BIGINT", "world": "INTEGER", "t": "INTEGER", "pass_no": "INTEGER",
                "atom": "INTEGER", "old_lower": "DOUBLE", "old_upper": "DOUBLE", "new_lower": "DOUBLE",
                "new_upper": "DOUBLE", "cause_kind": "TINYINT", "cause_id": "INTEGER", "grounding": "INTEGER",
                "n_sources": "SMALLINT"},
    "steps": {"episode": "BIGINT", "step": "INTEGER", "t": "INTEGER", "agent": "VARCHAR", "action": "INTEGER",
              "reward": "DOUBLE", "terminated": "BOOLEAN", "truncated": "BOOLEAN", "obs": "FLOAT[]"},
    # The run's actions (steps.action -> name; `position`: the action's place in decisions.values, NULL
    # for an action the policy does not offer), the policy's decision per agent and step, and each
    # step's reward split by term (tracelab.store.agent_rows): a term has a row where it was paid (its
    # value or its quantity not 0).
    "action_names": {"action": "INTEGER", "name": "VARCHAR", "position": "INTEGER"},
    # What each entry of steps.obs is: entry `position`, read as (obs // divisor) % size when `size` is
    # set (one number holding several parts: a Discrete space), and `labels[value]` the atom a value
    # stands for (an index part's), else the number itself.
    "observation_names": {"position": "INTEGER", "name": "VARCHAR", "divisor": "BIGINT", "size": "INTEGER",
                          "labels": "VARCHAR[]"},
    "decisions": {"episode": "BIGINT", "step": "INTEGER", "agent": "VARCHAR", "action": "INTEGER",
                  "output": "VARCHAR", "values": "FLOAT[]", "state_value": "DOUBLE", "explored": "BOOLEAN",
                  "epsilon": "DOUBLE", "mask": "BOOLEAN[]",
                  # a decomposed policy's (train --decompose) Q-values by reward term: `terms` names them,
                  # `term_values` holds each term's values of every action back to back (term-major,
                  # len(terms) x len(values)); NULL for any other policy
                  "terms": "VARCHAR[]", "term_values": "FLOAT[]"},
    # a reward term's row: `value` paid, `quantity` what its value per occurrence multiplied (a table
    # term's occurrences, a scaled atom's bound; NULL: not known, as in runs written before it was kept)
    "reward_terms": {"episode": "BIGINT", "step": "INTEGER", "agent": "VARCHAR", "term": "VARCHAR",
                     "value": "DOUBLE", "quantity": "DOUBLE"},
    "metrics": {"step": "BIGINT", "name": "VARCHAR", "value": "DOUBLE", "episode": "BIGINT", "time": "TIMESTAMP"},
    "episode_end": {"episode": "BIGINT", "steps": "INTEGER", "t_end": "INTEGER", "outcome": "VARCHAR",
                    "reward": "DOUBLE", "rewards": "VARCHAR", "ended_at": "TIMESTAMP", "info": "VARCHAR"},
}
# raw.run: the run's one metadata row (tracelab.store.meta.meta_table; config, rule files and versions as
# JSON text); not a part table, but stored in a sealed file beside the others.
RUN_COLUMNS: dict[str, str] = {
    "run_id": "VARCHAR", "command": "VARCHAR", "scenario": "VARCHAR", "seed": "BIGINT", "status": "VARCHAR",
    "started_at": "TIMESTAMP", "ended_at": "TIMESTAMP", "config": "VARCHAR", "rule_files": "VARCHAR",
    "versions": "VARCHAR", "pid": "BIGINT", "host": "VARCHAR", "board": "VARCHAR"}
# The stored tables of a sealed run.
STORED_COLUMNS: dict[str, dict[str, str]] = {**COLUMNS, "run": RUN_COLUMNS}


def _arrow_type(duckdb_type: str) -> "pa.DataType":
    import pyarrow as pa
    if duckdb_type.endswith("[]"):
        return pa.list_(_arrow_type(duckdb_type[:-2]))
    return {"TINYINT": pa.int8(), "SMALLINT": pa.int16(), "INTEGER": pa.int32(), "BIGINT": pa.int64(),
            "FLOAT": pa.float32(), "DOUBLE": pa.float64(), "BOOLEAN": pa.bool_(), "VARCHAR": pa.string(),
            "TIMESTAMP": pa.timestamp("us")}[duckdb_type]


@cache
def arrow_schema(table: str) -> "pa.Schema":
    """The Arrow schema of a stored table (its parts, the writer's tables; "run": raw.run's row)."""
    import pyarrow as pa
    return pa.schema([(name, _arrow_type(t)) for name, t in STORED_COLUMNS[table].items()])


@cache
def _schemas() -> "dict[str, pa.Schema]":
    return {t: arrow_schema(t) for t in COLUMNS}


def __getattr__(name: str) -> Any:
    # SCHEMAS (table -> Arrow schema, for the writers) is built on first use: importing this module loads
    # no pyarrow
    if name == "SCHEMAS":
        return _schemas()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


TABLES: tuple[str, ...] = tuple(COLUMNS)
# What a run written before runs declared their board (RunMeta.board) reads as: every command that
# wrote runs then played the grid game.
BOARD_BEFORE_DECLARED = "gridworld"
# Columns added after a table's first release, with the SQL value they read as in runs written before
# (the readers add it): clauses.closed, the clause's predicate is `%closed` (an unset atom reads [0,0]);
# run.board, the run's declared board; facts.episode, a fact given for one episode only.
ADDED_COLUMNS: dict[str, dict[str, str]] = {"clauses": {"closed": "false"},
                                            "run": {"board": f"'{BOARD_BEFORE_DECLARED}'"},
                                            "facts": {"episode": "CAST(NULL AS BIGINT)"},
                                            "decisions": {"terms": "CAST(NULL AS VARCHAR[])",
                                                          "term_values": "CAST(NULL AS FLOAT[])"},
                                            "reward_terms": {"quantity": "CAST(NULL AS DOUBLE)"}}
# Tables added after the first release: a run written before has none and reads it as empty (EMPTY_SQL).
ADDED_TABLES: tuple[str, ...] = ("edges", "action_names", "observation_names", "decisions", "reward_terms",
                                  "sources")


def empty_sql(table: str) -> str:
    """A SELECT of no rows with an added table's columns and types (what a run written before reads)."""
    return "SELECT " + ", ".join(f'CAST(NULL AS {t}) AS "{c}"' for c, t in COLUMNS[table].items()) + " LIMIT 0"


# The engine's trace columns (docs/engine-api.md) and the dtype each is stored as.
TRACE_COLUMNS: dict[str, str] = {
    "world": "int32", "t": "int32", "pass_no": "int32", "atom": "int32",
    "old_lower": "float64", "old_upper": "float64", "new_lower": "float64", "new_upper": "float64",
    "cause_kind": "int8", "cause_id": "int32", "grounding": "int32", "n_sources": "int16",
}

# The columns of few distinct values, dictionary-encoded in Parquet parts (the others are not: trying a
# dictionary on ids and texts that are all different costs write time and space; figures:
# docs/benchmarks.md, "Figures behind the code"). Tables not listed encode every column so.
DICTIONARY_COLUMNS: dict[str, list[str]] = {
    "changes": ["episode", "world", "t", "pass_no", "old_lower", "old_upper", "new_lower", "new_upper",
                "cause_kind", "cause_id", "n_sources"],
    "facts": ["start", "end", "static", "file", "line", "episode"],
    "atoms": ["label"], "groundings": ["rule"], "edges": [], "nodes": [], "sources": ["role"],
    "decisions": ["episode", "agent", "output", "explored", "epsilon"],
    "reward_terms": ["episode", "agent", "term", "value", "quantity"],
}
# Parquet options of a table's parts beyond the dictionaries: the change rows' `seq` (a counter) delta
# encoded, and min/max statistics only on the columns readers filter a live run by (episode, time, seq;
# an atom's or grounding's min/max over a row group spans nearly all of them). Together 20% less of the
# writer's encoding time of a traced play (docs/benchmarks/history.md, "Traced runs: the writer").
PART_OPTIONS: dict[str, dict[str, object]] = {
    "changes": {"column_encoding": {"seq": "DELTA_BINARY_PACKED"},
                "write_statistics": ["seq", "episode", "world", "t"]},
    # the agent's rows are read by episode and step: no statistics of the value and mask lists (issue 39's cost)
    "decisions": {"write_statistics": ["episode", "step"]},
    "reward_terms": {"write_statistics": ["episode", "step"]},
}

# Sort order of each table in a sealed file (point queries by episode and time).
SEAL_ORDER: dict[str, str] = {
    "changes": "episode, seq", "steps": "episode, step, agent", "metrics": "step, name",
    "groundings": "grounding", "atoms": "atom", "nodes": "node", "labels": "label", "edges": "source, target",
    "episode_begin": "episode", "episode_end": "episode", "action_names": "action",
    "observation_names": "position, divisor",
    "decisions": "episode, step, agent", "reward_terms": "episode, step, agent, term",
}

VIEWS_SQL = r"""
CREATE OR REPLACE VIEW atoms AS
SELECT a.atom, l.name AS label, n0.name AS arg0, n1.name AS arg1,
       CASE WHEN a.arg1 < 0 THEN n0.name ELSE '(' || n0.name || ',' || n1.name || ')' END AS node,
       l.name || '(' || n0.name || CASE WHEN a.arg1 < 0 THEN '' ELSE ',' || n1.name END || ')' AS text
FROM raw.atoms a JOIN raw.labels l USING (label)
LEFT JOIN raw.nodes n0 ON n0.node = a.arg0 LEFT JOIN raw.nodes n1 ON n1.node = a.arg1;

CREATE OR REPLACE VIEW rules AS
SELECT r.rule, r.name, r.delay, r.immediate, r.mode, r.head,
       (SELECT string_agg(c.text, ', ' ORDER BY c.pos) FROM raw.clauses c
         WHERE c.rule = r.rule AND c.pos >= 0) AS body,
       r.variables, r.text, r.file, r.line
FROM raw.rules r;

CREATE OR REPLACE VIEW facts AS SELECT * FROM raw.facts;

CREATE OR REPLACE VIEW edges AS
SELECT s.name AS source, d.name AS target, e.source AS source_id, e.target AS target_id
FROM raw.edges e LEFT JOIN raw.nodes s ON s.node = e.source LEFT JOIN raw.nodes d ON d.node = e.target;

CREATE OR REPLACE VIEW changes AS
SELECT c.episode, c.t, a.text AS atom, a.node, a.label,
       c.old_lower, c.old_upper, c.new_lower, c.new_upper,
       CASE c.cause_kind WHEN 0 THEN 'fact:' || coalesce(f.name, CAST(c.cause_id AS VARCHAR))
                         WHEN 1 THEN 'action'
                         WHEN 2 THEN coalesce(r.name, 'rule#' || c.cause_id)
                         WHEN 3 THEN 'policy:' || coalesce(p.name, CAST(c.cause_id AS VARCHAR))
                         WHEN 4 THEN 'reset'
                         ELSE 'cause' || c.cause_kind END AS rule,
       c.grounding, c.world, c.pass_no, c.seq, c.cause_kind, c.cause_id, c.n_sources, c.atom AS atom_id
FROM raw.changes c
LEFT JOIN atoms a ON a.atom = c.atom
LEFT JOIN raw.rules r ON c.cause_kind = 2 AND r.rule = c.cause_id
LEFT JOIN raw.facts f ON c.cause_kind = 0 AND f.fact = c.cause_id
LEFT JOIN raw.policies p ON c.cause_kind = 3 AND p.code = c.cause_id;

CREATE OR REPLACE VIEW groundings AS
SELECT g.grounding, r.name AS rule,
       array_to_string(list_transform(list_zip(r.variables, list_transform(g.var_values,
           lambda v: nl.names[v + 1])), lambda x: x[1] || '=' || x[2]), ', ') AS bindings,
       g.body_atoms, g.var_values, g.rule AS rule_id
FROM raw.groundings g JOIN raw.rules r ON r.rule = g.rule,
     (SELECT list(name ORDER BY node) AS names FROM raw.nodes) nl;

CREATE OR REPLACE VIEW firings AS
SELECT c.episode, c.t, r.name AS rule,
       array_to_string(list_transform(list_zip(r.variables, list_transform(g.var_values,
           lambda v: nl.names[v + 1])), lambda x: x[1] || '=' || x[2]), ', ') AS bindings,
       a.text AS head, c.new_lower, c.new_upper, r.delay, r.immediate,
       c.grounding, c.world, c.pass_no, c.seq
FROM raw.changes c
JOIN raw.rules r ON c.cause_kind = 2 AND r.rule = c.cause_id
LEFT JOIN raw.groundings g ON g.grounding = c.grounding
LEFT JOIN atoms a ON a.atom = c.atom,
(SELECT list(name ORDER BY node) AS names FROM raw.nodes) nl;

CREATE OR REPLACE VIEW episodes AS
SELECT coalesce(b.episode, e.episode) AS episode, b.world, e.steps, e.outcome, e.reward,
       e.rewards, b.t_start, e.t_end, b.seed, b.started_at, e.ended_at,
       e.episode IS NOT NULL AS ended, b.info AS begin_info, e.info AS end_info,
       -- training runs (docs/training.md): 'train' or 'eval', and the training step it began at
       json_extract_string(b.info, '$.kind') AS kind,
       TRY_CAST(json_extract(b.info, '$.train_step') AS BIGINT) AS train_step
FROM raw.episode_begin b FULL JOIN raw.episode_end e ON e.episode = b.episode;

-- the action's name from the run's action_names (NULL in a run written before they were recorded)
CREATE OR REPLACE VIEW steps AS
SELECT s.*, an.names[s.action + 1] AS action_name
FROM raw.steps s, (SELECT list(name ORDER BY action) AS names FROM raw.action_names) an;

-- the policy's decision per agent and step: `actions` names the entries of `values` (and `mask`)
CREATE OR REPLACE VIEW decisions AS
SELECT d.episode, d.step, d.agent, d.action, an.names[d.action + 1] AS action_name, d.explored, d.epsilon,
       d.output, an.offered AS actions, d.values, d.mask, d.state_value, d.terms, d.term_values
FROM raw.decisions d,
     (SELECT list(name ORDER BY action) AS names,
             list(name ORDER BY position) FILTER (WHERE position IS NOT NULL) AS offered
      FROM raw.action_names) an;

-- one row per action of each decision: its value, whether the mask allowed it, whether it was chosen
CREATE OR REPLACE VIEW action_values AS
SELECT d.episode, d.step, d.agent, u.pos - 1 AS position, d.actions[u.pos] AS action_name,
       d."values"[u.pos] AS value, coalesce(d.mask[u.pos], true) AS allowed, d.actions[u.pos] = d.action_name AS chosen
FROM decisions d, (SELECT unnest(range(1, 1 + max(len("values")))) AS pos FROM raw.decisions) u
WHERE u.pos <= len(d."values");

-- each step's reward by term (a row per term paid, a term worth 0 included: their sum is steps.reward),
-- and each episode's return by term (`quantity`: the occurrences, or the scaled atom's bounds, summed)
CREATE OR REPLACE VIEW rewards AS SELECT episode, step, agent, term, value, quantity FROM raw.reward_terms;
CREATE OR REPLACE VIEW returns AS
SELECT episode, agent, term, sum(value) AS value, count(*) AS steps, sum(quantity) AS quantity
FROM raw.reward_terms GROUP BY ALL;
CREATE OR REPLACE VIEW metrics AS SELECT * FROM raw.metrics;
CREATE OR REPLACE VIEW run AS SELECT * FROM raw.run;
"""
# The views above, by name (a sealed file holds a copy of each in its schema `main`).
VIEW_NAMES: tuple[str, ...] = tuple(re.findall(r"^CREATE OR REPLACE VIEW (\w+) AS", VIEWS_SQL, re.M))
# Each view's statement, in VIEWS_SQL's order (a view follows the views it reads).
VIEW_STATEMENTS: dict[str, str] = dict(zip(VIEW_NAMES, re.findall(
    r"^CREATE OR REPLACE VIEW \w+ AS.*?;$", VIEWS_SQL, re.M | re.S), strict=True))
