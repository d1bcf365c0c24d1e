"""A run's returns by reward term, and re-scored under other term values without re-simulating (`tracelab
rewards RUN [--set TERM=VALUE ...]`). The run records each step's reward by term (the `rewards` view) with
the quantity the value is of (a table term's occurrences, the scaled atom's bound; a term worth 0 that
occurred has a row of value 0), so a term re-scored to NEW is its recorded quantity x NEW: exact for a table
term and for the scaled atom (NEW is its scale). A run written before quantities were kept re-scores a term
as its recorded value x NEW / OLD, OLD its value per occurrence from the run's config (a spec world's
`[reward]` with the run's params, or what the world's registration reads in an older run's config:
world_extras.old_run_terms), and cannot re-score a term worth 0. The
actions stay the recorded ones: re-scoring changes no step, no end and no choice a learner made."""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from typing import Any

from tracelab.expressions import ExpressionError, evaluate
from tracelab.errors import UserError, close_names
from tracelab.store.kind import MAX_SPEC_TEXT, run_config, spec_text, world_params
from tracelab.store.reader import RunConnection
from tracelab.world_extras import old_run_terms

NO_TERMS = ("the run records no reward terms (written before tracelab recorded them by term, or by a "
            "caller that records the world's half only)")


@dataclass(frozen=True)
class Term:
    """A reward term of the run: its value per occurrence (`per`, None: the run does not say), what that
    value is (`unit`: 'value' per occurrence, or 'scale' of the scaled atom) and notes on what else it does."""
    name: str
    per: float | None
    unit: str = "value"
    notes: tuple[str, ...] = ()
    counted_at_zero: bool = True  # the run records the term's occurrences where it is worth 0


@dataclass
class Rescored:
    """Per episode and agent: the recorded return by term, and with `sets` its re-scored return."""
    terms: list[str]                                   # the terms with a recorded value, in column order
    rows: list[dict[str, Any]] = field(default_factory=list)  # episode, agent, by_term, ret, rescored
    sets: dict[str, tuple[float, float]] = field(default_factory=dict)  # term -> (old, new)
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        total = {"return": sum(r["return"] for r in self.rows)}
        if self.sets:
            total["rescored"] = sum(r["rescored"] for r in self.rows)
        return {"terms": self.terms, "set": {t: {"old": o, "new": n} for t, (o, n) in self.sets.items()},
                "episodes": self.rows, "total": total, "notes": self.notes}


def number(v: Any, names: dict[str, Any]) -> float | None:
    """A spec's number (a literal or an expression over its params and data), None if it is not one."""
    if isinstance(v, str):
        try:
            v = evaluate(v, names)
        except ExpressionError:
            return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        return None
    return float(v)


def _spec_terms(config: dict[str, Any], text: str | None) -> list[Term] | None:
    """A spec world's terms from its spec's `text` (kind.spec_text): its [reward.table] keys and scaled atom."""
    if not isinstance(text, str) or len(text) > MAX_SPEC_TEXT:
        return None
    try:
        spec = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError):
        return None
    reward, end = spec.get("reward", {}), spec.get("end", {})
    if not isinstance(reward, dict):
        return None
    data = spec.get("data", {})
    names = {**(data if isinstance(data, dict) else {}), **(world_params(config, text) or {})}
    ends = {k: [str(a).replace(" ", "") for a in end.get(k, [])] for k in ("terminated", "truncated", "win", "loss")
            if isinstance(end, dict) and isinstance(end.get(k), list)}

    def notes(atom: str, value: Any) -> tuple[str, ...]:
        where = [k for k, atoms in ends.items() if atom.replace(" ", "") in atoms]
        out = [f"{atom} also ends an episode ([end] {', '.join(where)}): re-scoring keeps the recorded ends"] \
            if where else []
        if isinstance(value, str):
            out.append(f"{atom}'s value is the expression {value!r}: --set changes this term only, not the params")
        return tuple(out)

    table = reward.get("table", {})
    terms = [Term(str(k), number(v, names), notes=notes(str(k), v))
             for k, v in (table.items() if isinstance(table, dict) else [])]
    if "atom" in reward:
        atom = str(reward["atom"])
        terms.append(Term(atom, number(reward.get("scale", 1.0), names), "scale",
                          (f"{atom} is the atom's lower bound x scale: --set {atom}=S sets the scale",
                           *notes(atom, reward.get("scale")))))
    return terms


def run_terms(con: RunConnection) -> tuple[list[Term], list[str]]:
    """The run's reward terms with their values per occurrence (from its config; a term recorded but not
    in the config has per None), and the run-wide notes (a learner's reward scale)."""
    config = run_config(con)
    terms = _spec_terms(config, spec_text(con, config)) or old_run_terms(config) or []
    named = {t.name for t in terms}
    recorded = [r[0] for r in con.execute("SELECT DISTINCT term FROM raw.reward_terms ORDER BY 1").fetchall()]
    terms += [Term(str(t), None) for t in recorded if t not in named]
    notes = []
    scale = config.get("reward_scale")
    if isinstance(scale, (int, float)) and not isinstance(scale, bool) and scale != 1:
        notes.append(f"the values are the game's; the learner saw them x {scale:g} (reward_scale)")
    return terms, notes


