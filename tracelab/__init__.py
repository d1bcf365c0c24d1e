"""tracelab: a semantic simulation proxy for reinforcement learning that explains itself."""
from pathlib import Path

__version__ = "0.1.0"

# rules/ lives beside the package in the source tree (the project is installed editable).
RULES_DIR = Path(__file__).resolve().parent.parent / "rules"
