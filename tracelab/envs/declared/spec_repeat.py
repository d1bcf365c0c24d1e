"""A spec's generated parts (docs/worlds.md, "Generated parts: `for`"): tables and list items written once
and repeated over ranges computed from the params, so that one spec makes a world of any size (war.toml's
agents 1..agents_per_team, bullets 1..ammo, the tally's steps 1..hits to kill).

- In a list, a table with `for` is repeated once per combination of its variables (the first variable
  slowest): its `each` list's items are spliced in, or, without `each`, the table itself (less `for`) is
  the item (an [[array]] of tables).
- In a table, an entry whose value is a table with `for` and an `each` table: each's entries, once per
  combination, take the entry's place (the entry's own key is only a label).
`for = { j = "range(1, agents_per_team + 1)" }` maps each variable to an expression giving a list. In the
repeated strings (keys and values), `{expr}` is the value of an expression over the params, the data and
the variables (`{{` and `}}` are braces); a string that is exactly one `{expr}` takes its value as it is
(a number stays a number). A `for` inside a repeated part sees the outer variables.

What is generated is counted before it is made and charged to the spec's budget (spec_size): a spec that
would generate more than fits is refused at the `for` that asks for it. Every later error about a
generated item is located at the line of its template, with the variables' values."""
from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from typing import Any

from tracelab.envs.declared.spec_file import KeyPath, SpecError, SpecSource
from tracelab.expressions import MAX_EXPRESSION_STEPS, Evaluation, ExpressionError

FOR, EACH = "for", "each"
NOT_GENERATED = ("params", "data")  # read before any expression can be computed
MAX_GENERATED = 1_000_000  # values generated in all (strings, numbers, tables), whatever the memory budget
# the expressions of all `for`s and `{expr}`s together, in the evaluator's steps (a node, an item), plus
# one a character parsed: seconds (~30 s of CPU at most on a loaded machine), where 1,000,000 copies of an expression of
# MAX_EXPRESSION_STEPS each would never end (war.toml at 20 agents a team takes ~0.3M)
MAX_GENERATION_STEPS = 8 * MAX_EXPRESSION_STEPS

# a generated path -> (its template's path, the variables' values), as SpecSource.origins holds them
Origins = dict[KeyPath, tuple[KeyPath, str]]


def expand_spec(src: SpecSource, names: dict[str, Any], charge: Callable[[KeyPath, int], None]) -> SpecSource:
    """`src` with every `for` expanded; `charge(path, n)` is told that n values in all will have been
    generated once the `for` at path is (it raises past the budget)."""
    if not _has_for(src.data):
        return src
    gen = _Generator(src, names, charge)
    data = {k: (v if k in NOT_GENERATED else gen.node(v, (k,), (k,), {}, "")) for k, v in src.data.items()}
    return SpecSource(src.path, data, src.key_lines, gen.origins)


def _has_for(node: Any) -> bool:
    if isinstance(node, dict):
        return FOR in node or any(_has_for(v) for v in node.values())
    if isinstance(node, list):
        return any(_has_for(v) for v in node)
    return False


