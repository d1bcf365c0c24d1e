"""Replaying a run: the chosen episodes, once (`replay_run`) or as they finish in a run being written
(`follow_run`, --live)."""
from __future__ import annotations

import time
from collections.abc import Callable

from tracelab.store.model import RunModel
from tracelab.store.reader import retrying, run_info
from tracelab.viewers.replay.outputs import Output
from tracelab.viewers.replay.recording import ReplayOptions, RunContext, record_episode
from tracelab.viewers.replay.select import EpisodeFilter, select_episodes


def replay_episodes(ctx: RunContext, episodes: list[int], out: Output,
                    options: ReplayOptions | None = None) -> int:
    """Each episode as its own recording into `out`; returns how many were sent."""
    for e in episodes:
        rec = out.recording(ctx.name, e)
        retrying(lambda: record_episode(ctx, e, rec, options))
        out.finished(rec)
    return len(episodes)


def replay_run(ctx: RunContext, f: EpisodeFilter, out: Output, options: ReplayOptions | None = None) -> int:
    episodes = retrying(lambda: select_episodes(ctx.con, f))
    if not episodes:
        raise ValueError("no episode of this run matches (played episodes with steps > 0"
                         + (f", outcome {f.outcome}" if f.outcome else "") + ")")
    n = replay_episodes(ctx, episodes, out, options)
    out.close()
    return n


def follow_run(ctx: RunContext, run: str, f: EpisodeFilter, out: Output, options: ReplayOptions | None = None,
               poll_s: float = 1.0, on_episode: Callable[[int], None] | None = None,
               max_idle_s: float | None = None) -> int:
    """Stream each episode the filter picks as soon as it has ended, until the run stops running (or
    `max_idle_s` passed without a new episode). Returns how many were sent."""
    sent: set[int] = set()
    idle_since = time.monotonic()
    while True:
        running = run_info(run).status == "running"
        new = retrying(lambda: select_episodes(ctx.con, EpisodeFilter(None, f.outcome), exclude=sent))
        if f.episodes is not None:
            new = [e for e in new if e in f.episodes]
        if f.limit is not None:
            new = new[:max(f.limit - len(sent), 0)]
        if new:
            ctx.refresh_metrics()
            ctx.model = RunModel(ctx.con)     # the vocabulary grows while a run is written
            for e in new:
                replay_episodes(ctx, [e], out, options)
                sent.add(e)
                out.write()
                if on_episode:
                    on_episode(e)
            idle_since = time.monotonic()
        done = f.limit is not None and len(sent) >= f.limit
        if done or not running or (max_idle_s is not None and time.monotonic() - idle_since > max_idle_s):
            break
        time.sleep(poll_s)
    out.close()
    return len(sent)
