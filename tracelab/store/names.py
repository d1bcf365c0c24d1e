"""The names a run knows (rules, causes, labels, nodes, atoms) and the one error for a name or pattern it
does not know: `no rule 'd_kiled' in this run; did you mean d_killed, h_killed?`.

Every command and viewer that takes a name from the user (trace's filters, why, why-not, replay, the TUI's
trace filters) checks it here, so a typo reads the same everywhere instead of an empty table."""
from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

from tracelab.errors import close_names

# The SQL of each kind's names, one column `name`. A cause is what the changes view's `rule` column
# names: a rule, fact:NAME, policy:NAME, action, reset.
_NAMES_SQL = {
    "rule": "SELECT name FROM raw.rules",
    "cause": "SELECT name FROM raw.rules UNION ALL SELECT 'fact:' || name FROM raw.facts "
             "UNION ALL SELECT 'policy:' || name FROM raw.policies "
             "UNION ALL SELECT 'action' UNION ALL SELECT 'reset'",
    "label": "SELECT name FROM raw.labels",
    "node": "SELECT name FROM raw.nodes",
}
_ATOMS_SQL = "SELECT text AS name, label FROM atoms"   # the atoms view: text is label(arg0[,arg1])
MAX_CANDIDATES = 20_000   # names compared for a suggestion (difflib is linear in them): atoms of one label
LISTED = 12               # names listed when none is close
_GLOB = re.compile(r"[*?\[]")
_ATOM = re.compile(r"^\s*([^()\s]+)\s*\((.*)\)\s*$")


class UnknownName(KeyError):
    """A name (or glob) that matches nothing in a run. A KeyError, which the CLI's store_errors turns into
    a one-line user error; str() is the message itself (KeyError's would quote it)."""

    def __str__(self) -> str:
        return str(self.args[0])


def unknown_name_message(kind: str, name: str, known: Sequence[str], where: str = " in this run") -> str:
    """`no KIND 'NAME'WHERE; did you mean A, B?`, or the known names listed when none is close."""
    near = close_names(name, known)
    if near:
        return f"no {kind} {name!r}{where}; did you mean {', '.join(near)}?"
    listed = sorted(known)[:LISTED]
    more = f", ... ({len(known):,} in all)" if len(known) > LISTED else ""
    return f"no {kind} {name!r}{where}; its {kind}s: {', '.join(listed) or 'none'}{more}"


def names_of(con: Any, kind: str) -> list[str]:
    """Every name of `kind` (rule, cause, label, node) in the run."""
    return [n for (n,) in con.execute(f"SELECT DISTINCT name FROM ({_NAMES_SQL[kind]}) ORDER BY name").fetchall()]


def _matches(con: Any, sql: str, pattern: str) -> bool:
    rows = con.execute(f"SELECT 1 FROM ({sql}) WHERE name GLOB ? LIMIT 1", [pattern]).fetchall()
    return bool(rows)


def check_name(con: Any, kind: str, pattern: str) -> None:
    """Raise UnknownName unless some name of `kind` (rule, cause, label, node, atom) matches `pattern`, an
    exact name or a GLOB (`*`, `?`, `[..]`)."""
    if kind == "atom":
        check_atom(con, pattern)
        return
    if not _matches(con, _NAMES_SQL[kind], pattern):
        shown = "rule" if kind == "cause" else kind     # a trace --rule names causes; the user said rule
        raise UnknownName(unknown_name_message(shown, pattern, names_of(con, kind)))


def check_atom(con: Any, pattern: str) -> None:
    """Raise UnknownName unless an atom of the run matches `pattern` (`label(arg,...)`, GLOBs allowed).
    Says what is wrong: the label, a node, or the atom as a whole (with the close atoms of its label and
    how to write a pattern)."""
    if _matches(con, _ATOMS_SQL, pattern):
        return
    m = _ATOM.match(pattern)
    label = m.group(1) if m else ""
    if m and not _GLOB.search(label):
        check_name(con, "label", label)
        for arg in (a.strip() for a in m.group(2).split(",")):
            if arg and not _GLOB.search(arg):
                check_name(con, "node", arg)
    same_label = " WHERE label = ?" if m and not _GLOB.search(label) else ""
    candidates = [n for n, _ in con.execute(f"{_ATOMS_SQL}{same_label} LIMIT {MAX_CANDIDATES}",
                                            [label] if same_label else []).fetchall()]
    import difflib  # deferred: only a name that matches nothing needs it
    near = difflib.get_close_matches(pattern.replace(" ", ""), candidates, n=5)
    labels = names_of(con, "label")
    example = label if same_label else pattern.strip() if pattern.strip() in labels else (labels or ["label"])[0]
    hint = f"did you mean {', '.join(near)}? " if near else ""
    raise UnknownName(f"no atom matches {pattern!r} in this run; {hint}write an atom as label(args) with "
                      f"* for any part, e.g. {example}(*)")
