"""tracelab: a semantic simulation proxy for reinforcement learning that explains itself."""
from pathlib import Path

__version__ = "0.1.0"

# The library prints nothing: its notices go to the `tracelab` loggers (tracelab.engine.notices, which
# imports logging when a module first makes one), shown where the application configures logging or asks
# for them (the CLI shows them on stderr: tracelab/commands/_notices.py).

# The rule programs and specs: inside the package in a built wheel (pyproject maps rules/ to tracelab/rules),
# beside it in the source tree that an editable install runs from.
_PACKAGED_RULES = Path(__file__).resolve().parent / "rules"
RULES_DIR = _PACKAGED_RULES if _PACKAGED_RULES.is_dir() else _PACKAGED_RULES.parent.parent / "rules"
