"""The terminal UI (`tracelab tui`): runs, episodes, the trace with its board and why-trees, rules, a
read-only SQL console and live training curves. docs/tui.md lists the screens and keys."""
