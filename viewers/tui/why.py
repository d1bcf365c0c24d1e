"""The Why view: the proof tree of the change selected in the trace (tracelab.store.why.explain_change: that
row's own rule and grounding, even when its atom changed again later in the step) as an expandable tree,
and why-not for a rule and bindings (`tracelab why-not`): type `RULE A=red-agent-1,X=c3_1 at T` in the
why-not line. For a decision (`w` in the trace's decision panel) the agent's why, as `tracelab why
--action` prints it: the actions ranked by value, the observation it acted on (Enter on a feature read
from an atom opens that atom's why tree), the reward terms; and why-not of the action under the panel's
cursor when the agent took another."""
from __future__ import annotations

import re
from typing import Any

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical, VerticalScroll
from textual.widgets import Input, Static, Tree
from textual.widgets.tree import TreeNode

from tracelab.engine.terminal_text import printable

from tracelab.store.agent_why import (
    ActionExplanation,
    explain_action,
    render_action,
    render_why_not_action,
    why_not_action,
)
from tracelab.store.why import (
    WhyNode,
    WhyNot,
    explain,
    explain_change,
    parse_bindings,
    render_why_not,
    why_not,
)
from tracelab.viewers.tui.colours import DIM, FALSE, TRUE, bound_colour, bound_text, styled_name
from tracelab.viewers.tui.source import RunSource
from tracelab.viewers.tui.shown_text import shown

DEPTH = 12
_WHY_NOT = re.compile(r"^\s*(\S+)\s*(.*?)\s*(?:\bat\s+|@\s*)(-?\d+)\s*$")


def node_label(n: WhyNode, at: int | None = None) -> Text:
    """One line of the tree: ok/NO, the clause or atom, its value, and what set it."""
    text = Text()
    if n.clause is None:
        text.append_text(styled_name(n.atom))
        text.append(" = ")
    else:
        text.append("ok " if n.holds else "NO ", style=f"bold {TRUE if n.holds else FALSE}")
        text.append_text(styled_name(n.clause))
        text.append(" = ")
    if n.clause is None and at is None and n.old is not None:   # the root of a change's tree: old -> new
        text.append(bound_text(*n.old), style=bound_colour(*n.old))
        text.append(" → ", style=DIM)
    lo, up = n.value
    text.append(bound_text(lo, up), style=bound_colour(lo, up))
    if n.clause is None and at is not None:
        text.append(f" at the end of t={at}:")
    c = n.cause
    if c is None or c.kind == "default":
        text.append("  never set" + (", read as [0,0]: %closed" if n.clause_closed else ""), style=DIM)
        return text
    text.append(f"  t={n.t} by ", style=DIM)
    text.append(c.name, style="bold" if c.kind == "rule" else "")
    if c.kind in ("rule", "policy"):
        delay = "!" if c.immediate else f"Δt={c.delay}"
        binds = ", ".join(f"{k}={v}" for k, v in c.bindings.items())
        text.append(f" ({delay}{'; ' + binds if binds else ''})", style=DIM)
    if n.repeated:
        text.append("  [explained above]", style="italic")
    if n.truncated:
        text.append("  [depth limit]", style="italic")
    return text


def parse_why_not(text: str) -> tuple[str, dict[str, str], int]:
    """`RULE A=x,B=y at T` (bindings optional); raises ValueError."""
    m = _WHY_NOT.match(text)
    if not m:
        raise ValueError(f"cannot read {text!r}: write RULE A=red-agent-1,X=c3_1 at 12")
    return m[1], parse_bindings(m[2].replace(" ", ",")), int(m[3])