class _Generator:
    def __init__(self, src: SpecSource, names: dict[str, Any], charge: Callable[[KeyPath, int], None]) -> None:
        self.src = src
        self.names = names
        self.charge = charge
        self.origins: Origins = {}
        self.generated = 0
        self.steps = 0  # spent by every expression so far, of MAX_GENERATION_STEPS

    def err(self, path: KeyPath, msg: str, note: str = "") -> SpecError:
        return self.src.error(path, msg, note=note)

    def node(self, v: Any, new: KeyPath, orig: KeyPath, env: dict[str, Any], note: str) -> Any:
        """`v` (written at `orig`, now at `new`) with its `for`s expanded and, inside a repeat (`env` holds
        its variables), its strings filled in."""
        if new != orig or note:
            self.origins[new] = (orig, note)
        if isinstance(v, str):
            return self.fill(v, orig, env, note) if env else v
        if isinstance(v, list):
            return self.items(v, new, orig, env, note)
        if isinstance(v, dict):
            if FOR in v:
                raise self.err((*orig, FOR), "a `for` belongs to a list item (a table in a list) or to a table "
                                             "entry's value")
            return self.entries(v, new, orig, env, note)
        return v

    def items(self, v: list[Any], new: KeyPath, orig: KeyPath, env: dict[str, Any], note: str) -> list[Any]:
        out: list[Any] = []
        for i, item in enumerate(v):
            if not (isinstance(item, dict) and FOR in item):
                out.append(self.node(item, (*new, len(out)), (*orig, i), env, note))
                continue
            where = (*orig, i)
            template = item.get(EACH) if EACH in item else {k: x for k, x in item.items() if k != FOR}
            if EACH in item and (len(item) != 2 or not isinstance(template, list)):
                raise self.err((*where, EACH), "in a list, `each` is a list of items (spliced in) and the only "
                                               "key beside `for`; without `each`, the table itself is repeated")
            for values, inner_note in self.combinations(item[FOR], where, env, note,
                                                        len(template) if EACH in item else 1, template):
                inner = {**env, **values}
                if EACH in item:
                    for k, x in enumerate(template):
                        out.append(self.node(x, (*new, len(out)), (*where, EACH, k), inner, inner_note))
                else:
                    out.append(self.node(template, (*new, len(out)), where, inner, inner_note))
        return out

    def entries(self, v: dict[str, Any], new: KeyPath, orig: KeyPath, env: dict[str, Any], note: str
                ) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for key, x in v.items():
            if not (isinstance(x, dict) and FOR in x):
                name = self.key(key, (*orig, key), env, note)
                self.put(out, name, self.node(x, (*new, name), (*orig, key), env, note), (*orig, key))
                continue
            where = (*orig, key)
            template = x.get(EACH)
            if set(x) != {FOR, EACH} or not isinstance(template, dict):
                raise self.err(where, "in a table, an entry with `for` takes an `each` table (its entries are "
                                      "repeated in the entry's place) and nothing else")
            for values, inner_note in self.combinations(x[FOR], where, env, note, len(template), template):
                inner = {**env, **values}
                for k, y in template.items():
                    name = self.key(k, (*where, EACH, k), inner, inner_note)
                    self.put(out, name, self.node(y, (*new, name), (*where, EACH, k), inner, inner_note),
                             (*where, EACH, k), inner_note)
        return out

    def put(self, out: dict[str, Any], name: str, value: Any, where: KeyPath, note: str = "") -> None:
        if name in out:
            raise self.err(where, f"makes the key {name!r} twice", note)
        out[name] = value

    def key(self, key: str, where: KeyPath, env: dict[str, Any], note: str) -> str:
        if not env:
            return key
        name = self.fill(key, where, env, note)
        return name if isinstance(name, str) else str(name)

    def combinations(self, spec: Any, where: KeyPath, env: dict[str, Any], note: str, per: int, template: Any
                     ) -> list[tuple[dict[str, Any], str]]:
        """Each combination of the `for` variables' values (the first slowest), with its note ("j = 2"),
        counted and charged before any is made."""
        path = (*where, FOR)
        if not isinstance(spec, dict) or not spec:
            raise self.err(path, "expected a table of variables, each an expression giving a list, such as "
                                 "{ j = \"range(1, agents + 1)\" }")
        axes = []
        for var, text in spec.items():
            if not var.isidentifier():
                raise self.err((*path, var), f"{var!r} is not a name for a variable")
            if var in self.names or var in env:
                raise self.err((*path, var), f"the variable {var!r} hides a param, a data name or an outer "
                                             "variable of the same name")
            value = self.compute(text, (*path, var), env, note) if isinstance(text, str) else text
            if not isinstance(value, list) or not all(isinstance(x, (int, str)) and not isinstance(x, bool)
                                                      for x in value):
                raise self.err((*path, var), f"expected a list of whole numbers or strings, got {_kind(value)}")
            axes.append((var, value))
        count = math.prod(len(values) for _, values in axes) * per * _size(template)
        self.generated += count
        if self.generated > MAX_GENERATED:
            raise self.err(path, f"generates {count:,} values ({self.generated:,} so far); a spec may generate "
                                 f"at most {MAX_GENERATED:,}")
        self.charge(path, self.generated)  # everything generated so far, against the budget
        out = []
        for combo in itertools.product(*(values for _, values in axes)):
            values = dict(zip((var for var, _ in axes), combo))
            text = ", ".join(f"{var} = {x}" for var, x in values.items())
            out.append((values, f"{note}, {text}" if note else text))
        return out

    def compute(self, text: str, where: KeyPath, env: dict[str, Any], note: str) -> Any:
        left = MAX_GENERATION_STEPS - self.steps - len(text)
        run = Evaluation({**self.names, **env}, min(left, MAX_EXPRESSION_STEPS))
        try:
            if left <= 0:
                raise ExpressionError("out of steps")
            return run.run(text)
        except ExpressionError as e:
            if left <= MAX_EXPRESSION_STEPS and run.steps >= left:
                raise self.err(where, f"generating the spec's parts takes more than {MAX_GENERATION_STEPS:,} "
                                      "steps of expressions (items built, compared or read)", note) from None
            raise self.err(where, str(e), note) from None
        finally:
            self.steps += len(text) + run.steps

    def fill(self, text: str, where: KeyPath, env: dict[str, Any], note: str) -> Any:
        """`text` with each `{expr}` replaced by its value; exactly one `{expr}`: the value itself."""
        pieces, i = [], 0
        while i < len(text):
            c = text[i]
            if c in "{}" and text.startswith(c * 2, i):
                pieces.append(c)
                i += 2
            elif c == "{":
                end = text.find("}", i)
                if end < 0:
                    raise self.err(where, f"{text[:60]!r}: a '{{' with no '}}' (write '{{{{' for a brace)", note)
                value = self.compute(text[i + 1:end], where, env, note)
                if i == 0 and end == len(text) - 1:
                    return value
                if not isinstance(value, (int, float, str)):
                    raise self.err(where, f"{text[:60]!r}: {{{text[i + 1:end]}}} is {_kind(value)}, not a "
                                          "number or a string to write in the text", note)
                pieces.append(str(value))
                i = end + 1
            elif c == "}":
                raise self.err(where, f"{text[:60]!r}: a '}}' with no '{{' (write '}}}}' for a brace)", note)
            else:
                j = min((k for k in (text.find("{", i), text.find("}", i)) if k >= 0), default=len(text))
                pieces.append(text[i:j])
                i = j
        return "".join(pieces)


def _size(node: Any) -> int:
    """Values in a template (each string, number and table counts one)."""
    if isinstance(node, dict):
        return 1 + sum(_size(v) for v in node.values())
    if isinstance(node, list):
        return 1 + sum(_size(v) for v in node)
    return 1


def _kind(v: Any) -> str:
    if isinstance(v, list):
        return f"a list of {len(v)}"
    if isinstance(v, dict):
        return "a table"
    return f"{type(v).__name__} {str(v)[:40]!r}"
