"""Static facts: the rows of a trace that set an atom from a fact the program declares `static` (a game's
map: `free(30)`, `leftOf(29,30)`, ... at t = 0). The engine never changes a static atom afterwards, so
these rows say nothing about the episode's dynamics; in a game run they are about half of every
episode's rows. The trace views hide them by default (tracelab trace's table, the TUI's trace, key `s`)
and say how many they hid."""
from __future__ import annotations

# A change row (raw.changes, or the changes view: both have cause_kind and cause_id) set by a static fact.
STATIC_ROW_SQL = "(cause_kind = 0 AND cause_id IN (SELECT fact FROM raw.facts WHERE static))"
FACT_CAUSE = 0   # tracelab.engine's CAUSE_FACT, as schema.CAUSE_NAMES names it
