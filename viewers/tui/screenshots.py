"""The README's pictures of the TUI, made by driving the app headless (`tracelab tui --screenshots DIR`):

tui-trace-why.png   sample_runs/advanced, episode 2 filtered to the death of red-agent-1 (the trace with
                    its board), above the why tree of that change
tui-reasoning.png   sample_runs/supply-chain, a reasoning run (no board): the trace filtered by the rule
                    alert at t=3 with the alerts true then beside it and the graph around the alerted
                    maintainer (their packages, exposed or not), above the why tree of that alert
tui-training.png    the Training view of a real training run: sample_runs/base-train, made by
                    `tracelab train` in sample_runs/regenerate.sh (its command is in the picture's header).
                    Nothing here writes metrics: a picture of curves shows a run on disk or none.
tui-decision.png    the same training run's first traced evaluation game at t=10: the board with the
                    trained agent's decision under it (its Q-values, the chosen action, the reward
                    terms), above the Why view of that decision with the why-not of the runner-up

textual saves SVG; rsvg-convert (Debian: librsvg2-bin) turns it into PNG. textual's SVG names the web font
Fira Code and spaces as &#160;, which rsvg draws narrow: both are replaced (DejaVu Sans Mono) first."""
from __future__ import annotations

import asyncio
import os
import re
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tracelab.store.reader import open_run
from tracelab.viewers.tui.app import TracelabApp
from tracelab.viewers.tui.decision import DecisionPanel
from tracelab.viewers.tui.graph_side import GraphSide
from tracelab.viewers.tui.lazy_table import LazyTable
from tracelab.viewers.tui.plot import BraillePlot
from tracelab.viewers.tui.trace import TracePane
from tracelab.viewers.tui.why import WhyPane

SIZE = (124, 34)
DEATH = (2, 14)  # sample_runs/advanced: red-agent-1 is shot dead in episode 2 at t=14 (episode, t)
ROOT = Path(__file__).resolve().parents[2]


async def _until(pilot: Any, done: Callable[[], bool], timeout: float = 60.0) -> None:
    loop = asyncio.get_running_loop()
    t0 = loop.time()
    while not done():
        await pilot.pause(0.05)
        if loop.time() - t0 > timeout:
            raise RuntimeError("the TUI did not reach the screen to photograph")


async def _trace_and_why(run: Path) -> tuple[str, str]:
    app = TracelabApp([run])
    async with app.run_test(size=SIZE) as pilot:
        episodes = app.screen.query_one("#ep-table", LazyTable)
        await _until(pilot, lambda: episodes.idle and episodes.cursor_row is not None)
        episodes.move_to(next(i for i in range(episodes.count) if episodes.row(i)["episode"] == DEATH[0]))
        await pilot.press("enter")
        pane = app.screen.query_one(TracePane)
        await _until(pilot, lambda: pane.table.idle and pane.table.count > 0)
        pane.field("range").value = str(DEATH[1])
        await pilot.press("slash", "enter")
        await _until(pilot, lambda: pane.filter is not None and pane.filter.t_from == DEATH[1] and pane.table.idle)
        death = next(i for i in range(pane.table.count) if pane.table.row(i)["atom"] == "alive(red-agent-1)")
        pane.table.move_to(death)
        await _until(pilot, lambda: pane.board is not None and pane.board.board is not None
                     and pane.board.step == DEATH[1])
        await pilot.pause(0.5)
        trace_svg = app.export_screenshot(title="tracelab tui · trace")
        await pilot.press("w")
        why = app.screen.query_one(WhyPane)
        await _until(pilot, lambda: why.why_tree.root.data is not None)
        await pilot.press("o")
        await pilot.pause(0.3)
        return trace_svg, app.export_screenshot(title="tracelab tui · why")


async def _reasoning(run: Path) -> tuple[str, str]:
    app = TracelabApp([run])
    async with app.run_test(size=SIZE) as pilot:
        episodes = app.screen.query_one("#ep-table", LazyTable)
        await _until(pilot, lambda: episodes.idle and episodes.cursor_row is not None)
        await pilot.press("enter")
        pane = app.screen.query_one(TracePane)
        await _until(pilot, lambda: pane.table.idle and pane.table.count > 0)
        pane.field("rule").value = "alert"
        pane.field("range").value = "3"
        await pilot.press("slash", "enter")
        await _until(pilot, lambda: pane.filter is not None and pane.filter.rule == "alert" and pane.table.idle
                     and pane.table.count > 0)
        side = pane.query_one(GraphSide)
        side.query_one("#gs-filter").value = "alert"
        side.reload()
        await _until(pilot, lambda: side.atoms is not None and side.atoms.t == 3 and side.hood is not None
                     and side.table.idle and "alert" in side.query_one("#gs-filter").value)
        pane.table.focus()
        # the graph around the atom under the cursor is read after the cursor rests: wait for that atom's
        await _until(pilot, lambda: side.hood is not None and side.hood.atom.startswith("alert(") and side.hood.t == 3)
        await pilot.pause(0.5)
        trace_svg = app.export_screenshot(title="tracelab tui · a reasoning run: atoms and graph")
        await pilot.press("w")
        why = app.screen.query_one(WhyPane)
        await _until(pilot, lambda: why.why_tree.root.data is not None)
        await pilot.press("o")
        await pilot.pause(0.3)
        return trace_svg, app.export_screenshot(title="tracelab tui · why")


