"""Facts from a table (Parquet or CSV) read through DuckDB, as columns: a million facts without a Python
object each (docs/language.md, "Fact tables").

Columns: `atom` (required: a ground literal in rule syntax, `link(a,b)`, `infected("Cell 3")`,
`~alarm(base)`), `lower` and `upper` (default 1), `start` and `end` (the window, default 0 and `start`),
`static` (default false), `episode` (optional: the one episode of a recorded reasoning the fact belongs
to, empty for every episode; Graph.fact_episode, which the engine itself does not read). The atom text is
split by DuckDB (a regular expression, vectorised); bad rows are errors naming the file, the row and the
value.
"""
from __future__ import annotations

import os
from typing import Any

import numpy as np

from .errors import ProgramCheckError
from .graph import Graph
from .program import MAX_TIME, unwritable_constant
from .duckdb_limits import QUERY_MEMORY_ENV, exact_file, query_memory
from .safe_files import check_regular, human_bytes

_CONST = r"""("[^"]*"|'[^']*'|[A-Za-z0-9_-]+)"""
_ATOM_RE = rf"^\s*(~?)\s*([a-z][A-Za-z0-9_]*)\s*\(\s*{_CONST}\s*(?:,\s*{_CONST}\s*)?\)\s*$"
_OPTIONAL = {"lower": "1.0", "upper": "1.0", "start": "0", "end": None, "static": "false", "episode": "NULL"}

# a constant without its quotes: "x" and x are one node
_UNQUOTE = "CASE WHEN left({q}, 1) IN ('\"', chr(39)) THEN substr({q}, 2, length({q}) - 2) ELSE {q} END"


def load_fact_table(path: str | os.PathLike[str]) -> Graph:
    """The facts of a Parquet (.parquet) or CSV file as a Graph (its nodes in order of first appearance).
    DuckDB parses the atoms and numbers the nodes and labels; Python only receives columns."""
    import duckdb  # when used: the engine's other inputs need no database

    file = os.fspath(path)
    if not os.path.exists(file):
        raise ProgramCheckError("no such fact table", file)
    check_regular(file)  # DuckDB would wait on a FIFO forever
    full = os.path.abspath(file)
    named = exact_file(full)  # read_csv/read_parquet would expand a `*` or `[` in the path
    # this connection may read that one file and nothing else, never installs or loads extensions, and is
    # bounded in memory and threads as a query on a run is; it never spills (an in-memory database would
    # spill into the working folder's .tmp/): a table too big for the limit is refused in one line
    limits = query_memory()
    con = duckdb.connect(":memory:", config={"autoinstall_known_extensions": False,
                                              "autoload_known_extensions": False,
                                              "memory_limit": f"{limits.memory}B", "threads": limits.threads,
                                              "temp_directory": ""})
    try:
        con.execute("SET allowed_paths = ?", [[full, named]])
        con.execute("SET enable_external_access = false")
        con.execute("SET enable_progress_bar = false")
        con.execute("SET lock_configuration = true")
        # CSV: a header row, comma-separated, "-quoted ("" inside quotes)
        source = "read_parquet(?)" if file.lower().endswith((".parquet", ".pq")) else \
            "read_csv(?, header = true, delim = ',', quote = '\"', escape = '\"')"
        columns = {c[0].lower(): c[0] for c in con.execute(f"DESCRIBE SELECT * FROM {source}", [named]).fetchall()}
        if "atom" not in columns:
            raise ProgramCheckError(f"a fact table needs an 'atom' column (found: {', '.join(columns)})", file)
        cols = {name: f'"{columns[name]}"' if name in columns else default for name, default in _OPTIONAL.items()}
        cols["end"] = cols["end"] or cols["start"]
        atom = f'CAST("{columns["atom"]}" AS VARCHAR)'
        con.execute(f"""
            CREATE TEMP TABLE f AS SELECT row_number() OVER () - 1 AS row, atom, p['neg'] = '~' AS neg,
                   p['pred'] AS pred, p['a0'] AS q0, p['a1'] AS q1, lower, upper, start, "end", static, episode
            FROM (SELECT {atom} AS atom, regexp_extract({atom}, ?, ['neg', 'pred', 'a0', 'a1']) AS p,
                         CAST({cols['lower']} AS DOUBLE) AS lower, CAST({cols['upper']} AS DOUBLE) AS upper,
                         CAST({cols['start']} AS BIGINT) AS start, CAST({cols['end']} AS BIGINT) AS "end",
                         CAST({cols['static']} AS BOOLEAN) AS static, CAST({cols['episode']} AS BIGINT) AS episode
                  FROM {source})""", [_ATOM_RE, named])
        _check_rows(con, file)
        con.execute(f"""
            CREATE TEMP TABLE ids AS SELECT name, row_number() OVER (ORDER BY min(place)) - 1 AS id
            FROM (SELECT {_UNQUOTE.format(q='q0')} AS name, 2 * row AS place FROM f UNION ALL
                  SELECT {_UNQUOTE.format(q='q1')}, 2 * row + 1 FROM f WHERE q1 <> '')
            GROUP BY name""")
        con.execute("""
            CREATE TEMP TABLE labels AS SELECT pred, row_number() OVER (ORDER BY pred) - 1 AS id,
                   min((q1 <> '')::INT) + 1 AS lo_arity, max((q1 <> '')::INT) + 1 AS hi_arity
            FROM f GROUP BY pred""")
        clash = con.execute("SELECT pred FROM labels WHERE lo_arity <> hi_arity LIMIT 1").fetchone()
        if clash is not None:
            raise ProgramCheckError(f"predicate '{clash[0]}' is used with one and with two arguments in this "
                                    "table", file)
        nodes = [row[0] for row in con.execute("SELECT name FROM ids ORDER BY id").fetchall()]
        labels = con.execute("SELECT pred, lo_arity FROM labels ORDER BY id").fetchall()
        r = con.execute(f"""
            SELECT l.id AS label, i0.id AS n0, coalesce(i1.id, -1) AS n1, f.neg, f.lower, f.upper, f.start,
                   f."end", f.static, coalesce(f.episode, -1) AS episode
            FROM f JOIN labels l USING (pred)
            JOIN ids i0 ON i0.name = {_UNQUOTE.format(q='q0')}
            LEFT JOIN ids i1 ON q1 <> '' AND i1.name = {_UNQUOTE.format(q='q1')}
            ORDER BY f.row""").fetchnumpy()
    except duckdb.OutOfMemoryException:
        raise ProgramCheckError(f"reading this fact table needs more than the {human_bytes(limits.memory)} of "
                                f"memory a DuckDB reading may use ({limits.source}); set {QUERY_MEMORY_ENV} to "
                                "raise it (e.g. 8G)", file) from None
    except duckdb.Error as e:
        raise ProgramCheckError(f"not a readable fact table: {str(e).splitlines()[0]}", file) from None
    finally:
        con.close()
    for name in nodes:
        why = unwritable_constant(name)
        if why is not None:
            raise ProgramCheckError(f"constant {name!r} cannot be written in the rule language: {why}", file)
    lower, upper = np.asarray(r["lower"], np.float64), np.asarray(r["upper"], np.float64)
    neg = np.asarray(r["neg"], np.bool_)
    lower, upper = np.where(neg, 1.0 - upper, lower), np.where(neg, 1.0 - lower, upper)
    return Graph(nodes=nodes, labels=[p for p, _ in labels], label_arity=[int(a) for _, a in labels],
                 fact_label=np.asarray(r["label"], np.int32),
                 fact_args=np.column_stack([r["n0"], r["n1"]]).astype(np.int32),
                 fact_bounds=np.column_stack([lower, upper]), file=file,
                 fact_window=np.column_stack([r["start"], r["end"]]).astype(np.int64),
                 fact_static=np.asarray(r["static"], np.bool_),
                 fact_episode=np.asarray(r["episode"], np.int64) if "episode" in columns else None)


