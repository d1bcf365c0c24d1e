"""`tracelab bench tui`'s first figure, in a fresh process: `python -m tracelab.bench.tui_first_screen RUN`
opens the TUI on RUN in textual's headless pilot (`load_app()([RUN]).run_test(size=(120, 40))`, the app
imported as `tracelab tui` imports it) and prints,
as one JSON line, the CPU seconds of this process (imports included: from its first instruction) and the
wall clock (time.time(), for the parent to subtract its spawn time) when the episodes table `#ep-table`
first has a cursor: the first screen a user sees, drawn."""
from __future__ import annotations

import asyncio
import json
import resource
import sys
import time
from pathlib import Path


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


async def _first_screen(run: Path) -> dict[str, float]:
    from tracelab.viewers.tui import load_app   # timed: what `tracelab tui` imports, as it imports it
    app = load_app()([run])
    async with app.run_test(size=(120, 40)):
        while True:
            tables = app.screen.query("#ep-table")
            if tables and tables.first().cursor_row is not None:
                return {"cpu_s": _cpu_s(), "wall_at": time.time()}
            await asyncio.sleep(0.002)  # not pilot.pause(): that waits for every widget's queue


def main() -> None:
    print(json.dumps(asyncio.run(_first_screen(Path(sys.argv[1])))), flush=True)


if __name__ == "__main__":
    main()
