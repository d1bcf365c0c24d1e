"""The cause kinds of a trace row (docs/language.md, "Trace"), for the Python code that reads rows: no
numba here, so reading a trace (tracelab.pyreason's rule trace, the reference evaluator) does not load
the kernels. kernel.py and lanes.py spell the same numbers out themselves: numba freezes a global into
its cached machine code and would not notice a change made here (tests/test_pyreason_imports.py checks
that all three agree)."""

CAUSE_FACT, CAUSE_EXTERNAL, CAUSE_RULE, CAUSE_POLICY, CAUSE_RESET = 0, 1, 2, 3, 4