async def _decision(run: Path) -> tuple[str, str]:
    app = TracelabApp([run])
    async with app.run_test(size=SIZE) as pilot:
        episodes = app.screen.query_one("#ep-table", LazyTable)
        await _until(pilot, lambda: episodes.idle and episodes.cursor_row is not None)
        await pilot.press("enter")
        pane = app.screen.query_one(TracePane)
        await _until(pilot, lambda: pane.filter is not None and pane.table.idle)
        await pilot.press("right_square_bracket")             # the first evaluation game (traced)
        await _until(pilot, lambda: pane.table.idle and pane.table.count > 0)
        pane.field("goto").value = "10"
        await pilot.press("g", "enter")
        panel = pane.query_one(DecisionPanel)
        await _until(pilot, lambda: panel.step is not None and panel.step.step == 10 and panel.display
                     and pane.board is not None and pane.board.board is not None and pane.board.step == 10)
        await pilot.pause(0.5)
        trace_svg = app.export_screenshot(title="tracelab tui · trace: the board and the agent's decision")
        await pilot.press("d", "down", "w")
        why = app.screen.query_one(WhyPane)
        await _until(pilot, lambda: why.action is not None)
        await pilot.pause(0.3)
        return trace_svg, app.export_screenshot(title="tracelab tui · why the agent did it")


async def _training(run: Path) -> str:
    app = TracelabApp([run])
    async with app.run_test(size=SIZE) as pilot:
        await pilot.press("6")
        await _until(pilot, lambda: app.screen.panes["training"].is_attached)
        plot = app.screen.query_one("#plot-loss", BraillePlot)
        await _until(pilot, lambda: plot.points > 0)
        await pilot.pause(0.3)
        return app.export_screenshot(title="tracelab tui · training")


def _fix_for_rsvg(svg: str) -> str:
    svg = svg.replace("Fira Code", "DejaVu Sans Mono").replace("&#160;", " ")
    return svg.replace("<svg ", '<svg xml:space="preserve" ', 1)


def stack(svgs: list[str]) -> str:
    """Several SVG screenshots one above the other, as one SVG."""
    parts, y, width = [], 0.0, 0.0
    for svg in svgs:
        w = float(re.search(r'viewBox="0 0 ([\d.]+) ([\d.]+)"', svg)[1])  # type: ignore[index]
        h = float(re.search(r'viewBox="0 0 ([\d.]+) ([\d.]+)"', svg)[2])  # type: ignore[index]
        body = re.sub(r"^<\?xml[^>]*>\s*", "", svg.strip())
        parts.append(body.replace("<svg ", f'<svg x="0" y="{y}" width="{w}" height="{h}" ', 1))
        y, width = y + h, max(width, w)
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{y}" '
            f'viewBox="0 0 {width} {y}">' + "".join(parts) + "</svg>")


def to_png(svg: str, png: Path) -> Path:
    converter = shutil.which("rsvg-convert")
    if converter is None:
        raise RuntimeError("rsvg-convert not found: install it (Debian: apt-get install librsvg2-bin)")
    fixed = png.with_suffix(".rsvg.svg")
    fixed.write_text(_fix_for_rsvg(svg))
    try:
        subprocess.run([converter, str(fixed), "-o", str(png)], check=True, capture_output=True)
    finally:
        fixed.unlink(missing_ok=True)
    return png


def training_run_problem(run: Path) -> str | None:
    """Why `run` cannot be the training picture's run (no metrics: not a training run), or None."""
    con = open_run(run)
    try:
        (metrics,) = con.execute("SELECT count(*) FROM metrics").fetchone()
    finally:
        con.close()
    if not metrics:
        return f"{str(run)!r} has no training metrics: photograph a run made by `tracelab train`"
    return None


def write_screenshots(directory: Path, trace_run: Path | None = None,
                      training_run: Path | None = None, reasoning_run: Path | None = None) -> list[Path]:
    """Write tui-trace-why.png (from `trace_run`, default sample_runs/advanced), tui-training.png (from
    `training_run`, default sample_runs/base-train: a real training run) and tui-reasoning.png (from
    `reasoning_run`, default sample_runs/supply-chain: a run without a board) and tui-decision.png (from
    `training_run`: its evaluation games record the policy's decisions) to `directory`."""
    os.environ.setdefault("TEXTUAL_ANIMATIONS", "none")
    trace_run = trace_run or ROOT / "sample_runs" / "advanced"
    training_run = training_run or ROOT / "sample_runs" / "base-train"
    reasoning_run = reasoning_run or ROOT / "sample_runs" / "supply-chain"
    for run in (trace_run, training_run, reasoning_run):
        if not run.exists():
            raise ValueError(f"no run {str(run)!r} to photograph")
    problem = training_run_problem(training_run)
    if problem:
        raise ValueError(problem)
    directory.mkdir(parents=True, exist_ok=True)
    trace_svg, why_svg = asyncio.run(_trace_and_why(trace_run))
    out = [to_png(stack([trace_svg, why_svg]), directory / "tui-trace-why.png")]
    out.append(to_png(asyncio.run(_training(training_run)), directory / "tui-training.png"))
    out.append(to_png(stack(list(asyncio.run(_reasoning(reasoning_run)))), directory / "tui-reasoning.png"))
    out.append(to_png(stack(list(asyncio.run(_decision(training_run)))), directory / "tui-decision.png"))
    return out
