"""tracelab.engine: a temporal annotated-logic engine (generalized annotated programs with delays and
immediate rules), compiled with numba, batched over worlds, with a columnar trace of every change.
The language and its semantics: docs/language.md."""
