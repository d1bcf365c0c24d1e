"""The objects of the modules loaded so far, frozen (`gc.freeze()`): they live until the process exits,
and no later garbage collection traverses them, the interpreter's final ones at exit included. numba's
and numpy's ~70,000 objects cost the warm hello world ~0.25 s of CPU in those collections
(docs/benchmarks/history.md, "The warm hello world, cut to what it uses"). Called after
`import tracelab.pyreason` and after each heavy library it loads later (the compiled engine, pandas).
What this gives up: an object made before a call that later becomes cyclic garbage is never freed."""
import gc


def freeze_loaded_modules() -> None:
    gc.freeze()
