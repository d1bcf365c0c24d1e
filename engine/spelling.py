"""How the rule language spells a name: a predicate, an unquoted constant. Its own module, without the
program's types, so that a reader of runs (tracelab/store/model.py reads an atom as the store writes it)
does not load them (issue 40: a reading command loads only what it uses)."""
from __future__ import annotations

import re

CONSTANT_RE = re.compile(r"[a-z0-9][A-Za-z0-9_-]*")  # unquoted constants; anything else must be quoted
# predicate names; annotation functions and GraphML attribute names that become predicates are written so
PREDICATE_RE = re.compile(r"[a-z][A-Za-z0-9_]*")