def parse_sets(sets: list[str], terms: list[Term], counts_zeros: bool = True) -> dict[str, tuple[float, float]]:
    """--set TERM=VALUE texts as term -> (old, new); a UserError names an unknown term (with a did-you-mean),
    a value that is not a number, a term whose old value the run does not give, or a term worth 0 whose
    occurrences the run does not record (`counts_zeros` False: a run written before they were kept)."""
    by_name = {t.name.replace(" ", ""): t for t in terms}
    out: dict[str, tuple[float, float]] = {}
    for text in sets:
        name, eq, value = text.rpartition("=")
        if not eq or not name.strip():
            raise UserError(f"--set {text!r}: expected TERM=VALUE")
        term = by_name.get(name.replace(" ", ""))
        if term is None:
            near = close_names(name.strip(), list(by_name))
            raise UserError(f"--set: no reward term {name.strip()!r} in this run"
                            + (f"; did you mean {', '.join(near)}?" if near else
                               f" (its terms: {', '.join(by_name) or 'none'})"))
        try:
            new = float(value)
        except ValueError:
            raise UserError(f"--set {text!r}: {value!r} is not a number") from None
        if not math.isfinite(new):
            raise UserError(f"--set {text!r}: expected a finite number")
        if term.per is None:
            raise UserError(f"--set: the run does not say {term.name}'s {term.unit} (its config has no value "
                            "for it): it cannot be re-scored")
        if term.per == 0 and not counts_zeros:
            raise UserError(f"--set: {term.name} is 0 in this run, which was written before tracelab recorded "
                            "the occurrences of terms worth 0: it cannot be re-scored from the record")
        if term.per == 0 and not term.counted_at_zero:
            raise UserError(f"--set: {term.name} is 0 in this run, and this world's record does not count its "
                            "occurrences where it is worth 0: it cannot be re-scored from the record")
        out[term.name] = (term.per, new)
    return out


def rescore(con: RunConnection, sets: list[str], episode: int | None = None) -> Rescored:
    """Each episode's return by term and agent (every recorded episode, or `episode`), re-scored with
    `sets` (TERM=VALUE texts); KeyError when the run records no reward terms or no such episode."""
    # no term rows and a non-zero reward: a run written before terms were recorded (a run whose every
    # reward is 0 has no term rows either: its returns are 0 by every term)
    if not con.execute("SELECT EXISTS (SELECT 1 FROM raw.reward_terms)").fetchall()[0][0] and \
            con.execute("SELECT EXISTS (SELECT 1 FROM raw.steps WHERE reward <> 0)").fetchall()[0][0]:
        raise KeyError(NO_TERMS)
    terms, notes = run_terms(con)
    # quantities are NULL in runs written before they were kept (schema.ADDED_COLUMNS)
    counts_zeros = con.execute("SELECT EXISTS (SELECT 1 FROM raw.reward_terms WHERE quantity IS NOT NULL)"
                               ).fetchall()[0][0]
    changed = parse_sets(sets, terms, counts_zeros)
    where, params = ("WHERE episode = ?", [episode]) if episode is not None else ("", [])
    returns = con.execute(f"SELECT episode, agent, sum(reward) FROM steps {where} GROUP BY ALL ORDER BY ALL",
                          params).fetchall()
    if not returns:
        raise KeyError("the run records no steps (not a run of games)" if episode is None else
                       f"episode {episode} has no steps in this run")
    by_term = con.execute(f"SELECT episode, agent, term, value, quantity FROM returns {where}", params).fetchall()
    values: dict[tuple[int, str], dict[str, float]] = {}
    quantities: dict[tuple[int, str], dict[str, float | None]] = {}
    for e, a, t, v, q in by_term:
        values.setdefault((int(e), str(a)), {})[str(t)] = float(v)
        quantities.setdefault((int(e), str(a)), {})[str(t)] = None if q is None else float(q)
    present = {t for v in values.values() for t in v}
    order = [t.name for t in terms if t.name in present]
    out = Rescored(order, sets=changed)
    for e, a, ret in returns:
        terms_of = values.get((int(e), str(a)), {})
        row = {"episode": int(e), "agent": str(a), "return": float(ret), "by_term": terms_of}
        if changed:
            row["rescored"] = float(ret) + sum(
                _term_change(v, quantities[(int(e), str(a))][t], *changed[t])
                for t, v in terms_of.items() if t in changed)
        out.rows.append(row)
    if changed:
        scope = f"episode {episode}" if episode is not None else "the recorded episodes"
        never = [f"{t} never occurred in {scope}: re-scoring it changes nothing" for t in changed if t not in present]
        out.notes = never + [n for t in terms if t.name in changed for n in t.notes] + notes + [
            "the actions are the recorded ones: a learner trained under the new values may act otherwise"]
    else:
        out.notes = notes
    return out


def _term_change(value: float, quantity: float | None, old: float, new: float) -> float:
    """What re-scoring a term from `old` to `new` adds to a return where it paid `value` in total: its
    quantity (occurrences, or the scaled atom's bounds) x new, less what it paid; a run without quantities
    scales the value (parse_sets refused a term worth 0 there)."""
    return quantity * new - value if quantity is not None else value * (new / old - 1)
