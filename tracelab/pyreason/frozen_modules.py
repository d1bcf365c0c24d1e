"""The objects of the modules loaded so far, frozen (`gc.freeze()`): they live until the process exits,
and no later garbage collection traverses them, the interpreter's final ones at exit included. numba's
and numpy's ~70,000 objects cost the warm hello world ~0.25 s of CPU in those collections
(docs/benchmarks/history.md, "The warm hello world, cut to what it uses"). Done by `import
tracelab.pyreason` and when a heavy library it needs later (pandas, the compiled engine) is first loaded.
What this gives up: an object made before then that later becomes cyclic garbage is never freed."""
import gc
import importlib
import sys
from types import ModuleType


def freeze_loaded_modules() -> None:
    gc.freeze()


def import_frozen(name: str) -> ModuleType:
    """`import name`; the first time, the objects of what it loaded are frozen (once, not per call)."""
    first = name not in sys.modules
    module = importlib.import_module(name)
    if first:
        gc.freeze()
    return module
