"""Integer tables for the rules evaluated per head grounding (quantified clauses, annotation functions),
read by the counting kernel (engine/kernel.py, `_agg_eval`).

Such a rule's groundings are the joins of its unquantified clauses (a quantified clause never binds, so
its atoms are not watched). The joins with the same head atom form a *head group*; a group's joins are
contiguous in rank order because the head's variables come first in `Rule.variables`. The kernel
re-evaluates every group in each pass (exact, not incremental): its active joins give the candidates of
each quantified clause (distinct atoms) and the atoms that feed the annotation function.
"""
from __future__ import annotations

import numpy as np

from . import kernel as K
from .grounding import Grounder
from .kernel_tables import AggregateTables
from .program import COMPARISONS, Rule

# the kernel's code of each built-in annotation function (engine/annotations.py has them in Python)
BUILTIN_CODES = {"average": K.FN_AVERAGE, "weighted_average": K.FN_WEIGHTED_AVERAGE, "min": K.FN_MIN,
                 "max": K.FN_MAX, "average_lower": K.FN_AVERAGE_LOWER}


def aggregated_rules(rules: list[Rule]) -> list[int]:
    return [i for i, r in enumerate(rules) if r.aggregated]


def aggregate_tables(grounder: Grounder, rules: list[Rule], inst: np.ndarray,
                     user_slots: dict[str, int]) -> AggregateTables:
    """The kernel's tables of the aggregated rules over the groundings found so far. `inst` is the
    grounding table of kernel_tables (rule, head, rank, kind); `user_slots` numbers the user functions."""
    agg = aggregated_rules(rules)
    max_body = max((len(rules[i].body) for i in agg), default=1)
    ag_rule = np.zeros((len(agg), K.N_AR), np.int64)
    ag_cf = np.zeros((len(agg), max_body, 3), np.float64)
    # per clause its test flags (kernel CLAUSE_NEGATED, CLAUSE_CLOSED): `~`, and a %closed predicate
    ag_cn = np.zeros((len(agg), max_body), np.uint8)
    q_rows: list[tuple[int, int, int, int]] = []
    q_vals: list[float] = []
    for a, ri in enumerate(agg):
        r = rules[ri]
        fn = K.FN_FIXED if r.annotation is None else BUILTIN_CODES.get(r.annotation, K.FN_USER)
        q0 = len(q_rows)
        for ci, q in enumerate(r.quantifiers):
            if q is not None:
                q_rows.append((ci, COMPARISONS.index(q.op), int(q.percent), int(q.available)))
                q_vals.append(q.value)
        ag_rule[a] = (ri, K.KIND_DELAYED if r.delay > 0 else K.KIND_ORDINARY, fn,
                      user_slots.get(r.annotation, -1) if fn == K.FN_USER else -1, q0, len(q_rows), len(r.body),
                      int(r.head.negated))
        for ci, lit in enumerate(r.body):
            ag_cf[a, ci] = (lit.lower, lit.upper, r.weights[ci] if r.weights else 1.0)
            closed = K.CLAUSE_CLOSED if lit.pred in grounder.closed else 0
            ag_cn[a, ci] = (K.CLAUSE_NEGATED if lit.negated else 0) | closed
    agg_of_rule = np.full(len(rules), -1, np.int64)
    agg_of_rule[agg] = np.arange(len(agg))
    # the aggregated rules' groundings in rank order, cut into head groups (rule, head atom)
    n = len(inst)
    is_agg = agg_of_rule[inst[:, K.INST_RULE]] >= 0 if n else np.zeros(0, np.bool_)
    gs = np.flatnonzero(is_agg)
    gs = gs[np.argsort(inst[gs, K.INST_RANK], kind="stable")]
    g_agg = agg_of_rule[inst[gs, K.INST_RULE]]
    g_head = inst[gs, K.INST_HEAD].astype(np.int64)
    new = np.ones(len(gs), np.bool_)
    if len(gs) > 1:
        new[1:] = (g_agg[1:] != g_agg[:-1]) | (g_head[1:] != g_head[:-1])
    starts = np.flatnonzero(new)
    hg_ptr = np.append(starts, len(gs)).astype(np.int64)
    hg_i = np.column_stack([g_agg[starts], g_head[starts]]).astype(np.int64) if len(starts) \
        else np.zeros((0, 2), np.int64)
    body = grounder.body_atoms(gs)[:, :max_body] if len(gs) else np.zeros((0, max_body), np.int64)
    je_body = np.full((len(gs), max_body), -1, np.int64)
    je_body[:, :body.shape[1]] = body
    sizes = np.diff(hg_ptr) * ag_rule[hg_i[:, 0], K.AR_NBODY] if len(starts) else np.zeros(0, np.int64)
    user = ag_rule[hg_i[:, 0], K.AR_FN] == K.FN_USER if len(starts) else np.zeros(0, np.bool_)
    n_user = int(user.sum())
    return AggregateTables(
        ag_rule=ag_rule, ag_cf=ag_cf, ag_cn=ag_cn,
        ag_q=np.array(q_rows, np.int64).reshape(-1, 4), ag_qv=np.array(q_vals, np.float64),
        hg_i=hg_i, hg_ptr=hg_ptr, je_g=gs.astype(np.int64), je_body=je_body,
        gather_cap=max(int(sizes.max()) if len(sizes) else 0, 1),
        request_cap=max(n_user, 1),
        user_gather_cap=max(int(sizes[user].sum()) if n_user else 0, 1),
    )

