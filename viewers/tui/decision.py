"""DecisionPanel: the agent's half of the trace cursor's step, beside the board: for each agent that decided
at that step (tracelab.store.agent_why.explain_action, what `tracelab why --action` prints), a bar per
action of the policy's value (Q-value or logit), the chosen action marked ▶, explored or greedy (and ε),
masked actions shown as masked; and the step's reward by term. Up/down move over the action rows when it
has the focus; `w` opens the why of the decision (and why-not of the action under the cursor) in the Why
view. A run without decisions (written before they were recorded, or played by a scripted policy) hides it."""
from __future__ import annotations

from dataclasses import dataclass

from rich.text import Text
from textual.binding import Binding
from textual.geometry import Size
from textual.message import Message
from textual.reactive import reactive
from textual.widget import Widget

from tracelab.engine.terminal_text import printable
from tracelab.store.agent_why import ActionExplanation, explain_action
from tracelab.viewers.tui.colours import DIM, FALSE, PARTIAL, TRUE, team_colour
from tracelab.viewers.tui.messages import ExplainAction
from tracelab.viewers.tui.source import RunSource, background

VALUE_WIDTH = 6     # "-12.3" and a space
MIN_WIDTH = 18      # narrower, the bars have no room
NAME_MAX = 8        # longer action names are cut (the Why view has them whole)


@dataclass(frozen=True)
class StepDecisions:
    """The decisions of every agent at one step of an episode (empty: none recorded there)."""
    episode: int
    step: int
    decisions: tuple[ActionExplanation, ...]

    def rows(self) -> list[tuple[str, str]]:
        """(agent, action) of each action row, in the order drawn."""
        return [(d.agent, a.name) for d in self.decisions for a in d.ranked]


def read_step(source: RunSource, episode: int, step: int) -> StepDecisions:
    """Every agent's decision at `step` of `episode` (none in a run that records none)."""
    agents = source.rows("SELECT DISTINCT agent FROM decisions WHERE episode = $e AND step = $s ORDER BY agent",
                         {"e": episode, "s": step})
    found = tuple(source.call(lambda con, a=r["agent"]: explain_action(con, episode, a, step)) for r in agents)
    return StepDecisions(episode, step, found)


def _bar(value: float, low: float, high: float, width: int) -> str:
    """A bar of `width` cells scaled from low (empty) to high (full), in eighths."""
    span = high - low
    eighths = round(width * 8 * ((value - low) / span if span > 0 else 1.0))
    full, part = divmod(max(0, min(width * 8, eighths)), 8)
    return ("█" * full + (" ▏▎▍▌▋▊▉"[part] if part else "")).ljust(width)


def draw(step: StepDecisions, width: int, cursor: int | None) -> Text:
    """The decisions of a step as text `width` cells wide; the action row `cursor` highlighted."""
    text = Text()
    row = 0
    for d in step.decisions:
        how = f"explored ε {d.epsilon:g}" if d.explored else "greedy"
        text.append(printable(d.agent)[: max(1, width - len(how) - 1)], style=f"bold {team_colour(d.agent) or ''}")
        text.append(f" {how}\n", style=f"bold {PARTIAL}" if d.explored else DIM)
        name_w = min(NAME_MAX, max(len(a.name) for a in d.ranked))
        bar_w = max(1, width - 2 - name_w - VALUE_WIDTH)
        allowed = [a.value for a in d.ranked if a.allowed] or [a.value for a in d.ranked]
        low, high = min(min(allowed), 0.0), max(allowed)
        for a in d.ranked:
            chosen = a.name == d.action
            line = Text()
            line.append("▶" if chosen else " ", style=f"bold {PARTIAL if d.explored else TRUE}")
            line.append(printable(a.name)[:name_w].ljust(name_w) + " ", style="bold" if chosen else "")
            if a.allowed:
                line.append(_bar(a.value, low, high, bar_w), style=TRUE if chosen else "")
                line.append(f"{a.value:>{VALUE_WIDTH}.3g}"[-VALUE_WIDTH:])
            else:   # its value is the Why view's: the mask, not the value, kept it out
                line.append("masked".rjust(bar_w + VALUE_WIDTH), style=f"italic {DIM}")
            if row == cursor:
                line.stylize("reverse")
            text.append_text(line)
            text.append("\n")
            row += 1
        if d.reward is not None:
            text.append(f"reward {d.reward:+g}\n", style="bold")
            for term, value in d.terms:
                text.append(f" {printable(term)[: width - 9]:<{width - 9}}", style=DIM)
                text.append(f"{value:>+8.3g}\n", style=TRUE if value > 0 else FALSE)
    return text


class DecisionPanel(Widget, can_focus=True):
    BINDINGS = [
        Binding("up", "move(-1)", "action", show=False),
        Binding("down", "move(1)", "action", show=False),
        Binding("w", "why", "why action"),
    ]

    class Shown(Message):
        """The panel was shown or hidden (the trace offers `d` while it shows)."""

    # the step shown (None: no decision there) and the action row under the cursor
    step: reactive[StepDecisions | None] = reactive(None)
    cursor: reactive[int] = reactive(0)

    def __init__(self, source: RunSource) -> None:
        super().__init__()
        self.source = source
        self.border_title = "decision"
        self.display = False
        self._asked: tuple[int, int] | None = None

    def show(self, episode: int, t: int) -> None:
        """Follow the trace's cursor: the decisions of step t of `episode` (read in a worker)."""
        if self._asked == (episode, t):
            return
        self._asked = (episode, t)
        self.run_worker(background(lambda: self._read(episode, t)), thread=True, group="decision", exclusive=True,
                        exit_on_error=False)

    def _read(self, episode: int, t: int) -> None:
        try:
            step = read_step(self.source, episode, t)
        except Exception:  # noqa: BLE001 - a run the panel cannot read shows no panel; the trace still shows
            step = StepDecisions(episode, t, ())
        self.app.call_from_thread(self._landed, episode, t, step)

    def _landed(self, episode: int, t: int, step: StepDecisions) -> None:
        if self._asked == (episode, t):   # not overtaken by a later cursor move
            self.step = step

    def watch_step(self, step: StepDecisions | None) -> None:
        shown = step is not None and bool(step.decisions)
        if shown != self.display:
            self.display = shown
            self.post_message(self.Shown())
        rows = 0 if step is None else len(step.rows())
        self.cursor = min(self.cursor, max(0, rows - 1))
        self.refresh(layout=True)

    def watch_cursor(self) -> None:
        self.refresh()

    def action_move(self, by: int) -> None:
        if self.step is not None and self.step.decisions:
            self.cursor = max(0, min(len(self.step.rows()) - 1, self.cursor + by))

    def action_why(self) -> None:
        """The why of the decision under the cursor (and why-not of its action when not the chosen one)."""
        if self.step is None or not self.step.decisions:
            return
        agent, action = self.step.rows()[self.cursor]
        self.post_message(ExplainAction(self.step.episode, agent, self.step.step, action))

    def get_content_height(self, container: Size, viewport: Size, width: int) -> int:
        """A line per agent, per action and per reward term (and each agent's reward line)."""
        if self.step is None:
            return 0
        return sum(1 + len(d.ranked) + (0 if d.reward is None else 1 + len(d.terms)) for d in self.step.decisions)

    def render(self) -> Text:
        if self.step is None or not self.step.decisions:
            return Text("")
        return draw(self.step, max(MIN_WIDTH, self.content_size.width), self.cursor if self.has_focus else None)

    def on_focus(self) -> None:
        self.refresh()

    def on_blur(self) -> None:
        self.refresh()
