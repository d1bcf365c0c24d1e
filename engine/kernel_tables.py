"""What crosses from grounding to the kernels: the integer tables of the groundings, named field by field
(as program.py names what crosses from the parser to the grounder).

The Engine (core.py) builds them after each grounding round (Grounder.kernel_tables,
aggregate_tables.aggregate_tables) and hands them to its backend, which passes the arrays one by one to
the numba kernels (kernel.py, lanes.py): numba compiles against plain arrays, and a kernel's signature,
hence its disk cache, stays the same whatever these classes hold.

Sizes: G groundings, A atoms, B binding clauses of all groundings, C watch classes (one per atom and
clause test), I immediate groundings; R aggregated rules, Q their quantifiers, H head groups, J their
joins. A `_ptr` array is a CSR index: entry i's rows are [ptr[i], ptr[i+1]) of the array it points into.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, slots=True)
class KernelTables:
    """Every grounding, its watches and its binding clauses (Grounder.kernel_tables)."""
    inst: np.ndarray      # int32 [G, 4]: rule, head atom, rank, kind index (kernel.INST_*)
    wc_ptr: np.ndarray    # int32 [A+1]: CSR by atom over the watch classes of the clauses that read it
    wc_bnd: np.ndarray    # float64 [C, 2]: a class's clause bound (lower, upper)
    wc_flags: np.ndarray  # uint8 [C]: a class's clause flags (kernel.CLAUSE_NEGATED, CLAUSE_CLOSED)
    wc_code: np.ndarray   # uint8 [C]: a class's truth code (grounding.truth_codes; the lanes kernel)
    wc_gptr: np.ndarray   # int32 [C+1]: CSR by class over wg
    wg: np.ndarray        # int32 [B]: the groundings that watch each class
    ih_ptr: np.ndarray    # int32 [A+1]: CSR by atom over ih_inst
    ih_inst: np.ndarray   # int32 [I]: the immediate groundings that set each atom, by atom
    b_ptr: np.ndarray     # int32 [G+1]: CSR by grounding over its binding clauses, changing atoms first
    b_atom: np.ndarray    # int32 [B]: a binding clause's atom
    b_flags: np.ndarray   # uint8 [B]: a binding clause's flags (as wc_flags)
    b_bnd: np.ndarray     # float64 [B, 2]: a binding clause's bound (lower, upper)
    b_code: np.ndarray    # uint8 [B]: a binding clause's truth code (as wc_code)


@dataclass(frozen=True, slots=True)
class AggregateTables:
    """The rules evaluated per head group: quantified clauses, annotation functions (aggregate_tables.py;
    read by the counting kernel only)."""
    ag_rule: np.ndarray   # int64 [R, N_AR]: rule, kind, function, user slot, quantifier rows, body length,
                          # head negated (kernel.AR_*)
    ag_cf: np.ndarray     # float64 [R, max body, 3]: per clause its bound (lower, upper) and weight
    ag_cn: np.ndarray     # uint8 [R, max body]: per clause its flags (kernel.CLAUSE_NEGATED, CLAUSE_CLOSED)
    ag_q: np.ndarray      # int64 [Q, 4]: per quantifier its clause, comparison (kernel.CMP_*), percent, available
    ag_qv: np.ndarray     # float64 [Q]: per quantifier its value (a count or a percentage)
    hg_i: np.ndarray      # int64 [H, 2]: per head group its row of ag_rule and its head atom
    hg_ptr: np.ndarray    # int64 [H+1]: CSR by head group over je_g
    je_g: np.ndarray      # int64 [J]: the groups' joins (groundings) in rank order
    je_body: np.ndarray   # int64 [J, max body]: a join's clause atoms (-1 past its rule's body)
    gather_cap: int       # scratch size (>= 1): the most atoms one head group feeds its function
    request_cap: int      # scratch size (>= 1): the user-function requests of one pass
    user_gather_cap: int  # scratch size (>= 1): the atoms all user-function requests of a pass read
