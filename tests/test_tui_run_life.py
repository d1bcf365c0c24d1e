"""The TUI and the store's readers follow a run's life as other processes change it: a writer stopped by
Ctrl-C (the header says `interrupted` and the views stop re-reading), and `seal` while the run is open (a
reader moves to the sealed file, even in the middle of a query). Real writer processes, real sealing."""
from __future__ import annotations

import os
import signal
from pathlib import Path
from typing import Any

os.environ["TEXTUAL_ANIMATIONS"] = "none"

from store_helpers import synthetic_trace, synthetic_vocabulary  # noqa: E402
from patience import PATIENCE  # noqa: E402
from tui_helpers import episodes_ready, live_writer, loaded, run_app, shown, wait_for  # noqa: E402

from tracelab.store import layout  # noqa: E402
from tracelab.store.reader import LiveRunConnection, open_run, retrying, run_info  # noqa: E402
from tracelab.store.seal import seal_run  # noqa: E402
from tracelab.store.writer import TraceWriter  # noqa: E402
from tracelab.viewers.tui.plot import BraillePlot  # noqa: E402
from tracelab.viewers.tui.trace import TracePane  # noqa: E402

EPISODES, ROWS = 3, 2_000


def write_finished_run(run: Path) -> Path:
    """A closed, unsealed run: EPISODES episodes of ROWS synthetic changes, one flush (a part) each."""
    with TraceWriter(run, {"command": "pytest run life"}) as w:
        w.write_vocabulary(synthetic_vocabulary())
        for e in range(EPISODES):
            w.begin_episode(e, t_start=0)
            w.write_changes(e, synthetic_trace(ROWS, t0=0, seed=e))
            w.end_episode(e, steps=10, outcome="win")
            w.flush()
    return run


def title(app: Any) -> str:
    return str(app.screen.query_one("#title").render())


# ---- the store -------------------------------------------------------------------------------------------

def test_a_live_connection_keeps_answering_when_its_run_is_sealed_even_mid_query(tmp_path: Path) -> None:
    run = write_finished_run(tmp_path / "run")
    con = open_run(run)
    assert isinstance(con, LiveRunConnection)
    count = "SELECT count(*), sum(seq) FROM changes"
    (before,) = con.execute(count).fetchall()
    assert before[0] == EPISODES * ROWS

    attempts = []

    def query() -> Any:
        rel = con.sql(count)          # bound to the parts the manifest lists now
        if not attempts:
            seal_run(run)             # ... which seal removes before the query reads them
        attempts.append(1)
        return rel.fetchall()[0]

    assert retrying(query) == before and len(attempts) == 2
    assert not layout.parts_dir(run).exists() and con.sealed
    assert con.execute(count).fetchall() == [before]
    assert con.execute("SELECT status FROM run").fetchall() == [("finished",)]
    con.close()


# ---- the TUI ---------------------------------------------------------------------------------------------

def test_the_header_follows_a_training_stopped_by_ctrl_c_and_the_views_stop_re_reading(tmp_path: Path) -> None:
    with live_writer("train", tmp_path) as (run, writer):
        async def body(app: Any, pilot: Any) -> None:
            await pilot.press("6")
            training = app.screen.panes["training"]
            await wait_for(pilot, lambda: training.is_attached)
            loss = app.screen.query_one("#plot-loss", BraillePlot)
            await wait_for(pilot, lambda: loss.points > 0)
            text = await shown(app, pilot)
            assert "live · running" in title(app) and "re-read every second" in text

            writer.send_signal(signal.SIGINT)                # Ctrl-C in the training's terminal
            writer.wait(timeout=PATIENCE)
            assert run_info(run).status == "interrupted"
            await wait_for(pilot, lambda: "interrupted" in title(app))
            assert "· live" not in title(app) and "running" not in title(app)
            status = app.screen.query_one("#train-status")
            await wait_for(pilot, lambda: "interrupted" in str(status.render()))
            text = await shown(app, pilot)
            assert "re-read every second" not in text and "interrupted" in text
            # the curves hold everything the writer flushed before it closed
            last = max(xs[-1] for xs in (s.xs for s in loss.series))
            steps = [int(line.split()[1]) for line in writer.stdout.read().split("\n") if line.startswith("step")]
            assert not steps or last >= steps[-1]
            # one last read after the close, then none: the views no longer re-read the run
            episodes = app.screen.panes["episodes"]
            await wait_for(pilot, lambda: training.live_reads.done and episodes.live_reads.done)
        run_app([run], body, size=(100, 30))


def test_enter_on_an_episode_after_the_run_was_sealed_shows_its_trace(tmp_path: Path) -> None:
    run = write_finished_run(tmp_path / "run")

    async def body(app: Any, pilot: Any) -> None:
        episodes = await episodes_ready(app, pilot)
        assert episodes.count == EPISODES and "sealed" not in title(app)
        seal_run(run)                                    # `tracelab seal RUN` in another shell
        assert not layout.parts_dir(run).exists()
        await pilot.press("enter")
        pane = app.screen.query_one(TracePane)
        trace = pane.table
        await wait_for(pilot, lambda: (trace.ready and trace.error is not None)
                       or (trace.count > 0 and loaded(trace)))
        assert trace.error is None, trace.error
        assert trace.count == ROWS and trace.row(0) is not None and trace.row(0)["seq"] == 0
        text = await shown(app, pilot)
        assert "No such file" not in text and "Errno" not in text
        await wait_for(pilot, lambda: "sealed" in title(app))
    run_app([run], body)
