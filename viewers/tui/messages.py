"""Messages the panes of a run send each other through the run screen."""
from __future__ import annotations

from textual.message import Message


class OpenTrace(Message):
    """Show an episode's trace, optionally filtered by rule and positioned at a timestep."""
    def __init__(self, episode: int, rule: str = "", at_t: int | None = None) -> None:
        super().__init__()
        self.episode, self.rule, self.at_t = episode, rule, at_t


class ExplainChange(Message):
    """Open the why tree of the change `seq` of an episode (the one selected in the trace); without a seq,
    of the atom's bound at the end of timestep t."""
    def __init__(self, episode: int, atom: str, t: int, seq: int | None = None) -> None:
        super().__init__()
        self.episode, self.atom, self.t, self.seq = episode, atom, t, seq



class ExplainAction(Message):
    """Open the why of `agent`'s decision at `step` of an episode (`tracelab why --action`); `action`: the
    action row chosen in the decision panel (its why-not when the agent took another)."""
    def __init__(self, episode: int, agent: str, step: int, action: str) -> None:
        super().__init__()
        self.episode, self.agent, self.step, self.action = episode, agent, step, action