_ROW_CHECKS = [
    ("pred = ''", "atom {atom!r} is not a ground literal (pred(a) or pred(a,b), constants quoted when they "
                  "are not letters, digits, '_' and '-')"),
    ('lower IS NULL OR upper IS NULL OR start IS NULL OR "end" IS NULL OR static IS NULL',
     "a value of {atom} is empty"),
    ("regexp_matches(q0, '^[A-Z_]') OR regexp_matches(q1, '^[A-Z_]')",
     "atom {atom!r} names a variable; a fact is ground (quote a constant that starts with an upper-case "
     "letter or '_')"),
    ("NOT (lower >= 0 AND lower <= upper AND upper <= 1)",
     "bound [{lower:g},{upper:g}] of {atom} is not inside [0,1] with lower <= upper"),
    (f'"end" > {MAX_TIME}',
     f"window {{start}}..{{end}} of {{atom}}: times are at most {MAX_TIME:,}, as in programs"),
    ("episode < 0", "episode {episode} of {atom}: an episode is an integer >= 0 (empty: every episode)"),
    ('NOT (start >= 0 AND start <= "end" AND (NOT static OR start = "end"))',
     "window {start}..{end} of {atom}: times are integers >= 0 with start <= end, and a static fact takes "
     "one time"),
]


def _check_rows(con: Any, file: str) -> None:
    """The first bad row, if any, as an error naming it (rows count from 1, after the header)."""
    for where, msg in _ROW_CHECKS:
        row = con.execute(f'SELECT row, atom, lower, upper, start, "end", episode FROM f WHERE {where} '
                          "ORDER BY row LIMIT 1").fetchone()
        if row is not None:
            i, atom, lower, upper, start, end, episode = row
            raise ProgramCheckError(f"row {i + 1}: " + msg.format(atom=atom, lower=lower or 0.0, upper=upper or 0.0,
                                                                   start=start, end=end, episode=episode), file)
