"""tracelab: a semantic simulation proxy for reinforcement learning that explains itself."""
import logging
from pathlib import Path

__version__ = "0.1.0"

# The library prints nothing: its notices go to the `tracelab` loggers, shown only where the application
# configures logging (the CLI shows them on stderr: tracelab/commands/_notices.py). Without this handler,
# Python would print warnings of an unconfigured logger to stderr itself.
logging.getLogger(__name__).addHandler(logging.NullHandler())

# rules/ lives beside the package in the source tree (the project is installed editable).
RULES_DIR = Path(__file__).resolve().parent.parent / "rules"