class WhyPane(Vertical):
    BINDINGS = [Binding("o", "expand_all", "expand all"), Binding("c", "collapse", "collapse"),
                Binding("slash", "focus_why_not", "why-not")]

    def __init__(self, source: RunSource) -> None:
        super().__init__()
        self.source = source
        self.episode: int | None = None
        self.at: int | None = None
        self.action: ActionExplanation | None = None   # the decision shown (tests wait on it)

    def compose(self) -> ComposeResult:
        yield Static(" select a change in the trace and press Enter or w", id="why-head", classes="status")
        tree: Tree[WhyNode] = Tree("(no explanation yet)", id="why-tree")
        tree.show_root = True
        yield tree
        yield Input(placeholder="why-not: RULE A=red-agent-1,X=c3_1 at T", id="why-not", compact=True)
        with VerticalScroll(id="why-not-out"):
            yield Static("", id="why-not-text")

    @property
    def head(self) -> Static:
        """The line over the tree: what it explains, or that it is working."""
        return self.query_one("#why-head", Static)

    @property
    def why_tree(self) -> Tree[Any]:
        return self.query_one("#why-tree", Tree)

    @property
    def why_not_line(self) -> Input:
        return self.query_one("#why-not", Input)

    def focus_default(self) -> None:
        self.why_tree.focus()

    def explain(self, episode: int, atom: str, t: int, seq: int | None = None) -> None:
        """The why tree of the selected change `seq` (its own rule and grounding, tracelab.store.why.
        explain_change: right even when the atom changed again later in t); without a seq, of the atom's
        bound at the end of t (what `tracelab why --at t` prints)."""
        self.episode, self.at = episode, t
        what = f"the change of {atom} (seq {seq})" if seq is not None else f"{atom} at the end of t={t}"
        self.head.update(f" why {what}, episode {episode} · working…")

        def work() -> None:
            try:
                root = self.source.call(lambda con: explain(con, episode, atom, t, depth=DEPTH) if seq is None
                                        else explain_change(con, episode, seq, depth=DEPTH))
            except Exception as e:  # noqa: BLE001
                self.app.call_from_thread(self._failed, str(e))
                return
            self.app.call_from_thread(self._show, root, t, episode, seq is not None)

        self.run_worker(work, thread=True, group="why", exclusive=True, exit_on_error=False)

    def explain_action(self, episode: int, agent: str, step: int, action: str) -> None:
        """The why of `agent`'s decision at `step` (`tracelab why --action`); `action` not the one taken:
        its why-not too (`why-not --action`)."""
        self.episode, self.at = episode, step
        self.head.update(
            shown(f" why {agent} did what it did at step {step}, episode {episode} · working…"))

        def work() -> None:
            try:
                e = self.source.call(lambda con: explain_action(con, episode, agent, step))
            except Exception as err:  # noqa: BLE001
                self.app.call_from_thread(self._failed, str(err).strip("'\""))
                return
            self.app.call_from_thread(self._show_action, e, action)

        self.run_worker(work, thread=True, group="why", exclusive=True, exit_on_error=False)

    def _show_action(self, e: ActionExplanation, action: str) -> None:
        """The decision as a tree: the text of `why --action`, one node a line, its sections expandable;
        a feature read from an atom carries it (Enter opens the atom's why)."""
        self.action = e
        tree = self.why_tree
        tree.clear()
        lines = render_action(e).splitlines()
        if action != e.action:
            lines[2:2] = ["why not " + action + ": " + render_why_not_action(why_not_action(e, action)).split(": ", 1)[-1]]
        tree.root.set_label(Text(lines[0], style="bold"))
        tree.root.data = None
        atoms = {f"  {printable(f.name)} = {printable(f.value)}": f.atom for f in e.features if f.atom is not None}
        section: TreeNode[Any] = tree.root
        for line in lines[1:]:
            if line.startswith("  "):
                section.add_leaf(Text(line[2:]), data=atoms.get(line))
            else:
                section = tree.root.add(Text(line), expand=True)
        tree.root.expand()
        self.head.update(shown(
            f" why {e.agent}'s {e.action} at step {e.step}, episode {e.episode} · Enter on a feature: its atom's why"))

    def on_tree_node_selected(self, event: Tree.NodeSelected[Any]) -> None:
        """Enter on an observation feature read from an atom: that atom's why tree, where it was read."""
        e, atom = self.action, event.node.data
        if e is not None and isinstance(atom, str) and e.observed_at is not None:
            event.stop()
            self.action = None
            self.explain(e.episode, atom, e.observed_at)

    def _failed(self, message: str) -> None:
        self.head.update(Text(f" {message}", style="bold red"))

    def _show(self, root: WhyNode, t: int, episode: int, of_change: bool) -> None:
        self.action = None
        tree = self.why_tree
        tree.clear()
        tree.root.set_label(node_label(root, None if of_change else t))
        tree.root.data = root
        self._add_children(tree.root, root, expand_levels=2)
        tree.root.expand()
        rule = root.cause.name if root.cause else ""
        if of_change:
            old = "" if root.old is None else f"{bound_text(*root.old)} → "
            what = f"the change {root.atom} {old}{bound_text(*root.value)} at t={root.t} pass {root.pass_no}"
        else:
            what = f"{root.atom} at the end of t={t}"
        self.head.update(
            f" why {what}, episode {episode} · {rule} · Enter/click expands, o all")
        if self.why_not_line.value == "" and root.cause and root.cause.kind == "rule":
            binds = ",".join(f"{k}={v}" for k, v in root.cause.bindings.items())
            self.why_not_line.placeholder = f"why-not: {rule} {binds} at {root.t}"

    def _add_children(self, parent: TreeNode[WhyNode], node: WhyNode, expand_levels: int) -> None:
        for child in node.children:
            if child.children:
                sub = parent.add(node_label(child), data=child, expand=expand_levels > 0)
                self._add_children(sub, child, expand_levels - 1)
            else:
                parent.add_leaf(node_label(child), data=child)

    def action_expand_all(self) -> None:
        self.why_tree.root.expand_all()

    def action_collapse(self) -> None:
        tree = self.why_tree
        tree.root.collapse_all()
        tree.root.expand()

    def action_focus_why_not(self) -> None:
        self.why_not_line.focus()

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        out = self.query_one("#why-not-text", Static)
        text = event.value.strip() or event.input.placeholder.removeprefix("why-not:").strip()
        if self.episode is None:
            out.update(Text("open an explanation first (it gives the episode)", style="bold red"))
            return
        try:
            rule, bindings, at = parse_why_not(text)
        except ValueError as e:
            out.update(Text(str(e), style="bold red"))
            return
        episode = self.episode

        def work() -> None:
            try:
                result: WhyNot = self.source.call(lambda con: why_not(con, episode, rule, bindings, at))
                shown = Text(render_why_not(result))
            except Exception as e:  # noqa: BLE001
                shown = Text(str(e).strip("'\""), style="bold red")
            self.app.call_from_thread(out.update, shown)

        self.run_worker(work, thread=True, group="why-not", exclusive=True, exit_on_error=False)
