"""tracelab: a semantic simulation proxy for reinforcement learning that explains itself."""
import logging
from pathlib import Path

__version__ = "0.1.0"

# The library prints nothing: its notices go to the `tracelab` loggers, shown only where the application
# configures logging (the CLI shows them on stderr: tracelab/commands/_notices.py). Without this handler,
# Python would print warnings of an unconfigured logger to stderr itself.
logging.getLogger(__name__).addHandler(logging.NullHandler())

# The rule programs and specs: inside the package in a built wheel (pyproject maps rules/ to tracelab/rules),
# beside it in the source tree that an editable install runs from.
_PACKAGED_RULES = Path(__file__).resolve().parent / "rules"
RULES_DIR = _PACKAGED_RULES if _PACKAGED_RULES.is_dir() else _PACKAGED_RULES.parent.parent / "rules"
